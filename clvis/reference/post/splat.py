"""NumPy reference of clvis.post.splat: the classical splat.

The classical splat the NARVis networks are measured against (``clvis
eval``'s "splat" baseline) and narvis-scan's guard runs beside the network
(clvis.post.guard.narvis_scan): each covered pixel of the raster's G-buffers
drawn as a screen-space Gaussian ellipse. float64 throughout (scipy's uniform
filter for the spacing); ``kernels_cl/post/splat.cl`` gathers the same sums
in float32.

Definition
----------
Per pixel p: sigma(p) = 0.5 / sqrt(max(frac(p), 1/81)), frac the mean
coverage of the 9 x 9 window around p (zeros outside the frame), or the
given `sigma` plane; NaN becomes 0.5; then clipped to 0.5 .. radius / 2.5.
With `vel`: speed = |vel|, ref = the 95th percentile (linear, numpy's
default) of the speeds of the covered pixels, rel = clip(speed / ref, 0, 1)
(0 everywhere when ref is 0 or nothing is covered), angle = atan2(vy, vx);
without: rel = 0, angle = 0. along = sigma (1 + (stretch - 1) rel), u = (cos
angle, sin angle).

A target t receives from every covered source s = t - d, d = (dx, dy) in
[-radius, radius]^2 (sources outside the frame do not exist), the weight
w = exp(-0.5 ((d.u_s / along_s)^2 + (d x u_s / sigma_s)^2)) with d.u = dx
cos + dy sin and d x u = -dx sin + dy cos; wsum = sum w, logt = sum
log1p(-opacity w), acc = sum w rgb_s. out(t) = acc / max(wsum, 1e-12) (1 -
exp(logt)): the weighted mean colour, premultiplied by the alpha 1 - prod(1
- opacity w), over black.
"""

from __future__ import annotations

import numpy as np

__all__ = ["params", "splat"]


def params(
    covered: np.ndarray,
    vel: np.ndarray | None,
    *,
    stretch: float,
    radius: int,
    sigma: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(sigma, along, cos, sin), each (H, W) float64: the per-pixel ellipse of
    the definition (the parts that need the whole frame: the coverage filter
    and the speed percentile)."""
    from scipy.ndimage import uniform_filter

    h, w = covered.shape
    if sigma is None:
        cov = covered.astype(np.float64)
        frac = uniform_filter(cov, 9, mode="constant")
        sigma = 0.5 / np.sqrt(np.maximum(frac, 1 / 81))
    sigma = np.clip(np.nan_to_num(np.asarray(sigma, np.float64), nan=0.5), 0.5, radius / 2.5)
    if vel is not None:
        speed = np.hypot(vel[..., 0], vel[..., 1])
        ref = float(np.quantile(speed[covered], 0.95)) if covered.any() else 0.0
        rel = np.clip(speed / ref, 0, 1) if ref > 0 else np.zeros_like(speed)
        ang = np.arctan2(vel[..., 1], vel[..., 0])
    else:
        rel, ang = np.zeros((h, w)), np.zeros((h, w))
    along = sigma * (1 + (stretch - 1) * rel)
    return sigma, along, np.cos(ang), np.sin(ang)


def splat(
    rgb: np.ndarray,
    covered: np.ndarray,
    vel: np.ndarray | None = None,
    *,
    stretch: float = 4.0,
    opacity: float = 0.5,
    radius: int = 6,
    sigma: np.ndarray | None = None,
) -> np.ndarray:
    """What a user would do without a network: each covered pixel drawn as a
    screen-space Gaussian ellipse, its standard deviation half the local
    pixel spacing of the points (from the coverage around it; `sigma` (H, W):
    given per pixel instead, e.g. a scan's radius plane GBuffers.radius_px)
    across the flow and up to `stretch` times that along its screen velocity
    `vel` (H, W, 2; None: round), clipped to 0.5 .. radius / 2.5 pixels,
    composited order-independently (colour: the weighted mean; alpha: 1 -
    prod(1 - opacity x weight)). rgb (H, W, 3) in [0, 1]; returns (H, W, 3)
    premultiplied over black. A scatter over the (2 radius + 1)^2 offsets."""
    covered = np.asarray(covered, bool)
    h, w = covered.shape
    sig, along, ca, sa = params(covered, vel, stretch=stretch, radius=radius, sigma=sigma)
    ys, xs = np.nonzero(covered)
    src_sig, src_along = sig[ys, xs], along[ys, xs]
    src_c, src_s, col = ca[ys, xs], sa[ys, xs], np.asarray(rgb)[ys, xs].astype(np.float64)
    acc = np.zeros((h, w, 3))
    wsum = np.zeros((h, w))
    logt = np.zeros((h, w))
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            ty, tx = ys + dy, xs + dx
            ok = (ty >= 0) & (ty < h) & (tx >= 0) & (tx < w)
            d_al = dx * src_c[ok] + dy * src_s[ok]
            d_ac = -dx * src_s[ok] + dy * src_c[ok]
            wt = np.exp(-0.5 * ((d_al / src_along[ok]) ** 2 + (d_ac / src_sig[ok]) ** 2))
            # one offset sends distinct sources to distinct pixels: plain += adds
            at = (ty[ok], tx[ok])
            wsum[at] += wt
            with np.errstate(divide="ignore"):  # opacity 1 at weight 1: alpha 1
                logt[at] += np.log1p(-opacity * wt)
            acc[at] += wt[:, None] * col[ok]
    alpha = 1 - np.exp(logt)
    mean = acc / np.maximum(wsum, 1e-12)[..., None]
    return (mean * alpha[..., None]).astype(np.float32)
