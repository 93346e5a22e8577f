"""NumPy definition of sort-last min-key compositing
(clvis.distributed.composite): per pixel, the partial with the smallest
64-bit key wins and its planes are the frame's."""

from __future__ import annotations

import numpy as np


def f32_key(depth: np.ndarray) -> np.ndarray:
    """The uint32 with the order of the float32 `depth`: for x >= 0 its bits
    with the sign bit set, for x < 0 its bits inverted (so -0.0 < +0.0)."""
    bits = np.asarray(depth, np.float32).view(np.uint32).astype(np.uint64)
    negative = bits >= 2**31
    return np.where(negative, 0xFFFFFFFF - bits, bits + 2**31).astype(np.uint64)


def keys(depth: np.ndarray, ids: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """f32_key(depth) * 2^32 + id where covered; 2^64 - 1 elsewhere."""
    k = f32_key(depth) * np.uint64(2**32) + np.asarray(ids, np.uint64)
    return np.where(covered, k, np.uint64(2**64 - 1))


def composite(keys_list: list[np.ndarray], planes_list: list[dict]) -> tuple[np.ndarray, dict]:
    """(key, planes): argmin over the stacked keys (first partial on equal
    keys: only empty pixels tie), each plane gathered from the winner."""
    stacked = np.stack(keys_list)
    winner = np.argmin(stacked, axis=0)
    key = np.take_along_axis(stacked, winner[None], axis=0)[0]
    planes = {}
    for name in planes_list[0]:
        s = np.stack([p[name] for p in planes_list])
        w = winner.reshape(winner.shape + (1,) * (s.ndim - 1 - winner.ndim))
        planes[name] = np.take_along_axis(s, w[None], axis=0)[0]
    return key, planes
