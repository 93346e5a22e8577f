/* traverse.cl — macrocell traversal with speculation of the progressive
 * isosurface raycaster (Dyken, Usher, Kumar 2024): per ray, walk the coarse
 * macrocell grid (4^3 ZFP blocks per cell) and, inside the coarse cells whose
 * range holds the isovalue, the fine grid (the ZFP blocks), and record up to
 * n_spec candidate blocks (fine range holds the isovalue) in front-to-back
 * order. The traversal state between passes is the ray's t alone.
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/camera.h, clvis/iso.h).
 * Build options: -cl-fp32-correctly-rounded-divide-sqrt (FP_CONTRACT is OFF
 * below: every float operation rounds on its own, so
 * clvis/reference/iso/traverse.py reproduces the results bit for bit). Define PACKET: 0
 * (default: one pixel / one listed ray a work-item) or 8 (the cpu profile: 8
 * a work-item, their ray set-up, clvis_iso_ray_setup's operations, done once
 * in float8 lanes by clvis_iso_ray_setup8 (clvis/iso.h); macro_traverse then walks the 8 rays one
 * after the other). Both give the same values bit for bit.
 * Includes clvis/camera.h (the 22-float camera-ray buffer, clvis_camera_ray),
 * clvis/iso.h (clvis_iso_ray_setup: the ray in index space and its box
 * interval; the 1/d convention of clvis/ray.h). fmin, floor and min come
 * from clvis/inline.h (exact; PoCL calls the builtins out of line, several
 * per block step).
 *
 * Volume [nz][ny][nx] samples, nx, ny, nz >= 2; ZFP blocks of 4^3 samples,
 * block id b = bx + nbx (by + nby bz), nb_ = ceil(n_ / 4); coarse cell id
 * c = cx + ncx (cy + ncy cz), nc_ = ceil(nb_ / 4) (clvis.iso.macrocell_grids,
 * kernels_cl/iso/macrocell.cl). A float2 range is (lo, hi); a block or coarse
 * cell is active iff lo <= isovalue <= hi ((+inf, -inf) and NaN: never).
 * macro_traverse reads that test's result, one bit a cell (macrocell.cl's
 * range_bits for the launch's isovalue: cell id i is bit i % 32 of word
 * i / 32): the 64^3 blocks of a 256^3 volume are 32 KB of bits instead of
 * 2 MB of ranges, so the walk's per-block look-up stays in the CPU's L1
 * (macro_traverse's CPU ~-15 % on PoCL, bench/results/iso-cpu.md).
 *
 * Per ray (float32, the rules of clvis/reference/iso/traverse.py): o, d from the ray
 * buffer; O = (o - origin) / spacing, D = d / spacing, inv = spacing / d_safe
 * (|d| < TINY -> copysign(TINY, d)); t0 = (0 - O) inv, t1 = ((n - 1) - O) inv;
 * t_enter = max(0, max_a min(t0, t1)), t_exit = min_a max(t0, t1); the ray
 * meets the box iff t_enter <= t_exit.
 *
 * Blocks along the ray. Block b_a spans index space [4 b_a, min(4 b_a + 4,
 * n_a - 1)] (the dual cells whose minimum corner lies in it), b_a in [0,
 * ceil((n_a - 1) / 4)). With T_a(x) = (x - O_a) inv_a (a float32 boundary
 * parameter, monotone in x), the ray is in block b_a along axis a for t in
 * the half-open [T_a(entry bound), T_a(exit bound)) (entry bound 4 b_a, exit
 * min(4 b_a + 4, n_a - 1) when inv_a > 0; swapped when inv_a < 0), and in
 * block b for t in the intersection over the axes. This is the block DDA of
 * tests/iso/test_raytrace.py (t_next recomputed from the block index, the
 * same T) except that blocks whose segment has zero length (a ray through a
 * block edge or corner, where the DDA steps two axes at one t; ties x < y < z
 * only order those) are never candidates. So the candidate sequence does not
 * depend on how it is split into passes, and every candidate has
 * t_out > t_in (a pass always makes progress).
 *
 * Locating the block at t (t < t_exit): start from the raytrace first-cell
 * rule, b_a = clamp(floor(O_a + t D_a), 0, n_a - 2) >> 2, then move each axis
 * back while t < T_a(entry bound) and forward while t >= T_a(exit bound).
 * Then loop: if the block's coarse cell is inactive, t = min_a T_a(coarse
 * exit bound) (the coarse cell's exit: the exit bound of its last block
 * along the ray) and locate again; else the block's segment is
 * [t, t_out = min(t_exit, min_a T_a(exit bound))]; an active block is a
 * candidate (entered at t); t = t_out. The ray ends when t >= t_exit.
 * After the n_spec-th candidate the walk goes on to the next candidate and
 * stops at its entry t (the resume t: the next pass locates that block
 * first, so the walk to it is done once); it ends without one where no block
 * whose range holds the isovalue is left on the ray (ray_t +INFINITY: the
 * ray cannot hit, so it is finished in this pass, not one pass later).
 * The walk keeps each axis's exit-bound T_a of the current block and
 * recomputes it only when that axis steps (the same float32 expression, so
 * the same value as recomputing it every step), and leaves a run of inactive
 * coarse cells by a coarse DDA of the same form (t = min_a T_a(coarse exit
 * bound), each axis stepping its coarse cell while t >= that bound), placing
 * the blocks only in the active coarse cell it stops in: the same t and the
 * same candidates as locating the block after every coarse skip, with
 * ~0-1 bound products a step instead of 6+ (macro_traverse's CPU -32-41 %
 * on PoCL: bench/replay_iso_traverse.py, bench/results/iso-cpu.md).
 * Coarse skipping gives exactly the sequence of the fine grid alone.
 *
 * Tiles. A renderer may trace the image in tiles, ranges of pixels [p0, p0 + npix)
 * (bands of rows): the per-pixel arrays of a launch (ray_t, enters, and the
 * `active` ids) then hold the tile's pixels only, indexed by j = p - p0, and
 * the ray is always that of image pixel p = p0 + j (so a tile's rays are
 * bit for bit those of the whole image). p0 = 0, npix = W * H: the whole image.
 *
 * kernel init_rays(
 *     global const float *cam,           22 floats: the camera rays of clvis/camera.h
 *     uint W, uint p0, uint npix,        image width (pixel p = py * W + px); the tile's
 *                                        first pixel p0 and pixel count npix
 *     uint nx, uint ny, uint nz, float dx, float dy, float dz, float ox, float oy, float oz,
 *     global float *ray_t,               out, per tile pixel j: t_enter, +INFINITY when the ray misses
 *     global uchar *enters)              out, per tile pixel j: 1 when the ray meets the box, else 0
 *   Global size >= npix (PACKET=8: >= ceil(npix / 8)), any local size. (The host compacts `enters` into the
 *   active list with clvis.primitives.compact_indices: deterministic order.)
 *
 * kernel macro_traverse(
 *     uint nx, uint ny, uint nz,         volume samples per axis
 *     float dx, float dy, float dz,      spacing
 *     float ox, float oy, float oz,      origin: world position of sample (0, 0, 0)
 *     float isovalue,                    the isovalue fine_bits and coarse_bits were made for
 *                                        (not read: the bits hold its tests)
 *     global const float *cam, uint W,   ray buffer, image width
 *     uint p0,                           the tile's first pixel (0: the whole image)
 *     global const uint *fine_bits,      ceil(nbx * nby * nbz / 32) words: the active blocks
 *                                        (range_bits of the block ranges for isovalue)
 *     global const uint *coarse_bits,    ceil(ncx * ncy * ncz / 32) words: the active coarse cells
 *     global const uint *active,         tile pixel ids j of the rays to traverse (pixel p0 + j)
 *     global const uint *count,          count[0]: how many entries of `active`
 *     global float *ray_t,               per tile pixel j, in: resume t (t_enter for a new ray);
 *                                        out: where the ray has a candidate after the n_spec
 *                                        it recorded, the t where it enters that one (the walk
 *                                        goes on past the n_spec-th to find it); else +INFINITY:
 *                                        a ray with no candidate block left cannot hit, so it
 *                                        is finished (no hit) in this pass, not in the next
 *     uint n_spec,                       1..64 candidates per ray
 *     global uint *cand_block,           count x n_spec: [i * n_spec + k] the k-th candidate
 *                                        block id of ray active[i], 0xFFFFFFFF past the last
 *     global float *cand_t)              count x n_spec: the t where the ray enters it (the
 *                                        ray_t to hand to raytrace_blocks), +INFINITY past the last
 *   Global size >= count (PACKET=8: >= ceil(count / 8)), a multiple of the local
 *   size; one work-item per listed ray (PACKET=8: per 8 listed rays, active[8 g ..
 *   8 g + 7]); any local size (the host uses 64, or 16 on the cpu profile).
 *   A ray whose ray_t is not finite or exceeds t_exit gets no candidates and
 *   ray_t = +INFINITY.
 */
