"""Distances from points to a triangle mesh, for tests that check hits against
scikit-image's marching-cubes surface (tests/ is on sys.path: pyproject's pythonpath)."""

import numpy as np
from scipy.spatial import cKDTree


def closest_on_triangles(p, a, b, c):
    """Closest points on triangles (a, b, c) to p, all (M, 3) (Ericson,
    Real-Time Collision Detection 5.1.5)."""
    ab, ac = b - a, c - a
    ap, bp, cp = p - a, p - b, p - c
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(all="ignore"):
        denom = va + vb + vc
        out = a + ab * (vb / denom)[:, None] + ac * (vc / denom)[:, None]
        on_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        out = np.where(on_ab[:, None], a + (d1 / (d1 - d3))[:, None] * ab, out)
        on_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        out = np.where(on_ac[:, None], a + (d2 / (d2 - d6))[:, None] * ac, out)
        on_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
        out = np.where(on_bc[:, None], b + ((d4 - d3) / ((d4 - d3) + (d5 - d6)))[:, None] * (c - b), out)
    out = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, out)
    out = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, out)
    return np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, out)


def mesh_distance(points, verts, faces, k=16):
    """Distance of each point to the mesh: the exact point–triangle minimum
    over the k triangles with the nearest centroids (an upper bound)."""
    tri = verts[faces]
    _, idx = cKDTree(tri.mean(axis=1)).query(points, k=k)
    p = np.repeat(points, k, axis=0)
    t = tri[idx.ravel()]
    q = closest_on_triangles(p, t[:, 0], t[:, 1], t[:, 2])
    return np.linalg.norm(p - q, axis=1).reshape(-1, k).min(axis=1)
