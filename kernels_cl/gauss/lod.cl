/* lod.cl — Gaussians from a sparse volume at three levels of detail
 * (Sharma & Schmalstieg, "3D Gaussian Particle Approximation of VDB Datasets").
 *
 * ABI
 * ---
 * No defines. Build with -cl-fp32-correctly-rounded-divide-sqrt (the mean of a
 * leaf divides by its voxel count and must round like IEEE division). The file
 * sets FP_CONTRACT OFF: every float operation below rounds on its own, so a
 * host can repeat the arithmetic bit for bit (clvis/reference/gauss/lod.py).
 *
 * The sparse volume (clvis.gauss.SparseVolume): L leaves of 8x8x8 voxels.
 *   coords       int   [3 L]   voxel index (z, y, x) of each leaf's first voxel
 *   masks        uint  [16 L]  active voxels: voxel i = 64 z + 8 y + x of a leaf
 *                              (leaf-local z, y, x) is bit (i & 31) of word i >> 5
 *   rows         int   [L]     the leaf's row of `values`, or -1 for a tile
 *   tile_values  float [L]     the value of every voxel of a tile leaf
 *   values       float [512 V] voxel values of the non-tile leaves, index 64 z + 8 y + x
 * A tile has all 512 voxels active. A leaf is *dense* when all 512 voxels are
 * active (tiles included), *sparse* otherwise (every leaf has an active voxel).
 *
 * lod: 0 low, 1 medium, 2 high. What each leaf yields, in this order:
 *   low     1 Gaussian: the bounding box of the active voxels; value = their mean.
 *   medium  dense leaf: its 8 blocks of 4^3 voxels. Sparse leaf: its 64 blocks
 *           of 2^3 voxels in turn: a block with all 8 voxels active gives one
 *           Gaussian, any other block one Gaussian per active voxel (z-y-x
 *           order within the block).
 *   high    dense leaf: its 64 blocks of 2^3 voxels. Sparse leaf: one Gaussian
 *           per active voxel.
 * Blocks run in z-y-x order within the leaf. A Gaussian covers a box of
 * voxels, first voxel index f and last l = f + e - 1 along each axis:
 *   mean_a  = ((float)f_a * d_a + o_a + ((float)l_a * d_a + o_a)) * 0.5f
 *   scale_a = 0.5f * ((float)e_a * d_a)
 * for a = x, y, z (d = spacing, o = origin). value: a single voxel's value; a
 * block's mean = s / n with s the sum of its n voxels taken one by one in
 * z-y-x order from s = 0.0f (a tile: its value). The low mean: 64 row sums
 * (row r = 8 z + y, s_r = sum over x = 0..7 of (active ? v : 0.0f), from 0.0f),
 * then s_r += s_{r+h} for h = 32, 16, 8, 4, 2, 1 (r < h), mean = s_0 / (float)count
 * (a tile: its value). Rotations are the identity and opacities 1 (the host's).
 *
 * kernel lod_count(global const uint *masks, uint nleaves, uint lod,
 *                  global uint *counts)
 *     counts[leaf] = number of Gaussians of the leaf. One work-item per leaf:
 *     global size >= nleaves, any local size.
 *
 * kernel lod_emit(global const int *coords, global const uint *masks,
 *                 global const int *rows, global const float *tile_values,
 *                 global const float *values, uint nleaves, uint lod,
 *                 float dz, float dy, float dx, float ox, float oy, float oz,
 *                 global const uint *offsets, global float *means,
 *                 global float *scales, global float *out_values)
 *     One work-group of exactly 64 work-items per leaf: global size 64 * nleaves,
 *     local size 64. offsets: exclusive prefix sum of lod_count's counts; the
 *     Gaussians of leaf k are written at rows offsets[k] ... of means (x, y, z
 *     float triples), scales (sigma_x, sigma_y, sigma_z) and out_values.
 */
#pragma OPENCL FP_CONTRACT OFF

#define WG 64
#define LEAF_VOXELS 512

/* the 8 active bits of row r = 8 z + y (bit x) */
inline uint row_bits(global const uint *m, uint r)
{
    return (m[r >> 2] >> ((r & 3u) * 8u)) & 0xffu;
}

inline int leaf_is_dense(global const uint *m)
{
    uint all = 0xffffffffu;
    for (uint k = 0; k < 16u; ++k)
        all &= m[k];
    return all == 0xffffffffu;
}

/* the active bits of 2^3 block b (bz = b >> 4, by = b >> 2 & 3, bx = b & 3),
 * bit 4 dz + 2 dy + dx */
