"""Eye-dome lighting (raster family): a screen-space shading pass over a
depth image that darkens each point by how far it lies behind its
neighbours, so the shape of a point cloud reads without normals (the
depth-only shading Potree and CloudCompare use for scans).

The definition is the docstring of :mod:`clvis.reference.raster.edl`; the
kernel is ``kernels_cl/raster/edl.cl``. numpy in, numpy out; a device array
in, a device array out (on the same queue, nothing read back).
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime
from .._arrays import buf, check_array, is_device, resolve_queue, result, to_device

__all__ = ["EDL_RADIUS", "EDL_STRENGTH", "MAX_EDL_RADIUS", "MAX_EDL_STRENGTH", "edl"]

EDL_STRENGTH = 1.0  # Potree's default strength
EDL_RADIUS = 1  # neighbours this many pixels away (Potree: 1.4, on a 4x4 ring)
MAX_EDL_STRENGTH = 1000.0
MAX_EDL_RADIUS = 64

_SRC = "raster/edl.cl"
PROFILES = {"cpu": {"WG": 64}, "gpu": {"WG": 256}}


def edl(
    depth: Any,
    rgba: Any,
    strength: float = EDL_STRENGTH,
    radius: int = EDL_RADIUS,
    *,
    queue: cl.CommandQueue | None = None,
) -> np.ndarray | cla.Array:
    """The H x W x 4 uint8 image `rgba` shaded by eye-dome lighting over the
    H x W float32 `depth` (the view depth of each pixel's point, +inf where
    empty, as :class:`clvis.raster.GBuffers` holds them).

    strength: >= 0 (0 leaves the image as it is; Potree's default 1).
    radius: the neighbours' distance in pixels, 1..64; with N x N points use
    about N.
    """
    queue = resolve_queue(queue, depth=depth, rgba=rgba)
    host = not (is_device(depth) or is_device(rgba))
    depth = check_array("depth", depth, dtypes=[np.float32], ndim=2)
    rgba = check_array("rgba", rgba, dtypes=[np.uint8], ndim=3)
    if rgba.shape[2] != 4:
        raise ValueError(f"rgba: expected 4 channels (RGBA), got shape {tuple(rgba.shape)}")
    if tuple(depth.shape) != tuple(rgba.shape[:2]):
        raise ValueError(f"depth: shape {tuple(depth.shape)} differs from rgba's {tuple(rgba.shape[:2])}")
    if isinstance(strength, bool) or not isinstance(strength, numbers.Real):
        raise TypeError(f"strength: expected a number, got {type(strength).__name__}")
    if not (math.isfinite(float(strength)) and 0 <= float(strength) <= MAX_EDL_STRENGTH):
        raise ValueError(f"strength: expected a finite number in 0..{MAX_EDL_STRENGTH:g}, got {strength!r}")
    if isinstance(radius, bool) or not isinstance(radius, (int, np.integer)):
        raise TypeError(f"radius: expected an int, got {type(radius).__name__}")
    if not 1 <= radius <= MAX_EDL_RADIUS:
        raise ValueError(f"radius: expected 1..{MAX_EDL_RADIUS}, got {radius}")
    h, w = (int(s) for s in depth.shape)
    if h * w >= 2**32:
        raise ValueError(f"depth: shape {tuple(depth.shape)}; at most 2^32 - 1 pixels")
    out = runtime.empty(queue, (h, w, 4), np.uint8, "edl output")
    if h * w:
        dd, rd = to_device(queue, "depth", depth), to_device(queue, "rgba", rgba)
        k = runtime.get_kernel(queue, _SRC, "edl", {})
        wg = PROFILES[runtime.tuning_profile(queue)]["WG"]
        runtime.launch(
            queue,
            k,
            *runtime.items(queue, h * w, wg),
            buf(dd),
            buf(rd),
            buf(out),
            np.uint32(w),
            np.uint32(h),
            np.uint32(radius),
            np.float32(strength),
        )
    return result(out, host)
