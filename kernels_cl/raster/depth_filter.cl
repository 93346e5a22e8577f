/* depth_filter.cl — hierarchical depth filter of a one-pixel-per-point image:
 * removes background points seen through holes in a foreground surface
 * (Vanherck, Zoomers et al., "Real-time Neural Rendering of LiDAR Point
 * Clouds", Eurographics 2025 short papers). The exact definition, with the
 * parts that follow the paper and the parts clvis chose, is the docstring of
 * clvis/reference/raster/depth_filter.py; the kernels below compute it bit for bit.
 *
 * ABI
 * ---
 * Defines (optional):
 *   ITEMS   pixels per work-item (default 1): work-item g handles the pixels
 *           g*ITEMS .. g*ITEMS + ITEMS - 1 of its level in row-major order.
 *           Launch any one-dimensional global size >= ceil(pixels / ITEMS)
 *           (work-items past the end do nothing) and any local size.
 *
 * Images are float32 depth, row-major, row 0 on top; +INFINITY means "no
 * point". Level 0 is the input image (w0 x h0); level k (k >= 1) is
 * wk = ceil(w(k-1) / 2) by hk = ceil(h(k-1) / 2). Levels 1..L live one after
 * another in one float buffer `pyr`: level 1 at element offset 0, level k+1
 * at off(k) + wk * hk. Sizes are kernel arguments, so one build serves every
 * image size; offsets are in elements (floats), not bytes.
 *
 * Host sequence for L >= 1 levels (all on one in-order queue):
 *   1. depth_minpool(depth, 0, w0, h0, pyr, off(1), w1, h1), then for
 *      k = 2..L depth_minpool(pyr, off(k-1), w(k-1), h(k-1), pyr, off(k), wk, hk);
 *   2. for k = L down to 2: depth_refine(pyr, off(k-1), w(k-1), h(k-1),
 *      off(k), wk, hk, strength, edge_tau);
 *   3. depth_keep(depth, w0, h0, pyr, off(1), w1, h1, 1, strength, edge_tau,
 *      keep, bad).
 * For L = 0 only step 3, with has_coarse = 0 (pass any valid buffer as pyr).
 *
 * kernel depth_minpool(global const float *src, ulong src_off, uint sw, uint sh,
 *                      global float *dst, ulong dst_off, uint dw, uint dh)
 *     dst level pixel (x, y) = min of the src level pixels (2x+i, 2y+j),
 *     i, j in {0, 1}, that lie inside sw x sh (dw = ceil(sw/2), dh = ceil(sh/2)).
 *     src and dst may be the same buffer (different, non-overlapping levels).
 *     Pixels: dw * dh.
 *
 * kernel depth_refine(global float *pyr, ulong fine_off, uint fw, uint fh,
 *                     ulong coarse_off, uint cw, uint ch,
 *                     float strength, float edge_tau)
 *     In place on level k-1 (fw x fh at fine_off, k-1 >= 1) given the final
 *     level k (cw x ch at coarse_off): each fine pixel that is not kept (see
 *     below: empty, or background) takes its parent's value. Pixels: fw * fh.
 *
 * kernel depth_keep(global const float *depth, uint w, uint h,
 *                   global const float *pyr, ulong coarse_off, uint cw, uint ch,
 *                   uint has_coarse, float strength, float edge_tau,
 *                   global uchar *keep, global uint *bad)
 *     keep[y*w + x] = 1 if input pixel (x, y) holds a point that is kept, else
 *     0 (has_coarse = 0: kept = holds a point). Counts bad input values:
 *     bad[0] += NaNs, bad[1] += values < 0 (-INFINITY included); the host
 *     zeroes bad (2 uints) first. Pixels: w * h.
 *
 * kernel depth_rgbda(global const uchar *rgba, uint channels,
 *                    global const float *depth, global const uchar *keep,
 *                    ulong n, global float *out)
 *     n pixels; rgba: n * channels bytes (channels >= 3, the first three
 *     are r, g, b); out: n * 5 floats, pixel i at out[5i .. 5i+4] =
 *     {r, g, b, depth, alpha}: where keep[i] != 0, c * 0x1.010102p-8f (the
 *     float nearest 1/255) for each colour byte c, depth[i], 1.0f; elsewhere
 *     0, 0, 0, +INFINITY, 0. Pixels: n.
 *
 * kernel depth_kept(global const float *depth, global const uchar *keep,
 *                   ulong n, global float *depth_out,
 *                   global const uchar *rgba, uint channels,
 *                   global uchar *rgba_out)
 *     The planes depth_filter keeps, n pixels: depth_out[i] = depth[i] where
 *     keep[i] != 0, else +INFINITY; for channels > 0 also the colour bytes,
 *     rgba_out[channels*i + c] = rgba[channels*i + c] where keep[i] != 0,
 *     else 0 (channels = 0: no colour; pass any valid buffers). Pixels: n.
 *
 * Decision (depth_refine and depth_keep). Fine pixel q with value d, parent
 * p = (qx/2, qy/2) on the coarse level F, whose value is v:
 *   lap  = (((F[up] + F[down]) + F[left]) + F[right]) - v * 4.0f
 *          (a neighbour outside the level counts as v itself)
 *   edge = lap > edge_tau * v
 *   ref  = edge ? max of F over the 3x3 pixels around p inside the level : v
 *   kept = d < +INFINITY && d <= strength * ref
 * in float32, in exactly this order (FP_CONTRACT OFF: no fused multiply-add),
 * so results equal the NumPy reference (on devices that keep float32
 * denormals, CL_FP_DENORM; a device flushing them may decide differently for
 * depths below ~1e-38).
 *
 * Memory traffic: minpool 4 reads + 1 write per coarse pixel; refine and keep
 * 1 read + 1 write per fine pixel plus up to 14 (cached) parent reads.
 */
