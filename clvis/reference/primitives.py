"""NumPy reference of clvis.primitives."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def scan(
    x: npt.ArrayLike, exclusive: bool = True, *, return_total: bool = False
) -> np.ndarray | tuple[np.ndarray, np.generic]:
    """Prefix sums in x's dtype (integers wrap)."""
    x = np.asarray(x)
    inclusive = np.cumsum(x, dtype=x.dtype)
    if exclusive:
        out = np.concatenate([np.zeros(min(1, x.size), x.dtype), inclusive[:-1]])
    else:
        out = inclusive
    total = inclusive[-1] if x.size else x.dtype.type(0)
    return (out, total) if return_total else out


def compact(x: npt.ArrayLike, flags: npt.ArrayLike) -> np.ndarray:
    return np.asarray(x)[np.asarray(flags) != 0]


def compact_indices(flags: npt.ArrayLike) -> np.ndarray:
    return np.flatnonzero(np.asarray(flags) != 0).astype(np.uint32)


def sort_key(keys: npt.ArrayLike) -> np.ndarray:
    """The unsigned integer whose order is clvis's total order of `keys`:
    unsigned as is; signed with the sign bit flipped; floats by IEEE 754 bits
    (-inf < ... < -0.0 < +0.0 < ... < +inf), every NaN after +inf."""
    keys = np.asarray(keys)
    bits = keys.dtype.itemsize * 8
    u = np.dtype(f"u{keys.dtype.itemsize}")
    top = u.type(1 << (bits - 1))
    raw = keys.view(u)
    if keys.dtype.kind == "u":
        return raw.copy()
    if keys.dtype.kind == "i":
        return raw ^ top
    key = np.where(raw & top, ~raw, raw | top)
    return np.where(np.isnan(keys), np.iinfo(u).max, key).astype(u)


def radix_sort(
    keys: npt.ArrayLike,
    values: npt.ArrayLike | None = None,
    *,
    key_bits: int | None = None,
    check: bool = True,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Stable sort by sort_key (key_bits: by the low key_bits bits only; check:
    the device's range check, which does not change a sort whose keys keep the
    promise)."""
    keys = np.asarray(keys)
    k = sort_key(keys)
    if key_bits is not None:
        k = k & k.dtype.type((1 << key_bits) - 1) if key_bits < keys.dtype.itemsize * 8 else k
    order = np.argsort(k, kind="stable")
    if values is None:
        return keys[order]
    return keys[order], np.asarray(values)[order]


def histogram(keys: npt.ArrayLike, nbins: int, *, check: bool = True) -> np.ndarray:
    """Counts per bin; keys outside [0, nbins) are in no bin."""
    keys = np.asarray(keys).astype(np.int64)
    inside = keys[(keys >= 0) & (keys < nbins)]
    return np.bincount(inside, minlength=nbins).astype(np.uint32)


def copy(x: npt.ArrayLike) -> np.ndarray:
    return np.array(x, copy=True)
