/* clvis/gauss_tiles.h — screen-space footprints of Gaussians on a grid of tiles.
 *
 * Shared by gauss/tiles.cl (the tile renderer) and gauss/splat.cl (the 2D
 * splatter), which bin Gaussians into ts x ts pixel tiles the same way:
 *
 *   float clvis_row4(r, x, y, z) = r[0..2] . (x, y, z) + r[3]  (a row of a 4x4
 *       projection applied to a point)
 *   clvis_gauss_inverse(g, L): L = W^-1 = R diag(s), L[j][k] = w[3k + j] / |row k
 *       of W|^2 (W's rows are orthogonal)
 *   clvis_ellipse: the screen ellipse dx' E^-1 dx <= 1 kept as its centre (cu, cv),
 *       adj(E) = (a00, a01; a01, a11), det(E) and pad, the px added around a
 *       tile's pixel centres (CLVIS_TILE_PAD + 1e-5 (|cu| + |cv|))
 *   clvis_ellipse_set(e, cu, cv, euu, evv, euv, det): e from E = (euu, euv; euv, evv)
 *   clvis_ellipse_rows_set(e, &r): r, what clvis_ellipse_row needs of e (once a Gaussian)
 *   int clvis_ellipse_row(&r, ty, W, H, ts, &c0, &c1): the tile columns c0 .. c1 of
 *       tile row ty that hold a pixel centre of the ellipse (its rows' centres,
 *       padded by e->pad, as a strip); 0 when none. Exact (in closed form, one
 *       strip a row, no test a tile): E's ellipse meets the strip
 *       v in [v0, v1] in a convex set whose u-extent runs from the lower
 *       branch's minimum to the upper branch's maximum, each at the strip's
 *       dv nearest the ellipse's leftmost / rightmost point
 *       (dv = -/+ euv / sqrt(euu)); widened by e->pad and 1e-3 sqrt(euu) (the
 *       rounding of sqrt(det (evv - dv^2)) near the ends), so conservative.
 *   int clvis_tile_rect(ulo, uhi, vlo, vhi, W, H, ts, r): r = (tx0, tx1, ty0, ty1),
 *       the tiles (inclusive) of the pixels whose centre px + 0.5 lies in
 *       [ulo, uhi] x [vlo, vhi] (clamped to [-1, W + 1] x [-1, H + 1]); 0 when
 *       there are none
 *
 *   uint clvis_tile_pixel(gid, W, ty0, tile0, ts, &px, &py, &row): a renderer's
 *       work-item gid, a work-item per pixel of ts x ts tiles (tile tile0 + gid /
 *       ts^2, pixel gid % ts^2 of it, row-major; tile index (ty - ty0) * tiles_x
 *       + tx): its tile, pixel (px, py) and row within the band of tiles
 *   clvis_lo, clvis_hi: fmin, fmax inline by comparison (PoCL calls its
 *       builtins out of line; the same results where a NaN can only be the
 *       first argument: it gives the second, as fmin / fmax). fabs, min, max,
 *       isfinite and any come from clvis/inline.h (clvis_il_*)
 *
 * clvis.reference.gauss.tiles and clvis.reference.gauss.splat repeat them.
 */
#ifndef CLVIS_GAUSS_TILES_H
#define CLVIS_GAUSS_TILES_H

#include "clvis/camera.h"
#include "clvis/inline.h"
#include "clvis/gauss.h"

#define CLVIS_TILE_PAD 0.05f

inline float clvis_row4(global const float *r, float x, float y, float z)
{
    return clvis_dot3(r[0], r[1], r[2], x, y, z) + r[3];
}

inline void clvis_gauss_inverse(global const clvis_gaussian *g, float L[3][3])
{
    for (int k = 0; k < 3; ++k) {
        float r2 = clvis_dot3(g->w[3 * k], g->w[3 * k + 1], g->w[3 * k + 2], g->w[3 * k], g->w[3 * k + 1],
                              g->w[3 * k + 2]);
        for (int j = 0; j < 3; ++j)
            L[j][k] = g->w[3 * k + j] / r2;
    }
}

typedef struct {
    float cu, cv;          /* ellipse centre */
    float a00, a01, a11;   /* adj(E) */
    float det;             /* det(E) */
    float pad;             /* px added around a tile's pixel centres */
} clvis_ellipse;

inline void clvis_ellipse_set(clvis_ellipse *e, float cu, float cv, float euu, float evv, float euv,
                              float det)
{
    e->cu = cu;
    e->cv = cv;
    e->a00 = evv;
    e->a01 = -euv;
    e->a11 = euu;
    e->det = det;
    e->pad = CLVIS_TILE_PAD + 1e-5f * (clvis_il_fabs(cu) + clvis_il_fabs(cv));
}

/* what clvis_ellipse_row needs of an ellipse, computed once */
typedef struct {
    float cu, cv, pad;
    float su, sv;          /* half extents sqrt(euu), sqrt(evv) */
    float ds;              /* dv of the rightmost point: euv / su */
    float euv, det, evv, ievv;
    float slack;           /* pad + 1e-3 su */
} clvis_ellipse_rows;

inline void clvis_ellipse_rows_set(const clvis_ellipse *e, clvis_ellipse_rows *r)
{
    r->cu = e->cu;
    r->cv = e->cv;
    r->pad = e->pad;
    r->su = sqrt(e->a11);
    r->sv = sqrt(e->a00);
    r->euv = -e->a01;
    r->ds = r->euv / r->su;
    r->det = e->det;
    r->evv = e->a00;
    r->ievv = 1.0f / e->a00;
    r->slack = e->pad + 1e-3f * r->su;
}

