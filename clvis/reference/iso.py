"""Dense NumPy isosurface raycaster: the definition of what the iso family's
OpenCL raycaster (Dyken, Usher, Kumar, TVCG 2024: progressive wavefront
isosurface raycasting over ZFP-compressed volumes) computes.

Everything here is in float64 arithmetic on float32 inputs; the OpenCL
version works in float32 and must meet the tolerance stated at the end.

Inputs
------
- ``volume``: a 3-D real array indexed [z, y, x], at least 2 samples per axis,
  finite. Its values are rounded to float32 first (what the kernels read; ZFP
  decodes float32), then used in float64.
- ``isovalue`` is rounded to float32; ``spacing`` (dz, dy, dx), positive,
  and ``origin`` (x, y, z) are rounded to float32. Sample [k, j, i] sits at
  world ``origin + (i dx, j dy, k dz)``.
- Rays: ``clvis.gauss.render.ray_buffer(camera, W, H)`` (22 float32
  coefficients) and ``clvis.reference.gauss.render.camera_rays`` give float32
  origins o on the near plane and unit directions d, one per pixel centre
  (px + 0.5, py + 0.5), row 0 on top, ray r = py * W + px. They are used in
  float64 from there on. The ray is o + t d, t >= 0 (no far-plane clipping).

Dual grid and the volume box
----------------------------
Index space: world p maps to g = (p - origin) / spacing (x, y, z order), so
sample (i, j, k) sits at g = (i, j, k). Cell (i, j, k), 0 <= i <= nx - 2 (and
so on), is the unit cube [i, i+1] x [j, j+1] x [k, k+1]; the field inside it is
the trilinear interpolant of its 8 corner samples. The volume box is
[0, n - 1] per axis (sample 0 to sample n - 1).

Entry (slab test)
-----------------
Per axis a: ``inv_a = spacing_a / d_safe_a`` (t per index unit), where
``d_safe_a = d_a``, except that a component with ``|d_a| < TINY_DIR`` (1e-20,
zero included) is replaced by ``copysign(TINY_DIR, d_a)`` (+0 -> +TINY,
-0 -> -TINY), exactly as clvis/ray.h's ``clvis_ray_safe_dir``. The index-space
ray is G(t) = O + t D, O = (o - origin) / spacing, D = d / spacing (D keeps
its zeros; only the inverse uses TINY_DIR). With
``t0 = (0 - O) inv``, ``t1 = (n - 1 - O) inv``: ``t_enter = max(0, max_a
min(t0_a, t1_a))``, ``t_exit = min_a max(t0_a, t1_a)``; the ray meets the volume
iff ``t_enter <= t_exit`` (a closed box; no padding in float64). A camera
inside the volume gets t_enter = 0. A ray lying in a face plane moves the
way its zero's sign says (see bvh.h): inwards it enters, outwards its interval
is [0, 0] at most.

Traversal (Amanatides & Woo 1987)
---------------------------------
The first cell is ``c = clamp(floor(G(t_enter)), 0, n - 2)`` per axis and
t_in = t_enter. Per step, for each axis, the parameter of the cell's next
boundary is recomputed from the cell index (no accumulated tMax):
``t_next_a = (c_a + [inv_a > 0] - O_a) inv_a``. The segment in the cell is
[t_in, t_out], ``t_out = max(t_in, min(t_exit, min_a t_next_a))``; it may have
length zero (a ray through an edge or a corner, or along a face). After the
cell is tested the ray steps one axis, the one with the smallest t_next (ties:
x before y before z), by sign(inv_a), and t_in = t_out. A ray ends at its
first hit, after the cell whose t_out >= t_exit, or when c leaves
[0, n - 2]. All rays step together (vectorised); the traversal is dense (every
cell on the path is visited), cells are only skipped by their value range.

Cell skipping: a cell whose 8 corner values have min > isovalue or max <
isovalue is skipped (the trilinear interpolant lies within the corner range,
so no zero is lost). :func:`cell_ranges`, :func:`block_ranges` and
:func:`coarse_ranges` are the macrocell grids the OpenCL version skips with.

Intersection in a cell (Marmitt et al. 2004)
--------------------------------------------
With s = t - t_in in [0, L], L = t_out - t_in, local coordinates
u(s) = G(t_in) - c + s D (x, y, z), and corner values v_abc - isovalue (the
isovalue is subtracted from the corners first), the interpolant minus the
isovalue is the cubic f(s) = c3 s^3 + c2 s^2 + c1 s + c0 (coefficients by
expanding the product of the three linear weights, :func:`cell_cubic`;
evaluated by Horner's rule). Its extrema are the roots of
f'(s) = 3 c3 s^2 + 2 c2 s + c1 strictly inside (0, L), from the stable
quadratic formula (q = -(B + sign(B) sqrt(B^2 - 4AC)) / 2, roots q / A and
C / q; A = 0 gives the linear root -C / B; a negative discriminant none).
Sorted, with 0 and L they split [0, L] into up to three monotone intervals
(a missing extremum is replaced by L, giving empty intervals [L, L]).

Zero rule: an interval [a, b] contains a zero iff ``(f(a) <= 0 and f(b) >= 0)
or (f(a) >= 0 and f(b) <= 0)`` (signs compared, never the product, which can
underflow). The hit is in the first interval, in order, that contains a zero;
so a value exactly equal to the isovalue counts (a tangential touch at an
extremum is a hit; a zero at a cell's entry is a hit at t_in), and in exact
arithmetic the hit is *the smallest t in [t_enter, t_exit] where the piecewise
trilinear field equals the isovalue*. A field that starts on either side of
the isovalue is treated alike (a camera inside the surface sees its first
crossing).

Root refinement in [a, b]: if f(a) == 0 the root is a. Otherwise, by default
(``refine=None``) 60 bisection steps (keep the left half [a, m] when it
has a zero by the zero rule, else [m, b]; the result is the midpoint of the
last bracket), which is the root to float64 precision. ``refine=k`` (an int)
instead is Marmitt's repeated linear interpolation: k times x = a - f(a)
(b - a) / (f(b) - f(a)), then replace a by x when f(x) has f(a)'s (nonzero)
sign, else b (so b when f(x) == 0); the result is one more interpolation in
the final bracket (k + 1 interpolations, k evaluations of f). Marmitt
uses k = 2 or 3. ``refine=("illinois", k)`` is the same with the Illinois
modification: when a step replaces the same end as the step before, the
kept end's f is halved first. ``refine=("bisection", k)`` is k bisection
steps. Measured against the exact root (128^2 rays, 64^3 volumes,
reliable pixels): Marmitt k = 3 leaves depth errors up to 8e-4 of the
diagonal on Marschner–Lobb (3.7 % of the hits above 1e-4) and k = 10 still
2e-4; Illinois k = 5 gives 1.5e-5, k = 6 8e-7. So the OpenCL version should
use Illinois with at least 6 steps (or bisect to the tolerance), not
Marmitt's 3.

Outputs
-------
t: the hit's ray parameter (world units, d is unit length), +inf at misses.
position = o + t d (world); depth = depth_row · [position, 1] with the
float32 depth row of the ray buffer (the view-axis distance), +inf at misses.
gradient: the analytic gradient of the hit cell's trilinear interpolant at the
hit (local coordinates clamped to [0, 1]), in world units (d/du divided by
dx, ...). The hit cell is the cell in which the traversal found the hit (at a
face, the cell before it). normal = gradient / |gradient|, flipped to face the
viewer (n · d <= 0); -d where the gradient is zero.

Shading (Blinn–Phong with a headlight): light l = view v = -d, so the half
vector h = l and, with x = |n · l|::

    rgb = clamp(base * (ambient + diffuse * x) + specular * x ** shininess, 0, 1)

defaults (:class:`Shading`): base (0.9, 0.75, 0.4), ambient 0.15, diffuse
0.75, specular 0.3, shininess 32. rgba float32: alpha 1 at hits; all zero at
misses.

What an OpenCL image must meet
------------------------------
Every pixel also gets ``margin`` (value units) and ``slope`` = |f'(t_hit)|
(value per world unit, 0 at misses). margin is the smallest |f| at the
*turning points* of f along the ray before its hit: t_enter; every extremum
inside a cell segment; every cell face where f' changes sign (or is zero)
across the face; t_exit (misses only); and the far end of the hit interval
(whatever it is: an extremum, a face or t_exit). A cell skipped by its range
contributes its gap to the isovalue, min - iso or iso - max, a lower bound of
|f| in it. Perturbing the field by less than margin (a perturbation of the
samples by less than margin perturbs the interpolant by less than margin) can
neither create a zero before the hit nor remove the hit's sign change, so it
cannot change the hit mask. Where slope * depth tolerance is below the
perturbation, the depth is ill-conditioned.

With ``eps = VALUE_TOLERANCE * (max - min of the volume)`` (1e-5 of the
value range, about 100 times float32's relative precision: room for the
float32 rounding of positions and values), a pixel is *reliable* when
margin > eps and, at hits, slope * DEPTH_TOLERANCE * diagonal > eps
(diagonal = |(n - 1) spacing|, the volume box's diagonal). On reliable pixels
the OpenCL image must have the same hit mask and depth within
``DEPTH_TOLERANCE`` (1e-4) of the diagonal; unreliable pixels (grazing rays,
exact touches, near-tangent crossings) are not compared. :func:`reliable` and
:func:`agreement` compute this (at 128^2, 0.02-0.03 % of the pixels are
unreliable on Marschner–Lobb 64^3, 0.1-0.3 % on turbulence 64^3 and 128^3). Normals there should agree
to about 1e-3, except where the hit lies within float noise of a cell face
(the gradient of the piecewise trilinear field is discontinuous across faces).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._arrays import real_array
from ..errors import DataError
from ..gauss.render import ray_buffer
from .gauss.render import camera_rays

__all__ = [
    "DEPTH_TOLERANCE",
    "TINY_DIR",
    "VALUE_TOLERANCE",
    "IsoImage",
    "Shading",
    "agreement",
    "block_ranges",
    "cell_cubic",
    "cell_ranges",
    "coarse_ranges",
    "cubic_first_zero",
    "reliable",
    "render",
    "render_rays",
    "shade",
]

TINY_DIR = 1e-20            # clvis/ray.h CLVIS_RAY_TINY_DIR
DEPTH_TOLERANCE = 1e-4      # depth agreement, as a fraction of the volume diagonal
VALUE_TOLERANCE = 1e-5      # reliability threshold, as a fraction of the value range
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


def _volume(volume) -> np.ndarray:
    """The volume as a float32 [z, y, x] array (copy), checked."""
    a = real_array("volume", volume)
    if a.ndim != 3:
        raise DataError(f"volume: expected a 3-D [z, y, x] array, got shape {a.shape}")
    if min(a.shape) < 2:
        raise DataError(f"volume: needs at least 2 samples per axis, got shape {a.shape}")
    a = a.astype(np.float32)
    if not np.isfinite(a).all():
        raise DataError("volume: values must be finite (as float32)")
    return a


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
# macrocell grids


def cell_ranges(volume):
    """(lo, hi), each (nz - 1, ny - 1, nx - 1) float32: the min and max of each
    dual cell's 8 corner samples (cell [k, j, i] has corners [k..k+1, j..j+1,
    i..i+1])."""
    v = _volume(volume)
    views = [v[dz:v.shape[0] - 1 + dz, dy:v.shape[1] - 1 + dy, dx:v.shape[2] - 1 + dx]
             for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)]
    return np.minimum.reduce(views), np.maximum.reduce(views)


def _reduce_blocks(lo, hi, factor, shape=None):
    """Per factor^3 group of entries, the min of lo and the max of hi; `shape`
    (default: just enough groups) may ask for more groups, which are empty."""
    if shape is None:
        shape = tuple(-(-s // factor) for s in lo.shape)
    pad = [(0, b * factor - s) for b, s in zip(shape, lo.shape)]
    lo = np.pad(lo, pad, constant_values=np.inf)
    hi = np.pad(hi, pad, constant_values=-np.inf)
    split = (shape[0], factor, shape[1], factor, shape[2], factor)
    return lo.reshape(split).min(axis=(1, 3, 5)), hi.reshape(split).max(axis=(1, 3, 5))


def _factor(name, v) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{name}: expected an int, got {type(v).__name__}")
    if v < 1:
        raise ValueError(f"{name}: must be at least 1, got {v}")
    return int(v)


def block_ranges(volume, block: int = 4):
    """(lo, hi), each (ceil(nz / block), ceil(ny / block), ceil(nx / block))
    float32: per block of block^3 samples (the ZFP blocks for block = 4; block
    [bz, by, bx] holds samples [block*bz .. block*bz + block - 1] per axis), the
    value range of every dual cell whose minimum corner lies in the block, that
    is, of the samples [block*b .. min(block*b + block, n - 1)] per axis (the
    block dilated by its +x, +y, +z neighbour samples). A block that holds no
    cell's minimum corner (the last one, when n - 1 is a multiple of block)
    gets the empty range (+inf, -inf), so it is always skipped."""
    block = _factor("block", block)
    lo, hi = cell_ranges(volume)
    return _reduce_blocks(lo, hi, block, tuple(-(-(s + 1) // block) for s in lo.shape))


def coarse_ranges(ranges, factor: int = 4):
    """(lo, hi) of the coarse macrocells: per factor^3 group of blocks (blocks
    [factor*c .. factor*c + factor - 1] per axis, the last group partial), the
    min of the blocks' lo and the max of their hi. `ranges` is (lo, hi) from
    :func:`block_ranges` (or :func:`cell_ranges`)."""
    try:
        lo, hi = (np.asarray(r) for r in ranges)
    except (TypeError, ValueError):
        raise TypeError("ranges: expected a (lo, hi) pair of arrays") from None
    if lo.ndim != 3 or lo.shape != hi.shape:
        raise ValueError(f"ranges: expected two 3-D arrays of one shape, got {lo.shape} and {hi.shape}")
    return _reduce_blocks(lo, hi, _factor("factor", factor))


# ---------------------------------------------------------------------------
# the cubic along a ray segment in one cell


def cell_cubic(corners, local, direction):
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


def cubic_first_zero(c, length, refine=None, start=True, end=True):
    """The first zero of the cubic ``c`` (c0, c1, c2, c3 arrays (M,)) on
    [0, length] by the rules of the module docstring.

    Returns (found bool, s float64 (NaN where not found), margin, interval).
    interval is the (M, 2) bracket [a, b] of the hit (NaN where not found).
    margin is the min of |f| over the turning points examined (+inf if none):
    the extrema inside (0, length) before the hit interval's far end (all of
    them when nothing is found), s = 0 where `start`, s = length where `end`
    (and no hit lies in an earlier interval), and the hit interval's far end;
    `start`, `end` are bools or (M,) bool arrays."""
    c = tuple(np.asarray(x, np.float64) for x in c)
    length = np.asarray(length, np.float64)
    e1, e2 = _extrema(c, length)
    pts = np.stack([np.zeros_like(length), e1, e2, length], axis=1)
    f = _horner([x[:, None] for x in c], pts)
    f[:, 0] = c[0]
    zero = _has_zero(f[:, :-1], f[:, 1:])
    found = zero.any(axis=1)
    k = np.argmax(zero, axis=1)
    rows = np.arange(len(length))
    upto = np.where(found, k + 1, 3)
    turning = np.stack([np.broadcast_to(start, length.shape), e1 < length, e2 < length,
                        np.broadcast_to(end, length.shape)], axis=1)
    turning &= np.arange(4)[None, :] <= upto[:, None]
    turning[rows, upto] |= found                 # the far end of the hit interval, whatever it is
    margin = np.where(turning, np.abs(f), np.inf).min(axis=1)
    a, b = pts[rows, k], pts[rows, k + 1]
    fa, fb = f[rows, k], f[rows, k + 1]
    s = _refine(c, a, b, fa, fb, refine)
    s = np.where(found, s, np.nan)
    interval = np.where(found[:, None], np.stack([a, b], axis=1), np.nan)
    return found, s, margin, interval


def _refine_mode(refine):
    """(method, steps) from refine: None, an int k (Marmitt), or (method, k)."""
    if refine is None:
        return "bisection", BISECTION_STEPS
    method, k = ("marmitt", refine) if not isinstance(refine, tuple) else refine
    if method not in ("marmitt", "illinois", "bisection") or isinstance(k, bool) \
            or not isinstance(k, (int, np.integer)) or k < 0:
        raise ValueError(f"refine: expected None, an int >= 0 or ('marmitt' | 'illinois' | 'bisection', "
                         f"int >= 0), got {refine!r}")
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
                left = _has_zero(fa, fm)         # a zero in [a, m]: keep it
                b, fb = np.where(left, m, b), np.where(left, fm, fb)
                a, fa = np.where(left, a, m), np.where(left, fa, fm)
            s = 0.5 * (a + b)
        else:
            def interpolate():
                x = np.where(fb != fa, a - fa * (b - a) / (fb - fa), a)
                return np.clip(x, np.minimum(a, b), np.maximum(a, b))

            last = np.zeros(len(a), np.int8)     # 1: a was replaced last step, -1: b
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


def render_rays(volume, origins, directions, isovalue, spacing=(1, 1, 1), origin=(0, 0, 0), refine=None):
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
    sp = _vec3("spacing", spacing, positive=True)[::-1].copy()     # dx, dy, dz
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
    prev_slope = np.full(len(act), np.nan)      # f' at the previous cell's exit, NaN: unknown
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
    dxv = corners[:, :, :, 1] - corners[:, :, :, 0]           # [z, y]
    dyv = corners[:, :, 1, :] - corners[:, :, 0, :]           # [z, x]
    dzv = corners[:, 1, :, :] - corners[:, 0, :, :]           # [y, x]
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


def shade(normal, directions, hit, shading: Shading | None = None) -> np.ndarray:
    """rgba (R, 4) float32 for normals facing the viewer (R, 3), ray directions
    (R, 3) and the hit mask (R,), by the module docstring's Blinn–Phong rule."""
    shading = shading or Shading()
    x = np.abs(np.einsum("ij,ij->i", np.nan_to_num(normal), directions))
    base = np.asarray(shading.base, np.float64)
    rgb = base[None, :] * (shading.ambient + shading.diffuse * x)[:, None] \
        + (shading.specular * x ** shading.shininess)[:, None]
    rgba = np.zeros((len(x), 4))
    rgba[:, :3] = np.clip(rgb, 0.0, 1.0)
    rgba[:, 3] = 1.0
    rgba[~hit] = 0.0
    return rgba.astype(np.float32)


