"""The Morton-code quantization shared by the raster and gauss families
(kernels_cl/include/clvis/morton.h does the same on the device).

A point p of a box [lo, hi] is quantized per axis to
q = clamp(trunc((p - lo) * scale), 0, 1023) with scale = float32(1023 / extent)
(0 for a flat axis), and its 30-bit code interleaves q with x in the lowest bit.
"""

from __future__ import annotations

import numpy as np

__all__ = ["BITS", "scale"]

BITS = 10  # bits per axis: 30-bit codes


def scale(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """1023 / extent per axis as float32 (0 for a flat axis), the extent taken
    in float64 from the float32 bounds."""
    ext = np.asarray(hi, np.float32).astype(np.float64) - np.asarray(lo, np.float32)
    return np.where(ext > 0, 1023.0 / np.where(ext > 0, ext, 1.0), 0.0).astype(np.float32)
