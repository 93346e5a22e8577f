"""Morton order of a point cloud (``kernels_cl/raster/morton.cl``): the
permutation along a 30-bit Morton curve (codes, then the primitives' radix
sort), and the gather of the points into that order with the inverse
permutation. :class:`~clvis.raster.Rasterizer` runs its cloud through both
(``morton=True``); NumPy definition: ``clvis.reference.raster.morton``.

The curve spans the points' finite bounding box, read with render.cl's
``batch_bounds`` through :mod:`clvis.raster.render` (which launches that file).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import morton, runtime
from .._arrays import check_array, is_device, resolve_queue
from ..errors import DeviceError
from ..primitives import radix_sort

__all__ = ["PROFILES", "morton_gather", "morton_order"]

# work-items per group of morton.cl's one-item-per-point kernels
PROFILES = {"cpu": {"item_wg": 64}, "gpu": {"item_wg": 256}}


def _items(queue: cl.CommandQueue, n: int) -> tuple[int, int]:
    """(global, local) sizes for one work-item per element of n."""
    return runtime.items(queue, n, PROFILES[runtime.tuning_profile(queue)]["item_wg"])


def morton_order(positions: Any, *, queue: cl.CommandQueue | None = None) -> np.ndarray | cla.Array:
    """The permutation that sorts points along a 30-bit Morton curve over
    their finite bounding box (10 bits per axis; ties keep input order;
    points with a NaN or infinite coordinate last). positions: float32 (N, 3).
    Returns uint32 (N,): numpy for numpy input, a device array for device input."""
    queue = resolve_queue(queue, positions=positions)
    host = not is_device(positions)
    p = check_array("positions", positions, dtypes=[np.float32], ndim=2)
    if p.shape[1] != 3:
        raise ValueError(f"positions: expected shape (N, 3), got {tuple(p.shape)}")
    n = p.shape[0]
    if n >= 0xFFFFFFFF:
        raise DeviceError(f"positions: {n} points; at most 2^32 - 2")
    if host:
        d = runtime.empty(queue, p.shape, np.float32, "positions")
        if n:
            d.set(p, queue=queue)
        p = d
    elif p.offset:
        p = p.copy()
    if n == 0:
        out = runtime.empty(queue, 0, np.uint32, "Morton permutation")
        return out.get() if host else out
    from .render import BATCH_SIZE, _batch_bounds  # render.py imports this module

    bounds = _batch_bounds(queue, p, BATCH_SIZE).get()
    lo, hi = bounds[:, :3].min(axis=0), bounds[:, 3:].max(axis=0)
    if not (lo <= hi).all():  # no finite point: every code is 0xFFFFFFFF
        lo = hi = np.zeros(3, np.float32)
    scale = morton.scale(lo, hi)
    codes = runtime.empty(queue, n, np.uint32, "Morton codes")
    k = runtime.get_kernel(queue, "raster/morton.cl", "morton_codes", {}, ())
    runtime.launch(
        queue,
        k,
        *_items(queue, n),
        p.base_data,
        np.uint32(n),
        *lo.astype(np.float32),
        *scale,
        codes.base_data,
    )
    iota = runtime.empty(queue, n, np.uint32, "Morton permutation")
    k = runtime.get_kernel(queue, "raster/morton.cl", "iota", {}, ())
    runtime.launch(queue, k, *_items(queue, n), np.uint32(n), iota.base_data)
    _, perm = radix_sort(codes, iota)
    return perm.get() if host else perm


def morton_gather(
    queue: cl.CommandQueue, positions: cla.Array, perm: cla.Array
) -> tuple[cla.Array, cla.Array]:
    """(positions[perm], the inverse permutation) on the device, for a
    permutation `perm` of the N points (uint32 (N,), from :func:`morton_order`)."""
    n = int(positions.shape[0])
    out = runtime.empty(queue, (n, 3), np.float32, "Morton-ordered positions")
    inv = runtime.empty(queue, n, np.uint32, "inverse permutation")
    k = runtime.get_kernel(queue, "raster/morton.cl", "gather_points", {})
    runtime.launch(
        queue, k, *_items(queue, n), positions.base_data, perm.base_data, np.uint32(n), out.base_data
    )
    k = runtime.get_kernel(queue, "raster/morton.cl", "invert_permutation", {})
    runtime.launch(queue, k, *_items(queue, n), perm.base_data, np.uint32(n), inv.base_data)
    return out, inv
