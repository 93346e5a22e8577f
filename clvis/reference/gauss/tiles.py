"""Reference of clvis/gauss/tiles.py (kernels_cl/gauss/tiles.cl).

The tile renderer's image is the brute-force render of
clvis.reference.gauss.render (every ray against every Gaussian, hits in
(t, id) order): that is its reference. What the binning must guarantee is
stated here from the brute force's hits, so tests can hold the kernels' keys
to it:

- :func:`required_tiles`: every (tile, Gaussian) pair with a hit by a ray of
  the tile; the kernels' keys must hold each of them (they may hold more:
  their footprint is a conservative outline).
- :func:`hit_depths`: per hit, the view depth d0 + t (D . d) of its point,
  which the tile's key for that Gaussian must not exceed (the order bound).
- :func:`ranges`: each tile's [first, end) run of sorted keys.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..camera import camera_rays
from .render import gaussian_records, hits


def ranges(keys: npt.ArrayLike, tiles: int) -> np.ndarray:
    """(tiles, 2) uint32: tile i's keys are sorted_keys[first:end]; (0, 0) for none."""
    k = np.asarray(keys, np.uint64)
    tile = (k >> np.uint64(32)).astype(np.int64)
    out = np.zeros((tiles, 2), np.uint32)
    for t in np.unique(tile):
        idx = np.flatnonzero(tile == t)
        out[t] = idx[0], idx[-1] + 1
    return out


def key_depth(keys: npt.ArrayLike) -> np.ndarray:
    """The float32 depth bound in a key's low 32 bits (clvis_key_f32 undone)."""
    low = (np.asarray(keys, np.uint64) & np.uint64(0xFFFFFFFF)).astype(np.uint32)
    bits = np.where(low & np.uint32(0x80000000), low & np.uint32(0x7FFFFFFF), ~low)
    return bits.astype(np.uint32).view(np.float32)


def hit_depths(
    means: npt.ArrayLike,
    scales: npt.ArrayLike,
    rotations: npt.ArrayLike,
    cam: npt.ArrayLike,
    width: int,
    height: int,
    tile: int,
    cutoff: float = 3.0,
) -> list[tuple[int, int, float]]:
    """Every hit of the brute force as (tile index row-major, Gaussian id,
    view depth of the hit point d0 + t c, in float64 from the float32 t)."""
    n = len(np.asarray(means))
    zeros = np.zeros(n, np.float32)
    mean, _, w, _ = gaussian_records(means, scales, rotations, zeros, zeros)
    o, d = camera_rays(cam, width, height)
    camf = np.asarray(cam, np.float64)
    c2 = np.float32(np.float32(cutoff) * np.float32(cutoff))
    tiles_x = -(-width // tile)
    out = []
    for p in range(width * height):
        with np.errstate(all="ignore"):
            t, m2, *_ = hits(o[p : p + 1], d[p : p + 1], mean, w)
        ids = np.flatnonzero(m2[0] <= c2)
        if not ids.size:
            continue
        px, py = p % width, p // width
        ti = (py // tile) * tiles_x + px // tile
        d0 = camf[18:21] @ o[p].astype(np.float64) + camf[21]
        cd = camf[18:21] @ d[p].astype(np.float64)
        for i in ids:
            out.append((ti, int(i), float(d0 + float(t[0, i]) * cd)))
    return out


def required_tiles(
    means: npt.ArrayLike,
    scales: npt.ArrayLike,
    rotations: npt.ArrayLike,
    cam: npt.ArrayLike,
    width: int,
    height: int,
    tile: int,
    cutoff: float = 3.0,
) -> set[tuple[int, int]]:
    """{(tile, Gaussian id)}: the pairs with at least one hit."""
    return {(ti, i) for ti, i, _ in hit_depths(means, scales, rotations, cam, width, height, tile, cutoff)}
