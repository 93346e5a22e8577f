"""iso family, internal: the block-raytracing launch (kernels_cl/iso/raytrace.cl).

The progressive pass loop calls :func:`raytrace_blocks` once per pass with the
rays grouped by the block they wait at; it is not public API. Everything
stays on the device: the arguments are ``pyopencl.array.Array`` objects (or
raw ``cl.Buffer`` for the cache), nothing is read back.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime

__all__ = ["PROFILES", "raytrace_blocks", "raytrace_kernel"]

_SRC = "iso/raytrace.cl"
# work-items per block group, per tuning profile (any size works; see the ABI)
# and rays a work-item traces at once in float8 lanes (PACKET: 0, one ray, or 8)
PROFILES = {"cpu": {"wg": 2, "packet": 8}, "gpu": {"wg": 64, "packet": 0}}
_arg = runtime.arg


def raytrace_kernel(queue: cl.CommandQueue, refine_steps: int, items: bool) -> cl.Kernel:
    """The raytrace_blocks kernel for the queue's tuning profile (its PACKET)."""
    packet = PROFILES[runtime.tuning_profile(queue)]["packet"]
    defines = {"REFINE_STEPS": int(refine_steps), "ITEMS": int(items), "PACKET": packet}
    return runtime.get_kernel(queue, _SRC, "raytrace_blocks", defines, runtime.EXACT_FP)


def raytrace_blocks(
    queue: cl.CommandQueue,
    bricks: cla.Array,
    slot_of_block: cla.Array,
    shape: Sequence[int],
    spacing: Sequence[float],
    origin: Sequence[float],
    isovalue: float,
    cam: cla.Array,
    width: int,
    groups: tuple[cla.Array, cla.Array, cla.Array],
    ray_ids: cla.Array,
    ray_t: cla.Array,
    outputs: tuple[cla.Array, cla.Array, cla.Array, cla.Array],
    *,
    refine_steps: int = 8,
    items: tuple[cla.Array, int, cla.Array | None] | None = None,
    first_pixel: int = 0,
    wait_for: Sequence[cl.Event] | None = None,
) -> cl.Event | None:
    """Launch ``raytrace_blocks`` (internal; see kernels_cl/iso/raytrace.cl's ABI).

    bricks (slots, 64) float32 and slot_of_block (nblocks,) int32: the block
    cache; shape (nz, ny, nx), spacing (dz, dy, dx), origin (x, y, z) of the
    volume; cam the 22-float ray buffer (device array); width the image width;
    groups = (group_blocks, group_offsets, group_counts), three uint32 device
    arrays of one length (the number of work-groups; 0 launches nothing);
    ray_ids uint32 pixel indices; ray_t float32 per pixel (in/out);
    outputs = (ray_hit uint8, hit_t float32, rgba float32 (.., 4), depth
    float32), per pixel, written at hits only. Returns the event (or None).

    items = (item_pixel uint32, n_spec, hitkey uint64 or None): the
    speculation mode (-D ITEMS=1): ray_ids are item ids, ray_t and the
    outputs are per item, and hitkey (per pixel) receives the 64-bit atomic
    min of (t bits << 32 | item) where the device has 64-bit atomics.

    first_pixel: the tile's first image pixel; pixel ids and per-pixel arrays
    are then the tile's (kernels_cl/iso/traverse.cl, Tiles)."""
    group_blocks, group_offsets, group_counts = groups
    ngroups = int(group_blocks.size)
    if ngroups == 0:
        return None
    nz, ny, nx = (int(s) for s in shape)
    dz, dy, dx = (np.float32(s) for s in spacing)
    ox, oy, oz = (np.float32(s) for s in origin)
    ray_hit, hit_t, rgba, depth = outputs
    wg = runtime.local_size(queue, PROFILES[runtime.tuning_profile(queue)]["wg"])
    k = raytrace_kernel(queue, refine_steps, items is not None)
    item_pixel, n_spec, hitkey = items if items is not None else (None, 1, None)
    return runtime.launch(
        queue,
        k,
        ngroups * wg,
        wg,
        _arg(bricks),
        _arg(slot_of_block),
        np.uint32(nx),
        np.uint32(ny),
        np.uint32(nz),
        dx,
        dy,
        dz,
        ox,
        oy,
        oz,
        np.float32(isovalue),
        _arg(cam),
        np.uint32(width),
        np.uint32(first_pixel),
        _arg(group_blocks),
        _arg(group_offsets),
        _arg(group_counts),
        _arg(ray_ids),
        _arg(ray_t),
        _arg(ray_hit),
        _arg(hit_t),
        _arg(rgba),
        _arg(depth),
        _arg(item_pixel),
        np.uint32(n_spec),
        _arg(hitkey),
        wait_for=wait_for,
    )
