/* tiles.cl — Gaussians binned to screen tiles, sorted per tile by a depth
 * bound, and composited per pixel in exact (t, id) order: the same image as
 * march.cl (same hit test, same alpha, same compositing), without a BVH.
 *
 * Data flow (clvis/gauss/tiles.py): tile_count (keys per Gaussian) -> exclusive
 * scan of the counts (clvis.primitives; from C: primitives/scan.cl with
 * T = ulong, its total m = the number of keys) -> tile_keys (one key per
 * Gaussian and tile it may touch) -> radix sort of the keys with the Gaussian
 * ids (primitives/radix_sort.cl with KEY_T = ulong, HAS_VALUES = 1, VAL_T =
 * uint; the keys use their low 32 + ceil(log2(tiles of the band)) bits) ->
 * tile_ranges (each tile's run of keys) -> gaussians.cl's gather_records (the
 * keys' records in key order) -> tile_render (per pixel). With m = 0 skip
 * tile_keys, the sort and tile_ranges (a zero global size is not a valid
 * launch): every range stays (0, 0).
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/gauss.h,
 *     clvis/gauss_tiles.h, clvis/keys.h).
 * Build options: -cl-fp32-correctly-rounded-divide-sqrt.
 * Defines:
 *   TS     tile side in pixels (default 16)
 *   KP     the streaming k-buffer's size, 1..64 (default 16)
 *   MODEL  0 max response, 1 absorption (march.cl's, default 0)
 *   COLOR  0 transfer-function rgb, 1 colors[id] (march.cl's, default 0)
 *   KEYS8  1: tile_keys bounds 8 of a Gaussian's tiles at once in float8
 *          lanes (tile_depth8; PoCL's CPU profile), 0 one tile at a time
 *          (tile_depth; default); the same keys
 *
 * Common arguments:
 *   recs      n clvis_gaussian records (clvis/gauss.h), in any order (the host
 *             keeps them in the LBVH's Morton leaf order: a tile's records lie
 *             close in memory); ids in keys are record positions
 *   proj      16 floats, 4 rows of 4: Pu, Pv, Pw (the pixel-homogeneous
 *             projection: (u w, v w, w) = P (x, y, z, 1), u, v continuous pixel
 *             coordinates, pixel centres at integer + 0.5, row 0 on top) and D
 *             (the view depth row, clvis/camera.h)
 *   near      the view depth of the rays' origins (the camera's near plane)
 *   cutoff    hit radius in standard deviations (the hit is m2 <= cutoff^2)
 *   W, H      image size; tiles_x = ceil(W / TS)
 *   ty0, ty1  the band: tile rows ty0 .. ty1 - 1 are binned; a key's tile is
 *             (ty - ty0) * tiles_x + tx
 * tile_count and tile_keys: one work-item per Gaussian, global size >= n
 * (items past n return), any local size. tile_ranges: one work-item per key,
 * global size >= m, any local size.
 *
 * kernel tile_count(recs, uint n, proj, float near, float cutoff, uint W, uint H,
 *                   uint ty0, uint ty1, global ulong *counts)      n
 *     counts[i] = the tiles of the band Gaussian i may touch (footprint below).
 * kernel tile_keys(recs, uint n, proj, float near, float cutoff, uint W, uint H,
 *                  uint ty0, uint ty1, global const ulong *offsets,  n: exclusive scan of counts
 *                  global const float *cam,                           22 floats (clvis/camera.h)
 *                  global ulong *keys, global uint *ids)              sum(counts) each
 *     keys[offsets[i] + k] = tile << 32 | clvis_key_f32(dk), ids[...] = i (record),
 *     tiles in row-major order. dk (tile_depth, or tile_depth8 with KEYS8): a
 *     lower bound of the view depth of every hit of Gaussian i by a ray of
 *     the tile.
 * kernel tile_ranges(global const ulong *keys, uint m,   m keys sorted ascending
 *                    global uint2 *ranges)               tiles_x * (ty1 - ty0), zeroed before:
 *     ranges[tile] = (first, last + 1) of the tile's keys; (0, 0) for none.
 * kernel tile_render(global const clvis_gaussian *keyrecs (keyrecs[i] = recs[ids[i]],
 *                    the keys' records in key order, gaussians.cl's gather_records
 *                    (recs, ids, m): the render kernels stream them, one random
 *                    read a key a band, not one a key a pixel row),
 *                    global const uint *order (record j is Gaussian order[j]: its id
 *                    for ties and colours), global const ulong *keys, global const uint *ids,
 *                    global const uint2 *ranges, global const float *cam (22 floats,
 *                    clvis/camera.h), uint W, uint H, uint ty0, uint tile0 (the band's
 *                    first tile this launch renders), uint rows (image rows of the
 *                    band: ty0 * TS .. ty0 * TS + rows - 1), uint out_y0 (the image
 *                    row that row 0 of the outputs holds),
 *                    tf, tf_n, tf_min, tf_scale, cutoff2, density, colors (as march.cl),
 *                    global float4 *rgba, global float *depth, global uint2 *stats)
 *     Outputs as march.cl's at (py - out_y0) * W + px; stats = (Gaussians
 *     composited, rounds). Global size: (tiles to render) * TS * TS, work-item i:
 *     tile tile0 + i / (TS * TS) of the band (row-major), pixel i % (TS * TS)
 *     in it (row-major); any local size dividing TS * TS.
 * kernel tile_render8(the arguments of tile_render)
 *     The CPU profile's form of tile_render, the same outputs: a work-item
 *     renders a row of 8 pixels of a tile in float8 lanes (TS a multiple of
 *     8). Global size: (tiles to render) * TS * TS / 8, work-item i: tile
 *     tile0 + i / (TS * TS / 8), row (i % (TS * TS / 8)) / (TS / 8), pixels
 *     8 * (i % (TS / 8)) .. + 7 of that row; any local size dividing
 *     TS * TS / 8. It flushes a lane's pending hits once a chunk of up to 16
 *     candidates (see below): the same composited hits in the same order as
 *     a flush per candidate, but with more than KP hits pending its rounds
 *     can differ from tile_render's.
 *
 * Footprint (tile_footprint): the Gaussian's cutoff ellipsoid, inflated by
 * 1.01 (as the BVH boxes of gaussians.cl), projected exactly: when it lies in
 * front of the eye's plane its outline is the ellipse with centre c and
 * matrix E (dual conic P Q* P^T of the ellipsoid's dual quadric Q*, expanded so
 * that no term cancels), a tile is kept when E's ellipse (plus 0.01 px) holds
 * a pixel centre of it (padded by 0.05 px; clvis_ellipse_row, a closed form per
 * tile row) — every pixel whose ray can hit lies inside; otherwise (the
 * ellipsoid straddles the eye's plane) every tile of the image. Gaussians wholly nearer than the near plane have none.
 *
 * Order (tile_render): a tile's keys are sorted by their depth bound dk. A
 * pixel's ray has origin o at view depth d0 and direction d with c = D . d > 0,
 * so a hit at t lies at depth d0 + t c >= dk: every later candidate's hits
 * have t >= (dk_next - d0) / c. A pending hit whose depth d0 + t c (plus 1e-5 of
 * its magnitude) is below dk_next can therefore be composited: hits are
 * composited in exact (t, id) order through a KP-entry buffer. When more than
 * KP hits are pending, the buffer keeps the KP smallest keys, the round
 * composites only keys below the smallest one it dropped, and another round
 * walks the same list for the keys beyond the last one composited (march.cl's
 * rounds). Compositing stops once T < 1e-3, as march.cl.
 */
