/* clvis/iso.h — shared by the iso kernels (traverse.cl, raytrace.cl).
 *
 * clvis_iso_ray_setup(cam, p, W, n, sp, org, o, d, O, D, inv, &t_enter, &t_exit):
 * pixel p's ray o, d (world; clvis_camera_ray of clvis/camera.h, p = py * W + px) in the
 * volume's index space: O = (o - origin) / spacing, D = d / spacing, inv =
 * spacing / d_safe (|d| < CLVIS_BVH_TINY_DIR -> copysign(TINY, d), the
 * convention of clvis/bvh.h); with t0 = (0 - O) inv, t1 = ((n - 1) - O) inv
 * per axis, t_enter = max(0, max_a min(t0, t1)) and t_exit = min_a max(t0, t1)
 * (the ray meets the box [0, n - 1] iff t_enter <= t_exit). n, sp, org are
 * per axis x, y, z. Include after clvis/bvh.h and clvis/camera.h, with
 * FP_CONTRACT OFF set before the includes (clvis/reference/iso_traverse.py
 * repeats these float32 operations).
 */
#ifndef CLVIS_ISO_H
#define CLVIS_ISO_H

inline void clvis_iso_ray_setup(global const float *cam, uint p, uint W, const int *n, const float *sp,
                                const float *org, float *o, float *d, float *O, float *D, float *inv,
                                float *t_enter, float *t_exit)
{
    clvis_camera_ray(cam, p % W, p / W, o, d);
    float te = 0.0f, tx = INFINITY;
    for (int a = 0; a < 3; ++a) {
        float ds = fabs(d[a]) < CLVIS_BVH_TINY_DIR ? copysign(CLVIS_BVH_TINY_DIR, d[a]) : d[a];
        inv[a] = sp[a] / ds;
        O[a] = (o[a] - org[a]) / sp[a];
        D[a] = d[a] / sp[a];
        float t0 = (0.0f - O[a]) * inv[a], t1 = ((float)(n[a] - 1) - O[a]) * inv[a];
        te = fmax(te, fmin(t0, t1));
        tx = fmin(tx, fmax(t0, t1));
    }
    *t_enter = te;
    *t_exit = tx;
}

#endif
