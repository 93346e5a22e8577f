/* render.cl — point rasterization into a 64-bit depth|index visibility buffer
 * (Schütz, Kerbl, Wimmer 2021/2022), with a two-pass fallback for devices
 * without 64-bit atomics, and the soft z-buffer's color accumulation.
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/atomics.h,
 *     clvis/camera.h, clvis/colormap.h, clvis/inline.h, clvis/keys.h).
 * Build options: -cl-fp32-correctly-rounded-divide-sqrt (for pixels
 * bit-identical to the NumPy reference; see clvis/camera.h). The clvis
 * runtime adds -DCLVIS_INT64_ATOMICS=1 when the device has 64-bit atomics;
 * render_visibility exists only then.
 * Defines (optional): VEC = 1 (default) or 8. With VEC 8, a group of one
 * work-item projects 8 points at a time in float8 registers (CPU devices:
 * SIMD); results are identical. Any local size works (the CPU work shape
 * launches 1 work-item per group, the GPU shape 256).
 * POINT_SIZE = N, 1 (default) to 64: a drawn point covers the N x N pixels
 * px - (N-1)/2 .. px + N/2 by py - (N-1)/2 .. py + N/2 (integer division;
 * (px, py) its pixel; for even N the extra column is on the right and the
 * extra row below), clipped to the image. Each covered pixel takes the
 * point's dkey << 32 | id exactly as its own pixel does (same early-z, same
 * atomics, same ties). Only points whose own pixel is in the image are drawn
 * (a point just outside the image draws nothing). All four per-batch kernels
 * (visibility, depth, index, soft_accumulate) cover the same pixels.
 *
 * Points and batches. positions: n points, 3 floats each (x, y, z), in render
 * order. They are cut into nb = ceil(n / batch) batches of `batch` consecutive
 * points (1 <= batch <= 2^24); bounds[6*b .. 6*b+5] = (min x, min y, min z, max x, max y, max z) of
 * the finite points of batch b (batch_bounds computes it; min > max for a batch
 * with none). Launch every per-batch kernel with global size nb * L and local
 * size L: group g walks batch b = g (walk's reverse bit in the three
 * visibility kernels: b = nb - 1 - g), item l takes points l, l + L, ... A batch
 * whose box the camera cannot see (clvis_box_culled) reads no point at all.
 * ids: NULL, or n uints: ids[i] = the index reported for point i (its index in
 * the caller's order when the points were reordered, e.g. by Morton code).
 * Ties (equal depth) go to the lowest id.
 *
 * Camera: cam, 20 floats (clvis/camera.h); near, far: finite floats; W, H:
 * image size (1 <= W, H <= 2^24).
 *
 * Visibility buffer vis: W*H ulongs, vis[py*W + px] = dkey << 32 | id, dkey =
 * clvis_key_f32(bits of depth) (order-preserving; for positive depths the
 * float bits with the sign bit set). Cleared to all ones (= empty) by the host.
 * Seen as uints, word 2p is the id and word 2p + 1 the dkey (little-endian).
 *
 * kernel batch_bounds(global const float *positions, uint n, uint batch,
 *                     global float *bounds)
 *     Global size >= nb, any local size; item b computes bounds of batch b.
 *
 * kernel batch_nonfinite(global const float *positions, uint n, uint batch,
 *                        global uint *counts)
 *     Global size >= nb, any local size; item b writes counts[b] = the number
 *     of points of batch b with a NaN or infinite coordinate (never drawn).
 *
 * kernel render_visibility(positions, ids, n, batch, bounds, cam, near, far,
 *                          W, H, global ulong *vis, global uchar *drawn,
 *                          uint walk)
 *     (64-bit atomics only.) Per drawn point: early-z (skip when its dkey
 *     exceeds the pixel's current dkey), else atom_min(vis + p, dkey<<32|id).
 *     drawn[b] = 1 if batch b was not culled, else 0 (written by item 0).
 *     walk holds two bits; the result is the same for every value, the speed
 *     is not. Bit 0 (reverse) walks the batches from the last to the first,
 *     and each batch from its last point to its first: early-z rejects most
 *     when near points come first. For a Morton-ordered cloud the host sets it
 *     when the view direction f has f.x + 2 f.y + 4 f.z < 0 (the code's z bit
 *     is the most significant of each level, x the least), so the points of
 *     each cell come nearest first. Bit 1 (coherent) makes the cpu profile
 *     test early-z for 8 points at once before their atomics (point size 1):
 *     that pays where most points are rejected (a Morton-ordered cloud walked
 *     nearest first) and costs where few are (a shuffled cloud), so the host
 *     sets it for Morton-ordered clouds only. walk = 0 or 1 means what the
 *     older `reverse` argument meant.
 *
 * kernel render_depth(... same arguments ..., global uint *vis, drawn, walk)
 * kernel render_index(... same arguments ..., global uint *vis, drawn, walk)
 *     The fallback, in this order: render_depth takes atomic_min of dkey into
 *     word 2p + 1; render_index, for every point whose dkey equals that word,
 *     takes atomic_min of its id into word 2p. The result is the same vis
 *     buffer, bit for bit.
 *
 * kernel soft_accumulate(positions, ids, n, batch, bounds, cam, near, far, W,
 *                        H, global const uint *vis, float tolerance,
 *                        uint color_mode, global const uchar4 *colors,
 *                        global const float *tf_src, uint tf_stride, uint tf_offset,
 *                        global const uchar4 *lut, uint lut_n, float tf_min,
 *                        float tf_scale, global uint *accum)
 *     After the visibility pass. For every drawn point and every pixel p of
 *     its POINT_SIZE square where its depth <=
 *     tolerance * (the pixel's nearest depth) (float32 product), adds its color
 *     (clvis_point_color) to accum[5p .. 5p+3] (r, g, b, a sums) and 1 to
 *     accum[5p+4] (the count), with atomic_add. accum is zeroed by the host.
 *     Integer sums: the result does not depend on the order of the additions.
 *     A pixel overflows after 2^32 / 255 (16.8 M) points within tolerance.
 *
 * Colors: clvis_point_color of clvis/colormap.h (color_mode 0 white, 1
 * colors[id], 2 the transfer function of tf_src[id * tf_stride + tf_offset] through lut).
 * colors and tf_src are indexed by id (the caller's order); buffers a mode
 * does not use may be NULL.
 *
 * Memory traffic per point: 12 bytes of position (+4 of id when it passes
 * early-z with ids); one 4-byte read of vis, and an atomic on it when the
 * point may win (per covered pixel with POINT_SIZE > 1). Culled batches: 24
 * bytes of bounds.
 */
