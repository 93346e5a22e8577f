/* splat.cl — the forward pass of 3D Gaussian Splatting (Kerbl et al. 2023):
 * each Gaussian projected to a 2D Gaussian by the EWA local affine
 * approximation, binned to screen tiles, sorted per tile by the view depth of
 * its mean, and alpha-blended front to back. NARVis's "GR". The binning and
 * the sort are tiles.cl's (tile_ranges, clvis.primitives scan and radix sort).
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/gauss.h,
 *     clvis/gauss_tiles.h, clvis/keys.h).
 * Build options: -cl-fp32-correctly-rounded-divide-sqrt.
 * Defines: TS (tile side in pixels, default 16); COLOR (0: transfer-function
 * rgb, 1: colors[id], as march.cl; default 0).
 * Arguments as tiles.cl's (recs, proj, near, W, H, ty0, ty1), and its data
 * flow (scan of the counts, sort of the keys with the ids, tile_ranges), with
 * splat_count and splat_keys in place of tile_count and tile_keys (no
 * gather_records: splat_render reads recs by id); splat_count and splat_keys
 * take one work-item per Gaussian: global size >= n, any local size. And:
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
 * kernel splat_count8(the arguments of splat_count)
 * kernel splat_keys8(the arguments of splat_keys)
 *     splat_count's and splat_keys's outputs (the same bits), a work-item per 8
 *     consecutive Gaussians 8 g .. 8 g + 7 (global size at least ceil(n / 8),
 *     any local size): projection, footprint and tile-row tests in float8 /
 *     int8 lanes (the same operations lane by lane), keys written lane by lane.
 * kernel splat_render(recs, global const uint *order (record j is Gaussian order[j], for
 *                     its colour), splats, keys, ids, ranges, uint W, uint H, uint ty0,
 *                     uint tile0, uint rows, uint out_y0 (as tiles.cl's tile_render),
 *                     tf, tf_n, tf_min, tf_scale, colors, rgba, depth, stats)
 *     Per pixel (px, py), its tile's list in (depth, record) order (equal
 *     depths by record position, the host's Morton order, not by id): d = (u, v) -
 *     (px + 0.5, py + 0.5), q = (A dx^2 + C dy^2) + 2 B dx dy; skipped when
 *     q > 9; alpha = min(0.99, opacity' exp(-q / 2)) (splat_alpha: splat.cl's
 *     own exp, within 2.3 x 2^-24 relative); skipped when alpha < 1/255;
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

/* The splat alpha min(0.99, opac exp(x)), x = -q / 2 in [-4.5, 0] (q <= 9),
 * with splat.cl's own exp: n = trunc(x log2 e - 1/2), r = x - n ln 2 (ln 2 in
 * two parts, Cody-Waite), exp(r) by its Taylor polynomial of degree 7
 * (Horner), times 2^n from the exponent bits: within 2.3 x 2^-24 relative of
 * exp for x in [-80, 0.5]. The scalar and the float8 forms are the same
 * operations lane by lane (FP_CONTRACT OFF: no fused multiply-add), so
 * splat_render and splat_render8 agree bit for bit with the alphas in float8
 * lanes, without a call (PoCL calls its exp out of line, and its float8 exp
 * differs from its scalar one in the last bit). min(0.99, a) by comparison:
 * a NaN gives 0.99, as fmin. splat_alpha takes q <= 9 (its callers' test);
 * splat_alpha8 any q, lanes above 9 (or NaN) giving a value in range. */
#define SPLAT_LOG2E 1.44269504f
#define SPLAT_LN2_HI 0.693145751953125f
#define SPLAT_LN2_LO 1.428606765330187e-06f

inline float splat_alpha(float opac, float q)
{
    float x = -0.5f * q;
    int n = (int)(x * SPLAT_LOG2E - 0.5f);
    float fn = (float)n;
    float r = (x - fn * SPLAT_LN2_HI) - fn * SPLAT_LN2_LO;
    float p = 1.0f / 5040.0f;
    p = p * r + 1.0f / 720.0f;
    p = p * r + 1.0f / 120.0f;
    p = p * r + 1.0f / 24.0f;
    p = p * r + 1.0f / 6.0f;
    p = p * r + 0.5f;
    p = p * r + 1.0f;
    p = p * r + 1.0f;
    float a = opac * (p * as_float((uint)(n + 127) << 23));
    return a < 0.99f ? a : 0.99f;
}

