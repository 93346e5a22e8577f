/* splat.cl — the classical splat (the NARVis networks' "splat" baseline and
 * narvis-scan's guard candidate): each covered pixel drawn as a screen-space
 * Gaussian ellipse, composited order-independently. The definition is the
 * docstring of clvis/reference/post/splat.py (float64); this kernel gathers
 * the same sums in float32, within float32 rounding of it (exp, log1p and
 * the sums' order: the reference's, offsets dy then dx).
 *
 * ABI
 * ---
 * Defines:
 *   R   the splat radius in pixels (required, 1..32): a target pixel reads
 *       the (2R+1)^2 sources around it.
 *
 * Images are row-major, row 0 on top, pixel i = y*w + x.
 *
 * kernel splat_gather(global const float *rgb, global const uchar *covered,
 *                     global const float4 *par, uint w, uint h,
 *                     float opacity, global float *out)
 *     rgb: 3 floats per pixel (read at covered pixels only); covered: one
 *     uchar per pixel, nonzero = a source; par: per pixel (cos, sin, along,
 *     sigma) of its ellipse (read at covered pixels only; along, sigma > 0:
 *     the host's clipped values); out: 3 floats per pixel, every pixel
 *     written. One work-item per target pixel; launch any one-dimensional
 *     global size >= w*h (work-items past the end do nothing) and any local
 *     size. Deterministic: no atomics, each pixel's sums in a fixed order.
 */

#ifndef R
#error "splat.cl: define R, the radius"
#endif

kernel void splat_gather(global const float *rgb, global const uchar *covered, global const float4 *par, uint w,
                         uint h, float opacity, global float *out) {
    const size_t gid = get_global_id(0);
    if (gid >= (size_t)w * h)
        return;
    const int x = (int)(gid % w), y = (int)(gid / w);
    float wsum = 0.0f, logt = 0.0f, a0 = 0.0f, a1 = 0.0f, a2 = 0.0f;
    for (int dy = -R; dy <= R; dy++) {
        const int sy = y - dy;
        if (sy < 0 || sy >= (int)h)
            continue;
        for (int dx = -R; dx <= R; dx++) {
            const int sx = x - dx;
            if (sx < 0 || sx >= (int)w)
                continue;
            const size_t s = (size_t)sy * w + sx;
            if (!covered[s])
                continue;
            const float4 p = par[s];
            const float fx = (float)dx, fy = (float)dy;
            const float d_al = (fx * p.x + fy * p.y) / p.z;
            const float d_ac = (-fx * p.y + fy * p.x) / p.w;
            const float wt = exp(-0.5f * (d_al * d_al + d_ac * d_ac));
            wsum += wt;
            logt += log1p(-opacity * wt);
            a0 += wt * rgb[3 * s];
            a1 += wt * rgb[3 * s + 1];
            a2 += wt * rgb[3 * s + 2];
        }
    }
    const float k = -expm1(logt) / fmax(wsum, 1e-12f);
    out[3 * gid] = a0 * k;
    out[3 * gid + 1] = a1 * k;
    out[3 * gid + 2] = a2 * k;
}