#pragma OPENCL FP_CONTRACT OFF
/* tile_render8's long8 helpers are inlined; clang on an x86 target without
 * AVX-512 would still note that passing long8 by value "changes the ABI"
 * (-Wpsabi), text the OpenCL runtime prints to the user's terminal */
#if defined(__clang__)
#pragma clang diagnostic ignored "-Wpsabi"
#endif

#include "clvis/gauss.h"
#include "clvis/gauss_tiles.h"
#include "clvis/keys.h"

#ifndef TS
#define TS 16
#endif
#ifndef KP
#define KP 16
#endif
#ifndef MODEL
#define MODEL 0
#endif
#ifndef COLOR
#define COLOR 0
#endif
#ifndef KEYS8
#define KEYS8 0
#endif
#define T_STOP 1e-3f
#define INFLATE 1.01f
#define EPS2 1e-4f     /* (0.01 px)^2 added to E's diagonal */

typedef struct {
    clvis_ellipse e;       /* the outline ellipse */
    clvis_ellipse_rows r;  /* its rows' form */
    int exact;             /* 1: test tiles against the ellipse; 0: every tile of the rectangle */
    int tx0, tx1, ty0, ty1;/* tile rectangle (inclusive); empty when tx0 > tx1 */
    float dmin;
} tile_footprint;

inline float absrow4(global const float *r, float x, float y, float z)
{
    return ((clvis_il_fabs(r[0] * x) + clvis_il_fabs(r[1] * y)) + clvis_il_fabs(r[2] * z)) + clvis_il_fabs(r[3]);
}

/* The footprint of record g; returns 0 when it touches no pixel. */
inline int footprint(global const clvis_gaussian *g, global const float *proj, float near, float cutoff,
                     uint W, uint H, tile_footprint *f)
{
    float c = cutoff * INFLATE;
    /* L = W^-1 = R diag(se): L[j][k] = w[3k + j] / |row k of W|^2 (rows orthogonal) */
    float L[3][3];
    clvis_gauss_inverse(g, L);
    float mx = g->mean[0], my = g->mean[1], mz = g->mean[2];
    /* b_r = c P_r[:3] L (the ellipsoid's extent along row r), m_r = P_r (mean, 1) */
    float b[4][3], m[4];
    for (int r = 0; r < 4; ++r) {
        global const float *P = proj + 4 * r;
        for (int k = 0; k < 3; ++k)
            b[r][k] = c * clvis_dot3(P[0], P[1], P[2], L[0][k], L[1][k], L[2][k]);
        m[r] = clvis_row4(P, mx, my, mz);
    }
    float sd = 1e-5f * absrow4(proj + 12, mx, my, mz) + 1e-30f;
    float ext_d = sqrt(clvis_dot3(b[3][0], b[3][1], b[3][2], b[3][0], b[3][1], b[3][2]));
    f->dmin = (m[3] - ext_d) - sd;
    if ((m[3] + ext_d) + sd < near)
        return 0;   /* wholly nearer than the rays' origins */
    float S[3][3];
    for (int r = 0; r < 3; ++r)
        for (int s = 0; s < 3; ++s)
            S[r][s] = clvis_dot3(b[r][0], b[r][1], b[r][2], b[s][0], b[s][1], b[s][2]);
    float mu = m[0], mv = m[1], mw = m[2];
    float fw = mw * mw - S[2][2];
    float ulo = 0.0f, uhi = (float)W, vlo = 0.0f, vhi = (float)H;
    f->exact = 0;
    if (mw > 0.0f && fw > 1e-6f * (mw * mw)) {
        /* the outline ellipse: E = N / fw^2 */
        float nuu = ((mw * mw) * S[0][0] - 2.0f * (mu * mw) * S[0][2]) + (mu * mu) * S[2][2]
                    - (S[0][0] * S[2][2] - S[0][2] * S[0][2]);
        float nvv = ((mw * mw) * S[1][1] - 2.0f * (mv * mw) * S[1][2]) + (mv * mv) * S[2][2]
                    - (S[1][1] * S[2][2] - S[1][2] * S[1][2]);
        float nuv = (((mw * mw) * S[0][1] - (mu * mw) * S[1][2]) - (mv * mw) * S[0][2]) + (mu * mv) * S[2][2]
                    + (S[0][2] * S[1][2] - S[0][1] * S[2][2]);
        float f2 = fw * fw;
        float euu = nuu / f2 + EPS2, evv = nvv / f2 + EPS2, euv = nuv / f2;
        float cu = (mu * mw - S[0][2]) / fw, cv = (mv * mw - S[1][2]) / fw;
        float det = euu * evv - euv * euv;
        if (euu > 0.0f && evv > 0.0f && det > 0.0f && clvis_il_isfinite(det) && clvis_il_isfinite(cu)
            && clvis_il_isfinite(cv)) {
            clvis_ellipse_set(&f->e, cu, cv, euu, evv, euv, det);
            clvis_ellipse_rows_set(&f->e, &f->r);
            f->exact = 1;
            float hu = sqrt(euu) + f->e.pad, hv = sqrt(evv) + f->e.pad;
            ulo = cu - hu;
            uhi = cu + hu;
            vlo = cv - hv;
            vhi = cv + hv;
        } else if (!(clvis_il_isfinite(cu) && clvis_il_isfinite(cv))) {
            /* keep the whole image */
        }
    } else if (mw <= 0.0f && fw > 1e-6f * (mw * mw)) {
        return 0;   /* wholly behind the eye's plane */
    }
    /* pixels whose centre px + 0.5 lies in [ulo, uhi] */
    int r[4];
    if (!clvis_tile_rect(ulo, uhi, vlo, vhi, W, H, TS, r))
        return 0;
    f->tx0 = r[0];
    f->tx1 = r[1];
    f->ty0 = r[2];
    f->ty1 = r[3];
    return 1;
}

/* the tile columns c0 .. c1 of tile row ty that the footprint keeps; 0 when none */
inline int tile_row(const tile_footprint *f, int ty, uint W, uint H, int *c0, int *c1)
{
    *c0 = f->tx0;
    *c1 = f->tx1;
    if (!f->exact)
        return 1;
    int a, b;
    if (!clvis_ellipse_row(&f->r, ty, W, H, TS, &a, &b))
        return 0;
    *c0 = clvis_il_imax(a, f->tx0);
    *c1 = clvis_il_imin(b, f->tx1);
    return *c0 <= *c1;
}

