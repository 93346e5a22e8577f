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
 *   KPN_SCALES    the number of scales, 1..8 (kpn_apply only).
 *   KPN_K<i>, KPN_S<i>  scale i's k (odd) and s (a power of two), for
 *                 every i < KPN_SCALES.
 *   KPN_CANDIDATES  K, the sum of the scales' k*k (the logits' candidate
 *                 channels; the background's is channel K).
 *                 With KPN_SCALES defined, every KPN_K<i>, KPN_S<i> and
 *                 KPN_CANDIDATES must be defined too (the file computes
 *                 none of them: a missing one fails the build); without
 *                 KPN_SCALES the file sets one scale, KPN_K0 = KPN_S0 =
 *                 KPN_CANDIDATES = 1. Compile-time, so the candidate loops
 *                 unroll and the block arithmetic is shifts (kpn_blocks
 *                 takes s as an argument and needs none of them).
 *                 Example, scales (k, s) = (3, 1), (5, 4): -DKPN_SCALES=2
 *                 -DKPN_K0=3 -DKPN_S0=1 -DKPN_K1=5 -DKPN_S1=4
 *                 -DKPN_CANDIDATES=34.
 * Launch sizes: any 1-D global size >= the kernel's item count (below);
 * items past it do nothing; any local size (clvis: 64; a WG define that
 * clvis passes is not read by the kernels).
 * wp must be a multiple of 8 (the networks' strides are 16).
 * Build with -cl-fp32-correctly-rounded-divide-sqrt (block means divide).
 *
 * Tensors are (1, C, hp, wp) float32, channel c of pixel (x, y) at
 * [c*hp*wp + y*wp + x]; hp and wp are multiples of every scale s.
 * Candidate j counts the scales in order, then dy, dx (row-major).
 *
 * kernel kpn_blocks(global const float *planes, global const float *nearness,
 *                   uint wp, uint hp, uint s, uint scale, global float *up)
 *     One item per block of scale s: (hp/s)*(wp/s) items, block (bx, by) =
 *     item % (wp/s), item / (wp/s). With cov = planes channel 3, p = (R*cov,
 *     G*cov, B*cov, nearness) (nearness read only with DEPTH_SELECT, else 0),
 *     n = mean cov over the block: value = mean(p) / max(n, 1e-12) and mask
 *     = min(4*s*s*n, 1) for s > 1, p and cov themselves for s = 1, written
 *     to every pixel of the block in the up-sampled planes of this scale:
 *     up[(scale*5 + c)*hp*wp + pixel], c = R, G, B, nearness, mask.
 *
 * kernel kpn_apply(global const float *up, global const float *logits,
 *                  uint wpu, uint hpu, float depth_scale, float bound,
 *                  global float *out)
 *     wpu, hpu: wp, hp; bound: the logit bound B, l = B tanh(logit / B)
 *     (> 0); depth_scale: gamma's factor (DEPTH_SELECT only, else unread).
 *     up: kpn_blocks' planes of all KPN_SCALES scales (5 * KPN_SCALES *
 *     hp*wp floats; with DEPTH_SELECT 0 the nearness planes are not read).
 *     One item per 8 pixels of a row (hp*wp/8 items; wp a multiple of 8):
 *     lanes are pixels, so every candidate is a vload8 of the up-sampled
 *     planes (row y + (dy - k/2)*s, columns x + (dx - k/2)*s; beyond the
 *     image: weight 0). logits: (1, K + 1 + DEPTH_SELECT, hp, wp); out: (1,
 *     3, hp, wp), the clamped weighted sum of the candidates' colours.
 *
 * Memory traffic: kpn_blocks reads each pixel's 4 (5) values and writes 5
 * per scale; kpn_apply reads K + 2 logits, k*k x 5 up-sampled values a scale
 * (rows shared with the neighbours, cached) and writes 3 floats a pixel.
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

kernel void kpn_blocks(global const float *planes, global const float *nearness, uint wp, uint hp, uint s,
                       uint scale, global float *up)
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
    float4 v;
    float m;
    if (s == 1) { /* the pixel itself, its coverage the mask */
        v = sum;
        m = n;
    } else {
        const float area = (float)(s * s);
        const float mean = n / area;
        v = (sum / area) / fmax(mean, 1e-12f);
        m = fmin(mean * (4.0f * area), 1.0f);
    }
    global float *u = up + (size_t)scale * 5 * npix;
    for (uint yy = 0; yy < s; ++yy) {
        const size_t row = (size_t)(by * s + yy) * wp + (size_t)bx * s;
        for (uint xx = 0; xx < s; ++xx) {
            const size_t i = row + xx;
            u[i] = v.x;
            u[npix + i] = v.y;
            u[2 * npix + i] = v.z;
            u[3 * npix + i] = v.w;
            u[4 * npix + i] = m;
        }
    }
}

/* plane c of the up-sampled planes u at row `row`, the 8 columns x0 + ox ..
 * x0 + ox + 7; columns beyond the image read `outside` */
static inline float8 kpn_row8(global const float *u, const int wp, const size_t row, const int x0, const int ox,
                              const float outside)
{
    const int c0 = x0 + ox;
    if (c0 >= 0 && c0 + 7 < wp)
        return vload8(0, u + row + c0);
    float lanes[8];
    for (int l = 0; l < 8; ++l) {
        const int c = c0 + l;
        lanes[l] = c >= 0 && c < wp ? u[row + c] : outside;
    }
    return vload8(0, lanes);
}

/* one scale's candidates: pass 0 maxes their nearness into *ref, pass 1
 * adds them to the softmax's sums; *j counts the logits */
