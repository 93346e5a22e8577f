"""Push-pull hole fill (post family): the classical baseline of the in-fill networks.

:func:`pushpull` averages the known pixels of an image down a pyramid (push)
and blends the coarse levels back up into the holes (pull). The exact
definition is the docstring of :mod:`clvis.reference.post.pushpull`; the
kernels are ``kernels_cl/post/pushpull.cl`` (pp_push0, pp_push, pp_pull,
pp_output) and repeat the reference's float32 operations in the same order.
numpy in: numpy out; device arrays in: a device array out on the same queue
(the input check reads back 4 bytes).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime
from .._arrays import buf, check_array, is_device, nonnegative_int, resolve_queue, result, to_device
from ..errors import DataError

__all__ = ["MAX_CHANNELS", "MAX_LEVELS", "MAX_SIDE", "default_levels", "pushpull"]

MAX_CHANNELS = 8
MAX_LEVELS = 16
MAX_SIDE = 2**32 - 1  # sizes are uint kernel arguments

_SRC = "post/pushpull.cl"

# -D work shapes per tuning profile: pixels per work-item (ITEMS) and the
# work-group size (fixed: PoCL compiles a work-group function per local size).
# Both give the same results; the tests run both on every device.
PROFILES = {
    "cpu": {"ITEMS": 16, "WG": 16},
    "gpu": {"ITEMS": 1, "WG": 256},
}


def default_levels(height: int, width: int) -> int:
    """The number of ceil-halvings that take a height x width image to 1 x 1."""
    levels = 0
    while height > 1 or width > 1:
        height, width = -(-height // 2), -(-width // 2)
        levels += 1
    return levels


def pushpull(
    image: Any, valid: Any, *, levels: int | None = None, queue: cl.CommandQueue | None = None
) -> np.ndarray | cla.Array:
    """Fill the holes of `image` from its known pixels by push-pull.

    image: H x W x C float32, C in 1..8; valid: H x W bool or uint8 (nonzero =
    a known pixel). Known values must be finite (DataError otherwise, raised
    after the kernels ran); values at holes are ignored (NaN allowed).
    levels: pyramid levels, 0..16; None halves until 1 x 1. With 0 levels the
    holes become 0.

    Returns H x W x C float32: known pixels keep their value bit for bit,
    holes get the pulled-up pyramid estimate. Where no pixel is known at all
    the result is all zeros (not an error).
    """
    queue = resolve_queue(queue, image=image, valid=valid)
    host = not (is_device(image) or is_device(valid))
    image = check_array("image", image, dtypes=[np.float32], ndim=3)
    valid = check_array("valid", valid, dtypes=[np.bool_, np.uint8], ndim=2)
    h, w, channels = (int(s) for s in image.shape)
    if not 1 <= channels <= MAX_CHANNELS:
        raise ValueError(f"image: expected 1..{MAX_CHANNELS} channels, got shape {tuple(image.shape)}")
    if tuple(valid.shape) != (h, w):
        raise ValueError(f"valid: shape {tuple(valid.shape)} differs from image's {(h, w)}")
    if h == 0 or w == 0:
        raise DataError(f"image: empty ({h} x {w} pixels); push-pull needs at least one pixel")
    if max(h, w) > MAX_SIDE:
        raise DataError(f"image: shape {(h, w)}; each side must be below 2^32")
    if levels is None:
        levels = default_levels(h, w)
    levels = nonnegative_int("levels", levels)
    if levels > MAX_LEVELS:
        raise ValueError(f"levels: expected 0..{MAX_LEVELS}, got {levels}")

    shapes = [(h, w)]
    for _ in range(levels):
        shapes.append((-(-shapes[-1][0] // 2), -(-shapes[-1][1] // 2)))
    offsets = [0, 0]  # offsets[k]: level k's first pixel in the pyramid (k >= 1)
    for hk, wk in shapes[1:]:
        offsets.append(offsets[-1] + hk * wk)
    pixels = offsets[-1]

    out = runtime.empty(queue, (h, w, channels), np.float32, "pushpull output")
    di = to_device(queue, "image", image)
    dv = to_device(queue, "valid", valid)
    if dv.dtype == np.bool_:
        dv = dv.view(np.uint8)
    bad = runtime.zeros(queue, 1, np.uint32, "pushpull input check")
    prof = PROFILES[runtime.tuning_profile(queue)]
    items, wg = prof["ITEMS"], prof["WG"]
    u32, u64, c = np.uint32, np.uint64, np.uint32(channels)

    def launch(name: str, n: int, *args: Any) -> None:
        k = runtime.get_kernel(queue, _SRC, name, {"ITEMS": items}, runtime.EXACT_FP)
        runtime.launch(queue, k, *runtime.items(queue, -(-n // items), wg), *args)

    if levels:
        col = runtime.empty(queue, pixels * channels, np.float32, "pushpull pyramid colours")
        wt = runtime.empty(queue, pixels, np.float32, "pushpull pyramid weights")
        h1, w1 = shapes[1]
        launch("pp_push0", h1 * w1, buf(di), buf(dv), u32(w), u32(h), c, buf(col), buf(wt), u32(w1), u32(h1))
        for k in range(2, levels + 1):
            (sh, sw), (dh, dw) = shapes[k - 1], shapes[k]
            launch(
                "pp_push",
                dh * dw,
                buf(col),
                buf(wt),
                c,
                u64(offsets[k - 1]),
                u32(sw),
                u32(sh),
                u64(offsets[k]),
                u32(dw),
                u32(dh),
            )
        for k in range(levels - 1, 0, -1):
            (fh, fw), (ch, cw) = shapes[k], shapes[k + 1]
            launch(
                "pp_pull",
                fh * fw,
                buf(col),
                buf(wt),
                c,
                u64(offsets[k]),
                u32(fw),
                u32(fh),
                u64(offsets[k + 1]),
                u32(cw),
                u32(ch),
            )
        coarse, (ch, cw), has = col, (h1, w1), 1
    else:
        coarse, (ch, cw), has = di, (0, 0), 0
    launch(
        "pp_output",
        h * w,
        buf(di),
        buf(dv),
        u32(w),
        u32(h),
        c,
        buf(coarse),
        u32(cw),
        u32(ch),
        u32(has),
        buf(out),
        buf(bad),
    )
    nonfinite = int(bad.get()[0])
    if nonfinite:
        raise DataError(
            f"image: {nonfinite} NaN or infinite values at valid pixels; known pixels must be finite"
        )
    return result(out, host)