/* min / max by comparison (a NaN argument gives the other); PoCL's fmin,
 * fmax, clamp, ceil and floor cost several times more in these loops */
inline float clvis_lo(float a, float b)
{
    return a < b ? a : b;
}

inline float clvis_hi(float a, float b)
{
    return a > b ? a : b;
}

inline int clvis_ellipse_row(const clvis_ellipse_rows *e, int ty, uint W, uint H, int ts, int *c0, int *c1)
{
    /* the strip of the row's pixel centres, relative to the centre */
    float lo = (((float)(ty * ts) + 0.5f) - e->pad) - e->cv;
    float hi = (((float)clvis_il_imin((ty + 1) * ts, (int)H) - 0.5f) + e->pad) - e->cv;
    int meets = lo <= e->sv && hi >= -e->sv;   /* tested at the end: no branch */
    lo = clvis_hi(lo, -e->sv);
    hi = clvis_lo(hi, e->sv);
    /* u(dv) = (euv dv +- sqrt(det (evv - dv^2))) / evv on the ellipse's boundary */
    float dr = clvis_lo(clvis_hi(e->ds, lo), hi), dl = clvis_lo(clvis_hi(-e->ds, lo), hi);
    float wr = sqrt(e->det * clvis_hi(e->evv - dr * dr, 0.0f));
    float wl = sqrt(e->det * clvis_hi(e->evv - dl * dl, 0.0f));
    /* the pixels px whose centre px + 0.5 lies in [ulo, uhi] + 0.5, px in
     * [-1, W]; NaN (overflowing terms): the whole row */
    float ulo = ((e->cu + (e->euv * dl - wl) * e->ievv) - e->slack) - 0.5f;
    float uhi = ((e->cu + (e->euv * dr + wr) * e->ievv) + e->slack) - 0.5f;
    ulo = ulo >= -1.0f ? ulo : -1.0f;
    ulo = ulo <= (float)W ? ulo : (float)W;  /* no int conversion out of range (a long needle's far end) */
    uhi = uhi <= (float)W ? uhi : (float)W;
    uhi = uhi >= -1.0f ? uhi : -1.0f;
    /* ceil(ulo) and floor(uhi) (at most one pixel too many: rounding of uhi + 1) */
    int px0 = (int)ulo, px1 = (int)(uhi + 1.0f) - 1;
    px0 += (float)px0 < ulo;
    px0 = clvis_il_imax(px0, 0);
    px1 = clvis_il_imin(px1, (int)W - 1);
    *c0 = px0 / ts;
    *c1 = px1 / ts;
    return meets && px0 <= px1;
}

inline int clvis_tile_rect(float ulo, float uhi, float vlo, float vhi, uint W, uint H, int ts, int *r)
{
    ulo = clvis_hi(ulo, -1.0f);
    vlo = clvis_hi(vlo, -1.0f);
    uhi = clvis_lo(uhi, (float)W + 1.0f);
    vhi = clvis_lo(vhi, (float)H + 1.0f);
    if (!(ulo <= uhi && vlo <= vhi))
        return 0;
    /* ceil(ulo - 0.5) and floor(uhi - 0.5) of values in [-1.5, W + 0.5] */
    float a = ulo - 0.5f, b = uhi - 0.5f, c = vlo - 0.5f, d = vhi - 0.5f;
    int px0 = (int)a, px1 = (int)b, py0 = (int)c, py1 = (int)d;
    px0 += (float)px0 < a;
    px1 -= (float)px1 > b;
    py0 += (float)py0 < c;
    py1 -= (float)py1 > d;
    px0 = clvis_il_imax(px0, 0);
    px1 = clvis_il_imin(px1, (int)W - 1);
    py0 = clvis_il_imax(py0, 0);
    py1 = clvis_il_imin(py1, (int)H - 1);
    if (px0 > px1 || py0 > py1)
        return 0;
    r[0] = px0 / ts;
    r[1] = px1 / ts;
    r[2] = py0 / ts;
    r[3] = py1 / ts;
    return 1;
}

inline uint clvis_tile_pixel(uint gid, uint W, uint ty0, uint tile0, uint ts, uint *px, uint *py, uint *row)
{
    uint tiles_x = (W + ts - 1) / ts;
    uint tile = tile0 + gid / (ts * ts), l = gid % (ts * ts);
    *px = (tile % tiles_x) * ts + l % ts;
    *row = (tile / tiles_x) * ts + l / ts;
    *py = ty0 * ts + *row;
    return tile;
}

/* As clvis_tile_pixel for a work-item per row of 8 pixels (ts / 8 of them a
 * tile row): *px0 the row's first pixel. */
inline uint clvis_tile_row8(uint gid, uint W, uint ty0, uint tile0, uint ts, uint *px0, uint *py, uint *row)
{
    uint tiles_x = (W + ts - 1) / ts;
    uint per_tile = ts * ts / 8;
    uint tile = tile0 + gid / per_tile, l8 = gid % per_tile;
    *px0 = (tile % tiles_x) * ts + (l8 % (ts / 8)) * 8;
    *row = (tile / tiles_x) * ts + l8 / (ts / 8);
    *py = ty0 * ts + *row;
    return tile;
}

#endif /* CLVIS_GAUSS_TILES_H */
