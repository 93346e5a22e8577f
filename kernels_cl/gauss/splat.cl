/* splat.cl — the forward pass of 3D Gaussian Splatting (Kerbl et al. 2023):
 * each Gaussian projected to a 2D Gaussian by the EWA local affine
 * approximation, binned to screen tiles, sorted per tile by the view depth of
 * its mean, and alpha-blended front to back. NARVis's "GR". The binning and
 * the sort are tiles.cl's (tile_ranges, clvis.primitives scan and radix sort).
 *
 * ABI
 * ---
 * Build options: -cl-fp32-correctly-rounded-divide-sqrt.
 * Defines: TS (tile side in pixels, default 16); COLOR (0: transfer-function
 * rgb, 1: colors[id], as march.cl; default 0).
 * Arguments as tiles.cl's (recs, proj, near, W, H, ty0, ty1), and:
 *   splats  n x 8 floats per Gaussian, written by splat_count:
 *           u, v (the projected mean, continuous pixel coordinates, centres at
 *           integer + 0.5), A, B, C (the conic: the inverse of the 2D
 *           covariance S2, q(dx, dy) = A dx^2 + 2 B dx dy + C dy^2), depth (view
 *           depth of the mean), visible (1 or 0), unused
 *
 * kernel splat_count(recs, uint n, proj, float near, uint W, uint H, uint ty0, uint ty1,
 *                    global float *splats, global ulong *counts)
 *     S2 = J S J^T + 0.3 I, S = L L^T the 3D covariance (L = W^-1, clvis/gauss.h),
 *     J = (1 / w) [Pu - uc Pw; Pv - vc Pw] (xyz parts, w = Pw (mean, 1)), uc, vc
 *     the projected mean clamped to 1.3 x the half image around its centre
 *     (3DGS's limit on the Jacobian). Culled: depth <= near, w <= 0, det(S2) <= 0.
 *     counts[i]: the band's tiles that the ellipse q <= 9 (3 sigma), inflated by
 *     1e-3 and 0.05 px, holds a pixel centre of (tiles.cl's footprint test,
 *     clvis_ellipse_row).
 * kernel splat_keys(same, global const float *splats, global const ulong *offsets,
 *                   global ulong *keys, global uint *ids)
 *     keys: (tile - band's first) << 32 | clvis_key_f32(depth), ids: i.
 * kernel splat_render(recs, global const uint *order (record j is Gaussian order[j], for
 *                     its colour), splats, keys, ids, ranges, uint W, uint H, uint ty0,
 *                     uint tile0, uint rows, uint out_y0 (as tiles.cl's tile_render),
 *                     tf, tf_n, tf_min, tf_scale, colors, rgba, depth, stats)
 *     Per pixel (px, py), its tile's list in (depth, record) order (equal
 *     depths by record position, the host's Morton order, not by id): d = (u, v) -
 *     (px + 0.5, py + 0.5), q = (A dx^2 + C dy^2) + 2 B dx dy; skipped when
 *     q > 9; alpha = min(0.99, opacity' exp(-q / 2)); skipped when alpha < 1/255;
 *     T' = T (1 - alpha); T' < 1e-4 ends the pixel without this Gaussian;
 *     else C += T alpha rgb, T = T'. rgba = (C, 1 - T); depth: the mean's depth
 *     of the Gaussian that first took T below 0.5 (+inf if none); stats =
 *     (Gaussians composited, 1). Global size and work-items as tiles.cl's
 *     tile_render (a work-item per pixel).
 * kernel splat_render8(the arguments of splat_render)
 *     splat_render's outputs (the same bits), a work-item per row of 8 pixels
 *     of a tile (TS a multiple of 8; q in float8 lanes). Global size and
 *     work-items as tiles.cl's tile_render8: (tiles to render) * TS * TS / 8,
 *     any local size dividing TS * TS / 8.
 */
#pragma OPENCL FP_CONTRACT OFF

#include "clvis/gauss.h"
#include "clvis/gauss_tiles.h"
#include "clvis/keys.h"

#ifndef TS
#define TS 16
#endif
#ifndef COLOR
#define COLOR 0
#endif
#define SPLAT_T_STOP 1e-4f
#define SPLAT_Q_MAX 9.0f
#define SPLAT_LOWPASS 0.3f

