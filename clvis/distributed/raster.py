"""Sort-last rendering of a partitioned point cloud on Dask workers.

:class:`DistributedRasterizer` spreads a cloud over the workers of a
``dask.distributed`` cluster (a ``LocalCluster`` of its own by default) and
renders it as one device would render the concatenated cloud:

1. open: each partition (a point file, read on a worker and never shipped
   from the client, or a block of dask arrays) is read where it will be
   rendered; the worker sends back a few numbers (count, origin, attribute
   names, value ranges);
2. build: the client fixes the common origin (the smallest of the
   partitions' origins: LAS tiles are stored relative to their own minimum),
   the offsets of the partitions in the concatenated order, and the value
   range of every attribute over the whole cloud; each worker shifts its
   points to the common origin (float64, then float32, as
   :func:`concatenate` does) and keeps a :class:`clvis.raster.Rasterizer` of
   them in a per-process registry. The futures the client holds are small
   handles naming them: the points stay on the workers across frames;
3. a frame: each worker renders its partitions, turns local indices into
   global ids (offset + index) and composites them by the smallest
   ``depth key << 32 | id`` (:mod:`clvis.distributed.composite`); then
   direct-send (each worker's frame cut into one band of rows per worker,
   band j composited on worker j, the bands gathered by the client) or a
   binary tree of pairwise composites. Ties between partitions go to the
   lowest global id, as on one device, so the G-buffers (index, depth, rgba,
   attributes, velocity, radius) are the single device's bit for bit.

Faults: the handles are Dask futures, so a worker lost in the middle of a
frame has its partitions re-opened elsewhere by the scheduler; a frame task
that finds a partition missing from its process's registry rebuilds it from
the handle (the file, the offset, the origin), so the frame completes with
the same result. A partition file that cannot be read raises the clvis
``DataError`` naming it on the client; a worker without a usable OpenCL
device raises ``DeviceError`` naming the worker.

Workers get their device as the rest of clvis does (``runtime.default_queue``:
CLVIS_DEVICE, PYOPENCL_CTX, a GPU, PoCL); they inherit the environment of
the process that starts the cluster.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .._arrays import on_host
from ..camera import Camera, aspect_checked, check_aspect
from ..errors import ClvisError, DataError, DeviceError
from ..io import PointCloud, read_points
from ..raster import EMPTY, GBuffers, Rasterizer
from . import composite as _c
from .cluster import (
    CONNECT_TIMEOUT,
    REGISTRY,
    ClusterOwner,
    current_worker,
    device_error,
    forget,
    frame_seconds,
)

if TYPE_CHECKING:
    import pyopencl as cl

__all__ = ["COMPOSITING", "DistributedRasterizer", "concatenate"]

COMPOSITING = _c.COMPOSITING
_FIELDS = ("index", "depth", "rgba", "vel2d", "vel_angle", "vel_speed", "radius_px")
# in this process's registry (cluster.REGISTRY): a partition's token → its
# PointCloud read but not built yet; a handle's token ("raster:" + its
# partitions' tokens) → the Rasterizer of its partitions


def concatenate(clouds: Sequence[PointCloud], origin: Any = None) -> PointCloud:
    """One cloud of `clouds` in order, positions relative to `origin`
    (default: the smallest of their origins): each cloud's positions + (its
    origin - origin) in float64, then float32: what the workers render."""
    clouds = list(clouds)
    if not clouds:
        raise ValueError("clouds: nothing to concatenate")
    o = np.min([c.origin for c in clouds], axis=0) if origin is None else np.asarray(origin, np.float64)
    names = list(clouds[0].attributes)
    for c in clouds:
        if list(c.attributes) != names:
            raise DataError(f"clouds: attributes {list(c.attributes)} differ from the first cloud's {names}")

    def cat(field: str) -> np.ndarray | None:
        vals = [getattr(c, field) for c in clouds]
        if all(v is None for v in vals):
            return None
        if any(v is None for v in vals):
            raise DataError(f"clouds: some have {field} and some do not")
        return np.concatenate(vals)

    return PointCloud(
        np.concatenate([_shift(c, o) for c in clouds]),
        cat("colors"),
        {k: np.concatenate([c.attributes[k] for c in clouds]) for k in names},
        cat("velocity"),
        cat("radius"),
        o,
    )


def _shift(cloud: PointCloud, origin: np.ndarray) -> np.ndarray:
    d = cloud.origin - origin
    if not d.any():
        return cloud.positions
    return (cloud.positions.astype(np.float64) + d).astype(np.float32)


# ---------------------------------------------------------------- the workers' side


def _read(spec: dict) -> PointCloud:
    """A partition's cloud: its file read here, or its arrays."""
    if spec["path"] is not None:
        path = spec["path"]
        try:
            cloud = read_points(path)
        except FileNotFoundError as e:
            raise DataError(f"{path}: no such file (on worker {current_worker()})") from e
        except ClvisError as e:
            msg = str(e)
            raise DataError(msg if path in msg else f"{path}: {msg}") from e
        except OSError as e:
            if e.strerror is None:
                raise DataError(f"{path}: cannot read it as a point cloud: {e}") from e
            # the worker's reason (a permission it lacks, a file gone bad)
            raise DataError(f"{path}: cannot read it on worker {current_worker()}: {e.strerror}") from e
        except (ValueError, TypeError) as e:
            raise DataError(f"{path}: cannot read it as a point cloud: {e}") from e
        keep = spec["fields"]
        if keep is not None:
            missing = [k for k in keep if k not in cloud.attributes]
            if missing:
                raise DataError(f"{path}: no attribute {missing[0]!r}; it has {list(cloud.attributes)}")
            cloud.attributes = {k: cloud.attributes[k] for k in keep}
        return cloud
    a = spec["arrays"]
    try:
        return PointCloud(
            a["positions"],
            a.get("colors"),
            dict(a.get("attributes") or {}),
            a.get("velocity"),
            a.get("radius"),
        )
    except (TypeError, ValueError) as e:
        raise DataError(f"partition {spec['number']}: {e}") from e


