/* macrocell.cl — the macrocell grids of the progressive isosurface raycaster
 * (Dyken, Usher, Kumar 2024), built from a ZFP fixed-rate stream on the device.
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/zfp.h).
 * No defines, no compiler flags. Includes clvis/zfp.h (stream layout, the
 * per-block decode). Volume [nz][ny][nx], blocks (bx, by, bz) of 4^3 samples,
 * block b = bx + nbx (by + nby bz), nb_ = ceil(n_ / 4), as in zfp.cl.
 *
 * The fine grid is the ZFP blocks. Block B's range is the value range of every
 * dual-grid cell whose minimum corner lies in B: the samples
 * [4 B_a .. min(4 B_a + 4, n_a - 1)] per axis a, the block dilated by its +x,
 * +y, +z neighbour samples. A block that holds no cell's minimum corner
 * (4 B_a >= n_a - 1 on some axis) gets the empty range (+inf, -inf). The
 * coarse grid: per 4^3 group of blocks, the min of their lo and the max of
 * their hi (the last group partial). clvis/reference/iso/macrocell.py block_ranges and
 * coarse_ranges give the same floats.
 *
 * kernel block_faces(global const ulong *stream, uint rate, uint nx, uint ny, uint nz,
 *                    global float2 *faces)
 *     Decodes each block once. faces[8 b + e] = (min, max) over the block's
 *     in-volume samples whose local coordinate is 0 along every axis in e
 *     (bit 0: x, bit 1: y, bit 2: z; e = 0: all its samples), (+inf, -inf)
 *     when there is none. One work-item per block: global >= nblocks, any
 *     local size.
 *
 * kernel block_ranges(global const float2 *faces, uint nx, uint ny, uint nz,
 *                     global float2 *ranges)
 *     ranges[b] = (lo, hi) of block b: the union of faces[8 (b + e) + e] over
 *     the neighbours b + e (e in {0, 1}^3) inside the grid, or (+inf, -inf)
 *     for a block without cells. One work-item per block.
 *
 * kernel coarse_ranges(global const float2 *ranges, uint nbx, uint nby, uint nbz,
 *                      global float2 *coarse)
 *     coarse[c] = the union of ranges over blocks [4 c_a .. 4 c_a + 3] per
 *     axis (inside the block grid), c = cx + ncx (cy + ncy cz), nc_ =
 *     ceil(nb_ / 4). One work-item per coarse cell.
 *
 * kernel range_bits(global const float2 *ranges, uint n, float isovalue, global uint *bits)
 *     The active bits of n ranges for one isovalue: bit j of bits[w] is 1 iff
 *     range 32 w + j holds it, lo <= isovalue <= hi ((+inf, -inf) and NaN:
 *     0); bits past n are 0. One work-item per word: global >= ceil(n / 32),
 *     any local size. macro_traverse (traverse.cl) reads the fine and coarse
 *     grids this way: 1 bit a block instead of 8 bytes, so the 64^3 blocks of
 *     a 256^3 volume take 32 KB (the CPU's L1 data cache) instead of 2 MB.
 *     clvis/reference/iso/macrocell.py range_bits gives the same words.
 */
#include "clvis/zfp.h"

inline float2 merge(float2 a, float2 b)
{
    return (float2)(fmin(a.x, b.x), fmax(a.y, b.y));
}

kernel __attribute__((vec_type_hint(ulong16))) void block_faces(global const ulong *stream, uint rate, uint nx, uint ny, uint nz,
                        global float2 *faces)
{
    ulong b = get_global_id(0);
    uint c[3], ext[3];
    int q[64], emax;
    if (!clvis_zfp_decode_volume_block(stream, rate, nx, ny, nz, b, c, ext, q, &emax))
        return;
    uint ex = ext[0], ey = ext[1], ez = ext[2];
    float2 f[8];
    for (uint e = 0; e < 8u; ++e)
        f[e] = (float2)(INFINITY, -INFINITY);
    for (uint z = 0; z < ez; ++z)
        for (uint y = 0; y < ey; ++y)
            for (uint x = 0; x < ex; ++x) {
                float v = clvis_zfp_value(q, 16u * z + 4u * y + x, emax);
                /* the faces this sample lies on: every e whose axes all have coordinate 0 */
                uint on = (x == 0u ? 1u : 0u) | (y == 0u ? 2u : 0u) | (z == 0u ? 4u : 0u);
                for (uint e = 0; e < 8u; ++e)
                    if ((e & on) == e)
                        f[e] = merge(f[e], (float2)(v, v));
            }
    for (uint e = 0; e < 8u; ++e)
        faces[8u * b + e] = f[e];
}

kernel void block_ranges(global const float2 *faces, uint nx, uint ny, uint nz, global float2 *ranges)
{
    uint nbx = clvis_zfp_blocks(nx), nby = clvis_zfp_blocks(ny), nbz = clvis_zfp_blocks(nz);
    ulong b = get_global_id(0);
    uint c[3];
    if (!clvis_zfp_grid_cell(b, nbx, nby, nbz, c))
        return;
    uint bx = c[0], by = c[1], bz = c[2];
    float2 r = (float2)(INFINITY, -INFINITY);
    /* no cell has its minimum corner in the block: the block starts at the last sample */
    if (4u * bx + 1u < nx && 4u * by + 1u < ny && 4u * bz + 1u < nz) {
        for (uint e = 0; e < 8u; ++e) {
            uint x = bx + (e & 1u), y = by + ((e >> 1) & 1u), z = bz + (e >> 2);
            if (x < nbx && y < nby && z < nbz)
                r = merge(r, faces[8u * (((ulong)z * nby + y) * nbx + x) + e]);
        }
    }
    ranges[b] = r;
}

kernel void coarse_ranges(global const float2 *ranges, uint nbx, uint nby, uint nbz, global float2 *coarse)
{
    uint ncx = clvis_zfp_blocks(nbx), ncy = clvis_zfp_blocks(nby), ncz = clvis_zfp_blocks(nbz);
    ulong c = get_global_id(0);
    uint cc[3];
    if (!clvis_zfp_grid_cell(c, ncx, ncy, ncz, cc))
        return;
    uint cx = cc[0], cy = cc[1], cz = cc[2];
    float2 r = (float2)(INFINITY, -INFINITY);
    for (uint z = 4u * cz; z < min(4u * cz + 4u, nbz); ++z)
        for (uint y = 4u * cy; y < min(4u * cy + 4u, nby); ++y)
            for (uint x = 4u * cx; x < min(4u * cx + 4u, nbx); ++x)
                r = merge(r, ranges[((ulong)z * nby + y) * nbx + x]);
    coarse[c] = r;
}

kernel void range_bits(global const float2 *ranges, uint n, float isovalue, global uint *bits)
{
    const uint w = get_global_id(0);
    if (w >= n / 32u + (n % 32u != 0u ? 1u : 0u))
        return;
    const uint j0 = 32u * w, m = min(32u, n - j0);
    uint word = 0u;
    for (uint j = 0u; j < m; ++j) {
        const float2 r = ranges[j0 + j];
        word |= (r.x <= isovalue && isovalue <= r.y ? 1u : 0u) << j;
    }
    bits[w] = word;
}
