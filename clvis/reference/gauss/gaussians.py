"""NumPy reference of clvis/gauss/gaussians.py (kernels_cl/gauss/gaussians.cl):
the per-Gaussian records march.cl reads and the world boxes of the BVH,
repeating the kernel's float32 operations one by one."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["gaussian_boxes", "gaussian_records"]

FLAT = np.float32(1e-3)
TINY = np.float32(1e-30)


def gaussian_records(
    means: npt.ArrayLike,
    scales: npt.ArrayLike,
    rotations: npt.ArrayLike,
    values: npt.ArrayLike,
    opacities: npt.ArrayLike,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(mean (N,3), value (N,), w (N,9), opacity (N,)) float32 as gaussian_records writes them."""
    s = np.asarray(scales, np.float32)
    r = np.asarray(rotations, np.float32).reshape(-1, 3, 3)
    lim = np.maximum(FLAT * np.maximum(np.maximum(s[:, 0], s[:, 1]), s[:, 2]), TINY)
    se = np.maximum(s, lim[:, None])
    w = np.empty((len(s), 9), np.float32)
    for k in range(3):
        for j in range(3):
            w[:, 3 * k + j] = r[:, j, k] / se[:, k]
    return (
        np.asarray(means, np.float32),
        np.asarray(values, np.float32),
        w,
        np.asarray(opacities, np.float32),
    )


def gaussian_boxes(
    means: npt.ArrayLike, scales: npt.ArrayLike, rotations: npt.ArrayLike, cutoff: float
) -> np.ndarray:
    """(N, 6) float32 boxes as gaussian_records writes them."""
    s = np.asarray(scales, np.float32)
    r = np.asarray(rotations, np.float32).reshape(-1, 3, 3)
    m = np.asarray(means, np.float32)
    lim = np.maximum(FLAT * np.maximum(np.maximum(s[:, 0], s[:, 1]), s[:, 2]), TINY)
    se = np.maximum(s, lim[:, None])
    out = np.empty((len(s), 6), np.float32)
    c = np.float32(cutoff)
    for j in range(3):
        a, b, cc = r[:, j, 0] * se[:, 0], r[:, j, 1] * se[:, 1], r[:, j, 2] * se[:, 2]
        h = c * np.sqrt((a * a + b * b) + cc * cc)
        h = (h * np.float32(1.01) + np.float32(1e-6) * np.abs(m[:, j])) + np.float32(1e-30)
        out[:, j] = m[:, j] - h
        out[:, 3 + j] = m[:, j] + h
    return out
