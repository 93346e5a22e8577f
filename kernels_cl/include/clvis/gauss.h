/* clvis/gauss.h — Gaussian records and camera rays of the gauss family.
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
 * Camera rays: a 22-float buffer (clvis.gauss.render.ray_buffer)
 *   [0..2] o0  [3..5] ou  [6..8] ov   origin  o = o0 + u ou + v ov
 *   [9..11] d0 [12..14] du [15..17] dv  direction dd = d0 + u du + v dv, d = dd / |dd|
 *   [18..21] depth row D: view depth of a point p = D . (p, 1)
 * with u = px + 0.5, v = py + 0.5 (pixel centres, row 0 on top). The origin is
 * on the near plane, so t >= 0 is what the camera sees. Every product and sum
 * is rounded separately, left to right (build with FP_CONTRACT OFF and
 * -cl-fp32-correctly-rounded-divide-sqrt): clvis/reference/gauss/render.py
 * repeats the same float32 operations.
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

#define CLVIS_GAUSS_FLAT 1e-3f
#define CLVIS_GAUSS_TINY 1e-30f

typedef struct {
    float mean[3];
    float value;
    float w[9];
    float opacity;
} clvis_gaussian;

inline float clvis_dot3(float a0, float a1, float a2, float b0, float b1, float b2)
{
    return (a0 * b0 + a1 * b1) + a2 * b2;
}

/* The pixel (px, py)'s ray: origin o[3] and unit direction d[3]. */
inline void clvis_camera_ray(global const float *cam, uint px, uint py, float *o, float *d)
{
    float u = (float)px + 0.5f, v = (float)py + 0.5f;
    float dd[3];
    for (int k = 0; k < 3; ++k) {
        o[k] = (cam[k] + u * cam[3 + k]) + v * cam[6 + k];
        dd[k] = (cam[9 + k] + u * cam[12 + k]) + v * cam[15 + k];
    }
    float len = sqrt(clvis_dot3(dd[0], dd[1], dd[2], dd[0], dd[1], dd[2]));
    for (int k = 0; k < 3; ++k)
        d[k] = dd[k] / len;
}

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

#endif
