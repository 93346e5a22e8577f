"""NumPy reference of the block raytracing (clvis.iso.raytrace,
kernels_cl/iso/raytrace.cl): rays through the dual grid, the cubic of each
cell along the ray, its first root, the gradient and the shading. The rules
are written out in clvis.reference.iso.render's module docstring."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .macrocell import _volume, cell_ranges

__all__ = [
    "BISECTION_STEPS",
    "TINY_DIR",
    "IsoImage",
    "Shading",
    "cell_cubic",
    "cubic_first_zero",
    "render_rays",
    "shade",
]

TINY_DIR = 1e-20  # clvis/ray.h CLVIS_RAY_TINY_DIR
BISECTION_STEPS = 60


@dataclass(frozen=True)
class Shading:
    """Blinn–Phong constants (headlight; see the module docstring)."""

    base: tuple = (0.9, 0.75, 0.4)
    ambient: float = 0.15
    diffuse: float = 0.75
    specular: float = 0.3
    shininess: float = 32.0


@dataclass
class IsoImage:
    """A rendered frame, arrays (H, W[, C]).

    hit bool; t, depth float64 (+inf at misses); position, gradient, normal
    (H, W, 3) float64 world (NaN at misses); rgba (H, W, 4) float32; margin,
    slope float64 (see the module docstring); cells int64 (cells visited,
    including the hit cell); diagonal and value_range floats of the volume."""

    hit: np.ndarray
    t: np.ndarray
    depth: np.ndarray
    position: np.ndarray
    gradient: np.ndarray
    normal: np.ndarray
    rgba: np.ndarray
    margin: np.ndarray
    slope: np.ndarray
    cells: np.ndarray
    diagonal: float
    value_range: float


def _vec3(name, v, positive=False) -> np.ndarray:
    try:
        a = np.array(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name}: expected three numbers, got {v!r}") from None
    if a.shape != (3,):
        raise ValueError(f"{name}: expected three numbers, got shape {a.shape}")
    a = a.astype(np.float32).astype(np.float64)
    if not np.isfinite(a).all() or (positive and (a <= 0).any()):
        raise ValueError(f"{name}: expected three finite{' positive' if positive else ''} numbers, got {v!r}")
    return a


def _iso(isovalue) -> float:
    v = float(np.float32(isovalue))
    if not np.isfinite(v):
        raise ValueError(f"isovalue: must be finite as float32, got {isovalue!r}")
    return v


# ---------------------------------------------------------------------------
# the cubic along a ray segment in one cell


def cell_cubic(
    corners: npt.ArrayLike, local: npt.ArrayLike, direction: npt.ArrayLike
) -> tuple[np.ndarray, ...]:
    """Coefficients (c0, c1, c2, c3), each (M,), of f(s) = sum c_k s^k, the
    trilinear interpolant of `corners` (M, 2, 2, 2) [z, y, x] (already minus
    the isovalue) along local(s) = local + s direction (M, 3) x, y, z."""
    corners = np.asarray(corners, np.float64)
    local = np.asarray(local, np.float64)
    direction = np.asarray(direction, np.float64)
    # weight of the lower (0) and upper (1) corner per axis: alpha + beta s
    alpha = [(1.0 - local[:, a], local[:, a]) for a in range(3)]
    beta = [(-direction[:, a], direction[:, a]) for a in range(3)]
    c = [np.zeros(len(corners)) for _ in range(4)]
    for iz in (0, 1):
        for iy in (0, 1):
            for ix in (0, 1):
                v = corners[:, iz, iy, ix]
                ax, ay, az = alpha[0][ix], alpha[1][iy], alpha[2][iz]
                bx, by, bz = beta[0][ix], beta[1][iy], beta[2][iz]
                c[0] += v * (ax * ay * az)
                c[1] += v * (bx * ay * az + ax * by * az + ax * ay * bz)
                c[2] += v * (bx * by * az + bx * ay * bz + ax * by * bz)
                c[3] += v * (bx * by * bz)
    return tuple(c)


def _horner(c, s):
    return ((c[3] * s + c[2]) * s + c[1]) * s + c[0]


def _has_zero(fa, fb):
    return ((fa <= 0) & (fb >= 0)) | ((fa >= 0) & (fb <= 0))


def _extrema(c, length):
    """The roots of f' strictly inside (0, length), sorted; missing ones -> length."""
    a, b, cc = 3.0 * c[3], 2.0 * c[2], c[1]
    with np.errstate(all="ignore"):
        disc = b * b - 4.0 * a * cc
        q = -0.5 * (b + np.copysign(np.sqrt(disc), b))
        r1 = np.where(a != 0, q / a, np.where(b != 0, -cc / b, np.nan))
        r2 = np.where((a != 0) & (q != 0), cc / q, np.nan)
        r1 = np.where((a != 0) & (disc < 0), np.nan, r1)
        r2 = np.where(disc < 0, np.nan, r2)
        r1 = np.where((r1 > 0) & (r1 < length), r1, length)
        r2 = np.where((r2 > 0) & (r2 < length), r2, length)
    return np.minimum(r1, r2), np.maximum(r1, r2)


