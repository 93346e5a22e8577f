/* pack.cl — images to and from the NCHW float32 tensors of the post family's
 * networks (batch 1), for ONNX Runtime. The definitions are the docstrings of
 * clvis/reference/post/pack.py; the kernels give its results bit for bit.
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/keys.h).
 * Defines (optional):
 *   ITEMS   pixels per work-item (default 1): work-item g handles the pixels
 *           g*ITEMS .. g*ITEMS + ITEMS - 1 in row-major order. Launch any
 *           one-dimensional global size >= ceil(pixels / ITEMS) (work-items
 *           past the end do nothing).
 *   WG      the local size (a power of two, default 1): rgbda_range must be
 *           launched with exactly this local size; the other kernels take any.
 * Build with -cl-fp32-correctly-rounded-divide-sqrt (pack_rgbda divides; the
 * reference divides in IEEE float32); the file sets FP_CONTRACT OFF itself.
 *
 * Images are row-major, row 0 on top, w x h pixels, channels interleaved.
 * A tensor is (1, C, hp, wp) float32 with hp >= h, wp >= w: channel c of
 * pixel (x, y) at [c*hp*wp + y*wp + x]. Pixels with x >= w or y >= h are
 * padding. The in-fill kernels (pack_iso, pack_count, pack_prior,
 * pack_depth) write it as finished rays that missed (0 in every channel).
 * The LiDAR and NARVis kernels (pack_rgbda, pack_rgb_coverage, pack_plane)
 * pack it as the image pixel (mirror(x, w), mirror(y, h)): the image
 * reflected about its last column and row (numpy.pad's "symmetric" mode:
 * ... n-1 | n-1 n-2 ..., with period 2n), so the network sees the scan go on
 * past its edge, not an empty band (which no network saw in training; the
 * LiDAR U-Net painted the last rows dark). Kernels over a tensor run one
 * item per tensor pixel (hp*wp).
 *
 * kernel pack_iso(global const float *rgba, global const uchar *hit,
 *                 global const uchar *active, uint w, uint h, uint wp, uint hp,
 *                 global float *out, global uint *bad)
 *     rgba: w*h*4 floats; hit, active: w*h uchars (nonzero = true). out:
 *     (1, 5, hp, wp) = R, G, B, HIT, ACTIVE. With shown = hit && !active:
 *     R, G, B = rgba's r, g, b where shown, else 0; HIT = shown ? 1 : 0;
 *     ACTIVE = active ? 1 : 0. Padding: all 0. bad[0] += the number of hit
 *     pixels whose r, g or b is not finite (the host zeroes it first).
 *
 * kernel pack_count(global const uchar *count, global const uchar *active, uint cap,
 *                   uint w, uint h, uint wp, uint hp, uint channel, global float *out)
 *     One more channel of pack_iso's tensor (the in-fill network with a
 *     candidates plane): out[channel] at pixel (x, y) = (float)min(count,
 *     cap) / (float)cap where active (count: w*h uchars, the candidate
 *     blocks left on the running ray, clvis.iso.IsoImage.candidates), else
 *     0; padding 0. cap >= 1. Other channels are not touched.
 *
 * kernel pack_prior(global const uchar *count, global const uchar *active, float miss,
 *                   uint cap, uint w, uint h, uint wp, uint hp, uint channel,
 *                   global float *out)
 *     One more channel (the in-fill network with a hit-prior plane): out[channel]
 *     at pixel (x, y) = 1 - miss^k where active, k = min(count, cap), the power
 *     taken as k float32 products 1 * miss * miss ... in order (miss: 1 - the
 *     frame's crossing rate, in [0, 1]); else 0; padding 0. Other channels are
 *     not touched.
 *
 * kernel iso_depth_range(global const float *t, global const float *next_t,
 *                         global const uchar *hit, global const uchar *active,
 *                         ulong n, global uint *stats)
 *     The depth range of an iso image (n pixels): its values are t[i] where
 *     hit && !active (a finished hit's ray parameter, an IsoImage's t)
 *     and next_t[i] where active (where a running ray's next candidate block
 *     begins, IsoImage.next_t), the finite ones only. stats (2 uints, zeroed
 *     by the host): stats[0] = max(stats[0], key(v)), stats[1] =
 *     max(stats[1], ~key(v)) over them, key() clvis_key_f32 (0: no value).
 *     Global size: a multiple of WG >= ceil(n / ITEMS); local size WG.
 *
 * kernel pack_depth(global const float *t, global const float *next_t,
 *                   global const uchar *hit, global const uchar *active,
 *                   uint w, uint h, uint wp, uint hp, uint channel,
 *                   global const uint *stats, global float *out)
 *     Two more channels of pack_iso's tensor (the in-fill network with depth
 *     planes): with lo, hi the extremes decoded from iso_depth_range's stats
 *     (on the same planes) and range = hi - lo, out[channel] = (t - lo) /
 *     range where hit && !active and t is finite, out[channel + 1] =
 *     (next_t - lo) / range where active and next_t is finite; 0 elsewhere,
 *     at padding, and everywhere when range is not > 0. Other channels are
 *     not touched.
 *
 * kernel rgbda_range(global const float *rgbda, ulong n, global uint *stats)
 *     rgbda: n pixels of 5 floats {r, g, b, depth, alpha}. Adds to stats
 *     (4 uints, zeroed by the host):
 *       stats[0] += NaN values (any of the 5 channels),
 *       stats[1] += pixels with alpha > 0 and depth == -INFINITY,
 *       stats[2] = max(stats[2], key(depth)) over kept pixels,
 *       stats[3] = max(stats[3], ~key(depth)) over kept pixels,
 *     where kept = alpha > 0 && isfinite(depth) and key() is clvis_key_f32
 *     (clvis/keys.h; never 0 or ~0 for a finite value, so 0 means "none").
 *     Global size: a multiple of WG >= ceil(n / ITEMS); local size WG.
 *
 * kernel pack_rgbda(global const float *rgbda, uint w, uint h, uint wp,
 *                   uint hp, global const uint *stats, global float *out)
 *     out: (1, 5, hp, wp) = R, G, B, A, D. At kept pixels: r, g, b, alpha as
 *     given and D = range > 0 ? (depth - dmin) / range : 0, range = dmax -
 *     dmin, dmin and dmax the kept depths' extremes decoded from stats[3]
 *     and stats[2] (rgbda_range's, on the same rgbda). Elsewhere (not kept,
 *     padding, as its mirrored pixel): R = G = B = A = 0, D = -1.
 *
 * kernel pack_rgb_coverage(global const uchar *rgba, global const uint *index,
 *                           uint w, uint h, uint wp, uint hp, global float *out)
 *     The NARVis U-Net's first 4 channels from rasterizer G-buffers: rgba
 *     w*h*4 uchars, index w*h uints (0xFFFFFFFF = empty). out: (1, C, hp, wp)
 *     with C >= 4; channels 0..3 = R, G, B, COVERAGE: at covered pixels
 *     (index != 0xFFFFFFFF) r / 255.0f, g / 255.0f, b / 255.0f and 1; else
 *     0. Other channels are not touched.
 *
 * kernel pack_plane(global const float *src, ulong offset, uint step,
 *                   global const uint *index, uint w, uint h, uint wp, uint hp,
 *                   uint channel, global float *out, global uint *bad)
 *     One more channel of the same tensor: out[channel] at pixel (x, y) =
 *     src[offset + step * (y*w + x)] where covered, 0 elsewhere; channel >= 4.
 *     A covered pixel whose value is NaN or infinite gets 0 and bad[channel -
 *     4] += 1, once a pixel (the host zeroes bad first and raises an error
 *     naming the plane).
 *
 * kernel unpack_rgba8(global const float *nchw, uint channels, uint wp,
 *                     uint hp, uint w, uint h, global uchar *out)
 *     nchw: (1, channels, hp, wp), channels 3 or 4, w <= wp, h <= hp. out:
 *     w*h*4 uchars, the top-left w x h pixels: each value v becomes
 *     rint(clamp(v, 0, 1) * 255) (rint: half to even), NaN becomes 0; alpha
 *     255 when channels = 3. Pixels: h * ceil(w / ITEMS) * ITEMS (one
 *     work-item a row segment of ITEMS pixels).
 *
 * Memory traffic: one read of each input value and one write of each output
 * value; rgbda_range reads the input once more and does 2 atomics per group.
 */
