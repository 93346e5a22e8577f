/* gaussians.cl — Gaussian records (clvis/gauss.h) and their bounding boxes.
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/gauss.h).
 * Build options: -cl-fp32-correctly-rounded-divide-sqrt (the whitening matrix
 * is bit-identical to clvis/reference/gauss/render.py). No defines.
 * One work-item per Gaussian: global size >= n, any local size.
 *
 * kernel gaussian_records(global const float *means,      n x 3
 *                         global const float *scales,     n x 3, >= 0
 *                         global const float *rotations,  n x 9, row-major R: R[j][k] = rotations[9i + 3j + k],
 *                                                          column k = axis k
 *                         global const float *values, global const float *opacities,   n each
 *                         uint n, float cutoff,
 *                         global clvis_gaussian *records, n records (clvis/gauss.h)
 *                         global float *boxes)             n x 6: lo xyz, hi xyz
 *     se_k = fmax(s_k, fmax(CLVIS_GAUSS_FLAT * max_j s_j, CLVIS_GAUSS_TINY)),
 *     w[3k + j] = R[j][k] / se_k. The box holds the cutoff-sigma ellipsoid
 *     {x : |W (x - mean)| <= cutoff} with margin: half extent along axis j
 *     h_j = cutoff * sqrt((R[j][0] se_0)^2 + (R[j][1] se_1)^2 + (R[j][2] se_2)^2),
 *     padded to h_j * 1.01 + 1e-6 |mean_j| + 1e-30 (R is orthonormal within
 *     1e-3; the pad also covers float rounding in the traversal).
 *
 * kernel gather_records(global const clvis_gaussian *src, global const uint *order, uint n,
 *                       global clvis_gaussian *dst)
 *     dst[j] = src[order[j]]: records in BVH leaf order.
 */
#pragma OPENCL FP_CONTRACT OFF

#include "clvis/gauss.h"

kernel void gaussian_records(global const float *means, global const float *scales,
                             global const float *rotations, global const float *values,
                             global const float *opacities, uint n, float cutoff,
                             global clvis_gaussian *records, global float *boxes)
{
    uint i = get_global_id(0);
    if (i >= n)
        return;
    float s0 = scales[3 * (size_t)i], s1 = scales[3 * (size_t)i + 1], s2 = scales[3 * (size_t)i + 2];
    float lim = fmax(CLVIS_GAUSS_FLAT * fmax(fmax(s0, s1), s2), CLVIS_GAUSS_TINY);
    float se[3] = {fmax(s0, lim), fmax(s1, lim), fmax(s2, lim)};
    global const float *R = rotations + 9 * (size_t)i;
    clvis_gaussian g;
    for (int k = 0; k < 3; ++k)
        for (int j = 0; j < 3; ++j)
            g.w[3 * k + j] = R[3 * j + k] / se[k];
    for (int j = 0; j < 3; ++j)
        g.mean[j] = means[3 * (size_t)i + j];
    g.value = values[i];
    g.opacity = opacities[i];
    records[i] = g;
    for (int j = 0; j < 3; ++j) {
        float a = R[3 * j] * se[0], b = R[3 * j + 1] * se[1], c = R[3 * j + 2] * se[2];
        float h = cutoff * sqrt((a * a + b * b) + c * c);
        h = (h * 1.01f + 1e-6f * fabs(g.mean[j])) + 1e-30f;
        boxes[6 * (size_t)i + j] = g.mean[j] - h;
        boxes[6 * (size_t)i + 3 + j] = g.mean[j] + h;
    }
}

kernel void gather_records(global const clvis_gaussian *src, global const uint *order, uint n,
                           global clvis_gaussian *dst)
{
    uint j = get_global_id(0);
    if (j < n)
        dst[j] = src[order[j]];
}
