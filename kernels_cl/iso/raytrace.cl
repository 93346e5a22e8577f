/* raytrace.cl — block raytracing of the progressive isosurface raycaster
 * (Dyken, Usher, Kumar 2024): the rays waiting at one 4^3 ZFP block are traced
 * through that block's dual cells against its decoded brick.
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/atomics.h,
 *     clvis/camera.h, clvis/iso.h, clvis/zfp.h).
 * Build options: -cl-fp32-correctly-rounded-divide-sqrt (FP_CONTRACT is OFF
 * below: every float operation rounds on its own).
 * Defines:
 *   ITEMS         0 (default): ray_ids are pixels, ray_t / ray_hit / hit_t /
 *                 rgba / depth are per pixel, as described below.
 *                 1: speculation. ray_ids are *items* e = i * n_spec + k, the
 *                 k-th candidate block of active ray i (pixel item_pixel[i]);
 *                 ray_t[e] is the t where item e enters its block (cand_t of
 *                 traverse.cl; read only), and ray_hit / hit_t / rgba / depth
 *                 are per item. With CLVIS_INT64_ATOMICS defined (its
 *                 value is not read, here or in pass.cl: build both files
 *                 alike; -DCLVIS_INT64_ATOMICS=0 turns it on, leave it
 *                 undefined for off), a hit also does
 *                 atom_min(hitkey[p], as_uint(t) << 32 | e): the pixel's
 *                 nearest hit over its items (the host fills hitkey with ones
 *                 first); without it, pass.cl's resolve scans the items.
 *                 Early exit (ITEMS with CLVIS_INT64_ATOMICS): an item reads
 *                 t_best, the t of hitkey[p] (the high word; all ones, a NaN,
 *                 before any hit), when it starts; it is skipped when its
 *                 ray_t[e] > t_best, and its march stops at the first cell
 *                 entered at t > t_best. Its hit would lie at t >= that entry,
 *                 after the pixel's nearest hit, so it could not win: such an
 *                 item writes no outputs (ray_hit[e] stays as the host set it)
 *                 and the winner, hence the image, is the same whatever the
 *                 order of the groups (pass.cl's View order puts a ray's nearer
 *                 blocks first so that most of these items are skipped). The
 *                 read is a plain load racing with the other groups' atomic
 *                 mins, a documented benign race (iso-skip, in the kernel).
 *   REFINE_STEPS  Illinois steps of the root refinement (default 8; the
 *                 reference docstring asks for >= 6)
 *   PACKET        0 (default; the gpu profile): one ray a work-item. 8 (the
 *                 cpu profile): a work-item traces 8 rays at a time in float8
 *                 lanes with a lane mask, the same float operations per lane
 *                 in the same order, so the same results bit for bit (see
 *                 "8-ray packets" below).
 * Includes clvis/camera.h (the 22-float camera-ray buffer and clvis_camera_ray),
 * clvis/iso.h (clvis_iso_ray_setup: the ray in index space and its box
 * interval; the 1/d convention of clvis/ray.h; the cell stages: cell cubic,
 * first zero, gradient, shading), clvis/zfp.h (the block grid). fmin, fmax, clamp,
 * floor and min come from clvis/inline.h (exact; PoCL calls the builtins out of
 * line, several per cell).
 *
 * Volume [nz][ny][nx] samples, nx, ny, nz >= 2; blocks (bx, by, bz) of 4^3
 * samples, block id b = bx + nbx (by + nby bz), nb_ = ceil(n_ / 4) (the ZFP
 * block grid of zfp.cl). The brick of a block is 64 floats, value
 * x + 4 y + 16 z = sample (4 bx + x, 4 by + y, 4 bz + z) (clvis.zfp.decode_blocks).
 *
 * kernel raytrace_blocks(
 *     global const float *bricks,        slots x 64 floats: the block cache (16-byte
 *                                        aligned, as a whole cl_mem is: PACKET=8 loads
 *                                        its rows as float4)
 *     global const int *slot_of_block,   nblocks: block id -> cache slot, -1 if absent
 *     uint nx, uint ny, uint nz,         volume samples per axis
 *     float dx, float dy, float dz,      spacing (world units per sample step)
 *     float ox, float oy, float oz,      origin: world position of sample (0, 0, 0)
 *     float isovalue,
 *     global const float *cam,           22 floats: the camera rays of clvis/camera.h
 *     uint W,                            image width: ray p = py * W + px
 *     uint p0,                           the tile's first pixel: pixel ids below (ray_ids,
 *                                        item_pixel) are tile pixels j, the ray of image
 *                                        pixel p0 + j, and per-pixel arrays are indexed by j
 *                                        (0: the whole image; see traverse.cl's Tiles)
 *     global const uint *group_blocks,   per work-group: the block id it traces
 *     global const uint *group_offsets,  per work-group: first index of its rays in ray_ids
 *     global const uint *group_counts,   per work-group: how many rays
 *     global const uint *ray_ids,        pixel index p of each ray
 *     global float *ray_t,               per pixel: in, the t where the ray enters the block;
 *                                        out (no hit), the t where it leaves the block,
 *                                        or +INFINITY when it left the volume; unchanged at a hit
 *     global uchar *ray_hit,             per pixel: set to 1 at a hit (else not written)
 *     global float *hit_t,               per pixel: the hit's t (written at hits only)
 *     global float4 *rgba,               per pixel: shaded colour, alpha 1 (hits only)
 *     global float *depth,               per pixel: view depth cam[18..21] . (o + t d, 1) (hits only)
 *     global const uint *item_pixel,     ITEMS only (else unused, may be NULL): see below
 *     uint n_spec,                       ITEMS only
 *     volatile global ulong *hitkey)     ITEMS only, with CLVIS_INT64_ATOMICS (may be NULL otherwise)
 *   Global size: groups x L, local size L (any L; the host uses 64, or 2 with PACKET=8):
 *   work-group g traces block group_blocks[g], work-item i its rays i, i + L, ... <
 *   group_counts[g] (PACKET=8: the packets of rays 8 i .. 8 i + 7, 8 (i + L) .., the
 *   rays past group_counts[g] empty lanes).
 *   Local memory: 125 floats (the dual brick).
 *   The block and its +x, +y, +z, +xy, +xz, +yz, +xyz neighbours inside the
 *   volume must be cached (their samples on the block's far faces are corners
 *   of the block's cells); an absent one reads as NaN (no hit in those cells).
 *
 * Per ray (the rules of clvis/reference/iso/traverse.py and raytrace.py, in float32): o, d from the ray
 * buffer; index space O = (o - origin) / spacing, D = d / spacing, inv = spacing /
 * d_safe (|d| < TINY -> copysign(TINY, d)); t_exit = min_a max(t0_a, t1_a) of the
 * box [0, n - 1]. The first cell is clamp(floor(O + t D), block's cells), the
 * block's cells being those whose minimum corner is in the block: [4 b_a,
 * min(4 b_a + 3, n_a - 2)] per axis. Then the reference's DDA (t_next recomputed
 * from the cell index, ties x < y < z, t_out = max(t_in, min(t_exit, t_next))),
 * cell skipping by the corner range, the cell cubic split at its extrema, the
 * zero rule, Illinois refinement (REFINE_STEPS), until a hit, t_out >= t_exit
 * or the cell leaves the volume (ray_t = +INFINITY), or the cell leaves the
 * block (ray_t = t_out). Shading: Blinn–Phong headlight with the gradient of
 * the hit cell's trilinear interpolant divided by spacing (clvis_iso_shade).
 * The stages, in the kernel's order: load_dual_brick, first_cell, then per
 * cell cell_exit, cell_corners, clvis_iso_cell_cubic, clvis_iso_first_zero
 * (march_cells), and at a hit clvis_iso_trilinear_gradient, clvis_iso_shade.
 * PACKET=8: load_dual_brick_rows (the same brick, by rows of float4 loads),
 * the set-up in float8 (clvis_iso_ray_setup8 in clvis/iso.h: clvis_iso_ray_setup's operations; a
 * packet whose lanes are all empty or skipped stops here), march_cells8 (first_cell, cell_exit,
 * cell_corners, rt_cell_cubic8 and rt_bracket8 per cell, in float8; a lane
 * with a root keeps its cell's bracket and cubic and leaves the loop, and
 * rt_refine8 refines the brackets of all lanes at once after it: the same
 * Illinois steps as clvis_iso_first_zero on the same values), then per lane
 * the scalar shading.
 */
