/* kpn.cl — the NARVis kernel-prediction head (clvis.post.nets.NarvisKPN):
 * per output pixel, softmax weights over candidate input colours at a few
 * pyramid scales and one background (black) weight, from the network's
 * logits; the image is the weighted sum of the candidates' colours. The
 * definitions are the docstring of clvis/reference/post/kpn.py; results are
 * within float32 rounding of it (tanh, exp and the sums' order).
 *
 * ABI
 * ---
 * Defines:
 *   DEPTH_SELECT  0 or 1 (default 0): the candidates' logits get gamma x
 *                 their nearness behind the pixel's nearest candidate.
 *   KPN_SCALES    the number of scales, 1..8 (kpn_apply only; default 1).
 *   KPN_K<i>, KPN_S<i>  scale i's k (odd) and s (a power of two), i <
 *                 KPN_SCALES; KPN_CANDIDATES = K, the sum of their k*k.
 *                 Compile-time, so the candidate loops unroll and the
 *                 block arithmetic is shifts (kpn_blocks takes s as an
 *                 argument and needs none of them).
 *   WG            the local size hint (any; default 64). Launch any 1-D
 *                 global size >= the item count; items past it do nothing.
 * Build with -cl-fp32-correctly-rounded-divide-sqrt (block means divide).
 *
 * Tensors are (1, C, hp, wp) float32, channel c of pixel (x, y) at
 * [c*hp*wp + y*wp + x]; hp and wp are multiples of every scale s.
 * Candidate j counts the scales in order, then dy, dx (row-major).
 * A scale with s > 1 reads block planes written by kpn_blocks at `base` =
 * the sum of (hp/s')*(wp/s') over the earlier scales with s' > 1.
 *
 * kernel kpn_blocks(global const float *planes, global const float *nearness,
 *                   uint wp, uint hp, uint s, uint base,
 *                   global float4 *blk, global float *msk)
 *     One item per block of scale s (s > 1): (hp/s)*(wp/s) items, block
 *     (bx, by) = item % (wp/s), item / (wp/s). With cov = planes channel 3,
 *     p = (R*cov, G*cov, B*cov, nearness) (nearness read only with
 *     DEPTH_SELECT, else 0), n = mean cov over the block:
 *     blk[base + item] = mean(p) / max(n, 1e-12); msk[base + item] =
 *     min(4*s*s*n, 1).
 *
 * kernel kpn_apply(global const float *planes, global const float *nearness,
 *                  global const float *logits, global const float4 *blk,
 *                  global const float *msk, uint wp, uint hp, float depth_scale,
 *                  float logit_bound, global float *out)
 *     One item per pixel (hp*wp). logits: (1, K + 1 + DEPTH_SELECT, hp, wp);
 *     nearness: (1, 1, hp, wp) (not read without DEPTH_SELECT: any buffer);
 *     out: (1, 3, hp, wp), the clamped weighted sum of the candidates'
 *     colours. Scale s = 1 reads planes (and nearness) itself.
 *
 * Memory traffic: kpn_blocks reads each pixel's 4 (5) values once per
 * scale; kpn_apply reads K + 2 logits, 9 x (4 + 1) values a scale (mostly
 * cached) and writes 3 floats a pixel.
 */
#pragma OPENCL FP_CONTRACT OFF

#ifndef DEPTH_SELECT
#define DEPTH_SELECT 0
#endif
#ifndef KPN_SCALES
#define KPN_SCALES 1
#define KPN_K0 1
#define KPN_S0 1
#define KPN_CANDIDATES 1
#endif
/* the candidates rounded up to a multiple of 8 (the softmax's vector width) */
#define KPN_PADDED ((KPN_CANDIDATES + 7) / 8 * 8)