#pragma OPENCL FP_CONTRACT OFF

#include "clvis/keys.h"

#ifndef ITEMS
#define ITEMS 1
#endif
#ifndef WG
#define WG 1
#endif

static inline float key_to_float(const uint key)
{
    return as_float(clvis_key_f32_inverse(key));
}

/* The work-group's largest key and largest ~key (its range's two ends;
 * 0: no value), each atomically maxed into range[0] and range[1].
 * Called by every work-item of the group (barriers). */
static void key_range_reduce(local uint *hi, local uint *lo, const uint kmax, const uint kminv,
                             global uint *range)
{
    const uint lid = get_local_id(0);
    hi[lid] = kmax;
    lo[lid] = kminv;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint s = WG / 2; s > 0; s >>= 1) {
        if (lid < s) {
            hi[lid] = max(hi[lid], hi[lid + s]);
            lo[lid] = max(lo[lid], lo[lid + s]);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) {
        if (hi[0])
            atomic_max(&range[0], hi[0]);
        if (lo[0])
            atomic_max(&range[1], lo[0]);
    }
}

/* numpy.pad's "symmetric" index of i on an axis of n samples (n >= 1) */
static inline uint mirror(const uint i, const uint n)
{
    if (i < n)
        return i;
    const uint j = i % (2 * n);
    return j < n ? j : 2 * n - 1 - j;
}