#pragma OPENCL FP_CONTRACT OFF

#include "clvis/atomics.h"
#include "clvis/camera.h"
#include "clvis/colormap.h"
#include "clvis/inline.h"
#include "clvis/keys.h"

#ifndef VEC
#define VEC 1
#endif
#ifndef POINT_SIZE
#define POINT_SIZE 1
#endif
#if POINT_SIZE < 1 || POINT_SIZE > 64
#error "POINT_SIZE must be 1..64"
#endif
/* the square of a point at pixel (px, py): px - SPLAT_LO .. px + SPLAT_HI */
#define SPLAT_LO ((POINT_SIZE - 1) / 2)
#define SPLAT_HI (POINT_SIZE / 2)

#define MODE_VIS64 0
#define MODE_DEPTH 1
#define MODE_INDEX 2

kernel void batch_bounds(global const float *positions, uint n, uint batch, global float *bounds)
{
    uint b = get_global_id(0);
    uint nb = (n + batch - 1) / batch;
    if (b >= nb)
        return;
    float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
    uint end = clvis_il_umin(n, (b + 1) * batch);
    for (uint i = b * batch; i < end; ++i) {
        float3 p = (float3)(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]);
        if (clvis_il_isfinite(p.x) && clvis_il_isfinite(p.y) && clvis_il_isfinite(p.z)) {
            lo = clvis_il_fmin3(lo, p);
            hi = clvis_il_fmax3(hi, p);
        }
    }
    vstore3(lo, 0, bounds + 6 * b);
    vstore3(hi, 0, bounds + 6 * b + 3);
}