def render(volume, camera, width, height, isovalue, spacing=(1, 1, 1), origin=(0, 0, 0),
           shading: Shading | None = None, refine=None) -> IsoImage:
    """Raycast the isosurface ``volume == isovalue`` for `camera` at `width` x
    `height` (see the module docstring for every rule). `refine`: None (the
    exact root), an int k (Marmitt's k linear-interpolation steps) or
    ("marmitt" | "illinois" | "bisection", k)."""
    if shading is not None and not isinstance(shading, Shading):
        raise TypeError(f"shading: expected a Shading, got {type(shading).__name__}")
    buf = ray_buffer(camera, width, height)
    w, h = int(width), int(height)
    o32, d32 = camera_rays(buf, w, h)
    r = render_rays(volume, o32, d32, isovalue, spacing, origin, refine)
    o, d = o32.astype(np.float64), d32.astype(np.float64)
    hit, t = r["hit"], r["t"]
    with np.errstate(invalid="ignore"):
        position = np.where(hit[:, None], o + np.where(hit, t, 0.0)[:, None] * d, np.nan)
        row = buf[18:22].astype(np.float64)
        depth = np.where(hit, position @ row[:3] + row[3], np.inf)
        g = r["gradient"]
        length = np.linalg.norm(g, axis=1)
        normal = np.where((length > 0)[:, None], g / np.where(length > 0, length, 1.0)[:, None], -d)
        normal = np.where((np.einsum("ij,ij->i", normal, d) > 0)[:, None], -normal, normal)
        normal = np.where(hit[:, None], normal, np.nan)
    rgba = shade(normal, d, hit, shading)
    vol = _volume(volume)
    sp = _vec3("spacing", spacing, positive=True)
    diagonal = float(np.linalg.norm((np.array(vol.shape) - 1) * sp))
    return IsoImage(
        hit=hit.reshape(h, w), t=t.reshape(h, w), depth=depth.reshape(h, w),
        position=position.reshape(h, w, 3), gradient=g.reshape(h, w, 3), normal=normal.reshape(h, w, 3),
        rgba=rgba.reshape(h, w, 4), margin=r["margin"].reshape(h, w), slope=r["slope"].reshape(h, w),
        cells=r["cells"].reshape(h, w), diagonal=diagonal,
        value_range=float(vol.max()) - float(vol.min()))