static inline int rgbda_kept(const float depth, const float alpha)
{
    return alpha > 0.0f && isfinite(depth);
}

kernel void pack_iso(global const float *rgba, global const uchar *hit,
                     global const uchar *active, const uint w, const uint h,
                     const uint wp, const uint hp, global float *out, global uint *bad)
{
    const ulong plane = (ulong)wp * hp;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    /* the pixel's column and row, stepped (not divided) from the first */
    uint y = (uint)(first / wp), x = (uint)(first - (ulong)y * wp);
    for (ulong i = first; i < plane && i < first + ITEMS; ++i, x = x + 1 < wp ? x + 1 : 0, y += x == 0) {
        float r = 0.0f, g = 0.0f, b = 0.0f, shown = 0.0f, act = 0.0f;
        if (x < w && y < h) {
            const ulong s = (ulong)y * w + x;
            const int is_hit = hit[s] != 0, is_active = active[s] != 0;
            if (is_hit) {
                const float4 c = vload4(s, rgba);
                if (!(isfinite(c.x) && isfinite(c.y) && isfinite(c.z)))
                    atomic_inc(&bad[0]);
                if (!is_active) {
                    r = c.x;
                    g = c.y;
                    b = c.z;
                    shown = 1.0f;
                }
            }
            act = is_active ? 1.0f : 0.0f;
        }
        out[i] = r;
        out[plane + i] = g;
        out[2 * plane + i] = b;
        out[3 * plane + i] = shown;
        out[4 * plane + i] = act;
    }
}

kernel void pack_count(global const uchar *count, global const uchar *active, const uint cap,
                       const uint w, const uint h, const uint wp, const uint hp, const uint channel,
                       global float *out)
{
    const ulong plane = (ulong)wp * hp;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    uint y = (uint)(first / wp), x = (uint)(first - (ulong)y * wp);
    for (ulong i = first; i < plane && i < first + ITEMS; ++i, x = x + 1 < wp ? x + 1 : 0, y += x == 0) {
        float v = 0.0f;
        if (x < w && y < h) {
            const ulong s = (ulong)y * w + x;
            if (active[s] != 0)
                v = (float)min((uint)count[s], cap) / (float)cap;
        }
        out[channel * plane + i] = v;
    }
}

