/* march.cl — ray marching through Gaussians in depth order over an LBVH
 * (3D Gaussian Ray Tracing's k-buffer rounds; Sharma & Schmalstieg's
 * absorption model as the alternative).
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/bvh.h, clvis/gauss.h,
 *     clvis/ray.h).
 * Build options: -cl-fp32-correctly-rounded-divide-sqrt.
 * Defines:
 *   K      the k-buffer size, 1..64 (default 16): hits gathered per round at most
 *   K0     hits gathered in the first round (default K); each later round
 *          doubles it, up to K. A small K0 stops the first traversal early for
 *          rays that turn opaque after a few hits; a large K needs fewer rounds
 *          for rays that go through many.
 *   MODEL  0: max response (3DGRT): alpha = min(0.99, opacity' * exp(-m2 / 2)),
 *             m2 at the ray's closest approach t (clvis/gauss.h)
 *          1: absorption: alpha = 1 - exp(-density * opacity' * I), I the line
 *             integral of exp(-|W(x - mean)|^2 / 2) over the ray's t >= 0:
 *             I = exp(-ms2 / 2) * sqrt(pi / (2a)) * erfc(-ts * sqrt(a / 2)),
 *             ms2 = |o' + ts d'|^2 at the unclamped ts
 *   (default 0). opacity' = record opacity * the transfer function's alpha.
 *   COLOR  0: a hit's colour is its transfer-function entry's rgb
 *          1: a hit's colour is colors[id].xyz / 255 (its own rgb; .w unused);
 *             the transfer function still gives the alpha factor
 *   (default 0).
 *
 * kernel march(global const clvis_bvh_node *nodes,  the LBVH of clvis/bvh.h (n - 1 nodes, root 0;
 *                                                   one node with right = NONE when n == 1)
 *              global const float *leaf_boxes,      n x 6 (lo xyz, hi xyz), leaf order
 *              global const clvis_gaussian *recs,   n records in leaf order (clvis/gauss.h)
 *              global const uint *order,            leaf j is Gaussian order[j] (its id)
 *              uint n, global const float *cam,     22 floats: the camera rays of clvis/camera.h
 *              uint W, uint H,
 *              global const float4 *tf, uint tf_n,  transfer function: rgb colour, alpha factor
 *              float tf_min, float tf_scale,        entry i = clamp(floor((value - tf_min) * tf_scale * tf_n), 0, tf_n - 1)
 *              float cutoff2, float density,
 *              global const uchar4 *colors,         COLOR 1: n rgb(a) colours indexed by Gaussian id
 *                                                   (original order, not leaf order); COLOR 0: unread
 *              uint y0, uint rows,                  the band of image rows y0 .. y0 + rows - 1 to render
 *              global float4 *rgba,                 rows * W: premultiplied rgb, alpha = 1 - T
 *              global float *depth,                 rows * W: view depth where T first drops below 0.5, else +inf
 *              global uint2 *stats)                 rows * W: (Gaussians composited, rounds)
 *     The outputs hold the band only: pixel (px, py) at (py - y0) * W + px. A
 *     host renders a large image band by band over the same BVH (bounded
 *     memory for the per-ray state), or in one band (y0 = 0, rows = H).
 *     Global size: 64 * ceil(W / 8) * ceil(rows / 8), a work-item per pixel of 8 x 8 pixel
 *     tiles of the band (work-item i: tile i / 64, pixel i % 64 in it, row-major); any local
 *     size dividing 64 (64 on GPUs: a tile a group).
 *     Per ray: rounds of a full BVH traversal collecting the k nearest hits (k = K0, 2 K0, ... K)
 *     whose key (t, id) is beyond the last key composited, then compositing
 *     them front to back: C += T * alpha * rgb, T *= 1 - alpha, until T < 1e-3
 *     (after the Gaussian that brought it there) or a round finds fewer than k.
 *     A hit is m2 <= cutoff2 at t >= 0; the hit order is (t, id) ascending.
 *     Boxes are culled by clvis_ray_slab of clvis/ray.h (1/d by its tiny-direction
 *     rule); the Gaussians by clvis_gauss_hit of clvis/gauss.h.
 *     Stages: collect_round (the traversal: clvis_ray_slab, clvis_gauss_hit,
 *     clvis_gauss_hit_alpha, kbuffer_insert), then hit_color and clvis_gauss_composite per hit.
 */