static inline void kpn_scale(global const float *up, global const float *logits, const int wp, const int hp,
                             const int k, const int s, const int scale, const int x0, const int y, const int pass,
                             const float8 ref, const float8 gamma, const float bound, const float inv_bound,
                             int *j, float8 *near, float8 *total, float8 *r, float8 *g, float8 *b)
{
    const size_t npix = (size_t)wp * hp;
    global const float *u = up + (size_t)scale * 5 * npix;
    for (int dy = 0; dy < k; ++dy) {
        const int yy = y + (dy - k / 2) * s;
        const bool row_in = yy >= 0 && yy < hp;
        const size_t row = (size_t)(row_in ? yy : 0) * wp;
        for (int dx = 0; dx < k; ++dx, ++*j) {
            if (!row_in)
                continue; /* the whole row of candidates beyond the grid: weight 0 */
            const int ox = (dx - k / 2) * s;
            if (pass == 0) {
#if DEPTH_SELECT
                *near = fmax(*near, kpn_row8(u + 3 * npix, wp, row, x0, ox, -INFINITY));
#endif
                continue;
            }
            const float8 m = kpn_row8(u + 4 * npix, wp, row, x0, ox, 0.0f);
            float8 l = bound * tanh(vload8(0, logits + (size_t)*j * npix + row - (size_t)(yy - y) * wp + x0) *
                                    inv_bound);
#if DEPTH_SELECT
            l += gamma * fmax(kpn_row8(u + 3 * npix, wp, row, x0, ox, 0.0f) - ref, -1.0f);
#endif
            const float8 e = exp(l) * m; /* masked or beyond the grid: exactly 0 */
            *total += e;
            *r += e * kpn_row8(u, wp, row, x0, ox, 0.0f);
            *g += e * kpn_row8(u + npix, wp, row, x0, ox, 0.0f);
            *b += e * kpn_row8(u + 2 * npix, wp, row, x0, ox, 0.0f);
        }
    }
}

#define KPN_ALL_SCALES(PASS)                                                                                      \
    do {                                                                                                          \
        int j = 0;                                                                                                \
        KPN_ONE(0, PASS);                                                                                         \
        KPN_MORE(PASS)                                                                                            \
    } while (0)
#define KPN_ONE(i, PASS)                                                                                          \
    kpn_scale(up, logits, wp, hp, KPN_K##i, KPN_S##i, i, x0, y, PASS, ref, gamma, bound, inv_bound, &j, &near,     \
              &total, &r, &g, &b)
#if KPN_SCALES == 1
#define KPN_MORE(PASS)
#elif KPN_SCALES == 2
#define KPN_MORE(PASS) KPN_ONE(1, PASS);
#elif KPN_SCALES == 3
#define KPN_MORE(PASS) KPN_ONE(1, PASS); KPN_ONE(2, PASS);
#elif KPN_SCALES == 4
#define KPN_MORE(PASS) KPN_ONE(1, PASS); KPN_ONE(2, PASS); KPN_ONE(3, PASS);
#elif KPN_SCALES == 5
#define KPN_MORE(PASS) KPN_ONE(1, PASS); KPN_ONE(2, PASS); KPN_ONE(3, PASS); KPN_ONE(4, PASS);
#elif KPN_SCALES == 6
#define KPN_MORE(PASS) KPN_ONE(1, PASS); KPN_ONE(2, PASS); KPN_ONE(3, PASS); KPN_ONE(4, PASS); KPN_ONE(5, PASS);
#elif KPN_SCALES == 7
#define KPN_MORE(PASS)                                                                                            \
    KPN_ONE(1, PASS); KPN_ONE(2, PASS); KPN_ONE(3, PASS); KPN_ONE(4, PASS); KPN_ONE(5, PASS); KPN_ONE(6, PASS);
#else
#define KPN_MORE(PASS)                                                                                            \
    KPN_ONE(1, PASS); KPN_ONE(2, PASS); KPN_ONE(3, PASS); KPN_ONE(4, PASS); KPN_ONE(5, PASS); KPN_ONE(6, PASS);   \
    KPN_ONE(7, PASS);
#endif

kernel void kpn_apply(global const float *up, global const float *logits, uint wpu, uint hpu, float depth_scale,
                      float bound, global float *out)
{
    const int wp = (int)wpu, hp = (int)hpu;
    const size_t npix = (size_t)wp * hp;
    const size_t item = get_global_id(0);
    if (item >= npix / 8)
        return;
    const int x0 = (int)(item % (wpu / 8)) * 8, y = (int)(item / (wpu / 8));
    const size_t idx = (size_t)y * wp + x0;
    const float inv_bound = 1.0f / bound;
    float8 near = (float8)(-INFINITY), total = (float8)(0.0f), r = (float8)(0.0f), g = (float8)(0.0f),
           b = (float8)(0.0f);
    float8 ref = (float8)(0.0f), gamma = (float8)(0.0f);
#if DEPTH_SELECT
    KPN_ALL_SCALES(0);
    ref = near; /* the nearest in-grid candidate's nearness */
    const float8 gl = vload8(0, logits + (size_t)(KPN_CANDIDATES + 1) * npix + idx);
    gamma = select(log1p(exp(gl)), gl, gl > 20.0f) * depth_scale;
#endif
    KPN_ALL_SCALES(1);
    total += exp(bound * tanh(vload8(0, logits + (size_t)KPN_CANDIDATES * npix + idx) * inv_bound));
    vstore8(clamp(r / total, 0.0f, 1.0f), 0, out + idx);
    vstore8(clamp(g / total, 0.0f, 1.0f), 0, out + npix + idx);
    vstore8(clamp(b / total, 0.0f, 1.0f), 0, out + 2 * npix + idx);
}