kernel void kpn_blocks(global const float *planes, global const float *nearness, uint wp, uint hp,
                       uint s, uint base, global float4 *blk, global float *msk)
{
    const uint wb = wp / s, hb = hp / s;
    const size_t item = get_global_id(0);
    if (item >= (size_t)wb * hb)
        return;
    const uint bx = (uint)(item % wb), by = (uint)(item / wb);
    const size_t npix = (size_t)wp * hp;
    float4 sum = (float4)(0.0f);
    float n = 0.0f;
    for (uint yy = 0; yy < s; ++yy) {
        const size_t row = (size_t)(by * s + yy) * wp + (size_t)bx * s;
        for (uint xx = 0; xx < s; ++xx) {
            const size_t i = row + xx;
            const float cov = planes[3 * npix + i];
            float4 p = (float4)(planes[i] * cov, planes[npix + i] * cov, planes[2 * npix + i] * cov, 0.0f);
#if DEPTH_SELECT
            p.w = nearness[i];
#endif
            sum += p;
            n += cov;
        }
    }
    const float area = (float)(s * s);
    const float mean = n / area;
    blk[base + item] = (sum / area) / fmax(mean, 1e-12f);
    msk[base + item] = fmin(mean * (4.0f * area), 1.0f);
}

/* candidate (oy, ox) of scale s from pixel (x, y): its value and mask, 0
 * (and *inside false) beyond the block grid; no branch on the data (the
 * index is clamped and the values zeroed), so work-items vectorize */
static inline float4 kpn_candidate(global const float *planes, global const float *nearness,
                                   global const float4 *blk, global const float *msk, const int wp,
                                   const int hp, const int s, const int base, const int x, const int y,
                                   const int oy, const int ox, float *m, bool *inside)
{
    const int wb = wp / s, hb = hp / s;
    const int bx = x / s + ox, by = y / s + oy;
    *inside = bx >= 0 && by >= 0 && bx < wb && by < hb;
    const int cx = clamp(bx, 0, wb - 1), cy = clamp(by, 0, hb - 1);
    float4 v;
    if (s == 1) { /* s is a compile-time constant at every call: no branch left */
        const size_t npix = (size_t)wp * hp, i = (size_t)cy * wp + cx;
        const float cov = planes[3 * npix + i];
        v = (float4)(planes[i] * cov, planes[npix + i] * cov, planes[2 * npix + i] * cov, 0.0f);
#if DEPTH_SELECT
        v.w = nearness[i];
#endif
        *m = cov;
    } else {
        const size_t i = (size_t)base + (size_t)cy * wb + cx;
        v = blk[i];
        *m = msk[i];
    }
    if (!*inside) {
        v = (float4)(0.0f);
        *m = 0.0f;
    }
    return v;
}

/* one scale's candidates' colours, nearness and masks into the pixel's
 * arrays at *j (counted on) */
static inline void kpn_scale(global const float *planes, global const float *nearness, global const float4 *blk,
                             global const float *msk, const int wp, const int hp, const int k, const int s,
                             const int base, const int x, const int y, int *j, float *cr, float *cg, float *cb,
                             float *cn, float *cm)
{
    for (int dy = 0; dy < k; ++dy)
        for (int dx = 0; dx < k; ++dx, ++*j) {
            bool inside;
            const float4 v = kpn_candidate(planes, nearness, blk, msk, wp, hp, s, base, x, y, dy - k / 2,
                                           dx - k / 2, cm + *j, &inside);
            cr[*j] = v.x;
            cg[*j] = v.y;
            cb[*j] = v.z;
            cn[*j] = inside ? v.w : -INFINITY; /* out of the nearest's max; mask 0 */
        }
}

/* the scales as compile-time constants: KPN_K<i>, KPN_S<i> for i < KPN_SCALES */
#define KPN_BASE_AFTER(b, i) ((b) + (KPN_S##i > 1 ? (hp / KPN_S##i) * (wp / KPN_S##i) : 0))

