"""NumPy reference of the macrocell grids (clvis.iso.macrocell,
kernels_cl/iso/macrocell.cl): value ranges of dual cells, ZFP blocks and
coarse groups of blocks."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from ..._arrays import real_array
from ...errors import DataError

__all__ = ["block_ranges", "cell_ranges", "coarse_ranges", "range_bits"]


def _volume(volume) -> np.ndarray:
    """The volume as a float32 [z, y, x] array (copy), checked."""
    a = real_array("volume", volume)
    if a.ndim != 3:
        raise DataError(f"volume: expected a 3-D [z, y, x] array, got shape {a.shape}")
    if min(a.shape) < 2:
        raise DataError(f"volume: needs at least 2 samples per axis, got shape {a.shape}")
    a = a.astype(np.float32)
    if not np.isfinite(a).all():
        raise DataError("volume: values must be finite (as float32)")
    return a


# ---------------------------------------------------------------------------
# macrocell grids


def cell_ranges(volume: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), each (nz - 1, ny - 1, nx - 1) float32: the min and max of each
    dual cell's 8 corner samples (cell [k, j, i] has corners [k..k+1, j..j+1,
    i..i+1])."""
    v = _volume(volume)
    views = [
        v[dz : v.shape[0] - 1 + dz, dy : v.shape[1] - 1 + dy, dx : v.shape[2] - 1 + dx]
        for dz in (0, 1)
        for dy in (0, 1)
        for dx in (0, 1)
    ]
    return np.minimum.reduce(views), np.maximum.reduce(views)


def _reduce_blocks(lo, hi, factor, shape=None):
    """Per factor^3 group of entries, the min of lo and the max of hi; `shape`
    (default: just enough groups) may ask for more groups, which are empty."""
    if shape is None:
        shape = tuple(-(-s // factor) for s in lo.shape)
    pad = [(0, b * factor - s) for b, s in zip(shape, lo.shape, strict=True)]
    lo = np.pad(lo, pad, constant_values=np.inf)
    hi = np.pad(hi, pad, constant_values=-np.inf)
    split = (shape[0], factor, shape[1], factor, shape[2], factor)
    return lo.reshape(split).min(axis=(1, 3, 5)), hi.reshape(split).max(axis=(1, 3, 5))


def _factor(name, v) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{name}: expected an int, got {type(v).__name__}")
    if v < 1:
        raise ValueError(f"{name}: must be at least 1, got {v}")
    return int(v)


def block_ranges(volume: npt.ArrayLike, block: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), each (ceil(nz / block), ceil(ny / block), ceil(nx / block))
    float32: per block of block^3 samples (the ZFP blocks for block = 4; block
    [bz, by, bx] holds samples [block*bz .. block*bz + block - 1] per axis), the
    value range of every dual cell whose minimum corner lies in the block, that
    is, of the samples [block*b .. min(block*b + block, n - 1)] per axis (the
    block dilated by its +x, +y, +z neighbour samples). A block that holds no
    cell's minimum corner (the last one, when n - 1 is a multiple of block)
    gets the empty range (+inf, -inf), so it is always skipped."""
    block = _factor("block", block)
    lo, hi = cell_ranges(volume)
    return _reduce_blocks(lo, hi, block, tuple(-(-(s + 1) // block) for s in lo.shape))


def coarse_ranges(ranges: Sequence[npt.ArrayLike], factor: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the coarse macrocells: per factor^3 group of blocks (blocks
    [factor*c .. factor*c + factor - 1] per axis, the last group partial), the
    min of the blocks' lo and the max of their hi. `ranges` is (lo, hi) from
    :func:`block_ranges` (or :func:`cell_ranges`)."""
    try:
        lo, hi = (np.asarray(r) for r in ranges)
    except (TypeError, ValueError):
        raise TypeError("ranges: expected a (lo, hi) pair of arrays") from None
    if lo.ndim != 3 or lo.shape != hi.shape:
        raise ValueError(f"ranges: expected two 3-D arrays of one shape, got {lo.shape} and {hi.shape}")
    return _reduce_blocks(lo, hi, _factor("factor", factor))


def range_bits(ranges: npt.ArrayLike, isovalue: float) -> np.ndarray:
    """The active bits of float32 ranges (..., 2) of (lo, hi), flattened in C
    order, for one isovalue: a uint32 array of ceil(n / 32) words whose bit
    j of word w is 1 iff range 32 w + j holds the isovalue, lo <= isovalue <=
    hi in float32 ((+inf, -inf) and NaN: 0), bits past n 0
    (kernels_cl/iso/macrocell.cl's range_bits)."""
    r = np.asarray(ranges)
    if r.dtype != np.float32 or r.ndim < 1 or r.shape[-1] != 2:
        raise ValueError(f"ranges: expected a float32 array of shape (..., 2), got {r.dtype} {r.shape}")
    v = np.float32(isovalue)
    r = r.reshape(-1, 2)
    on = (r[:, 0] <= v) & (v <= r[:, 1])
    on = np.concatenate([on, np.zeros(-on.size % 32, bool)]).reshape(-1, 32)
    return (on.astype(np.uint32) << np.arange(32, dtype=np.uint32)).sum(axis=1, dtype=np.uint32)