def _meta(cloud: PointCloud) -> dict:
    ranges = {}
    for k, v in cloud.attributes.items():
        f = v[np.isfinite(v)] if v.dtype.kind == "f" else v
        ranges[k] = (float(f.min()), float(f.max())) if f.size else None
    c = cloud.colors
    return {
        "n": len(cloud),
        "origin": cloud.origin.copy(),
        "names": list(cloud.attributes),
        "dtypes": [str(v.dtype) for v in cloud.attributes.values()],
        "fields": tuple(f for f in ("colors", "velocity", "radius") if getattr(cloud, f) is not None),
        "ranges": ranges,
        # (its first colour, whether its colours vary), None without colours or points
        "colors": None
        if c is None or not len(c)
        else (c[0, :3].tolist(), bool((c[:, :3] != c[:1, :3]).any())),
    }


def _bounds(cloud: PointCloud) -> tuple[np.ndarray, np.ndarray] | None:
    """(min, max) of the finite positions as stored (local coordinates), or None."""
    try:
        return cloud.bounds()
    except ValueError:  # no finite point
        return None


def _open(spec: dict, arrays: Any = None) -> dict:
    """Task: read the partition, keep it in this process, return its meta."""
    if arrays is not None:
        spec = {**spec, "arrays": arrays}
    cloud = _read(spec)
    REGISTRY.put(spec["token"], cloud)
    return _meta(cloud)