kernel void batch_nonfinite(global const float *positions, uint n, uint batch, global uint *counts)
{
    uint b = get_global_id(0);
    uint nb = (n + batch - 1) / batch;
    if (b >= nb)
        return;
    uint bad = 0;
    uint end = clvis_il_umin(n, (b + 1) * batch);
    for (uint i = b * batch; i < end; ++i) {
        float x = positions[3 * i], y = positions[3 * i + 1], z = positions[3 * i + 2];
        bad += (clvis_il_isfinite(x) && clvis_il_isfinite(y) && clvis_il_isfinite(z)) ? 0u : 1u;
    }
    counts[b] = bad;
}

/* One drawn point i at pixel p with depth key dkey, as `mode` says. */
inline void raster_point(int mode, uint i, uint p, uint dkey, global const uint *ids,
                         volatile global uint *words)
{
    if (mode == MODE_INDEX) {
        if (dkey == words[clvis_hi_word(p)])
            clvis_atomic_min_u32(words + clvis_lo_word(p), ids ? ids[i] : i);
        return;
    }
    /* benign race (early-z): early-z reads the pixel's depth key with a plain
     * (volatile) load while other work-items update the same word with the
     * atomic min below (Oclgrind reports each such pair). The word only ever
     * decreases, so the value read, current or stale, is >= the key the
     * pixel ends with. A point is skipped only when its dkey is greater than
     * that value, hence greater than the final winner's: it could not have
     * won. A stale (larger) value can only let through a point that the
     * atomic min then rejects; it never rejects a point that would win, so
     * the buffer is exactly what the atomics alone would make. The load is
     * of one aligned 32-bit word (the high half of the 64-bit entry on the
     * 64-bit path), which devices read whole: it gives the high half of a
     * value the entry did hold. It is not made atomic because the only
     * atomic read OpenCL 1.2 offers is a read-modify-write (atomic_or(p, 0)),
     * which would write to every pixel a point lands on and cost what
     * early-z saves. (render_index's read above has no writer in its launch.) */
    if (dkey > words[clvis_hi_word(p)])     /* early-z: it cannot win */
        return;
    if (mode == MODE_DEPTH) {
        clvis_atomic_min_u32(words + clvis_hi_word(p), dkey);
    } else {
#ifdef CLVIS_INT64_ATOMICS
        uint id = ids ? ids[i] : i;
        clvis_atomic_min_u64((volatile global ulong *)words + p, ((ulong)dkey << 32) | id);
#endif
    }
}

/* A drawn point i at pixel (px, py): raster_point on each pixel of its
 * POINT_SIZE square inside the image (just the pixel itself for size 1). */
inline void raster_splat(int mode, uint i, uint px, uint py, uint W, uint H, uint dkey,
                         global const uint *ids, volatile global uint *words)
{
#if POINT_SIZE == 1
    raster_point(mode, i, py * W + px, dkey, ids, words);
#else
    uint x0 = px >= SPLAT_LO ? px - SPLAT_LO : 0u, x1 = clvis_il_umin(px + SPLAT_HI, W - 1u);
    uint y0 = py >= SPLAT_LO ? py - SPLAT_LO : 0u, y1 = clvis_il_umin(py + SPLAT_HI, H - 1u);
    for (uint y = y0; y <= y1; ++y)
        for (uint x = x0; x <= x1; ++x)
            raster_point(mode, i, y * W + x, dkey, ids, words);
#endif
}

#if VEC == 8
/* raster_batch's steps of 8 points (one work-item per batch: L == 1) over
 * the batch's points start .. end - 1 (walk as there): the projection in
 * vector registers, then the drawn lanes one by one. Returns how many points
 * it took (a multiple of 8; the rest go to the scalar loop). w_depth: the
 * camera's clip w row equals its depth row (clvis_project8 then reuses clip
 * w as the depth). inside (a constant at each call site: one loop for the
 * batches whose box lies inside the view, one for the others): the batch
 * box passed clvis_box_inside (clvis_project8 then tests only the depth
 * range). */
