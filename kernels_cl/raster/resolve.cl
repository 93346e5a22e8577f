/* resolve.cl — from the visibility buffer to multi-attribute G-buffers
 * (NARVis "MACR": render, then resolve).
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/camera.h,
 *     clvis/colormap.h, clvis/inline.h, clvis/keys.h).
 * Build options: -cl-fp32-correctly-rounded-divide-sqrt (bit-identical screen
 * velocity and splat radius; see clvis/camera.h). No defines.
 *
 * Both kernels: one work-item per pixel p = py * W + px; global size >= W * H,
 * any local size. vis: the visibility buffer of render.cl as 2 * W * H uints
 * (word 2p: id, word 2p + 1: dkey; both all ones = empty). The winner `id` is
 * an index in the caller's order: colors, tf_src, attr_f32, attr_u8, velocity
 * and radius are indexed by it. The depth of a covered pixel is the float
 * whose clvis_key_f32 is dkey.
 *
 * kernel resolve(global const uint *vis, uint W, uint H,
 *                uint color_mode, global const uchar4 *colors,
 *                global const float *tf_src, uint tf_stride, uint tf_offset,
 *                global const uchar4 *lut, uint lut_n, float tf_min, float tf_scale,
 *                global const uint *accum,
 *                global uint *index_out, global float *depth_out, global uchar4 *rgba_out)
 *     Per pixel, covered / empty:
 *       index_out[p]  id / 0xFFFFFFFF
 *       depth_out[p]  the depth / +inf
 *       rgba_out[p]   the winner's color (clvis_point_color of clvis/colormap.h)
 *                     / (0, 0, 0, 0). With accum (soft z; NULL: off), 5 uints a
 *                     pixel from render.cl's soft_accumulate (r, g, b, a sums,
 *                     count), the rounded mean (sum + count / 2) / count per
 *                     channel instead (the winner's color if count is 0).
 *
 * kernel resolve_attributes(global const uint *vis, uint W, uint H,
 *                           global const float *positions, global const uint *inv,
 *                           global const float *cam, float focal, uint flags,
 *                           uint nf, global const float *attr_f32,
 *                           uint nu, global const uchar *attr_u8,
 *                           global const float *velocity, global const float *radius,
 *                           global float *attr_f32_out, global uchar *attr_u8_out,
 *                           global float *vel_out, global float *angle_out,
 *                           global float *speed_out, global float *radius_out)
 *     Per pixel, covered / empty:
 *       attr_f32_out[a * W * H + p] = attr_f32[id * nf + a] / NaN, a < nf
 *       attr_u8_out[a * W * H + p]  = attr_u8[id * nu + a]  / 0,   a < nu
 *     flags & 1 (velocity, 3 floats a point, world units per unit time): the
 *     point is positions[inv[id]] (render order; inv NULL: the same order),
 *     c its clip coordinates (clvis_row_dot with the 20-float camera cam) and
 *     c_v = the linear part of M applied to the velocity (clvis_row_dir):
 *       vel_out[2p]     vx = (0.5 * W) * ((c_vx * c_w - c_x * c_vw) / (c_w * c_w))
 *       vel_out[2p + 1] vy = -((0.5 * H) * ((c_vy * c_w - c_y * c_vw) / (c_w * c_w)))
 *                       (the derivative of the pixel position (sx, sy), y down) / NaN
 *       angle_out[p]    atan2(vy, vx) / NaN
 *       speed_out[p]    sqrt(vx * vx + vy * vy) / NaN
 *     flags & 2 (radius, 1 float a point, world units; focal = 0.5 * H * P[1][1]):
 *       radius_out[p]   (radius[id] * focal) / depth, the splat radius in pixels / NaN;
 *       with flags & 4 (an orthographic camera: pixels a world unit at every
 *       depth) radius[id] * focal
 *     Buffers of disabled outputs (and of nf = 0, nu = 0) may be NULL.
 *
 * Memory traffic per pixel: 8 bytes of vis, the winner's data (a random read),
 * and every output plane written once.
 */
#pragma OPENCL FP_CONTRACT OFF

#include "clvis/camera.h"
#include "clvis/colormap.h"
#include "clvis/inline.h"
#include "clvis/keys.h"

#define RESOLVE_VELOCITY 1u
#define RESOLVE_RADIUS 2u
#define RESOLVE_ORTHOGRAPHIC 4u

inline float resolve_depth(uint dkey)
{
    return as_float(clvis_key_f32_inverse(dkey));
}

