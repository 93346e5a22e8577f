/* clvis/camera.h — the camera and pixel conventions of clvis, in OpenCL C:
 * the projection of the rasterizers and the rays of the ray casters.
 *
 * Camera buffer (the rasterizers: raster/render.cl, raster/resolve.cl):
 * 20 floats, row-major.
 *   cam[0..15]   M = projection @ view (column vectors: clip = M [x y z 1]^T)
 *   cam[16..19]  D = -view[2, :], so depth = D . [x y z 1] is the view-space
 *                distance along the view axis (clip w for a perspective camera;
 *                for an orthographic one clip w is 1 and depth comes from D)
 *
 * Projection of a point p = (x, y, z), in float32 with every multiply and add
 * rounded separately (the including file must say #pragma OPENCL FP_CONTRACT
 * OFF, and be built with -cl-fp32-correctly-rounded-divide-sqrt, for results
 * bit-identical to clvis.camera.Camera.project):
 *   clip_i = ((M[i,0]*x + M[i,1]*y) + M[i,2]*z) + M[i,3]
 *   depth  = ((D[0]*x + D[1]*y) + D[2]*z) + D[3]
 *   r = 1 / clip_3 (one division; correctly rounded)
 *   sx = ((clip_0 * r) * 0.5 + 0.5) * W,  sy = (0.5 - (clip_1 * r) * 0.5) * H
 *   drawn when x, y, z are finite, near <= depth <= far, clip_3 > 0,
 *   0 <= sx < W and 0 <= sy < H; pixel (floor(sx), floor(sy)), row 0 on top.
 *
 * Camera rays (the ray casters: gauss/march.cl, iso/traverse.cl, iso/raytrace.cl)
 * -----------
 * A 22-float buffer (clvis.camera.ray_buffer (Python)):
 *   [0..2] o0  [3..5] ou  [6..8] ov   origin  o = o0 + u ou + v ov
 *   [9..11] d0 [12..14] du [15..17] dv  direction dd = d0 + u du + v dv, d = dd / |dd|
 *   [18..21] depth row D: view depth of a point p = D . (p, 1)
 * with u = px + 0.5, v = py + 0.5 (pixel centres, row 0 on top). The origin is
 * on the near plane, so t >= 0 is what the camera sees. Every product and sum
 * is rounded separately, left to right (FP_CONTRACT OFF before the include,
 * and -cl-fp32-correctly-rounded-divide-sqrt); the NumPy references repeat the
 * same float32 operations.
 *
 *   clvis_dot3(a0, a1, a2, b0, b1, b2) = (a0 b0 + a1 b1) + a2 b2
 *   clvis_camera_ray(cam, px, py, o, d): pixel (px, py)'s origin o[3] and unit
 *       direction d[3]
 *   clvis_ray_depth(cam, o, d, t): the view depth D . (o + t d, 1) of the point at t
 */
#ifndef CLVIS_CAMERA_H
#define CLVIS_CAMERA_H

#include "clvis/inline.h"

typedef struct {
    float4 r0, r1, r2, r3;  /* rows of M */
    float4 d;               /* depth row D */
} clvis_camera;

inline clvis_camera clvis_load_camera(global const float *cam)
{
    clvis_camera c;
    c.r0 = vload4(0, cam);
    c.r1 = vload4(1, cam);
    c.r2 = vload4(2, cam);
    c.r3 = vload4(3, cam);
    c.d = vload4(4, cam);
    return c;
}

/* ((r.x*x + r.y*y) + r.z*z) + r.w, each operation rounded */
inline float clvis_row_dot(float4 r, float x, float y, float z)
{
    return ((r.x * x + r.y * y) + r.z * z) + r.w;
}

/* The linear part only (a direction, such as a velocity): (r.x*x + r.y*y) + r.z*z */
inline float clvis_row_dir(float4 r, float x, float y, float z)
{
    return (r.x * x + r.y * y) + r.z * z;
}

/* Project p; returns 1 when it is drawn, with its continuous pixel position
 * (*sx, *sy) and *depth. fw, fh: the image size as floats (exact: W, H <= 2^24). */