/* the 2D splat of g into s[0..7]; returns 0 when culled */
inline int splat_project(global const clvis_gaussian *g, global const float *proj, float near, uint W, uint H,
                         float *s)
{
    for (int k = 0; k < 8; ++k)
        s[k] = 0.0f;
    float L[3][3];
    clvis_gauss_inverse(g, L);
    float mx = g->mean[0], my = g->mean[1], mz = g->mean[2];
    global const float *Pu = proj, *Pv = proj + 4, *Pw = proj + 8, *D = proj + 12;
    float w = clvis_row4(Pw, mx, my, mz), dep = clvis_row4(D, mx, my, mz);
    if (!(dep > near) || !(w > 0.0f))
        return 0;
    float u = clvis_row4(Pu, mx, my, mz) / w, v = clvis_row4(Pv, mx, my, mz) / w;
    float hw = 0.5f * (float)W, hh = 0.5f * (float)H;
    /* clamp(u, lo, hi) (u NaN is culled below) */
    float uc = clvis_lo(clvis_hi(u, hw - 1.3f * hw), hw + 1.3f * hw);
    float vc = clvis_lo(clvis_hi(v, hh - 1.3f * hh), hh + 1.3f * hh);
    float J[2][3];
    for (int k = 0; k < 3; ++k) {
        J[0][k] = (Pu[k] - uc * Pw[k]) / w;
        J[1][k] = (Pv[k] - vc * Pw[k]) / w;
    }
    /* M = J L (2 x 3); S2 = M M^T + 0.3 I */
    float M[2][3];
    for (int r = 0; r < 2; ++r)
        for (int k = 0; k < 3; ++k)
            M[r][k] = clvis_dot3(J[r][0], J[r][1], J[r][2], L[0][k], L[1][k], L[2][k]);
    float a = clvis_dot3(M[0][0], M[0][1], M[0][2], M[0][0], M[0][1], M[0][2]) + SPLAT_LOWPASS;
    float b = clvis_dot3(M[0][0], M[0][1], M[0][2], M[1][0], M[1][1], M[1][2]);
    float c = clvis_dot3(M[1][0], M[1][1], M[1][2], M[1][0], M[1][1], M[1][2]) + SPLAT_LOWPASS;
    float det = a * c - b * b;
    if (!(det > 0.0f) || !clvis_il_isfinite(det) || !clvis_il_isfinite(u) || !clvis_il_isfinite(v))
        return 0;
    s[0] = u;
    s[1] = v;
    s[2] = c / det;
    s[3] = -b / det;
    s[4] = a / det;
    s[5] = dep;
    s[6] = 1.0f;
    s[7] = 0.0f;
    return 1;
}

/* the tiles (inclusive range) and the test of the ellipse q <= 9 (inflated) */
typedef struct {
    clvis_ellipse e;
    clvis_ellipse_rows r;
    int tx0, tx1, ty0, ty1;
} splat_fp;

inline int splat_footprint(const float *s, uint W, uint H, splat_fp *f)
{
    if (s[6] == 0.0f)
        return 0;
    /* E = 9.009 S2 = 9.009 inverse(conic) */
    float ca = s[2], cb = s[3], cc = s[4];
    float cdet = ca * cc - cb * cb;
    float k = SPLAT_Q_MAX * 1.001f;
    float euu = k * cc / cdet, evv = k * ca / cdet, euv = -k * cb / cdet;
    float det = euu * evv - euv * euv;
    if (!(euu > 0.0f && evv > 0.0f && det > 0.0f && clvis_il_isfinite(det)))
        return 0;
    clvis_ellipse_set(&f->e, s[0], s[1], euu, evv, euv, det);
    clvis_ellipse_rows_set(&f->e, &f->r);
    float hu = sqrt(euu) + f->e.pad, hv = sqrt(evv) + f->e.pad;
    int r[4];
    if (!clvis_tile_rect(s[0] - hu, s[0] + hu, s[1] - hv, s[1] + hv, W, H, TS, r))
        return 0;
    f->tx0 = r[0];
    f->tx1 = r[1];
    f->ty0 = r[2];
    f->ty1 = r[3];
    return 1;
}

/* the tile columns c0 .. c1 of tile row ty that the ellipse meets; 0 when none */
inline int splat_row(const splat_fp *f, int ty, uint W, uint H, int *c0, int *c1)
{
    int a, b;
    if (!clvis_ellipse_row(&f->r, ty, W, H, TS, &a, &b))
        return 0;
    *c0 = clvis_il_imax(a, f->tx0);
    *c1 = clvis_il_imin(b, f->tx1);
    return *c0 <= *c1;
}