kernel void tile_count(global const clvis_gaussian *recs, uint n, global const float *proj, float near,
                       float cutoff, uint W, uint H, uint ty0, uint ty1, global ulong *counts)
{
    uint i = get_global_id(0);
    if (i >= n)
        return;
    tile_footprint f;
    ulong cnt = 0;
    if (footprint(recs + i, proj, near, cutoff, W, H, &f)) {
        int y0 = clvis_il_imax(f.ty0, (int)ty0), y1 = clvis_il_imin(f.ty1, (int)ty1 - 1);
        for (int ty = y0; ty <= y1; ++ty) {
            int c0, c1;
            if (tile_row(&f, ty, W, H, &c0, &c1))
                cnt += (ulong)(c1 - c0 + 1);
        }
    }
    counts[i] = cnt;
}

/* A lower bound of the view depth of Gaussian g's hits by the rays of tile
 * (tx, ty). A hit at t = ts > 0 is the ray's point of least Mahalanobis
 * distance, y = x - mean with y' S^-1 d = 0 and y' S^-1 y <= c^2 (S the
 * covariance), whose depth offset f . y is at least
 * -c sqrt(f' S f - (f . d)^2 / (d' S^-1 d)). Over the tile's directions
 * dd(u, v) (linear in u, v), f . dd is linear and |W dd|^2 convex, so their
 * extremes over the rectangle of pixel centres are at its corners. Hits at
 * t = 0 lie on the near plane: a Gaussian reaching it keeps dmin. */
inline float tile_depth(const tile_footprint *f, float m3, float fsf, float c, float sd, const float *a0,
                        const float *au, const float *av, float fd0, float fdu, float fdv, float near, int tx,
                        int ty, uint W, uint H)
{
    if (!(f->dmin > near))
        return f->dmin;
    float us[2] = {(float)(tx * TS) + 0.5f, (float)clvis_il_imin((tx + 1) * TS, (int)W) - 0.5f};
    float vs[2] = {(float)(ty * TS) + 0.5f, (float)clvis_il_imin((ty + 1) * TS, (int)H) - 0.5f};
    float qmax = 0.0f, fmin2 = INFINITY, fdlo = INFINITY, fdhi = -INFINITY;
    for (int k = 0; k < 4; ++k) {
        float u = us[k & 1], v = vs[k >> 1];
        float x0 = (a0[0] + u * au[0]) + v * av[0];
        float x1 = (a0[1] + u * au[1]) + v * av[1];
        float x2 = (a0[2] + u * au[2]) + v * av[2];
        qmax = clvis_il_fmax(qmax, clvis_dot3(x0, x1, x2, x0, x1, x2));
        float fd = (fd0 + u * fdu) + v * fdv;
        fdlo = clvis_il_fmin(fdlo, fd);
        fdhi = clvis_il_fmax(fdhi, fd);
        fmin2 = clvis_il_fmin(fmin2, fd * fd);
    }
    float h = (fdlo > 0.0f || fdhi < 0.0f) ? (fmin2 / qmax) * 0.99999f : 0.0f;
    float g = clvis_il_fmax(fsf - h, 0.0f) + 1e-5f * fsf;
    float lo = (m3 - c * sqrt(g)) - sd;
    return clvis_il_isfinite(lo) ? clvis_il_fmax(lo, f->dmin) : f->dmin;
}

inline float8 il_fmin8(float8 a, float8 b)
{
    return (a < b | b != b) ? a : b;   /* clvis_il_fmin lane by lane */
}

inline float8 il_fmax8(float8 a, float8 b)
{
    return (a > b | b != b) ? a : b;   /* clvis_il_fmax lane by lane */
}

/* tile_depth8: the bound for 8 tiles (tx, ty) at once in float8 lanes, each
 * lane the scalar operations of one tile (the same bits as one tile at a
 * time); the caller handles f->dmin <= near (every tile's bound is dmin). */
inline float8 tile_depth8(const tile_footprint *f, float m3, float fsf, float c, float sd, const float *a0,
                          const float *au, const float *av, float fd0, float fdu, float fdv, int8 tx, int8 ty,
                          uint W, uint H)
{
    int8 tx1 = (tx + 1) * TS, ty1 = (ty + 1) * TS;   /* min with W, H by comparison (PoCL calls min) */
    tx1 = tx1 < (int)W ? tx1 : (int8)((int)W);
    ty1 = ty1 < (int)H ? ty1 : (int8)((int)H);
    float8 us[2] = {convert_float8(tx * TS) + 0.5f, convert_float8(tx1) - 0.5f};
    float8 vs[2] = {convert_float8(ty * TS) + 0.5f, convert_float8(ty1) - 0.5f};
    float8 qmax = 0.0f, fmin2 = INFINITY, fdlo = INFINITY, fdhi = -INFINITY;
    for (int k = 0; k < 4; ++k) {
        float8 u = us[k & 1], v = vs[k >> 1];
        float8 x0 = (a0[0] + u * au[0]) + v * av[0];
        float8 x1 = (a0[1] + u * au[1]) + v * av[1];
        float8 x2 = (a0[2] + u * au[2]) + v * av[2];
        qmax = il_fmax8(qmax, (x0 * x0 + x1 * x1) + x2 * x2);
        float8 fd = (fd0 + u * fdu) + v * fdv;
        fdlo = il_fmin8(fdlo, fd);
        fdhi = il_fmax8(fdhi, fd);
        fmin2 = il_fmin8(fmin2, fd * fd);
    }
    float8 h = (fdlo > 0.0f | fdhi < 0.0f) ? (fmin2 / qmax) * 0.99999f : (float8)(0.0f);
    float8 g = il_fmax8(fsf - h, (float8)(0.0f)) + 1e-5f * fsf;
    float8 lo = (m3 - c * sqrt(g)) - sd;
    float8 dmin = (float8)(f->dmin);
    return clvis_il_isfinite8(lo) ? il_fmax8(lo, dmin) : dmin;
}

/* tile_keys' keys of the batch's n tiles (tile columns bx, rows by, lanes
 * past n repeat the last tile) at keys[at ..] */
inline void tile_keys_batch(const tile_footprint *f, float m3, float fsf, float c, float sd, const float *a0,
                            const float *au, const float *av, float fd0, float fdu, float fdv, bool flat,
                            int *bx, int *by, int n, uint W, uint H, uint ty0, uint tiles_x, uint id,
                            global ulong *keys, global uint *ids, ulong at)
{
    for (int k = n; k < 8; ++k) {
        bx[k] = bx[n - 1];
        by[k] = by[n - 1];
    }
    float dk[8];
    if (flat) {
        for (int k = 0; k < 8; ++k)
            dk[k] = f->dmin;
    } else {
        float8 d8 = tile_depth8(f, m3, fsf, c, sd, a0, au, av, fd0, fdu, fdv, CLVIS_IL_VLOAD8(int8, bx),
                                CLVIS_IL_VLOAD8(int8, by), W, H);
        CLVIS_IL_VSTORE8(d8, dk);
    }
    for (int k = 0; k < n; ++k) {
        ulong tile = (ulong)(by[k] - (int)ty0) * tiles_x + (ulong)bx[k];
        keys[at + k] = tile << 32 | (ulong)clvis_key_f32(as_uint(dk[k]));
        ids[at + k] = id;
    }
}

