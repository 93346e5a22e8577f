/* raytrace.cl — block raytracing of the progressive isosurface raycaster
 * (Dyken, Usher, Kumar 2024): the rays waiting at one 4^3 ZFP block are traced
 * through that block's dual cells against its decoded brick.
 *
 * ABI
 * ---
 * Build options: -cl-fp32-correctly-rounded-divide-sqrt (FP_CONTRACT is OFF
 * below: every float operation rounds on its own).
 * Defines:
 *   ITEMS         0 (default): ray_ids are pixels, ray_t / ray_hit / hit_t /
 *                 rgba / depth are per pixel, as described below.
 *                 1: speculation. ray_ids are *items* e = i * n_spec + k, the
 *                 k-th candidate block of active ray i (pixel item_pixel[i]);
 *                 ray_t[e] is the t where item e enters its block (cand_t of
 *                 traverse.cl; read only), and ray_hit / hit_t / rgba / depth
 *                 are per item. With CLVIS_INT64_ATOMICS, a hit also does
 *                 atom_min(hitkey[p], as_uint(t) << 32 | e): the pixel's
 *                 nearest hit over its items (the host fills hitkey with ones
 *                 first); without it, pass.cl's resolve scans the items.
 *   REFINE_STEPS  Illinois steps of the root refinement (default 8; the
 *                 reference docstring asks for >= 6)
 * Includes clvis/camera.h (the 22-float camera-ray buffer and clvis_camera_ray),
 * clvis/iso.h (clvis_iso_ray_setup: the ray in index space and its box
 * interval; the 1/d convention of clvis/ray.h).
 *
 * Volume [nz][ny][nx] samples, nx, ny, nz >= 2; blocks (bx, by, bz) of 4^3
 * samples, block id b = bx + nbx (by + nby bz), nb_ = ceil(n_ / 4) (the ZFP
 * block grid of zfp.cl). The brick of a block is 64 floats, value
 * x + 4 y + 16 z = sample (4 bx + x, 4 by + y, 4 bz + z) (clvis.zfp.decode_blocks).
 *
 * kernel raytrace_blocks(
 *     global const float *bricks,        slots x 64 floats: the block cache
 *     global const int *slot_of_block,   nblocks: block id -> cache slot, -1 if absent
 *     uint nx, uint ny, uint nz,         volume samples per axis
 *     float dx, float dy, float dz,      spacing (world units per sample step)
 *     float ox, float oy, float oz,      origin: world position of sample (0, 0, 0)
 *     float isovalue,
 *     global const float *cam,           22 floats: the camera rays of clvis/camera.h
 *     uint W,                            image width: ray p = py * W + px
 *     global const uint *group_blocks,   per work-group: the block id it traces
 *     global const uint *group_offsets,  per work-group: first index of its rays in ray_ids
 *     global const uint *group_counts,   per work-group: how many rays
 *     global const uint *ray_ids,        pixel index p of each ray
 *     global float *ray_t,               per pixel: in, the t where the ray enters the block;
 *                                        out (no hit), the t where it leaves the block,
 *                                        or +INFINITY when it left the volume; unchanged at a hit
 *     global uchar *ray_hit,             per pixel: set to 1 at a hit (else not written)
 *     global float *hit_t,               per pixel: the hit's t (written at hits only)
 *     global float4 *rgba,               per pixel: shaded colour, alpha 1 (hits only)
 *     global float *depth,               per pixel: view depth cam[18..21] . (o + t d, 1) (hits only)
 *     global const uint *item_pixel,     ITEMS only (else unused, may be NULL): see below
 *     uint n_spec,                       ITEMS only
 *     volatile global ulong *hitkey)     ITEMS only, with CLVIS_INT64_ATOMICS (may be NULL otherwise)
 *   Global size: groups x L, local size L (any L; the host uses 64 or 16): work-group g
 *   traces block group_blocks[g], work-item i its rays i, i + L, ... < group_counts[g].
 *   Local memory: 125 floats (the dual brick).
 *   The block and its +x, +y, +z, +xy, +xz, +yz, +xyz neighbours inside the
 *   volume must be cached (their samples on the block's far faces are corners
 *   of the block's cells); an absent one reads as NaN (no hit in those cells).
 *
 * Per ray (the rules of clvis/reference/iso.py, in float32): o, d from the ray
 * buffer; index space O = (o - origin) / spacing, D = d / spacing, inv = spacing /
 * d_safe (|d| < TINY -> copysign(TINY, d)); t_exit = min_a max(t0_a, t1_a) of the
 * box [0, n - 1]. The first cell is clamp(floor(O + t D), block's cells), the
 * block's cells being those whose minimum corner is in the block: [4 b_a,
 * min(4 b_a + 3, n_a - 2)] per axis. Then the reference's DDA (t_next recomputed
 * from the cell index, ties x < y < z, t_out = max(t_in, min(t_exit, t_next))),
 * cell skipping by the corner range, the cell cubic split at its extrema, the
 * zero rule, Illinois refinement (REFINE_STEPS), until a hit, t_out >= t_exit
 * or the cell leaves the volume (ray_t = +INFINITY), or the cell leaves the
 * block (ray_t = t_out). Shading: Blinn–Phong headlight with the gradient of
 * the hit cell's trilinear interpolant divided by spacing (constants below).
 */
