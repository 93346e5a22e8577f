/* clvis/gauss.h — Gaussian records of the gauss family and the ray–Gaussian test.
 *
 * A Gaussian's density along a ray is opacity * exp(-m^2 / 2), m the
 * Mahalanobis distance. Kernels test rays against a *record*, which holds the
 * whitening matrix W = diag(1 / s) R^T (R's columns are the Gaussian's axes, s
 * its standard deviations along them), so that m = |W (x - mean)|.
 *
 *   typedef struct {          byte offset
 *       float mean[3];        0   world position
 *       float value;          12  scalar the transfer function maps to colour
 *       float w[9];           16  W row-major: w[3k + j] = R[j][k] / s_k
 *       float opacity;        52  in [0, 1]
 *   } clvis_gaussian;         56 bytes, 4-byte aligned (numpy: clvis.gauss.render.GAUSSIAN_DTYPE)
 *
 * Degenerate Gaussians: s_k is clamped below to max(CLVIS_GAUSS_FLAT * max_j s_j,
 * CLVIS_GAUSS_TINY) before W is formed, so a flat Gaussian is a thin slab.
 *
 * Camera rays (the 22-float buffer, clvis_camera_ray, clvis_dot3): clvis/camera.h.
 *
 * clvis_gauss_hit(g, o, d, &t, &m2, &ts, &a): the ray's closest approach to g
 * in the Mahalanobis sense over t >= 0:
 *   r = o - mean; o' = W r; d' = W d             (each row ((w0 r0 + w1 r1) + w2 r2))
 *   a = |d'|^2, b = o'.d', ts = -b / a            (ts: the unclamped maximum)
 *   t = fmax(ts, 0); m2 = |o' + t d'|^2
 * A ray hits g when m2 <= cutoff^2; t orders the hits (ties by Gaussian id).
 */
#ifndef CLVIS_GAUSS_H
#define CLVIS_GAUSS_H

#include "clvis/camera.h"

#define CLVIS_GAUSS_FLAT 1e-3f
#define CLVIS_GAUSS_TINY 1e-30f

typedef struct {
    float mean[3];
    float value;
    float w[9];
    float opacity;
} clvis_gaussian;

inline void clvis_gauss_hit(global const clvis_gaussian *g, const float *o, const float *d,
                            float *t, float *m2, float *ts, float *a, float *op, float *dp)
{
    float r0 = o[0] - g->mean[0], r1 = o[1] - g->mean[1], r2 = o[2] - g->mean[2];
    for (int k = 0; k < 3; ++k) {
        op[k] = clvis_dot3(g->w[3 * k], g->w[3 * k + 1], g->w[3 * k + 2], r0, r1, r2);
        dp[k] = clvis_dot3(g->w[3 * k], g->w[3 * k + 1], g->w[3 * k + 2], d[0], d[1], d[2]);
    }
    *a = clvis_dot3(dp[0], dp[1], dp[2], dp[0], dp[1], dp[2]);
    float b = clvis_dot3(op[0], op[1], op[2], dp[0], dp[1], dp[2]);
    *ts = -b / *a;
    *t = fmax(*ts, 0.0f);
    float p0 = op[0] + *t * dp[0], p1 = op[1] + *t * dp[1], p2 = op[2] + *t * dp[2];
    *m2 = clvis_dot3(p0, p1, p2, p0, p1, p2);
}

#endif /* CLVIS_GAUSS_H */