#pragma OPENCL FP_CONTRACT OFF

#ifndef ITEMS
#define ITEMS 1
#endif

#define AT(buf, off, w, x, y) ((buf)[(off) + (ulong)(y) * (w) + (x)])

static inline float min2(float a, float b) { return b < a ? b : a; }
static inline float max2(float a, float b) { return b > a ? b : a; }

/* The depth a fine pixel under coarse pixel (px, py) is compared with. */
static float parent_ref(global const float *c, const ulong off, const uint cw,
                        const uint ch, const uint px, const uint py, const float edge_tau)
{
    const float v = AT(c, off, cw, px, py);
    const float up = py > 0 ? AT(c, off, cw, px, py - 1) : v;
    const float down = py + 1 < ch ? AT(c, off, cw, px, py + 1) : v;
    const float left = px > 0 ? AT(c, off, cw, px - 1, py) : v;
    const float right = px + 1 < cw ? AT(c, off, cw, px + 1, py) : v;
    const float lap = (((up + down) + left) + right) - v * 4.0f;
    if (!(lap > edge_tau * v))
        return v;
    float m = v;
    const uint y0 = py > 0 ? py - 1 : 0, y1 = py + 1 < ch ? py + 1 : py;
    const uint x0 = px > 0 ? px - 1 : 0, x1 = px + 1 < cw ? px + 1 : px;
    for (uint y = y0; y <= y1; ++y)
        for (uint x = x0; x <= x1; ++x)
            m = max2(m, AT(c, off, cw, x, y));
    return m;
}

static inline int is_kept(const float d, const float ref, const float strength)
{
    return d < INFINITY && d <= strength * ref;
}

kernel void depth_minpool(global const float *src, const ulong src_off,
                          const uint sw, const uint sh,
                          global float *dst, const ulong dst_off,
                          const uint dw, const uint dh)
{
    const ulong n = (ulong)dw * dh;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    for (ulong i = first; i < n && i < first + ITEMS; ++i) {
        const uint y = (uint)(i / dw), x = (uint)(i - (ulong)y * dw);
        const uint sx = 2 * x, sy = 2 * y;
        float m = AT(src, src_off, sw, sx, sy);
        if (sx + 1 < sw)
            m = min2(m, AT(src, src_off, sw, sx + 1, sy));
        if (sy + 1 < sh) {
            m = min2(m, AT(src, src_off, sw, sx, sy + 1));
            if (sx + 1 < sw)
                m = min2(m, AT(src, src_off, sw, sx + 1, sy + 1));
        }
        AT(dst, dst_off, dw, x, y) = m;
    }
}

kernel void depth_refine(global float *pyr, const ulong fine_off,
                         const uint fw, const uint fh,
                         const ulong coarse_off, const uint cw, const uint ch,
                         const float strength, const float edge_tau)
{
    const ulong n = (ulong)fw * fh;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    for (ulong i = first; i < n && i < first + ITEMS; ++i) {
        const uint y = (uint)(i / fw), x = (uint)(i - (ulong)y * fw);
        const float d = pyr[fine_off + i];
        const float ref = parent_ref(pyr, coarse_off, cw, ch, x / 2, y / 2, edge_tau);
        if (!is_kept(d, ref, strength))
            pyr[fine_off + i] = AT(pyr, coarse_off, cw, x / 2, y / 2);
    }
}

kernel void depth_keep(global const float *depth, const uint w, const uint h,
                       global const float *pyr, const ulong coarse_off,
                       const uint cw, const uint ch, const uint has_coarse,
                       const float strength, const float edge_tau,
                       global uchar *keep, global uint *bad)
{
    const ulong n = (ulong)w * h;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    for (ulong i = first; i < n && i < first + ITEMS; ++i) {
        const float d = depth[i];
        if (isnan(d))
            atomic_inc(&bad[0]);
        else if (d < 0.0f)
            atomic_inc(&bad[1]);
        int k;
        if (has_coarse) {
            const uint y = (uint)(i / w), x = (uint)(i - (ulong)y * w);
            k = is_kept(d, parent_ref(pyr, coarse_off, cw, ch, x / 2, y / 2, edge_tau), strength);
        } else {
            k = d < INFINITY;
        }
        keep[i] = (uchar)k;
    }
}

kernel void depth_rgbda(global const uchar *rgba, const uint channels,
                        global const float *depth, global const uchar *keep,
                        const ulong n, global float *out)
{
    const float inv255 = 0x1.010102p-8f;    /* the float nearest 1/255 */
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    for (ulong i = first; i < n && i < first + ITEMS; ++i) {
        global float *o = out + 5 * i;
        if (keep[i]) {
            global const uchar *c = rgba + (ulong)channels * i;
            o[0] = (float)c[0] * inv255;
            o[1] = (float)c[1] * inv255;
            o[2] = (float)c[2] * inv255;
            o[3] = depth[i];
            o[4] = 1.0f;
        } else {
            o[0] = 0.0f;
            o[1] = 0.0f;
            o[2] = 0.0f;
            o[3] = INFINITY;
            o[4] = 0.0f;
        }
    }
}

kernel void depth_kept(global const float *depth, global const uchar *keep, const ulong n,
                       global float *depth_out, global const uchar *rgba, const uint channels,
                       global uchar *rgba_out)
{
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    for (ulong i = first; i < n && i < first + ITEMS; ++i) {
        const int kept = keep[i] != 0;
        depth_out[i] = kept ? depth[i] : INFINITY;
        for (uint c = 0; c < channels; ++c)
            rgba_out[(ulong)channels * i + c] = kept ? rgba[(ulong)channels * i + c] : (uchar)0;
    }
}
