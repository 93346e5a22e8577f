"""The classical splat the NARVis networks are measured against (``clvis
eval``'s "splat" baseline) and narvis-scan's guard runs beside the network
(clvis.post.guard.narvis_scan): each covered pixel of the raster's G-buffers
drawn as a screen-space Gaussian ellipse. NumPy (and scipy's uniform filter
for the spacing); no kernel, no torch.
"""

from __future__ import annotations

import numpy as np

__all__ = ["splat"]


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
    premultiplied over black."""
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
    ca, sa = np.cos(ang), np.sin(ang)
    ys, xs = np.nonzero(covered)
    src_sig, src_along = sigma[ys, xs], along[ys, xs]
    src_c, src_s, col = ca[ys, xs], sa[ys, xs], rgb[ys, xs].astype(np.float64)
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
            logt[at] += np.log1p(-opacity * wt)
            acc[at] += wt[:, None] * col[ok]
    alpha = 1 - np.exp(logt)
    mean = acc / np.maximum(wsum, 1e-12)[..., None]
    return (mean * alpha[..., None]).astype(np.float32)