kernel void splat_count(global const clvis_gaussian *recs, uint n, global const float *proj, float near,
                        uint W, uint H, uint ty0, uint ty1, global float *splats, global ulong *counts)
{
    uint i = get_global_id(0);
    if (i >= n)
        return;
    float s[8];
    splat_project(recs + i, proj, near, W, H, s);
    for (int k = 0; k < 8; ++k)
        splats[8 * (size_t)i + k] = s[k];
    splat_fp f;
    ulong cnt = 0;
    if (splat_footprint(s, W, H, &f)) {
        int y0 = clvis_il_imax(f.ty0, (int)ty0), y1 = clvis_il_imin(f.ty1, (int)ty1 - 1);
        for (int ty = y0; ty <= y1; ++ty) {
            int c0, c1;
            if (splat_row(&f, ty, W, H, &c0, &c1))
                cnt += (ulong)(c1 - c0 + 1);
        }
    }
    counts[i] = cnt;
}

kernel void splat_keys(global const clvis_gaussian *recs, uint n, global const float *proj, float near,
                       uint W, uint H, uint ty0, uint ty1, global const float *splats,
                       global const ulong *offsets, global ulong *keys, global uint *ids)
{
    uint i = get_global_id(0);
    if (i >= n)
        return;
    float s[8];
    for (int k = 0; k < 8; ++k)
        s[k] = splats[8 * (size_t)i + k];
    splat_fp f;
    if (!splat_footprint(s, W, H, &f))
        return;
    uint tiles_x = (W + TS - 1) / TS;
    ulong dkey = (ulong)clvis_key_f32(as_uint(s[5]));
    ulong at = offsets[i];
    int y0 = clvis_il_imax(f.ty0, (int)ty0), y1 = clvis_il_imin(f.ty1, (int)ty1 - 1);
    for (int ty = y0; ty <= y1; ++ty) {
        int c0, c1;
        if (!splat_row(&f, ty, W, H, &c0, &c1))
            continue;
        for (int tx = c0; tx <= c1; ++tx) {
            keys[at] = ((ulong)(ty - (int)ty0) * tiles_x + (ulong)tx) << 32 | dkey;
            ids[at] = i;
            ++at;
        }
    }
}

kernel void splat_render(global const clvis_gaussian *recs, global const uint *order, global const float *splats,
                         global const ulong *keys,
                         global const uint *ids, global const uint2 *ranges, uint W, uint H, uint ty0,
                         uint tile0, uint rows, uint out_y0, global const float4 *tf, uint tf_n, float tf_min,
                         float tf_scale, global const uchar4 *colors, global float4 *rgba, global float *depth,
                         global uint2 *stats)
{
    uint px, py, row;
    uint tile = clvis_tile_pixel(get_global_id(0), W, ty0, tile0, TS, &px, &py, &row);
    if (px >= W || row >= rows || py >= H)
        return;
    size_t pix = (size_t)(py - out_y0) * W + px;
    float fx = (float)px + 0.5f, fy = (float)py + 0.5f;
    uint2 range = ranges[tile];
    float T = 1.0f, cr = 0.0f, cg = 0.0f, cb = 0.0f, z = INFINITY;
    uint hits = 0;
    for (uint i = range.x; i < range.y; ++i) {
        uint id = ids[i];
        global const float *s = splats + 8 * (size_t)id;
        float dx = s[0] - fx, dy = s[1] - fy;
        float q = (s[2] * dx * dx + s[4] * dy * dy) + 2.0f * s[3] * dx * dy;
        if (!(q <= SPLAT_Q_MAX))
            continue;
        global const clvis_gaussian *g = recs + id;
        uint ti = clvis_gauss_tf_index(g->value, tf_min, tf_scale, tf_n);
        float alpha = fmin(0.99f, (g->opacity * tf[ti].w) * exp(-0.5f * q));
        if (alpha < 1.0f / 255.0f)
            continue;
        float Tn = T * (1.0f - alpha);
        if (Tn < SPLAT_T_STOP)
            break;
#if COLOR == 1
        float4 c = clvis_gauss_rgb8(colors[order[id]]);
#else
        float4 c = tf[ti];
#endif
        clvis_gauss_composite(alpha, c, &T, &cr, &cg, &cb);
        ++hits;
        if (T < 0.5f && z == INFINITY)
            z = s[5];
    }
    rgba[pix] = (float4)(cr, cg, cb, 1.0f - T);
    depth[pix] = z;
    stats[pix] = (uint2)(hits, 1u);
}

