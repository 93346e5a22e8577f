"""NumPy reference of clvis.raster.depth_filter (clvis.depth_filter): the hierarchical depth filter.

A point cloud rasterized with one pixel per point shows background points
through the holes between foreground points. Vanherck, Zoomers et al. ("Real-
time Neural Rendering of LiDAR Point Clouds", Eurographics 2025 short papers,
Fig. 2) remove them before their U-Net with a depth heuristic on a min-pooled
image pyramid. This module is the exact definition clvis implements; the
kernels of ``kernels_cl/raster/depth_filter.cl`` reproduce it bit for bit.

Definition
----------
Input: ``depth`` (H x W float32); ``+inf`` means "no point" (empty pixel),
every other value must be finite and >= 0 (NaN and negative values are
errors). Parameters: ``levels`` L (0..16), ``filter_strength`` s (>= 1; the
tolerance factor: larger removes fewer points), ``edge_threshold`` t (>= 0).
All arithmetic is float32, s and t rounded to float32 first.

1. Pyramid. D0 = depth. For k = 1..L, Dk has ceil(H(k-1)/2) x ceil(W(k-1)/2)
   pixels; Dk[y, x] = min of D(k-1)[2y+i, 2x+j] (i, j in {0, 1}) over those
   inside D(k-1) (the missing row/column of an odd size counts as +inf).
   Levels past log2 of the size are 1 x 1 copies of the level before.
2. Coarse to fine. F_L = D_L. For k = L down to 1, every pixel q of level
   k-1, with value d = D(k-1)[q] and parent p = (qy // 2, qx // 2), v = F_k[p]:

   - edge test of the parent on F_k (a neighbour outside the level counts as
     v itself): ``lap = (((up + down) + left) + right) - 4*v``;
     ``edge = lap > t * v``. A positive Laplacian means p is nearer than its
     surroundings: p lies on the foreground side of a depth discontinuity;
   - reference depth: ``ref = max of F_k over the 3x3 pixels around p`` (those
     inside the level) on an edge, else ``ref = v``;
   - ``kept = d < inf and d <= s * ref``;
   - for k >= 2, the filled level F(k-1)[q] = d if kept, else v (a removed or
     empty pixel takes its parent's depth).

   The result is the keep mask of level 0: ``kept`` for every input pixel.
   L = 0 keeps every pixel that holds a point.

Why this removes see-through points: a 2 x 2 min-pool sees the foreground
point beside a background one, so a background pixel is farther than s times
its parent and goes. A hole wider than one block survives at the fine levels,
but a coarser level still sees foreground around it; that level removes the
hole's min-pooled value and fills in the parent's (foreground) depth, and the
finer levels then compare the hole's pixels with it. At a silhouette the
parent block holds the nearer object although its background pixels are
legitimately visible; there the parent is an edge and the pixel is compared
with the farthest parent around, so background beside an object survives.

What follows the paper and its authors' public implementation: the 2 x 2
min-pool pyramid (default 4 levels), the coarse-to-fine pass in which pixels
failing the test take a value from the coarser level, the test
``d <= s * parent`` with s = 1.025 by default, the Laplacian edge test with
the 4-neighbour kernel, and on edges keeping a pixel that passes against any
parent of the 3 x 3 neighbourhood (the maximum). What clvis chose: ceil sizes
with +inf padding for odd sizes (the public code drops the last odd row and
column); the fill takes the parent's value (not a bilinear upsample, which
would smear +inf and need arithmetic beyond one multiply); the edge threshold
is relative, ``lap > t * v`` with t = 0.01 by default (the public code uses a
fixed 0.03 in scene units), and neighbours outside the level count as the
centre (the public code never marks border pixels); the explicit rules for
empty pixels and the validation of NaN and negative depths.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from ...errors import DataError

LEVELS = 4
FILTER_STRENGTH = 1.025
EDGE_THRESHOLD = 0.01
MAX_LEVELS = 16
INV255 = np.float32(1.0) / np.float32(255.0)  # the float32 nearest 1/255

_INF = np.float32(np.inf)


def level_shapes(shape: Sequence[int], levels: int) -> list[tuple[int, int]]:
    """[(H0, W0), (H1, W1), ... (HL, WL)]: ceil halving per level."""
    h, w = shape
    out = [(h, w)]
    for _ in range(levels):
        h, w = -(-h // 2), -(-w // 2)
        out.append((h, w))
    return out


def _min_pool(d):
    h, w = d.shape
    padded = np.full((h + h % 2, w + w % 2), _INF, np.float32)
    padded[:h, :w] = d
    return padded.reshape(padded.shape[0] // 2, 2, padded.shape[1] // 2, 2).min(axis=(1, 3))


def _reference_depth(f, t):
    """For each pixel of level f: the depth its children are compared with."""
    g = np.pad(f, 1, mode="edge")  # outside neighbour = the centre itself
    with np.errstate(over="ignore", invalid="ignore"):
        lap = (((g[:-2, 1:-1] + g[2:, 1:-1]) + g[1:-1, :-2]) + g[1:-1, 2:]) - f * np.float32(4)
        edge = lap > t * f
    h, w = f.shape
    m = np.pad(f, 1, constant_values=-_INF)  # outside pixels take no part in the max
    around = np.max([m[dy : dy + h, dx : dx + w] for dy in range(3) for dx in range(3)], axis=0)
    return np.where(edge, around, f)


def _up(a, shape):
    """Each pixel of the finer level `shape` gets its parent's value."""
    return a.repeat(2, axis=0).repeat(2, axis=1)[: shape[0], : shape[1]]


