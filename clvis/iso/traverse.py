"""iso family, internal: macrocell traversal with speculation
(kernels_cl/iso/traverse.cl; reference clvis/reference/iso/traverse.py).

The progressive pass loop calls :func:`init_rays` once per frame and
:func:`macro_traverse` once per pass; not public API. Device arrays in, device
arrays out; the only transfer is none (the active-ray count stays on the
device: ``count`` is a 1-element uint32 device array).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime
from ..primitives import compact_indices
from .macrocell import range_bits

__all__ = ["MAX_SPEC", "PROFILES", "init_rays", "macro_traverse", "traverse_kernel"]

_SRC = "iso/traverse.cl"
# work-items per group, per tuning profile (any size works; see the ABI), and
# rays a work-item sets up at once in float8 lanes (PACKET: 0, one ray, or 8)
PROFILES = {"cpu": {"wg": 16, "packet": 8}, "gpu": {"wg": 64, "packet": 0}}
MAX_SPEC = 64
_arg = runtime.arg


def _profile(queue: cl.CommandQueue) -> tuple[int, int, dict[str, int]]:
    """(wg, rays a work-item, kernel defines) of the queue's tuning profile."""
    prof = PROFILES[runtime.tuning_profile(queue)]
    packet = int(prof["packet"])
    return int(prof["wg"]), max(packet, 1), {"PACKET": packet}


def traverse_kernel(queue: cl.CommandQueue, name: str) -> cl.Kernel:
    """The traverse.cl kernel `name` for the queue's tuning profile (its PACKET)."""
    return runtime.get_kernel(queue, _SRC, name, _profile(queue)[2], runtime.EXACT_FP)


def _volume_args(shape, spacing, origin):
    nz, ny, nx = (int(s) for s in shape)
    if min(nx, ny, nz) < 2:
        raise ValueError(f"shape: every axis needs at least 2 samples, got {tuple(shape)}")
    dz, dy, dx = (np.float32(s) for s in spacing)
    ox, oy, oz = (np.float32(s) for s in origin)
    return (np.uint32(nx), np.uint32(ny), np.uint32(nz), dx, dy, dz, ox, oy, oz)


def init_rays(
    queue: cl.CommandQueue,
    cam: cla.Array,
    width: int,
    height: int,
    shape: Sequence[int],
    spacing: Sequence[float],
    origin: Sequence[float],
    *,
    pixels: tuple[int, int] | None = None,
    wait_for: Sequence[cl.Event] | None = None,
) -> tuple[cla.Array, cla.Array, cla.Array]:
    """Per pixel the box entry t (+inf on a miss) and the list of rays that
    meet the volume box. cam: the 22-float ray buffer (device array).
    pixels = (p0, n): only the tile of image pixels p0 .. p0 + n - 1 (default
    the whole image); the arrays then hold the tile's pixels, indexed p - p0.
    Returns (ray_t float32 (n,), active uint32 (n,), count uint32 (1,)),
    device arrays; the first count[0] entries of active are the (tile) pixel
    ids in ascending order (clvis.primitives.compact_indices)."""
    w, h = int(width), int(height)
    if w * h == 0:
        raise ValueError(f"width, height: need at least one pixel, got {w} x {h}")
    p0, npix = (0, w * h) if pixels is None else (int(pixels[0]), int(pixels[1]))
    if not (0 <= p0 and 0 < npix and p0 + npix <= w * h):
        raise ValueError(f"pixels: the tile ({p0}, {npix}) must lie in the {w} x {h} image")
    ray_t = runtime.empty(queue, npix, np.float32, "ray_t")
    enters = runtime.empty(queue, npix, np.uint8, "ray enters flags")
    wg, per_item, _ = _profile(queue)
    k = traverse_kernel(queue, "init_rays")
    runtime.launch(
        queue,
        k,
        *runtime.items(queue, -(-npix // per_item), wg),
        _arg(cam),
        np.uint32(w),
        np.uint32(p0),
        np.uint32(npix),
        *_volume_args(shape, spacing, origin),
        ray_t.base_data,
        enters.base_data,
        wait_for=wait_for,
    )
    count = runtime.empty(queue, 1, np.uint32, "active ray count")
    active, count = compact_indices(enters, count=count, queue=queue)
    return ray_t, active, count


def macro_traverse(
    queue: cl.CommandQueue,
    shape: Sequence[int],
    spacing: Sequence[float],
    origin: Sequence[float],
    isovalue: float,
    cam: cla.Array,
    width: int,
    fine: cla.Array,
    coarse: cla.Array,
    active: cla.Array,
    count: cla.Array,
    max_rays: int,
    ray_t: cla.Array,
    n_spec: int,
    cand_block: cla.Array,
    cand_t: cla.Array,
    *,
    first_pixel: int = 0,
    wait_for: Sequence[cl.Event] | None = None,
) -> cl.Event | None:
    """Launch ``macro_traverse`` (see kernels_cl/iso/traverse.cl's ABI).

    fine, coarse: float32 device arrays (.., 2) (clvis.iso.macrocell_grids,
    host=False), whose clvis.iso.macrocell.range_bits for isovalue are made
    here; or those bits (uint32 device arrays), as the renderer passes them,
    made once a frame; active uint32 pixel ids; count uint32 (1,) how many;
    max_rays an upper bound of count[0] (sizes the launch; <= active.size);
    ray_t float32 per pixel (in/out); cand_block uint32 and cand_t float32
    with room for max_rays * n_spec entries (out); first_pixel: the tile's
    first image pixel (active ids and ray_t are the tile's). Returns the event (None
    when max_rays is 0)."""
    n_spec = int(n_spec)
    if not 1 <= n_spec <= MAX_SPEC:
        raise ValueError(f"n_spec: must be in 1..{MAX_SPEC}, got {n_spec}")
    max_rays = int(max_rays)
    if max_rays == 0:
        return None
    if max_rays > active.size:
        raise ValueError(f"max_rays: {max_rays} exceeds the active list's {active.size} entries")
    if cand_block.size < max_rays * n_spec or cand_t.size < max_rays * n_spec:
        raise ValueError(
            f"cand_block, cand_t: need room for {max_rays * n_spec} entries, "
            f"got {cand_block.size} and {cand_t.size}"
        )
    if fine.dtype != np.uint32:
        fine = range_bits(fine, isovalue, queue=queue)
    if coarse.dtype != np.uint32:
        coarse = range_bits(coarse, isovalue, queue=queue)
    wg, per_item, _ = _profile(queue)
    k = traverse_kernel(queue, "macro_traverse")
    return runtime.launch(
        queue,
        k,
        *runtime.items(queue, -(-max_rays // per_item), wg),
        *_volume_args(shape, spacing, origin),
        np.float32(isovalue),
        _arg(cam),
        np.uint32(width),
        np.uint32(first_pixel),
        _arg(fine),
        _arg(coarse),
        _arg(active),
        _arg(count),
        _arg(ray_t),
        np.uint32(n_spec),
        _arg(cand_block),
        _arg(cand_t),
        wait_for=wait_for,
    )