/* before the includes: clvis_camera_ray must not contract either */
#pragma OPENCL FP_CONTRACT OFF

#include "clvis/camera.h"
#include "clvis/iso.h"

#define NO_BLOCK 0xFFFFFFFFu


#ifndef PACKET
#define PACKET 0
#endif

kernel void init_rays(global const float *cam, uint W, uint p0, uint npix, uint nx, uint ny, uint nz,
                      float dx, float dy, float dz, float ox, float oy, float oz,
                      global float *ray_t, global uchar *enters)
{
    const int n[3] = {(int)nx, (int)ny, (int)nz};
    const float sp[3] = {dx, dy, dz}, org[3] = {ox, oy, oz};
#if PACKET == 8
    const uint j0 = 8u * get_global_id(0);   /* pixels j0 .. j0 + 7 of the tile */
    if (j0 >= npix)
        return;
    uint pix[8];
    for (int k = 0; k < 8; ++k)
        pix[k] = min(j0 + (uint)k, npix - 1u);   /* past the tile: a copy, not stored */
    float8 O[3], D[3], inv[3], te, tx;
    float8 o_[3], d_[3];
    clvis_iso_ray_setup8(cam, p0, pix, W, n, sp, org, o_, d_, O, D, inv, &te, &tx);
    const int8 in = te <= tx;
    float rt[8];
    int inl[8];
    CLVIS_IL_VSTORE8(in ? te : (float8)(INFINITY), rt);
    CLVIS_IL_VSTORE8(in, inl);
    if (j0 + 8u <= npix) {
        for (int k = 0; k < 8; ++k) {
            ray_t[j0 + (uint)k] = rt[k];
            enters[j0 + (uint)k] = (uchar)(inl[k] != 0);
        }
    } else {
        for (uint k = 0; j0 + k < npix; ++k) {
            ray_t[j0 + k] = rt[k];
            enters[j0 + k] = (uchar)(inl[k] != 0);
        }
    }
#else
    const uint j = get_global_id(0);
    if (j >= npix)
        return;
    float o[3], d[3], O[3], D[3], inv[3], te, tx;
    clvis_iso_ray_setup(cam, p0 + j, W, n, sp, org, o, d, O, D, inv, &te, &tx);
    const int in = te <= tx;
    ray_t[j] = in ? te : INFINITY;
    enters[j] = (uchar)in;
#endif
}

