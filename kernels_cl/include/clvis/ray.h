/* clvis/ray.h — rays against axis-aligned boxes: the inverse direction with
 * the tiny-direction rule and the slab test, shared by the BVH traversal of
 * gauss/march.cl and the iso kernels' volume box (clvis/iso.h).
 *
 * A ray o + t d. Before 1/d, a component with |d| < CLVIS_RAY_TINY_DIR (zero
 * included) is replaced by CLVIS_RAY_TINY_DIR with d's sign (+0 -> +TINY, -0
 * -> -TINY): clvis_ray_safe_dir. So 1/d is finite and nonzero, and (lo - o) /
 * d is never NaN for finite boxes and origins. A ray parallel to a slab and
 * inside it gets (-huge, +huge) there; outside it, an empty interval. A ray
 * lying exactly in a face plane (o on the face, that component of d zero)
 * moves the way the zero's sign says, as if tilted by TINY: inwards it hits,
 * outwards its interval on that axis ends at t = 0. The NumPy references
 * (clvis.reference.iso.traverse, clvis.reference.iso.raytrace) use the same rule.
 *
 *   float clvis_ray_safe_dir(float d)        d, or copysign(TINY, d) when |d| < TINY
 *   float clvis_ray_inv_dir(float d)         1 / clvis_ray_safe_dir(d)
 *   float clvis_ray_min(a, b), clvis_ray_max(a, b)
 *       a < b ? a : b and a > b ? a : b: for NaN-free operands the same
 *       values as fmin/fmax (they may differ on the sign of a zero result),
 *       and about twice as fast on PoCL.
 *   void clvis_ray_slab(const float *o, const float *inv, lo0, lo1, lo2,
 *                       hi0, hi1, hi2, float *t_enter, float *t_exit)
 *       per axis a: t0 = (lo_a - o_a) * inv_a, t1 = (hi_a - o_a) * inv_a
 *       (each rounded); *t_enter = max(max(min0, min1), min2), *t_exit =
 *       min(min(max0, max1), max2) of the per-axis min(t0, t1) and max(t0,
 *       t1), all by compare and select. The ray is in the closed box for t in
 *       [*t_enter, *t_exit] (empty when t_enter > t_exit), up to the rounding
 *       of those products (no widening). o and inv must not be NaN.
 *
 * Include with FP_CONTRACT OFF in force (results are then bit-identical to
 * the NumPy references). Includes clvis/inline.h (fabs and copysign, which
 * PoCL calls out of line).
 */
#ifndef CLVIS_RAY_H
#define CLVIS_RAY_H

#include "clvis/inline.h"

/* |d| below this is replaced by +-CLVIS_RAY_TINY_DIR before 1/d */
#define CLVIS_RAY_TINY_DIR 1e-20f

inline float clvis_ray_safe_dir(float d)
{
    return clvis_il_fabs(d) < CLVIS_RAY_TINY_DIR ? clvis_il_copysign(CLVIS_RAY_TINY_DIR, d) : d;
}

inline float clvis_ray_inv_dir(float d)
{
    return 1.0f / clvis_ray_safe_dir(d);
}

inline float clvis_ray_min(float a, float b) { return a < b ? a : b; }
inline float clvis_ray_max(float a, float b) { return a > b ? a : b; }

inline void clvis_ray_slab(const float *o, const float *inv, float lo0, float lo1, float lo2,
                           float hi0, float hi1, float hi2, float *t_enter, float *t_exit)
{
    float a0 = (lo0 - o[0]) * inv[0], b0 = (hi0 - o[0]) * inv[0];
    float a1 = (lo1 - o[1]) * inv[1], b1 = (hi1 - o[1]) * inv[1];
    float a2 = (lo2 - o[2]) * inv[2], b2 = (hi2 - o[2]) * inv[2];
    *t_enter = clvis_ray_max(clvis_ray_max(clvis_ray_min(a0, b0), clvis_ray_min(a1, b1)), clvis_ray_min(a2, b2));
    *t_exit = clvis_ray_min(clvis_ray_min(clvis_ray_max(a0, b0), clvis_ray_max(a1, b1)), clvis_ray_max(a2, b2));
}

#endif /* CLVIS_RAY_H */