__attribute__((always_inline))
inline uint raster_steps8(int mode, int w_depth, int inside, global const float *positions,
                          global const uint *ids, const clvis_camera *c, float near, float far,
                          uint W, uint H, uint start, uint end, uint walk,
                          volatile global uint *words)
{
    uint reverse = walk & 1u, count = end - start, t = 0;
    float fw = (float)W, fh = (float)H;
    clvis_camera cc = *c;   /* in registers, not reloaded after each atomic */
    for (; t + 8 <= count; t += 8) {
        uint i = reverse ? end - t - 8 : start + t;
        /* the 8 points' x, y, z (point k in lane k): 4-float loads into the
         * two 128-bit halves, m03 = x0 y0 z0 x1 | x4 y4 z4 x5, m14 = y1 z1
         * x2 y2 | y5 z5 x6 y6, m25 = z2 x3 y3 z3 | z6 x7 y7 z7, then five
         * in-half shuffles (one vshufps each on AVX). `zero` (0: count <=
         * batch <= 2^24) is XORed in after the loads and after the first
         * shuffles so that the compiler can neither see the lanes as
         * single floats of memory nor merge the two levels of shuffles:
         * PoCL's LLVM 14 turns them back into 24 one-float loads, or ~35
         * blends and permutes. */
        global const float *p = positions + 3 * (size_t)i;
        uint8 zero = (uint8)(count >> 31);
        float8 m03 = as_float8(as_uint8((float8)(CLVIS_IL_VLOAD4(float4, p),
                                                  CLVIS_IL_VLOAD4(float4, p + 12))) ^ zero);
        float8 m14 = as_float8(as_uint8((float8)(CLVIS_IL_VLOAD4(float4, p + 4),
                                                  CLVIS_IL_VLOAD4(float4, p + 16))) ^ zero);
        float8 m25 = as_float8(as_uint8((float8)(CLVIS_IL_VLOAD4(float4, p + 8),
                                                  CLVIS_IL_VLOAD4(float4, p + 20))) ^ zero);
        float8 xy = (float8)(m14.s2, m14.s3, m25.s1, m25.s2, m14.s6, m14.s7, m25.s5, m25.s6);
        float8 yz = (float8)(m03.s1, m03.s2, m14.s0, m14.s1, m03.s5, m03.s6, m14.s4, m14.s5);
        /* xy = x2 y2 x3 y3 | x6 y6 x7 y7, yz = y0 z0 y1 z1 | y4 z4 y5 z5 */
        xy = as_float8(as_uint8(xy) ^ zero);
        yz = as_float8(as_uint8(yz) ^ zero);
        float8 x = (float8)(m03.s0, m03.s3, xy.s0, xy.s2, m03.s4, m03.s7, xy.s4, xy.s6);
        float8 y = (float8)(yz.s0, yz.s2, xy.s1, xy.s3, yz.s4, yz.s6, xy.s5, xy.s7);
        float8 z = (float8)(yz.s1, yz.s3, m25.s0, m25.s3, yz.s5, yz.s7, m25.s4, m25.s7);
        float8 sx, sy, depth;
        int8 drawn8 = clvis_project8(&cc, x, y, z, near, far, fw, fh, &sx, &sy, &depth, w_depth,
                                      inside);
        if (!clvis_il_any8(drawn8))
            continue;
        /* the lanes through unions, not vstore8 (a call on PoCL) */
        union { uint8 v; uint s[8]; } pxs, pys, key;
        union { int8 v; int s[8]; } ok;
        /* 0 <= sx < W <= 2^24 in the drawn lanes: the int conversion is exact */
        pxs.v = as_uint8(convert_int8(sx));
        pys.v = as_uint8(convert_int8(sy));
        /* w_depth: depth = clip w > 0 in the drawn lanes, whose key is then
         * the float bits with the sign bit set (clvis_key_f32) */
        key.v = w_depth ? as_uint8(depth) | (uint8)(0x80000000u)
                        : clvis_key_f32_8(as_uint8(depth));
        ok.v = drawn8;
#if POINT_SIZE == 1
        if (mode != MODE_INDEX && (walk & 2u) != 0u) {
            /* benign race (early-z): early-z of the 8 lanes at once (8
             * independent loads, one vector compare), then raster_point on
             * only the lanes that pass, in the same lane order. The loads are
             * raster_point's early-z read (safe: see there), done earlier;
             * raster_point repeats the test against the word as it is then,
             * so a word read here before an earlier lane's atomic can only
             * let a point through to that second test. The same points win. */
            union { uint8 v; uint s[8]; } pix, z;
            pix.v = clvis_il_select8((uint8)(0u), pys.v * (uint8)(W) + pxs.v, drawn8);
            z.v = (uint8)(words[clvis_hi_word(pix.s[0])], words[clvis_hi_word(pix.s[1])],
                          words[clvis_hi_word(pix.s[2])], words[clvis_hi_word(pix.s[3])],
                          words[clvis_hi_word(pix.s[4])], words[clvis_hi_word(pix.s[5])],
                          words[clvis_hi_word(pix.s[6])], words[clvis_hi_word(pix.s[7])]);
            int8 pass = drawn8 & (key.v <= z.v);
            if (!clvis_il_any8(pass))
                continue;
            uint8 bit = reverse ? (uint8)(128u, 64u, 32u, 16u, 8u, 4u, 2u, 1u)
                                : (uint8)(1u, 2u, 4u, 8u, 16u, 32u, 64u, 128u);
            uint8 sel = bit & as_uint8(pass);
            uint4 m4 = sel.lo | sel.hi;
            uint2 m2 = m4.lo | m4.hi;
            uint m = m2.x | m2.y;
            while (m != 0u) {
                uint kk = clvis_il_ctz64((ulong)m);
                uint k = reverse ? 7u - kk : kk;
                m &= m - 1u;
                raster_point(mode, i + k, pix.s[k], key.s[k], ids, words);
            }
            continue;
        }
#endif
        for (int kk = 0; kk < 8; ++kk) {
            int k = reverse ? 7 - kk : kk;
            if (ok.s[k])
                raster_splat(mode, i + k, pxs.s[k], pys.s[k], W, H, key.s[k], ids, words);
        }
    }
    return t;
}
#endif