/* T_a of the block b's exit bound along the ray (the entry bound when `entry`) */
inline float block_bound_t(int b, int size, int n, float O, float inv, int entry)
{
    int up = inv > 0.0f;
    int hi = clvis_il_imin(size * b + size, n - 1), lo = size * b;
    int x = (up != entry) ? hi : lo;
    return ((float)x - O) * inv;
}

/* One axis of the block DDA: while the block has a successor along the ray
 * (b != last) and t is at or past its exit bound T (te), step to it and
 * recompute its exit bound (the same T as block_bound_t's). */
#define CLVIS_TRAV_ADVANCE(b, te, step, last, n, O, inv)              \
    while ((b) != (last) && t >= (te)) {                              \
        (b) += (step);                                                \
        (te) = block_bound_t((b), 4, (n), (O), (inv), 0);             \
    }

/* bit i of a range_bits array: cell i is active */
inline uint tr_bit(global const uint *bits, uint i)
{
    return (bits[i >> 5] >> (i & 31u)) & 1u;
}

/* The walk of ray active[i] (tile pixel p) from ray_t[p], given its set-up
 * (O, D, inv per axis, t_exit): its candidates and its resume t. */
inline void tr_walk(uint i, uint p, const int *n, const int *nb, const int *ncb, const int *nc,
                    const float *O, const float *D, const float *inv, float t_exit,
                    global const uint *fine_bits, global const uint *coarse_bits, global float *ray_t,
                    uint n_spec, global uint *cand_block, global float *cand_t)
{
    float t = ray_t[p];
    uint found = 0;
    float resume = INFINITY;
    if (t < t_exit) {   /* false for +INFINITY and NaN */
        int b[3];
        for (int a = 0; a < 3; ++a) {
            float g = clvis_il_floor(O[a] + t * D[a]);
            int c = g >= 0.0f ? (g <= (float)(n[a] - 2) ? (int)g : n[a] - 2) : 0;
            b[a] = c >> 2;
            /* back while t is before the block's entry along a */
            int step = inv[a] > 0.0f ? 1 : -1;
            while (b[a] - step >= 0 && b[a] - step < ncb[a]
                   && t < block_bound_t(b[a], 4, n[a], O[a], inv[a], 1))
                b[a] -= step;
        }
        /* The walk keeps, per axis, the block index, its step along the ray, the
         * last block along the ray and the T of the block's exit bound (so each
         * bound is computed once per block entered, not once per loop step). */
        const float Ox = O[0], Oy = O[1], Oz = O[2], ix = inv[0], iy = inv[1], iz = inv[2];
        const int sx = ix > 0.0f ? 1 : -1, sy = iy > 0.0f ? 1 : -1, sz = iz > 0.0f ? 1 : -1;
        const int lx = sx > 0 ? ncb[0] - 1 : 0, ly = sy > 0 ? ncb[1] - 1 : 0, lz = sz > 0 ? ncb[2] - 1 : 0;
        int bx = b[0], by = b[1], bz = b[2];
        const int mx = lx >> 2, my = ly >> 2, mz = lz >> 2;   /* the coarse cells of the last blocks */
        float ex = block_bound_t(bx, 4, n[0], Ox, ix, 0), ey = block_bound_t(by, 4, n[1], Oy, iy, 0),
              ez = block_bound_t(bz, 4, n[2], Oz, iz, 0);
        for (;;) {
            if (!(t < t_exit))
                break;
            /* forward while t is at or past the block's exit along a (stays in range: t < t_exit) */
            CLVIS_TRAV_ADVANCE(bx, ex, sx, lx, n[0], Ox, ix);
            CLVIS_TRAV_ADVANCE(by, ey, sy, ly, n[1], Oy, iy);
            CLVIS_TRAV_ADVANCE(bz, ez, sz, lz, n[2], Oz, iz);
            const int cx = bx >> 2, cy = by >> 2, cz = bz >> 2;
            if (!tr_bit(coarse_bits, (uint)(cx + nc[0] * (cy + nc[1] * cz)))) {
                /* The coarse walk: per axis the coarse cell and the T of its exit bound (the
                 * exit bound of its last block along the ray, the same integer x, so the
                 * same T), stepped like the blocks: t = the nearest coarse exit, the cells
                 * it passes, until an active coarse cell or t_exit. The coarse cell at t
                 * is the one holding the block at t, so this is the fine walk's sequence
                 * of t without locating the blocks inside each inactive coarse cell. */
                int kx = cx, ky = cy, kz = cz, stuck = 0;
                float fx = block_bound_t(kx, 16, n[0], Ox, ix, 0), fy = block_bound_t(ky, 16, n[1], Oy, iy, 0),
                      fz = block_bound_t(kz, 16, n[2], Oz, iz, 0);
                for (;;) {
                    const float tc = clvis_il_fmin(clvis_il_fmin(clvis_il_fmin(INFINITY, fx), fy), fz);
                    if (!(tc > t)) {   /* cannot happen (the block's exit is > t); never loop */
                        stuck = 1;
                        break;
                    }
                    t = tc;
                    if (!(t < t_exit))
                        break;
                    while (kx != mx && t >= fx) {
                        kx += sx;
                        fx = block_bound_t(kx, 16, n[0], Ox, ix, 0);
                    }
                    while (ky != my && t >= fy) {
                        ky += sy;
                        fy = block_bound_t(ky, 16, n[1], Oy, iy, 0);
                    }
                    while (kz != mz && t >= fz) {
                        kz += sz;
                        fz = block_bound_t(kz, 16, n[2], Oz, iz, 0);
                    }
                    if (tr_bit(coarse_bits, (uint)(kx + nc[0] * (ky + nc[1] * kz))))
                        break;
                }
                if (stuck)
                    break;
                /* an axis that changed coarse cell restarts at that cell's first block along
                 * the ray (its blocks before it end at or before the coarse entry <= t); the
                 * forward moves at the top of the loop then find the block at t */
                if (kx != cx) {
                    bx = sx > 0 ? 4 * kx : clvis_il_imin(4 * kx + 3, ncb[0] - 1);
                    ex = block_bound_t(bx, 4, n[0], Ox, ix, 0);
                }
                if (ky != cy) {
                    by = sy > 0 ? 4 * ky : clvis_il_imin(4 * ky + 3, ncb[1] - 1);
                    ey = block_bound_t(by, 4, n[1], Oy, iy, 0);
                }
                if (kz != cz) {
                    bz = sz > 0 ? 4 * kz : clvis_il_imin(4 * kz + 3, ncb[2] - 1);
                    ez = block_bound_t(bz, 4, n[2], Oz, iz, 0);
                }
                continue;
            }
            const float t_out = clvis_il_fmin(clvis_il_fmin(clvis_il_fmin(t_exit, ex), ey), ez);
            const uint id = (uint)bx + (uint)nb[0] * ((uint)by + (uint)nb[1] * (uint)bz);
            if (tr_bit(fine_bits, id)) {
                if (found == n_spec) {   /* the next pass's first candidate: resume at its entry */
                    resume = t;
                    break;
                }
                cand_block[i * n_spec + found] = id;
                cand_t[i * n_spec + found] = t;
                ++found;
            }
            t = t_out;
        }
    }
    for (uint k = found; k < n_spec; ++k) {
        cand_block[i * n_spec + k] = NO_BLOCK;
        cand_t[i * n_spec + k] = INFINITY;
    }
    ray_t[p] = resume;
}

