"""Brute-force reference of clvis/gauss/render.py: every ray against every
Gaussian, hits sorted by (t, id), composited front to back.

The per-Gaussian records (:mod:`.gaussians`), the rays and the hit test repeat march.cl's float32
operations one by one (numpy float32 arithmetic is IEEE, as is OpenCL's with
FP_CONTRACT OFF and correctly rounded division and sqrt), so the set of hits
and their order are the kernel's exactly. exp and erfc are evaluated in
float64 here; compositing is in float64. Tests compare with a tolerance.

With per-Gaussian colours (`colors`, (N, 3) uint8) a hit composites its own
rgb / 255 (clvis_gauss_rgb8) instead of its transfer-function entry's rgb;
the entry's alpha factor still scales the opacity.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ..camera import camera_rays
from .gaussians import gaussian_records

T_STOP = 1e-3


def _dot(a0, a1, a2, b0, b1, b2):
    return (a0 * b0 + a1 * b1) + a2 * b2


def hits(
    o: np.ndarray, d: np.ndarray, mean: np.ndarray, w: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For rays (R, 3) and Gaussians: t, m2, ts, a, ms2 (R, N) float32, as clvis_gauss_hit."""
    r = [o[:, None, j] - mean[None, :, j] for j in range(3)]
    op = [
        _dot(w[None, :, 3 * k], w[None, :, 3 * k + 1], w[None, :, 3 * k + 2], r[0], r[1], r[2])
        for k in range(3)
    ]
    dp = [
        _dot(
            w[None, :, 3 * k],
            w[None, :, 3 * k + 1],
            w[None, :, 3 * k + 2],
            d[:, None, 0],
            d[:, None, 1],
            d[:, None, 2],
        )
        for k in range(3)
    ]
    a = _dot(*dp, *dp)
    b = _dot(*op, *dp)
    ts = -b / a
    t = np.fmax(ts, np.float32(0))
    p = [op[k] + t * dp[k] for k in range(3)]
    m2 = _dot(*p, *p)
    s = [op[k] + ts * dp[k] for k in range(3)]
    ms2 = _dot(*s, *s)
    return t, m2, ts, a, ms2


def tf_lookup(values: npt.ArrayLike, table: np.ndarray, vmin: float, scale: float) -> np.ndarray:
    """Transfer-function entries (N, 4) float32 by march.cl's index rule."""
    n = table.shape[0]
    x = np.floor(((np.asarray(values, np.float32) - np.float32(vmin)) * np.float32(scale)) * np.float32(n))
    i = np.where(x >= n - 1, n - 1, np.where(x > 0, x, 0)).astype(np.intp)
    return table[i]


def rgb8(colors: npt.ArrayLike) -> np.ndarray:
    """(N, 3) float32 colours from uint8 ones, as clvis_gauss_rgb8: c / 255."""
    return np.asarray(colors, np.uint8)[:, :3].astype(np.float32) / np.float32(255)


def render(
    means: npt.ArrayLike,
    scales: npt.ArrayLike,
    rotations: npt.ArrayLike,
    values: npt.ArrayLike,
    opacities: npt.ArrayLike,
    cam: npt.ArrayLike,
    width: int,
    height: int,
    table: np.ndarray,
    vmin: float,
    scale: float,
    *,
    model: str = "max_response",
    cutoff: float = 3.0,
    density: float = 1.0,
    colors: npt.ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """rgba (H, W, 4), depth (H, W), hits (H, W): brute force.

    cam: the 22-float ray buffer (clvis.camera.ray_buffer); table, vmin,
    scale: the transfer function (TransferFunction.table() and .limits());
    colors: None or each Gaussian's own (N, 3) uint8 rgb."""
    o, d = camera_rays(cam, width, height)
    rgba, depth, count = render_rays(
        means,
        scales,
        rotations,
        values,
        opacities,
        o,
        d,
        cam,
        table,
        vmin,
        scale,
        model=model,
        cutoff=cutoff,
        density=density,
        colors=colors,
    )
    return rgba.reshape(height, width, 4), depth.reshape(height, width), count.reshape(height, width)


def render_rays(
    means: npt.ArrayLike,
    scales: npt.ArrayLike,
    rotations: npt.ArrayLike,
    values: npt.ArrayLike,
    opacities: npt.ArrayLike,
    o: np.ndarray,
    d: np.ndarray,
    cam: npt.ArrayLike,
    table: np.ndarray,
    vmin: float,
    scale: float,
    *,
    model: str = "max_response",
    cutoff: float = 3.0,
    density: float = 1.0,
    colors: npt.ArrayLike | None = None,
    chunk: int = 1 << 22,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """rgba (R, 4) float32, depth (R,), hits (R,) for rays o, d (R, 3) float32
    (camera_rays); cam supplies the depth row; colors as in :func:`render`."""
    mean, value, w, opac = gaussian_records(means, scales, rotations, values, opacities)
    nrays, n = len(o), len(mean)
    rgba = np.zeros((nrays, 4), np.float64)
    depth = np.full(nrays, np.inf, np.float32)
    count = np.zeros(nrays, np.uint32)
    if n == 0:
        return rgba.astype(np.float32), depth, count
    c2 = np.float32(np.float32(cutoff) * np.float32(cutoff))
    tfv = tf_lookup(value, table, vmin, scale).astype(np.float64)
    eff = opac.astype(np.float64) * tfv[:, 3]
    rgb = tfv[:, :3] if colors is None else rgb8(colors).astype(np.float64)
    camf = np.asarray(cam, np.float32)
    step = max(1, chunk // max(n, 1))
    ids = np.arange(n)
    for start in range(0, nrays, step):
        sl = slice(start, min(start + step, nrays))
        with np.errstate(all="ignore"):
            t, m2, ts, a, ms2 = hits(o[sl], d[sl], mean, w)
        hit = m2 <= c2
        for rr in range(t.shape[0]):
            sel = np.flatnonzero(hit[rr])
            if not sel.size:
                continue
            order = sel[np.lexsort((ids[sel], t[rr, sel]))]
            if model == "max_response":
                alpha = np.minimum(0.99, eff[order] * np.exp(-0.5 * m2[rr, order].astype(np.float64)))
            else:
                aa = a[rr, order].astype(np.float64)
                arg = -ts[rr, order].astype(np.float64) * np.sqrt(0.5 * aa)
                integral = (
                    np.exp(-0.5 * ms2[rr, order].astype(np.float64))
                    * np.sqrt(np.pi / (2 * aa))
                    * np.array([math.erfc(x) for x in arg])
                )
                alpha = 1 - np.exp(-density * eff[order] * integral)
            after = np.cumprod(1 - alpha)
            before = np.concatenate([[1.0], after[:-1]])
            keep = before >= T_STOP  # composited: T had not yet dropped below 1e-3
            m = int(keep.sum())
            wgt = before[:m] * alpha[:m]
            rgba[sl.start + rr, :3] = (wgt[:, None] * rgb[order[:m]]).sum(axis=0)
            rgba[sl.start + rr, 3] = 1 - after[m - 1]
            count[sl.start + rr] = m
            below = np.flatnonzero(after[:m] < 0.5)
            if below.size:
                tt = t[rr, order[below[0]]]
                oo, dd = o[sl.start + rr], d[sl.start + rr]
                p = [oo[k] + tt * dd[k] for k in range(3)]
                depth[sl.start + rr] = _dot(camf[18], camf[19], camf[20], *p) + camf[21]
    return rgba.astype(np.float32), depth, count
