"""The classical splat (post family): the baseline the NARVis networks are
measured against (``clvis eval``'s "splat") and narvis-scan's guard runs
beside the network (clvis.post.guard.narvis_scan).

:func:`splat` draws each covered pixel of the raster's G-buffers as a
screen-space Gaussian ellipse. The exact definition is the docstring of
:mod:`clvis.reference.post.splat` (float64, a NumPy scatter); the kernel is
``kernels_cl/post/splat.cl`` (splat_gather: one work-item per 8 output pixels of
a row gathering the (2 radius + 1)^2 sources around each, float8 lanes, from
padded source planes; float32, no atomics),
within float32 rounding of it. The per-pixel ellipse (the coverage filter's
sigma, the 95th-percentile speed, the angle) stays host-side NumPy: O(H W),
a few ms at 512 x 512, and the percentile needs the whole frame.
numpy in: numpy out; device arrays in: read back, a device array out.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime
from .._arrays import buf, check_array, is_device, resolve_queue, result, to_device, to_host
from ..errors import DataError

__all__ = ["MAX_RADIUS", "splat"]

MAX_RADIUS = 32
_SRC = "post/splat.cl"
_WG = 64
_REALS = [np.float32, np.float64]


def _ellipses(
    cov: np.ndarray, vel: np.ndarray | None, stretch: float, radius: int, sigma: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each pixel's ellipse as the reference defines it (float64, host):
    its standard deviations across and along the flow and the direction of
    its long axis, (sigma, along, cos, sin). The parts that need the whole
    frame, so the kernel does not: the coverage box filter and the covered
    pixels' 95th-percentile speed."""
    from scipy.ndimage import uniform_filter

    if sigma is None:  # half the local spacing: the covered share of a 9 x 9 box
        share = uniform_filter(cov.astype(np.float64), 9, mode="constant")
        sigma = 0.5 / np.sqrt(np.maximum(share, 1 / 81))
    sig = np.clip(np.nan_to_num(np.asarray(sigma, np.float64), nan=0.5), 0.5, radius / 2.5)
    if vel is None:
        zero = np.zeros_like(sig)
        return sig, sig, zero + 1.0, zero
    vx, vy = np.asarray(vel[..., 0], np.float64), np.asarray(vel[..., 1], np.float64)
    speed = np.hypot(vx, vy)
    top = float(np.quantile(speed[cov], 0.95)) if cov.any() else 0.0
    rel = np.clip(speed / top, 0, 1) if top > 0 else np.zeros_like(speed)
    ang = np.arctan2(vy, vx)
    return sig, sig * (1 + (stretch - 1) * rel), np.cos(ang), np.sin(ang)


def splat(
    rgb: Any,
    covered: Any,
    vel: Any = None,
    *,
    stretch: float = 4.0,
    opacity: float = 0.5,
    radius: int = 6,
    sigma: Any = None,
    queue: cl.CommandQueue | None = None,
) -> np.ndarray | cla.Array:
    """What a user would do without a network: each covered pixel drawn as a
    screen-space Gaussian ellipse, its standard deviation half the local
    pixel spacing of the points (from the coverage around it; `sigma` (H, W):
    given per pixel instead, e.g. a scan's radius plane GBuffers.radius_px,
    NaN meaning 0.5) across the flow and up to `stretch` (>= 1) times that
    along its screen velocity `vel` (H, W, 2; None: round), clipped to 0.5 ..
    radius / 2.5 pixels, composited order-independently (colour: the
    weighted mean; alpha: 1 - prod(1 - opacity x weight), opacity in 0..1).

    rgb (H, W, 3) float32 or float64, finite at covered pixels (values
    elsewhere are never read); covered (H, W) bool or uint8 (nonzero =
    covered); radius 1..32 (an int). Returns (H, W, 3) float32 premultiplied
    over black; all zeros where nothing is covered.
    """
    queue = resolve_queue(queue, rgb=rgb, covered=covered, vel=vel, sigma=sigma)
    host = not any(is_device(a) for a in (rgb, covered, vel, sigma))
    rgb = to_host(check_array("rgb", rgb, dtypes=_REALS, ndim=3))
    covered = to_host(check_array("covered", covered, dtypes=[np.bool_, np.uint8], ndim=2))
    h, w = (int(s) for s in covered.shape)
    if tuple(rgb.shape) != (h, w, 3):
        raise ValueError(f"rgb: shape {tuple(rgb.shape)}; expected {(h, w, 3)} (covered's {(h, w)} x 3)")
    if vel is not None:
        vel = to_host(check_array("vel", vel, dtypes=_REALS, ndim=3))
        if tuple(vel.shape) != (h, w, 2):
            raise ValueError(f"vel: shape {tuple(vel.shape)}; expected {(h, w, 2)}")
    if sigma is not None:
        sigma = to_host(check_array("sigma", sigma, dtypes=_REALS, ndim=2))
        if tuple(sigma.shape) != (h, w):
            raise ValueError(f"sigma: shape {tuple(sigma.shape)} differs from covered's {(h, w)}")
    if isinstance(radius, bool) or not isinstance(radius, (int, np.integer)):
        raise TypeError(f"radius: expected an int, got {type(radius).__name__}")
    if not 1 <= radius <= MAX_RADIUS:
        raise ValueError(f"radius: expected 1..{MAX_RADIUS} pixels, got {radius}")
    stretch, opacity = float(stretch), float(opacity)
    if not (np.isfinite(stretch) and stretch >= 1):
        raise ValueError(f"stretch: expected a finite value >= 1, got {stretch}")
    if not 0 <= opacity <= 1:
        raise ValueError(f"opacity: expected 0..1, got {opacity}")
    if h == 0 or w == 0:
        raise DataError(f"covered: empty ({h} x {w} pixels); the splat needs at least one pixel")
    if h * w >= 2**32:
        raise DataError(f"covered: {h} x {w} pixels; at most 2^32 - 1")
    cov = covered != 0
    if not np.isfinite(rgb[cov]).all():
        raise DataError("rgb: NaN or infinite values at covered pixels; the colours splatted must be finite")
    if vel is not None and not np.isfinite(vel[cov]).all():
        raise DataError("vel: NaN or infinite values at covered pixels; velocities must be finite")

    sig, along, ca, sa = _ellipses(cov, vel, stretch, int(radius), sigma)
    r = int(radius)
    pw, ph = w + 2 * r + 8, h + 2 * r
    src = np.zeros((8, ph, pw), np.float32)  # the kernel's 8 padded source planes
    for k, plane in enumerate((ca, sa, 1 / along, 1 / sig, cov, *np.moveaxis(rgb, -1, 0))):
        src[k, r : r + h, r : r + w] = np.where(cov, plane, 0)
    out = runtime.empty(queue, (h, w, 3), np.float32, "splat output")
    dsrc = to_device(queue, "splat sources", src)
    kern = runtime.get_kernel(queue, _SRC, "splat_gather", {"R": r})
    runtime.launch(
        queue,
        kern,
        *runtime.items(queue, h * -(-w // 8), _WG),
        buf(dsrc),
        np.uint32(pw),
        np.uint32(ph),
        np.uint32(w),
        np.uint32(h),
        np.float32(opacity),
        buf(out),
    )
    return result(out, host)
