"""NumPy reference of clvis.gauss.sparse (SparseVolume.from_dense) and
clvis.gauss.lod: the same functions, the same arguments, written for
obviousness. Every float is computed in float32 in the order that
kernels_cl/gauss/lod.cl's ABI comment fixes, so results match bit for bit.
Never called by the library.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from ...gauss.gaussians import Gaussians
from ...gauss.sparse import SparseVolume

if TYPE_CHECKING:
    import pyopencl as cl

__all__ = ["gaussians_from_volume", "lod_table", "sparse_from_dense"]

LODS = ("low", "medium", "high")
F32 = np.float32


def sparse_from_dense(
    volume: npt.ArrayLike,
    threshold: float | None = None,
    mask: npt.ArrayLike | None = None,
    spacing: Sequence[float] = (1.0, 1.0, 1.0),
    origin: Sequence[float] = (0.0, 0.0, 0.0),
) -> dict[str, Any]:
    """The fields of SparseVolume.from_dense as a dict, one leaf at a time:
    shape, spacing, origin, coords (L, 3), masks (L, 16) uint32, tiles (L,),
    tile_values (L,), values (V, 512)."""
    vol = np.asarray(volume).astype(F32)
    if threshold is not None and mask is not None:
        raise ValueError("threshold, mask: give one of them, not both")
    if mask is not None:
        act = np.asarray(mask, bool)
    elif threshold is not None:
        act = vol.astype(np.float64) > float(threshold)
    else:
        act = np.ones(vol.shape, bool)
    coords, masks, tiles, tile_values, values = [], [], [], [], []
    for lz in range(0, vol.shape[0], 8):
        for ly in range(0, vol.shape[1], 8):
            for lx in range(0, vol.shape[2], 8):
                a = np.zeros((8, 8, 8), bool)
                v = np.zeros((8, 8, 8), F32)
                sub = (slice(lz, lz + 8), slice(ly, ly + 8), slice(lx, lx + 8))
                part = act[sub]
                a[: part.shape[0], : part.shape[1], : part.shape[2]] = part
                v[: part.shape[0], : part.shape[1], : part.shape[2]] = np.where(part, vol[sub], F32(0))
                if not a.any():
                    continue
                flat_a, flat_v = a.ravel(), v.ravel()
                coords.append((lz, ly, lx))
                masks.append([sum(int(flat_a[32 * w + b]) << b for b in range(32)) for w in range(16)])
                is_tile = bool(flat_a.all() and len(set(flat_v.view(np.uint32).tolist())) == 1)
                tiles.append(is_tile)
                tile_values.append(flat_v[0] if is_tile else F32(0))
                if not is_tile:
                    values.append(flat_v)
    return {
        "shape": vol.shape,
        "spacing": tuple(float(s) for s in spacing),
        "origin": tuple(float(o) for o in origin),
        "coords": np.array(coords, np.int32).reshape(-1, 3),
        "masks": np.array(masks, np.uint32).reshape(-1, 16),
        "tiles": np.array(tiles, bool),
        "tile_values": np.array(tile_values, F32),
        "values": np.array(values, F32).reshape(-1, 512),
    }


def _sparse(volume_or_sparse, threshold, mask, spacing, origin) -> SparseVolume:
    if isinstance(volume_or_sparse, SparseVolume):
        return volume_or_sparse
    d = sparse_from_dense(
        volume_or_sparse,
        threshold,
        mask,
        (1.0, 1.0, 1.0) if spacing is None else spacing,
        (0.0, 0.0, 0.0) if origin is None else origin,
    )
    return SparseVolume(**d)


def _centre(first, ext, d, o):
    a = first.astype(np.int32).astype(F32) * d + o  # (float)int, as the kernel
    b = (first + ext - 1).astype(np.int32).astype(F32) * d + o
    return (a + b) * F32(0.5)


def _sequential_sum(blocks):
    """Sum over the last axis, one term at a time from 0.0f."""
    s = np.zeros(blocks.shape[:-1], F32)
    for k in range(blocks.shape[-1]):
        s = s + blocks[..., k]
    return s


def _blocks(a, n):
    """(L, 8, 8, 8) -> (L, (8/n)^3 blocks in z-y-x order, n^3 voxels in z-y-x order)."""
    nb = 8 // n
    return a.reshape(len(a), nb, n, nb, n, nb, n).transpose(0, 1, 3, 5, 2, 4, 6).reshape(len(a), nb**3, n**3)


def _block_first(b, n):
    """Leaf-local (z, y, x) of the first voxel of block b (of size n)."""
    nb = 8 // n
    return np.stack([b // (nb * nb) * n, b // nb % nb * n, b % nb * n], axis=-1)


def gaussians_from_volume(
    volume_or_sparse: SparseVolume | npt.ArrayLike,
    lod: str = "medium",
    threshold: float | None = None,
    mask: npt.ArrayLike | None = None,
    spacing: Sequence[float] | None = None,
    origin: Sequence[float] | None = None,
    queue: cl.CommandQueue | None = None,
) -> Gaussians:
    """What clvis.gauss.lod.gaussians_from_volume returns (queue is ignored)."""
    if lod not in LODS:
        raise ValueError(f"lod: {lod!r}")
    sv = _sparse(volume_or_sparse, threshold, mask, spacing, origin)
    L = sv.n_leaves
    A = sv.active_masks().reshape(L, 8, 8, 8)
    V = np.where(A, sv.leaf_values().reshape(L, 8, 8, 8), F32(0)).astype(F32)
    C = sv.coords.astype(np.int64)
    dense = A.reshape(L, 512).all(axis=1)
    tiles, tv = sv.tiles, sv.tile_values
    d = np.asarray(sv.spacing, F32)  # dz, dy, dx
    o = np.asarray(sv.origin, F32)[::-1]  # oz, oy, ox
    # candidate Gaussians: leaf, unit, sub (the sort keys), first voxel (z, y, x), extent, value
    rec: dict[str, list[np.ndarray]] = {k: [] for k in ("leaf", "unit", "sub", "first", "ext", "value")}

    def add(leaf, unit, sub, first, ext, value):
        rec["leaf"].append(leaf)
        rec["unit"].append(unit)
        rec["sub"].append(sub)
        rec["first"].append(first.reshape(-1, 3))
        rec["ext"].append(np.broadcast_to(np.asarray(ext), first.shape).reshape(-1, 3))
        rec["value"].append(value.astype(F32))

    leaves = np.arange(L)
    if lod == "low":
        rows = _sequential_sum(V)  # (L, 8, 8): over x
        p = rows.reshape(L, 64)
        for h in (32, 16, 8, 4, 2, 1):
            p = p[:, :h] + p[:, h : 2 * h]
        count = A.reshape(L, 512).sum(axis=1)
        mean = np.where(tiles, tv, p[:, 0] / count.astype(F32))
        los, his = [], []
        for axes in ((2, 3), (1, 3), (1, 2)):
            has = np.asarray(A.any(axis=axes))  # (L, 8)
            los.append(has.argmax(axis=1))
            his.append(7 - has[:, ::-1].argmax(axis=1))
        lo, hi = np.stack(los, axis=1), np.stack(his, axis=1)
        add(leaves, np.zeros(L, int), np.zeros(L, int), C + lo, hi - lo + 1, mean)
    else:
        n_dense = 4 if lod == "medium" else 2
        # dense leaves: their blocks
        dl = np.flatnonzero(dense)
        if len(dl):
            s = _sequential_sum(_blocks(V[dl], n_dense))  # (D, nb^3)
            val = np.where(tiles[dl, None], tv[dl, None], s / F32(n_dense**3))
            nb3 = (8 // n_dense) ** 3
            b = np.arange(nb3)
            first = C[dl, None, :] + _block_first(b, n_dense)[None]
            add(
                np.repeat(dl, nb3),
                np.tile(b, len(dl)),
                np.zeros(len(dl) * nb3, int),
                first,
                (n_dense,) * 3,
                val.ravel(),
            )
        sl = np.flatnonzero(~dense)
        if len(sl):
            if lod == "medium":
                ab = _blocks(A[sl], 2)  # (S, 64 blocks, 8)
                vb = _blocks(V[sl], 2)
                full = ab.all(axis=2)
                fs, fb = np.nonzero(full)
                add(
                    sl[fs],
                    fb,
                    np.zeros(len(fs), int),
                    C[sl[fs]] + _block_first(fb, 2),
                    (2, 2, 2),
                    _sequential_sum(vb[fs, fb]) / F32(8),
                )
                ps, pb, pk = np.nonzero(ab & ~full[:, :, None])  # single voxels of partial blocks
                local = _block_first(pb, 2) + np.stack([pk >> 2, (pk >> 1) & 1, pk & 1], axis=-1)
                add(sl[ps], pb, pk, C[sl[ps]] + local, (1, 1, 1), vb[ps, pb, pk])
            else:
                vs, z, y, x = np.nonzero(A[sl])
                add(
                    sl[vs],
                    64 * z + 8 * y + x,
                    np.zeros(len(vs), int),
                    C[sl[vs]] + np.stack([z, y, x], -1),
                    (1, 1, 1),
                    V[sl[vs], z, y, x],
                )
    if not rec["leaf"]:
        return Gaussians(np.zeros((0, 3), F32), np.zeros((0, 3), F32), values=np.zeros(0, F32))
    leaf, unit, sub = (np.concatenate(rec[k]) for k in ("leaf", "unit", "sub"))
    first, ext = np.concatenate(rec["first"]), np.concatenate(rec["ext"])
    value = np.concatenate(rec["value"])
    order = np.lexsort((sub, unit, leaf))
    first, ext, value = first[order], ext[order], value[order]
    zyx_means = np.stack([_centre(first[:, a], ext[:, a], d[a], o[a]) for a in range(3)], axis=1)
    zyx_scales = np.stack([F32(0.5) * (ext[:, a].astype(F32) * d[a]) for a in range(3)], axis=1)
    return Gaussians(zyx_means[:, ::-1], zyx_scales[:, ::-1], values=value)


def lod_table(sparse: SparseVolume | npt.ArrayLike, queue: cl.CommandQueue | None = None) -> dict[str, int]:
    """{lod: number of Gaussians} (queue is ignored)."""
    return {lod: len(gaussians_from_volume(sparse, lod)) for lod in LODS}
