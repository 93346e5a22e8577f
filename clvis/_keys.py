"""Host copies of kernels_cl/include/clvis/keys.h's float32 depth key (NumPy):
the order-preserving uint32 of a float32 and its inverse, for code that builds
or reads depth keys on the host (distributed compositing, the gauss BVH's
bounds). The one host copy: the library writes these nowhere else (the NumPy
references define them again, as references do)."""

from __future__ import annotations

import numpy as np

SIGN = np.uint32(0x80000000)


def key_f32(depth) -> np.ndarray:
    """clvis_key_f32 of float32 values without NaN: non-negative floats get
    the sign bit set, negative ones every bit flipped (uint32)."""
    bits = np.ascontiguousarray(depth, np.float32).view(np.uint32)
    return np.where(bits & SIGN, ~bits, bits | SIGN).astype(np.uint32)


def key_f32_inverse(keys) -> np.ndarray:
    """clvis_key_f32_inverse: the float32 values of keys."""
    k = np.asarray(keys, np.uint32)
    return np.where(k & SIGN, k ^ SIGN, ~k).astype(np.uint32).view(np.float32)
