"""Sort-last compositing by the smallest 64-bit key per pixel.

Every worker renders its own partition of the data into a full-frame
*partial*: per pixel a 64-bit key and the planes of the winner there (index,
depth, rgba, attributes, ...). The key is the render's own ordering made
global: ``depth key << 32 | global id``, where the depth key is the float's
order-preserving uint32 (raster/resolve.cl's ``clvis_key_f32``) and the id
is unique across partitions (points: partition offset + local index;
volumes: the brick's number). An empty pixel's key is all ones. Taking the
partial with the smaller key, pixel by pixel, is associative and commutative
and the keys of covered pixels never tie, so any grouping of the partials
(direct-send bands, a binary tree, all at once) gives the same frame as one
device that saw every partition: that device keeps the same minimum. Only
empty pixels tie, so their planes must be the same in every partial (the
renderers' empty values: index all ones, depth +inf, rgba 0, NaN).

A :class:`Partial` may cover a band of rows (``rows``): direct-send splits
each worker's partial into one band per worker, sends band j to worker j,
which composites its band over every worker's, and the client gathers the
bands (IceT's direct-send). NumPy definition: ``clvis.reference.distributed.composite``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from .._keys import key_f32, key_f32_inverse

__all__ = [
    "EMPTY_KEY",
    "Partial",
    "assemble",
    "bands",
    "composite",
    "depth_keys",
    "depths_of",
    "ids_of",
    "split",
]

EMPTY_KEY = np.uint64(0xFFFFFFFFFFFFFFFF)


def depth_keys(depth: np.ndarray, ids: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """uint64 keys ``f32key(depth) << 32 | id`` where `covered`, all ones
    elsewhere. f32key maps float32 bits to a uint32 of the same order
    (non-negative floats: sign bit set; negative ones: every bit flipped),
    the inverse of resolve.cl's ``resolve_depth``."""
    k32 = key_f32(depth).astype(np.uint64)
    key = (k32 << np.uint64(32)) | np.asarray(ids).astype(np.uint64)
    return np.where(covered, key, EMPTY_KEY)


def ids_of(key: np.ndarray) -> np.ndarray:
    """The ids of `key` (its low 32 bits): 0xFFFFFFFF where empty. The key
    carries the winner's id and depth, so partials need not send them too."""
    return (key & np.uint64(0xFFFFFFFF)).astype(np.uint32)


def depths_of(key: np.ndarray) -> np.ndarray:
    """The float32 depths of `key` (the inverse of depth_keys' f32key on its
    high 32 bits): +inf where empty."""
    depth = key_f32_inverse((key >> np.uint64(32)).astype(np.uint32))
    return np.where(key == EMPTY_KEY, np.float32(np.inf), depth).astype(np.float32)


@dataclasses.dataclass
class Partial:
    """Rows ``rows[0]:rows[1]`` of a frame: ``key`` (h, W) uint64 and
    ``planes`` name → array whose first two axes are (h, W). ``worker``: the
    address of the worker that holds it (None on the client); ``sent``:
    worker → bytes the partials composited into this one crossed from that
    worker to another; ``seconds``: named timings of the work behind it;
    ``counts``: named counts of it (summed when partials are composited)."""

    rows: tuple[int, int]
    key: np.ndarray
    planes: dict
    worker: str | None = None
    sent: dict = dataclasses.field(default_factory=dict)
    seconds: dict = dataclasses.field(default_factory=dict)
    counts: dict = dataclasses.field(default_factory=dict)

    @property
    def nbytes(self) -> int:
        """Bytes of the key and the planes (what sending it moves)."""
        return int(self.key.nbytes + sum(a.nbytes for a in self.planes.values()))


def _merge_counts(dicts: Sequence[Mapping]) -> dict:
    out: dict = {}
    for d in dicts:
        for k, v in d.items():
            out[k] = out.get(k, 0) + v
    return out


def composite(parts: Sequence[Partial], worker: str | None = None) -> Partial:
    """The per-pixel smallest key over `parts` (all of the same rows and the
    same planes), with the winner's planes. `worker`: where this runs; the
    bytes of every part held elsewhere are counted as sent by its worker."""
    if not parts:
        raise ValueError("parts: nothing to composite")
    first = parts[0]
    for p in parts[1:]:
        if p.rows != first.rows or p.key.shape != first.key.shape or p.planes.keys() != first.planes.keys():
            raise ValueError(
                f"parts: partials of rows {p.rows} / shape {p.key.shape} / planes {sorted(p.planes)} "
                f"cannot be composited with rows {first.rows} / {first.key.shape} / {sorted(first.planes)}"
            )
    key = first.key.copy()
    planes = {name: a.copy() for name, a in first.planes.items()}
    for p in parts[1:]:
        take = p.key < key
        key[take] = p.key[take]
        for name, a in planes.items():
            a[take] = p.planes[name][take]
    sent = _merge_counts([p.sent for p in parts])
    for p in parts:
        if p.worker is not None and p.worker != worker:
            sent[p.worker] = sent.get(p.worker, 0) + p.nbytes
    seconds = _merge_counts([p.seconds for p in parts])
    return Partial(first.rows, key, planes, worker, sent, seconds, _merge_counts([p.counts for p in parts]))


def bands(height: int, n: int) -> list[tuple[int, int]]:
    """`n` bands of rows covering 0..height, as even as they come (the
    first ``height % n`` one row taller; bands may be empty when n > height)."""
    if n < 1:
        raise ValueError(f"n: expected at least one band, got {n}")
    q, r = divmod(height, n)
    edges = [0]
    for i in range(n):
        edges.append(edges[-1] + q + (1 if i < r else 0))
    return list(zip(edges[:-1], edges[1:], strict=True))


def split(part: Partial, rows: tuple[int, int], carry: bool = True) -> Partial:
    """The band `rows` (absolute row numbers) of `part`, copied (a view would
    send the whole frame). carry: the band takes the partial's seconds and
    counts (give them to one band only, or they add up once per band)."""
    r0, r1 = rows
    a0, a1 = part.rows
    if not a0 <= r0 <= r1 <= a1:
        raise ValueError(f"rows: {rows} is not inside the partial's rows {part.rows}")
    s = slice(r0 - a0, r1 - a0)
    return Partial(
        (r0, r1),
        part.key[s].copy(),
        {name: a[s].copy() for name, a in part.planes.items()},
        part.worker,
        {},
        dict(part.seconds) if carry else {},
        dict(part.counts) if carry else {},
    )


def assemble(parts: Sequence[Partial]) -> Partial:
    """Bands that tile a frame, in any order, stacked into one partial."""
    parts = sorted(parts, key=lambda p: p.rows)
    for a, b in zip(parts[:-1], parts[1:], strict=True):
        if a.rows[1] != b.rows[0]:
            raise ValueError(f"parts: bands {a.rows} and {b.rows} do not meet")
    first = parts[0]
    key = np.concatenate([p.key for p in parts])
    planes = {name: np.concatenate([p.planes[name] for p in parts]) for name in first.planes}
    return Partial(
        (first.rows[0], parts[-1].rows[1]),
        key,
        planes,
        None,
        _merge_counts([p.sent for p in parts]),
        _merge_counts([p.seconds for p in parts]),
        _merge_counts([p.counts for p in parts]),
    )
