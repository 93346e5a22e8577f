/* raytrace.cl — block raytracing of the progressive isosurface raycaster
 * (Dyken, Usher, Kumar 2024): the rays waiting at one 4^3 ZFP block are traced
 * through that block's dual cells against its decoded brick.
 *
 * ABI
 * ---
 * Build options: -cl-fp32-correctly-rounded-divide-sqrt (FP_CONTRACT is OFF
 * below: every float operation rounds on its own).
 * Defines:
 *   ITEMS         0 (default): ray_ids are pixels, ray_t / ray_hit / hit_t /
 *                 rgba / depth are per pixel, as described below.
 *                 1: speculation. ray_ids are *items* e = i * n_spec + k, the
 *                 k-th candidate block of active ray i (pixel item_pixel[i]);
 *                 ray_t[e] is the t where item e enters its block (cand_t of
 *                 traverse.cl; read only), and ray_hit / hit_t / rgba / depth
 *                 are per item. With CLVIS_INT64_ATOMICS, a hit also does
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
 *     global const float *bricks,        slots x 64 floats: the block cache
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
 *   Global size: groups x L, local size L (any L; the host uses 64 or 16): work-group g
 *   traces block group_blocks[g], work-item i its rays i, i + L, ... < group_counts[g].
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

    load_dual_brick(brick, bricks, slot_of_block, n, b0, nbx, nby, lid, lsize);
    barrier(CLK_LOCAL_MEM_FENCE);

    const float sp[3] = {dx, dy, dz}, org[3] = {ox, oy, oz};
    int clo[3], chi[3];
    for (int a = 0; a < 3; ++a) {
        clo[a] = b0[a];
        chi[a] = clvis_il_imin(b0[a] + 3, n[a] - 2);
    }
    const uint count = group_counts[g], offset = group_offsets[g];

    for (uint r = lid; r < count; r += lsize) {
#if ITEMS
        const uint e = ray_ids[offset + r];             /* the item: (ray e / n_spec, candidate) */
        const uint p = item_pixel[e / n_spec];
#else
        const uint p = ray_ids[offset + r], e = p;      /* outputs and state per pixel */
#endif
        const float t_in = ray_t[e];
#if ITEMS && CLVIS_INT64_ATOMICS
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
#if ITEMS && CLVIS_INT64_ATOMICS
        /* the nearest hit of the pixel's items: t >= 0, so its bits order as uints */
        clvis_atomic_min_u64(hitkey + p, ((ulong)as_uint(t) << 32) | e);
#endif
        rgba[e] = clvis_iso_shade(grad, d);
        depth[e] = clvis_ray_depth(cam, o, d, t);
    }
}