/* before the includes: clvis_camera_ray must not contract either */
#pragma OPENCL FP_CONTRACT OFF

#include "clvis/camera.h"
#include "clvis/iso.h"
#include "clvis/atomics.h"
#include "clvis/zfp.h"

#ifndef ITEMS
#define ITEMS 0
#endif
#ifndef REFINE_STEPS
#define REFINE_STEPS 8
#endif

#ifndef PACKET
#define PACKET 0
#endif

#define BRICK_SIDE 5

/* The dual brick of the block whose first sample is b0: samples b0 + (0..4)
 * per axis, from this block and its +x/+y/+z neighbours (NaN where outside the
 * volume or not cached); work-item lid of lsize fills entries lid, lid + lsize, ... */
inline void load_dual_brick(local float *brick, global const float *bricks,
                            global const int *slot_of_block, const int *n, const int *b0,
                            uint nbx, uint nby, uint lid, uint lsize)
{
    for (uint i = lid; i < BRICK_SIDE * BRICK_SIDE * BRICK_SIDE; i += lsize) {
        int lx = (int)(i % BRICK_SIDE), ly = (int)(i / BRICK_SIDE % BRICK_SIDE), lz = (int)(i / 25u);
        int sx = b0[0] + lx, sy = b0[1] + ly, sz = b0[2] + lz;
        float v = NAN;
        if (sx < n[0] && sy < n[1] && sz < n[2]) {
            int slot = slot_of_block[clvis_zfp_block_id((uint)(sx >> 2), (uint)(sy >> 2), (uint)(sz >> 2), nbx, nby)];
            if (slot >= 0)
                v = bricks[64ul * (ulong)slot + (ulong)((sx & 3) + 4 * (sy & 3) + 16 * (sz & 3))];
        }
        brick[i] = v;
    }
}