/* ---------------------------------------------------------------- 8 lanes
 * splat_render8: splat_render's result (the same bits), a work-item per row
 * of 8 pixels of a tile (TS a multiple of 8; work-items as tiles.cl's
 * tile_render8): a candidate's id and splat are read once for the 8 pixels
 * and q is computed in float8 lanes (the same operations as splat_render,
 * lane by lane); alpha, the stop test and compositing lane by lane for the
 * lanes with q <= 9 only. The row ends when its 8 pixels have stopped.
 * Same arguments as splat_render. */
kernel void splat_render8(global const clvis_gaussian *recs, global const uint *order, global const float *splats,
                          global const ulong *keys, global const uint *ids, global const uint2 *ranges, uint W,
                          uint H, uint ty0, uint tile0, uint rows, uint out_y0, global const float4 *tf, uint tf_n,
                          float tf_min, float tf_scale, global const uchar4 *colors, global float4 *rgba,
                          global float *depth, global uint2 *stats)
{
    uint px0, py, row;
    uint tile = clvis_tile_row8(get_global_id(0), W, ty0, tile0, TS, &px0, &py, &row);
    if (px0 >= W || row >= rows || py >= H)
        return;
    float fxs[8], T[8], cr[8], cg[8], cb[8], z[8];
    uint hits[8];
    int on[8];   /* -1: the lane still blends (a mask lane of int8), 0: stopped */
    uint2 range = ranges[tile];
    int live = 0;
    for (int l = 0; l < 8; ++l) {
        fxs[l] = (float)(px0 + l) + 0.5f;
        T[l] = 1.0f;
        cr[l] = cg[l] = cb[l] = 0.0f;
        z[l] = INFINITY;
        hits[l] = 0;
        on[l] = px0 + l < W ? -1 : 0;
        live += on[l] != 0;
    }
    float8 fx = vload8(0, fxs);
    float fy = (float)py + 0.5f;
    int8 on8 = vload8(0, on);
    for (uint i = range.x; i < range.y && live > 0; ++i) {
        uint id = ids[i];
        global const float *s = splats + 8 * (size_t)id;
        float8 dx = s[0] - fx;
        float dy = s[1] - fy;
        float8 q8 = (s[2] * dx * dx + s[4] * dy * dy) + 2.0f * s[3] * dx * dy;
        int8 in8 = (q8 <= SPLAT_Q_MAX) & on8;
        if (!clvis_il_any8(in8))
            continue;
        global const clvis_gaussian *g = recs + id;
        uint ti = clvis_gauss_tf_index(g->value, tf_min, tf_scale, tf_n);
        float opac = g->opacity * tf[ti].w;
#if COLOR == 1
        float4 c = clvis_gauss_rgb8(colors[order[id]]);
#else
        float4 c = tf[ti];
#endif
        float q[8];
        int in[8];
        vstore8(q8, 0, q);
        vstore8(in8, 0, in);
        for (int l = 0; l < 8; ++l) {
            if (!in[l])
                continue;
            float alpha = fmin(0.99f, opac * exp(-0.5f * q[l]));
            if (alpha < 1.0f / 255.0f)
                continue;
            float Tn = T[l] * (1.0f - alpha);
            if (Tn < SPLAT_T_STOP) {
                on[l] = 0;
                --live;
                continue;
            }
            clvis_gauss_composite(alpha, c, &T[l], &cr[l], &cg[l], &cb[l]);
            ++hits[l];
            if (T[l] < 0.5f && z[l] == INFINITY)
                z[l] = s[5];
        }
        on8 = vload8(0, on);
    }
    for (int l = 0; l < 8 && px0 + l < W; ++l) {
        size_t pix = (size_t)(py - out_y0) * W + px0 + l;
        rgba[pix] = (float4)(cr[l], cg[l], cb[l], 1.0f - T[l]);
        depth[pix] = z[l];
        stats[pix] = (uint2)(hits[l], 1u);
    }
}