kernel void tile_keys(global const clvis_gaussian *recs, uint n, global const float *proj, float near,
                      float cutoff, uint W, uint H, uint ty0, uint ty1, global const ulong *offsets,
                      global const float *cam, global ulong *keys, global uint *ids)
{
    uint i = get_global_id(0);
    if (i >= n)
        return;
    tile_footprint f;
    global const clvis_gaussian *g = recs + i;
    if (!footprint(g, proj, near, cutoff, W, H, &f))
        return;
    /* W dd = a0 + u au + v av; f . dd = fd0 + u fdu + v fdv (f = D's xyz) */
    float a0[3], au[3], av[3];
    for (int k = 0; k < 3; ++k) {
        a0[k] = clvis_dot3(g->w[3 * k], g->w[3 * k + 1], g->w[3 * k + 2], cam[9], cam[10], cam[11]);
        au[k] = clvis_dot3(g->w[3 * k], g->w[3 * k + 1], g->w[3 * k + 2], cam[12], cam[13], cam[14]);
        av[k] = clvis_dot3(g->w[3 * k], g->w[3 * k + 1], g->w[3 * k + 2], cam[15], cam[16], cam[17]);
    }
    global const float *D = proj + 12;
    float fd0 = clvis_dot3(D[0], D[1], D[2], cam[9], cam[10], cam[11]);
    float fdu = clvis_dot3(D[0], D[1], D[2], cam[12], cam[13], cam[14]);
    float fdv = clvis_dot3(D[0], D[1], D[2], cam[15], cam[16], cam[17]);
    float c = cutoff * INFLATE;
    float m3 = clvis_row4(D, g->mean[0], g->mean[1], g->mean[2]);
    float sd = 1e-5f * absrow4(D, g->mean[0], g->mean[1], g->mean[2]) + 1e-30f;
    /* f' S f = |f' L|^2, L = W^-1 as in footprint */
    float L[3][3], e[3];
    clvis_gauss_inverse(g, L);
    for (int k = 0; k < 3; ++k)
        e[k] = clvis_dot3(D[0], D[1], D[2], L[0][k], L[1][k], L[2][k]);
    float fsf = clvis_dot3(e[0], e[1], e[2], e[0], e[1], e[2]);
    uint tiles_x = (W + TS - 1) / TS;
    ulong at = offsets[i];
#if KEYS8
    bool flat = !(f.dmin > near);   /* hits at t = 0 on the near plane: every bound is dmin */
    /* the tiles in row-major order, 8 at a time */
    int bx[8], by[8], nb = 0;
    int y0 = clvis_il_imax(f.ty0, (int)ty0), y1 = clvis_il_imin(f.ty1, (int)ty1 - 1);
    for (int ty = y0; ty <= y1; ++ty) {
        int c0, c1;
        if (!tile_row(&f, ty, W, H, &c0, &c1))
            continue;
        for (int tx = c0; tx <= c1; ++tx) {
            bx[nb] = tx;
            by[nb] = ty;
            if (++nb == 8) {
                tile_keys_batch(&f, m3, fsf, c, sd, a0, au, av, fd0, fdu, fdv, flat, bx, by, 8, W, H, ty0,
                                tiles_x, i, keys, ids, at);
                at += 8;
                nb = 0;
            }
        }
    }
    if (nb > 0)
        tile_keys_batch(&f, m3, fsf, c, sd, a0, au, av, fd0, fdu, fdv, flat, bx, by, nb, W, H, ty0, tiles_x, i,
                        keys, ids, at);
#else
    int y0 = clvis_il_imax(f.ty0, (int)ty0), y1 = clvis_il_imin(f.ty1, (int)ty1 - 1);
    for (int ty = y0; ty <= y1; ++ty) {
        int c0, c1;
        if (!tile_row(&f, ty, W, H, &c0, &c1))
            continue;
        for (int tx = c0; tx <= c1; ++tx) {
            float dk = tile_depth(&f, m3, fsf, c, sd, a0, au, av, fd0, fdu, fdv, near, tx, ty, W, H);
            ulong tile = (ulong)(ty - (int)ty0) * tiles_x + (ulong)tx;
            keys[at] = tile << 32 | (ulong)clvis_key_f32(as_uint(dk));
            ids[at] = i;
            ++at;
        }
    }
#endif
}

kernel void tile_ranges(global const ulong *keys, uint m, global uint2 *ranges)
{
    uint i = get_global_id(0);
    if (i >= m)
        return;
    uint tile = (uint)(keys[i] >> 32);
    if (i == 0 || (uint)(keys[i - 1] >> 32) != tile)
        ranges[tile].x = i;
    if (i == m - 1 || (uint)(keys[i + 1] >> 32) != tile)
        ranges[tile].y = i + 1;
}

inline float4 hit_color(global const float4 *tf, uint ti, global const uchar4 *colors, uint id)
{
#if COLOR == 1
    return clvis_gauss_rgb8(colors[id]);
#else
    return tf[ti];
#endif
}

