"""NumPy reference of NARVis's sub-pixel rule (kernels_cl/post/subpixel.cl,
clvis.post.subpixel): where the Gaussians the network stands in for are
well under a pixel across, the Gaussian renderer's image is the point
raster's (each Gaussian paints the pixel its point falls in and next to
nothing beside it), and the network's output is blended toward the input's
colours; unless the window looks like a volume of points (GR blends several
Gaussians along each ray there, the raster shows the front one), where the
blend is held back.

Inputs:

- ``planes``: the network's packed input (1, C, Hp, Wp) float32; channels
  0..2 are R, G, B (0 where nothing was drawn), channel 3 the coverage,
  channel ``radius_channel`` the radius plane (GR's sigma in pixels,
  GBuffers.radius_px; 0 where nothing was drawn) and channel
  ``depth_channel`` the view depth (0 where nothing was drawn).
- ``image``: the network's output (1, 3, Hp, Wp) float32.

Definitions (per pixel (y, x)), with m = ``reach``:

- the depth-consistent colour noise of a covered pixel p: its neighbours
  n are the covered pixels of its 8-neighbourhood with |z_n - z_p| <= tau
  * z_p (z the depth plane); q_p = the mean over them of sum_c |c_p - c_n|
  (c = R, G, B), v_p = 1; a pixel with no such neighbour (or uncovered)
  has v_p = 0 (q_p = 0). A volume's front points are scattered in depth
  and colour from pixel to pixel while a curve or sheet changes its colour
  smoothly along itself: q is large where several layers of points show;
- over the window |dy| <= m, |dx| <= m (clipped at the image's edges, A
  pixels): S = sum of the radius over the covered pixels (coverage > 0),
  N = their count, Q = sum of q * v, V = sum of v;
- the local sigma R = S / N, the coverage fraction F = N / A, the colour
  noise C = Q / V (0 where V = 0);
- the sigma weight ws = clamp((hi - R) / (hi - lo), 0, 1), 0 where N = 0;
  the volume score u = clamp((C - c_lo) / (c_hi - c_lo), 0, 1) *
  clamp((F - f_lo) / (f_hi - f_lo), 0, 1) (``volume`` = (tau, c_lo, c_hi,
  f_lo, f_hi); None: u = 0, the sigma rule alone);
- w = ws * (1 - u); out_c = w * planes_c + (1 - w) * image_c for c = R,
  G, B.

Returns (1, 3, Hp, Wp) float32 (sums in float64, so within float32
rounding of the kernel's).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["colour_noise", "subpixel_blend", "subpixel_weight"]


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


def _shifted(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """a[y + dy, x + dx], 0 outside."""
    h, w = a.shape
    p = np.pad(a, 1)
    return p[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]


def colour_noise(planes: np.ndarray, depth_channel: int, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """(q, v), each (Hp, Wp) float64: the depth-consistent colour noise of
    every pixel and whether it has one (see above)."""
    p = np.asarray(planes, np.float64)[0]
    cov, z = (p[3] > 0).astype(np.float64), p[depth_channel]
    s = np.zeros_like(cov)
    n = np.zeros_like(cov)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy == 0 and dx == 0:
                continue
            near = cov * _shifted(cov, dy, dx) * (np.abs(z - _shifted(z, dy, dx)) <= tau * z)
            s += near * sum(np.abs(p[c] - _shifted(p[c], dy, dx)) for c in range(3))
            n += near
    v = (n > 0).astype(np.float64)
    return s / np.where(n > 0, n, 1.0), v


def subpixel_weight(
    planes: np.ndarray,
    radius_channel: int,
    lo: float,
    hi: float,
    reach: int,
    depth_channel: int | None = None,
    volume: Sequence[float] | None = None,
) -> np.ndarray:
    """(Hp, Wp) float64: the weight w of the input's colours (see above)."""
    p = np.asarray(planes, np.float64)[0]
    cov, rad = (p[3] > 0).astype(np.float64), p[radius_channel]
    s, n = _box(rad * cov, reach), _box(cov, reach)
    r = s / np.where(n > 0, n, 1.0)
    ws = np.where(n > 0, np.clip((hi - r) / (hi - lo), 0.0, 1.0), 0.0)
    if volume is None:
        return ws
    if depth_channel is None:
        raise ValueError("depth_channel: needed with volume")
    tau, c_lo, c_hi, f_lo, f_hi = (float(v) for v in volume)
    q, v = colour_noise(planes, depth_channel, tau)
    qs, vs = _box(q * v, reach), _box(v, reach)
    c = np.where(vs > 0, qs / np.where(vs > 0, vs, 1.0), 0.0)
    f = n / _box(np.ones_like(cov), reach)
    u = np.clip((c - c_lo) / (c_hi - c_lo), 0.0, 1.0) * np.clip((f - f_lo) / (f_hi - f_lo), 0.0, 1.0)
    return ws * (1.0 - u)


def subpixel_blend(
    planes: np.ndarray,
    image: np.ndarray,
    radius_channel: int,
    lo: float,
    hi: float,
    reach: int,
    depth_channel: int | None = None,
    volume: Sequence[float] | None = None,
) -> np.ndarray:
    """(1, 3, Hp, Wp) float32: the network's `image` blended toward the
    input's colours by subpixel_weight."""
    w = subpixel_weight(planes, radius_channel, lo, hi, reach, depth_channel, volume)
    p = np.asarray(planes, np.float64)[0, :3]
    out = w * p + (1 - w) * np.asarray(image, np.float64)[0]
    return out[None].astype(np.float32)