/* before the includes: clvis_camera_ray must not contract either */
#pragma OPENCL FP_CONTRACT OFF

#include "clvis/camera.h"
#include "clvis/iso.h"
#include "clvis/atomics.h"

#ifndef ITEMS
#define ITEMS 0
#endif
#ifndef REFINE_STEPS
#define REFINE_STEPS 8
#endif

/* clvis.reference.iso.Shading defaults */
#define SHADE_BASE_R 0.9f
#define SHADE_BASE_G 0.75f
#define SHADE_BASE_B 0.4f
#define SHADE_AMBIENT 0.15f
#define SHADE_DIFFUSE 0.75f
#define SHADE_SPECULAR 0.3f

#define BRICK_SIDE 5

inline float horner(const float *c, float s)
{
    return ((c[3] * s + c[2]) * s + c[1]) * s + c[0];
}

inline int has_zero(float fa, float fb)
{
    return (fa <= 0.0f && fb >= 0.0f) || (fa >= 0.0f && fb <= 0.0f);
}

inline float interpolate(float a, float b, float fa, float fb)
{
    float x = fb != fa ? a - fa * (b - a) / (fb - fa) : a;
    return clamp(x, fmin(a, b), fmax(a, b));
}

/* The first zero of the cubic c on [0, len] by the zero rule; 1 and *s if found. */
inline int first_zero(const float *c, float len, float *s)
{
    float A = 3.0f * c[3], B = 2.0f * c[2], C = c[1];
    float disc = B * B - 4.0f * A * C;
    float r1 = NAN, r2 = NAN;
    if (disc >= 0.0f) {
        float q = -0.5f * (B + copysign(sqrt(disc), B));
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
    float pts[4] = {0.0f, fmin(r1, r2), fmax(r1, r2), len};
    float f[4];
    f[0] = c[0];
    for (int k = 1; k < 4; ++k)
        f[k] = horner(c, pts[k]);
    for (int k = 0; k < 3; ++k) {
        if (!has_zero(f[k], f[k + 1]))
            continue;
        float a = pts[k], b = pts[k + 1], fa = f[k], fb = f[k + 1];
        if (fa == 0.0f) {
            *s = a;
            return 1;
        }
        int last = 0; /* 1: a was replaced last step, -1: b */
        for (int i = 0; i < REFINE_STEPS; ++i) {
            float x = interpolate(a, b, fa, fb);
            float fx = horner(c, x);
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
        *s = interpolate(a, b, fa, fb);
        return 1;
    }
    return 0;
}

kernel void raytrace_blocks(global const float *bricks, global const int *slot_of_block,
                            uint nx, uint ny, uint nz, float dx, float dy, float dz,
                            float ox, float oy, float oz, float isovalue,
                            global const float *cam, uint W,
                            global const uint *group_blocks, global const uint *group_offsets,
                            global const uint *group_counts, global const uint *ray_ids,
                            global float *ray_t, global uchar *ray_hit, global float *hit_t,
                            global float4 *rgba, global float *depth,
                            global const uint *item_pixel, uint n_spec, volatile global ulong *hitkey)
{
    local float brick[BRICK_SIDE * BRICK_SIDE * BRICK_SIDE];
    const uint g = get_group_id(0), lid = get_local_id(0), lsize = get_local_size(0);
    const uint nbx = (nx + 3u) >> 2, nby = (ny + 3u) >> 2;
    const uint block = group_blocks[g];
    const int bx = (int)(block % nbx), by = (int)(block / nbx % nby), bz = (int)(block / (nbx * nby));
    const int n[3] = {(int)nx, (int)ny, (int)nz};
    const int b0[3] = {4 * bx, 4 * by, 4 * bz};

    /* the dual brick: samples 4 b + (0..4) per axis, from this block and its +x/+y/+z neighbours */
    for (uint i = lid; i < BRICK_SIDE * BRICK_SIDE * BRICK_SIDE; i += lsize) {
        int lx = (int)(i % BRICK_SIDE), ly = (int)(i / BRICK_SIDE % BRICK_SIDE), lz = (int)(i / 25u);
        int sx = b0[0] + lx, sy = b0[1] + ly, sz = b0[2] + lz;
        float v = NAN;
        if (sx < n[0] && sy < n[1] && sz < n[2]) {
            uint nb = (uint)(sx >> 2) + nbx * ((uint)(sy >> 2) + nby * (uint)(sz >> 2));
            int slot = slot_of_block[nb];
            if (slot >= 0)
                v = bricks[64ul * (ulong)slot + (ulong)((sx & 3) + 4 * (sy & 3) + 16 * (sz & 3))];
        }
        brick[i] = v;
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    const float sp[3] = {dx, dy, dz}, org[3] = {ox, oy, oz};
    int clo[3], chi[3];
    for (int a = 0; a < 3; ++a) {
        clo[a] = b0[a];
        chi[a] = min(b0[a] + 3, n[a] - 2);
    }
    const uint count = group_counts[g], offset = group_offsets[g];

    for (uint r = lid; r < count; r += lsize) {
#if ITEMS
        const uint e = ray_ids[offset + r];             /* the item: (ray e / n_spec, candidate) */
        const uint p = item_pixel[e / n_spec];
#else
        const uint p = ray_ids[offset + r], e = p;      /* outputs and state per pixel */
#endif
        float o[3], d[3], O[3], D[3], inv[3], t_enter, t_exit;
        clvis_iso_ray_setup(cam, p, W, n, sp, org, o, d, O, D, inv, &t_enter, &t_exit);
        float t_in = ray_t[e];
        int c[3];
        for (int a = 0; a < 3; ++a) {
            float gpos = floor(O[a] + t_in * D[a]);
            int ci = gpos >= (float)clo[a] ? (gpos <= (float)chi[a] ? (int)gpos : chi[a]) : clo[a];
            c[a] = ci;
        }

        float out_t = t_in;
        for (;;) {
            float tn[3];
            for (int a = 0; a < 3; ++a)
                tn[a] = ((float)(c[a] + (inv[a] > 0.0f ? 1 : 0)) - O[a]) * inv[a];
            int axis = 0;
            if (tn[1] < tn[axis])
                axis = 1;
            if (tn[2] < tn[axis])
                axis = 2;
            const float t_out = fmax(t_in, fmin(tn[axis], t_exit));

            /* the cell's corners, minus the isovalue; skip it by its range */
            const int base = (c[0] - b0[0]) + BRICK_SIDE * ((c[1] - b0[1]) + BRICK_SIDE * (c[2] - b0[2]));
            float v[8];
            float vmin = INFINITY, vmax = -INFINITY;
            for (int k = 0; k < 8; ++k) {
                float x = brick[base + (k & 1) + BRICK_SIDE * ((k >> 1) & 1) + 25 * (k >> 2)];
                vmin = fmin(vmin, x);
                vmax = fmax(vmax, x);
                v[k] = x - isovalue;
            }
            if (vmin <= isovalue && vmax >= isovalue) {
                float u[3];
                for (int a = 0; a < 3; ++a)
                    u[a] = (O[a] + t_in * D[a]) - (float)c[a];
                /* cubic coefficients: product of the three linear weights alpha + beta s */
                float cf[4] = {0.0f, 0.0f, 0.0f, 0.0f};
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
                float s;
                if (first_zero(cf, t_out - t_in, &s)) {
                    const float t = t_in + s;
                    /* gradient of the trilinear interpolant at the hit, world units */
                    float w[3];
                    for (int a = 0; a < 3; ++a)
                        w[a] = clamp(u[a] + s * D[a], 0.0f, 1.0f);
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
                    gx /= dx;
                    gy /= dy;
                    gz /= dz;
                    float len = sqrt(clvis_dot3(gx, gy, gz, gx, gy, gz));
                    float x = len > 0.0f ? fabs(clvis_dot3(gx, gy, gz, d[0], d[1], d[2])) / len : 1.0f;
                    x = fmin(x, 1.0f);
                    float x2 = x * x, x4 = x2 * x2, x8 = x4 * x4, x16 = x8 * x8, x32 = x16 * x16;
                    float lit = SHADE_AMBIENT + SHADE_DIFFUSE * x, spec = SHADE_SPECULAR * x32;
                    float px = o[0] + t * d[0], py = o[1] + t * d[1], pz = o[2] + t * d[2];
                    ray_hit[e] = 1;
                    hit_t[e] = t;
#if ITEMS && CLVIS_INT64_ATOMICS
                    /* the nearest hit of the pixel's items: t >= 0, so its bits order as uints */
                    clvis_atomic_min_u64(hitkey + p, ((ulong)as_uint(t) << 32) | e);
#endif
                    rgba[e] = (float4)(clamp(SHADE_BASE_R * lit + spec, 0.0f, 1.0f),
                                       clamp(SHADE_BASE_G * lit + spec, 0.0f, 1.0f),
                                       clamp(SHADE_BASE_B * lit + spec, 0.0f, 1.0f), 1.0f);
                    depth[e] = clvis_dot3(cam[18], cam[19], cam[20], px, py, pz) + cam[21];
                    out_t = -1.0f; /* marks the hit: ray_t stays */
                    break;
                }
            }
            if (t_out >= t_exit) {
                out_t = INFINITY;
                break;
            }
            c[axis] += inv[axis] > 0.0f ? 1 : -1;
            if (c[axis] < 0 || c[axis] > n[axis] - 2) {
                out_t = INFINITY;
                break;
            }
            if (c[axis] < clo[axis] || c[axis] > chi[axis]) {
                out_t = t_out;
                break;
            }
            t_in = t_out;
        }
#if !ITEMS
        if (out_t >= 0.0f)
            ray_t[p] = out_t;
#endif
    }
}