/* The first cell of a ray entering the block at t_in: clamp(floor(O + t_in D),
 * the block's cells [clo, chi]). */
inline void first_cell(const float *O, const float *D, float t_in, const int *clo, const int *chi, int *c)
{
    for (int a = 0; a < 3; ++a) {
        float gpos = clvis_il_floor(O[a] + t_in * D[a]);
        c[a] = gpos >= (float)clo[a] ? (gpos <= (float)chi[a] ? (int)gpos : chi[a]) : clo[a];
    }
}

/* The DDA's exit from cell c: t_next recomputed from the cell index (ties
 * x < y < z: *axis), t_out = max(t_in, min(t_next, t_exit)). */
inline float cell_exit(const int *c, const float *O, const float *inv, float t_in, float t_exit, int *axis)
{
    float tn[3];
    for (int a = 0; a < 3; ++a)
        tn[a] = ((float)(c[a] + (inv[a] > 0.0f ? 1 : 0)) - O[a]) * inv[a];
    int ax = 0;
    if (tn[1] < tn[ax])
        ax = 1;
    if (tn[2] < tn[ax])
        ax = 2;
    *axis = ax;
    return clvis_il_fmax(t_in, clvis_il_fmin(tn[ax], t_exit));
}

/* Cell c's corners minus the isovalue into v[8] (v[x + 2 y + 4 z]); 1 when
 * their range holds the isovalue (the cell may hold the surface), else 0. */
inline int cell_corners(local const float *brick, const int *c, const int *b0, float isovalue, float *v)
{
    const int base = (c[0] - b0[0]) + BRICK_SIDE * ((c[1] - b0[1]) + BRICK_SIDE * (c[2] - b0[2]));
    float vmin = INFINITY, vmax = -INFINITY;
    for (int k = 0; k < 8; ++k) {
        float x = brick[base + (k & 1) + BRICK_SIDE * ((k >> 1) & 1) + 25 * (k >> 2)];
        vmin = clvis_il_fmin(vmin, x);
        vmax = clvis_il_fmax(vmax, x);
        v[k] = x - isovalue;
    }
    return vmin <= isovalue && vmax >= isovalue;
}

/* A ray through the block's cells [clo, chi] from cell c at t_in. Returns 1 at
 * a hit: *t = t_in + s of the hit cell, v its corners, u the local position
 * where the ray entered it, *s the root. Else 0 with *t the ray's new ray_t:
 * the t where it leaves the block, or +INFINITY when it leaves the volume or
 * enters a cell at t > t_stop (ITEMS' early exit; NaN: never). */
inline int march_cells(local const float *brick, const int *n, const int *b0, const int *clo,
                       const int *chi, const float *O, const float *D, const float *inv,
                       float t_exit, float isovalue, float t_stop, float t_in, int *c,
                       float *v, float *u, float *s, float *t)
{
    for (;;) {
        if (t_in > t_stop) {   /* ITEMS: past the pixel's nearest hit (never for NaN) */
            *t = INFINITY;
            return 0;
        }
        int axis;
        const float t_out = cell_exit(c, O, inv, t_in, t_exit, &axis);
        if (cell_corners(brick, c, b0, isovalue, v)) {
            for (int a = 0; a < 3; ++a)
                u[a] = (O[a] + t_in * D[a]) - (float)c[a];
            float cf[4];
            clvis_iso_cell_cubic(v, u, D, cf);
            if (clvis_iso_first_zero(cf, t_out - t_in, REFINE_STEPS, s)) {
                *t = t_in + *s;
                return 1;
            }
        }
        if (t_out >= t_exit) {
            *t = INFINITY;
            return 0;
        }
        c[axis] += inv[axis] > 0.0f ? 1 : -1;
        if (c[axis] < 0 || c[axis] > n[axis] - 2) {
            *t = INFINITY;
            return 0;
        }
        if (c[axis] < clo[axis] || c[axis] > chi[axis]) {
            *t = t_out;
            return 0;
        }
        t_in = t_out;
    }
}

#if PACKET
/* ------------------------------------------------------------- 8-ray packets
 * PACKET=8 (the cpu profile): a work-item traces its rays 8 at a time, one
 * per float8 / int8 lane, with a lane mask (live). Every lane performs the
 * scalar path's float operations in the same order (the cell stages of iso.h
 * below are written again in float8, operation for operation; sqrt and the
 * divisions are correctly rounded per lane), so each ray's result is bit for
 * bit the scalar one; lanes that are done or empty compute values that are
 * never used. The comparisons give -1 / 0 lane masks; c ? a : b selects per
 * lane. The hit's shading stays scalar, per lane. */
