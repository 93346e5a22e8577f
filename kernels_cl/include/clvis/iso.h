/* clvis/iso.h — shared by the iso kernels (traverse.cl, raytrace.cl).
 *
 * clvis_iso_ray_setup(cam, p, W, n, sp, org, o, d, O, D, inv, &t_enter, &t_exit):
 * pixel p's ray o, d (world; clvis_camera_ray of clvis/camera.h, p = py * W + px) in the
 * volume's index space: O = (o - origin) / spacing, D = d / spacing, inv =
 * spacing / clvis_ray_safe_dir(d) (|d| < CLVIS_RAY_TINY_DIR -> copysign(TINY, d),
 * clvis/ray.h); with t0 = (0 - O) inv, t1 = ((n - 1) - O) inv per axis
 * (clvis_ray_slab), t_enter = max(max_a min(t0, t1), 0) and t_exit =
 * min_a max(t0, t1) (the ray meets the box [0, n - 1] iff t_enter <=
 * t_exit). n, sp, org are per axis x, y, z. Includes clvis/camera.h and
 * clvis/ray.h; the including file sets FP_CONTRACT OFF before its includes
 * (clvis/reference/iso_traverse.py repeats these float32 operations).
 */
#ifndef CLVIS_ISO_H
#define CLVIS_ISO_H

#include "clvis/camera.h"
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

#endif /* CLVIS_ISO_H */
