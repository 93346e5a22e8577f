/* clvis/iso.h — shared by the iso kernels (traverse.cl, raytrace.cl): the ray
 * in the volume's index space, and the stages of tracing a ray through one
 * dual cell (each repeats a function of the NumPy reference clvis.reference.iso,
 * in float32 where the reference works in float64).
 *
 * clvis_iso_ray_setup(cam, p, W, n, sp, org, o, d, O, D, inv, &t_enter, &t_exit):
 * pixel p's ray o, d (world; clvis_camera_ray of clvis/camera.h, p = py * W + px) in the
 * volume's index space: O = (o - origin) / spacing, D = d / spacing, inv =
 * spacing / clvis_ray_safe_dir(d) (|d| < CLVIS_RAY_TINY_DIR -> copysign(TINY, d),
 * clvis/ray.h); with t0 = (0 - O) inv, t1 = ((n - 1) - O) inv per axis
 * (clvis_ray_slab), t_enter = max(max_a min(t0, t1), 0) and t_exit =
 * min_a max(t0, t1) (the ray meets the box [0, n - 1] iff t_enter <=
 * t_exit). n, sp, org are per axis x, y, z. Includes clvis/camera.h,
 * clvis/ray.h and clvis/inline.h (the cell stages take fmin, fmax, clamp,
 * fabs and copysign from it: calls on PoCL, inline there); the including file sets FP_CONTRACT OFF before its includes
 * (clvis/reference/iso/traverse.py repeats these float32 operations).
 *
 * Cell stages. A dual cell's corners v[8] (minus the isovalue), v[x + 2 y + 4 z]
 * for the corner at offset (x, y, z); u[3] the ray's local position in the
 * cell where it enters, D[3] its index-space direction.
 *
 *   clvis_iso_cell_cubic(v, u, D, cf): cf[4], f(s) = sum cf_k s^k, the trilinear
 *       interpolant along u + s D (reference cell_cubic; the corner terms summed
 *       in the order k = 0..7, each weight a product of the linear weights).
 *   int clvis_iso_first_zero(cf, len, steps, &s): 1 and the first zero s of f on
 *       [0, len] (reference cubic_first_zero with refine = ("illinois", steps):
 *       split at the extrema, the first interval with a sign change or zero,
 *       Illinois refinement), else 0.
 *   clvis_iso_trilinear_gradient(v, w, g): g[3] = d/dx, d/dy, d/dz of the
 *       interpolant at local w[3] (reference _trilinear_gradient).
 *   float4 clvis_iso_shade(g, d): Blinn–Phong headlight colour (alpha 1) of a
 *       hit with gradient g[3] (world units) seen along unit d[3] (reference
 *       shade with the default Shading: the CLVIS_ISO_SHADE_* constants,
 *       shininess 32).
 */
#ifndef CLVIS_ISO_H
#define CLVIS_ISO_H

#include "clvis/camera.h"
#include "clvis/inline.h"
#include "clvis/ray.h"

inline void clvis_iso_ray_setup(global const float *cam, uint p, uint W, const int *n, const float *sp,
                                const float *org, float *o, float *d, float *O, float *D, float *inv,
                                float *t_enter, float *t_exit)
{
    clvis_camera_ray(cam, p % W, p / W, o, d);
    for (int a = 0; a < 3; ++a) {
        inv[a] = sp[a] / clvis_ray_safe_dir(d[a]);
        O[a] = (o[a] - org[a]) / sp[a];
        D[a] = d[a] / sp[a];
    }
    float te, tx;
    clvis_ray_slab(O, inv, 0.0f, 0.0f, 0.0f, (float)(n[0] - 1), (float)(n[1] - 1), (float)(n[2] - 1), &te, &tx);
    *t_enter = clvis_ray_max(te, 0.0f);
    *t_exit = tx;
}

/* ---------------------------------------------------------------- cell stages */

/* clvis.reference.iso.Shading defaults */
#define CLVIS_ISO_SHADE_BASE_R 0.9f
#define CLVIS_ISO_SHADE_BASE_G 0.75f
#define CLVIS_ISO_SHADE_BASE_B 0.4f
#define CLVIS_ISO_SHADE_AMBIENT 0.15f
#define CLVIS_ISO_SHADE_DIFFUSE 0.75f
#define CLVIS_ISO_SHADE_SPECULAR 0.3f