kernel void tile_render(global const clvis_gaussian *keyrecs, global const uint *order, global const ulong *keys,
                        global const uint *ids,
                        global const uint2 *ranges, global const float *cam, uint W, uint H, uint ty0,
                        uint tile0, uint rows, uint out_y0, global const float4 *tf, uint tf_n, float tf_min,
                        float tf_scale, float cutoff2, float density, global const uchar4 *colors,
                        global float4 *rgba, global float *depth, global uint2 *stats)
{
    uint px, py, row;
    uint tile = clvis_tile_pixel(get_global_id(0), W, ty0, tile0, TS, &px, &py, &row);
    if (px >= W || row >= rows || py >= H)
        return;
    size_t pix = (size_t)(py - out_y0) * W + px;

    float o[3], d[3];
    clvis_camera_ray(cam, px, py, o, d);
    /* view depth of the ray's point at t: d0 + t cd */
    float cd = clvis_dot3(cam[18], cam[19], cam[20], d[0], d[1], d[2]);
    float d0 = clvis_dot3(cam[18], cam[19], cam[20], o[0], o[1], o[2]) + cam[21];
    bool stream = cd > 0.0f;

    uint2 range = ranges[tile];
    float T = 1.0f, cr = 0.0f, cg = 0.0f, cb = 0.0f, z = INFINITY;
    float last_t = -1.0f;   /* every hit has t >= 0 */
    uint last_id = 0, hits = 0, rounds = 0;
    bool done = range.x >= range.y;
    /* pending hits, key descending: [kn - 1] is the smallest */
    float kt[KP];
    uint ki[KP];
    float ka[KP];
    uint kc[KP];
    while (!done) {
        ++rounds;
        int kn = 0;
        bool over = false;
        float ct = INFINITY;   /* the round's ceiling: the smallest key it dropped */
        uint cid = 0xFFFFFFFFu;
        for (uint i = range.x; i < range.y; ++i) {
            if (stream && kn > 0) {
                float dm = as_float(clvis_key_f32_inverse((uint)keys[i]));
                while (kn > 0) {
                    float h = kt[kn - 1] * cd;
                    if (!((h + d0) + 1e-5f * (fabs(h) + fabs(d0)) < dm))
                        break;
                    --kn;
                    clvis_gauss_composite(ka[kn], hit_color(tf, kc[kn], colors, ki[kn]), &T, &cr, &cg, &cb);
                    ++hits;
                    last_t = kt[kn];
                    last_id = ki[kn];
                    if (T < 0.5f && z == INFINITY)
                        z = clvis_ray_depth(cam, o, d, kt[kn]);
                    if (T < T_STOP) {
                        done = true;
                        break;
                    }
                }
                if (done)
                    break;
            }
            uint j = ids[i];
            global const clvis_gaussian *g = keyrecs + i;
            float t, m2, ts, a, op[3], dp[3];
            clvis_gauss_hit(g, o, d, &t, &m2, &ts, &a, op, dp);
            if (!(m2 <= cutoff2))
                continue;
            uint id = order[j];
            if (!clvis_gauss_key_less(last_t, last_id, t, id))
                continue;   /* composited in an earlier round */
            if (over && !clvis_gauss_key_less(t, id, ct, cid))
                continue;   /* beyond the round's ceiling */
            if (kn == KP) {
                over = true;
                if (clvis_gauss_key_less(kt[0], ki[0], t, id)) {
                    ct = t;   /* the new hit is the largest: drop it */
                    cid = id;
                    continue;
                }
                ct = kt[0];   /* drop the largest pending hit */
                cid = ki[0];
                for (int q = 0; q < KP - 1; ++q) {
                    kt[q] = kt[q + 1];
                    ki[q] = ki[q + 1];
                    ka[q] = ka[q + 1];
                    kc[q] = kc[q + 1];
                }
                kn = KP - 1;
            }
            uint ti;
            float alpha = clvis_gauss_hit_alpha(g, tf, tf_n, tf_min, tf_scale, MODEL, density, m2, ts, a,
                                                op, dp, &ti);
            int pos = kn++;
            while (pos > 0 && clvis_gauss_key_less(kt[pos - 1], ki[pos - 1], t, id)) {
                kt[pos] = kt[pos - 1];
                ki[pos] = ki[pos - 1];
                ka[pos] = ka[pos - 1];
                kc[pos] = kc[pos - 1];
                --pos;
            }
            kt[pos] = t;
            ki[pos] = id;
            ka[pos] = alpha;
            kc[pos] = ti;
        }
        /* the rest of the round, front to back */
        while (!done && kn > 0) {
            --kn;
            clvis_gauss_composite(ka[kn], hit_color(tf, kc[kn], colors, ki[kn]), &T, &cr, &cg, &cb);
            ++hits;
            last_t = kt[kn];
            last_id = ki[kn];
            if (T < 0.5f && z == INFINITY)
                z = clvis_ray_depth(cam, o, d, kt[kn]);
            if (T < T_STOP)
                done = true;
        }
        if (!over)
            done = true;
    }
    rgba[pix] = (float4)(cr, cg, cb, 1.0f - T);
    depth[pix] = z;
    stats[pix] = (uint2)(hits, rounds);
}

/* ---------------------------------------------------------------- 8 lanes
 * tile_render8: tile_render's result, a work-item per row of 8 pixels of a
 * tile (TS a multiple of 8): the hit test of a candidate runs on the 8 rays
 * at once in float8 lanes (the same operations as clvis_gauss_hit, lane by
 * lane), so are the alphas (gauss.h's clvis_gauss_alpha_*8: float8 exp/erfc,
 * whose last bit may differ from tile_render's scalar ones), the pending
 * buffers and compositing per lane. Global size:
 * (tiles to render) * TS * TS / 8; work-item i: tile
 * tile0 + i / (TS * TS / 8), row (i % (TS * TS / 8)) / (TS / 8) of it, pixels
 * 8 * (i % (TS / 8)) .. + 7 of that row; any local size dividing TS * TS / 8.
 * Same arguments as tile_render. */

/* Pending hits of tile_render8 in two 64-bit words each: the key
 * as_uint(t) << 32 | id (t >= 0, -0 made +0, so the unsigned order of the
 * word is the (t, id) order) and the payload as_uint(alpha) << 32 | the
 * transfer-function entry. */
inline ulong pend_key(float t, uint id)
{
    return (ulong)as_uint(t + 0.0f) << 32 | id;
}

inline float pend_t(ulong k)
{
    return as_float((uint)(k >> 32));
}

/* the lane's 8 bits of the int8 comparison v (lane l: bit l) */
inline uint lane_bits8(int8 v)
{
    int8 b = v & (int8)(1, 2, 4, 8, 16, 32, 64, 128);
    int4 a = b.lo | b.hi;
    int2 c = a.lo | a.hi;
    return (uint)(c.x | c.y);
}

/* the 8 x 8 bit matrix x (byte s, bit l) transposed (byte l, bit s) */
inline ulong transpose8x8(ulong x)
{
    ulong t = (x ^ (x >> 7)) & 0x00AA00AA00AA00AAul;
    x = x ^ t ^ (t << 7);
    t = (x ^ (x >> 14)) & 0x0000CCCC0000CCCCul;
    x = x ^ t ^ (t << 14);
    t = (x ^ (x >> 28)) & 0x00000000F0F0F0F0ul;
    return x ^ t ^ (t << 28);
}

#define KEY_NONE 0x7FFFFFFFFFFFFFFFul   /* above every pending key: no hit, no ceiling */

/* p[0], p[stride], ..., p[7 stride] as the vector type TV */
#define CLVIS_STRIDED8(TV, p, st) \
    ((TV)((p)[0], (p)[(st)], (p)[2 * (st)], (p)[3 * (st)], (p)[4 * (st)], (p)[5 * (st)], (p)[6 * (st)], (p)[7 * (st)]))

/* hi << 32 | lo, lane by lane */
inline long8 pack8(uint8 tb, uint8 id)
{
#ifdef __ENDIAN_LITTLE__
    return as_long8((uint16)(id.s0, tb.s0, id.s1, tb.s1, id.s2, tb.s2, id.s3, tb.s3, id.s4, tb.s4, id.s5, tb.s5,
                             id.s6, tb.s6, id.s7, tb.s7));
#else
    return as_long8((uint16)(tb.s0, id.s0, tb.s1, id.s1, tb.s2, id.s2, tb.s3, id.s3, tb.s4, id.s4, tb.s5, id.s5,
                             tb.s6, id.s6, tb.s7, id.s7));
#endif
}

/* pend_key of 8 hits (t >= 0) as signed 64-bit lanes */
inline long8 slot_keys8(float8 t, uint8 id)
{
    return pack8(as_uint8(t + 0.0f), id);
}

/* the lane's 8 bits of the long8 comparison v (lane l: bit l) */
inline uint lane_bits8l(long8 v)
{
    long8 b = v & (long8)(1, 2, 4, 8, 16, 32, 64, 128);
    long4 a = b.lo | b.hi;
    long2 c = a.lo | a.hi;
    return (uint)(c.x | c.y);
}

/* the set bits of a 16-bit x, without a call */
inline int popcount16(uint x)
{
    x = x - ((x >> 1) & 0x5555u);
    x = (x & 0x3333u) + ((x >> 2) & 0x3333u);
    x = (x + (x >> 4)) & 0x0F0Fu;
    return (int)((x + (x >> 8)) & 0x1Fu);
}

