"""A VDB-like sparse layout of a scalar volume (Sharma & Schmalstieg, Section 3).

The volume is cut into leaves of 8x8x8 voxels, as OpenVDB's leaf nodes are. A
voxel is *active* (part of the data) or not; a leaf without an active voxel is
not stored, and a leaf whose 512 voxels are all active and hold the same value
(bit for bit) is stored as a *tile*: one value and no voxel array. Voxels
outside the volume (in the last leaves of a volume whose size is not a
multiple of 8) are inactive.

Volumes are numpy arrays indexed [z, y, x]; spacing is (dz, dy, dx) and the
sample [z, y, x] sits at world position (x*dx, y*dy, z*dz) + origin, origin
being (ox, oy, oz) (DESIGN.md).

:func:`read_vdb` reads a float grid of an OpenVDB file into this layout
through the optional ``tinyvdb`` package and, for blosc-compressed active
tiles and leaves of grids saved as half floats, ``blosc`` (``pip install ".[vdb]"`` from a clvis
checkout, or ``pip install tinyvdb blosc``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._arrays import triple
from ..errors import DataError
from ..io.files import regular_file
from ..io.vdb import GridLeaves, vdb_grids
from ..io.volumes import volume_parts

__all__ = [
    "LEAF",
    "LEAF_VOXELS",
    "SparseVolume",
    "default_isovalue",
    "dense_volume",
    "read_vdb",
    "read_vdb_volume",
]

LEAF = 8  # voxels along each side of a leaf
LEAF_VOXELS = LEAF**3  # 512
_MASK_WORDS = LEAF_VOXELS // 32
_MAX_SIDE = 2**31 - LEAF  # voxel indices stay int32 in the kernels
_BITS = (np.uint32(1) << np.arange(32, dtype=np.uint32)).astype(np.uint32)


def _pack_masks(active: np.ndarray) -> np.ndarray:
    """(L, 512) bool -> (L, 16) uint32, bit i of the leaf = voxel i."""
    a = active.reshape(len(active), _MASK_WORDS, 32).astype(np.uint32)
    return (a * _BITS).sum(axis=2, dtype=np.uint32).astype(np.uint32)


def _unpack_masks(masks: np.ndarray) -> np.ndarray:
    """(L, 16) uint32 -> (L, 512) bool."""
    return ((masks[:, :, None] & _BITS) != 0).reshape(len(masks), LEAF_VOXELS)


class SparseVolume:
    """A scalar volume as 8^3 leaves of active voxels (VDB-like).

    Fields
    ------
    shape : (Z, Y, X) ints, the size of the volume in voxels.
    spacing : (dz, dy, dx) floats > 0, the voxel size per axis.
    origin : (ox, oy, oz) floats, the world position of sample [0, 0, 0].
    coords : (L, 3) int32, voxel index [z, y, x] of each leaf's first voxel
        (multiples of 8), leaves in z-y-x order of the leaf grid.
    masks : (L, 16) uint32 active masks: bit i (word i // 32, bit i % 32) is
        voxel i of the leaf, i = 64*z + 8*y + x in leaf-local coordinates.
        Every stored leaf has an active voxel; voxels outside the volume are
        never active.
    tiles : (L,) bool, the leaf is a tile: all 512 voxels active, one value.
    tile_values : (L,) float32, the value of each tile leaf (0 for the others).
    values : (V, 512) float32, the voxels of the V non-tile leaves, in leaf
        order, [z, y, x] order within a leaf (index 64*z + 8*y + x); inactive
        voxels hold 0. :attr:`value_rows` maps a leaf to its row.

    Active values are finite (NaN or Inf in an active voxel is a DataError).
    Build one with :meth:`from_dense` or :func:`read_vdb`; the constructor
    takes the fields above and checks them.

    read_vdb also sets, from the file (else these defaults):

    background : float, the grid's background value (0.0; a level set's:
        its narrow band's outside), what :func:`dense_volume` puts where no
        voxel is active.
    grid_class : str or None, the grid's "class" metadata ("level set",
        "fog volume", ...; None), which :func:`default_isovalue` reads.
    """

    background: float = 0.0
    grid_class: str | None = None

    def __init__(
        self,
        shape: Sequence[int],
        spacing: Sequence[float],
        origin: Sequence[float],
        coords: np.ndarray,
        masks: np.ndarray,
        tiles: np.ndarray,
        tile_values: np.ndarray,
        values: np.ndarray,
    ) -> None:
        shape = tuple(int(s) for s in shape)
        if len(shape) != 3 or min(shape) < 0 or max(shape) > _MAX_SIDE:
            raise ValueError(f"shape: expected 3 sizes in [0, {_MAX_SIDE}], got {shape}")
        self.shape = shape
        self.spacing = triple("spacing", spacing, positive=True)
        self.origin = triple("origin", origin, positive=False)
        self.coords = np.ascontiguousarray(coords, np.int32).reshape(-1, 3)
        n = len(self.coords)
        self.masks = np.ascontiguousarray(masks, np.uint32)
        self.tiles = np.ascontiguousarray(tiles, bool)
        self.tile_values = np.ascontiguousarray(tile_values, np.float32)
        self.values = np.ascontiguousarray(values, np.float32)
        if self.masks.shape != (n, _MASK_WORDS):
            raise ValueError(f"masks: expected shape ({n}, {_MASK_WORDS}), got {self.masks.shape}")
        if self.tiles.shape != (n,) or self.tile_values.shape != (n,):
            raise ValueError(
                f"tiles, tile_values: expected shape ({n},), got {self.tiles.shape}, {self.tile_values.shape}"
            )
        nv = n - int(self.tiles.sum())
        if self.values.shape != (nv, LEAF_VOXELS):
            raise ValueError(
                f"values: expected shape ({nv}, {LEAF_VOXELS}) for {nv} non-tile leaves, "
                f"got {self.values.shape}"
            )
        self._check()

    # ------------------------------------------------------------------
    def _check(self) -> None:
        c = self.coords.astype(np.int64)
        n = len(c)
        if n:
            if (c % LEAF).any() or (c < 0).any() or (c >= np.asarray(self.shape)).any():
                raise DataError("coords: leaf origins must be multiples of 8 inside the volume")
            d = np.diff(c, axis=0)  # consecutive leaves: lexicographically increasing
            first = d[np.arange(len(d)), (d != 0).argmax(axis=1)] if len(d) else d[:, 0]
            if (first <= 0).any():
                raise DataError("coords: leaves must be unique and in z-y-x order")
        active = _unpack_masks(self.masks)
        if n and not active.any(axis=1).all():
            raise DataError(f"masks: leaf {int(np.flatnonzero(~active.any(axis=1))[0])} has no active voxel")
        if n and not active[self.tiles].all():
            raise DataError("masks: a tile leaf must have all 512 voxels active")
        inside = self._inside()
        if (active & ~inside).any():
            raise DataError(
                f"masks: leaf {int(np.flatnonzero((active & ~inside).any(axis=1))[0])} has "
                "active voxels outside the volume"
            )
        if not np.isfinite(self.tile_values[self.tiles]).all():
            bad = int(np.flatnonzero(self.tiles & ~np.isfinite(self.tile_values))[0])
            raise DataError(
                f"tile_values: tile leaf {bad} at voxel {self.coords[bad].tolist()} is not finite"
            )
        vals = self.values
        act = active[~self.tiles]
        if vals.size and not np.isfinite(vals[act]).all():
            r, i = np.argwhere(act & ~np.isfinite(vals))[0]
            leaf = int(np.flatnonzero(~self.tiles)[r])
            zyx = self.coords[leaf].astype(np.int64) + [i // 64, i // 8 % 8, i % 8]
            raise DataError(f"volume: active voxel [z, y, x] = {zyx.tolist()} is {vals[r, i]} (not finite)")

    def _inside(self) -> np.ndarray:
        """(L, 512) bool: the voxel lies inside the volume."""
        room = np.asarray(self.shape, np.int64) - self.coords.astype(np.int64)  # (L, 3) z, y, x
        r = np.arange(LEAF)
        inside = (
            (r < room[:, 0:1])[:, :, None, None]
            & (r < room[:, 1:2])[:, None, :, None]
            & (r < room[:, 2:3])[:, None, None, :]
        )
        return inside.reshape(len(room), LEAF_VOXELS)

    # ------------------------------------------------------------------
    @property
    def n_leaves(self) -> int:
        return len(self.coords)

    @property
    def n_tiles(self) -> int:
        return int(self.tiles.sum())

    @property
    def n_active(self) -> int:
        """Number of active voxels."""
        return int(_unpack_masks(self.masks).sum())

    @property
    def value_rows(self) -> np.ndarray:
        """(L,) int32: the row of :attr:`values` of each leaf, -1 for a tile."""
        rows = np.cumsum(~self.tiles, dtype=np.int64) - 1
        return np.where(self.tiles, -1, rows).astype(np.int32)

    @property
    def nbytes(self) -> int:
        """Bytes of the layout's arrays: leaf coords (12 B), masks (64 B), tile
        flag (1 B) and tile value (4 B) per leaf, 2048 B per non-tile leaf."""
        return sum(a.nbytes for a in (self.coords, self.masks, self.tiles, self.tile_values, self.values))

    def active_masks(self) -> np.ndarray:
        """(L, 512) bool: the active voxels of each leaf ([z, y, x] order)."""
        return _unpack_masks(self.masks)

    def leaf_values(self) -> np.ndarray:
        """(L, 512) float32: the voxels of every leaf, tiles expanded."""
        out = np.zeros((self.n_leaves, LEAF_VOXELS), np.float32)
        out[~self.tiles] = self.values
        out[self.tiles] = self.tile_values[self.tiles, None]
        return out

    def to_dense(self, background: float = 0.0) -> np.ndarray:
        """The float32 [Z, Y, X] volume: active voxels' values, `background` elsewhere."""
        vol, _ = self._dense(background)
        return vol

    def active(self) -> np.ndarray:
        """bool [Z, Y, X]: the active voxels."""
        _, act = self._dense(0.0)
        return act

    def _dense(self, background):
        Z, Y, X = self.shape
        pz, py, px = (-(-s // LEAF) * LEAF for s in self.shape)
        vol = np.full((pz, py, px), np.float32(background), np.float32)
        act = np.zeros((pz, py, px), bool)
        if self.n_leaves:
            a = self.active_masks()
            v = np.where(a, self.leaf_values(), np.float32(background))
            lz, ly, lx = (self.coords[:, k] // LEAF for k in range(3))
            _leaf_view(vol)[lz, ly, lx] = v.reshape(-1, LEAF, LEAF, LEAF)
            _leaf_view(act)[lz, ly, lx] = a.reshape(-1, LEAF, LEAF, LEAF)
        return vol[:Z, :Y, :X].copy(), act[:Z, :Y, :X].copy()

    # ------------------------------------------------------------------
    @classmethod
    def from_dense(
        cls,
        volume: Any,
        threshold: float | None = None,
        mask: Any = None,
        spacing: Sequence[float] | None = None,
        origin: Sequence[float] | None = None,
    ) -> SparseVolume:
        """The sparse layout of a [Z, Y, X] volume (any real dtype, stored as
        float32), or of a clvis.Volume (clvis.read_volume's: its data, and its
        spacing and origin where they are None; else (1, 1, 1) and (0, 0, 0)).

        Active voxels: ``volume > threshold`` (NaN is never above it), or
        ``mask`` (a bool array of the volume's shape), not both; with neither,
        every voxel is active. A non-finite active value raises DataError
        naming the voxel.
        """
        volume, spacing, origin = volume_parts(volume, spacing, origin)
        vol = _check_volume(volume)
        act = _active(vol, threshold, mask)
        spacing = triple("spacing", spacing, positive=True)
        origin = triple("origin", origin, positive=False)
        if act.any() and not np.isfinite(vol[act]).all():
            zyx = np.argwhere(act & ~np.isfinite(vol))[0]
            raise DataError(
                f"volume: active voxel [z, y, x] = {zyx.tolist()} is {vol[tuple(zyx)]} (not finite)"
            )
        Z, Y, X = vol.shape
        pz, py, px = (-(-s // LEAF) * LEAF for s in vol.shape)
        pv = np.zeros((pz, py, px), np.float32)
        pa = np.zeros((pz, py, px), bool)
        pv[:Z, :Y, :X] = np.where(act, vol, np.float32(0))
        pa[:Z, :Y, :X] = act

        lv = _leaf_view(pv).reshape(-1, LEAF_VOXELS)
        la = _leaf_view(pa).reshape(-1, LEAF_VOXELS)
        keep = la.any(axis=1)
        idx = np.flatnonzero(keep)
        nly, nlx = py // LEAF, px // LEAF
        coords = np.stack([idx // (nly * nlx), idx // nlx % nly, idx % nlx], axis=1) * LEAF
        return cls._from_leaves(vol.shape, spacing, origin, coords, lv[keep], la[keep])

    def restricted(
        self, threshold: float | None = None, spacing: Sequence[float] | None = None
    ) -> SparseVolume:
        """This volume with, leaf by leaf (never made dense): only its active
        voxels above `threshold` (None: all of them, a level set's negative
        values too), compared as :meth:`from_dense` compares, and `spacing`
        ((dz, dy, dx); None: its own). Leaves left without an active voxel
        are dropped."""
        values, active = self.leaf_values(), self.active_masks()
        if threshold is not None:
            active &= np.greater(values, np.float64(threshold))
        keep = active.any(axis=1)
        out = self._from_leaves(
            self.shape,
            self.spacing if spacing is None else spacing,
            self.origin,
            self.coords[keep],
            values[keep],
            active[keep],
        )
        out.background, out.grid_class = self.background, self.grid_class
        return out

    @classmethod
    def _from_leaves(cls, shape, spacing, origin, coords, lv, la) -> SparseVolume:
        """From (L, 512) leaf values and active flags (leaves already in order)."""
        lv = np.where(la, lv, np.float32(0)).astype(np.float32)
        bits = lv.view(np.uint32)
        tiles = la.all(axis=1) & (bits == bits[:, :1]).all(axis=1)
        tile_values = np.where(tiles, lv[:, 0] if len(lv) else np.zeros(0, np.float32), np.float32(0)).astype(
            np.float32
        )
        return cls(
            shape, spacing, origin, coords.astype(np.int32), _pack_masks(la), tiles, tile_values, lv[~tiles]
        )

    def __repr__(self) -> str:
        return (
            f"SparseVolume(shape={self.shape}, leaves={self.n_leaves}, tiles={self.n_tiles}, "
            f"active={self.n_active})"
        )


def _leaf_view(a: np.ndarray) -> np.ndarray:
    """A [Z, Y, X] array with sides multiple of 8 seen as [lz, ly, lx, z, y, x] (a view)."""
    pz, py, px = a.shape
    return a.reshape(pz // LEAF, LEAF, py // LEAF, LEAF, px // LEAF, LEAF).transpose(0, 2, 4, 1, 3, 5)


def _check_volume(volume) -> np.ndarray:
    if isinstance(volume, (str, bytes)) or volume is None:
        raise TypeError(f"volume: expected a 3-D array, got {type(volume).__name__}")
    v = np.asarray(volume)
    if v.dtype == bool or not (np.issubdtype(v.dtype, np.floating) or np.issubdtype(v.dtype, np.integer)):
        raise TypeError(f"volume: expected real numbers, got dtype {v.dtype}")
    if v.ndim != 3:
        raise ValueError(f"volume: expected a 3-D [z, y, x] array, got shape {v.shape}")
    if max(v.shape) > _MAX_SIDE:
        raise ValueError(f"volume: sides must be at most {_MAX_SIDE}, got {v.shape}")
    return np.ascontiguousarray(v, np.float32)


def _active(vol: np.ndarray, threshold, mask) -> np.ndarray:
    if threshold is not None and mask is not None:
        raise ValueError("threshold, mask: give one of them, not both")
    if mask is not None:
        if isinstance(mask, (str, bytes)):
            raise TypeError(f"mask: expected a bool array, got {type(mask).__name__}")
        m = np.asarray(mask)
        if m.dtype != bool:
            raise TypeError(f"mask: expected a bool array, got dtype {m.dtype}")
        if m.shape != vol.shape:
            raise ValueError(f"mask: shape {m.shape} differs from the volume's {vol.shape}")
        return np.ascontiguousarray(m)
    if threshold is not None:
        if isinstance(threshold, (bool, np.bool_)) or not isinstance(threshold, (int, float, np.number)):
            raise TypeError(f"threshold: expected a number, got {type(threshold).__name__}")
        t = float(threshold)
        if math.isnan(t):
            raise ValueError("threshold: NaN")
        return np.greater(vol, np.float64(t))  # compared exactly, in float64
    return np.ones(vol.shape, bool)


# --------------------------------------------------------------------------
# OpenVDB files through tinyvdb


def _tinyvdb():
    try:
        import tinyvdb
    except ImportError as e:
        raise ImportError(
            'read_vdb needs the tinyvdb package: pip install ".[vdb]" in a clvis checkout '
            "(or pip install tinyvdb)"
        ) from e
    return tinyvdb


def read_vdb(path: str | os.PathLike[str], grid: str | int | None = None) -> SparseVolume:
    """The active voxels of a float grid of an OpenVDB file, as a SparseVolume.

    grid: the grid's name, or its index in the file; default: the first float
    grid. VDB index coordinates (i, j, k) = (x, y, z) are shifted by the
    leaf-aligned offset ``off = 8 * floor(min active coordinate / 8)`` so the
    smallest active coordinate lands in the first leaf: voxel (i, j, k) is
    array sample [k - off_z, j - off_y, i - off_x], VDB leaves stay leaves, and
    the shape reaches the largest active coordinate. spacing is the grid's
    voxel size (dz, dy, dx), origin the world position of sample [0, 0, 0]
    (translation + voxel size * off). Only scale/translate transforms (or an
    affine map without rotation) with positive scales are accepted (a
    mirrored axis is a DataError).

    Each leaf is placed by clvis's walk of the file (clvis.io.vdb.vdb_leaves)
    and its values are tinyvdb's (a grid saved as half floats: the walk's,
    tinyvdb 0.9 reading half floats' subnormals as half their value); a leaf
    where the two disagree raises DataError. A file tinyvdb 0.9 cannot read
    because a grid saved as half floats stores inactive values other than
    the background (tinyvdb reads them as half floats), or for another
    grid (a frustum map tinyvdb cannot parse), is read by the walk alone,
    where the walk reads the grid whole. Active tiles (uniform regions stored above the leaves, 8^3,
    128^3 or 4096^3 voxels), which tinyvdb does not read, are decoded by the
    walk (blosc-compressed ones need the blosc package) and become tile
    leaves. A missing
    file raises FileNotFoundError; a malformed one DataError naming the file;
    one whose leaves would not fit in host memory DeviceError, before tinyvdb
    reads them.
    """
    return _read(path, grid)[0]


def _read(path, grid) -> tuple[SparseVolume, str | None, GridLeaves | None]:
    """read_vdb's volume, the grid's name and its walk (GridLeaves: its class
    and background), the two None for a file the walk does not follow."""
    if grid is not None and (isinstance(grid, bool) or not isinstance(grid, (str, int, np.integer))):
        raise TypeError(f"grid: expected a name, an index or None, got {type(grid).__name__}")
    tinyvdb = _tinyvdb()
    p = regular_file(path)  # FileNotFoundError; DataError for a directory, FIFO, device
    grids = vdb_grids(p)  # counts the file cannot hold, before tinyvdb allocates them
    walked = [leaves for _, _, leaves in grids]
    # the grid read, early (its active tiles are what read_vdb makes whole)
    selected = _select(p, [n for n, _, _ in grids], [t for _, t, _ in grids], grid) if grids else None
    _check_memory(p, walked, selected)
    name, leaves = (None, None) if selected is None else (grids[selected][0], walked[selected])
    try:
        f = tinyvdb.open(str(p))
    except (RuntimeError, ValueError, OSError, MemoryError, IndexError) as e:
        failed: Exception = e
    else:
        try:
            return _with_metadata(_read_grid(f, p, grid, walked), leaves), name, leaves
        except DataError:
            raise
        except (RuntimeError, ValueError, OSError, MemoryError, IndexError, KeyError, TypeError) as e:
            failed = e
        finally:
            f.close()
    why = _why_tinyvdb_fails(walked)
    if grids:  # the grid as the walk alone reads it, where it reads it whole
        # (what tinyvdb misreads; a file tinyvdb refuses for another grid, such
        # as one of a frustum map, which clvis does not read either)
        sv = _read_walked(p, grid, grids, f"not a readable VDB file: {failed}{why}")
        return _with_metadata(sv, leaves), name, leaves
    raise DataError(f"{p}: not a readable VDB file: {failed}") from None


def _with_metadata(sv: SparseVolume, leaves: GridLeaves | None) -> SparseVolume:
    """sv with the walk's background value and class of its grid (where the walk has them)."""
    if leaves is not None:
        sv.background, sv.grid_class = float(leaves.background), leaves.grid_class
    return sv


def read_vdb_volume(path: str | os.PathLike[str], grid: str | int | None = None) -> tuple[Any, str | None]:
    """A float grid of an OpenVDB file made dense, for an isosurface
    (``clvis iso FILE.vdb``): (a clvis.Volume [z, y, x] of :func:`read_vdb`'s
    layout, its ``array`` the grid's name; the grid's class from its
    metadata, e.g. "level set" or "fog volume", or None).

    Voxels not active take the grid's background value: 0 for a fog volume;
    for a level set its narrow band's outside (+half width), so that a
    surface seen from outside is the level set's zero crossing (inside the
    band's inner edge the fill is the outside's value too: a camera inside
    the object sees that edge). A volume that would not fit in host memory
    is refused (DeviceError) before it is made (:func:`dense_volume`)."""
    from ..io.volumes import Volume

    sv, name, _ = _read(path, grid)
    p = Path(path)
    data = dense_volume(sv, f"{p}: grid {name!r}", "clvis gauss, clvis view")
    return Volume(data, sv.spacing, sv.origin, str(p), array=name), sv.grid_class


# host bytes a voxel of a grid made dense takes at the peak (SparseVolume.to_dense:
# the volume, its padded leaf view and the active mask)
DENSE_BYTES_PER_VOXEL = 12


def dense_volume(sv: SparseVolume, what: str, instead: str) -> np.ndarray:
    """The float32 [Z, Y, X] volume of `sv`, its background value
    (:attr:`SparseVolume.background`) where no voxel is active, for an
    isosurface (``clvis iso FILE.vdb``, the viewer's iso mode of a grid).
    Refused before it is made: a volume that would not fit in host memory
    (DeviceError, `what` naming the grid, `instead` what needs no dense copy)
    and a background that is not finite (DataError)."""
    from ..errors import DeviceError
    from ..runtime import host_available_bytes

    if not math.isfinite(sv.background):
        raise DataError(f"{what}: its background value is {sv.background} (not finite): no dense volume")
    need = DENSE_BYTES_PER_VOXEL * math.prod(sv.shape)
    avail = host_available_bytes()
    if avail is not None and need > avail:
        raise DeviceError(
            f"{what} made dense is {'x'.join(map(str, sv.shape[::-1]))} voxels, "
            f"about {need / 1e9:.2f} GB of host memory, and only {avail / 1e9:.2f} GB is available "
            f"(its Gaussians need no dense copy: {instead})"
        )
    return sv.to_dense(sv.background)


def default_isovalue(volume: SparseVolume | np.ndarray, grid_class: str | None = None) -> float:
    """The isovalue a grid made dense is first shown at (``clvis iso
    FILE.vdb``, the viewer's iso mode): 0 for a level set (its surface),
    else Otsu's threshold of the dense volume (clvis.io.volumes.otsu_level).

    volume: the dense array (with the grid's `grid_class`), or the
    SparseVolume (its own :attr:`~SparseVolume.grid_class`): its dense
    volume's samples are read from the leaves, the very ones otsu_level
    takes of the dense array (every k-th of at most ~2M), never made dense."""
    from ..io.volumes import otsu_level

    if isinstance(volume, SparseVolume):
        if volume.grid_class == "level set":
            return 0.0
        return otsu_level(_dense_samples(volume))
    return 0.0 if grid_class == "level set" else otsu_level(volume)


def _dense_samples(sv: SparseVolume) -> np.ndarray:
    """otsu_level's samples of sv's dense volume (``dense.ravel()[::step]``,
    the background where no voxel is active), from the leaves."""
    from ..io.volumes import OTSU_SAMPLES

    Z, Y, X = sv.shape
    size = Z * Y * X
    step = max(1, size // OTSU_SAMPLES)
    flat = np.arange(0, size, step, dtype=np.int64)
    z, y, x = flat // (Y * X), flat // X % Y, flat % X
    ny, nx = -(-Y // LEAF), -(-X // LEAF)
    keys = (z // LEAF * ny + y // LEAF) * nx + x // LEAF
    c = sv.coords.astype(np.int64) // LEAF
    leaf_keys = (c[:, 0] * ny + c[:, 1]) * nx + c[:, 2]  # ascending: leaves in z-y-x order
    row = np.searchsorted(leaf_keys, keys)
    found = row < len(leaf_keys)
    found[found] = leaf_keys[row[found]] == keys[found]
    out = np.full(len(flat), np.float32(sv.background), np.float32)
    leaf = row[found]
    voxel = (z[found] % LEAF) * 64 + (y[found] % LEAF) * 8 + x[found] % LEAF
    active = (sv.masks[leaf, voxel // 32] >> (voxel % 32).astype(np.uint32)) & 1 == 1
    if len(sv.values):  # a tile's row is -1: its value is the tile's
        stored = sv.values[np.maximum(sv.value_rows[leaf], 0), voxel]
    else:
        stored = np.zeros(len(leaf), np.float32)
    value = np.where(sv.tiles[leaf], sv.tile_values[leaf], stored)
    out[np.flatnonzero(found)[active]] = value[active]
    return out


def _why_tinyvdb_fails(walked: list[GridLeaves | None]) -> str:
    """What the walk found that tinyvdb 0.9 cannot read (its own error says
    "OOM" or "Failed to read BLOSC data"), or ""."""
    bad = [i for i, w in enumerate(walked) if w is not None and w.half_inactive and w.parent is None]
    if not bad:
        return ""
    return (
        f" (tinyvdb 0.9 cannot read grid{'s' if len(bad) > 1 else ''} {', '.join(map(str, bad))}: saved "
        "as half floats, with nodes storing inactive values other than the background)"
    )


def _read_walked(p: Path, grid, grids: list[tuple[str, str, GridLeaves | None]], why: str) -> SparseVolume:
    """A grid of a file tinyvdb cannot read, from clvis's walk alone (its
    transform, leaves, values and tiles; every count the walk checked, every
    value block decoded to its declared size); `why` tinyvdb failed, in the
    DataError for a grid the walk does not read whole (another tree or value
    type, a map clvis does not read)."""
    names, types = [n for n, _, _ in grids], [t for _, t, _ in grids]
    idx = _select(p, names, types, grid)
    leaves = grids[idx][2]
    if leaves is None or leaves.transform is None or leaves.leaf_blocks is None:
        raise DataError(f"{p}: {why}; clvis's walk does not read grid {names[idx]!r} alone")
    voxel_size, translation = _transform(p, leaves.transform)
    active = np.unpackbits(leaves.masks, axis=1, bitorder="little").view(bool)
    at, lv, la = leaves.origins, _zyx(leaves.leaf_values()), _zyx(active)
    return _assemble(p, names[idx], leaves, at, lv, la, voxel_size, translation)


def _is_float(type_name: str) -> bool:
    return type_name.startswith("Tree_float_")


# host bytes reading a grid takes (measured: 103 MB for 17,864 leaves of 70,661
# voxels, where this gives 130 MB): tinyvdb holds every grid's leaves (512
# values and the masks), read_vdb's leaf arrays 2.5 KB a leaf, and its
# per-voxel index arrays (int64 coordinates, their leaf, the sort) ~150 B a voxel
_BYTES_PER_LEAF = 3 * 2048 + 512
_BYTES_PER_VOXEL = 160


def _check_memory(p: Path, walked: list[GridLeaves | None], selected: int | None = None) -> None:
    """DeviceError (as clvis's other host-memory refusals) before tinyvdb
    reads a file whose leaves and voxels would not fit in host memory: every
    grid's leaves (tinyvdb reads them all; an instance grid's are its
    parent's), the active tiles of the grid `selected` (None: of every grid)."""
    from ..errors import DeviceError
    from ..runtime import host_available_bytes

    counts = [
        (w.active, len(w), w.tile_leaves if selected in (None, i) else 0)
        if w.parent is None
        else (0, 0, w.tile_leaves if selected == i else 0)
        for i, w in enumerate(walked)
        if w is not None
    ]
    if not counts:
        return
    # an active tile's leaves are made whole in read_vdb's leaf arrays (no voxel arrays)
    need = sum(v * _BYTES_PER_VOXEL + (n + t) * _BYTES_PER_LEAF for v, n, t in counts)
    if need < 1 << 26:
        return
    avail = host_available_bytes()
    if avail is not None and need > avail:
        voxels, leaves, tiled = (sum(c[i] for c in counts) for i in range(3))
        tiles = f" and {tiled:,} leaves of active tiles" if tiled else ""
        raise DeviceError(
            f"{p}: reading its {voxels:,} active voxels in {leaves:,} leaves{tiles} needs about "
            f"{need / 1e9:.2f} GB of host memory, and only {avail / 1e9:.2f} GB is available"
        )


def _select(p: Path, names: list[str], types: list[str], grid) -> int:
    """The index of the float grid `grid` names (read_vdb's grid)."""
    n = len(names)
    if grid is None:
        idx = next((i for i in range(n) if _is_float(types[i])), None)
        if idx is None:
            raise DataError(f"{p}: no float grid (grids: {_listing(names, types)})")
    elif isinstance(grid, str):
        if grid not in names:
            raise DataError(f"{p}: no grid named {grid!r} (grids: {_listing(names, types)})")
        idx = names.index(grid)
    else:
        if not 0 <= int(grid) < n:
            raise DataError(f"{p}: no grid {int(grid)}; the file has {n}")
        idx = int(grid)
    if not _is_float(types[idx]):
        raise DataError(f"{p}: grid {names[idx]!r} is a {types[idx]}, not a float grid")
    return idx


def _read_grid(f, p: Path, grid, walked: list[GridLeaves | None]) -> SparseVolume:
    f.read_grids()
    n = int(f.grid_count)
    names = [f.grid_name(i) for i in range(n)]
    types = [f.grid_type_name(i) for i in range(n)]
    idx = _select(p, names, types, grid)
    g = f.grid(idx)
    voxel_size, translation = _transform(p, g.transform)
    leaves = walked[idx] if len(walked) == n else None
    name = names[idx]
    if leaves is not None:
        # an instance grid has no tree of its own: its parent's (tinyvdb's is empty)
        tree_grid = g if leaves.parent is None else f.grid(leaves.parent)
        at, lv, la = _leaf_values(p, name, tree_grid, leaves)
    else:  # a tree clvis's walk does not follow: tinyvdb's own list of voxels
        sp = g.to_sparse()
        ijk = np.frombuffer(sp["coords"], np.int32).reshape(-1, 3).astype(np.int64)
        vals = np.frombuffer(sp["values"], np.float32)
        if len(ijk) != int(sp["count"]) or len(vals) != len(ijk):
            raise DataError(f"{p}: grid {name!r}: inconsistent voxel data")
        at, lv, la = _voxel_leaves(p, name, ijk, vals)
    return _assemble(p, name, leaves, at, lv, la, voxel_size, translation)


def _assemble(
    p: Path, name: str, leaves: GridLeaves | None, at, lv, la, voxel_size, translation
) -> SparseVolume:
    """A grid's SparseVolume from its leaves ((L, 3) origins (i, j, k), (L,
    512) values and activity, [z, y, x]-major inside) and active tiles."""
    tile_at, tile_vals = _tile_leaves(leaves)
    if len(tile_at):  # each active tile's leaves, whole, after the stored leaves
        at = np.concatenate([at, tile_at])
        lv = np.concatenate([lv, np.repeat(tile_vals[:, None], LEAF_VOXELS, axis=1)])
        la = np.concatenate([la, np.ones((len(tile_at), LEAF_VOXELS), bool)])
    if (at % LEAF).any():  # the root's child or tile origins are the file's
        raise DataError(
            f"{p}: grid {name!r}: a leaf at (x, y, z) = {at[(at % LEAF).any(axis=1)][0].tolist()} "
            "is not on the 8-voxel grid"
        )
    keep = la.any(axis=1)  # a VDB leaf may hold no active voxel
    at, lv, la = at[keep], lv[keep], la[keep]
    spacing = (voxel_size[2], voxel_size[1], voxel_size[0])
    try:  # as SparseVolume takes it (float32 > 0: a voxel size of 1e-300 is 0 there)
        triple("spacing", spacing, positive=True)
    except ValueError as e:
        raise DataError(f"{p}: grid {name!r}: {e}") from None
    if len(at) == 0:
        return SparseVolume(
            (0, 0, 0),
            spacing,
            translation,
            np.zeros((0, 3), np.int32),
            np.zeros((0, _MASK_WORDS), np.uint32),
            np.zeros(0, bool),
            np.zeros(0, np.float32),
            np.zeros((0, LEAF_VOXELS), np.float32),
        )
    bad = la & ~np.isfinite(lv)
    if bad.any():
        leaf, voxel = (int(v[0]) for v in np.nonzero(bad))
        xyz = (at[leaf] + [voxel % LEAF, voxel // LEAF % LEAF, voxel // (LEAF * LEAF)]).tolist()
        raise DataError(f"{p}: grid {name!r}: active voxel (x, y, z) = {xyz} is not finite")
    # leaves [z, y, x]-major inside (clvis's layout); the bounds of the active voxels
    zyx = at[:, ::-1]
    cube = la.reshape(-1, LEAF, LEAF, LEAF)
    rows: list[np.ndarray] = [
        np.any(cube, axis=axes) for axes in ((2, 3), (1, 3), (1, 2))
    ]  # (L, 8) per z, y, x
    last = np.stack([LEAF - 1 - np.argmax(r[:, ::-1], axis=1) for r in rows], axis=1)
    off = zyx.min(axis=0)  # leaf-aligned: the leaf origins are multiples of 8
    shape = tuple(int(s) for s in (zyx + last).max(axis=0) - off + 1)
    if max(shape) > _MAX_SIDE:
        raise DataError(
            f"{p}: grid {name!r} spans {shape[::-1]} voxels (x, y, z); at most {_MAX_SIDE} per axis"
        )
    coords, first = np.unique((zyx - off) // LEAF, axis=0, return_index=True)
    if len(first) != len(at):
        raise DataError(
            f"{p}: grid {name!r}: a voxel appears twice (two leaves, or a tile and a leaf, at one place)"
        )
    off_xyz = off[::-1].astype(np.float64)
    origin = tuple(float(t + s * o) for t, s, o in zip(translation, voxel_size, off_xyz, strict=True))
    try:
        return SparseVolume._from_leaves(shape, spacing, origin, coords * LEAF, lv[first], la[first])
    except ValueError as e:  # what SparseVolume refuses (a voxel size 0 in float32: 1e-300)
        raise DataError(f"{p}: grid {name!r}: {e}") from None


def _voxel_leaves(p: Path, name: str, ijk: np.ndarray, vals: np.ndarray) -> tuple[np.ndarray, ...]:
    """(N, 3) voxel coordinates (i, j, k) and their values as leaves: ((L,
    3) int64 leaf origins (i, j, k), (L, 512) float32 values and bool
    activity, [z, y, x]-major inside)."""
    leaf, inv = np.unique(np.floor_divide(ijk, LEAF), axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    x, y, z = (np.mod(ijk, LEAF)).T
    li = z * 64 + y * 8 + x
    if (np.bincount(inv * LEAF_VOXELS + li, minlength=1) > 1).any():
        raise DataError(f"{p}: grid {name!r}: a voxel appears twice")
    lv = np.zeros((len(leaf), LEAF_VOXELS), np.float32)
    la = np.zeros((len(leaf), LEAF_VOXELS), bool)
    lv[inv, li] = vals
    la[inv, li] = True
    return leaf * LEAF, lv, la


def _tile_leaves(leaves: GridLeaves | None) -> tuple[np.ndarray, np.ndarray]:
    """The leaves the grid's active tiles cover: ((N, 3) int64 (i, j, k) of
    each leaf's first voxel, (N,) float32 the tile's value)."""
    if leaves is None or not leaves.tile_blocks:
        return np.zeros((0, 3), np.int64), np.zeros(0, np.float32)
    origins, log2, values = leaves.tile_origins, leaves.tile_log2, leaves.tile_values()
    parts, part_values = [], []
    for k in np.unique(log2):
        pick = log2 == k
        side = 1 << (int(k) - 3)  # leaves a side
        grid = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), axis=-1).reshape(-1, 3) * LEAF
        parts.append((origins[pick][:, None, :] + grid[None]).reshape(-1, 3))
        part_values.append(np.repeat(values[pick], len(grid)))
    return np.concatenate(parts), np.concatenate(part_values)


def _leaf_values(p: Path, name: str, g, leaves: GridLeaves) -> tuple[np.ndarray, ...]:
    """A walked grid's leaves, in file order: ((L, 3) int64 origins (i, j,
    k), (L, 512) float32 values and bool activity, [z, y, x]-major inside).

    Where each leaf is and which of its voxels are active come from clvis's
    walk of the file (GridLeaves); the values from tinyvdb's tree, which holds
    every leaf's 512 values decompressed (zip, blosc, half floats: but a
    half float's subnormal comes back as half its value, so a half-float
    grid's values are the walk's, GridLeaves.leaf_values). tinyvdb
    0.9's own voxel list (VDBGrid.to_sparse) drops leaves of many trees: of a
    16^3 node of more than 64 leaves it returns 64, and a level-set sphere of
    radius 40 voxels written by OpenVDB 10 came back with 87,614 of its
    120,414 voxels. The two sources are checked leaf by leaf (the count of
    leaves, each leaf's active count) before any value is used."""
    tree = g.tree
    nodes = (tree.node(i) for i in range(int(tree.num_nodes)))
    # a VDB leaf is [x, y, z]-major (bit n: x = n >> 6, y = (n >> 3) & 7, z = n & 7)
    active = np.unpackbits(leaves.masks, axis=1, bitorder="little").view(bool)
    counts = active.sum(axis=1, dtype=np.int64)
    # half floats: clvis's decoding below (tinyvdb 0.9 halves the subnormals),
    # tinyvdb's leaves only matched against the file's
    values = None if leaves.half else np.empty((len(leaves), LEAF_VOXELS), np.float32)
    k = 0
    for node in nodes:
        if node.type != "leaf":
            continue
        if k == len(leaves):
            raise DataError(f"{p}: grid {name!r}: tinyvdb read more leaves than the file's {len(leaves):,}")
        data = node.data
        if data is None or len(data) != 4 * LEAF_VOXELS or int(node.active_voxel_count) != counts[k]:
            raise DataError(
                f"{p}: grid {name!r}: tinyvdb's leaf {k:,} does not match the file's "
                f"({int(node.active_voxel_count)} active voxels, {counts[k]} in its value mask)"
            )
        if values is not None:
            values[k] = np.frombuffer(data, np.float32)
        k += 1
    if k != len(leaves):
        raise DataError(f"{p}: grid {name!r}: tinyvdb read {k:,} leaves of the file's {len(leaves):,}")
    if values is None:
        values = leaves.leaf_values()
    return leaves.origins, _zyx(values), _zyx(active)


def _zyx(a: np.ndarray) -> np.ndarray:
    """(L, 512) in VDB's [x, y, z]-major leaf order -> [z, y, x]-major."""
    return np.ascontiguousarray(a.reshape(-1, LEAF, LEAF, LEAF).transpose(0, 3, 2, 1)).reshape(
        -1, LEAF_VOXELS
    )


def _listing(names, types) -> str:
    return ", ".join(f"{n!r} ({t})" for n, t in zip(names, types, strict=True)) or "none"


def _transform(p: Path, t: dict):
    kind = t.get("type")
    if kind in ("uniform_scale", "uniform_scale_translate", "scale", "scale_translate", "translation"):
        # the scale, signed (a scale map's voxel size is its absolute value:
        # a mirrored grid read by it would come out unmirrored, misplaced)
        vs = tuple(float(v) for v in t.get("scale", t["voxel_size"]))
        tr = tuple(float(v) for v in t["translation"])
    elif kind == "affine":
        m = np.asarray(t["matrix"], np.float64)
        lin = m[:3, :3]
        if (lin != np.diag(np.diag(lin))).any():
            raise DataError(
                f"{p}: the grid's transform rotates or shears; only axis-aligned "
                "scale/translate maps are supported"
            )
        vs = tuple(float(v) for v in np.diag(lin))
        tr = tuple(float(v) for v in m[3, :3])
    else:
        raise DataError(f"{p}: unsupported grid transform {kind!r}")
    if all(math.isfinite(v) for v in vs) and any(v < 0 for v in vs):
        raise DataError(
            f"{p}: the grid's transform mirrors an axis (scale {vs}); only positive scales are supported"
        )
    if not all(math.isfinite(v) and v > 0 for v in vs) or not all(math.isfinite(v) for v in tr):
        raise DataError(
            f"{p}: the grid's voxel size {vs} / translation {tr} is not usable (needs finite sizes > 0)"
        )
    return vs, tr