inline void clvis_iso_cell_cubic(const float *v, const float *u, const float *D, float *cf)
{
    /* product of the three linear weights alpha + beta s */
    cf[0] = 0.0f;
    cf[1] = 0.0f;
    cf[2] = 0.0f;
    cf[3] = 0.0f;
    for (int k = 0; k < 8; ++k) {
        int ix = k & 1, iy = (k >> 1) & 1, iz = k >> 2;
        float ax = ix ? u[0] : 1.0f - u[0], ay = iy ? u[1] : 1.0f - u[1];
        float az = iz ? u[2] : 1.0f - u[2];
        float bxx = ix ? D[0] : -D[0], byy = iy ? D[1] : -D[1], bzz = iz ? D[2] : -D[2];
        cf[0] += v[k] * (ax * ay * az);
        cf[1] += v[k] * ((bxx * ay * az + ax * byy * az) + ax * ay * bzz);
        cf[2] += v[k] * ((bxx * byy * az + bxx * ay * bzz) + ax * byy * bzz);
        cf[3] += v[k] * (bxx * byy * bzz);
    }
}

inline float clvis_iso_horner(const float *c, float s)
{
    return ((c[3] * s + c[2]) * s + c[1]) * s + c[0];
}

inline int clvis_iso_has_zero(float fa, float fb)
{
    return (fa <= 0.0f && fb >= 0.0f) || (fa >= 0.0f && fb <= 0.0f);
}

inline float clvis_iso_interpolate(float a, float b, float fa, float fb)
{
    float x = fb != fa ? a - fa * (b - a) / (fb - fa) : a;
    return clvis_il_clamp(x, clvis_il_fmin(a, b), clvis_il_fmax(a, b));
}

/* The first zero of the cubic c on [0, len] by the zero rule; 1 and *s if found. */
inline int clvis_iso_first_zero(const float *c, float len, int steps, float *s)
{
    float A = 3.0f * c[3], B = 2.0f * c[2], C = c[1];
    float disc = B * B - 4.0f * A * C;
    float r1 = NAN, r2 = NAN;
    if (disc >= 0.0f) {
        float q = -0.5f * (B + clvis_il_copysign(sqrt(disc), B));
        if (A != 0.0f) {
            r1 = q / A;
            if (q != 0.0f)
                r2 = C / q;
        } else if (B != 0.0f) {
            r1 = -C / B;
        }
    }
    r1 = (r1 > 0.0f && r1 < len) ? r1 : len;
    r2 = (r2 > 0.0f && r2 < len) ? r2 : len;
    float pts[4] = {0.0f, clvis_il_fmin(r1, r2), clvis_il_fmax(r1, r2), len};
    float f[4];
    f[0] = c[0];
    for (int k = 1; k < 4; ++k)
        f[k] = clvis_iso_horner(c, pts[k]);
    for (int k = 0; k < 3; ++k) {
        if (!clvis_iso_has_zero(f[k], f[k + 1]))
            continue;
        float a = pts[k], b = pts[k + 1], fa = f[k], fb = f[k + 1];
        if (fa == 0.0f) {
            *s = a;
            return 1;
        }
        int last = 0; /* 1: a was replaced last step, -1: b */
        for (int i = 0; i < steps; ++i) {
            float x = clvis_iso_interpolate(a, b, fa, fb);
            float fx = clvis_iso_horner(c, x);
            int same_as_a = (fx > 0.0f && fa > 0.0f) || (fx < 0.0f && fa < 0.0f);
            if (same_as_a) {
                if (last == 1)
                    fb *= 0.5f;
                a = x;
                fa = fx;
                last = 1;
            } else {
                if (last == -1)
                    fa *= 0.5f;
                b = x;
                fb = fx;
                last = -1;
            }
        }
        *s = clvis_iso_interpolate(a, b, fa, fb);
        return 1;
    }
    return 0;
}

inline void clvis_iso_trilinear_gradient(const float *v, const float *w, float *g)
{
    float gx = 0.0f, gy = 0.0f, gz = 0.0f;
    for (int k = 0; k < 4; ++k) {
        /* edges along x: (y, z) = (k & 1, k >> 1); similarly for y and z */
        int e0 = k & 1, e1 = k >> 1;
        float wy = e0 ? w[1] : 1.0f - w[1], wz = e1 ? w[2] : 1.0f - w[2];
        float wx = e0 ? w[0] : 1.0f - w[0];
        float wy1 = e1 ? w[1] : 1.0f - w[1];
        gx += (v[1 + 2 * e0 + 4 * e1] - v[2 * e0 + 4 * e1]) * (wz * wy);
        gy += (v[2 + e0 + 4 * e1] - v[e0 + 4 * e1]) * (wz * wx);
        gz += (v[4 + e0 + 2 * e1] - v[e0 + 2 * e1]) * (wy1 * wx);
    }
    g[0] = gx;
    g[1] = gy;
    g[2] = gz;
}