/* clvis_gauss_tf_index with floor inline (clvis_il_floor: the same value) */
inline uint tf_index_il(float value, float tf_min, float tf_scale, uint tf_n)
{
    float x = clvis_il_floor(((value - tf_min) * tf_scale) * (float)tf_n);
    return x >= (float)(tf_n - 1) ? tf_n - 1 : x > 0.0f ? (uint)x : 0u;
}

/* the lowest set bit's index of b (b != 0), without a call */
inline uint low_bit(uint b)
{
    return (as_uint((float)(b & (0u - b))) >> 23) - 127u;
}

/* the lane's smallest pending hit composited (lane state in L_* scalars) */
#define POP_L()                                                                                       \
    do {                                                                                              \
        int q_ = L_hd++;                                                                              \
        --L_kn;                                                                                       \
        ulong k_ = PK[q_], v_ = PV[q_];                                                               \
        clvis_gauss_composite(as_float((uint)(v_ >> 32)), hit_color(tf, (uint)v_, colors, (uint)k_),  \
                              &L_T, &L_cr, &L_cg, &L_cb);                                             \
        ++L_hits;                                                                                     \
        L_last = k_;                                                                                  \
        if (L_T < 0.5f && L_z == INFINITY)                                                            \
            L_z = clvis_ray_depth(cam, o[l], d[l], pend_t(k_));                                       \
        if (L_T < T_STOP)                                                                             \
            L_done = true;                                                                            \
    } while (0)

/* the lane's flush threshold: the depth of its smallest pending hit, plus slack */
#define FRONT_L()                                                                                     \
    do {                                                                                              \
        if (L_kn > 0 && L_cd > 0.0f) {                                                                \
            float h_ = pend_t(PK[L_hd]) * L_cd;                                                       \
            L_front = (h_ + L_d0) + 1e-5f * (clvis_il_fabs(h_) + L_ad0);                              \
        } else                                                                                        \
            L_front = INFINITY;                                                                       \
    } while (0)

/* composite the lane's pending hits below dm (march.cl's order: every later
 * candidate's hits lie at depth >= dm) */
#define FLUSH_L(dm)                                                                                   \
    do {                                                                                              \
        while (L_front < (dm) && !L_done) {                                                           \
            POP_L();                                                                                  \
            FRONT_L();                                                                                \
        }                                                                                             \
    } while (0)

/* tile_render8 walks the candidates in chunks of up to 16 that hit a live
 * lane: their hit tests and alphas in float8 lanes (kept per chunk slot),
 * then lane by lane, the lane's state in registers: the chunk's 16 slots as
 * keys in signed 64-bit lanes (a slot the lane missed, or whose hit lies at
 * or before the last composited or at or beyond the round's ceiling: above
 * every key), the pending hits above the smallest kept key beside them (a
 * few: hits come nearly in key order), each placed by its rank in that
 * union (the keys differ; the unkept slots all land on a spare entry past
 * the window), then the flush for the next candidate's key. (More than 16
 * such pending hits, or more than KP pending: the kept hits ranked among
 * themselves and merged from the window's end, or inserted one by one.) A lane composites the same hits in
 * the same order as with a flush before each candidate: every hit of a
 * candidate lies at depth >= its key, and the keys ascend, so a flush put
 * off past the chunk's insertions composites the same key-order prefix.
 * (Only the rounds can differ, when more than KP hits are pending.) */