#if PACKET != 8
#error "PACKET is 0 or 8"
#endif

/* load_dual_brick by rows: the block's and its 7 neighbours' slots are read
 * once (not per sample), each row of 5 is one float4 load from its block and
 * one float from the +x neighbour, all independent (the bricks are cache
 * misses: they can be in flight together), and the samples outside the volume
 * become NaN after the loads. Work-item lid of lsize fills the z planes lid,
 * lid + lsize, ... The same values as load_dual_brick. */
inline void load_dual_brick_rows(local float *brick, global const float *bricks,
                                 global const int *slot_of_block, const int *n, const int *b0,
                                 uint nbx, uint nby, uint lid, uint lsize)
{
    int slot[8];
    for (int j = 0; j < 8; ++j) {
        const int ex = j & 1, ey = (j >> 1) & 1, ez = j >> 2;
        const int in = b0[0] + 4 * ex < n[0] && b0[1] + 4 * ey < n[1] && b0[2] + 4 * ez < n[2];
        slot[j] = in ? slot_of_block[clvis_zfp_block_id((uint)(b0[0] >> 2) + ex, (uint)(b0[1] >> 2) + ey,
                                                        (uint)(b0[2] >> 2) + ez, nbx, nby)]
                     : -1;
    }
    const int nxin = n[0] - b0[0];   /* samples of a row inside the volume (>= 1) */
    for (uint lz = lid; lz < BRICK_SIDE; lz += lsize) {
        const int z = (int)lz;
        for (int ly = 0; ly < BRICK_SIDE; ++ly) {
            const int j = 2 * (ly >> 2) + 4 * (z >> 2), s0 = slot[j], s1 = slot[j + 1];
            const ulong off = (ulong)(4 * (ly & 3) + 16 * (z & 3));
            float4 row = (float4)(NAN);
            float last = NAN;
            if (s0 >= 0)
                row = *(global const float4 *)(bricks + 64ul * (ulong)s0 + off);
            if (s1 >= 0)
                last = bricks[64ul * (ulong)s1 + off];
            const int in = b0[1] + ly < n[1] && b0[2] + z < n[2];
            local float *dst = brick + BRICK_SIDE * ly + 25 * z;
            dst[0] = in && 0 < nxin ? row.s0 : NAN;
            dst[1] = in && 1 < nxin ? row.s1 : NAN;
            dst[2] = in && 2 < nxin ? row.s2 : NAN;
            dst[3] = in && 3 < nxin ? row.s3 : NAN;
            dst[4] = in && 4 < nxin ? last : NAN;
        }
    }
}

inline float8 rt_fmin8(float8 a, float8 b)
{
    return (a < b || b != b) ? a : b;   /* clvis_il_fmin per lane */
}

inline float8 rt_fmax8(float8 a, float8 b)
{
    return (a > b || b != b) ? a : b;   /* clvis_il_fmax per lane */
}

inline float8 rt_clamp8(float8 x, float8 lo, float8 hi)
{
    return rt_fmin8(rt_fmax8(x, lo), hi);
}

inline float8 rt_copysign8(float8 x, float8 y)
{
    return as_float8((as_uint8(x) & (uint8)(0x7FFFFFFFu)) | (as_uint8(y) & (uint8)(0x80000000u)));
}

/* int8 <-> float8 lane conversions. Clang's __builtin_convertvector compiles
 * inline (PoCL 3 calls convert_float8 / convert_int8 out of line); other
 * compilers take the builtins, which give the same results (int -> float
 * rounds to nearest even, float -> int truncates toward zero). */
#if defined(__clang__) && defined(__has_builtin)
#if __has_builtin(__builtin_convertvector)
#define RT_CONVERTVECTOR 1
#endif
#endif
#ifdef RT_CONVERTVECTOR
#define rt_ftoi8(x) __builtin_convertvector((x), int8)
#else
#define rt_ftoi8(x) convert_int8(x)
#endif

inline float8 rt_itof8(int8 i)
{
#ifdef RT_CONVERTVECTOR
    return __builtin_convertvector(i, float8);
#else
    return convert_float8(i);
#endif
}

/* clvis_il_floor per lane (the truncation is used only where |x| < 2^23) */
inline float8 rt_floor8(float8 x)
{
    const int8 small = (as_uint8(x) & (uint8)(0x7FFFFFFFu)) < (uint8)(0x4B000000u);
    const int8 xi = small ? rt_ftoi8(x) : (int8)(0);
    float8 t = rt_itof8(xi);
    t = t > x ? t - 1.0f : t;
    t = as_float8(as_uint8(t) | (as_uint8(x) & (uint8)(0x80000000u)));
    return small ? t : x;
}

inline int rt_any8(int8 m)
{
    return clvis_il_any8(m);
}

