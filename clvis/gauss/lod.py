"""Gaussians from a sparse volume at three levels of detail (Sharma & Schmalstieg).

Each 8^3 leaf of a :class:`~clvis.gauss.sparse.SparseVolume` becomes a few
axis-aligned Gaussians. A leaf is *dense* when all 512 voxels are active
(tiles included), *sparse* otherwise.

- ``"low"``: one Gaussian per leaf over the bounding box of its active voxels
  (sigma = half the box's extent per axis), value = the mean active value.
- ``"medium"``: dense leaves give their 8 blocks of 4^3 voxels; in a sparse
  leaf each 2^3 block whose 8 voxels are active gives one Gaussian, and every
  other block one Gaussian per active voxel.
- ``"high"``: dense leaves give their 64 blocks of 2^3 voxels; sparse leaves
  one Gaussian per active voxel.

A Gaussian of a box of voxels sits at the box's centre (the mean of its first
and last voxel positions) with sigma = half its extent times the spacing of
each axis; rotations are the identity and opacities 1. Output order: leaf
order, then blocks (and the voxels of a partial block) in z-y-x order.

The Gaussians are made on the device by ``kernels_cl/gauss/lod.cl``: a count
per leaf, an exclusive :func:`clvis.scan` for the offsets, then one 64-item
work-group per leaf (the leaf in local memory) writes them compactly. Every
float is computed in float32 in a fixed order (the .cl file's ABI comment),
so the results equal ``clvis.reference.gauss.lod`` bit for bit.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import pyopencl as cl

from .. import runtime
from .._arrays import resolve_queue
from ..errors import ClvisWarning, DeviceError
from ..primitives import scan
from .gaussians import Gaussians
from .sparse import SparseVolume

__all__ = [
    "BYTES_PER_AXIS_ALIGNED_GAUSSIAN",
    "BYTES_PER_GAUSSIAN",
    "LODS",
    "LodRow",
    "LodTable",
    "gaussians_from_volume",
    "lod_table",
]

LODS = ("low", "medium", "high")
# as clvis.gauss.Gaussians stores one: means 12 + scales 12 + rotations 36 + value 4 + opacity 4
BYTES_PER_GAUSSIAN = 68
# an axis-aligned Gaussian needs no rotation: means 12 + scales 12 + value 4 + opacity 4
BYTES_PER_AXIS_ALIGNED_GAUSSIAN = 32
_SRC = "gauss/lod.cl"
# work shapes per tuning profile: lod_emit's summation order is defined for a
# 64-item group per leaf, so both profiles use it; "count_wg" is the local size
# of the one-item-per-leaf count kernel (a fixed one: PoCL would compile a
# work-group function for every size the driver chose)
PROFILES = {"cpu": {"WG": 64, "count_wg": 64}, "gpu": {"WG": 64, "count_wg": 256}}
_MAX_LEAVES = (2**32 - 1) // 512  # Gaussian offsets are uint32


def _lod_index(lod) -> int:
    if not isinstance(lod, str) or lod not in LODS:
        raise ValueError(f"lod: expected one of {', '.join(map(repr, LODS))}, got {lod!r}")
    return LODS.index(lod)


def _as_sparse(volume_or_sparse, threshold, mask, spacing, origin) -> SparseVolume:
    if isinstance(volume_or_sparse, SparseVolume):
        given = [
            n
            for n, v in (("threshold", threshold), ("mask", mask), ("spacing", spacing), ("origin", origin))
            if v is not None
        ]
        if given:
            raise ValueError(
                f"{', '.join(given)}: a SparseVolume already has its active voxels, "
                "spacing and origin; pass these with a dense volume only"
            )
        return volume_or_sparse
    return SparseVolume.from_dense(
        volume_or_sparse, threshold=threshold, mask=mask, spacing=spacing, origin=origin
    )


class _DeviceLeaves:
    """A SparseVolume's arrays on the device."""

    def __init__(self, queue, sv: SparseVolume):
        if sv.n_leaves > _MAX_LEAVES:
            raise DeviceError(
                f"volume: {sv.n_leaves} leaves; at most {_MAX_LEAVES} (Gaussian offsets are 32-bit)"
            )
        caps = runtime.capabilities(queue)
        if caps.max_work_group_size < PROFILES["cpu"]["WG"]:
            raise DeviceError(f"{runtime.describe(queue.device)}: lod.cl needs work-groups of 64 items")
        self.queue = queue
        self.n = sv.n_leaves
        self.coords = _put(queue, "coords", sv.coords)
        self.masks = _put(queue, "masks", sv.masks)
        self.rows = _put(queue, "rows", sv.value_rows)
        self.tile_values = _put(queue, "tile_values", sv.tile_values)
        self.values = _put(queue, "values", sv.values if len(sv.values) else np.zeros((1, 512), np.float32))
        self.spacing = np.asarray(sv.spacing, np.float32)  # dz, dy, dx
        self.origin = np.asarray(sv.origin, np.float32)  # ox, oy, oz

    def counts(self, lod: int):
        """(per-leaf counts, offsets, total) for one LOD; total read with one small transfer."""
        q = self.queue
        counts = runtime.empty(q, self.n, np.uint32, "LOD counts")
        wg = PROFILES[runtime.tuning_profile(q)]["count_wg"]
        k = runtime.get_kernel(q, _SRC, "lod_count", {}, runtime.EXACT_FP)
        runtime.launch(
            q,
            k,
            *runtime.items(q, self.n, wg),
            self.masks.base_data,
            np.uint32(self.n),
            np.uint32(lod),
            counts.base_data,
        )
        offsets, total = scan(counts, exclusive=True, return_total=True, queue=q)
        return offsets, int(total.get()[0])

    def emit(self, lod: int) -> Gaussians:
        q = self.queue
        offsets, total = self.counts(lod)
        means = runtime.empty(q, (max(total, 1), 3), np.float32, "Gaussian means")
        scales = runtime.empty(q, (max(total, 1), 3), np.float32, "Gaussian scales")
        values = runtime.empty(q, max(total, 1), np.float32, "Gaussian values")
        wg = PROFILES[runtime.tuning_profile(q)]["WG"]
        k = runtime.get_kernel(q, _SRC, "lod_emit", {}, runtime.EXACT_FP)
        dz, dy, dx = self.spacing
        ox, oy, oz = self.origin
        runtime.launch(
            q,
            k,
            self.n * wg,
            wg,
            self.coords.base_data,
            self.masks.base_data,
            self.rows.base_data,
            self.tile_values.base_data,
            self.values.base_data,
            np.uint32(self.n),
            np.uint32(lod),
            dz,
            dy,
            dx,
            ox,
            oy,
            oz,
            offsets.base_data,
            means.base_data,
            scales.base_data,
            values.base_data,
        )
        return Gaussians(means.get()[:total], scales.get()[:total], values=values.get()[:total])