#pragma OPENCL FP_CONTRACT OFF

#include "clvis/bvh.h"
#include "clvis/gauss.h"
#include "clvis/ray.h"

#ifndef K
#define K 16
#endif
#ifndef K0
#define K0 K
#endif
#ifndef MODEL
#define MODEL 0
#endif
#ifndef COLOR
#define COLOR 0
#endif
#define STACK 64
#define T_STOP 1e-3f

/* The colour hit (leaf j, transfer-function entry ti) composites with (COLOR). */
inline float4 hit_color(global const float4 *tf, uint ti, global const uchar4 *colors,
                        global const uint *order, uint j)
{
#if COLOR == 1
    return clvis_gauss_rgb8(colors[order[j]]);
#else
    return tf[ti];
#endif
}

/* Put hit (t, id) of leaf j at position pos of the k-buffer (pos: its free
 * slot or the last one), moving it forward to keep (t, id) ascending. */
inline void kbuffer_insert(float *kt, uint *kj, float *ka, uint *kc, global const uint *order, int pos,
                           float t, uint id, uint j, float alpha, uint ti)
{
    while (pos > 0 && clvis_gauss_key_less(t, id, kt[pos - 1], order[kj[pos - 1]])) {
        kt[pos] = kt[pos - 1];
        kj[pos] = kj[pos - 1];
        ka[pos] = ka[pos - 1];
        kc[pos] = kc[pos - 1];
        --pos;
    }
    kt[pos] = t;
    kj[pos] = j;
    ka[pos] = alpha;
    kc[pos] = ti;
}

/* One round: a full traversal of the BVH collecting into the k-buffer (kt,
 * kj, ka, kc) the cap nearest hits whose key is beyond (last_t, last_id);
 * returns how many it holds (< cap: the ray has no more hits). A subtree is
 * skipped when its box misses the ray at t >= lower or, with the buffer
 * full, the box starts beyond the buffer's last hit. */
inline int collect_round(global const clvis_bvh_node *nodes, global const float *leaf_boxes,
                         global const clvis_gaussian *recs, global const uint *order,
                         const float *o, const float *d, const float *inv, float last_t, uint last_id,
                         int cap, global const float4 *tf, uint tf_n, float tf_min, float tf_scale,
                         float cutoff2, float density, float *kt, uint *kj, float *ka, uint *kc)
{
    uint stack[STACK];
    float stack_t[STACK];
    int kn = 0;
    int sp = 0;
    float lower = fmax(last_t, 0.0f);
    /* root */
    {
        float t0, t1;
        global const clvis_bvh_node *r = nodes;
        clvis_ray_slab(o, inv, r->lo[0], r->lo[1], r->lo[2], r->hi[0], r->hi[1], r->hi[2], &t0, &t1);
        if (t1 >= t0 && t1 >= lower) {
            stack[sp] = 0;
            stack_t[sp++] = t0;
        }
    }
    while (sp > 0) {
        --sp;
        uint node = stack[sp];
        if (kn == cap && stack_t[sp] > kt[cap - 1])
            continue;
        global const clvis_bvh_node *nd = nodes + node;
        uint ch[2] = {nd->left, nd->right};
        uint push[2];
        float push_t[2];
        int np = 0;
        for (int c = 0; c < 2; ++c) {
            uint child = ch[c];
            if (child == CLVIS_BVH_NONE)
                continue;
            float t0, t1;
            if (child & CLVIS_BVH_LEAF) {
                uint j = child & ~CLVIS_BVH_LEAF;
                global const float *bx = leaf_boxes + 6 * (size_t)j;
                clvis_ray_slab(o, inv, bx[0], bx[1], bx[2], bx[3], bx[4], bx[5], &t0, &t1);
                if (!(t1 >= t0 && t1 >= lower) || (kn == cap && t0 > kt[cap - 1]))
                    continue;
                float t, m2, ts, a, op[3], dp[3];
                clvis_gauss_hit(recs + j, o, d, &t, &m2, &ts, &a, op, dp);
                if (!(m2 <= cutoff2))
                    continue;
                uint id = order[j];
                if (!clvis_gauss_key_less(last_t, last_id, t, id))
                    continue;
                int pos;
                if (kn < cap)
                    pos = kn++;
                else if (clvis_gauss_key_less(t, id, kt[cap - 1], order[kj[cap - 1]]))
                    pos = cap - 1;
                else
                    continue;
                uint ti;
                float alpha = clvis_gauss_hit_alpha(recs + j, tf, tf_n, tf_min, tf_scale, MODEL, density, m2,
                                                    ts, a, op, dp, &ti);
                kbuffer_insert(kt, kj, ka, kc, order, pos, t, id, j, alpha, ti);
            } else {
                global const clvis_bvh_node *cn = nodes + child;
                clvis_ray_slab(o, inv, cn->lo[0], cn->lo[1], cn->lo[2], cn->hi[0], cn->hi[1], cn->hi[2], &t0, &t1);
                if (!(t1 >= t0 && t1 >= lower) || (kn == cap && t0 > kt[cap - 1]))
                    continue;
                push[np] = child;
                push_t[np++] = t0;
            }
        }
        /* the nearer child on top */
        if (np == 2 && push_t[0] < push_t[1]) {
            stack[sp] = push[1];
            stack_t[sp++] = push_t[1];
            stack[sp] = push[0];
            stack_t[sp++] = push_t[0];
        } else {
            for (int c = 0; c < np; ++c) {
                stack[sp] = push[c];
                stack_t[sp++] = push_t[c];
            }
        }
    }
    return kn;
}

