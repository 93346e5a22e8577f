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
 *   WG            the local size hint (any; default 64). Launch any 1-D
 *                 global size >= the item count; items past it do nothing.
 * Build with -cl-fp32-correctly-rounded-divide-sqrt (block means divide).
 *
 * Tensors are (1, C, hp, wp) float32, channel c of pixel (x, y) at
 * [c*hp*wp + y*wp + x]; hp and wp are multiples of every scale s.
 * Scales: ks[2*i], ks[2*i + 1] = (k, s) for i < scales; k odd, s a power of
 * two; K = sum of k*k; candidate j counts scales in order, then dy, dx.
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
 *                  global const float *msk, global const int *ks, uint scales,
 *                  uint wp, uint hp, float depth_scale, float logit_bound,
 *                  global float *out)
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

/* candidate (oy, ox) blocks from pixel (x, y) at scale s: value and mask;
 * false beyond the block grid */
static bool kpn_candidate(global const float *planes, global const float *nearness,
                          global const float4 *blk, global const float *msk, uint wp, uint hp,
                          uint s, uint base, int x, int y, int oy, int ox, float4 *v, float *m)
{
    const int wb = (int)(wp / s), hb = (int)(hp / s);
    const int bx = x / (int)s + ox, by = y / (int)s + oy;
    if (bx < 0 || by < 0 || bx >= wb || by >= hb)
        return false;
    if (s == 1) {
        const size_t npix = (size_t)wp * hp, i = (size_t)by * wp + (size_t)bx;
        const float cov = planes[3 * npix + i];
        *v = (float4)(planes[i] * cov, planes[npix + i] * cov, planes[2 * npix + i] * cov, 0.0f);
#if DEPTH_SELECT
        v->w = nearness[i];
#endif
        *m = cov;
    } else {
        const size_t i = base + (size_t)by * wb + (size_t)bx;
        *v = blk[i];
        *m = msk[i];
    }
    return true;
}

kernel void kpn_apply(global const float *planes, global const float *nearness, global const float *logits,
                      global const float4 *blk, global const float *msk, global const int *ks, uint scales,
                      uint wp, uint hp, float depth_scale, float logit_bound, global float *out)
{
    const size_t npix = (size_t)wp * hp;
    const size_t idx = get_global_id(0);
    if (idx >= npix)
        return;
    const int x = (int)(idx % wp), y = (int)(idx / wp);
    uint kk = 0;
    for (uint i = 0; i < scales; ++i)
        kk += (uint)(ks[2 * i] * ks[2 * i]);
    const float inv_bound = 1.0f / logit_bound;
    float4 v;
    float m;

#if DEPTH_SELECT
    float ref = -INFINITY; /* the nearest in-grid candidate's nearness */
    {
        uint base = 0;
        for (uint i = 0; i < scales; ++i) {
            const int k = ks[2 * i];
            const uint s = (uint)ks[2 * i + 1];
            for (int dy = 0; dy < k; ++dy)
                for (int dx = 0; dx < k; ++dx)
                    if (kpn_candidate(planes, nearness, blk, msk, wp, hp, s, base, x, y, dy - k / 2, dx - k / 2,
                                      &v, &m))
                        ref = fmax(ref, v.w);
            if (s > 1)
                base += (hp / s) * (wp / s);
        }
    }
    const float g = logits[(size_t)(kk + 1) * npix + idx];
    const float gamma = (g > 20.0f ? g : log1p(exp(g))) * depth_scale;
#endif

    float3 acc = (float3)(0.0f);
    float total = 0.0f;
    uint j = 0, base = 0;
    for (uint i = 0; i < scales; ++i) {
        const int k = ks[2 * i];
        const uint s = (uint)ks[2 * i + 1];
        for (int dy = 0; dy < k; ++dy) {
            for (int dx = 0; dx < k; ++dx, ++j) {
                if (!kpn_candidate(planes, nearness, blk, msk, wp, hp, s, base, x, y, dy - k / 2, dx - k / 2,
                                   &v, &m) ||
                    m == 0.0f)
                    continue; /* masked out of the softmax: weight exactly 0 */
                float l = logit_bound * tanh(logits[(size_t)j * npix + idx] * inv_bound);
#if DEPTH_SELECT
                l += gamma * (v.w - ref);
#endif
                const float e = exp(l) * m;
                total += e;
                acc += e * v.xyz;
            }
        }
        if (s > 1)
            base += (hp / s) * (wp / s);
    }
    total += exp(logit_bound * tanh(logits[(size_t)kk * npix + idx] * inv_bound)); /* the background */
    const float3 c = clamp(acc / total, 0.0f, 1.0f);
    out[idx] = c.x;
    out[npix + idx] = c.y;
    out[2 * npix + idx] = c.z;
}
