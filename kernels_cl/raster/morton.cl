/* morton.cl — Morton order of a point cloud (Schütz et al. 2021: points sorted
 * along a Z-order curve hit the same pixels in turn, so early-z rejects most).
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/inline.h,
 *     clvis/morton.h).
 * No defines. One work-item per point: global size >= n, any local size.
 *
 * kernel morton_codes(global const float *positions, uint n,
 *                     float lox, float loy, float loz,
 *                     float sx, float sy, float sz, global uint *codes)
 *     positions: n points of 3 floats. q_a = (a - lo_a) * s_a (float32), clamped
 *     to [0, 1023] and truncated (clvis_morton_quantize); codes[i] =
 *     clvis_morton3(qx, qy, qz) (clvis/morton.h, 30 bits), or
 *     0xFFFFFFFF for a point with a NaN or infinite coordinate (sorted last).
 *     The kernel takes lo and s as given. clvis's codes (clvis.morton.scale,
 *     clvis/reference/morton.py) use lo_a, hi_a = the min and max of the
 *     finite points' coordinates (0, 0 when none is finite) and
 *     s_a = (float)(1023.0 / ((double)hi_a - (double)lo_a)), the extent and
 *     the division in double, or 0 for a flat axis; 1023.0f / (hi_a - lo_a)
 *     in float32 can round differently and move a few points to another cell.
 *
 * kernel gather_points(global const float *src, global const uint *perm, uint n,
 *                      global float *dst)
 *     dst point i = src point perm[i] (3 floats each).
 *
 * kernel invert_permutation(global const uint *perm, uint n, global uint *inv)
 *     inv[perm[i]] = i; perm must be a permutation of 0 .. n-1.
 *
 * kernel iota(uint n, global uint *out)
 *     out[i] = i.
 */
#pragma OPENCL FP_CONTRACT OFF

#include "clvis/inline.h"
#include "clvis/morton.h"

kernel void morton_codes(global const float *positions, uint n, float lox, float loy, float loz,
                         float sx, float sy, float sz, global uint *codes)
{
    uint i = get_global_id(0);
    if (i >= n)
        return;
    float x = positions[3 * (size_t)i], y = positions[3 * (size_t)i + 1],
          z = positions[3 * (size_t)i + 2];
    if (!(clvis_il_isfinite(x) && clvis_il_isfinite(y) && clvis_il_isfinite(z))) {
        codes[i] = 0xFFFFFFFFu;
        return;
    }
    codes[i] = clvis_morton3(clvis_morton_quantize((x - lox) * sx), clvis_morton_quantize((y - loy) * sy),
                             clvis_morton_quantize((z - loz) * sz));
}

kernel void gather_points(global const float *src, global const uint *perm, uint n,
                          global float *dst)
{
    uint i = get_global_id(0);
    if (i >= n)
        return;
    size_t j = perm[i];
    dst[3 * (size_t)i] = src[3 * j];
    dst[3 * (size_t)i + 1] = src[3 * j + 1];
    dst[3 * (size_t)i + 2] = src[3 * j + 2];
}

kernel void invert_permutation(global const uint *perm, uint n, global uint *inv)
{
    uint i = get_global_id(0);
    if (i < n)
        inv[perm[i]] = i;
}

kernel void iota(uint n, global uint *out)
{
    uint i = get_global_id(0);
    if (i < n)
        out[i] = i;
}