/* The body of the three visibility kernels; `mode` is a constant at each call
 * site, so each kernel compiles to its own loop. */
inline void raster_batch(int mode, global const float *positions, global const uint *ids,
                         uint n, uint batch, global const float *bounds, global const float *cam,
                         float near, float far, uint W, uint H, global uint *vis,
                         global uchar *drawn, uint walk)
{
    uint reverse = walk & 1u;
    /* reverse also takes the batches last to first (group g: batch nb-1-g),
     * so that the whole cloud, not just each batch, comes nearest first to
     * devices that run the groups roughly in order */
    uint nb = (n + batch - 1) / batch;
    uint b = reverse ? nb - 1u - get_group_id(0) : get_group_id(0);
    uint l = get_local_id(0), L = get_local_size(0);
    clvis_camera c = clvis_load_camera(cam);
    float3 lo = vload3(0, bounds + 6 * b), hi = vload3(0, bounds + 6 * b + 3);
    int culled = clvis_box_culled(&c, lo, hi, near, far);
    if (l == 0 && mode != MODE_INDEX)
        drawn[b] = culled ? 0 : 1;
    if (culled)
        return;
    float fw = (float)W, fh = (float)H;
    uint start = b * batch, end = clvis_il_umin(n, (b + 1) * batch), count = end - start, t = l;
    volatile global uint *words = vis;
#if VEC == 8
    if (L == 1) {
        /* a perspective camera's clip w row is its depth row (equal values:
         * clvis_project8's w_depth); always_inline (PoCL would call one
         * function with `inside` as an argument, and test it per point) */
        int w_depth = c.r3.x == c.d.x && c.r3.y == c.d.y && c.r3.z == c.d.z && c.r3.w == c.d.w;
        if (clvis_box_inside(&c, lo, hi))
            t = raster_steps8(mode, w_depth, 1, positions, ids, &c, near, far, W, H, start, end,
                              walk, words);
        else
            t = raster_steps8(mode, w_depth, 0, positions, ids, &c, near, far, W, H, start, end,
                              walk, words);
    }
#endif
    for (; t < count; t += L) {
        uint i = reverse ? end - 1 - t : start + t;
        float x = positions[3 * i], y = positions[3 * i + 1], z = positions[3 * i + 2];
        float sx, sy, depth;
        if (clvis_project(&c, x, y, z, near, far, fw, fh, &sx, &sy, &depth))
            raster_splat(mode, i, (uint)sx, (uint)sy, W, H, clvis_key_f32(as_uint(depth)), ids,
                         words);
    }
}

