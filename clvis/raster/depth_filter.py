"""Hierarchical depth filter of a one-pixel-per-point image (raster family).

A point cloud rasterized with one pixel per point shows background points
through the holes between foreground points. :func:`depth_filter_mask` finds
them with the min-pooled depth pyramid of Vanherck, Zoomers et al., "Real-time
Neural Rendering of LiDAR Point Clouds" (Eurographics 2025 short papers), and
:func:`rgbda` assembles the filtered RGBDA image their network takes;
:func:`filter_gbuffers` empties the removed points in every plane of a
G-buffer set (the input of the NARVis scan network, clvis.post.specs).

The exact definition (and which parts follow the paper) is the docstring of
:mod:`clvis.reference.raster.depth_filter`; the kernels are
``kernels_cl/raster/depth_filter.cl`` and give identical masks on every device.
Each function takes numpy arrays (returns numpy) or ``pyopencl.array.Array``
(returns device arrays on the same queue, no host round trip beyond the
8-byte read of the input check).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import typing
from collections.abc import Sequence
from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime
from .._arrays import buf, check_array, is_device, resolve_queue, result, to_device, to_host
from ..errors import DataError
from ..images import Picture, rgba8
from .render import EMPTY, GBuffers

__all__ = [
    "EDGE_THRESHOLD",
    "FILTER_STRENGTH",
    "LEVELS",
    "MAX_LEVELS",
    "FilteredImage",
    "depth_filter",
    "depth_filter_mask",
    "filter_gbuffers",
    "level_shapes",
    "rgbda",
]

LEVELS = 4  # pyramid levels (the paper's implementation: 4)
FILTER_STRENGTH = 1.025  # tolerance factor (the paper's implementation: 1.025)
EDGE_THRESHOLD = 0.01  # relative Laplacian threshold (clvis's choice)
MAX_LEVELS = 16

_SRC = "raster/depth_filter.cl"

# -D work shapes per tuning profile (runtime.tuning_profile): pixels per
# work-item (ITEMS) and a fixed work-group size (PoCL compiles a work-group
# function per local size, so a driver-chosen one would mean a compile per
# image size). Both give the same results; tests run both on every device.
PROFILES = {
    "cpu": {"ITEMS": 16, "WG": 16},
    "gpu": {"ITEMS": 1, "WG": 256},
}

_MAX_SIDE = 2**32 - 1


def level_shapes(shape: Sequence[int], levels: int) -> list[tuple[int, int]]:
    """[(H0, W0), ... (HL, WL)]: each level ceil(H/2) x ceil(W/2) of the one before."""
    h, w = (int(s) for s in shape)
    out = [(h, w)]
    for _ in range(levels):
        h, w = -(-h // 2), -(-w // 2)
        out.append((h, w))
    return out


def _launcher(queue):
    prof = PROFILES[runtime.tuning_profile(queue)]
    items, wg = prof["ITEMS"], prof["WG"]
    defines = {"ITEMS": items}

    def launch(name, pixels, *args):
        k = runtime.get_kernel(queue, _SRC, name, defines)
        runtime.launch(queue, k, *runtime.items(queue, -(-pixels // items), wg), *args)

    return launch


def _real(name, value, low, what):
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name}: expected a number, got {type(value).__name__}")
    f = float(value)
    if not (math.isfinite(f) and low <= f <= float(np.finfo(np.float32).max)):
        raise ValueError(f"{name}: expected {what}, got {value!r}")
    return np.float32(f)


def depth_filter_mask(
    depth: Any,
    levels: int = LEVELS,
    filter_strength: float = FILTER_STRENGTH,
    *,
    edge_threshold: float = EDGE_THRESHOLD,
    queue: cl.CommandQueue | None = None,
) -> np.ndarray | cla.Array:
    """Which pixels of a one-pixel-per-point depth image to keep.

    depth: H x W float32, +inf where no point landed; every other value must
    be finite and >= 0 (depth = clip w, positive in front of the camera):
    NaN or a negative value (-inf included) raises DataError after the
    filter ran (for device input that costs one 8-byte read).
    levels: pyramid levels, 0..16 (0 keeps every pixel holding a point).
    filter_strength: >= 1; a pixel farther than filter_strength times the
    foreground depth around it is background. Larger removes fewer points.
    edge_threshold: >= 0; relative Laplacian above which a coarse pixel counts
    as the near side of a depth edge (its children are then compared with the
    farthest of its 3 x 3 neighbours). Larger removes more points beside
    silhouettes.

    Returns the H x W mask: a numpy bool array for numpy input, a uint8 device
    array (1 = the pixel holds a point and keeps it) for device input.
    """
    queue = resolve_queue(queue, depth=depth)
    host = not is_device(depth)
    depth = check_array("depth", depth, dtypes=[np.float32], ndim=2)
    if isinstance(levels, bool) or not isinstance(levels, (int, np.integer)):
        raise TypeError(f"levels: expected an int, got {type(levels).__name__}")
    if not 0 <= levels <= MAX_LEVELS:
        raise ValueError(f"levels: expected 0..{MAX_LEVELS}, got {levels}")
    levels = int(levels)
    strength = _real("filter_strength", filter_strength, 1.0, "a finite number >= 1")
    tau = _real("edge_threshold", edge_threshold, 0.0, "a finite number >= 0")
    h, w = (int(s) for s in depth.shape)
    if max(h, w) > _MAX_SIDE:
        raise ValueError(f"depth: shape {depth.shape}; each side must be below 2^32")

    if h * w == 0:
        return (
            np.zeros((h, w), np.bool_)
            if host
            else runtime.empty(queue, (h, w), np.uint8, "depth_filter keep mask")
        )
    keep = runtime.empty(queue, (h, w), np.uint8, "depth_filter keep mask")
    dd = to_device(queue, "depth", depth)
    launch = _launcher(queue)
    shapes = level_shapes((h, w), levels)
    offsets = [0, 0]  # offsets[k]: level k in pyr (k >= 1)
    for hk, wk in shapes[1:]:
        offsets.append(offsets[-1] + hk * wk)
    bad = runtime.zeros(queue, 2, np.uint32, "depth_filter input check")
    u32, u64 = np.uint32, np.uint64

    if levels:
        pyr = runtime.empty(queue, offsets[levels + 1], np.float32, "depth_filter pyramid")
        for k in range(1, levels + 1):
            (sh, sw), (ch, cw) = shapes[k - 1], shapes[k]
            src, src_off = (dd, 0) if k == 1 else (pyr, offsets[k - 1])
            launch(
                "depth_minpool",
                ch * cw,
                buf(src),
                u64(src_off),
                u32(sw),
                u32(sh),
                buf(pyr),
                u64(offsets[k]),
                u32(cw),
                u32(ch),
            )
        for k in range(levels, 1, -1):
            (fh, fw), (ch, cw) = shapes[k - 1], shapes[k]
            launch(
                "depth_refine",
                fh * fw,
                buf(pyr),
                u64(offsets[k - 1]),
                u32(fw),
                u32(fh),
                u64(offsets[k]),
                u32(cw),
                u32(ch),
                strength,
                tau,
            )
        ch, cw = shapes[1]
        launch(
            "depth_keep",
            h * w,
            buf(dd),
            u32(w),
            u32(h),
            buf(pyr),
            u64(0),
            u32(cw),
            u32(ch),
            u32(1),
            strength,
            tau,
            buf(keep),
            buf(bad),
        )
    else:
        launch(
            "depth_keep",
            h * w,
            buf(dd),
            u32(w),
            u32(h),
            buf(dd),
            u64(0),
            u32(0),
            u32(0),
            u32(0),
            strength,
            tau,
            buf(keep),
            buf(bad),
        )

    nan, negative = (int(c) for c in bad.get())
    if nan or negative:
        raise DataError(
            f"depth: {nan} NaN and {negative} negative values; a depth is a "
            "finite value >= 0, or +inf where there is no point"
        )
    return keep.get().view(np.bool_) if host else keep


def rgbda(
    rgba: Any, depth: Any, keep: Any, *, queue: cl.CommandQueue | None = None
) -> np.ndarray | cla.Array:
    """The filtered RGBDA image: H x W x 5 float32 [r, g, b, depth, alpha].

    rgba: H x W x C uint8 (C = 3 or 4; the first three channels are used);
    depth: H x W float32; keep: H x W bool or uint8 (nonzero = kept), e.g.
    from :func:`depth_filter_mask`. Where keep: each colour byte times the
    float32 nearest 1/255 (255 gives exactly 1.0), the depth, alpha 1.0;
    elsewhere 0, 0, 0, +inf, 0.

    numpy in: numpy out. If any input is a device array, a device array out.
    """
    queue = resolve_queue(queue, rgba=rgba, depth=depth, keep=keep)
    host = not (is_device(rgba) or is_device(depth) or is_device(keep))
    rgba = check_array("rgba", rgba, dtypes=[np.uint8], ndim=3)
    depth = check_array("depth", depth, dtypes=[np.float32], ndim=2)
    keep = check_array("keep", keep, dtypes=[np.bool_, np.uint8], ndim=2)
    if rgba.shape[2] not in (3, 4):
        raise ValueError(f"rgba: expected 3 or 4 channels, got shape {tuple(rgba.shape)}")
    if tuple(depth.shape) != tuple(rgba.shape[:2]):
        raise ValueError(f"depth: shape {tuple(depth.shape)} differs from rgba's {tuple(rgba.shape[:2])}")
    if tuple(keep.shape) != tuple(rgba.shape[:2]):
        raise ValueError(f"keep: shape {tuple(keep.shape)} differs from rgba's {tuple(rgba.shape[:2])}")
    h, w, c = (int(s) for s in rgba.shape)
    out = runtime.empty(queue, (h, w, 5), np.float32, "rgbda output")
    n = h * w
    if n:
        rd, dd, kd = (to_device(queue, nm, x) for nm, x in (("rgba", rgba), ("depth", depth), ("keep", keep)))
        if kd.dtype == np.bool_:
            kd = kd.view(np.uint8)
        _launcher(queue)("depth_rgbda", n, buf(rd), np.uint32(c), buf(dd), buf(kd), np.uint64(n), buf(out))
    return result(out, host)


@dataclasses.dataclass(repr=False)
class FilteredImage(Picture):
    """What :func:`depth_filter` keeps. keep: bool [H, W] (a point is there and
    kept); depth: float32, +inf where removed or empty; rgba: uint8 [H, W, 4]
    with alpha 0 where removed (None for a depth-only input); rgbda: float32
    [H, W, 5] = (r, g, b in [0, 1], depth, alpha in {0, 1}), the input of the
    LiDAR paper's network. numpy arrays for numpy input; for device input
    (``host=False`` G-buffers, a device depth image) ``pyopencl.array.Array``
    of the same shapes and dtypes, on the input's queue.
    ``to_uint8(background=None)`` and ``save_png(path)``: the kept points as a
    picture (their colours; the kept depth in grey for a depth-only input), as
    for every image type (:class:`clvis.images.Picture`). index: the
    G-buffers' uint32 [H, W] point index as given (which point each pixel
    shows, 0xFFFFFFFF none; read where ``keep``), None for a depth-only input:
    the LiDAR guard withholds whole points by it."""

    keep: np.ndarray | cla.Array
    depth: np.ndarray | cla.Array
    rgba: np.ndarray | cla.Array | None
    rgbda: np.ndarray | cla.Array
    index: np.ndarray | cla.Array | None = None

    def to_uint8(self, background: Sequence[int] | None = None) -> np.ndarray:
        """(H, W, 4) uint8 RGBA of what is kept, transparent elsewhere, or over
        the RGB `background` (0..255 each)."""
        from ..images import depth_image

        rgba = to_host(self.rgba) if self.rgba is not None else depth_image(to_host(self.depth))
        return rgba8(rgba, background)


def depth_filter(
    gbuffers_or_depth: GBuffers | Any,
    levels: int = LEVELS,
    filter_strength: float = FILTER_STRENGTH,
    *,
    edge_threshold: float = EDGE_THRESHOLD,
    queue: cl.CommandQueue | None = None,
) -> FilteredImage:
    """Remove background points seen through holes in the foreground (the
    hierarchical min-pool filter of Vanherck, Zoomers et al. 2025; the rules
    are in ``clvis.reference.raster.depth_filter``). gbuffers_or_depth: a
    :class:`GBuffers` or an [H, W] float32 depth image (+inf = empty).

    numpy in, numpy out: the planes cross to the device once, the mask and
    the RGBDA image come back and the kept planes are a select on the host.
    Device planes in (``render(..., host=False)``), device planes out: all
    four are made where the planes are (the depth_kept kernel for the kept
    depth and colour), nothing read back but the 8-byte input check."""
    if isinstance(gbuffers_or_depth, GBuffers):
        depth, rgba = gbuffers_or_depth.depth, gbuffers_or_depth.rgba
        index = gbuffers_or_depth.index
    else:
        depth, rgba, index = gbuffers_or_depth, None, None
    queue = resolve_queue(queue, depth=depth, rgba=rgba)
    host = not (is_device(depth) or is_device(rgba))
    depth = check_array("depth", depth, dtypes=[np.float32], ndim=2)
    h, w = (int(s) for s in depth.shape)
    if rgba is not None:
        rgba = check_array("rgba", rgba, dtypes=[np.uint8], ndim=3)
        if tuple(rgba.shape[:2]) != (h, w) or rgba.shape[2] not in (3, 4):
            raise ValueError(f"rgba: expected shape {(h, w)} x 3 or 4 channels, got {tuple(rgba.shape)}")
    dd = to_device(queue, "depth", depth)
    # device in, device out: the uint8 mask and the rgbda stay where they are
    keep = typing.cast(
        cla.Array,
        depth_filter_mask(dd, levels, filter_strength, edge_threshold=edge_threshold, queue=queue),
    )
    rd = None if rgba is None else to_device(queue, "rgba", rgba)
    colors = rd if rd is not None else runtime.zeros(queue, (h, w, 4), np.uint8, "depth_filter colours")
    out_rgbda = typing.cast(cla.Array, rgbda(colors, dd, keep, queue=queue))
    if host:
        kept = keep.get().view(np.bool_)
        return FilteredImage(
            keep=kept,
            depth=np.where(kept, depth, np.float32(np.inf)).astype(np.float32),
            rgba=None if rgba is None else np.where(kept[..., None], rgba, 0).astype(np.uint8),
            rgbda=out_rgbda.get(),
            index=index,
        )
    kept_depth = runtime.empty(queue, (h, w), np.float32, "depth_filter kept depth")
    kept_rgba = None if rd is None else runtime.empty(queue, rd.shape, np.uint8, "depth_filter kept rgba")
    n = h * w
    if n:
        _launcher(queue)(
            "depth_kept",
            n,
            buf(dd),
            buf(keep),
            np.uint64(n),
            buf(kept_depth),
            buf(rd if rd is not None else dd),  # no colour: any valid buffer, unread
            np.uint32(0 if rd is None else rd.shape[2]),
            buf(kept_rgba if kept_rgba is not None else kept_depth),
        )
    return FilteredImage(
        keep=keep.view(np.bool_), depth=kept_depth, rgba=kept_rgba, rgbda=out_rgbda, index=index
    )


def filter_gbuffers(
    gbuffers: GBuffers,
    levels: int = LEVELS,
    filter_strength: float = FILTER_STRENGTH,
    *,
    edge_threshold: float = EDGE_THRESHOLD,
    queue: cl.CommandQueue | None = None,
) -> GBuffers:
    """The G-buffers with the points :func:`depth_filter_mask` removes taken
    out of every plane: where a point was drawn but not kept, the index is
    EMPTY, the depth +inf, the rgba (0, 0, 0, 0), float planes (attributes,
    screen velocity, radius) NaN and uint8 attribute planes 0, as the
    renderer leaves a pixel no point reached. Pixels kept are bit for bit
    the input's; ``stats`` is the input's plus ``depth_filter_removed``
    (the pixels emptied). The NARVis scan network's pipeline
    (clvis.post.specs: its ``depth_filter``): far-side points seen through
    the gaps of a sparse near surface leave the frame before it.

    The mask is computed on the device (the depth plane crosses once when
    it is on the host); the planes come back as numpy arrays (device planes,
    ``render(host=False)``, are read back once)."""
    if not isinstance(gbuffers, GBuffers):
        raise TypeError(f"gbuffers: expected GBuffers, got {type(gbuffers).__name__}")

    keep = to_host(
        depth_filter_mask(gbuffers.depth, levels, filter_strength, edge_threshold=edge_threshold, queue=queue)
    ).astype(np.bool_)
    index = np.asarray(to_host(gbuffers.index))
    if index.shape != keep.shape:
        raise ValueError(f"index: shape {index.shape} differs from the depth plane's {keep.shape}")
    removed = (index != EMPTY) & ~keep

    def emptied(plane: Any) -> Any:
        if plane is None:
            return None
        a = np.asarray(to_host(plane))
        if a.shape[:2] != keep.shape:
            raise ValueError(f"plane of shape {a.shape}: expected {keep.shape} first (the depth plane's)")
        m = removed.reshape(removed.shape + (1,) * (a.ndim - 2))
        if a.dtype == np.uint32:
            fill = EMPTY
        elif a.dtype.kind == "f":
            fill = np.inf if plane is gbuffers.depth else np.nan
        else:
            fill = 0
        return np.where(m, a.dtype.type(fill), a)

    return dataclasses.replace(
        gbuffers,
        index=emptied(gbuffers.index),
        depth=emptied(gbuffers.depth),
        rgba=emptied(gbuffers.rgba),
        attributes={k: emptied(v) for k, v in gbuffers.attributes.items()},
        vel2d=emptied(gbuffers.vel2d),
        vel_angle=emptied(gbuffers.vel_angle),
        vel_speed=emptied(gbuffers.vel_speed),
        radius_px=emptied(gbuffers.radius_px),
        stats={**gbuffers.stats, "depth_filter_removed": int(removed.sum())},
    )