inline float4 clvis_iso_shade(const float *g, const float *d)
{
    float len = sqrt(clvis_dot3(g[0], g[1], g[2], g[0], g[1], g[2]));
    float x = len > 0.0f ? clvis_il_fabs(clvis_dot3(g[0], g[1], g[2], d[0], d[1], d[2])) / len : 1.0f;
    x = clvis_il_fmin(x, 1.0f);
    float x2 = x * x, x4 = x2 * x2, x8 = x4 * x4, x16 = x8 * x8, x32 = x16 * x16;
    float lit = CLVIS_ISO_SHADE_AMBIENT + CLVIS_ISO_SHADE_DIFFUSE * x, spec = CLVIS_ISO_SHADE_SPECULAR * x32;
    return (float4)(clvis_il_clamp(CLVIS_ISO_SHADE_BASE_R * lit + spec, 0.0f, 1.0f),
                    clvis_il_clamp(CLVIS_ISO_SHADE_BASE_G * lit + spec, 0.0f, 1.0f),
                    clvis_il_clamp(CLVIS_ISO_SHADE_BASE_B * lit + spec, 0.0f, 1.0f), 1.0f);
}

/* clvis_iso_ray_setup for the 8 pixels p0 + pix[k] (k = 0..7) in float8 lanes:
 * the same float32 operations lane by lane, so the same values (the cpu
 * profile's 8-ray packets in init_rays, macro_traverse and raytrace_blocks;
 * a caller ignores the outputs it does not need). o, d: the camera ray;
 * O, D, inv, t_enter, t_exit as clvis_iso_ray_setup's. */
inline void clvis_iso_ray_setup8(global const float *cam, uint p0, const uint *pix, uint W, const int *n,
                                 const float *sp, const float *org, float8 *o, float8 *d, float8 *O,
                                 float8 *D, float8 *inv, float8 *t_enter, float8 *t_exit)
{
    float pu[8], pv[8];
    for (int k = 0; k < 8; ++k) {
        const uint p = p0 + pix[k];
        pu[k] = (float)(p % W) + 0.5f;
        pv[k] = (float)(p / W) + 0.5f;
    }
    const float8 u = CLVIS_IL_VLOAD8(float8, pu), v = CLVIS_IL_VLOAD8(float8, pv);
    float8 dd[3];
    for (int a = 0; a < 3; ++a) {   /* clvis_camera_ray */
        o[a] = (cam[a] + u * cam[3 + a]) + v * cam[6 + a];
        dd[a] = (cam[9 + a] + u * cam[12 + a]) + v * cam[15 + a];
    }
    const float8 len = sqrt((dd[0] * dd[0] + dd[1] * dd[1]) + dd[2] * dd[2]);
    float8 lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
        d[a] = dd[a] / len;
        const float8 safe = (as_float8(as_uint8(d[a]) & (uint8)(0x7FFFFFFFu)) < CLVIS_RAY_TINY_DIR)
                                ? as_float8(as_uint8((float8)(CLVIS_RAY_TINY_DIR))
                                            | (as_uint8(d[a]) & (uint8)(0x80000000u)))
                                : d[a];   /* clvis_ray_safe_dir */
        inv[a] = sp[a] / safe;
        O[a] = (o[a] - org[a]) / sp[a];
        D[a] = d[a] / sp[a];
        /* clvis_ray_slab over [0, n - 1] */
        const float8 t0 = (0.0f - O[a]) * inv[a], t1 = ((float)(n[a] - 1) - O[a]) * inv[a];
        lo[a] = t0 < t1 ? t0 : t1;
        hi[a] = t0 > t1 ? t0 : t1;
    }
    const float8 l01 = lo[0] > lo[1] ? lo[0] : lo[1], l012 = l01 > lo[2] ? l01 : lo[2];
    *t_enter = l012 > 0.0f ? l012 : 0.0f;
    const float8 m01 = hi[0] < hi[1] ? hi[0] : hi[1];
    *t_exit = m01 < hi[2] ? m01 : hi[2];
}

#endif /* CLVIS_ISO_H */
