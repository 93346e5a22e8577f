/* splat.cl — the classical splat (the NARVis networks' "splat" baseline and
 * narvis-scan's guard candidate): each covered pixel drawn as a screen-space
 * Gaussian ellipse, composited order-independently. The definition is the
 * docstring of clvis/reference/post/splat.py (float64); this kernel gathers
 * the same sums in float32, within float32 rounding of it (exp, the
 * reciprocals of the ellipse's axes, the transmittance as the product
 * prod(1 - opacity w) where the reference sums log1p (the same alpha, half
 * the kernel's time on PoCL, 4e-7 apart on the tests' frames) and the sums'
 * order: the reference's, offsets dy then dx).
 *
 * ABI
 * ---
 * Defines:
 *   R   the splat radius in pixels (required, 1..32): a target pixel reads
 *       the (2R+1)^2 sources around it.
 *
 * kernel splat_gather(global const float *src, uint pw, uint ph,
 *                     uint w, uint h, float opacity, global float *out)
 *     src: 8 planes of the sources, each pw x ph floats row-major, plane k at
 *     element offset k*pw*ph: cos, sin (the ellipse's long axis), 1/along,
 *     1/sigma (its standard deviations' reciprocals), m (1 at a covered
 *     pixel, else 0), r, g, b. They are the w x h frame padded with R
 *     uncovered pixels (all 8 planes 0) above, below and left, and at least
 *     R + 7 right: frame pixel (x, y) is source (x + R, y + R), pw >= w +
 *     2R + 7, ph = h + 2R. out: w x h x 3 floats (pixel y*w + x, colour c at
 *     3 (y*w + x) + c), every pixel written.
 *     One work-item per 8 pixels of a row (lanes = pixels x0..x0+7, x0 =
 *     8 (g mod ceil(w/8)), row g / ceil(w/8)): launch any one-dimensional
 *     global size >= h * ceil(w/8) (work-items past the end do nothing) and
 *     any local size. No bounds checks in the loop (the padding), no
 *     branches on coverage (m weighs an uncovered source 0), no atomics:
 *     each pixel's sums in a fixed order, deterministic.
 */

#ifndef R
#error "splat.cl: define R, the radius"
#endif

kernel void splat_gather(global const float *src, uint pw, uint ph, uint w, uint h, float opacity,
                         global float *out) {
    const uint blocks = (w + 7) / 8;
    const size_t gid = get_global_id(0);
    if (gid >= (size_t)blocks * h)
        return;
    const uint y = (uint)(gid / blocks), x0 = 8 * (uint)(gid % blocks);
    const size_t plane = (size_t)pw * ph;
    global const float *pc = src, *ps = src + plane, *pa = src + 2 * plane, *pg = src + 3 * plane;
    global const float *pm = src + 4 * plane, *pr = src + 5 * plane, *pgr = src + 6 * plane;
    global const float *pb = src + 7 * plane;
    float8 wsum = 0.0f, tr = 1.0f, a0 = 0.0f, a1 = 0.0f, a2 = 0.0f;
    for (int dy = -R; dy <= R; dy++) {
        const size_t row = (size_t)(y - dy + R) * pw + x0 + R;
        const float fy = (float)dy;
        for (int dx = -R; dx <= R; dx++) {
            const size_t s = row - dx;
            const float fx = (float)dx;
            const float8 c = vload8(0, pc + s), sn = vload8(0, ps + s);
            const float8 d_al = (fx * c + fy * sn) * vload8(0, pa + s);
            const float8 d_ac = (fy * c - fx * sn) * vload8(0, pg + s);
            const float8 wt = vload8(0, pm + s) * exp(-0.5f * (d_al * d_al + d_ac * d_ac));
            wsum += wt;
            tr *= 1.0f - opacity * wt;
            a0 += wt * vload8(0, pr + s);
            a1 += wt * vload8(0, pgr + s);
            a2 += wt * vload8(0, pb + s);
        }
    }
    const float8 k = (1.0f - tr) / fmax(wsum, 1e-12f);
    float o0[8], o1[8], o2[8];
    vstore8(a0 * k, 0, o0);
    vstore8(a1 * k, 0, o1);
    vstore8(a2 * k, 0, o2);
    const size_t base = (size_t)y * w;
    for (uint i = 0; i < 8 && x0 + i < w; i++) {
        out[3 * (base + x0 + i)] = o0[i];
        out[3 * (base + x0 + i) + 1] = o1[i];
        out[3 * (base + x0 + i) + 2] = o2[i];
    }
}
