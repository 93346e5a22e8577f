"""NumPy reference of NARVis's sub-pixel rule (kernels_cl/post/subpixel.cl,
clvis.post.subpixel): where the Gaussians the network stands in for are
well under a pixel across, the Gaussian renderer's image is the point
raster's (each Gaussian paints the pixel its point falls in and next to
nothing beside it), and the network's output is blended toward the input's
colours.

Inputs:

- ``planes``: the network's packed input (1, C, Hp, Wp) float32; channels
  0..2 are R, G, B (0 where nothing was drawn), channel 3 the coverage and
  channel ``radius_channel`` the radius plane (GR's sigma in pixels,
  GBuffers.radius_px; 0 where nothing was drawn).
- ``image``: the network's output (1, 3, Hp, Wp) float32.

Definitions (per pixel (y, x)), with m = ``reach``:

- over the window |dy| <= m, |dx| <= m (clipped at the image's edges):
  S = sum of radius * coverage, N = sum of coverage;
- the local sigma R = S / N; where N = 0 the weight is 0;
- w = clamp((hi - R) / (hi - lo), 0, 1): 1 at or below ``lo`` pixels, 0
  at or above ``hi``;
- out_c = w * planes_c + (1 - w) * image_c for c = R, G, B.

Returns (1, 3, Hp, Wp) float32 (sums in float64, so within float32
rounding of the kernel's).
"""

from __future__ import annotations

import numpy as np

__all__ = ["subpixel_blend", "subpixel_weight"]


def _box(a: np.ndarray, m: int) -> np.ndarray:
    """Sums of a (H, W) over the (2m+1)^2 window around every pixel, clipped."""
    h, w = a.shape
    c = np.zeros((h + 1, w + 1))
    c[1:, 1:] = np.cumsum(np.cumsum(a, axis=0), axis=1)
    y0 = np.clip(np.arange(h) - m, 0, h)
    y1 = np.clip(np.arange(h) + m + 1, 0, h)
    x0 = np.clip(np.arange(w) - m, 0, w)
    x1 = np.clip(np.arange(w) + m + 1, 0, w)
    return c[y1][:, x1] - c[y0][:, x1] - c[y1][:, x0] + c[y0][:, x0]


def subpixel_weight(planes: np.ndarray, radius_channel: int, lo: float, hi: float, reach: int) -> np.ndarray:
    """(Hp, Wp) float64: the weight w of the input's colours (see above)."""
    p = np.asarray(planes, np.float64)[0]
    cov, rad = p[3], p[radius_channel]
    s, n = _box(rad * cov, reach), _box(cov, reach)
    r = s / np.where(n > 0, n, 1.0)
    return np.where(n > 0, np.clip((hi - r) / (hi - lo), 0.0, 1.0), 0.0)


def subpixel_blend(
    planes: np.ndarray, image: np.ndarray, radius_channel: int, lo: float, hi: float, reach: int
) -> np.ndarray:
    """(1, 3, Hp, Wp) float32: the network's `image` blended toward the
    input's colours by subpixel_weight."""
    w = subpixel_weight(planes, radius_channel, lo, hi, reach)
    p = np.asarray(planes, np.float64)[0, :3]
    out = w * p + (1 - w) * np.asarray(image, np.float64)[0]
    return out[None].astype(np.float32)