inline int clvis_project(const clvis_camera *c, float x, float y, float z,
                         float near, float far, float fw, float fh,
                         float *sx, float *sy, float *depth)
{
    float cx = clvis_row_dot(c->r0, x, y, z);
    float cy = clvis_row_dot(c->r1, x, y, z);
    float cw = clvis_row_dot(c->r3, x, y, z);
    float d = clvis_row_dot(c->d, x, y, z);
    float r = 1.0f / cw;
    float px = ((cx * r) * 0.5f + 0.5f) * fw;
    float py = (0.5f - (cy * r) * 0.5f) * fh;
    *sx = px;
    *sy = py;
    *depth = d;
    return clvis_il_isfinite(x) && clvis_il_isfinite(y) && clvis_il_isfinite(z) && d >= near
        && d <= far && cw > 0.0f
        && px >= 0.0f && px < fw && py >= 0.0f && py < fh;
}

/* clvis_project on 8 points at once (the same operations lane by lane, so
 * the same results); returns -1 in the lanes drawn, 0 elsewhere. near and far
 * must be finite. Then the finiteness test of x, y, z is left out: it is
 * implied by near <= depth <= far, since a NaN or infinite coordinate makes
 * every sum it enters, so depth, NaN or infinite (0 * inf is NaN).
 * w_depth: the caller has found the clip w row equal to the depth row, value
 * by value (a perspective camera: M's last row is -view[2, :] = D), and depth
 * is taken to be clip w. Both sums then agree in value at every step, and in
 * their bits unless the result is a zero (its sign may differ); a drawn point
 * has clip w > 0, so its depth is the same float either way, and each lane's
 * tests give the same answer (-0 == +0).
 * inside: the caller has found (clvis_box_inside) that every finite point of
 * the points' box has clip w > 0 and its pixel inside the image; then only
 * near <= depth <= far is tested, which also rejects the non-finite points
 * (above): the same lanes are drawn. */
inline int8 clvis_project8(const clvis_camera *c, float8 x, float8 y, float8 z,
                           float near, float far, float fw, float fh,
                           float8 *sx, float8 *sy, float8 *depth, int w_depth, int inside)
{
    float8 cx = ((c->r0.x * x + c->r0.y * y) + c->r0.z * z) + c->r0.w;
    float8 cy = ((c->r1.x * x + c->r1.y * y) + c->r1.z * z) + c->r1.w;
    float8 cw = ((c->r3.x * x + c->r3.y * y) + c->r3.z * z) + c->r3.w;
    float8 d = w_depth ? cw : ((c->d.x * x + c->d.y * y) + c->d.z * z) + c->d.w;
    float8 r = 1.0f / cw;
    float8 px = ((cx * r) * 0.5f + 0.5f) * fw;
    float8 py = (0.5f - (cy * r) * 0.5f) * fh;
    *sx = px;
    *sy = py;
    *depth = d;
    if (inside)
        return (d >= near) & (d <= far);
    return (d >= near) & (d <= far) & (cw > 0.0f)
        & (px >= 0.0f) & (px < fw) & (py >= 0.0f) & (py < fh);
}

/* 1 when no point of the box [lo, hi] can be drawn: all eight corners lie
 * beyond one of the planes x = -w, x = w, y = -w, y = w, w = 0, depth = near,
 * depth = far, by a margin of 1e-5 of the largest magnitude any point of the
 * box can give those sums (sum_j |M[i,j]| * max(|lo_j|, |hi_j|) + |M[i,3]|).
 * That is far above the float32 rounding of a point's own projection (a few
 * ulp of the same magnitudes), so a point that clvis_project draws is never
 * culled. An empty box (lo > hi, or NaN) is culled. */