class _Handle:
    """What the client holds for the partitions one worker opened, built into
    one Rasterizer there: its name in the worker's registry and how to build
    it again. Small, so Dask never moves points."""

    def __init__(self, specs: list, origin: np.ndarray, offsets: list, ns: list, options: dict) -> None:
        self.specs = [{k: v for k, v in spec.items() if k != "arrays"} for spec in specs]
        self.origin, self.offsets, self.ns, self.options = origin, list(offsets), list(ns), options
        self.worker = current_worker()
        self.device_bytes = 0
        #: (min, max) of its points relative to origin, float64 (None: no finite point)
        self.bounds: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def token(self) -> str:
        return "raster:" + "|".join(s["token"] for s in self.specs)

    def global_ids(self, index: np.ndarray) -> np.ndarray:
        """The Rasterizer's indices (its partitions one after the other, in
        the global order) as global ids; EMPTY stays EMPTY."""
        covered = index != EMPTY
        ends = np.cumsum(self.ns)
        local = index[covered].astype(np.int64)
        k = np.searchsorted(ends, local, side="right")
        starts = ends - np.asarray(self.ns)
        out = np.full(index.shape, EMPTY, np.uint32)
        out[covered] = (local - starts[k] + np.asarray(self.offsets, np.int64)[k]).astype(np.uint32)
        return out


def _queue() -> cl.CommandQueue:
    from .. import runtime

    try:
        return runtime.default_queue()
    except ClvisError as e:
        raise device_error(e) from e
    except Exception as e:  # pyopencl's own (no platform, ICD loader errors)
        raise device_error(e) from e


def _build_here(handle: _Handle, arrays: Any = None) -> Rasterizer:
    clouds = []
    for i, (spec, n) in enumerate(zip(handle.specs, handle.ns, strict=True)):
        cloud = REGISTRY.pop(spec["token"])
        if cloud is None:  # opened on another worker, or this process is new
            cloud = _read({**spec, "arrays": arrays[i]} if arrays is not None else spec)
        if len(cloud) != n:
            raise DataError(
                f"{spec['path'] or 'partition {}'.format(spec['number'])}: "
                f"{len(cloud)} points now, {n} when it was opened"
            )
        clouds.append(cloud)
    # one cloud of this worker's partitions in their global order, so that
    # ties between them still go to the lowest global id
    cloud = clouds[0] if len(clouds) == 1 else concatenate(clouds, handle.origin)
    del clouds
    q = _queue()
    o = handle.options
    try:
        # a PointCloud, not its fields as arguments: a LAS file has more
        # attributes than one render resolves (render(planes=) picks)
        shifted = PointCloud(
            _shift(cloud, handle.origin),
            colors=cloud.colors,
            attributes=cloud.attributes,
            velocity=cloud.velocity,
            radius=cloud.radius,
            origin=handle.origin,
        )
        handle.bounds = _bounds(shifted)
        r = Rasterizer(
            shifted,
            morton=o["morton"],
            batch_size=o["batch_size"],
            queue=q,
        )
    except DeviceError as e:
        raise device_error(e) from e
    return REGISTRY.put(handle.token, r)


def _build(
    specs: list, origin: np.ndarray, offsets: list, ns: list, options: dict, arrays: Any = None
) -> _Handle:
    """Task: one Rasterizer of these partitions, kept in this process."""
    h = _Handle(specs, origin, offsets, ns, options)
    r = _build_here(h, arrays)
    h.device_bytes = int(r.positions.nbytes)
    return h


def _rasterizer(handle: _Handle, arrays: Any = None) -> Rasterizer:
    r = REGISTRY.get(handle.token)
    return r if r is not None else _build_here(handle, arrays)


_STATS = ("points", "batches", "batches_drawn", "points_read", "points_nonfinite")


