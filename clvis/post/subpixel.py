"""NARVis's sub-pixel rule on the device (kernels_cl/post/subpixel.cl): the
network's output blended toward the input's colours where the local sigma
of the Gaussians it stands in for (the radius plane, GR's sigma in pixels,
averaged over the covered pixels of a (2m+1)^2 window) is under a pixel.

Why: a Gaussian of sigma s pixels across the flow gives a neighbouring
pixel exp(-1 / (2 s^2)) of its peak: 3e-4 at s = 0.25, a third at s = 0.7.
Below a quarter pixel the Gaussian renderer paints the pixels the points
fall in and nothing beside them, which is the point raster; the network
was trained almost entirely on sigmas above half a pixel (the hurricane at
512 x 512: 0.6-3.6; the training flows: 0.9-7.5, one attractor view at
0.3) and widens thin trajectories there (issue 21: the Lorenz attractor's
hemisphere view, sigma 0.29 px, network 20.5 dB against the raster's 24.1).
The weight ramps from 1 at ``lo`` to 0 at ``hi`` pixels. The window's half
side m = 16 covers the head's reach (15 pixels: the 3 x 3 blocks of its
coarsest scale, 8 pixels), so a pixel whose window covers nothing is one
the network paints black anyway. lo, hi and m were chosen on frames of the
training families only (bench/results/README.md, issue 21 narvis21g); they
are NarvisSpec.subpixel.

The volume score (issue 21 narvis21h, NarvisSpec.subpixel_volume): sigma
alone does not tell a thin curve or sheet of points from a volume of many
points a pixel, where GR blends several Gaussians along each ray and the
raster shows the front one (the network's smoothing is right there: the
held-out hurricane at 4x lost 0.06 SSIM under the sigma rule). Where the
window is densely covered and its colours jump between neighbours at one
depth (a volume's front points are scattered; a curve's colour changes
smoothly along it), the blend is held back. Definitions:
clvis.reference.post.subpixel.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime
from .._arrays import buf, buffer_of, check_array, is_device, resolve_queue, result, to_device
from ..errors import DataError

__all__ = ["subpixel_blend"]

_SRC = "post/subpixel.cl"
_WG = 64
#: the largest window half side a caller may ask for
MAX_REACH = 64


def subpixel_blend(
    planes: Any,
    image: Any,
    *,
    radius_channel: int,
    lo: float,
    hi: float,
    reach: int = 8,
    depth_channel: int | None = None,
    volume: Sequence[float] | None = None,
    out: cla.Array | None = None,
    queue: cl.CommandQueue | None = None,
) -> np.ndarray | cla.Array:
    """(1, 3, Hp, Wp) float32: `image` (the network's output (1, 3, Hp, Wp))
    blended toward `planes`' colours (the network's input (1, C, Hp, Wp):
    R, G, B, coverage, ..., the radius plane at `radius_channel`, the depth
    plane at `depth_channel`) with the weight clamp((hi - R) / (hi - lo), 0,
    1), R the mean radius of the covered pixels of the (2 reach + 1)^2
    window (0 where the window covers nothing), times 1 - the window's
    volume score where `volume` = (tau, c_lo, c_hi, f_lo, f_hi) is given
    (clvis.reference.post.subpixel). Numpy or device arrays; `out`: a device
    array to write into (returned; it may be `image` itself); otherwise the
    result is where the inputs were."""
    queue = resolve_queue(queue, planes=planes, image=image, out=out)
    host = not is_device(planes) and not is_device(image)
    planes = check_array("planes", planes, dtypes=[np.float32], ndim=4)
    image = check_array("image", image, dtypes=[np.float32], ndim=4)
    n, c, hp, wp = (int(v) for v in planes.shape)
    if n != 1 or c < 5:
        raise ValueError(f"planes: expected shape (1, C >= 5, H, W), got {tuple(planes.shape)}")
    if hp == 0 or wp == 0:
        raise DataError(f"planes: empty ({hp} x {wp} pixels)")
    if tuple(image.shape) != (1, 3, hp, wp):
        raise ValueError(f"image: expected shape {(1, 3, hp, wp)}, got {tuple(image.shape)}")
    _check_channel("radius_channel", radius_channel, c)
    lo, hi = float(lo), float(hi)
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo < hi):
        raise ValueError(f"lo, hi: expected finite 0 <= lo < hi, got {lo!r}, {hi!r}")
    if isinstance(reach, bool) or not isinstance(reach, (int, np.integer)) or not 0 <= reach <= MAX_REACH:
        raise ValueError(f"reach: expected an int in 0..{MAX_REACH}, got {reach!r}")
    vol = _check_volume(volume, depth_channel, radius_channel, c)
    if out is not None and (
        not is_device(out)
        or out.dtype != np.float32
        or tuple(out.shape) != (1, 3, hp, wp)
        or not out.flags.c_contiguous
        or out.offset
    ):
        raise ValueError(f"out: expected a whole C-contiguous device array of shape {(1, 3, hp, wp)} float32")
    d_planes = to_device(queue, "planes", planes)
    if out is None:
        dst = runtime.empty(queue, (1, 3, hp, wp), np.float32, "subpixel output")
    else:
        dst = out
    if image is not dst:  # a numpy image uploaded, a device one (whole: to_device) copied
        src = to_device(queue, "image", image)
        cl.enqueue_copy(queue, buffer_of(dst), buffer_of(src), byte_count=dst.nbytes)
    terms = runtime.empty(queue, (hp * wp * 4,), np.int64, "subpixel terms")
    sums = runtime.empty(queue, (hp * wp * 4,), np.int64, "subpixel row sums")
    defines = {"REACH": int(reach), "VOLUME": int(vol is not None), "WG": _WG}
    tau, c_lo, c_hi, f_lo, f_hi = vol if vol is not None else (0.0, 0.0, 1.0, 0.0, 1.0)
    u32, f32 = np.uint32, np.float32
    k_terms = runtime.get_kernel(queue, _SRC, "subpixel_terms", defines, runtime.EXACT_FP)
    runtime.launch(
        queue,
        k_terms,
        *runtime.items(queue, hp * wp, _WG),
        buf(d_planes),
        u32(wp),
        u32(hp),
        u32(radius_channel),
        u32(depth_channel if vol is not None and depth_channel is not None else 0),
        f32(tau),
        buf(terms),
    )
    rows = runtime.get_kernel(queue, _SRC, "subpixel_rows", defines, runtime.EXACT_FP)
    runtime.launch(queue, rows, *runtime.items(queue, hp, _WG), buf(terms), u32(wp), u32(hp), buf(sums))
    blend = runtime.get_kernel(queue, _SRC, "subpixel_blend", defines, runtime.EXACT_FP)
    runtime.launch(
        queue,
        blend,
        *runtime.items(queue, wp, _WG),
        buf(d_planes),
        buf(sums),
        u32(wp),
        u32(hp),
        f32(lo),
        f32(hi),
        f32(c_lo),
        f32(c_hi),
        f32(f_lo),
        f32(f_hi),
        buf(dst),
    )
    return dst if out is not None else result(dst, host)


def _check_channel(name: str, ch: Any, c: int) -> None:
    if isinstance(ch, bool) or not isinstance(ch, (int, np.integer)):
        raise TypeError(f"{name}: expected an int, got {ch!r}")
    if not 4 <= int(ch) < c:
        raise ValueError(f"{name}: expected 4..{c - 1} (a plane after R, G, B, coverage), got {ch}")


def _check_volume(
    volume: Sequence[float] | None, depth_channel: int | None, radius_channel: int, c: int
) -> tuple[float, float, float, float, float] | None:
    """The volume score's (tau, c_lo, c_hi, f_lo, f_hi) as floats, checked
    (and the depth channel with it); None where it is not asked for."""
    if volume is None:
        return None
    if depth_channel is None:
        raise ValueError("depth_channel: the volume score reads the depth plane; give its channel")
    _check_channel("depth_channel", depth_channel, c)
    if int(depth_channel) == int(radius_channel):
        raise ValueError(f"depth_channel: the radius plane's channel ({radius_channel}), expected another")
    try:
        vals = tuple(float(v) for v in volume)
    except (TypeError, ValueError):
        raise ValueError(f"volume: expected (tau, c_lo, c_hi, f_lo, f_hi), got {volume!r}") from None
    if len(vals) != 5 or not all(np.isfinite(vals)):
        raise ValueError(f"volume: expected 5 finite numbers (tau, c_lo, c_hi, f_lo, f_hi), got {volume!r}")
    tau, c_lo, c_hi, f_lo, f_hi = vals
    if not (tau >= 0 and 0 <= c_lo < c_hi and 0 <= f_lo < f_hi):
        raise ValueError(f"volume: expected tau >= 0, 0 <= c_lo < c_hi, 0 <= f_lo < f_hi, got {volume!r}")
    return tau, c_lo, c_hi, f_lo, f_hi