inline int clvis_box_culled(const clvis_camera *c, float3 lo, float3 hi, float near, float far)
{
    if (!(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z))
        return 1;
    float4 a = (float4)(clvis_il_fmax3(clvis_il_fabs3(lo), clvis_il_fabs3(hi)), 1.0f);
    float4 ax = clvis_il_fabs4(c->r0) * a, ay = clvis_il_fabs4(c->r1) * a;
    float4 aw = clvis_il_fabs4(c->r3) * a, ad = clvis_il_fabs4(c->d) * a;
    float sw = (aw.x + aw.y) + (aw.z + aw.w);
    float mx = 1e-5f * ((ax.x + ax.y) + (ax.z + ax.w) + sw);
    float my = 1e-5f * ((ay.x + ay.y) + (ay.z + ay.w) + sw);
    float mw = 1e-5f * sw;
    float md = 1e-5f * ((ad.x + ad.y) + (ad.z + ad.w) + clvis_il_fabs(near) + clvis_il_fabs(far));
    /* bit k set: every corner so far is beyond plane k */
    uint all_out = 0x7Fu;
    for (int k = 0; k < 8; ++k) {
        float x = (k & 1) ? hi.x : lo.x;
        float y = (k & 2) ? hi.y : lo.y;
        float z = (k & 4) ? hi.z : lo.z;
        float cx = clvis_row_dot(c->r0, x, y, z);
        float cy = clvis_row_dot(c->r1, x, y, z);
        float cw = clvis_row_dot(c->r3, x, y, z);
        float d = clvis_row_dot(c->d, x, y, z);
        uint out = 0;
        out |= (cx + cw < -mx) ? 0x01u : 0u;    /* x < -w */
        out |= (cx - cw > mx) ? 0x02u : 0u;     /* x > w */
        out |= (cy + cw < -my) ? 0x04u : 0u;    /* y < -w */
        out |= (cy - cw > my) ? 0x08u : 0u;     /* y > w */
        out |= (cw < -mw) ? 0x10u : 0u;         /* w < 0 */
        out |= (d - near < -md) ? 0x20u : 0u;   /* depth < near */
        out |= (d - far > md) ? 0x40u : 0u;     /* depth > far */
        all_out &= out;
    }
    return all_out != 0u;
}

/* 1 when every point of the box [lo, hi] has clip w > 0 and its pixel
 * position inside the image (0 <= sx < W, 0 <= sy < H) as clvis_project
 * computes them, so that for the finite points of the box only
 * near <= depth <= far is left to test. Each corner must lie inside the
 * planes x = -w, x = w, y = -w, y = w and above w = 0 by a margin of 1e-4
 * of the largest magnitude the sums can take over the box (as in
 * clvis_box_culled) plus 1e-30. The conditions are linear in the point, so
 * what holds at the corners holds in the box; a point's computed clip x and
 * w are within 4.0001 * 2^-24 of those magnitudes of the exact ones (four
 * rounded operations), so the computed |x / w| stays below 1 - 5e-5, and
 * the rounding of 1 / w, the quotient and the pixel arithmetic (a few
 * 2^-24 relative) cannot reach the image edge. Degenerate (NaN, infinite)
 * magnitudes make it 0. */
inline int clvis_box_inside(const clvis_camera *c, float3 lo, float3 hi)
{
    float4 a = (float4)(clvis_il_fmax3(clvis_il_fabs3(lo), clvis_il_fabs3(hi)), 1.0f);
    float4 ax = clvis_il_fabs4(c->r0) * a, ay = clvis_il_fabs4(c->r1) * a;
    float4 aw = clvis_il_fabs4(c->r3) * a;
    float sw = (aw.x + aw.y) + (aw.z + aw.w);
    float mx = 1e-4f * ((ax.x + ax.y) + (ax.z + ax.w) + sw) + 1e-30f;
    float my = 1e-4f * ((ay.x + ay.y) + (ay.z + ay.w) + sw) + 1e-30f;
    float mw = 1e-4f * sw + 1e-30f;
    int in = lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z;
    for (int k = 0; k < 8; ++k) {
        float x = (k & 1) ? hi.x : lo.x;
        float y = (k & 2) ? hi.y : lo.y;
        float z = (k & 4) ? hi.z : lo.z;
        float cx = clvis_row_dot(c->r0, x, y, z);
        float cy = clvis_row_dot(c->r1, x, y, z);
        float cw = clvis_row_dot(c->r3, x, y, z);
        in &= (cw - cx > mx) && (cw + cx > mx) && (cw - cy > my) && (cw + cy > my) && (cw > mw);
    }
    return in;
}

/* ---------------------------------------------------------------- camera rays */

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

/* The view depth of the ray's point at t: D . (o + t d, 1), cam[18..21] = D. */
inline float clvis_ray_depth(global const float *cam, const float *o, const float *d, float t)
{
    float p0 = o[0] + t * d[0], p1 = o[1] + t * d[1], p2 = o[2] + t * d[2];
    return clvis_dot3(cam[18], cam[19], cam[20], p0, p1, p2) + cam[21];
}

#endif /* CLVIS_CAMERA_H */