#ifdef CLVIS_INT64_ATOMICS
kernel void render_visibility(global const float *positions, global const uint *ids, uint n,
                              uint batch, global const float *bounds, global const float *cam,
                              float near, float far, uint W, uint H, global ulong *vis,
                              global uchar *drawn, uint walk)
{
    raster_batch(MODE_VIS64, positions, ids, n, batch, bounds, cam, near, far, W, H,
                 (global uint *)vis, drawn, walk);
}
#endif

kernel void render_depth(global const float *positions, global const uint *ids, uint n,
                         uint batch, global const float *bounds, global const float *cam,
                         float near, float far, uint W, uint H, global uint *vis,
                         global uchar *drawn, uint walk)
{
    raster_batch(MODE_DEPTH, positions, ids, n, batch, bounds, cam, near, far, W, H, vis, drawn,
                 walk);
}

kernel void render_index(global const float *positions, global const uint *ids, uint n,
                         uint batch, global const float *bounds, global const float *cam,
                         float near, float far, uint W, uint H, global uint *vis,
                         global uchar *drawn, uint walk)
{
    raster_batch(MODE_INDEX, positions, ids, n, batch, bounds, cam, near, far, W, H, vis, drawn,
                 walk);
}

/* soft_accumulate at one pixel p of point i (its depth: `depth`). */
inline void soft_pixel(uint i, uint p, float depth, global const uint *ids, global const uint *vis,
                       float tolerance, uint color_mode, global const uchar4 *colors,
                       global const float *tf_src, uint tf_stride, uint tf_offset,
                       global const uchar4 *lut, uint lut_n, float tf_min, float tf_scale,
                       global uint *accum)
{
    uint k = vis[clvis_hi_word(p)];
    float nearest = as_float(clvis_key_f32_inverse(k));
    if (!(depth <= tolerance * nearest))
        return;
    uint id = ids ? ids[i] : i;
    uint4 col = clvis_point_color(id, color_mode, colors, tf_src, tf_stride, tf_offset, lut, lut_n,
                                  tf_min, tf_scale);
    volatile global uint *a = accum + 5 * (size_t)p;
    atomic_add(a + 0, col.x);
    atomic_add(a + 1, col.y);
    atomic_add(a + 2, col.z);
    atomic_add(a + 3, col.w);
    atomic_add(a + 4, 1u);
}

kernel void soft_accumulate(global const float *positions, global const uint *ids, uint n,
                            uint batch, global const float *bounds, global const float *cam,
                            float near, float far, uint W, uint H, global const uint *vis,
                            float tolerance, uint color_mode, global const uchar4 *colors,
                            global const float *tf_src, uint tf_stride, uint tf_offset, global const uchar4 *lut,
                            uint lut_n, float tf_min, float tf_scale, global uint *accum)
{
    uint b = get_group_id(0);
    uint l = get_local_id(0), L = get_local_size(0);
    clvis_camera c = clvis_load_camera(cam);
    float3 lo = vload3(0, bounds + 6 * b), hi = vload3(0, bounds + 6 * b + 3);
    if (clvis_box_culled(&c, lo, hi, near, far))
        return;
    float fw = (float)W, fh = (float)H;
    uint end = clvis_il_umin(n, (b + 1) * batch);
    for (uint i = b * batch + l; i < end; i += L) {
        float x = positions[3 * i], y = positions[3 * i + 1], z = positions[3 * i + 2];
        float sx, sy, depth;
        if (!clvis_project(&c, x, y, z, near, far, fw, fh, &sx, &sy, &depth))
            continue;
        uint px = (uint)sx, py = (uint)sy;
        uint x0 = px >= SPLAT_LO ? px - SPLAT_LO : 0u, x1 = clvis_il_umin(px + SPLAT_HI, W - 1u);
        uint y0 = py >= SPLAT_LO ? py - SPLAT_LO : 0u, y1 = clvis_il_umin(py + SPLAT_HI, H - 1u);
        for (uint yy = y0; yy <= y1; ++yy)
            for (uint xx = x0; xx <= x1; ++xx)
                soft_pixel(i, yy * W + xx, depth, ids, vis, tolerance, color_mode, colors, tf_src,
                           tf_stride, tf_offset, lut, lut_n, tf_min, tf_scale, accum);
    }
}
