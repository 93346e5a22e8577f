"""Image-size limits, in one place: what each family accepts and why.

Every limit is a side (width or height, each at least 1) and a pixel count
(width x height), and each comes from what a kernel or a buffer can address:

- :data:`RASTER`: at most 2^15 a side, so pixel coordinates are exact in
  float32 with room for a splat's offsets and addressable as uint, and
  2^31 - 1 pixels: render.cl and resolve.cl index pixels with 32-bit integers.
- :data:`ISO`: no side limit of its own (a side may be as long as the pixel
  count allows: the rays are made per pixel index, not from float
  coordinates), and 2^31 - 1 pixels: traverse.cl, raytrace.cl and pass.cl
  index pixels with 32-bit integers.
- :data:`GAUSS`: no side limit of its own (rays are made per pixel index),
  and 2^32 - 1 pixels: march.cl, tiles.cl and splat.cl index pixels with
  32-bit unsigned integers.
- :data:`POST_PACK`: at most 32768 a padded side and 2^28 padded pixels, so
  a packed network input of up to 5 channels stays below 2^31 elements
  (pack.cl's 32-bit indices).
- :data:`POST_INFER`: at most 8192 a side and 2^25 pixels: the networks'
  activations at that size already take about 2.5 GB (the LiDAR U-Net); a
  larger frame belongs in tiles.
- The command line takes :data:`RASTER`'s rule for every command (one size
  rule; its renderers all accept it, and --post checks POST_INFER's).

:func:`check_image_size` applies one of them with the message every family
gives (TypeError for a non-int, ValueError naming the limit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GAUSS", "ISO", "POST_INFER", "POST_PACK", "RASTER", "ImageLimits", "check_image_size"]


@dataclass(frozen=True)
class ImageLimits:
    """`max_side` per side, `max_pixels` in all; `why`: the reason, as the
    error message gives it."""

    max_side: int
    max_pixels: int
    why: str


RASTER = ImageLimits(1 << 15, 2**31 - 1, "the kernels index pixels with 32-bit integers")
ISO = ImageLimits(2**31 - 1, 2**31 - 1, "the kernels index pixels with 32-bit integers")
GAUSS = ImageLimits(2**32 - 1, 2**32 - 1, "the kernels index pixels with 32-bit unsigned integers")
POST_PACK = ImageLimits(32768, 2**28, "a 5-channel network input stays below 2^31 elements")
POST_INFER = ImageLimits(8192, 2**25, "the networks' activations at that size take about 2.5 GB")


def _power(n: int) -> str:
    """2^k or 2^k - 1 when n is one, else n."""
    for k in range(64):
        if n == 1 << k:
            return f"2^{k}"
        if n == (1 << k) - 1:
            return f"2^{k} - 1"
    return str(n)


def check_image_size(width: object, height: object, limits: ImageLimits) -> tuple[int, int]:
    """(width, height) as ints when they are within `limits`: TypeError for
    anything but an int (bool included), ValueError naming the side or the
    pixel count and the limit."""
    sides = []
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
            raise TypeError(f"{name}: expected an int, got {type(v).__name__}")
        if not 1 <= int(v) <= limits.max_side:
            raise ValueError(f"{name}: {int(v)} is outside [1, {limits.max_side}]")
        sides.append(int(v))
    w, h = sides
    if w * h > limits.max_pixels:
        raise ValueError(
            f"width x height: {w}x{h} = {w * h} pixels; at most {_power(limits.max_pixels)} ({limits.why})"
        )
    return w, h
