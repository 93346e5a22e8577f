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
 *   int clvis_ellipse_meets(e, u0, u1, v0, v1): 1 when dx' adj(E) dx <= det(E)
 *       somewhere on the rectangle [u0, u1] x [v0, v1]
 *   int clvis_ellipse_tile(e, tx, ty, W, H, ts): clvis_ellipse_meets on tile
 *       (tx, ty)'s pixel centres, padded by e->pad
 *   int clvis_tile_rect(ulo, uhi, vlo, vhi, W, H, ts, r): r = (tx0, tx1, ty0, ty1),
 *       the tiles (inclusive) of the pixels whose centre px + 0.5 lies in
 *       [ulo, uhi] x [vlo, vhi] (clamped to [-1, W + 1] x [-1, H + 1]); 0 when
 *       there are none
 *
 *   uint clvis_tile_pixel(gid, W, ty0, tile0, ts, &px, &py, &row): a renderer's
 *       work-item gid, a work-item per pixel of ts x ts tiles (tile tile0 + gid /
 *       ts^2, pixel gid % ts^2 of it, row-major; tile index (ty - ty0) * tiles_x
 *       + tx): its tile, pixel (px, py) and row within the band of tiles
 *
 * clvis.reference.gauss.tiles and clvis.reference.gauss.splat repeat them.
 */
#ifndef CLVIS_GAUSS_TILES_H
#define CLVIS_GAUSS_TILES_H

#include "clvis/camera.h"
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
    e->pad = CLVIS_TILE_PAD + 1e-5f * (fabs(cu) + fabs(cv));
}

inline int clvis_ellipse_meets(const clvis_ellipse *e, float u0, float u1, float v0, float v1)
{
    if (e->cu >= u0 && e->cu <= u1 && e->cv >= v0 && e->cv <= v1)
        return 1;
    float us[2] = {u0, u1}, vs[2] = {v0, v1};
    for (int k = 0; k < 2; ++k) {
        /* vertical edge u = us[k] */
        float dx = us[k] - e->cu;
        float dy = clamp(-(e->a01 * dx) / e->a11, v0 - e->cv, v1 - e->cv);
        if ((e->a00 * dx * dx + 2.0f * e->a01 * dx * dy) + e->a11 * dy * dy <= e->det)
            return 1;
        /* horizontal edge v = vs[k] */
        dy = vs[k] - e->cv;
        dx = clamp(-(e->a01 * dy) / e->a00, u0 - e->cu, u1 - e->cu);
        if ((e->a00 * dx * dx + 2.0f * e->a01 * dx * dy) + e->a11 * dy * dy <= e->det)
            return 1;
    }
    return 0;
}

inline int clvis_ellipse_tile(const clvis_ellipse *e, int tx, int ty, uint W, uint H, int ts)
{
    float u0 = (float)(tx * ts) + 0.5f, u1 = (float)min((tx + 1) * ts, (int)W) - 0.5f;
    float v0 = (float)(ty * ts) + 0.5f, v1 = (float)min((ty + 1) * ts, (int)H) - 0.5f;
    return clvis_ellipse_meets(e, u0 - e->pad, u1 + e->pad, v0 - e->pad, v1 + e->pad);
}

inline int clvis_tile_rect(float ulo, float uhi, float vlo, float vhi, uint W, uint H, int ts, int *r)
{
    ulo = fmax(ulo, -1.0f);
    vlo = fmax(vlo, -1.0f);
    uhi = fmin(uhi, (float)W + 1.0f);
    vhi = fmin(vhi, (float)H + 1.0f);
    if (!(ulo <= uhi && vlo <= vhi))
        return 0;
    int px0 = max((int)ceil(ulo - 0.5f), 0), px1 = min((int)floor(uhi - 0.5f), (int)W - 1);
    int py0 = max((int)ceil(vlo - 0.5f), 0), py1 = min((int)floor(vhi - 0.5f), (int)H - 1);
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

#endif /* CLVIS_GAUSS_TILES_H */
