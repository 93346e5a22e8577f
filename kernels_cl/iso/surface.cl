/* surface.cl — a second field at the isosurface hits: the value of a volume
 * (any grid: its own shape, spacing and origin) at the world point each
 * pixel's ray hit the surface, so the surface can be coloured by another
 * quantity (clvis.iso.sample_hits). The definition is the docstring of
 * clvis/reference/iso/surface.py; the kernel works in float32 (the reference
 * in float64 from the same float32 inputs and bounds the difference).
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/camera.h).
 * Defines: none. Built with FP_CONTRACT OFF (below) and
 * -cl-fp32-correctly-rounded-divide-sqrt (runtime.EXACT_FP), as the other iso
 * kernels, so that the rays are clvis/camera.h's to the bit.
 *
 * Images are row-major, row 0 on top, w pixels a row, n pixels in all.
 *
 * kernel sample_hits(global const float *cam, uint w, uint n,
 *                    global const uchar *hit, global const float *t,
 *                    global const float *field, uint nx, uint ny, uint nz,
 *                    float sx, float sy, float sz, float ox, float oy, float oz,
 *                    global float *out)
 *     cam: the 22-float ray buffer the image was rendered with
 *     (clvis.camera.ray_buffer; clvis_camera_ray). hit: n bytes, nonzero
 *     where the pixel's ray hit the surface; t: n floats, its ray parameter.
 *     field: nx * ny * nz floats, [z][y][x] row-major (x fastest), each axis
 *     >= 2; sample (i, j, k) at world (ox + i sx, oy + j sy, oz + k sz),
 *     spacing > 0. out: n floats.
 *     For pixel p < n with hit[p] and a finite t[p]: the world point
 *     P = o + t d (o, d: clvis_camera_ray of pixel (p % w, p / w)), its index
 *     position g = (P - origin) / spacing per axis; when every g_a lies in
 *     [-SLACK, n_a - 1 + SLACK] (SLACK = 1e-3 index units: the hits of the
 *     raycaster lie in the volume box up to float32 rounding), g is clamped to
 *     [0, n_a - 1] and out[p] is the trilinear interpolant there (cell
 *     c_a = min(floor(g_a), n_a - 2), f_a = g_a - c_a; lerp along x, then y,
 *     then z, lerp(a, b, f) = a + f (b - a)); otherwise out[p] = NaN.
 *     Pixels without a hit: NaN.
 *     Global size: any one-dimensional size >= n (items past n do nothing);
 *     any local size.
 */

#pragma OPENCL FP_CONTRACT OFF

#include "clvis/camera.h"

#define SURFACE_SLACK 1e-3f

inline float surface_lerp(float a, float b, float f) { return a + f * (b - a); }

kernel void sample_hits(global const float *cam, uint w, uint n, global const uchar *hit,
                        global const float *t, global const float *field, uint nx, uint ny, uint nz,
                        float sx, float sy, float sz, float ox, float oy, float oz, global float *out)
{
    size_t p = get_global_id(0);
    if (p >= n) return;
    float tp = t[p];
    if (!hit[p] || !isfinite(tp)) {
        out[p] = NAN;
        return;
    }
    float o[3], d[3];
    clvis_camera_ray(cam, (uint)(p % w), (uint)(p / w), o, d);
    const float sp[3] = {sx, sy, sz}, org[3] = {ox, oy, oz};
    const uint dims[3] = {nx, ny, nz};
    float f[3];
    size_t c[3];
    for (int a = 0; a < 3; ++a) {
        float g = ((o[a] + tp * d[a]) - org[a]) / sp[a];
        float top = (float)(dims[a] - 1);
        if (!(g >= -SURFACE_SLACK && g <= top + SURFACE_SLACK)) {
            out[p] = NAN;
            return;
        }
        g = clamp(g, 0.0f, top);
        float cell = fmin(floor(g), top - 1.0f);
        c[a] = (size_t)cell;
        f[a] = g - cell;
    }
    size_t sxs = 1, sys = nx, szs = (size_t)nx * ny;
    size_t i0 = c[0] + c[1] * sys + c[2] * szs;
    float v000 = field[i0], v100 = field[i0 + sxs];
    float v010 = field[i0 + sys], v110 = field[i0 + sys + sxs];
    float v001 = field[i0 + szs], v101 = field[i0 + szs + sxs];
    float v011 = field[i0 + szs + sys], v111 = field[i0 + szs + sys + sxs];
    float x00 = surface_lerp(v000, v100, f[0]), x10 = surface_lerp(v010, v110, f[0]);
    float x01 = surface_lerp(v001, v101, f[0]), x11 = surface_lerp(v011, v111, f[0]);
    float y0 = surface_lerp(x00, x10, f[1]), y1 = surface_lerp(x01, x11, f[1]);
    out[p] = surface_lerp(y0, y1, f[2]);
}
