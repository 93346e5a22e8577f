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
 *   } clvis_gaussian;         56 bytes, 4-byte aligned (numpy: clvis.gauss.gaussians.GAUSSIAN_DTYPE)
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
 *
 * The stages of compositing a hit (gauss/march.cl; clvis.reference.gauss.render's
 * tf_lookup and render_rays repeat them, render_rays in float64):
 *   uint clvis_gauss_tf_index(value, tf_min, tf_scale, tf_n): the transfer-function
 *       entry clamp(floor(((value - tf_min) * tf_scale) * tf_n), 0, tf_n - 1)
 *   float clvis_gauss_alpha_max_response(opac, m2) = min(0.99, opac exp(-m2 / 2))
 *   float clvis_gauss_alpha_absorption(opac, density, ts, a, op, dp)
 *       = 1 - exp(-(density opac) I), I = (exp(-ms2 / 2) sqrt(pi / (2a)))
 *       erfc(-ts sqrt(a / 2)), ms2 = |o' + ts d'|^2 (op = o', dp = d' of
 *       clvis_gauss_hit)
 *   float8 clvis_gauss_alpha_max_response8(opac, m2), clvis_gauss_alpha_absorption8(opac,
 *       density, ts, a, op0, op1, op2, dp0, dp1, dp2): the same on 8 rays (float8 lanes;
 *       exp/erfc/sqrt of float8 may differ from the scalar ones in the last bit)
 *   float4 clvis_gauss_rgb8(c): a per-Gaussian uchar4 colour as (r, g, b, a) / 255
 *       (correctly rounded division), used in place of the transfer function's
 *       colour when a Gaussian carries its own
 *   clvis_gauss_composite(alpha, c, &T, &cr, &cg, &cb): one front-to-back step,
 *       w = T alpha; cr += w c.x, cg += w c.y, cb += w c.z; T = T (1 - alpha)
 *   float clvis_gauss_hit_alpha(g, tf, tf_n, tf_min, tf_scale, model, density, m2, ts, a,
 *       op, dp, &ti): a hit's alpha, model 0 max response, 1 absorption, opac =
 *       g's opacity times the alpha factor of its transfer-function entry *ti
 *   bool clvis_gauss_key_less(ta, ia, tb, ib): (ta, ia) < (tb, ib), the hit order
 * (opac: the record's opacity times the transfer function's alpha factor.)
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

inline uint clvis_gauss_tf_index(float value, float tf_min, float tf_scale, uint tf_n)
{
    float x = floor(((value - tf_min) * tf_scale) * (float)tf_n);
    return x >= (float)(tf_n - 1) ? tf_n - 1 : x > 0.0f ? (uint)x : 0u;
}

inline float clvis_gauss_alpha_max_response(float opac, float m2)
{
    float a = opac * exp(-0.5f * m2);
    return a < 0.99f ? a : 0.99f;   /* fmin(0.99, a) (a NaN gives 0.99), without a call */
}

inline float clvis_gauss_alpha_absorption(float opac, float density, float ts, float a,
                                          const float *op, const float *dp)
{
    float s0 = op[0] + ts * dp[0], s1 = op[1] + ts * dp[1], s2 = op[2] + ts * dp[2];
    float ms2 = clvis_dot3(s0, s1, s2, s0, s1, s2);
    float integral = (exp(-0.5f * ms2) * sqrt(M_PI_F / (2.0f * a))) * erfc(-ts * sqrt(0.5f * a));
    return 1.0f - exp(-((density * opac) * integral));
}

/* the two alphas on 8 lanes (tile_render8): the same operations lane by lane;
 * float8 exp/erfc/sqrt may differ from the scalar ones in the last bit */
inline float8 clvis_gauss_alpha_max_response8(float opac, float8 m2)
{
    float8 a = opac * exp(-0.5f * m2);
    return a < 0.99f ? a : 0.99f;
}

inline float8 clvis_gauss_alpha_absorption8(float opac, float density, float8 ts, float8 a, float8 op0,
                                            float8 op1, float8 op2, float8 dp0, float8 dp1, float8 dp2)
{
    float8 s0 = op0 + ts * dp0, s1 = op1 + ts * dp1, s2 = op2 + ts * dp2;
    float8 ms2 = (s0 * s0 + s1 * s1) + s2 * s2;
    float8 integral = (exp(-0.5f * ms2) * sqrt(M_PI_F / (2.0f * a))) * erfc(-ts * sqrt(0.5f * a));
    return 1.0f - exp(-((density * opac) * integral));
}

inline float4 clvis_gauss_rgb8(uchar4 c)
{
    return convert_float4(c) / 255.0f;
}

inline void clvis_gauss_composite(float alpha, float4 c, float *T, float *cr, float *cg, float *cb)
{
    float wgt = *T * alpha;
    *cr += wgt * c.x;
    *cg += wgt * c.y;
    *cb += wgt * c.z;
    *T = *T * (1.0f - alpha);
}

inline float clvis_gauss_hit_alpha(global const clvis_gaussian *g, global const float4 *tf, uint tf_n,
                                   float tf_min, float tf_scale, int model, float density, float m2,
                                   float ts, float a, const float *op, const float *dp, uint *ti)
{
    *ti = clvis_gauss_tf_index(g->value, tf_min, tf_scale, tf_n);
    float opac = g->opacity * tf[*ti].w;
    if (model == 1)
        return clvis_gauss_alpha_absorption(opac, density, ts, a, op, dp);
    return clvis_gauss_alpha_max_response(opac, m2);
}

inline bool clvis_gauss_key_less(float ta, uint ia, float tb, uint ib)
{
    return ta < tb || (ta == tb && ia < ib);
}

#endif /* CLVIS_GAUSS_H */
