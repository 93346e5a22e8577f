/* pushpull.cl — push-pull hole fill of a multi-channel image (the classical
 * baseline of the post family's in-fill networks). The definition is the
 * docstring of clvis/reference/post/pushpull.py; the kernels below repeat its
 * float32 operations in the same order.
 *
 * ABI
 * ---
 * Defines (optional):
 *   ITEMS   pixels per work-item (default 1): work-item g handles the pixels
 *           g*ITEMS .. g*ITEMS + ITEMS - 1 of its level in row-major order.
 *           Launch any one-dimensional global size >= ceil(pixels / ITEMS)
 *           (work-items past the end do nothing) and any local size.
 * Build with -cl-fp32-correctly-rounded-divide-sqrt (the reference divides
 * in IEEE float32); the file sets FP_CONTRACT OFF itself.
 *
 * Images are row-major, row 0 on top, C = `channels` (1..8) float32 values
 * per pixel, interleaved: pixel i's channel c at [i*C + c]. Level 0 is the
 * input `image` (w0 x h0) with `valid` (w0*h0 uchars, nonzero = known). Level
 * k (k >= 1) is wk = ceil(w(k-1) / 2) by hk = ceil(h(k-1) / 2) pixels. Levels
 * 1..L live one after another in two buffers: weights `wt` (one float per
 * pixel; level 1 at offset 0, level k+1 at off(k+1) = off(k) + wk*hk) and
 * colours `col` (C floats per pixel, level k at element offset off(k) * C).
 * Offsets below are pixel offsets (off(k)), in elements, not bytes.
 *
 * Host sequence for L >= 1 levels (one in-order queue):
 *   1. pp_push0(image, valid, w0, h0, C, col, wt, w1, h1), then for
 *      k = 2..L pp_push(col, wt, C, off(k-1), w(k-1), h(k-1), off(k), wk, hk);
 *   2. for k = L-1 down to 1: pp_pull(col, wt, C, off(k), wk, hk, off(k+1),
 *      w(k+1), h(k+1));
 *   3. pp_output(image, valid, w0, h0, C, col, w1, h1, 1, out, bad).
 * For L = 0 only step 3 with has_coarse = 0 (pass any valid buffer as col).
 *
 * kernel pp_push0(global const float *image, global const uchar *valid,
 *                 uint w, uint h, uint channels,
 *                 global float *col, global float *wt, uint cw, uint ch)
 *     Level 1 (at offset 0) from level 0: push() below with child weight 1
 *     where valid, else 0 (a hole's value, maybe NaN, is never read).
 *     Pixels: cw * ch.
 *
 * kernel pp_push(global float *col, global float *wt, uint channels,
 *                ulong src_off, uint sw, uint sh,
 *                ulong dst_off, uint dw, uint dh)
 *     Level k+1 (dw x dh at dst_off) from level k (sw x sh at src_off), both
 *     in the pyramid buffers. Pixels: dw * dh.
 *
 * kernel pp_pull(global float *col, global const float *wt, uint channels,
 *                ulong fine_off, uint fw, uint fh,
 *                ulong coarse_off, uint cw, uint ch)
 *     In place on level k (fine, k >= 1) given the final level k+1 (coarse):
 *     c = w*c + (1-w)*bilerp(coarse). Pixels: fw * fh.
 *
 * kernel pp_output(global const float *image, global const uchar *valid,
 *                  uint w, uint h, uint channels,
 *                  global const float *col, uint cw, uint ch, uint has_coarse,
 *                  global float *out, global uint *bad)
 *     out (w*h*C floats): the image where valid, elsewhere bilerp(level 1)
 *     (0 when has_coarse = 0). bad[0] += the number of non-finite values at
 *     valid pixels; the host zeroes bad (1 uint) first. Pixels: w * h.
 *
 * push (one coarse pixel (x, y)): its children are the fine pixels
 * (2x+i, 2y+j), taken in the order (i, j) = (0,0), (1,0), (0,1), (1,1) and
 * only where inside the fine level;
 *     wsum = ((w0 + w1) + w2) + w3,  csum = ((w0*c0 + w1*c1) + w2*c2) + w3*c3,
 *     weight = min(1, wsum),  colour = wsum > 0 ? csum / wsum : 0.
 * bilerp (fine pixel (x, y) from the coarse level cw x ch):
 *     gx = clamp(x*0.5f - 0.25f, 0, cw-1), x0 = floor(gx),
 *     x1 = min(x0+1, cw-1), fx = gx - x0 (likewise y), and
 *     ((1-fy) * ((1-fx)*c00 + fx*c10)) + (fy * ((1-fx)*c01 + fx*c11)),
 *     with cXY the coarse pixel (xX, yY).
 *
 * Memory traffic: push 4 (C+1) reads + (C+1) writes per coarse pixel; pull
 * and output 4C (cached) coarse reads + (C+1) reads + C writes per pixel.
 */
#pragma OPENCL FP_CONTRACT OFF

#ifndef ITEMS
#define ITEMS 1
#endif

/* The coarse estimate of channel c at fine pixel (x, y). */
static float bilerp(global const float *col, const ulong off, const uint cw, const uint ch,
                    const uint channels, const uint c, const uint x, const uint y)
{
    const float gx = clamp((float)x * 0.5f - 0.25f, 0.0f, (float)(cw - 1));
    const float gy = clamp((float)y * 0.5f - 0.25f, 0.0f, (float)(ch - 1));
    const uint x0 = (uint)gx, y0 = (uint)gy;    /* gx, gy >= 0: truncation = floor */
    const uint x1 = min(x0 + 1, cw - 1), y1 = min(y0 + 1, ch - 1);
    const float fx = gx - (float)x0, fy = gy - (float)y0;
    global const float *p = col + off * channels + c;
    const float c00 = p[((ulong)y0 * cw + x0) * channels];
    const float c10 = p[((ulong)y0 * cw + x1) * channels];
    const float c01 = p[((ulong)y1 * cw + x0) * channels];
    const float c11 = p[((ulong)y1 * cw + x1) * channels];
    const float top = (1.0f - fx) * c00 + fx * c10;
    const float bottom = (1.0f - fx) * c01 + fx * c11;
    return (1.0f - fy) * top + fy * bottom;
}