def _check(
    depth_in: npt.ArrayLike, levels: int, filter_strength: float, edge_threshold: float
) -> tuple[np.ndarray, np.float32, np.float32]:
    depth = np.asarray(depth_in)
    if depth.dtype != np.float32:
        raise TypeError(f"depth: dtype {depth.dtype.name} is not supported; expected float32")
    if depth.ndim != 2:
        raise ValueError(f"depth: expected a 2-D array, got shape {depth.shape}")
    if not 0 <= levels <= MAX_LEVELS:
        raise ValueError(f"levels: expected 0..{MAX_LEVELS}, got {levels}")
    s, t = np.float32(filter_strength), np.float32(edge_threshold)
    if not (np.isfinite(s) and s >= 1):
        raise ValueError(f"filter_strength: expected a finite number >= 1, got {filter_strength}")
    if not (np.isfinite(t) and t >= 0):
        raise ValueError(f"edge_threshold: expected a finite number >= 0, got {edge_threshold}")
    if np.isnan(depth).any() or (depth < 0).any():
        raise DataError("depth: NaN or negative values")
    return depth, s, t


def depth_filter_mask(
    depth: npt.ArrayLike,
    levels: int = LEVELS,
    filter_strength: float = FILTER_STRENGTH,
    *,
    edge_threshold: float = EDGE_THRESHOLD,
) -> np.ndarray:
    """The keep mask (H x W bool) of the definition above."""
    depth, s, t = _check(depth, levels, filter_strength, edge_threshold)
    if depth.size == 0 or levels == 0:
        return depth < _INF
    pyramid = [depth]
    for _ in range(levels):
        pyramid.append(_min_pool(pyramid[-1]))
    f = pyramid[levels]
    for k in range(levels, 0, -1):
        d = pyramid[k - 1]
        ref = _up(_reference_depth(f, t), d.shape)
        with np.errstate(over="ignore"):
            kept = (d < _INF) & (d <= s * ref)
        if k == 1:
            return kept
        f = np.where(kept, d, _up(f, d.shape))
    raise AssertionError("unreachable: the loop returns at k == 1")


def rgbda(rgba: npt.ArrayLike, depth: npt.ArrayLike, keep: npt.ArrayLike) -> np.ndarray:
    """H x W x 5 float32 [r, g, b, depth, alpha]: where keep, the colour bytes
    times the float32 nearest 1/255, the depth and 1; elsewhere 0, 0, 0, +inf, 0."""
    rgba, depth, keep = np.asarray(rgba), np.asarray(depth), np.asarray(keep).astype(bool)
    out = np.zeros(depth.shape + (5,), np.float32)
    out[..., :3] = np.where(keep[..., None], rgba[..., :3].astype(np.float32) * INV255, 0)
    out[..., 3] = np.where(keep, depth, _INF)
    out[..., 4] = keep
    return out


def kept(
    depth: npt.ArrayLike, keep: npt.ArrayLike, rgba: npt.ArrayLike | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """The planes depth_filter keeps: (depth, +inf where not keep; the colour
    bytes, every channel 0 where not keep, or None without rgba)."""
    depth, keep = np.asarray(depth, np.float32), np.asarray(keep).astype(bool)
    out_rgba = None
    if rgba is not None:
        out_rgba = np.where(keep[..., None], np.asarray(rgba), 0).astype(np.uint8)
    return np.where(keep, depth, _INF).astype(np.float32), out_rgba