inline uint block2_bits(global const uint *m, uint b)
{
    uint z = 2u * (b >> 4), y = 2u * ((b >> 2) & 3u), x = 2u * (b & 3u);
    return ((row_bits(m, 8u * z + y) >> x) & 3u)
         | (((row_bits(m, 8u * z + y + 1u) >> x) & 3u) << 2)
         | (((row_bits(m, 8u * (z + 1u) + y) >> x) & 3u) << 4)
         | (((row_bits(m, 8u * (z + 1u) + y + 1u) >> x) & 3u) << 6);
}

/* Gaussians of work unit t (0..63) of a leaf: the order of the units is the
 * order of the output */
inline uint unit_count(global const uint *m, uint lod, int dense, uint t)
{
    if (lod == 0u)
        return t == 0u ? 1u : 0u;
    if (dense)
        return (lod == 2u || t < 8u) ? 1u : 0u;
    if (lod == 2u)
        return popcount(row_bits(m, t));
    uint bm = block2_bits(m, t);
    return bm == 0xffu ? 1u : popcount(bm);
}

kernel void lod_count(global const uint *masks, uint nleaves, uint lod, global uint *counts)
{
    uint leaf = get_global_id(0);
    if (leaf >= nleaves)
        return;
    global const uint *m = masks + 16 * (size_t)leaf;
    int dense = leaf_is_dense(m);
    uint n = 0;
    for (uint t = 0; t < WG; ++t)
        n += unit_count(m, lod, dense, t);
    counts[leaf] = n;
}

inline uint ctz32(uint x)
{
    return 31u - clz(x & (0u - x));
}

inline float centre(int f, uint e, float d, float o)
{
    float a = (float)f * d + o;
    float b = (float)(f + (int)e - 1) * d + o;
    return (a + b) * 0.5f;
}

/* one Gaussian: first voxel (z, y, x) = f, extent (ez, ey, ex) voxels */
inline void write_gaussian(size_t g, int fz, int fy, int fx, uint ez, uint ey, uint ex, float value,
                           float dz, float dy, float dx, float ox, float oy, float oz,
                           global float *means, global float *scales, global float *out_values)
{
    means[3 * g] = centre(fx, ex, dx, ox);
    means[3 * g + 1] = centre(fy, ey, dy, oy);
    means[3 * g + 2] = centre(fz, ez, dz, oz);
    scales[3 * g] = 0.5f * ((float)ex * dx);
    scales[3 * g + 1] = 0.5f * ((float)ey * dy);
    scales[3 * g + 2] = 0.5f * ((float)ez * dz);
    out_values[g] = value;
}

/* Work-group steps, written out (no loop around a barrier) */
#define LOW_STEP(S)                                                     \
    if (t < (S)) {                                                      \
        psum[t] = psum[t] + psum[t + (S)];                              \
        pcnt[t] += pcnt[t + (S)];                                       \
        for (uint a = 0; a < 3u; ++a) {                                 \
            plo[a * WG + t] = min(plo[a * WG + t], plo[a * WG + t + (S)]); \
            phi[a * WG + t] = max(phi[a * WG + t], phi[a * WG + t + (S)]); \
        }                                                               \
    }                                                                   \
    barrier(CLK_LOCAL_MEM_FENCE);

