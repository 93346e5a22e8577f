"""Eye-dome lighting: the NumPy definition of kernels_cl/raster/edl.cl.

A pixel holds a point when its depth is finite and > 0. For such a pixel at
depth d, each of its 8 neighbours at ``radius`` pixels (along the rows, the
columns and the diagonals) that lies inside the image and holds a point at
depth dn adds ``max(0, log2(d) - log2(dn))``: how far, in octaves of depth,
the point lies behind it. ``response`` is that sum over 8 (a missing
neighbour adds 0, so silhouettes against the background stay lit);
``shade = exp(-EDL_SCALE * strength * response)`` and r, g, b become
``round(c * shade)`` (half to even), alpha kept. Every other pixel is
copied. All in float32, the order of the kernel's operations.
"""

from __future__ import annotations

import numpy as np

EDL_SCALE = np.float32(300.0)  # the kernel's default -DEDL_SCALE


def edl(depth: np.ndarray, rgba: np.ndarray, strength: float = 1.0, radius: int = 1) -> np.ndarray:
    depth = np.asarray(depth, np.float32)
    rgba = np.asarray(rgba, np.uint8)
    h, w = depth.shape
    holds = np.isfinite(depth) & (depth > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ld = np.where(holds, np.log2(np.where(holds, depth, np.float32(1))), np.float32(0)).astype(np.float32)
    total = np.zeros((h, w), np.float32)
    r = int(radius)
    for j in (-1, 0, 1):
        for k in (-1, 0, 1):
            if j == 0 and k == 0:
                continue
            # neighbour of (y, x) is (y + j r, x + k r)
            nb_ld = np.zeros((h, w), np.float32)
            nb_holds = np.zeros((h, w), np.bool_)
            ys, yd = _window(h, j * r)
            xs, xd = _window(w, k * r)
            nb_ld[yd, xd] = ld[ys, xs]
            nb_holds[yd, xd] = holds[ys, xs]
            diff = np.maximum(np.float32(0), (ld - nb_ld).astype(np.float32))
            total = np.where(nb_holds, (total + diff).astype(np.float32), total)
    response = (total / np.float32(8)).astype(np.float32)
    shade = np.exp((-EDL_SCALE * np.float32(strength)) * response).astype(np.float32)
    out = rgba.copy()
    rgb = np.rint(rgba[..., :3].astype(np.float32) * shade[..., None])
    shaded = np.clip(rgb, 0, 255).astype(np.uint8)
    out[..., :3] = np.where(holds[..., None], shaded, rgba[..., :3])
    return out


def _window(n: int, off: int) -> tuple[slice, slice]:
    """(source, destination) slices along an axis of length n so that
    destination index t reads source index t + off, where that lies in 0..n-1."""
    if off >= 0:
        return slice(off, n), slice(0, max(n - off, 0))
    return slice(0, max(n + off, 0)), slice(-off, n)