/* Writes the coarse pixel `d` from its children: `cwts` their weights,
 * `cidx` their pixel indices in `src` (n of them, in push order). */
static void push(global const float *src, const uint channels, const uint n,
                 const float *cwts, const ulong *cidx,
                 global float *dcol, global float *dwt, const ulong d)
{
    float wsum = cwts[0];
    for (uint k = 1; k < n; ++k)
        wsum = wsum + cwts[k];
    dwt[d] = min(1.0f, wsum);
    for (uint c = 0; c < channels; ++c) {
        float csum = 0.0f;
        if (wsum > 0.0f) {
            csum = cwts[0] * src[cidx[0] * channels + c];
            for (uint k = 1; k < n; ++k)
                csum = csum + cwts[k] * src[cidx[k] * channels + c];
            csum = csum / wsum;
        }
        dcol[d * channels + c] = csum;
    }
}

/* The children of coarse pixel (x, y) inside a sw x sh level, in push order. */
static uint children(const uint x, const uint y, const uint sw, const uint sh, ulong *cidx)
{
    const uint sx = 2 * x, sy = 2 * y;
    uint n = 0;
    cidx[n++] = (ulong)sy * sw + sx;
    if (sx + 1 < sw)
        cidx[n++] = (ulong)sy * sw + sx + 1;
    if (sy + 1 < sh) {
        cidx[n++] = (ulong)(sy + 1) * sw + sx;
        if (sx + 1 < sw)
            cidx[n++] = (ulong)(sy + 1) * sw + sx + 1;
    }
    return n;
}

kernel void pp_push0(global const float *image, global const uchar *valid,
                     const uint w, const uint h, const uint channels,
                     global float *col, global float *wt, const uint cw, const uint ch)
{
    const ulong n = (ulong)cw * ch;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    for (ulong i = first; i < n && i < first + ITEMS; ++i) {
        const uint y = (uint)(i / cw), x = (uint)(i - (ulong)y * cw);
        ulong cidx[4], kept[4];
        float cwts[4];
        const uint m = children(x, y, w, h, cidx);
        uint nk = 0;
        for (uint k = 0; k < m; ++k)
            if (valid[cidx[k]]) {       /* a hole adds weight 0: skipped, its value unread */
                kept[nk] = cidx[k];
                cwts[nk++] = 1.0f;
            }
        if (nk == 0) {
            wt[i] = 0.0f;
            for (uint c = 0; c < channels; ++c)
                col[i * channels + c] = 0.0f;
        } else {
            push(image, channels, nk, cwts, kept, col, wt, i);
        }
    }
}

kernel void pp_push(global float *col, global float *wt, const uint channels,
                    const ulong src_off, const uint sw, const uint sh,
                    const ulong dst_off, const uint dw, const uint dh)
{
    const ulong n = (ulong)dw * dh;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    for (ulong i = first; i < n && i < first + ITEMS; ++i) {
        const uint y = (uint)(i / dw), x = (uint)(i - (ulong)y * dw);
        ulong cidx[4];
        float cwts[4];
        const uint m = children(x, y, sw, sh, cidx);
        for (uint k = 0; k < m; ++k)
            cwts[k] = wt[src_off + cidx[k]];
        push(col + src_off * channels, channels, m, cwts, cidx, col + dst_off * channels,
             wt + dst_off, i);
    }
}

kernel void pp_pull(global float *col, global const float *wt, const uint channels,
                    const ulong fine_off, const uint fw, const uint fh,
                    const ulong coarse_off, const uint cw, const uint ch)
{
    const ulong n = (ulong)fw * fh;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    for (ulong i = first; i < n && i < first + ITEMS; ++i) {
        const uint y = (uint)(i / fw), x = (uint)(i - (ulong)y * fw);
        const float w = wt[fine_off + i];
        global float *p = col + (fine_off + i) * channels;
        for (uint c = 0; c < channels; ++c) {
            const float est = bilerp(col, coarse_off, cw, ch, channels, c, x, y);
            p[c] = w * p[c] + (1.0f - w) * est;
        }
    }
}

kernel void pp_output(global const float *image, global const uchar *valid,
                      const uint w, const uint h, const uint channels,
                      global const float *col, const uint cw, const uint ch,
                      const uint has_coarse, global float *out, global uint *bad)
{
    const ulong n = (ulong)w * h;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    for (ulong i = first; i < n && i < first + ITEMS; ++i) {
        const uint y = (uint)(i / w), x = (uint)(i - (ulong)y * w);
        global const float *src = image + i * channels;
        global float *dst = out + i * channels;
        if (valid[i]) {
            uint nonfinite = 0;
            for (uint c = 0; c < channels; ++c) {
                const float v = src[c];
                nonfinite += !isfinite(v);
                dst[c] = v;
            }
            if (nonfinite)
                atomic_add(&bad[0], nonfinite);
        } else {
            for (uint c = 0; c < channels; ++c)
                dst[c] = has_coarse ? bilerp(col, 0, cw, ch, channels, c, x, y) : 0.0f;
        }
    }
}
