"""NumPy reference of the Morton codes both the raster and the gauss
family build (kernels_cl/include/clvis/morton.h, clvis/morton.py)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["morton_codes"]


def _spread3(v: np.ndarray) -> np.ndarray:
    """Bit k of v (10 bits) moved to bit 3k."""
    out = np.zeros_like(v)
    for k in range(10):
        out |= ((v >> np.uint32(k)) & np.uint32(1)) << np.uint32(3 * k)
    return out


def morton_codes(positions: npt.ArrayLike) -> np.ndarray:
    """30-bit Morton codes over the finite bounding box (clvis/morton.h's rule):
    q = clamp(trunc((a - lo) * float32(1023 / extent)), 0, 1023) per axis,
    x in the lowest bit; 0xFFFFFFFF for non-finite points."""
    p = np.asarray(positions, np.float32).reshape(-1, 3)
    finite = np.isfinite(p).all(axis=1)
    if finite.any():
        lo, hi = p[finite].min(axis=0), p[finite].max(axis=0)
    else:
        lo = hi = np.zeros(3, np.float32)
    ext = hi.astype(np.float64) - lo
    scale = np.where(ext > 0, 1023.0 / np.where(ext > 0, ext, 1.0), 0.0).astype(np.float32)
    with np.errstate(invalid="ignore"):
        t = (p - lo) * scale
    q = np.where(t <= 0, 0, np.where(t >= 1023, 1023, np.nan_to_num(t))).astype(np.uint32)
    codes = _spread3(q[:, 0]) | (_spread3(q[:, 1]) << np.uint32(1)) | (_spread3(q[:, 2]) << np.uint32(2))
    return np.where(finite, codes, np.uint32(0xFFFFFFFF)).astype(np.uint32)
