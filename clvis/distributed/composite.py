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
bands (IceT's direct-send). A partial may also be a *rectangle* of the frame
(``cols`` and ``empty`` given: a volume brick's screen footprint): pixels
outside it are empty, so rectangles composite onto their union (or a given
rectangle) filled with the planes' ``empty`` values, a band of a rectangle
is its intersection with the band (IceT composites image regions the same
way), and only the footprints' pixels are sent. NumPy definition:
``clvis.reference.distributed.composite``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from .._keys import key_f32, key_f32_inverse

__all__ = [
    "COMPOSITING",
    "DIRECT_SEND_MAX_WORKERS_POINTS",
    "DIRECT_SEND_MAX_WORKERS_VOLUMES",
    "EMPTY_KEY",
    "Partial",
    "assemble",
    "bands",
    "composite",
    "depth_keys",
    "depths_of",
    "ids_of",
    "schedule",
    "split",
]

EMPTY_KEY = np.uint64(0xFFFFFFFFFFFFFFFF)

# The compositing schedules a distributed renderer takes: "auto" picks one
# by the number of workers (schedule()).
COMPOSITING = ("auto", "direct", "tree")

# "auto" composites by direct-send up to these worker counts and by the
# binary tree beyond: where the projections in bench/results/
# distributed-cpu.md cross (Dask's ~1 ms of scheduler time per task makes
# direct-send's P^2 band tasks cost more than the tree's ceil(log2 P)
# levels of merges and transfers, each level a full frame for points, a
# footprint's union for volumes). Points at 1920x1080 (93 ms to merge a
# frame, 20 ms to send it): direct-send is cheaper up to 20 workers (at 20:
# 4.58 s against 4.61 s for 10^10 points), the tree from 21. Volume
# footprints, 512^3 at 512x512: the two are within 8 ms of each other up to
# 5 workers and the tree is cheaper from 6 on (at 8: 143 ms against 186 ms).
DIRECT_SEND_MAX_WORKERS_POINTS = 20
DIRECT_SEND_MAX_WORKERS_VOLUMES = 5


def schedule(compositing: str, workers: int, direct_max: int) -> str:
    """The schedule a frame over `workers` partials uses: "direct" or
    "tree" as given; "auto": "direct" up to `direct_max` workers (one of
    the DIRECT_SEND_MAX_WORKERS_* constants), "tree" beyond."""
    if compositing not in COMPOSITING:
        raise ValueError(f"compositing: expected one of {COMPOSITING}, got {compositing!r}")
    if compositing != "auto":
        return compositing
    return "direct" if workers <= direct_max else "tree"


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
    ``counts``: named counts of it (summed when partials are composited).
    ``cols``: the first column and the end (default: from 0, the key's
    width); ``empty``: plane name → its value at an empty pixel (0 when not
    named). With ``empty`` given the partial is a rectangle: it composites
    with partials of other rectangles and is cut to bands by intersection."""

    rows: tuple[int, int]
    key: np.ndarray
    planes: dict
    worker: str | None = None
    sent: dict = dataclasses.field(default_factory=dict)
    seconds: dict = dataclasses.field(default_factory=dict)
    counts: dict = dataclasses.field(default_factory=dict)
    cols: tuple[int, int] | None = None
    empty: dict | None = None

    @property
    def rect(self) -> tuple[int, int, int, int]:
        """(first row, end row, first column, end column) of the frame."""
        c0 = self.cols[0] if self.cols is not None else 0
        return self.rows[0], self.rows[1], c0, c0 + self.key.shape[1]

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


def _union(parts: Sequence[Partial]) -> tuple[int, int, int, int]:
    """The smallest rectangle holding every part with pixels (the first's
    when none has)."""
    rects = [p.rect for p in parts if p.key.size]
    if not rects:
        return parts[0].rect
    return (
        min(r[0] for r in rects),
        max(r[1] for r in rects),
        min(r[2] for r in rects),
        max(r[3] for r in rects),
    )


def _paste(parts: Sequence[Partial], rect: tuple[int, int, int, int]) -> tuple[np.ndarray, dict]:
    """(key, planes) of `rect`: empty, then each part's pixels inside it where
    its key is smaller."""
    r0, r1, c0, c1 = rect
    first = parts[0]
    empty = first.empty or {}
    key = np.full((r1 - r0, c1 - c0), EMPTY_KEY, np.uint64)
    planes = {
        name: np.full((r1 - r0, c1 - c0) + a.shape[2:], empty.get(name, 0), a.dtype)
        for name, a in first.planes.items()
    }
    for p in parts:
        pr0, pr1, pc0, pc1 = p.rect
        a0, a1, b0, b1 = max(pr0, r0), min(pr1, r1), max(pc0, c0), min(pc1, c1)
        if a0 >= a1 or b0 >= b1:
            continue
        src = (slice(a0 - pr0, a1 - pr0), slice(b0 - pc0, b1 - pc0))
        dst = (slice(a0 - r0, a1 - r0), slice(b0 - c0, b1 - c0))
        k, pk = key[dst], p.key[src]
        take = pk < k
        k[take] = pk[take]
        for name, a in planes.items():
            a[dst][take] = p.planes[name][src][take]
    return key, planes


def composite(
    parts: Sequence[Partial], worker: str | None = None, rect: tuple[int, int, int, int] | None = None
) -> Partial:
    """The per-pixel smallest key over `parts` (all of the same rows and the
    same planes, or rectangles: onto `rect`, default their union), with the
    winner's planes. `worker`: where this runs; the bytes of every part held
    elsewhere are counted as sent by its worker."""
    if not parts:
        raise ValueError("parts: nothing to composite")
    first = parts[0]
    same = rect is None and all(p.rect == first.rect and p.key.shape == first.key.shape for p in parts)
    for p in parts[1:]:
        if p.planes.keys() != first.planes.keys() or not same and (p.empty is None or first.empty is None):
            raise ValueError(
                f"parts: partials of rows {p.rows} / shape {p.key.shape} / planes {sorted(p.planes)} "
                f"cannot be composited with rows {first.rows} / {first.key.shape} / {sorted(first.planes)}"
            )
    if same:
        key = first.key.copy()
        planes = {name: a.copy() for name, a in first.planes.items()}
        for p in parts[1:]:
            take = p.key < key
            key[take] = p.key[take]
            for name, a in planes.items():
                a[take] = p.planes[name][take]
        r0, r1, c0, c1 = first.rect
    else:
        r0, r1, c0, c1 = rect if rect is not None else _union(parts)
        key, planes = _paste(parts, (r0, r1, c0, c1))
    sent = _merge_counts([p.sent for p in parts])
    for p in parts:
        if p.worker is not None and p.worker != worker:
            sent[p.worker] = sent.get(p.worker, 0) + p.nbytes
    seconds = _merge_counts([p.seconds for p in parts])
    counts = _merge_counts([p.counts for p in parts])
    cols = first.cols if same else (c0, c1)
    return Partial((r0, r1), key, planes, worker, sent, seconds, counts, cols, first.empty)


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
    if part.empty is not None:  # a rectangle: its intersection with the band (maybe no rows)
        r0, r1 = min(max(r0, a0), r1), max(min(r1, a1), r0)
        r1 = max(r0, r1)
    elif not a0 <= r0 <= r1 <= a1:
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
        part.cols,
        part.empty,
    )


def assemble(parts: Sequence[Partial], frame: tuple[int, int] | None = None) -> Partial:
    """Bands that tile a frame, in any order, stacked into one partial; or
    rectangles (partials with ``empty``) placed in a frame of `frame`
    (height, width) rows and columns."""
    if frame is not None and any(p.empty is not None for p in parts):
        key, planes = _paste(parts, (0, frame[0], 0, frame[1]))
        return Partial(
            (0, frame[0]),
            key,
            planes,
            None,
            _merge_counts([p.sent for p in parts]),
            _merge_counts([p.seconds for p in parts]),
            _merge_counts([p.counts for p in parts]),
            None,
            parts[0].empty,
        )
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
