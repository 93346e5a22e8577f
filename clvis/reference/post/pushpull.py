"""NumPy reference of clvis.post.pushpull: push-pull hole fill.

The classical way to fill the holes of a sparse image (Gortler et al., "The
Lumigraph", 1996; Grossman & Dally, "Point Sample Rendering", 1998): average
the known pixels down an image pyramid (push), then blend the coarse levels
back up where the finer ones know little (pull). The post family's in-fill
networks must beat it. The kernels of ``kernels_cl/post/pushpull.cl`` repeat
these float32 operations in the same order.

Definition
----------
Input: ``image`` (H x W x C float32, C in 1..8) and ``valid`` (H x W, nonzero
= a known pixel). Values at holes are never read (they may be NaN); known
values must be finite. Every operation is float32.

1. Level 0: weight w0 = 1 at known pixels, 0 at holes; colour c0 = the image
   at known pixels (0 at holes).
2. Push. Level k+1 has ceil(Hk/2) x ceil(Wk/2) pixels; pixel (y, x) has the
   children (2y+j, 2x+i) of level k, taken in the order (i, j) = (0, 0),
   (1, 0), (0, 1), (1, 1); a child outside level k counts weight 0:
   ``wsum = ((w_0 + w_1) + w_2) + w_3``,
   ``csum = ((w_0*c_0 + w_1*c_1) + w_2*c_2) + w_3*c_3``,
   ``weight = min(1, wsum)``, ``colour = csum / wsum if wsum > 0 else 0``.
   The default number of levels L halves until 1 x 1 (L = 0 for a 1 x 1
   image); a given L may go further (levels past 1 x 1 copy the 1 x 1 one).
3. Pull. For k = L-1 down to 0, every pixel (y, x) of level k takes the
   coarse estimate e = the bilinear interpolation of the (final) level k+1 at
   the pixel's centre, ``gx = clamp(x*0.5 - 0.25, 0, W(k+1) - 1)``,
   ``x0 = floor(gx)``, ``x1 = min(x0 + 1, W(k+1) - 1)``, ``fx = gx - x0``
   (likewise y), ``e = ((1-fy) * ((1-fx)*c[y0,x0] + fx*c[y0,x1]))
   + (fy * ((1-fx)*c[y1,x0] + fx*c[y1,x1]))``, and becomes
   ``w*c + (1-w)*e``. On level 0 (w is 0 or 1) that is: the image's value at
   known pixels (bit for bit), e at holes.

With L = 0 holes stay 0. With no known pixel at all every weight and colour
is 0: the result is all zeros (not an error).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ...errors import DataError

MAX_CHANNELS = 8
MAX_LEVELS = 16

_F = np.float32


def default_levels(height: int, width: int) -> int:
    """The number of halvings until 1 x 1."""
    levels = 0
    while height > 1 or width > 1:
        height, width = -(-height // 2), -(-width // 2)
        levels += 1
    return levels


def _push(col: np.ndarray, wt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    h, w, ch = col.shape
    hp, wp = h + h % 2, w + w % 2
    c = np.zeros((hp, wp, ch), _F)
    c[:h, :w] = col
    g = np.zeros((hp, wp), _F)
    g[:h, :w] = wt
    kids = [(0, 0), (0, 1), (1, 0), (1, 1)]  # (row, column): (i, j) = (0,0), (1,0), (0,1), (1,1)
    ws = [g[dy::2, dx::2] for dy, dx in kids]
    cs = [c[dy::2, dx::2] for dy, dx in kids]
    wsum = ((ws[0] + ws[1]) + ws[2]) + ws[3]
    csum = ((ws[0][..., None] * cs[0] + ws[1][..., None] * cs[1]) + ws[2][..., None] * cs[2]) + ws[3][
        ..., None
    ] * cs[3]
    some = wsum > 0
    colour = np.where(some[..., None], csum / np.where(some, wsum, _F(1))[..., None], _F(0))
    return colour.astype(_F), np.minimum(_F(1), wsum)


def _axis(n: int, coarse: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    g = np.clip(np.arange(n, dtype=_F) * _F(0.5) - _F(0.25), _F(0), _F(coarse - 1))
    i0 = np.floor(g).astype(np.int64)
    i1 = np.minimum(i0 + 1, coarse - 1)
    return i0, i1, (g - i0.astype(_F)).astype(_F)


def bilerp(coarse: np.ndarray, height: int, width: int) -> np.ndarray:
    """The coarse estimate at every pixel of a height x width level."""
    ch, cw = coarse.shape[:2]
    y0, y1, fy = _axis(height, ch)
    x0, x1, fx = _axis(width, cw)
    fy, fx = fy[:, None, None], fx[None, :, None]
    top = (_F(1) - fx) * coarse[y0][:, x0] + fx * coarse[y0][:, x1]
    bottom = (_F(1) - fx) * coarse[y1][:, x0] + fx * coarse[y1][:, x1]
    return ((_F(1) - fy) * top + fy * bottom).astype(_F)


def pushpull(image: npt.ArrayLike, valid: npt.ArrayLike, *, levels: int | None = None) -> np.ndarray:
    """The filled image (H x W x C float32) of the definition above."""
    image = np.asarray(image)
    valid = np.asarray(valid).astype(bool)  # nonzero
    if image.dtype != np.float32 or image.ndim != 3 or not 1 <= image.shape[2] <= MAX_CHANNELS:
        raise ValueError(f"image: expected H x W x C float32 with C in 1..{MAX_CHANNELS}")
    if valid.shape != image.shape[:2]:
        raise ValueError("valid: shape differs from image's")
    h, w = valid.shape
    if h == 0 or w == 0:
        raise DataError("image: empty")
    if not np.isfinite(image[valid]).all():
        raise DataError("image: non-finite values at valid pixels")
    if levels is None:
        levels = default_levels(h, w)
    col = np.where(valid[..., None], image, _F(0)).astype(_F)
    wt = valid.astype(_F)
    pyramid = [(col, wt)]
    for _ in range(levels):
        pyramid.append(_push(*pyramid[-1]))
    c = pyramid[-1][0]
    for k in range(levels - 1, 0, -1):
        ck, wk = pyramid[k]
        est = bilerp(c, *wk.shape)
        c = (wk[..., None] * ck + (_F(1) - wk[..., None]) * est).astype(_F)
    if levels == 0:
        return col
    return np.where(valid[..., None], image, bilerp(c, h, w)).astype(_F)