kernel void pack_prior(global const uchar *count, global const uchar *active, const float miss,
                       const uint cap, const uint w, const uint h, const uint wp, const uint hp,
                       const uint channel, global float *out)
{
    const ulong plane = (ulong)wp * hp;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    uint y = (uint)(first / wp), x = (uint)(first - (ulong)y * wp);
    for (ulong i = first; i < plane && i < first + ITEMS; ++i, x = x + 1 < wp ? x + 1 : 0, y += x == 0) {
        float v = 0.0f;
        if (x < w && y < h) {
            const ulong s = (ulong)y * w + x;
            if (active[s] != 0) {
                const uint k = min((uint)count[s], cap);
                float p = 1.0f;
                for (uint j = 0; j < k; ++j)
                    p = p * miss;
                v = 1.0f - p;
            }
        }
        out[channel * plane + i] = v;
    }
}

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void iso_depth_range(global const float *t, global const float *next_t, global const uchar *hit,
                     global const uchar *active, const ulong n, global uint *stats)
{
    local uint hi[WG], lo[WG];      /* max key, max ~key: 0 = no value */
    uint kmax = 0, kminv = 0;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    for (ulong i = first; i < n && i < first + ITEMS; ++i) {
        const int running = active[i] != 0;
        const float v = running ? next_t[i] : t[i];
        if ((running || hit[i] != 0) && isfinite(v)) {
            const uint k = clvis_key_f32(as_uint(v));
            kmax = max(kmax, k);
            kminv = max(kminv, ~k);
        }
    }
    key_range_reduce(hi, lo, kmax, kminv, stats);
}

kernel void pack_depth(global const float *t, global const float *next_t, global const uchar *hit,
                       global const uchar *active, const uint w, const uint h, const uint wp,
                       const uint hp, const uint channel, global const uint *stats,
                       global float *out)
{
    const ulong plane = (ulong)wp * hp;
    /* no value at all: stats 0, range not > 0, every pixel 0 */
    const float vmax = key_to_float(stats[0]), vmin = key_to_float(~stats[1]);
    const float range = stats[0] ? vmax - vmin : 0.0f;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    uint y = (uint)(first / wp), x = (uint)(first - (ulong)y * wp);
    for (ulong i = first; i < plane && i < first + ITEMS; ++i, x = x + 1 < wp ? x + 1 : 0, y += x == 0) {
        float done = 0.0f, next = 0.0f;
        if (x < w && y < h && range > 0.0f) {
            const ulong s = (ulong)y * w + x;
            if (active[s] != 0) {
                if (isfinite(next_t[s]))
                    next = (next_t[s] - vmin) / range;
            } else if (hit[s] != 0 && isfinite(t[s])) {
                done = (t[s] - vmin) / range;
            }
        }
        out[channel * plane + i] = done;
        out[(channel + 1) * plane + i] = next;
    }
}

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void rgbda_range(global const float *rgbda, const ulong n, global uint *stats)
{
    local uint hi[WG], lo[WG];      /* max key, max ~key: 0 = no kept pixel */
    uint kmax = 0, kminv = 0, nan = 0, neg = 0;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    for (ulong i = first; i < n && i < first + ITEMS; ++i) {
        global const float *p = rgbda + 5 * i;
        for (uint c = 0; c < 5; ++c)
            nan += isnan(p[c]) ? 1 : 0;
        const float d = p[3], a = p[4];
        if (a > 0.0f && d == -INFINITY)
            ++neg;
        if (rgbda_kept(d, a)) {
            const uint k = clvis_key_f32(as_uint(d));
            kmax = max(kmax, k);
            kminv = max(kminv, ~k);
        }
    }
    if (nan)
        atomic_add(&stats[0], nan);
    if (neg)
        atomic_add(&stats[1], neg);
    key_range_reduce(hi, lo, kmax, kminv, stats + 2);
}

kernel void pack_rgbda(global const float *rgbda, const uint w, const uint h,
                       const uint wp, const uint hp, global const uint *stats,
                       global float *out)
{
    const ulong plane = (ulong)wp * hp;
    const float dmax = key_to_float(stats[2]), dmin = key_to_float(~stats[3]);
    const float range = dmax - dmin;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    /* the pixel's column and row, stepped (not divided) from the first */
    uint y = (uint)(first / wp), x = (uint)(first - (ulong)y * wp);
    for (ulong i = first; i < plane && i < first + ITEMS; ++i, x = x + 1 < wp ? x + 1 : 0, y += x == 0) {
        float r = 0.0f, g = 0.0f, b = 0.0f, a = 0.0f, dn = -1.0f;
        {
            global const float *p = rgbda + 5 * ((ulong)mirror(y, h) * w + mirror(x, w));
            const float d = p[3];
            if (rgbda_kept(d, p[4])) {
                r = p[0];
                g = p[1];
                b = p[2];
                a = p[4];
                dn = range > 0.0f ? (d - dmin) / range : 0.0f;
            }
        }
        out[i] = r;
        out[plane + i] = g;
        out[2 * plane + i] = b;
        out[3 * plane + i] = a;
        out[4 * plane + i] = dn;
    }
}