inline float8 rt_horner8(const float8 *c, float8 s)
{
    return ((c[3] * s + c[2]) * s + c[1]) * s + c[0];
}

inline int8 rt_has_zero8(float8 fa, float8 fb)
{
    return (fa <= 0.0f && fb >= 0.0f) || (fa >= 0.0f && fb <= 0.0f);
}

inline float8 rt_interpolate8(float8 a, float8 b, float8 fa, float8 fb)
{
    float8 x = fb != fa ? a - fa * (b - a) / (fb - fa) : a;
    return rt_clamp8(x, rt_fmin8(a, b), rt_fmax8(a, b));
}

/* clvis_iso_cell_cubic per lane */
inline void rt_cell_cubic8(const float8 *v, const float8 *u, const float8 *D, float8 *cf)
{
    cf[0] = 0.0f;
    cf[1] = 0.0f;
    cf[2] = 0.0f;
    cf[3] = 0.0f;
    for (int k = 0; k < 8; ++k) {
        int ix = k & 1, iy = (k >> 1) & 1, iz = k >> 2;
        float8 ax = ix ? u[0] : 1.0f - u[0], ay = iy ? u[1] : 1.0f - u[1];
        float8 az = iz ? u[2] : 1.0f - u[2];
        float8 bxx = ix ? D[0] : -D[0], byy = iy ? D[1] : -D[1], bzz = iz ? D[2] : -D[2];
        cf[0] += v[k] * (ax * ay * az);
        cf[1] += v[k] * ((bxx * ay * az + ax * byy * az) + ax * ay * bzz);
        cf[2] += v[k] * ((bxx * byy * az + bxx * ay * bzz) + ax * byy * bzz);
        cf[3] += v[k] * (bxx * byy * bzz);
    }
}

/* clvis_iso_first_zero per lane, in two stages. rt_bracket8: the lanes with a
 * zero (-1) and their interval: the first of [0, r1], [r1, r2], [r2, len]
 * with a sign change or zero (ends a, b, values fa, fb). */
inline int8 rt_bracket8(const float8 *c, float8 len, float8 *a, float8 *b, float8 *fa, float8 *fb)
{
    const float8 A = 3.0f * c[3], B = 2.0f * c[2], C = c[1];
    const float8 disc = B * B - 4.0f * A * C;
    const int8 real = disc >= 0.0f, anz = A != 0.0f;
    const float8 q = -0.5f * (B + rt_copysign8(sqrt(disc), B));
    float8 r1 = real && anz ? q / A : (float8)(NAN);
    float8 r2 = real && anz && q != 0.0f ? C / q : (float8)(NAN);
    r1 = real && !anz && B != 0.0f ? -C / B : r1;
    r1 = (r1 > 0.0f && r1 < len) ? r1 : len;
    r2 = (r2 > 0.0f && r2 < len) ? r2 : len;
    const float8 pts[4] = {(float8)(0.0f), rt_fmin8(r1, r2), rt_fmax8(r1, r2), len};
    float8 f[4];
    f[0] = c[0];
    for (int k = 1; k < 4; ++k)
        f[k] = rt_horner8(c, pts[k]);
    int8 found = (int8)(0);
    for (int k = 0; k < 3; ++k) {
        const int8 z = rt_has_zero8(f[k], f[k + 1]) & ~found;   /* the first such interval */
        *a = z ? pts[k] : *a;
        *b = z ? pts[k + 1] : *b;
        *fa = z ? f[k] : *fa;
        *fb = z ? f[k + 1] : *fb;
        found |= z;
    }
    return found;
}

/* rt_refine8: the root in a bracket: a where fa == 0, else REFINE_STEPS
 * Illinois steps and the interpolation of the last bracket. */
inline float8 rt_refine8(const float8 *c, float8 a, float8 b, float8 fa, float8 fb)
{
    const int8 at_a = fa == 0.0f;
    const float8 a0 = a;
    int8 last_a = (int8)(0), last_b = (int8)(0);   /* a (b) was replaced last step */
    for (int i = 0; i < REFINE_STEPS; ++i) {
        const float8 x = rt_interpolate8(a, b, fa, fb);
        const float8 fx = rt_horner8(c, x);
        const int8 same_as_a = (fx > 0.0f && fa > 0.0f) || (fx < 0.0f && fa < 0.0f);
        const float8 fb_half = last_a ? fb * 0.5f : fb, fa_half = last_b ? fa * 0.5f : fa;
        fb = same_as_a ? fb_half : fx;
        fa = same_as_a ? fx : fa_half;
        a = same_as_a ? x : a;
        b = same_as_a ? b : x;
        last_a = same_as_a;
        last_b = ~same_as_a;
    }
    const float8 r = rt_interpolate8(a, b, fa, fb);
    return at_a ? a0 : r;
}


/* march_cells for the live lanes: per lane the scalar loop's result, *hit
 * (-1 at a hit) and *t (hit: t_in + s; else the new ray_t), at a hit also
 * v[8], u[3] and *s. */