kernel void march(global const clvis_bvh_node *nodes, global const float *leaf_boxes,
                  global const clvis_gaussian *recs, global const uint *order, uint n,
                  global const float *cam, uint W, uint H, global const float4 *tf, uint tf_n,
                  float tf_min, float tf_scale, float cutoff2, float density,
                  global const uchar4 *colors, uint y0, uint rows,
                  global float4 *rgba, global float *depth, global uint2 *stats)
{
    uint tiles_x = (W + 7) / 8;
    uint tile = get_global_id(0) / 64, l = get_global_id(0) % 64;
    uint px = (tile % tiles_x) * 8 + (l & 7), row = (tile / tiles_x) * 8 + (l >> 3);
    uint py = y0 + row;
    if (px >= W || row >= rows || py >= H)
        return;
    size_t pix = (size_t)row * W + px;

    float o[3], d[3], inv[3];
    clvis_camera_ray(cam, px, py, o, d);
    for (int k = 0; k < 3; ++k)
        inv[k] = clvis_ray_inv_dir(d[k]);

    float T = 1.0f, cr = 0.0f, cg = 0.0f, cb = 0.0f, z = INFINITY;
    float last_t = -1.0f;   /* every hit has t >= 0 */
    uint last_id = 0, hits = 0, rounds = 0;
    bool done = n == 0;
    float kt[K];           /* the round's hits: t ascending, ties by id */
    uint kj[K];            /* their leaf positions (id = order[j]) */
    float ka[K];           /* their alpha */
    uint kc[K];            /* their transfer-function entry */

    /* the round's capacity: K0 in the first round, doubling up to K, so a ray
     * that turns opaque early does not traverse its whole length for K hits */
    int cap = K0 < K ? K0 : K;
    while (!done) {
        ++rounds;
        int kn = collect_round(nodes, leaf_boxes, recs, order, o, d, inv, last_t, last_id, cap, tf, tf_n,
                               tf_min, tf_scale, cutoff2, density, kt, kj, ka, kc);
        /* composite the round front to back */
        for (int h = 0; h < kn; ++h) {
            clvis_gauss_composite(ka[h], hit_color(tf, kc[h], colors, order, kj[h]), &T, &cr, &cg, &cb);
            ++hits;
            if (T < 0.5f && z == INFINITY)
                z = clvis_ray_depth(cam, o, d, kt[h]);
            if (T < T_STOP) {
                done = true;
                break;
            }
        }
        if (kn < cap)
            done = true;
        else {
            last_t = kt[cap - 1];
            last_id = order[kj[cap - 1]];
            cap = 2 * cap < K ? 2 * cap : K;
        }
    }
    rgba[pix] = (float4)(cr, cg, cb, 1.0f - T);
    depth[pix] = z;
    stats[pix] = (uint2)(hits, rounds);
}