kernel void resolve(global const uint *vis, uint W, uint H,
                    uint color_mode, global const uchar4 *colors,
                    global const float *tf_src, uint tf_stride, uint tf_offset,
                    global const uchar4 *lut, uint lut_n, float tf_min, float tf_scale,
                    global const uint *accum,
                    global uint *index_out, global float *depth_out, global uchar4 *rgba_out)
{
    size_t p = get_global_id(0);
    if (p >= (size_t)W * H)
        return;
    uint id = vis[2 * p], dkey = vis[2 * p + 1];
    if (id == 0xFFFFFFFFu && dkey == 0xFFFFFFFFu) {
        index_out[p] = 0xFFFFFFFFu;
        depth_out[p] = INFINITY;
        rgba_out[p] = (uchar4)(0);
        return;
    }
    index_out[p] = id;
    depth_out[p] = resolve_depth(dkey);
    uint count = accum ? accum[5 * p + 4] : 0u;
    uint4 col;
    if (count > 0u)
        col = (vload4(0, accum + 5 * p) + count / 2u) / count;
    else
        col = clvis_point_color(id, color_mode, colors, tf_src, tf_stride, tf_offset, lut, lut_n,
                                tf_min, tf_scale);
    rgba_out[p] = convert_uchar4(col);
}

kernel void resolve_attributes(global const uint *vis, uint W, uint H,
                               global const float *positions, global const uint *inv,
                               global const float *cam, float focal, uint flags,
                               uint nf, global const float *attr_f32,
                               uint nu, global const uchar *attr_u8,
                               global const float *velocity, global const float *radius,
                               global float *attr_f32_out, global uchar *attr_u8_out,
                               global float *vel_out, global float *angle_out,
                               global float *speed_out, global float *radius_out)
{
    size_t npix = (size_t)W * H;
    size_t p = get_global_id(0);
    if (p >= npix)
        return;
    uint id = vis[2 * p], dkey = vis[2 * p + 1];
    if (id == 0xFFFFFFFFu && dkey == 0xFFFFFFFFu) {
        for (uint a = 0; a < nf; ++a)
            attr_f32_out[a * npix + p] = NAN;
        for (uint a = 0; a < nu; ++a)
            attr_u8_out[a * npix + p] = 0;
        if (flags & RESOLVE_VELOCITY) {
            vel_out[2 * p] = NAN;
            vel_out[2 * p + 1] = NAN;
            angle_out[p] = NAN;
            speed_out[p] = NAN;
        }
        if (flags & RESOLVE_RADIUS)
            radius_out[p] = NAN;
        return;
    }
    for (uint a = 0; a < nf; ++a)
        attr_f32_out[a * npix + p] = attr_f32[(size_t)id * nf + a];
    for (uint a = 0; a < nu; ++a)
        attr_u8_out[a * npix + p] = attr_u8[(size_t)id * nu + a];
    if (flags & RESOLVE_VELOCITY) {
        clvis_camera c = clvis_load_camera(cam);
        size_t r = inv ? inv[id] : id;
        float x = positions[3 * r], y = positions[3 * r + 1], z = positions[3 * r + 2];
        size_t v = 3 * (size_t)id;
        float vx3 = velocity[v], vy3 = velocity[v + 1], vz3 = velocity[v + 2];
        float cx = clvis_row_dot(c.r0, x, y, z);
        float cy = clvis_row_dot(c.r1, x, y, z);
        float cw = clvis_row_dot(c.r3, x, y, z);
        float vcx = clvis_row_dir(c.r0, vx3, vy3, vz3);
        float vcy = clvis_row_dir(c.r1, vx3, vy3, vz3);
        float vcw = clvis_row_dir(c.r3, vx3, vy3, vz3);
        float ww = cw * cw;
        float vx = (0.5f * (float)W) * ((vcx * cw - cx * vcw) / ww);
        float vy = -((0.5f * (float)H) * ((vcy * cw - cy * vcw) / ww));
        vel_out[2 * p] = vx;
        vel_out[2 * p + 1] = vy;
        angle_out[p] = atan2(vy, vx);
        speed_out[p] = sqrt(vx * vx + vy * vy);
    }
    if (flags & RESOLVE_RADIUS)
        radius_out[p] = (flags & RESOLVE_ORTHOGRAPHIC) ? radius[id] * focal
                                                      : (radius[id] * focal) / resolve_depth(dkey);
}