inline void march_cells8(local const float *brick, const int *n, const int *b0, const int *clo,
                         const int *chi, const float8 *O, const float8 *D, const float8 *inv,
                         float8 t_exit, float isovalue, float8 t_stop, float8 t_in, int8 live,
                         int8 *hit, float8 *v, float8 *u, float8 *s, float8 *t)
{
    int8 c[3], step[3], up[3];
    for (int a = 0; a < 3; ++a) {
        const float8 gpos = rt_floor8(O[a] + t_in * D[a]);
        const int8 gi = rt_ftoi8(gpos);   /* used where clo <= gpos <= chi */
        c[a] = gpos >= (float)clo[a] ? (gpos <= (float)chi[a] ? gi : (int8)(chi[a])) : (int8)(clo[a]);
        up[a] = inv[a] > 0.0f;
        step[a] = up[a] ? (int8)(1) : (int8)(-1);
    }
    float8 res = t_in, hit_in = 0.0f, ha = 0.0f, hb = 0.0f, hfa = 0.0f, hfb = 0.0f;
    float8 hcf[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    int8 got = (int8)(0);
    while (rt_any8(live)) {
        const int8 stop = live & (t_in > t_stop);
        res = stop ? (float8)(INFINITY) : res;
        live &= ~stop;
        /* cell_exit */
        float8 tn[3];
        for (int a = 0; a < 3; ++a)
            tn[a] = (rt_itof8(c[a] - up[a]) - O[a]) * inv[a];   /* up is -1: c + 1 */
        float8 tb = tn[0];
        const int8 ay = tn[1] < tb;
        tb = ay ? tn[1] : tb;
        const int8 az = tn[2] < tb;
        tb = az ? tn[2] : tb;
        const int8 is_z = az, is_y = ay & ~az, is_x = ~(ay | az);
        const float8 t_out = rt_fmax8(t_in, rt_fmin8(tb, t_exit));
        /* cell_corners */
        const int8 base = live ? (c[0] - b0[0]) + BRICK_SIDE * ((c[1] - b0[1]) + BRICK_SIDE * (c[2] - b0[2])) : (int8)(0);
        float8 cv[8];
        float8 vmin = INFINITY, vmax = -INFINITY;
        for (int k = 0; k < 8; ++k) {
            const int off = (k & 1) + BRICK_SIDE * ((k >> 1) & 1) + 25 * (k >> 2);
            const float8 x = (float8)(brick[base.s0 + off], brick[base.s1 + off], brick[base.s2 + off],
                                      brick[base.s3 + off], brick[base.s4 + off], brick[base.s5 + off],
                                      brick[base.s6 + off], brick[base.s7 + off]);
            vmin = rt_fmin8(vmin, x);
            vmax = rt_fmax8(vmax, x);
            cv[k] = x - isovalue;
        }
        const int8 cand = live & (vmin <= isovalue && vmax >= isovalue);
        if (rt_any8(cand)) {
            float8 cu[3], cf[4];
            for (int a = 0; a < 3; ++a)
                cu[a] = (O[a] + t_in * D[a]) - rt_itof8(c[a]);
            rt_cell_cubic8(cv, cu, D, cf);
            float8 a = 0.0f, b = 0.0f, fa = 0.0f, fb = 0.0f;
            const int8 h = cand & rt_bracket8(cf, t_out - t_in, &a, &b, &fa, &fb);
            /* a hit: the lane keeps its cell's bracket; the roots are refined
             * once, after the loop, for all lanes together */
            hit_in = h ? t_in : hit_in;
            ha = h ? a : ha;
            hb = h ? b : hb;
            hfa = h ? fa : hfa;
            hfb = h ? fb : hfb;
            for (int k = 0; k < 4; ++k)
                hcf[k] = h ? cf[k] : hcf[k];
            for (int a = 0; a < 3; ++a)
                u[a] = h ? cu[a] : u[a];
            for (int k = 0; k < 8; ++k)
                v[k] = h ? cv[k] : v[k];
            got |= h;
            live &= ~h;
        }
        const int8 out = live & (t_out >= t_exit);
        res = out ? (float8)(INFINITY) : res;
        live &= ~out;
        c[0] += live & is_x ? step[0] : (int8)(0);
        c[1] += live & is_y ? step[1] : (int8)(0);
        c[2] += live & is_z ? step[2] : (int8)(0);
        /* the scalar loop tests the stepped axis only */
        const int8 is_a[3] = {is_x, is_y, is_z};
        int8 gone = (int8)(0), left = (int8)(0);
        for (int a = 0; a < 3; ++a) {
            gone |= is_a[a] & (c[a] < 0 || c[a] > n[a] - 2);
            left |= is_a[a] & (c[a] < clo[a] || c[a] > chi[a]);
        }
        gone &= live;
        res = gone ? (float8)(INFINITY) : res;
        live &= ~gone;
        left &= live;
        res = left ? t_out : res;
        live &= ~left;
        t_in = t_out;
    }
    if (rt_any8(got)) {
        *s = rt_refine8(hcf, ha, hb, hfa, hfb);
        res = got ? hit_in + *s : res;
    }
    *hit = got;
    *t = res;
}
#endif /* PACKET */

kernel void raytrace_blocks(global const float *bricks, global const int *slot_of_block,
                            uint nx, uint ny, uint nz, float dx, float dy, float dz,
                            float ox, float oy, float oz, float isovalue,
                            global const float *cam, uint W, uint p0,
                            global const uint *group_blocks, global const uint *group_offsets,
                            global const uint *group_counts, global const uint *ray_ids,
                            global float *ray_t, global uchar *ray_hit, global float *hit_t,
                            global float4 *rgba, global float *depth,
                            global const uint *item_pixel, uint n_spec, volatile global ulong *hitkey)
{
    local float brick[BRICK_SIDE * BRICK_SIDE * BRICK_SIDE];
    const uint g = get_group_id(0), lid = get_local_id(0), lsize = get_local_size(0);
    const uint nbx = clvis_zfp_blocks(nx), nby = clvis_zfp_blocks(ny), nbz = clvis_zfp_blocks(nz);
    uint bc[3];
    if (!clvis_zfp_grid_cell(group_blocks[g], nbx, nby, nbz, bc))
        return;     /* not a block of the grid (the whole group returns) */
    const int n[3] = {(int)nx, (int)ny, (int)nz};
    const int b0[3] = {4 * (int)bc[0], 4 * (int)bc[1], 4 * (int)bc[2]};

#if PACKET
    load_dual_brick_rows(brick, bricks, slot_of_block, n, b0, nbx, nby, lid, lsize);
#else
    load_dual_brick(brick, bricks, slot_of_block, n, b0, nbx, nby, lid, lsize);
#endif
    barrier(CLK_LOCAL_MEM_FENCE);

    const float sp[3] = {dx, dy, dz}, org[3] = {ox, oy, oz};
    int clo[3], chi[3];
    for (int a = 0; a < 3; ++a) {
        clo[a] = b0[a];
        chi[a] = clvis_il_imin(b0[a] + 3, n[a] - 2);
    }
    const uint count = group_counts[g], offset = group_offsets[g];

#if PACKET
    for (uint r0 = PACKET * lid; r0 < count; r0 += PACKET * lsize) {
        /* per lane k, ray r0 + k: first the loads of all lanes (cache misses:
         * in flight together), then the scalar set-up */
        uint pk[8], ek[8];
        int ok[8];
        float ltin[8], ltstop[8];
        for (int k = 0; k < 8; ++k) {
            const uint r = r0 + (uint)k;
            uint p = 0, e = 0;
            if (r < count) {
#if ITEMS
                e = ray_ids[offset + r];
                p = item_pixel[e / n_spec];
#else
                p = ray_ids[offset + r];
                e = p;
#endif
            }
            pk[k] = p;
            ek[k] = e;
        }
        for (int k = 0; k < 8; ++k) {
            const int on = r0 + (uint)k < count;
            ltin[k] = on ? ray_t[ek[k]] : 0.0f;
#if ITEMS && defined(CLVIS_INT64_ATOMICS)
            /* benign race (iso-skip): as in the scalar path below */
            ltstop[k] = on ? as_float(((volatile global uint *)hitkey)[clvis_hi_word(pk[k])]) : NAN;
#else
            ltstop[k] = NAN;
#endif
            ok[k] = on && !(ltin[k] > ltstop[k]) ? -1 : 0;   /* ITEMS: skipped past the nearest hit */
        }
        const int8 ok8 = CLVIS_IL_VLOAD8(int8, ok);
        if (!rt_any8(ok8))
            continue;   /* every lane empty or skipped */
        float8 o8[3], d8[3], O8[3], D8[3], inv8[3], texit8;
        float8 tenter8;   /* not needed here */
        clvis_iso_ray_setup8(cam, p0, pk, W, n, sp, org, o8, d8, O8, D8, inv8, &tenter8, &texit8);
        float lo[3][8], ld[3][8], lD[3][8];
        for (int a = 0; a < 3; ++a) {
            CLVIS_IL_VSTORE8(o8[a], lo[a]);
            CLVIS_IL_VSTORE8(d8[a], ld[a]);
            CLVIS_IL_VSTORE8(D8[a], lD[a]);
        }
        int8 hit8;
        float8 v8[8], u8[3], s8 = 0.0f, t8;
        for (int k = 0; k < 8; ++k)
            v8[k] = 0.0f;
        for (int a = 0; a < 3; ++a)
            u8[a] = 0.0f;
        march_cells8(brick, n, b0, clo, chi, O8, D8, inv8, texit8, isovalue, CLVIS_IL_VLOAD8(float8, ltstop),
                     CLVIS_IL_VLOAD8(float8, ltin), ok8, &hit8, v8, u8, &s8, &t8);
        int lhit[8];
        float lt[8], ls[8], lu[3][8], lv[8][8];
        CLVIS_IL_VSTORE8(hit8, lhit);
        CLVIS_IL_VSTORE8(t8, lt);
        CLVIS_IL_VSTORE8(s8, ls);
        for (int a = 0; a < 3; ++a)
            CLVIS_IL_VSTORE8(u8[a], lu[a]);
        for (int j = 0; j < 8; ++j)
            CLVIS_IL_VSTORE8(v8[j], lv[j]);
        for (int k = 0; k < 8; ++k) {
            if (!ok[k])
                continue;
            const uint p = pk[k], e = ek[k];
            const float t = lt[k];
            if (!lhit[k]) {
#if !ITEMS
                ray_t[p] = t;
#endif
                continue;
            }
            float v[8], w[3], grad[3], o[3], d[3];
            for (int j = 0; j < 8; ++j)
                v[j] = lv[j][k];
            for (int a = 0; a < 3; ++a) {
                o[a] = lo[a][k];
                d[a] = ld[a][k];
            }
            for (int a = 0; a < 3; ++a)
                w[a] = clvis_il_clamp(lu[a][k] + ls[k] * lD[a][k], 0.0f, 1.0f);
            clvis_iso_trilinear_gradient(v, w, grad);
            grad[0] /= dx;
            grad[1] /= dy;
            grad[2] /= dz;
            ray_hit[e] = 1;
            hit_t[e] = t;
#if ITEMS && defined(CLVIS_INT64_ATOMICS)
            clvis_atomic_min_u64(hitkey + p, ((ulong)as_uint(t) << 32) | e);
#endif
            rgba[e] = clvis_iso_shade(grad, d);
            depth[e] = clvis_ray_depth(cam, o, d, t);
        }
    }
#else
    for (uint r = lid; r < count; r += lsize) {
#if ITEMS
        const uint e = ray_ids[offset + r];             /* the item: (ray e / n_spec, candidate) */
        const uint p = item_pixel[e / n_spec];
#else
        const uint p = ray_ids[offset + r], e = p;      /* outputs and state per pixel */
#endif
        const float t_in = ray_t[e];
#if ITEMS && defined(CLVIS_INT64_ATOMICS)
        /* benign race (iso-skip): t_best, the t of the pixel's nearest hit so
         * far (all ones, a NaN, before any hit), is the high word of hitkey[p]
         * read with a plain (volatile) 32-bit load while other groups update
         * the entry with the atomic min below (Oclgrind reports each such
         * pair). The entry only ever decreases, so the value read, current or
         * stale, is >= the t the pixel ends with; this item's hit would lie at
         * t >= t_in, so when t_in > t_best it could not win and is skipped. A
         * stale value only skips less; it never skips an item that would win,
         * so the winner is what the atomics alone give. One aligned 32-bit
         * word (little-endian entries, clvis_hi_word of clvis/atomics.h), read
         * whole: the high half of a value the entry did hold. Not an atomic
         * read: OpenCL 1.2's only one is a read-modify-write (atom_add of 0),
         * measured to take back half of what the skip saves on PoCL. */
        const float t_best = as_float(((volatile global uint *)hitkey)[clvis_hi_word(p)]);
        if (t_in > t_best)
            continue;
#else
        const float t_best = NAN;
#endif
        float o[3], d[3], O[3], D[3], inv[3], t_enter, t_exit;
        clvis_iso_ray_setup(cam, p0 + p, W, n, sp, org, o, d, O, D, inv, &t_enter, &t_exit);
        int c[3];
        first_cell(O, D, t_in, clo, chi, c);
        float v[8], u[3], s, t;
        if (!march_cells(brick, n, b0, clo, chi, O, D, inv, t_exit, isovalue, t_best, t_in, c, v, u, &s, &t)) {
#if !ITEMS
            ray_t[p] = t;
#endif
            continue;
        }
        /* the hit: shade by the gradient of the cell's trilinear interpolant, world units */
        float w[3], grad[3];
        for (int a = 0; a < 3; ++a)
            w[a] = clvis_il_clamp(u[a] + s * D[a], 0.0f, 1.0f);
        clvis_iso_trilinear_gradient(v, w, grad);
        grad[0] /= dx;
        grad[1] /= dy;
        grad[2] /= dz;
        ray_hit[e] = 1;
        hit_t[e] = t;   /* ray_t stays */
#if ITEMS && defined(CLVIS_INT64_ATOMICS)
        /* the nearest hit of the pixel's items: t >= 0, so its bits order as uints */
        clvis_atomic_min_u64(hitkey + p, ((ulong)as_uint(t) << 32) | e);
#endif
        rgba[e] = clvis_iso_shade(grad, d);
        depth[e] = clvis_ray_depth(cam, o, d, t);
    }
#endif /* PACKET */
}