# ---------------------------------------------------------------------------
# the tolerance an OpenCL image must meet


def reliable(image: IsoImage, value_tolerance: float = VALUE_TOLERANCE,
             depth_tolerance: float = DEPTH_TOLERANCE) -> np.ndarray:
    """(H, W) bool: the pixels whose hit mask and depth are stable under value
    perturbations of ``eps = value_tolerance * image.value_range``: margin >
    eps and, at hits, slope * depth_tolerance * diagonal > eps. (A constant
    volume has value_range 0: then only margin > 0 is asked.)"""
    eps = value_tolerance * image.value_range
    ok = image.margin > eps
    return ok & (~image.hit | (image.slope * depth_tolerance * image.diagonal > eps))


def agreement(reference: IsoImage, hit, depth, value_tolerance: float = VALUE_TOLERANCE,
              depth_tolerance: float = DEPTH_TOLERANCE) -> dict:
    """Compare another image's hit mask and depth (H, W) with `reference` on
    its reliable pixels. Returns {"ok", "reliable" (count), "unreliable"
    (count), "mask_mismatches" (reliable pixels whose hit differs),
    "depth_error" (max |depth difference| / diagonal over reliable pixels that
    both hit, 0 if none)}; ok means no mismatch and depth_error <=
    depth_tolerance."""
    hit = np.asarray(hit, bool)
    depth = np.asarray(depth, np.float64)
    if hit.shape != reference.hit.shape or depth.shape != reference.hit.shape:
        raise ValueError(f"hit, depth: expected shape {reference.hit.shape}, got {hit.shape} and {depth.shape}")
    rel = reliable(reference, value_tolerance, depth_tolerance)
    mism = int((rel & (hit != reference.hit)).sum())
    both = rel & hit & reference.hit
    err = float(np.abs(depth[both] - reference.depth[both]).max() / reference.diagonal) if both.any() else 0.0
    return {"ok": mism == 0 and err <= depth_tolerance, "reliable": int(rel.sum()),
            "unreliable": int((~rel).sum()), "mask_mismatches": mism, "depth_error": err}