kernel void kpn_apply(global const float *planes, global const float *nearness, global const float *logits,
                      global const float4 *blk, global const float *msk, uint wpu, uint hpu, float depth_scale,
                      float bound, global float *out)
{
    const int wp = (int)wpu, hp = (int)hpu;
    const size_t npix = (size_t)wp * hp;
    const size_t idx = get_global_id(0);
    if (idx >= npix)
        return;
    const int x = (int)(idx % wpu), y = (int)(idx / wpu);
    const float inv_bound = 1.0f / bound;
    /* block-plane bases: the earlier s > 1 scales' block counts */
    const int b0 = 0;
    const int b1 = KPN_BASE_AFTER(b0, 0);
#if KPN_SCALES > 1
    const int b2 = KPN_BASE_AFTER(b1, 1);
#endif
#if KPN_SCALES > 2
    const int b3 = KPN_BASE_AFTER(b2, 2);
#endif
#if KPN_SCALES > 3
    const int b4 = KPN_BASE_AFTER(b3, 3);
#endif
#if KPN_SCALES > 4
    const int b5 = KPN_BASE_AFTER(b4, 4);
#endif
#if KPN_SCALES > 5
    const int b6 = KPN_BASE_AFTER(b5, 5);
#endif
#if KPN_SCALES > 6
    const int b7 = KPN_BASE_AFTER(b6, 6);
#endif
    (void)b1;

    /* the candidates gathered, then the softmax 8 at a time (vector tanh
     * and exp); the tail past K has mask 0 */
    float cr[KPN_PADDED], cg[KPN_PADDED], cb[KPN_PADDED], cn[KPN_PADDED], cm[KPN_PADDED], lg[KPN_PADDED];
    int j = 0;
#define KPN_SCALE(i)                                                                                              \
    kpn_scale(planes, nearness, blk, msk, wp, hp, KPN_K##i, KPN_S##i, b##i, x, y, &j, cr, cg, cb, cn, cm)
    KPN_SCALE(0);
#if KPN_SCALES > 1
    KPN_SCALE(1);
#endif
#if KPN_SCALES > 2
    KPN_SCALE(2);
#endif
#if KPN_SCALES > 3
    KPN_SCALE(3);
#endif
#if KPN_SCALES > 4
    KPN_SCALE(4);
#endif
#if KPN_SCALES > 5
    KPN_SCALE(5);
#endif
#if KPN_SCALES > 6
    KPN_SCALE(6);
#endif
#if KPN_SCALES > 7
    KPN_SCALE(7);
#endif
    for (int i = 0; i < KPN_PADDED; ++i) {
        const bool real = i < KPN_CANDIDATES;
        lg[i] = real ? logits[(size_t)i * npix + idx] : 0.0f;
        if (!real) {
            cr[i] = cg[i] = cb[i] = cm[i] = 0.0f;
            cn[i] = -INFINITY;
        }
    }
    float ref = 0.0f, gamma = 0.0f;
#if DEPTH_SELECT
    ref = -INFINITY; /* the nearest in-grid candidate's nearness (-INFINITY beyond the grid) */
    for (int i = 0; i < KPN_CANDIDATES; ++i)
        ref = fmax(ref, cn[i]);
    const float g = logits[(size_t)(KPN_CANDIDATES + 1) * npix + idx];
    gamma = (g > 20.0f ? g : log1p(exp(g))) * depth_scale;
#endif
    float8 tot8 = (float8)(0.0f), r8 = (float8)(0.0f), g8 = (float8)(0.0f), b8 = (float8)(0.0f);
    for (int i = 0; i < KPN_PADDED; i += 8) {
        float8 l = bound * tanh(vload8(0, lg + i) * inv_bound);
#if DEPTH_SELECT
        l += gamma * fmax(vload8(0, cn + i) - ref, -1.0f); /* beyond the grid: masked */
#endif
        const float8 e = exp(l) * vload8(0, cm + i); /* masked: exactly 0 */
        tot8 += e;
        r8 += e * vload8(0, cr + i);
        g8 += e * vload8(0, cg + i);
        b8 += e * vload8(0, cb + i);
    }
#define KPN_SUM8(v) ((((v).s0 + (v).s1) + ((v).s2 + (v).s3)) + (((v).s4 + (v).s5) + ((v).s6 + (v).s7)))
    float total = KPN_SUM8(tot8);
    const float3 acc = (float3)(KPN_SUM8(r8), KPN_SUM8(g8), KPN_SUM8(b8));
    total += exp(bound * tanh(logits[(size_t)KPN_CANDIDATES * npix + idx] * inv_bound)); /* the background */
    const float3 c = clamp(acc / total, 0.0f, 1.0f);
    out[idx] = c.x;
    out[npix + idx] = c.y;
    out[2 * npix + idx] = c.z;
}