def _put(queue, what, a: np.ndarray):
    d = runtime.empty(queue, a.shape, a.dtype, what)
    d.set(np.ascontiguousarray(a), queue=queue)
    return d


def _empty_gaussians() -> Gaussians:
    return Gaussians(
        np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), values=np.zeros(0, np.float32)
    )


def gaussians_from_volume(
    volume_or_sparse: SparseVolume | Any,
    lod: str = "medium",
    threshold: float | None = None,
    mask: Any = None,
    spacing: Sequence[float] | None = None,
    origin: Sequence[float] | None = None,
    queue: cl.CommandQueue | None = None,
) -> Gaussians:
    """The Gaussians of a volume at level of detail `lod` ("low", "medium" or "high").

    volume_or_sparse: a [Z, Y, X] numpy volume or a clvis.Volume (made sparse
    with :meth:`SparseVolume.from_dense`: active voxels by ``threshold``
    (value > threshold) or a bool ``mask``, all voxels with neither;
    ``spacing`` (dz, dy, dx) default a Volume's or (1, 1, 1), ``origin`` (ox,
    oy, oz) default a Volume's or (0, 0, 0)), or a
    :class:`SparseVolume` (then threshold, mask, spacing and origin must be
    None). Returns float32 :class:`Gaussians` (module docstring for the rules
    and the order). A non-finite active value raises DataError naming the voxel.
    """
    lod_i = _lod_index(lod)
    sv = _as_sparse(volume_or_sparse, threshold, mask, spacing, origin)
    queue = resolve_queue(queue)
    if sv.n_leaves == 0:
        return _empty_gaussians()
    _warn_far(sv)
    return _DeviceLeaves(queue, sv).emit(lod_i)