kernel void tile_render8(global const clvis_gaussian *keyrecs, global const uint *order, global const ulong *keys,
                        global const uint *ids,
                         global const uint2 *ranges, global const float *cam, uint W, uint H, uint ty0,
                         uint tile0, uint rows, uint out_y0, global const float4 *tf, uint tf_n, float tf_min,
                         float tf_scale, float cutoff2, float density, global const uchar4 *colors,
                         global float4 *rgba, global float *depth, global uint2 *stats)
{
    uint px0, py, row;
    uint tile = clvis_tile_row8(get_global_id(0), W, ty0, tile0, TS, &px0, &py, &row);
    if (px0 >= W || row >= rows || py >= H)
        return;

    float o[8][3], d[8][3], cd[8], d0[8], ad0[8];
    float T[8], cr[8], cg[8], cb[8], z[8], front[8];
    ulong last[8], ceil_k[8];   /* the last key composited; the round's ceiling */
    uint hits[8], nround[8];
    bool done[8], over[8];
    int kn[8], hd[8];
    /* pending: pk[hd .. hd + kn - 1], key ascending, [hd] the smallest (the
     * window moves back to 0 when it reaches the end) */
    ulong pk[8][KP + 1], pv[8][KP + 1];   /* + 1: a spare entry (the union's unused slots) */
    ulong NK[32], NV[32], SK[16], SV[16];   /* a lane's chunk slots' keys and the pending ones they pass; sorted */
    float lox[8], loy[8], loz[8], ldx[8], ldy[8], ldz[8];
    /* the chunk: per slot the candidate's t and alpha per lane, its id and tf entry */
    float ct[16 * 8], ca[16 * 8];
    uint cid[16], cti[16];
    for (int s = 0; s < 16; ++s) {   /* the slots past a chunk's end are read (their lanes masked) */
        for (int l = 0; l < 8; ++l)
            ct[8 * s + l] = ca[8 * s + l] = 0.0f;
        cid[s] = cti[s] = 0;
    }
    uint2 range = ranges[tile];
    int live = 0;
    uint donem = 0;   /* bit l: lane l done */
    for (int l = 0; l < 8; ++l) {
        uint px = min(px0 + l, W - 1);
        clvis_camera_ray(cam, px, py, o[l], d[l]);
        cd[l] = clvis_dot3(cam[18], cam[19], cam[20], d[l][0], d[l][1], d[l][2]);
        d0[l] = clvis_dot3(cam[18], cam[19], cam[20], o[l][0], o[l][1], o[l][2]) + cam[21];
        ad0[l] = fabs(d0[l]);
        lox[l] = o[l][0]; loy[l] = o[l][1]; loz[l] = o[l][2];
        ldx[l] = d[l][0]; ldy[l] = d[l][1]; ldz[l] = d[l][2];
        T[l] = 1.0f; cr[l] = cg[l] = cb[l] = 0.0f; z[l] = INFINITY;
        hits[l] = 0; nround[l] = 0;
        done[l] = px0 + l >= W || range.x >= range.y;
        live += !done[l];
        donem |= (uint)done[l] << l;
    }
    float8 ox = CLVIS_IL_VLOAD8(float8, lox), oy = CLVIS_IL_VLOAD8(float8, loy), oz = CLVIS_IL_VLOAD8(float8, loz);
    float8 dx = CLVIS_IL_VLOAD8(float8, ldx), dy = CLVIS_IL_VLOAD8(float8, ldy), dz = CLVIS_IL_VLOAD8(float8, ldz);
    bool first = true;   /* round 1: every hit is beyond "last" */
    while (live > 0) {
        for (int l = 0; l < 8; ++l) {
            kn[l] = 0;
            hd[l] = 0;
            over[l] = false;
            ceil_k[l] = KEY_NONE;
            front[l] = INFINITY;
            nround[l] += !done[l];
        }
        int nc = 0;
        ulong chm = 0, chm1 = 0;   /* byte s of slots 0-7 / 8-15: the lanes slot s hits */
        for (uint i = range.x; i < range.y; ++i) {
            uint j = ids[i];
            global const clvis_gaussian *g = keyrecs + i;
            /* clvis_gauss_hit on 8 rays */
            float8 r0 = ox - g->mean[0], r1 = oy - g->mean[1], r2 = oz - g->mean[2];
            float8 op0 = (g->w[0] * r0 + g->w[1] * r1) + g->w[2] * r2;
            float8 op1 = (g->w[3] * r0 + g->w[4] * r1) + g->w[5] * r2;
            float8 op2 = (g->w[6] * r0 + g->w[7] * r1) + g->w[8] * r2;
            float8 dp0 = (g->w[0] * dx + g->w[1] * dy) + g->w[2] * dz;
            float8 dp1 = (g->w[3] * dx + g->w[4] * dy) + g->w[5] * dz;
            float8 dp2 = (g->w[6] * dx + g->w[7] * dy) + g->w[8] * dz;
            float8 a8 = (dp0 * dp0 + dp1 * dp1) + dp2 * dp2;
            float8 b8 = (op0 * dp0 + op1 * dp1) + op2 * dp2;
            float8 ts8 = -b8 / a8;
            float8 t8 = ts8 > 0.0f ? ts8 : 0.0f;   /* fmax(ts8, 0) (a NaN gives 0), without a call */
            float8 p0 = op0 + t8 * dp0, p1 = op1 + t8 * dp1, p2 = op2 + t8 * dp2;
            float8 m28 = (p0 * p0 + p1 * p1) + p2 * p2;
            uint hm = lane_bits8(m28 <= cutoff2) & ~donem;
            if (hm != 0) {
                /* one transfer-function entry a candidate; the 8 lanes' alphas in
                 * float8 (one exp for the row: PoCL calls exp out of line), the
                 * scalar functions' operations lane by lane (gauss.h's
                 * clvis_gauss_alpha_*8; the vector exp/erfc may differ from the
                 * scalar ones in the last bit) */
                uint ti = tf_index_il(g->value, tf_min, tf_scale, tf_n);
                float opac = g->opacity * tf[ti].w;
#if MODEL == 1
                float8 alpha8 = clvis_gauss_alpha_absorption8(opac, density, ts8, a8, op0, op1, op2, dp0, dp1, dp2);
#else
                float8 alpha8 = clvis_gauss_alpha_max_response8(opac, m28);
#endif
                CLVIS_IL_VSTORE8(t8, ct + 8 * nc);
                CLVIS_IL_VSTORE8(alpha8, ca + 8 * nc);
                cid[nc] = order[j];
                cti[nc] = ti;
                if (nc < 8)
                    chm |= (ulong)hm << (8 * nc);
                else
                    chm1 |= (ulong)hm << (8 * (nc - 8));
                ++nc;
            }
            bool more = i + 1 < range.y;
            if (nc < 16 && more)
                continue;
            if (nc == 0)
                break;
            /* the chunk, lane by lane */
            float dmn = more ? as_float(clvis_key_f32_inverse((uint)keys[i + 1])) : 0.0f;
            ulong lbits = transpose8x8(chm), lbits1 = transpose8x8(chm1);
            for (int l = 0; l < 8; ++l) {
                uint lb = ((uint)(lbits >> (8 * l)) & 0xFFu) | ((uint)(lbits1 >> (8 * l)) & 0xFFu) << 8;
                if (lb == 0 && !(more && front[l] < dmn))
                    continue;
                if (done[l])
                    continue;
                private ulong *PK = pk[l], *PV = pv[l];
                float L_T = T[l], L_cr = cr[l], L_cg = cg[l], L_cb = cb[l], L_z = z[l], L_front = front[l];
                float L_cd = cd[l], L_d0 = d0[l], L_ad0 = ad0[l];
                ulong L_last = last[l], L_ceil = ceil_k[l];
                uint L_hits = hits[l];
                bool L_done = false, L_over = over[l];
                int L_kn = kn[l], L_hd = hd[l];
                /* the lane's hits of the chunk beyond "last" and below the
                 * ceiling: their keys per chunk slot (KEY_NONE: none), 16
                 * slots in signed 64-bit lanes (keys are below 2^63) */
                long8 sb = (long8)(1, 2, 4, 8, 16, 32, 64, 128);
                long8 kA = slot_keys8(CLVIS_STRIDED8(float8, ct + l, 8), CLVIS_IL_VLOAD8(uint8, cid));
                long8 kB = slot_keys8(CLVIS_STRIDED8(float8, ct + 64 + l, 8), CLVIS_IL_VLOAD8(uint8, cid + 8));
                long8 okA = (((long8)((long)(lb & 0xFFu)) & sb) != 0) & (kA < (long)L_ceil);
                long8 okB = (((long8)((long)(lb >> 8)) & sb) != 0) & (kB < (long)L_ceil);
                if (!first) {
                    okA &= kA > (long)L_last;
                    okB &= kB > (long)L_last;
                }
                kA = okA ? kA : (long8)(KEY_NONE);
                kB = okB ? kB : (long8)(KEY_NONE);
                uint kept = lane_bits8l(okA) | lane_bits8l(okB) << 8;
                int m = popcount16(kept);
                long8 mn8 = kA < kB ? kA : kB;
                long4 mn4 = mn8.lo < mn8.hi ? mn8.lo : mn8.hi;
                long2 mn2 = mn4.lo < mn4.hi ? mn4.lo : mn4.hi;
                ulong kmin = (ulong)(mn2.x < mn2.y ? mn2.x : mn2.y);   /* the smallest kept */
                int nt = 0;   /* pending hits above kmin (they move), when they are 16 at most */
                bool fits = false;
                if (m > 0 && L_kn + m <= KP) {
                    if (L_hd + L_kn + m > KP) {   /* at the end: move the window to 0 */
                        for (int q = 0; q < L_kn; ++q) {
                            PK[q] = PK[L_hd + q];
                            PV[q] = PV[L_hd + q];
                        }
                        L_hd = 0;
                    }
                    int e_ = L_hd + L_kn;
                    while (nt < L_kn && nt < 16 && PK[e_ - 1 - nt] > kmin) {
                        NK[16 + nt] = PK[e_ - 1 - nt];
                        NV[16 + nt] = PV[e_ - 1 - nt];
                        ++nt;
                    }
                    fits = !(nt < L_kn && PK[e_ - 1 - nt] > kmin);
                }
                CLVIS_IL_VSTORE8(kA, NK);
                CLVIS_IL_VSTORE8(kB, NK + 8);
                if (fits) {
                    /* the kept hits and the pending ones they pass, placed by
                     * rank in their union (the keys differ), 16 slots and 8 or
                     * 16 pending at once */
                    for (int p_ = 16 + nt; p_ < 32; ++p_)
                        NK[p_] = KEY_NONE;
                    long8 uc = as_long8(CLVIS_IL_VLOAD8(ulong8, NK + 16));
                    long8 ra = 0, rb = 0, rc = 0, rd = 0;
                    if (nt <= 8) {
                        for (int b_ = 0; b_ < 16 + nt; ++b_) {
                            long8 kb = (long8)((long)NK[b_]);
                            ra += kA > kb;
                            rb += kB > kb;
                            rc += uc > kb;
                        }
                    } else {
                        long8 ud = as_long8(CLVIS_IL_VLOAD8(ulong8, NK + 24));
                        for (int b_ = 0; b_ < 16 + nt; ++b_) {
                            long8 kb = (long8)((long)NK[b_]);
                            ra += kA > kb;
                            rb += kB > kb;
                            rc += uc > kb;
                            rd += ud > kb;
                        }
                    }
                    long R[32];
                    CLVIS_IL_VSTORE8(ra, R);
                    CLVIS_IL_VSTORE8(rb, R + 8);
                    CLVIS_IL_VSTORE8(rc, R + 16);
                    CLVIS_IL_VSTORE8(rd, R + 24);
                    /* every slot written: those without a hit (rank m + nt) all
                     * at the window's new end + 1, a spare entry */
                    long8 vA = pack8(as_uint8(CLVIS_STRIDED8(float8, ca + l, 8)), CLVIS_IL_VLOAD8(uint8, cti));
                    long8 vB = pack8(as_uint8(CLVIS_STRIDED8(float8, ca + 64 + l, 8)), CLVIS_IL_VLOAD8(uint8, cti + 8));
                    long V[16];
                    CLVIS_IL_VSTORE8(vA, V);
                    CLVIS_IL_VSTORE8(vB, V + 8);
                    int base = L_hd + L_kn - nt;
                    for (int s = 0; s < 16; ++s) {
                        int w_ = base - (int)R[s];
                        PK[w_] = NK[s];
                        PV[w_] = (ulong)V[s];
                    }
                    for (int a_ = 0; a_ < nt; ++a_) {
                        int w_ = base - (int)R[16 + a_];
                        PK[w_] = NK[16 + a_];
                        PV[w_] = NV[16 + a_];
                    }
                    L_kn += m;
                    FRONT_L();
                } else if (m > 0) {
                    /* the kept hits in chunk order at NK[0 .. m - 1] */
                    int c_ = 0;
                    while (kept != 0) {
                        uint s = low_bit(kept);
                        kept &= kept - 1u;
                        NK[c_] = NK[s];
                        NV[c_] = (ulong)as_uint(ca[8 * s + l]) << 32 | cti[s];
                        ++c_;
                    }
                }
                if (!fits && m > 0 && L_kn + m <= KP) {
                    /* sorted (rank of each: the keys differ), then merged
                     * into the window from its end: hits come nearly in key
                     * order, so few pending ones move */
                    for (int a_ = 0; a_ < m; ++a_) {
                        int r_ = 0;
                        for (int b_ = 0; b_ < m; ++b_)
                            r_ += NK[b_] < NK[a_];
                        SK[r_] = NK[a_];
                        SV[r_] = NV[a_];
                    }
                    if (L_hd + L_kn + m > KP) {   /* at the end: move the window to 0 */
                        for (int q = 0; q < L_kn; ++q) {
                            PK[q] = PK[L_hd + q];
                            PV[q] = PV[L_hd + q];
                        }
                        L_hd = 0;
                    }
                    int i_ = L_hd + L_kn - 1, j_ = m - 1, w_ = L_hd + L_kn + m - 1;
                    while (j_ >= 0) {
                        int io_ = i_ < 0 ? 0 : i_;
                        ulong ko_ = PK[io_], vo_ = PV[io_], kw_ = SK[j_], vw_ = SV[j_];
                        int old_ = (i_ >= L_hd) & (ko_ > kw_);
                        PK[w_] = old_ ? ko_ : kw_;
                        PV[w_] = old_ ? vo_ : vw_;
                        i_ -= old_;
                        j_ -= 1 - old_;
                        --w_;
                    }
                    L_kn += m;
                    FRONT_L();
                } else if (!fits && m > 0) {
                    /* more than KP pending: one by one, the largest dropped */
                    for (int e_ = 0; e_ < m; ++e_) {
                        ulong k = NK[e_], v = NV[e_];
                        if (k >= L_ceil)
                            continue;   /* beyond the round's ceiling */
                        if (L_kn == KP) {   /* then L_hd == 0 */
                            L_over = true;
                            if (PK[KP - 1] < k) {
                                L_ceil = k;   /* the new hit is the largest: drop it */
                                continue;
                            }
                            L_ceil = PK[KP - 1];   /* drop the largest pending hit */
                            L_kn = KP - 1;
                        }
                        if (L_hd + L_kn == KP) {   /* at the end: move the window to 0 */
                            for (int q = 0; q < L_kn; ++q) {
                                PK[q] = PK[L_hd + q];
                                PV[q] = PV[L_hd + q];
                            }
                            L_hd = 0;
                        }
                        int pos = L_hd + L_kn++;
                        while (pos > L_hd && PK[pos - 1] > k) {
                            PK[pos] = PK[pos - 1];
                            PV[pos] = PV[pos - 1];
                            --pos;
                        }
                        PK[pos] = k;
                        PV[pos] = v;
                    }
                    FRONT_L();
                }
                if (more && !L_done)
                    FLUSH_L(dmn);
                T[l] = L_T; cr[l] = L_cr; cg[l] = L_cg; cb[l] = L_cb; z[l] = L_z; front[l] = L_front;
                last[l] = L_last; ceil_k[l] = L_ceil; hits[l] = L_hits; over[l] = L_over;
                kn[l] = L_kn; hd[l] = L_hd;
                if (L_done) {
                    done[l] = true;
                    donem |= 1u << l;
                    --live;
                }
            }
            nc = 0;
            chm = 0;
            chm1 = 0;
            if (live == 0)
                break;
        }
        /* the rest of the round, front to back; lanes without overflow are done */
        for (int l = 0; l < 8; ++l) {
            if (done[l])
                continue;
            private ulong *PK = pk[l], *PV = pv[l];
            float L_T = T[l], L_cr = cr[l], L_cg = cg[l], L_cb = cb[l], L_z = z[l];
            ulong L_last = last[l];
            uint L_hits = hits[l];
            bool L_done = false;
            int L_kn = kn[l], L_hd = hd[l];
            while (!L_done && L_kn > 0)
                POP_L();
            T[l] = L_T; cr[l] = L_cr; cg[l] = L_cg; cb[l] = L_cb; z[l] = L_z;
            last[l] = L_last; hits[l] = L_hits;
            if (L_done || !over[l]) {
                done[l] = true;
                donem |= 1u << l;
                --live;
            }
        }
        first = false;
    }
    for (int l = 0; l < 8 && px0 + l < W; ++l) {
        size_t pix = (size_t)(py - out_y0) * W + px0 + l;
        rgba[pix] = (float4)(cr[l], cg[l], cb[l], 1.0f - T[l]);
        depth[pix] = z[l];
        stats[pix] = (uint2)(hits[l], nround[l]);
    }
}
