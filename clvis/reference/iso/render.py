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
- Rays: ``clvis.camera.ray_buffer(camera, W, H)`` (22 float32
  coefficients) and ``clvis.reference.camera.camera_rays`` give float32
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

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from ...camera import Camera, ray_buffer
from ..camera import camera_rays
from .raytrace import (  # noqa: F401  (the rules' building blocks, re-exported)
    BISECTION_STEPS,
    TINY_DIR,
    IsoImage,
    Shading,
    _iso,
    _rays,
    _vec3,
    _volume,
    render_rays,
    shade,
)

__all__ = ["DEPTH_TOLERANCE", "VALUE_TOLERANCE", "agreement", "reliable", "render"]

DEPTH_TOLERANCE = 1e-4  # depth agreement, as a fraction of the volume diagonal
VALUE_TOLERANCE = 1e-5  # reliability threshold, as a fraction of the value range


def render(
    volume: npt.ArrayLike,
    camera: Camera,
    width: int,
    height: int,
    isovalue: float,
    spacing: Sequence[float] = (1, 1, 1),
    origin: Sequence[float] = (0, 0, 0),
    shading: Shading | None = None,
    refine: int | tuple[str, int] | None = None,
) -> IsoImage:
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
        hit=hit.reshape(h, w),
        t=t.reshape(h, w),
        depth=depth.reshape(h, w),
        position=position.reshape(h, w, 3),
        gradient=g.reshape(h, w, 3),
        normal=normal.reshape(h, w, 3),
        rgba=rgba.reshape(h, w, 4),
        margin=r["margin"].reshape(h, w),
        slope=r["slope"].reshape(h, w),
        cells=r["cells"].reshape(h, w),
        diagonal=diagonal,
        value_range=float(vol.max()) - float(vol.min()),
    )


# ---------------------------------------------------------------------------
# the tolerance an OpenCL image must meet


def reliable(
    image: IsoImage, value_tolerance: float = VALUE_TOLERANCE, depth_tolerance: float = DEPTH_TOLERANCE
) -> np.ndarray:
    """(H, W) bool: the pixels whose hit mask and depth are stable under value
    perturbations of ``eps = value_tolerance * image.value_range``: margin >
    eps and, at hits, slope * depth_tolerance * diagonal > eps. (A constant
    volume has value_range 0: then only margin > 0 is asked.)"""
    eps = value_tolerance * image.value_range
    ok = image.margin > eps
    return ok & (~image.hit | (image.slope * depth_tolerance * image.diagonal > eps))


def agreement(
    reference: IsoImage,
    hit: npt.ArrayLike,
    depth: npt.ArrayLike,
    value_tolerance: float = VALUE_TOLERANCE,
    depth_tolerance: float = DEPTH_TOLERANCE,
) -> dict:
    """Compare another image's hit mask and depth (H, W) with `reference` on
    its reliable pixels. Returns {"ok", "reliable" (count), "unreliable"
    (count), "mask_mismatches" (reliable pixels whose hit differs),
    "depth_error" (max |depth difference| / diagonal over reliable pixels that
    both hit, 0 if none)}; ok means no mismatch and depth_error <=
    depth_tolerance."""
    hit = np.asarray(hit, bool)
    depth = np.asarray(depth, np.float64)
    if hit.shape != reference.hit.shape or depth.shape != reference.hit.shape:
        raise ValueError(
            f"hit, depth: expected shape {reference.hit.shape}, got {hit.shape} and {depth.shape}"
        )
    rel = reliable(reference, value_tolerance, depth_tolerance)
    mism = int((rel & (hit != reference.hit)).sum())
    both = rel & hit & reference.hit
    err = float(np.abs(depth[both] - reference.depth[both]).max() / reference.diagonal) if both.any() else 0.0
    return {
        "ok": mism == 0 and err <= depth_tolerance,
        "reliable": int(rel.sum()),
        "unreliable": int((~rel).sum()),
        "mask_mismatches": mism,
        "depth_error": err,
    }