# float32 steps are 2^-23 of a position: past this many voxels from the world
# origin a voxel spans fewer than 16 of them
_FAR_VOXELS = 2**19


def _warn_far(sv: SparseVolume) -> None:
    """ClvisWarning for a volume whose float32 Gaussians cannot resolve its
    voxels: a grid at map coordinates (translation 4,000,000, voxels of 0.25)
    rendered fully transparent."""
    ends = [
        max(abs(o), abs(o + d * n))
        for o, d, n in zip(sv.origin, sv.spacing[::-1], sv.shape[::-1], strict=True)
    ]
    step = min(sv.spacing)
    if max(ends) > _FAR_VOXELS * step:
        warnings.warn(
            ClvisWarning(
                f"the volume reaches {max(ends):g} from the world origin with voxels of {step:g}: its "
                "float32 Gaussians cannot resolve them there (drawn blurred, or not at all); give it an "
                "origin near (0, 0, 0) and move the camera by the same offset"
            ),
            stacklevel=3,
        )


@dataclasses.dataclass(frozen=True)
class LodRow:
    """One level of detail: how many Gaussians, and their bytes as
    clvis.gauss.Gaussians stores them (68 B each) and axis-aligned (32 B)."""

    lod: str
    gaussians: int
    bytes: int
    axis_aligned_bytes: int


@dataclasses.dataclass(frozen=True)
class LodTable:
    """The paper's Table 1 for one volume: the sparse volume (leaves, tiles,
    active voxels, bytes of its layout) and a :class:`LodRow` per LOD."""

    leaves: int
    tiles: int
    active_voxels: int
    sparse_bytes: int
    rows: tuple

    def __getitem__(self, lod: str) -> LodRow:
        for r in self.rows:
            if r.lod == lod:
                return r
        raise KeyError(lod)

    def format(self) -> str:
        head = (
            f"sparse volume: {self.leaves} leaves ({self.tiles} tiles), {self.active_voxels} active "
            f"voxels, {self.sparse_bytes} B"
        )
        lines = [head, f"{'LOD':<8}{'Gaussians':>12}{'bytes':>14}{'axis-aligned B':>16}"]
        lines += [f"{r.lod:<8}{r.gaussians:>12}{r.bytes:>14}{r.axis_aligned_bytes:>16}" for r in self.rows]
        return "\n".join(lines)


def lod_table(sparse: SparseVolume | Any, queue: cl.CommandQueue | None = None) -> LodTable:
    """Gaussian counts and sizes of every LOD of `sparse` (a SparseVolume, or
    a dense volume with every voxel active), counted on the device without
    making the Gaussians."""
    sv = _as_sparse(sparse, None, None, None, None)
    queue = resolve_queue(queue)
    dev = _DeviceLeaves(queue, sv) if sv.n_leaves else None
    rows = []
    for i, name in enumerate(LODS):
        n = dev.counts(i)[1] if dev is not None else 0
        rows.append(LodRow(name, n, n * BYTES_PER_GAUSSIAN, n * BYTES_PER_AXIS_ALIGNED_GAUSSIAN))
    return LodTable(sv.n_leaves, sv.n_tiles, sv.n_active, sv.nbytes, tuple(rows))
