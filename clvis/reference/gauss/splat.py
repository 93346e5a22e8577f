"""Reference of the splatting model (kernels_cl/gauss/splat.cl,
GaussianRenderer(model="splat")): the forward pass of 3D Gaussian Splatting
in float64.

Per Gaussian: S = L L^T (L = W^-1 of its record, clvis.reference.gauss.render),
projected mean (u, v) = (Pu . m, Pv . m) / (Pw . m) (m = (mean, 1); P the
pixel-homogeneous rows of clvis.gauss.tiles.projection_rows), culled when its
view depth <= near or Pw . m <= 0; J = [Pu - uc Pw; Pv - vc Pw] / (Pw . m)
with uc, vc the projected mean clamped to 1.3 x the half image around the
image centre; S2 = J S J^T + 0.3 I; the conic is S2^-1. Per pixel (centre
(px + 0.5, py + 0.5)), Gaussians in (depth, id) order: q = d^T S2^-1 d,
skipped when q > 9; alpha = min(0.99, opacity' exp(-q / 2)), skipped below
1/255; the pixel ends (without it) once T (1 - alpha) < 1e-4; else
C += T alpha rgb, T *= 1 - alpha. depth: the mean's view depth of the
Gaussian that first took T below 0.5.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .render import gaussian_records, rgb8, tf_lookup

Q_MAX = 9.0
LOWPASS = 0.3
T_STOP = 1e-4


def project(
    means: npt.ArrayLike,
    scales: npt.ArrayLike,
    rotations: npt.ArrayLike,
    proj: npt.ArrayLike,
    near: float,
    width: int,
    height: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(uv (N, 2), conic (N, 3): A, B, C, depth (N,), visible (N,) bool), float64."""
    n = len(np.asarray(means))
    z = np.zeros(n, np.float32)
    mean, _, w, _ = gaussian_records(means, scales, rotations, z, z)
    W = w.astype(np.float64).reshape(n, 3, 3)  # row k = axis k / s_k
    L = np.linalg.inv(W) if n else np.zeros((0, 3, 3))
    S = L @ np.swapaxes(L, 1, 2)
    P = np.asarray(proj, np.float32).astype(np.float64).reshape(4, 4)
    m = np.concatenate([mean.astype(np.float64), np.ones((n, 1))], axis=1)
    pu, pv, pw, dep = (m @ P[k] for k in range(4))
    with np.errstate(all="ignore"):
        u, v = pu / pw, pv / pw
        hw, hh = width / 2, height / 2
        uc = np.clip(u, hw - 1.3 * hw, hw + 1.3 * hw)
        vc = np.clip(v, hh - 1.3 * hh, hh + 1.3 * hh)
        J = (
            np.stack([P[0, :3] - uc[:, None] * P[2, :3], P[1, :3] - vc[:, None] * P[2, :3]], axis=1)
            / pw[:, None, None]
        )
        S2 = J @ S @ np.swapaxes(J, 1, 2) + LOWPASS * np.eye(2)
        a, b, c = S2[:, 0, 0], S2[:, 0, 1], S2[:, 1, 1]
        det = a * c - b * b
        conic = np.stack([c / det, -b / det, a / det], axis=1)
    visible = (dep > near) & (pw > 0) & (det > 0) & np.isfinite(det) & np.isfinite(u) & np.isfinite(v)
    return np.stack([u, v], axis=1), conic, dep, visible


def render(
    means: npt.ArrayLike,
    scales: npt.ArrayLike,
    rotations: npt.ArrayLike,
    values: npt.ArrayLike,
    opacities: npt.ArrayLike,
    proj: npt.ArrayLike,
    near: float,
    width: int,
    height: int,
    table: np.ndarray,
    vmin: float,
    scale: float,
    *,
    colors: npt.ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """rgba (H, W, 4), depth (H, W), composited count (H, W)."""
    uv, conic, dep, vis = project(means, scales, rotations, proj, near, width, height)
    tfv = tf_lookup(values, table, vmin, scale).astype(np.float64)
    opac = np.asarray(opacities, np.float32).astype(np.float64) * tfv[:, 3]
    rgb = tfv[:, :3] if colors is None else rgb8(colors).astype(np.float64)
    idx = np.flatnonzero(vis)
    order = idx[np.lexsort((idx, dep[idx].astype(np.float32)))]
    rgba = np.zeros((height, width, 4))
    depth = np.full((height, width), np.inf, np.float32)
    count = np.zeros((height, width), np.uint32)
    px, py = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    T = np.ones((height, width))
    live = np.ones((height, width), bool)
    for i in order:
        dx, dy = uv[i, 0] - px, uv[i, 1] - py
        q = conic[i, 0] * dx * dx + conic[i, 2] * dy * dy + 2 * conic[i, 1] * dx * dy
        alpha = np.minimum(0.99, opac[i] * np.exp(-0.5 * q))
        use = live & (q <= Q_MAX) & (alpha >= 1 / 255)
        tn = T * (1 - alpha)
        stop = use & (tn < T_STOP)
        live &= ~stop
        use &= ~stop
        rgba[..., :3] += np.where(use, T * alpha, 0)[..., None] * rgb[i]
        newly = use & (tn < 0.5) & (T >= 0.5)
        depth[newly] = np.float32(dep[i])
        T = np.where(use, tn, T)
        count += use
    rgba[..., 3] = 1 - T
    return rgba.astype(np.float32), depth, count