inline float8 splat_alpha8(float opac, float8 q8)
{
    float8 q = q8 <= SPLAT_Q_MAX ? q8 : (float8)(SPLAT_Q_MAX);   /* lanes out (q > 9, NaN): any value, in range */
    float8 x = -0.5f * q;
    int8 n = convert_int8(x * SPLAT_LOG2E - 0.5f);
    float8 fn = convert_float8(n);
    float8 r = (x - fn * SPLAT_LN2_HI) - fn * SPLAT_LN2_LO;
    float8 p = (float8)(1.0f / 5040.0f);
    p = p * r + 1.0f / 720.0f;
    p = p * r + 1.0f / 120.0f;
    p = p * r + 1.0f / 24.0f;
    p = p * r + 1.0f / 6.0f;
    p = p * r + 0.5f;
    p = p * r + 1.0f;
    p = p * r + 1.0f;
    float8 a = opac * (p * as_float8(as_uint8(n + 127) << 23));
    return a < 0.99f ? a : (float8)(0.99f);
}

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
        float alpha = splat_alpha(g->opacity * tf[ti].w, q);
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
 * lane by lane), and so are the alphas (splat_alpha8); the stop test and compositing lane by lane for the
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
        float al[8];
        int in[8];
        vstore8(splat_alpha8(opac, q8), 0, al);
        vstore8(in8, 0, in);
        for (int l = 0; l < 8; ++l) {
            if (!in[l])
                continue;
            float alpha = al[l];
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

/* ---------------------------------------------------------------- 8 Gaussians a work-item
 * splat_count8 / splat_keys8: splat_count's and splat_keys's outputs (the
 * same bits: splats, counts, keys, ids), a work-item per 8 consecutive
 * Gaussians 8 i .. 8 i + 7 (global size ceil(n / 8)): the projection, the
 * footprint and each tile row's test in float8 / int8 lanes, the same
 * operations as splat_project, splat_footprint and clvis_ellipse_row lane by
 * lane (divisions and sqrt correctly rounded, so vector and scalar agree);
 * the keys written lane by lane in splat_keys's order. For PoCL, which
 * neither inlines the scalar helpers nor vectorises across work-items. */
inline float8 splat_lo8(float8 a, float8 b)
{
    return a < b ? a : b;
}

inline float8 splat_hi8(float8 a, float8 b)
{
    return a > b ? a : b;
}

inline float8 splat_dot3_8(float8 a0, float8 a1, float8 a2, float8 b0, float8 b1, float8 b2)
{
    return (a0 * b0 + a1 * b1) + a2 * b2;
}

inline float8 splat_row4_8(global const float *r, float8 x, float8 y, float8 z)
{
    return ((r[0] * x + r[1] * y) + r[2] * z) + r[3];
}

inline int8 splat_isfinite8(float8 x)
{
    return (as_int8(x) & (int8)(0x7F800000)) != (int8)(0x7F800000);
}

/* splat_project on Gaussians i0 .. i0 + 7 (index clamped to n - 1): s[k] the lanes of s[k] */
inline void splat_project8(global const clvis_gaussian *recs, uint i0, uint n, global const float *proj, float near,
                           uint W, uint H, float8 *s)
{
    float f[12][8];
    for (int l = 0; l < 8; ++l) {
        global const clvis_gaussian *g = recs + clvis_il_umin(i0 + (uint)l, n - 1u);
        f[0][l] = g->mean[0];
        f[1][l] = g->mean[1];
        f[2][l] = g->mean[2];
        for (int k = 0; k < 9; ++k)
            f[3 + k][l] = g->w[k];
    }
    float8 mx = CLVIS_IL_VLOAD8(float8, f[0]), my = CLVIS_IL_VLOAD8(float8, f[1]),
           mz = CLVIS_IL_VLOAD8(float8, f[2]);
    float8 w[9];
    for (int k = 0; k < 9; ++k)
        w[k] = CLVIS_IL_VLOAD8(float8, f[3 + k]);
    float8 L[3][3];
    for (int k = 0; k < 3; ++k) {
        float8 r2 = splat_dot3_8(w[3 * k], w[3 * k + 1], w[3 * k + 2], w[3 * k], w[3 * k + 1], w[3 * k + 2]);
        for (int j = 0; j < 3; ++j)
            L[j][k] = w[3 * k + j] / r2;
    }
    global const float *Pu = proj, *Pv = proj + 4, *Pw = proj + 8, *D = proj + 12;
    float8 pw = splat_row4_8(Pw, mx, my, mz), dep = splat_row4_8(D, mx, my, mz);
    int8 ok = (dep > near) & (pw > 0.0f);
    float8 u = splat_row4_8(Pu, mx, my, mz) / pw, v = splat_row4_8(Pv, mx, my, mz) / pw;
    float hw = 0.5f * (float)W, hh = 0.5f * (float)H;
    float8 uc = splat_lo8(splat_hi8(u, (float8)(hw - 1.3f * hw)), (float8)(hw + 1.3f * hw));
    float8 vc = splat_lo8(splat_hi8(v, (float8)(hh - 1.3f * hh)), (float8)(hh + 1.3f * hh));
    float8 J[2][3];
    for (int k = 0; k < 3; ++k) {
        J[0][k] = (Pu[k] - uc * Pw[k]) / pw;
        J[1][k] = (Pv[k] - vc * Pw[k]) / pw;
    }
    float8 M[2][3];
    for (int r = 0; r < 2; ++r)
        for (int k = 0; k < 3; ++k)
            M[r][k] = splat_dot3_8(J[r][0], J[r][1], J[r][2], L[0][k], L[1][k], L[2][k]);
    float8 a = splat_dot3_8(M[0][0], M[0][1], M[0][2], M[0][0], M[0][1], M[0][2]) + SPLAT_LOWPASS;
    float8 b = splat_dot3_8(M[0][0], M[0][1], M[0][2], M[1][0], M[1][1], M[1][2]);
    float8 c = splat_dot3_8(M[1][0], M[1][1], M[1][2], M[1][0], M[1][1], M[1][2]) + SPLAT_LOWPASS;
    float8 det = a * c - b * b;
    ok &= (det > 0.0f) & splat_isfinite8(det) & splat_isfinite8(u) & splat_isfinite8(v);
    float8 zero = (float8)(0.0f);
    s[0] = ok ? u : zero;
    s[1] = ok ? v : zero;
    s[2] = ok ? c / det : zero;
    s[3] = ok ? -b / det : zero;
    s[4] = ok ? a / det : zero;
    s[5] = ok ? dep : zero;
    s[6] = ok ? (float8)(1.0f) : zero;
    s[7] = zero;
}

/* splat_fp and clvis_ellipse_rows on 8 lanes; ok: -1 where splat_footprint gives 1 */
typedef struct {
    float8 cu, cv, pad, sv, ds, euv, det, evv, ievv, slack;
    int8 tx0, tx1, ty0, ty1, ok;
} splat_fp8;

inline void splat_footprint8(const float8 *s, uint W, uint H, splat_fp8 *f)
{
    float8 ca = s[2], cb = s[3], cc = s[4];
    float8 cdet = ca * cc - cb * cb;
    float k = SPLAT_Q_MAX * 1.001f;
    float8 euu = k * cc / cdet, evv = k * ca / cdet, euv = -k * cb / cdet;
    float8 det = euu * evv - euv * euv;
    int8 ok = (s[6] != 0.0f) & (euu > 0.0f) & (evv > 0.0f) & (det > 0.0f) & splat_isfinite8(det);
    /* clvis_ellipse_set, clvis_ellipse_rows_set */
    f->cu = s[0];
    f->cv = s[1];
    f->pad = CLVIS_TILE_PAD + 1e-5f * (as_float8(as_uint8(s[0]) & (uint8)(0x7FFFFFFFu)) +
                                       as_float8(as_uint8(s[1]) & (uint8)(0x7FFFFFFFu)));
    float8 su = sqrt(euu);
    f->sv = sqrt(evv);
    f->euv = -(-euv);
    f->ds = f->euv / su;
    f->det = det;
    f->evv = evv;
    f->ievv = 1.0f / evv;
    f->slack = f->pad + 1e-3f * su;
    /* clvis_tile_rect(s0 - hu, s0 + hu, s1 - hv, s1 + hv, W, H, TS) */
    float8 hu = su + f->pad, hv = f->sv + f->pad;
    float8 ulo = splat_hi8(s[0] - hu, (float8)(-1.0f)), vlo = splat_hi8(s[1] - hv, (float8)(-1.0f));
    float8 uhi = splat_lo8(s[0] + hu, (float8)((float)W + 1.0f)), vhi = splat_lo8(s[1] + hv, (float8)((float)H + 1.0f));
    ok &= (ulo <= uhi) & (vlo <= vhi);
    float8 a = ulo - 0.5f, b = uhi - 0.5f, c = vlo - 0.5f, d = vhi - 0.5f;
    /* lanes that are not ok may hold any value: zero them before the conversions */
    float8 zero = (float8)(0.0f);
    a = ok ? a : zero;
    b = ok ? b : zero;
    c = ok ? c : zero;
    d = ok ? d : zero;
    int8 px0 = convert_int8(a), px1 = convert_int8(b), py0 = convert_int8(c), py1 = convert_int8(d);
    px0 -= convert_float8(px0) < a;   /* true is -1 */
    px1 += convert_float8(px1) > b;
    py0 -= convert_float8(py0) < c;
    py1 += convert_float8(py1) > d;
    px0 = px0 > 0 ? px0 : (int8)(0);
    px1 = px1 < (int)W - 1 ? px1 : (int8)((int)W - 1);
    py0 = py0 > 0 ? py0 : (int8)(0);
    py1 = py1 < (int)H - 1 ? py1 : (int8)((int)H - 1);
    ok &= (px0 <= px1) & (py0 <= py1);
    f->tx0 = px0 / TS;
    f->tx1 = px1 / TS;
    f->ty0 = py0 / TS;
    f->ty1 = py1 / TS;
    f->ok = ok;
}

/* clvis_ellipse_row and splat_row on 8 lanes (tile row ty[l] of lane l):
 * -1 where the lane's row holds tiles c0 .. c1 */
inline int8 splat_row8(const splat_fp8 *f, int8 ty, uint W, uint H, int8 *c0, int8 *c1)
{
    int8 yh = (ty + 1) * TS;
    yh = yh < (int)H ? yh : (int8)((int)H);
    float8 lo = ((convert_float8(ty * TS) + 0.5f) - f->pad) - f->cv;
    float8 hi = ((convert_float8(yh) - 0.5f) + f->pad) - f->cv;
    int8 meets = (lo <= f->sv) & (hi >= -f->sv);
    lo = splat_hi8(lo, -f->sv);
    hi = splat_lo8(hi, f->sv);
    float8 dr = splat_lo8(splat_hi8(f->ds, lo), hi), dl = splat_lo8(splat_hi8(-f->ds, lo), hi);
    float8 wr = sqrt(f->det * splat_hi8(f->evv - dr * dr, (float8)(0.0f)));
    float8 wl = sqrt(f->det * splat_hi8(f->evv - dl * dl, (float8)(0.0f)));
    float8 ulo = ((f->cu + (f->euv * dl - wl) * f->ievv) - f->slack) - 0.5f;
    float8 uhi = ((f->cu + (f->euv * dr + wr) * f->ievv) + f->slack) - 0.5f;
    float8 m1 = (float8)(-1.0f), fw = (float8)((float)W);
    ulo = ulo >= -1.0f ? ulo : m1;
    ulo = ulo <= (float)W ? ulo : fw;
    uhi = uhi <= (float)W ? uhi : fw;
    uhi = uhi >= -1.0f ? uhi : m1;
    int8 px0 = convert_int8(ulo), px1 = convert_int8(uhi + 1.0f) - 1;
    px0 -= convert_float8(px0) < ulo;
    px0 = px0 > 0 ? px0 : (int8)(0);
    px1 = px1 < (int)W - 1 ? px1 : (int8)((int)W - 1);
    int8 a = px0 / TS, b = px1 / TS;
    *c0 = a > f->tx0 ? a : f->tx0;
    *c1 = b < f->tx1 ? b : f->tx1;
    return meets & (px0 <= px1) & (*c0 <= *c1);
}

/* the band's tile rows of each lane: y0 .. y1 (y0 > y1 where none) */
inline void splat_rows8(const splat_fp8 *f, uint ty0, uint ty1, int8 *y0, int8 *y1)
{
    int8 a = f->ty0 > (int)ty0 ? f->ty0 : (int8)((int)ty0);
    int8 b = f->ty1 < (int)ty1 - 1 ? f->ty1 : (int8)((int)ty1 - 1);
    *y0 = f->ok ? a : (int8)(1);
    *y1 = f->ok ? b : (int8)(0);
}

kernel void splat_count8(global const clvis_gaussian *recs, uint n, global const float *proj, float near,
                         uint W, uint H, uint ty0, uint ty1, global float *splats, global ulong *counts)
{
    uint i0 = 8 * get_global_id(0);
    if (i0 >= n)
        return;
    float8 s[8];
    splat_project8(recs, i0, n, proj, near, W, H, s);
    int nl = (int)clvis_il_umin(8u, n - i0);
    float sl[8][8];
    for (int k = 0; k < 8; ++k)
        CLVIS_IL_VSTORE8(s[k], sl[k]);
    for (int l = 0; l < nl; ++l)
        for (int k = 0; k < 8; ++k)
            splats[8 * (size_t)(i0 + l) + k] = sl[k][l];
    splat_fp8 f;
    splat_footprint8(s, W, H, &f);
    int8 y0, y1;
    splat_rows8(&f, ty0, ty1, &y0, &y1);
    int8 cnt = (int8)(0);
    for (int8 ty = y0; clvis_il_any8(ty <= y1); ty += 1) {
        int8 c0, c1;
        int8 in = splat_row8(&f, ty, W, H, &c0, &c1) & (ty <= y1);
        cnt += in ? c1 - c0 + 1 : (int8)(0);
    }
    int cl[8];
    CLVIS_IL_VSTORE8(cnt, cl);
    for (int l = 0; l < nl; ++l)
        counts[i0 + l] = (ulong)(uint)cl[l];
}

kernel void splat_keys8(global const clvis_gaussian *recs, uint n, global const float *proj, float near,
                        uint W, uint H, uint ty0, uint ty1, global const float *splats,
                        global const ulong *offsets, global ulong *keys, global uint *ids)
{
    uint i0 = 8 * get_global_id(0);
    if (i0 >= n)
        return;
    int nl = (int)clvis_il_umin(8u, n - i0);
    float sl[8][8];
    for (int l = 0; l < 8; ++l) {
        global const float *p = splats + 8 * (size_t)(i0 + (uint)clvis_il_imin(l, nl - 1));
        for (int k = 0; k < 8; ++k)
            sl[k][l] = p[k];
    }
    float8 s[8];
    for (int k = 0; k < 8; ++k)
        s[k] = CLVIS_IL_VLOAD8(float8, sl[k]);
    splat_fp8 f;
    splat_footprint8(s, W, H, &f);
    f.ok &= (int8)(0, 1, 2, 3, 4, 5, 6, 7) < nl;
    int8 y0, y1;
    splat_rows8(&f, ty0, ty1, &y0, &y1);
    uint tiles_x = (W + TS - 1) / TS;
    ulong at[8];
    uint dkey[8];
    for (int l = 0; l < nl; ++l) {
        at[l] = offsets[i0 + l];
        dkey[l] = clvis_key_f32(as_uint(sl[5][l]));
    }
    for (int8 ty = y0; clvis_il_any8(ty <= y1); ty += 1) {
        int8 c0, c1;
        int8 in = splat_row8(&f, ty, W, H, &c0, &c1) & (ty <= y1);
        if (!clvis_il_any8(in))
            continue;
        int a[8], b[8], on[8], y[8];
        CLVIS_IL_VSTORE8(c0, a);
        CLVIS_IL_VSTORE8(c1, b);
        CLVIS_IL_VSTORE8(in, on);
        CLVIS_IL_VSTORE8(ty, y);
        for (int l = 0; l < nl; ++l) {
            if (!on[l])
                continue;
            ulong row = (ulong)(y[l] - (int)ty0) * tiles_x;
            for (int tx = a[l]; tx <= b[l]; ++tx) {
                keys[at[l]] = (row + (ulong)tx) << 32 | (ulong)dkey[l];
                ids[at[l]] = i0 + (uint)l;
                ++at[l];
            }
        }
    }
}