kernel void pack_rgb_coverage(global const uchar *rgba, global const uint *index,
                              const uint w, const uint h, const uint wp, const uint hp,
                              global float *out)
{
    const ulong plane = (ulong)wp * hp;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    /* the pixel's column and row, stepped (not divided) from the first */
    uint y = (uint)(first / wp), x = (uint)(first - (ulong)y * wp);
    for (ulong i = first; i < plane && i < first + ITEMS; ++i, x = x + 1 < wp ? x + 1 : 0, y += x == 0) {
        float r = 0.0f, g = 0.0f, b = 0.0f, cov = 0.0f;
        {
            const ulong s = (ulong)mirror(y, h) * w + mirror(x, w);
            if (index[s] != 0xFFFFFFFFu) {
                const uchar4 c = vload4(s, rgba);
                r = (float)c.x / 255.0f;
                g = (float)c.y / 255.0f;
                b = (float)c.z / 255.0f;
                cov = 1.0f;
            }
        }
        out[i] = r;
        out[plane + i] = g;
        out[2 * plane + i] = b;
        out[3 * plane + i] = cov;
    }
}

kernel void pack_plane(global const float *src, const ulong offset, const uint step,
                       global const uint *index, const uint w, const uint h,
                       const uint wp, const uint hp, const uint channel,
                       global float *out, global uint *bad)
{
    const ulong plane = (ulong)wp * hp;
    const ulong first = (ulong)get_global_id(0) * ITEMS;
    uint nonfinite = 0;
    /* the pixel's column and row, stepped (not divided) from the first */
    uint y = (uint)(first / wp), x = (uint)(first - (ulong)y * wp);
    for (ulong i = first; i < plane && i < first + ITEMS; ++i, x = x + 1 < wp ? x + 1 : 0, y += x == 0) {
        float v = 0.0f;
        {
            const ulong s = (ulong)mirror(y, h) * w + mirror(x, w);
            if (index[s] != 0xFFFFFFFFu) {
                v = src[offset + (ulong)step * s];
                if (!isfinite(v)) {
                    nonfinite += x < w && y < h;  /* each pixel once, not its mirror images */
                    v = 0.0f;
                }
            }
        }
        out[channel * plane + i] = v;
    }
    if (nonfinite)
        atomic_add(&bad[channel - 4], nonfinite);
}

kernel void unpack_rgba8(global const float *nchw, const uint channels, const uint wp,
                         const uint hp, const uint w, const uint h, global uchar *out)
{
    /* one work-item a row segment of ITEMS pixels (h * ceil(w / ITEMS) work-
     * items): one division a work-item, not a 64-bit one a pixel, and the
     * four channels as one float4 (4x less CPU on PoCL at 1280x720 than a
     * work-item per ITEMS consecutive pixels of the flat index) */
    const uint plane = wp * hp, per = (w + ITEMS - 1) / ITEMS;
    const uint g = get_global_id(0), y = g / per, x0 = (g - y * per) * ITEMS;
    if (y >= h)
        return;
    const uint x1 = min(x0 + ITEMS, w);
    for (uint x = x0; x < x1; ++x) {
        const uint s = y * wp + x;
        float4 f = (float4)(nchw[s], nchw[plane + s], nchw[2 * plane + s],
                            channels > 3 ? nchw[3 * plane + s] : 1.0f);
        f = select(clamp(f, 0.0f, 1.0f), (float4)(0.0f), isnan(f));
        vstore4(convert_uchar4(rint(f * 255.0f)), y * w + x, out);
    }
}