def render_one(handle: _Handle, arrays: Any, view: dict) -> _c.Partial:
    """The full-frame partial of one handle's Rasterizer (cluster.render_partial
    composites a worker's): index and depth travel in the key, global ids."""
    r = _rasterizer(handle, arrays)
    with aspect_checked():  # the client's render() checked the camera: no warning per partition
        g = r.render(
            view["camera"],
            view["width"],
            view["height"],
            color_by=view["color_by"],
            colormap=view["colormap"],
            value_range=view["value_range"],
            planes=view["planes"],
            point_size=view["point_size"],
        )
    covered = on_host(g.index) != EMPTY
    index = handle.global_ids(on_host(g.index))
    planes = {}  # index and depth travel in the key
    for f in _FIELDS[2:]:
        a = getattr(g, f)
        if a is not None:
            planes[f] = a
    for k, a in g.attributes.items():
        planes["attr:" + k] = a
    key = _c.depth_keys(on_host(g.depth), index, covered)
    counts = {k: g.stats.get(k, 0) for k in _STATS}
    return _c.Partial((0, view["height"]), key, planes, current_worker(), counts=counts)


def _sample(handle: _Handle, arrays: Any, step: int) -> tuple[np.ndarray, np.ndarray]:
    """Task: (global ids, positions) of the handle's points whose global id
    is a multiple of `step`: float32 positions relative to the common origin,
    as the Rasterizer holds them."""
    r = _rasterizer(handle, arrays)
    ids, local = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    start = 0
    for off, n in zip(handle.offsets, handle.ns, strict=True):
        first = -off % step  # the first multiple of step at or after off, from off
        k = np.arange(first, n, step, dtype=np.int64)
        ids.append(off + k)
        local.append(start + k)
        start += n
    idx = np.concatenate(local)
    if not len(idx):
        return np.zeros(0, np.int64), np.zeros((0, 3), np.float32)
    pos = r.positions.get()
    if r.inv is not None:  # Morton order on the device: the caller's index i sits at inv[i]
        idx = r.inv.get()[idx]
    return np.concatenate(ids), pos[idx]


def _fenced(handle: _Handle, arrays: Any, fences: tuple, step: int | None = None, starts: Any = None) -> list:
    """Task: the handle's points inside the fences (lo, hi), per partition in
    order (what clvis.camera.robust_bounds keeps of the concatenated cloud).
    step None: (offset, kept, finite, min, max) per partition (its global
    offset, the counts of its points inside and of its finite points; min,
    max of those inside, float32 (3,), None when it keeps none); else, with
    `starts` (global offset → the rank among the kept points of that
    partition's first), (ranks, positions) of the kept points whose rank
    is a multiple of `step`."""
    r = _rasterizer(handle, arrays)
    pos = r.positions.get()
    if r.inv is not None:  # Morton order on the device: back to the partitions' order
        pos = pos[r.inv.get()]
    lo, hi = fences
    out: list = []
    start = 0
    for off, n in zip(handle.offsets, handle.ns, strict=True):
        p = pos[start : start + n]
        start += n
        with np.errstate(invalid="ignore"):
            q = p[((p >= lo) & (p <= hi)).all(axis=1)]  # NaN and inf compare False: left out
        if step is None:
            finite = int(np.isfinite(p).all(axis=1).sum())
            out.append(
                (off, len(q), finite, q.min(axis=0) if len(q) else None, q.max(axis=0) if len(q) else None)
            )
        else:
            r0 = int(starts.get(off, 0)) if len(q) else 0
            first = -r0 % step
            out.append((r0 + np.arange(first, len(q), step, dtype=np.int64), q[first::step]))
    return out


# ---------------------------------------------------------------- the client's side