#define SCAN_STEP(OFF)                                                  \
    {                                                                   \
        uint y_ = t >= (OFF) ? pscan[t - (OFF)] : 0u;                   \
        barrier(CLK_LOCAL_MEM_FENCE);                                   \
        pscan[t] += y_;                                                 \
        barrier(CLK_LOCAL_MEM_FENCE);                                   \
    }

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void lod_emit(global const int *coords, global const uint *masks, global const int *rows,
              global const float *tile_values, global const float *values, uint nleaves, uint lod,
              float dz, float dy, float dx, float ox, float oy, float oz,
              global const uint *offsets, global float *means, global float *scales,
              global float *out_values)
{
    local float vals[LEAF_VOXELS];
    local float psum[WG];
    local uint pcnt[WG];
    local uint plo[3 * WG];
    local uint phi[3 * WG];
    local uint pscan[WG];

    const uint leaf = get_group_id(0);
    const uint t = get_local_id(0);
    if (leaf >= nleaves)
        return;                         /* uniform over the group */
    global const uint *m = masks + 16 * (size_t)leaf;
    const int row = rows[leaf];
    const float tv = tile_values[leaf];
    const int cz = coords[3 * (size_t)leaf], cy = coords[3 * (size_t)leaf + 1],
              cx = coords[3 * (size_t)leaf + 2];
    const int dense = leaf_is_dense(m);

    /* phase 1: the leaf into local memory, row t by work-item t */
    for (uint x = 0; x < 8u; ++x)
        vals[8u * t + x] = row >= 0 ? values[(size_t)LEAF_VOXELS * (size_t)row + 8u * t + x] : tv;
    barrier(CLK_LOCAL_MEM_FENCE);

    if (lod == 0u) {
        /* low: row sums and row bounding boxes, then a tree over the 64 rows */
        uint rb = row_bits(m, t);
        float s = 0.0f;
        for (uint x = 0; x < 8u; ++x)
            s += ((rb >> x) & 1u) ? vals[8u * t + x] : 0.0f;
        psum[t] = s;
        pcnt[t] = popcount(rb);
        uint z = t >> 3, y = t & 7u;
        plo[t] = rb ? z : 0xffu;
        phi[t] = rb ? z : 0u;
        plo[WG + t] = rb ? y : 0xffu;
        phi[WG + t] = rb ? y : 0u;
        plo[2 * WG + t] = rb ? ctz32(rb) : 0xffu;
        phi[2 * WG + t] = rb ? 31u - clz(rb) : 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        LOW_STEP(32) LOW_STEP(16) LOW_STEP(8) LOW_STEP(4) LOW_STEP(2) LOW_STEP(1)
        if (t == 0u) {
            float value = row < 0 ? tv : psum[0] / (float)pcnt[0];
            write_gaussian(offsets[leaf], cz + (int)plo[0], cy + (int)plo[WG], cx + (int)plo[2 * WG],
                           phi[0] - plo[0] + 1u, phi[WG] - plo[WG] + 1u,
                           phi[2 * WG] - plo[2 * WG] + 1u, value,
                           dz, dy, dx, ox, oy, oz, means, scales, out_values);
        }
        return;
    }

    /* medium / high: work-item t is unit t; its Gaussians (at most 8) first
     * into private memory, then a scan of the counts places them */
    const uint cnt = unit_count(m, lod, dense, t);
    float pv[8];
    uint pf[8];
    uint pn = 1u;
    if (dense) {
        if (cnt) {
            const uint n = lod == 2u ? 2u : 4u, nb = 8u / n;
            const uint bz = n * (t / (nb * nb)), by = n * ((t / nb) % nb), bx = n * (t % nb);
            float s = 0.0f;
            for (uint z = 0; z < n; ++z)
                for (uint y = 0; y < n; ++y)
                    for (uint x = 0; x < n; ++x)
                        s += vals[64u * (bz + z) + 8u * (by + y) + bx + x];
            pv[0] = row < 0 ? tv : s / (float)(n * n * n);
            pf[0] = 64u * bz + 8u * by + bx;
            pn = n;
        }
    } else if (lod == 2u) {
        const uint rb = row_bits(m, t);
        uint j = 0;
        for (uint x = 0; x < 8u; ++x) {
            if ((rb >> x) & 1u) {
                pv[j] = vals[8u * t + x];
                pf[j] = 8u * t + x;
                ++j;
            }
        }
    } else {
        const uint bm = block2_bits(m, t);
        const uint first = 64u * (2u * (t >> 4)) + 8u * (2u * ((t >> 2) & 3u)) + 2u * (t & 3u);
        if (bm == 0xffu) {
            float s = 0.0f;
            for (uint k = 0; k < 8u; ++k)
                s += vals[first + 64u * (k >> 2) + 8u * ((k >> 1) & 1u) + (k & 1u)];
            pv[0] = s / 8.0f;
            pf[0] = first;
            pn = 2u;
        } else {
            uint j = 0;
            for (uint k = 0; k < 8u; ++k) {
                if ((bm >> k) & 1u) {
                    uint i = first + 64u * (k >> 2) + 8u * ((k >> 1) & 1u) + (k & 1u);
                    pv[j] = vals[i];
                    pf[j] = i;
                    ++j;
                }
            }
        }
    }

    pscan[t] = cnt;
    barrier(CLK_LOCAL_MEM_FENCE);
    SCAN_STEP(1) SCAN_STEP(2) SCAN_STEP(4) SCAN_STEP(8) SCAN_STEP(16) SCAN_STEP(32)
    const size_t base = (size_t)offsets[leaf] + (pscan[t] - cnt);
    for (uint j = 0; j < cnt; ++j) {
        const uint f = pf[j];
        write_gaussian(base + j, cz + (int)(f >> 6), cy + (int)((f >> 3) & 7u), cx + (int)(f & 7u),
                       pn, pn, pn, pv[j], dz, dy, dx, ox, oy, oz, means, scales, out_values);
    }
}