kernel void macro_traverse(uint nx, uint ny, uint nz, float dx, float dy, float dz,
                           float ox, float oy, float oz, float isovalue,
                           global const float *cam, uint W, uint p0,
                           global const uint *fine_bits, global const uint *coarse_bits,
                           global const uint *active, global const uint *count,
                           global float *ray_t, uint n_spec,
                           global uint *cand_block, global float *cand_t)
{
    const int n[3] = {(int)nx, (int)ny, (int)nz};
    const float sp[3] = {dx, dy, dz}, org[3] = {ox, oy, oz};
    const int nb[3] = {(n[0] + 3) >> 2, (n[1] + 3) >> 2, (n[2] + 3) >> 2};
    const int ncb[3] = {(n[0] + 2) >> 2, (n[1] + 2) >> 2, (n[2] + 2) >> 2};  /* blocks with cells */
    const int nc[3] = {(nb[0] + 3) >> 2, (nb[1] + 3) >> 2, (nb[2] + 3) >> 2};
    const uint cnt = count[0];
#if PACKET == 8
    /* rays active[i0 .. i0 + 7]: the set-up in float8 lanes, then each lane's walk */
    const uint i0 = 8u * get_global_id(0);
    if (i0 >= cnt)
        return;
    const uint m = min(8u, cnt - i0);
    uint pix[8];
    for (uint k = 0; k < 8u; ++k)
        pix[k] = active[i0 + min(k, m - 1u)];   /* past the list: a copy, not walked */
    float8 O8[3], D8[3], inv8[3], te8, tx8;
    float8 o8_[3], d8_[3];
    clvis_iso_ray_setup8(cam, p0, pix, W, n, sp, org, o8_, d8_, O8, D8, inv8, &te8, &tx8);
    float lO[3][8], lD[3][8], linv[3][8], ltx[8];
    for (int a = 0; a < 3; ++a) {
        CLVIS_IL_VSTORE8(O8[a], lO[a]);
        CLVIS_IL_VSTORE8(D8[a], lD[a]);
        CLVIS_IL_VSTORE8(inv8[a], linv[a]);
    }
    CLVIS_IL_VSTORE8(tx8, ltx);
    for (uint k = 0; k < m; ++k) {
        const float O[3] = {lO[0][k], lO[1][k], lO[2][k]}, D[3] = {lD[0][k], lD[1][k], lD[2][k]};
        const float inv[3] = {linv[0][k], linv[1][k], linv[2][k]};
        tr_walk(i0 + k, pix[k], n, nb, ncb, nc, O, D, inv, ltx[k], fine_bits, coarse_bits, ray_t,
                n_spec, cand_block, cand_t);
    }
#else
    const uint i = get_global_id(0);
    if (i >= cnt)
        return;
    const uint p = active[i];   /* the tile's pixel: image pixel p0 + p */
    float o[3], d[3], O[3], D[3], inv[3], te, t_exit;
    clvis_iso_ray_setup(cam, p0 + p, W, n, sp, org, o, d, O, D, inv, &te, &t_exit);
    tr_walk(i, p, n, nb, ncb, nc, O, D, inv, t_exit, fine_bits, coarse_bits, ray_t, n_spec,
            cand_block, cand_t);
#endif
}