def cubic_first_zero(
    c: Sequence[npt.ArrayLike],
    length: npt.ArrayLike,
    refine: int | tuple[str, int] | None = None,
    start: bool | np.ndarray = True,
    end: bool | np.ndarray = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The first zero of the cubic ``c`` (c0, c1, c2, c3 arrays (M,)) on
    [0, length] by the rules of the module docstring.

    Returns (found bool, s float64 (NaN where not found), margin, interval).
    interval is the (M, 2) bracket [a, b] of the hit (NaN where not found).
    margin is the min of |f| over the turning points examined (+inf if none):
    the extrema inside (0, length) before the hit interval's far end (all of
    them when nothing is found), s = 0 where `start`, s = length where `end`
    (and no hit lies in an earlier interval), and the hit interval's far end;
    `start`, `end` are bools or (M,) bool arrays."""
    cs = tuple(np.asarray(x, np.float64) for x in c)
    length = np.asarray(length, np.float64)
    e1, e2 = _extrema(cs, length)
    pts = np.stack([np.zeros_like(length), e1, e2, length], axis=1)
    f = _horner([x[:, None] for x in cs], pts)
    f[:, 0] = cs[0]
    zero = _has_zero(f[:, :-1], f[:, 1:])
    found = zero.any(axis=1)
    k = np.argmax(zero, axis=1)
    rows = np.arange(len(length))
    upto = np.where(found, k + 1, 3)
    turning = np.stack(
        [np.broadcast_to(start, length.shape), e1 < length, e2 < length, np.broadcast_to(end, length.shape)],
        axis=1,
    )
    turning &= np.arange(4)[None, :] <= upto[:, None]
    turning[rows, upto] |= found  # the far end of the hit interval, whatever it is
    margin = np.where(turning, np.abs(f), np.inf).min(axis=1)
    a, b = pts[rows, k], pts[rows, k + 1]
    fa, fb = f[rows, k], f[rows, k + 1]
    s = _refine(cs, a, b, fa, fb, refine)
    s = np.where(found, s, np.nan)
    interval = np.where(found[:, None], np.stack([a, b], axis=1), np.nan)
    return found, s, margin, interval


def _refine_mode(refine):
    """(method, steps) from refine: None, an int k (Marmitt), or (method, k)."""
    if refine is None:
        return "bisection", BISECTION_STEPS
    method, k = ("marmitt", refine) if not isinstance(refine, tuple) else refine
    if (
        method not in ("marmitt", "illinois", "bisection")
        or isinstance(k, bool)
        or not isinstance(k, (int, np.integer))
        or k < 0
    ):
        raise ValueError(
            f"refine: expected None, an int >= 0 or ('marmitt' | 'illinois' | 'bisection', "
            f"int >= 0), got {refine!r}"
        )
    return method, int(k)


def _refine(c, a, b, fa, fb, refine):
    """The root in brackets [a, b] (f(a), f(b) of opposite signs or zero)."""
    method, steps = _refine_mode(refine)
    a0 = a
    at_a = fa == 0
    with np.errstate(all="ignore"):
        if method == "bisection":
            for _ in range(steps):
                m = 0.5 * (a + b)
                fm = _horner(c, m)
                left = _has_zero(fa, fm)  # a zero in [a, m]: keep it
                b, fb = np.where(left, m, b), np.where(left, fm, fb)
                a, fa = np.where(left, a, m), np.where(left, fa, fm)
            s = 0.5 * (a + b)
        else:

            def interpolate():
                x = np.where(fb != fa, a - fa * (b - a) / (fb - fa), a)
                return np.clip(x, np.minimum(a, b), np.maximum(a, b))

            last = np.zeros(len(a), np.int8)  # 1: a was replaced last step, -1: b
            for _ in range(steps):
                x = interpolate()
                fx = _horner(c, x)
                same_as_a = ((fx > 0) & (fa > 0)) | ((fx < 0) & (fa < 0))
                if method == "illinois":
                    fb = np.where(same_as_a & (last == 1), 0.5 * fb, fb)
                    fa = np.where(~same_as_a & (last == -1), 0.5 * fa, fa)
                    last = np.where(same_as_a, 1, -1).astype(np.int8)
                a, fa = np.where(same_as_a, x, a), np.where(same_as_a, fx, fa)
                b, fb = np.where(same_as_a, b, x), np.where(same_as_a, fb, fx)
            s = interpolate()
    return np.where(at_a, a0, s)


# ---------------------------------------------------------------------------
# rendering


def render_rays(
    volume: npt.ArrayLike,
    origins: npt.ArrayLike,
    directions: npt.ArrayLike,
    isovalue: float,
    spacing: Sequence[float] = (1, 1, 1),
    origin: Sequence[float] = (0, 0, 0),
    refine: int | tuple[str, int] | None = None,
) -> dict[str, np.ndarray]:
    """First hits of rays o + t d (t >= 0) with the isosurface, by the rules of
    the module docstring. `origins`, `directions` (R, 3) are rounded to float32
    (directions should be unit length for t to be a world distance).

    Returns a dict of (R,) arrays: hit, t (+inf at misses), cell (R, 3) int64
    x, y, z of the hit cell (-1 at misses), gradient (R, 3) world (NaN at
    misses), margin, slope, cells (cells visited)."""
    vol32 = _volume(volume)
    vol = vol32.astype(np.float64)
    iso = _iso(isovalue)
    _refine_mode(refine)
    sp = _vec3("spacing", spacing, positive=True)[::-1].copy()  # dx, dy, dz
    org = _vec3("origin", origin)
    o = _rays("origins", origins)
    d = _rays("directions", directions)
    if len(o) != len(d):
        raise ValueError(f"directions: {len(d)} rays, but origins has {len(o)}")
    nz, ny, nx = vol.shape
    n = np.array([nx, ny, nz], np.int64)
    lo, hi = (r.astype(np.float64).ravel() for r in cell_ranges(vol32))
    shifted = vol - iso

    nr = len(o)
    d_safe = np.where(np.abs(d) < TINY_DIR, np.copysign(TINY_DIR, d), d)
    inv = sp / d_safe
    O = (o - org) / sp
    D = d / sp
    t0 = (0.0 - O) * inv
    t1 = (n - 1 - O) * inv
    t_enter = np.maximum(0.0, np.minimum(t0, t1).max(axis=1))
    t_exit = np.maximum(t0, t1).min(axis=1)
    inside = t_enter <= t_exit

    out = {
        "hit": np.zeros(nr, bool),
        "t": np.full(nr, np.inf),
        "cell": np.full((nr, 3), -1, np.int64),
        "gradient": np.full((nr, 3), np.nan),
        "margin": np.full(nr, np.inf),
        "slope": np.zeros(nr),
        "cells": np.zeros(nr, np.int64),
    }
    act = np.nonzero(inside)[0]
    with np.errstate(invalid="ignore", over="ignore"):
        c = np.clip(np.floor(O[act] + t_enter[act, None] * D[act]), 0, n - 2).astype(np.int64)
    t_in = t_enter[act]
    prev_slope = np.full(len(act), np.nan)  # f' at the previous cell's exit, NaN: unknown
    step_offsets = np.array([[dz, dy, dx] for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)])
    sample_strides = np.array([ny * nx, nx, 1])
    while act.size:
        Oa, Da, inva, te = O[act], D[act], inv[act], t_exit[act]
        rows = np.arange(len(act))
        t_next = (c + (inva > 0) - Oa) * inva
        axis = np.argmin(t_next, axis=1)
        t_out = np.maximum(t_in, np.minimum(t_next[rows, axis], te))
        out["cells"][act] += 1
        cidx = (c[:, 2] * (ny - 1) + c[:, 1]) * (nx - 1) + c[:, 0]
        clo, chi = lo[cidx], hi[cidx]
        cand = (clo <= iso) & (chi >= iso)
        gap = np.maximum(clo - iso, iso - chi)
        np.minimum.at(out["margin"], act[~cand], gap[~cand])
        hit = np.zeros(len(act), bool)
        k = np.nonzero(cand)[0]
        slope_out = np.full(len(act), np.nan)
        if k.size:
            base = c[k, 2] * sample_strides[0] + c[k, 1] * sample_strides[1] + c[k, 0]
            corners = shifted.ravel()[base[:, None] + step_offsets @ sample_strides].reshape(-1, 2, 2, 2)
            local = Oa[k] + t_in[k, None] * Da[k] - c[k]
            coef = cell_cubic(corners, local, Da[k])
            length = t_out[k] - t_in[k]
            # s = 0 is a turning point unless f' keeps its (nonzero) sign across the face
            ps = prev_slope[k]
            start = ~(((ps > 0) & (coef[1] > 0)) | ((ps < 0) & (coef[1] < 0)))
            found, s, margin, _ = cubic_first_zero(coef, length, refine, start, t_out[k] >= te[k])
            slope_out[k] = (3.0 * coef[3] * length + 2.0 * coef[2]) * length + coef[1]
            np.minimum.at(out["margin"], act[k], margin)
            h = k[found]
            hit[h] = True
            ray = act[h]
            sh = s[found]
            out["hit"][ray] = True
            out["t"][ray] = t_in[h] + sh
            out["cell"][ray] = c[h]
            cf = tuple(x[found] for x in coef)
            out["slope"][ray] = np.abs((3.0 * cf[3] * sh + 2.0 * cf[2]) * sh + cf[1])
            u = np.clip(local[found] + sh[:, None] * Da[h], 0.0, 1.0)
            out["gradient"][ray] = _trilinear_gradient(corners[found], u) / sp
        finished = hit | (t_out >= te)
        c[rows, axis] += np.where(inva[rows, axis] > 0, 1, -1)
        outside = ((c < 0) | (c > n - 2)).any(axis=1)
        keep = ~(finished | outside)
        act, c, t_in, prev_slope = act[keep], c[keep], t_out[keep], slope_out[keep]
    return out


def _trilinear_gradient(corners, u):
    """d/du, d/dv, d/dw (x, y, z) of the trilinear interpolant of corners
    (M, 2, 2, 2) [z, y, x] at local u (M, 3)."""
    wx = np.stack([1.0 - u[:, 0], u[:, 0]], axis=1)
    wy = np.stack([1.0 - u[:, 1], u[:, 1]], axis=1)
    wz = np.stack([1.0 - u[:, 2], u[:, 2]], axis=1)
    dxv = corners[:, :, :, 1] - corners[:, :, :, 0]  # [z, y]
    dyv = corners[:, :, 1, :] - corners[:, :, 0, :]  # [z, x]
    dzv = corners[:, 1, :, :] - corners[:, 0, :, :]  # [y, x]
    gx = np.einsum("mzy,mz,my->m", dxv, wz, wy)
    gy = np.einsum("mzx,mz,mx->m", dyv, wz, wx)
    gz = np.einsum("myx,my,mx->m", dzv, wy, wx)
    return np.stack([gx, gy, gz], axis=1)


def _rays(name, a) -> np.ndarray:
    a = np.asarray(a, np.float32)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (R, 3), got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: must be finite")
    return a.astype(np.float64)


def shade(
    normal: np.ndarray, directions: np.ndarray, hit: np.ndarray, shading: Shading | None = None
) -> np.ndarray:
    """rgba (R, 4) float32 for normals facing the viewer (R, 3), ray directions
    (R, 3) and the hit mask (R,), by the module docstring's Blinn–Phong rule."""
    shading = shading or Shading()
    x = np.abs(np.einsum("ij,ij->i", np.nan_to_num(normal), directions))
    base = np.asarray(shading.base, np.float64)
    rgb = (
        base[None, :] * (shading.ambient + shading.diffuse * x)[:, None]
        + (shading.specular * x**shading.shininess)[:, None]
    )
    rgba = np.zeros((len(x), 4))
    rgba[:, :3] = np.clip(rgb, 0.0, 1.0)
    rgba[:, 3] = 1.0
    rgba[~hit] = 0.0
    return rgba.astype(np.float32)
