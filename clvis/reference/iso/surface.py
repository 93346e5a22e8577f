"""A second field at the isosurface hits: the NumPy definition of
kernels_cl/iso/surface.cl (clvis.iso.sample_hits).

For each pixel whose ray hit the surface (``hit`` and a finite ``t``), the
world point ``P = o + t d`` (o, d: the pixel's ray, clvis.reference.camera's
``camera_rays`` of the image's ray buffer, float32) is mapped to the field's
index space ``g = (P - origin) / spacing`` (x, y, z order; sample [k, j, i]
of the [z, y, x] field sits at ``origin + (i dx, j dy, k dz)``). When every
``g_a`` lies in ``[-SLACK, n_a - 1 + SLACK]`` (SLACK = 1e-3 index units: the
raycaster's hits lie in its volume box up to float32 rounding) g is clamped
to ``[0, n_a - 1]`` and the value is the trilinear interpolant of the cell
``c_a = min(floor(g_a), n_a - 2)`` at ``f_a = g_a - c_a`` (lerp along x,
then y, then z); otherwise, and at pixels without a hit, NaN.

Everything in float64 from the float32 inputs (the field, t, the rays, the
spacing and origin rounded to float32). The kernel works in float32: its
values differ by rounding, at most about VALUE_TOLERANCE times the field's
range plus the field's change over POSITION_TOLERANCE index units (tests/iso/test_surface.py).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from ...camera import Camera, ray_buffer
from ..camera import camera_rays

__all__ = ["POSITION_TOLERANCE", "SLACK", "VALUE_TOLERANCE", "sample_hits"]

SLACK = 1e-3
VALUE_TOLERANCE = 1e-5
POSITION_TOLERANCE = 1e-4


def sample_hits(
    field: npt.ArrayLike,
    camera: Camera,
    width: int,
    height: int,
    hit: npt.ArrayLike,
    t: npt.ArrayLike,
    spacing: Sequence[float] = (1.0, 1.0, 1.0),
    origin: Sequence[float] = (0.0, 0.0, 0.0),
) -> np.ndarray:
    """(height, width) float64: the field's value at each pixel's hit (see
    the module doc); `spacing` (dz, dy, dx) and `origin` (x, y, z) place the
    field, `hit` and `t` are the image's planes."""
    f = np.asarray(field, np.float32).astype(np.float64)
    if f.ndim != 3 or min(f.shape) < 2:
        raise ValueError(f"field: expected a 3-D array with at least 2 samples per axis, got {f.shape}")
    w, h = int(width), int(height)
    o, d = camera_rays(ray_buffer(camera, w, h), w, h)
    hit = np.asarray(hit, bool).reshape(-1)
    tt = np.asarray(t, np.float32).reshape(-1).astype(np.float64)
    ok = hit & np.isfinite(tt)
    sp = np.asarray(spacing, np.float32).astype(np.float64)[::-1]  # x, y, z
    org = np.asarray(origin, np.float32).astype(np.float64)
    n = np.array(f.shape[::-1], np.float64)  # nx, ny, nz
    p = o.astype(np.float64) + np.where(ok, tt, 0.0)[:, None] * d.astype(np.float64)
    g = (p - org) / sp
    ok &= ((g >= -SLACK) & (g <= n - 1 + SLACK)).all(axis=1)
    g = np.clip(g, 0.0, n - 1)
    c = np.minimum(np.floor(g), n - 2).astype(np.int64)
    fr = g - c
    out = np.full(len(g), np.nan)
    if ok.any():
        cx, cy, cz = (c[ok, a] for a in range(3))
        fx, fy, fz = (fr[ok, a] for a in range(3))

        def lerp(a, b, s):
            return a + s * (b - a)

        def v(dx, dy, dz):
            return f[cz + dz, cy + dy, cx + dx]

        x00, x10 = lerp(v(0, 0, 0), v(1, 0, 0), fx), lerp(v(0, 1, 0), v(1, 1, 0), fx)
        x01, x11 = lerp(v(0, 0, 1), v(1, 0, 1), fx), lerp(v(0, 1, 1), v(1, 1, 1), fx)
        out[ok] = lerp(lerp(x00, x10, fy), lerp(x01, x11, fy), fz)
    return out.reshape(h, w)