class DistributedRasterizer(ClusterOwner):
    """A point cloud spread over Dask workers, rendered as one device would
    render the concatenated cloud (the module doc says how).

    sources: a sequence of point files (PLY, LAS, LAZ, NPY, NPZ), each a
    partition, read on the workers (the paths must be valid there); or dask
    arrays: ``positions`` (N, 3), partitioned by its chunks along the first
    axis, with ``colors`` (N, 3|4), ``attributes`` (name → (N,)),
    ``velocity``, ``radius`` chunked alike. The concatenated order (the
    files in order, or the arrays) gives the global point ids.

    client: a ``dask.distributed.Client``; None starts a ``LocalCluster`` of
    `workers` processes of one thread each (closed with :meth:`close` or the
    ``with`` block). fields: for files, the attributes to keep (default all;
    every file must have them). morton, batch_size: the Rasterizers'.
    compositing: "auto" (default: direct-send up to
    ``composite.DIRECT_SEND_MAX_WORKERS_POINTS`` workers, the binary tree
    beyond), "direct" (direct-send) or "tree". timeout: seconds
    any wait on the cluster may take (a build, a frame) before a
    :class:`clvis.errors.ClusterTimeout` (a ``TimeoutError``) saying what
    timed out; connect_timeout: seconds to reach a scheduler given by
    address (a refused connection fails at once). A render after
    :meth:`close` raises :class:`clvis.errors.ClusterError`.
    """

    def __init__(
        self,
        sources: Any,
        client: Any = None,
        *,
        colors: Any = None,
        attributes: Mapping[str, Any] | None = None,
        velocity: Any = None,
        radius: Any = None,
        fields: Sequence[str] | None = None,
        morton: bool = True,
        batch_size: int = 10240,
        compositing: str = "auto",
        workers: int = 2,
        timeout: float = 300.0,
        connect_timeout: float = CONNECT_TIMEOUT,
    ) -> None:
        if compositing not in COMPOSITING:
            raise ValueError(f"compositing: expected one of {COMPOSITING}, got {compositing!r}")
        self.compositing = compositing
        specs, arrays = self._partitions(sources, colors, attributes, velocity, radius, fields)
        super().__init__(client, workers, timeout, connect_timeout)
        try:
            self._setup(specs, arrays, {"morton": bool(morton), "batch_size": int(batch_size)})
        except BaseException:
            self.close()
            raise

    # -- partitions
    @staticmethod
    def _partitions(
        sources: Any,
        colors: Any,
        attributes: Mapping[str, Any] | None,
        velocity: Any,
        radius: Any,
        fields: Sequence[str] | None,
    ) -> tuple[list[dict[str, Any]], list[Any]]:
        token = uuid.uuid4().hex
        if hasattr(sources, "to_delayed") and hasattr(sources, "chunks"):
            pos = sources
            if pos.ndim != 2 or pos.shape[1] != 3:
                raise ValueError(f"sources: dask positions must have shape (N, 3), got {pos.shape}")
            pos = pos.rechunk({1: 3})
            chunks = pos.chunks[0]
            extra = {"colors": colors, "velocity": velocity, "radius": radius}
            blocks: dict[str, list] = {"positions": list(pos.to_delayed().ravel())}
            for name, a in extra.items():
                if a is not None:
                    blocks[name] = _blocks(name, a, chunks)
            attrs = {k: _blocks(f"attributes[{k!r}]", a, chunks) for k, a in (attributes or {}).items()}
            specs: list[dict[str, Any]] = []
            arrays: list[Any] = []
            for i in range(len(chunks)):
                specs.append({"token": f"{token}-{i}", "path": None, "number": i, "fields": None})
                d = {name: b[i] for name, b in blocks.items()}
                d["attributes"] = {k: b[i] for k, b in attrs.items()}
                arrays.append(d)
            return specs, arrays
        if isinstance(sources, (str, os.PathLike)):
            sources = [sources]
        if any(x is not None for x in (colors, attributes, velocity, radius)):
            raise ValueError("colors, attributes, velocity, radius: only with dask array sources")
        paths = []
        for s in sources:
            if not isinstance(s, (str, os.PathLike)):
                raise TypeError(f"sources: expected point file paths or a dask array, got {type(s).__name__}")
            # absolute: workers started elsewhere (dask worker in another
            # folder, on a shared file system) read the file the client checked
            paths.append(os.path.abspath(s))
        if not paths:
            raise ValueError("sources: no partition given")
        keep = None if fields is None else [str(f) for f in fields]
        specs = [
            {"token": f"{token}-{i}", "path": p, "number": i, "fields": keep} for i, p in enumerate(paths)
        ]
        return specs, [None] * len(specs)

    def _setup(self, specs: list[dict[str, Any]], arrays: list[Any], options: dict[str, Any]) -> None:
        client = self.client
        if any(a is not None for a in arrays):
            arrays = [_computed(client, a) for a in arrays]  # the blocks, kept on the workers
        opened = [client.submit(_open, s, a, pure=False) for s, a in zip(specs, arrays, strict=True)]
        self.hold([], [], [s["token"] for s in specs])  # what close() lets go of if this fails
        metas = self._gather(opened, f"opening {len(specs)} partitions")
        self._check_partitions(specs, metas)
        origin = np.min([m["origin"] for m in metas], axis=0)
        counts = [m["n"] for m in metas]
        offsets = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        self.n = int(sum(counts))
        if self.n >= 0xFFFFFFFF:
            raise DeviceError(f"sources: {self.n} points; at most 2^32 - 2 (0xFFFFFFFF marks empty pixels)")
        self.origin = origin
        self.counts = counts
        self.offsets = [int(o) for o in offsets]
        self.attribute_names = metas[0]["names"]
        self.fields = metas[0]["fields"]
        self._ranges = {k: _merge_ranges([m["ranges"][k] for m in metas]) for k in self.attribute_names}
        #: attribute name → whether it holds more than one finite value over the cloud
        self.varies = {
            k: len({v for m in metas if m["ranges"][k] is not None for v in m["ranges"][k]}) > 1
            for k in self.attribute_names
        }
        colours = [m["colors"] for m in metas if m["colors"] is not None]
        #: whether the cloud has colours of more than one value (red, green, blue)
        self.colors_vary = any(v for _, v in colours) or len({tuple(f) for f, _ in colours}) > 1
        # the partitions each worker opened become one Rasterizer there: one
        # render, one resolve and one partial per worker and frame
        where = self._who_has(opened)
        groups: dict = {}
        for i, f in enumerate(opened):
            groups.setdefault(where.get(f.key), []).append(i)
        members = list(groups.values())
        held = [[arrays[i] for i in idx] if arrays[idx[0]] is not None else None for idx in members]

        def build(k: int, worker: str | None = None) -> Any:
            idx = members[k]
            return client.submit(
                _build,
                [specs[i] for i in idx],
                origin,
                [int(offsets[i]) for i in idx],
                [int(counts[i]) for i in idx],
                options,
                held[k],
                pure=False,
                **self._pin(worker),
            )

        handles = [build(k, w) for k, w in enumerate(groups)]
        self.npartitions = len(specs)
        names = [", ".join(specs[i]["path"] or f"partition {i}" for i in idx) for idx in members]
        built = self._gather_built(handles, f"building {len(handles)} Rasterizers", build, names)
        self.device_bytes = int(sum(h.device_bytes for h in built))
        b = [h.bounds for h in built if h.bounds is not None]
        self.bounds = (  # of the float32 positions the workers hold: the concatenated cloud's, exactly
            (np.min([x[0] for x in b], axis=0), np.max([x[1] for x in b], axis=0)) if b else None
        )
        self.hold(handles, held, [s["token"] for s in specs] + [h.token for h in built])
        self._run_on_workers(forget, [s["token"] for s in specs])  # clouds opened where not built

    def _check_partitions(self, specs: list[dict[str, Any]], metas: list[dict[str, Any]]) -> None:
        def name(i: int) -> str:
            return specs[i]["path"] or f"partition {i}"

        for i, m in enumerate(metas[1:], 1):
            for what in ("names", "dtypes", "fields"):
                if m[what] != metas[0][what]:
                    raise DataError(
                        f"{name(i)}: its {'attributes' if what != 'fields' else 'fields'} "
                        f"{m[what]} differ from {name(0)}'s {metas[0][what]}"
                    )

    def sample(self, limit: int = 200_000) -> np.ndarray:
        """Every k-th point of the concatenated cloud (k = max(1, n // limit),
        the points whose global id is a multiple of k), float32 (m, 3)
        relative to :attr:`origin`: the same rows, bit for bit, as
        ``concatenate(clouds).positions[::k]`` on one device, so a view
        fitted to a sample frames the cloud the same way on both."""
        self._check_open()
        if isinstance(limit, bool) or not isinstance(limit, (int, np.integer)) or limit < 1:
            raise ValueError(f"limit: expected a positive int, got {limit!r}")
        return self._every(max(1, self.n // int(limit)))

    def _every(self, step: int) -> np.ndarray:
        """The points whose global id is a multiple of `step`, in order."""
        where = self._who_has(self._handles)
        futures = [
            self.client.submit(_sample, h, a, step, pure=False, **self._near(where, h))
            for h, a in zip(self._handles, self._arrays, strict=True)
        ]
        got = self._gather(futures, f"a sample of every {step}th point")
        ids = np.concatenate([g[0] for g in got] + [np.zeros(0, np.int64)])
        pos = np.concatenate([g[1] for g in got] + [np.zeros((0, 3), np.float32)])
        return pos[np.argsort(ids, kind="stable")]

    def framing(self, limit: int = 200_000) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
        """(lo, hi, points, kept, total): the framing of the concatenated cloud
        that one device gives it (``clvis.camera.robust_bounds``: the box of
        the bulk, stray points far outside it left out; the fences from the
        same sample rows), with the points to fit a view to (every k-th of
        the kept ones, as ``fit_camera`` samples them on one device), kept
        and total counts of finite points. lo, hi float64 relative to
        :attr:`origin`; points float32 (m, 3). ValueError when no point is
        finite."""
        from ..camera import robust_fences, robust_sample_step

        self._check_open()
        if isinstance(limit, bool) or not isinstance(limit, (int, np.integer)) or limit < 1:
            raise ValueError(f"limit: expected a positive int, got {limit!r}")
        if self.bounds is None:
            raise ValueError("bounds: the cloud has no finite points")
        fences = robust_fences(self._every(robust_sample_step(self.n)))
        where = self._who_has(self._handles)

        def each(step: int | None, starts: dict | None) -> list:
            futures = [
                self.client.submit(_fenced, h, a, fences, step, starts, pure=False, **self._near(where, h))
                for h, a in zip(self._handles, self._arrays, strict=True)
            ]
            return self._gather(futures, "the points inside the framing fences")

        # (offset, kept, finite, min, max) of every partition, in the global order
        per = sorted((st for sts in each(None, None) for st in sts), key=lambda st: st[0])
        kept, total = sum(st[1] for st in per), sum(st[2] for st in per)
        if kept == total:  # nothing stray: every finite point, as one device frames them
            return self.bounds[0], self.bounds[1], self.sample(limit), kept, total
        lo = np.min([st[3] for st in per if st[1]], axis=0).astype(np.float64)
        hi = np.max([st[4] for st in per if st[1]], axis=0).astype(np.float64)
        # the rank of each partition's first kept point (offsets are unique
        # among partitions that keep points; empty ones share the next's)
        some = [st for st in per if st[1]]
        first = np.cumsum([0] + [st[1] for st in some])[:-1]
        rank = {st[0]: int(r) for st, r in zip(some, first, strict=True)}
        step = max(1, kept // int(limit))
        got = each(step, rank)
        ids = np.concatenate([i for st in got for i, _ in st] + [np.zeros(0, np.int64)])
        pos = np.concatenate([p for st in got for _, p in st] + [np.zeros((0, 3), np.float32)])
        return lo, hi, pos[np.argsort(ids, kind="stable")], kept, total

    # -- frames
    def render(
        self,
        camera: Camera,
        width: int,
        height: int,
        *,
        color_by: str | None = None,
        colormap: str = "viridis",
        value_range: tuple[float, float] | None = None,
        planes: Any = None,
        point_size: int = 1,
    ) -> GBuffers:
        """One view: the G-buffers of the concatenated cloud (see
        ``Rasterizer.render``; soft z needs the colours of every partition
        near a pixel's winner and is not offered). ``stats``: the points'
        counts summed, and ``partitions``, ``workers``, ``compositing``,
        ``seconds`` (frame: wall time on the client; render, composite:
        summed over the workers' tasks), ``bytes_sent`` (worker → bytes its
        partials sent to other workers and to the client)."""
        self._check_open()
        view = self._view(camera, width, height, color_by, colormap, value_range, planes, point_size)
        whole, frame, sent, nworkers = self._frame(render_one, view)
        return self._gbuffers(whole, frame, sent, nworkers)

    def _view(
        self,
        camera: Camera,
        width: int,
        height: int,
        color_by: str | None,
        colormap: str,
        value_range: tuple[float, float] | None,
        planes: Any,
        point_size: int,
    ) -> dict:
        from ..raster.inputs import check_camera, check_point_size, check_size

        check_camera(camera)
        width, height = check_size(width, height)
        check_aspect(camera, width, height)
        check_point_size(point_size)
        if color_by is not None and color_by not in self.attribute_names:
            raise ValueError(
                f"color_by: no attribute {color_by!r}; the cloud has "
                f"{', '.join(self.attribute_names) or 'none'}"
            )
        if color_by is not None and value_range is None:
            value_range = self._ranges[color_by]
        if planes is None:
            planes = list(self.attribute_names) if len(self.attribute_names) <= 8 else []
        return {
            "camera": camera,
            "width": width,
            "height": height,
            "color_by": color_by,
            "colormap": colormap,
            "value_range": value_range,
            "planes": [planes] if isinstance(planes, str) else list(planes),
            "point_size": point_size,
        }

    def _gbuffers(self, whole: _c.Partial, frame: float, sent: dict, nparts: int) -> GBuffers:
        p = whole.planes
        attrs = {k[5:]: v for k, v in p.items() if k.startswith("attr:")}
        g = GBuffers(
            index=_c.ids_of(whole.key),
            depth=_c.depths_of(whole.key),
            rgba=p["rgba"],
            attributes=attrs,
            vel2d=p.get("vel2d"),
            vel_angle=p.get("vel_angle"),
            vel_speed=p.get("vel_speed"),
            radius_px=p.get("radius_px"),
        )
        g.stats = {
            **whole.counts,
            "partitions": self.npartitions,
            "workers": nparts,
            "compositing": self.frame_compositing,
            "seconds": frame_seconds(frame, whole.seconds),
            "bytes_sent": sent,
        }
        return g


def _computed(client: Any, blocks: dict) -> dict:
    """The delayed blocks of one partition as futures (computed on the workers)."""
    out = {k: client.compute(v) for k, v in blocks.items() if k != "attributes"}
    out["attributes"] = {k: client.compute(v) for k, v in blocks["attributes"].items()}
    return out


def _blocks(name: str, a: Any, chunks: tuple) -> list:
    if not (hasattr(a, "to_delayed") and hasattr(a, "chunks")):
        raise TypeError(f"{name}: expected a dask array like the positions, got {type(a).__name__}")
    if a.shape[0] != sum(chunks):
        raise ValueError(f"{name}: {a.shape[0]} rows, the positions have {sum(chunks)}")
    a = a.rechunk({0: chunks, **{k: -1 for k in range(1, a.ndim)}})
    return list(a.to_delayed().ravel())


def _merge_ranges(ranges: list) -> tuple[float, float]:
    """colormap.value_range of the concatenation from the partitions' own
    finite (min, max) (None: no finite value)."""
    r = [x for x in ranges if x is not None]
    if not r:
        return 0.0, 1.0
    return min(x[0] for x in r), max(x[1] for x in r)
