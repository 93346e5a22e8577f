"""Sort-last isosurface rendering of a bricked volume on Dask workers.

:class:`DistributedIsoRenderer` cuts a [z, y, x] volume into bricks whose
cells do not overlap: brick (a_z, a_y, a_x) owns the cells a .. a + B - 1 of
each axis (B, the brick edge in cells, a multiple of 4, so bricks start on
ZFP's 4^3 block grid). It holds the samples a .. a + B + 3: the +1 neighbour
sample the dual grid's last cell needs, and the rest of that neighbour block,
so every ZFP block of the brick is a block of the whole volume: compressed
alone at the same rate it decodes to the same values (fixed-rate zfp codes
blocks independently; the volume's partial blocks at its far faces are
padded the same way). A brick therefore sees exactly the single device's
field in its cells; the cells of the neighbour block it also holds are the
next brick's too and give the same hits.

Each brick is read where it is rendered: from the array given (sliced on the
client), or from a file by slicing a memory map on the worker (.npy, .raw;
NIfTI through nibabel's array proxy), so a volume larger than one worker's
memory renders. By default each worker keeps one :class:`clvis.iso.IsoRenderer`
over the union of its bricks (:func:`worker_plan`: whole z layers of bricks,
one slab per worker; ``per_worker=False``: one per brick), its origin moved
to the slab's first sample, and renders every frame with it, only over the
rectangle of the frame the slab's box projects to (:func:`footprint`,
:func:`window`); a pixel's nearest hit wins by the smallest ``depth key <<
32 | renderer number`` (:mod:`clvis.distributed.composite`), then
direct-send or a tree as for points (:mod:`clvis.distributed.raster`).

Faults: bricks of an in-memory array are scattered from the client, which
keeps the array: a frame whose tasks were cancelled with lost data sends
those bricks again and rebuilds them; a loss not recovered is a
:class:`clvis.errors.ClusterError` naming the bricks and the worker that
held them.

The image is the single device's up to float32 rounding: a brick's rays
enter its own box, so its t and depths are rounded differently; hit masks
and depths agree under the iso tests' rule (``clvis.reference.iso.render.
agreement``: the same hits on reliable pixels, depths within 1e-4 of the
volume's diagonal).
"""

from __future__ import annotations

import math
import os
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._arrays import on_host, triple
from ..camera import Camera, aspect_checked, check_aspect
from ..errors import ClusterError, ClvisError, DataError, DeviceError
from ..iso import IsoImage, IsoRenderer
from . import composite as _c
from .cluster import (
    CONNECT_TIMEOUT,
    REGISTRY,
    ClusterOwner,
    connected_workers,
    current_worker,
    device_error,
    frame_seconds,
)

__all__ = ["DistributedIsoRenderer", "brick_plan", "footprint", "window", "worker_plan"]

ZFP_BLOCK = 4


def brick_plan(shape: Sequence[int], brick: int | Sequence[int]) -> list[tuple[tuple[int, int], ...]]:
    """The bricks of a [z, y, x] volume of `shape` with `brick` cells a side
    (a multiple of 4, per axis or one for all): per brick, the sample range
    (start, stop) of each axis, z first, stop exclusive: start .. start +
    brick + 4 clipped to the volume (its own cells and the next ZFP block)."""
    shape = tuple(int(s) for s in shape)
    if len(shape) != 3 or min(shape) < 2:
        raise DataError(f"volume: every axis needs at least 2 samples, got shape {shape}")
    edges = (brick,) * 3 if isinstance(brick, (int, np.integer)) else tuple(brick)
    if len(edges) != 3 or any(
        isinstance(b, bool) or not isinstance(b, (int, np.integer)) or b < ZFP_BLOCK or b % ZFP_BLOCK
        for b in edges
    ):
        raise ValueError(f"brick: expected a multiple of {ZFP_BLOCK} (or three), got {brick!r}")
    axes = [
        [(a, min(a + int(b) + ZFP_BLOCK, n)) for a in range(0, n - 1, int(b))]
        for n, b in zip(shape, edges, strict=True)
    ]
    return [(z, y, x) for z in axes[0] for y in axes[1] for x in axes[2]]


def worker_plan(bricks: Sequence[tuple], workers: int) -> list[tuple[tuple, int]]:
    """The bricks (brick_plan's, z-major) grouped into one slab per worker:
    the z layers of bricks split into `workers` runs of consecutive layers
    (as even as they come), each run's samples the union of its bricks'
    ranges. (ranges, bricks in it) per slab; the bricks themselves when
    there are fewer z layers than workers."""
    layers: dict = {}
    for r in bricks:
        layers.setdefault(r[0], []).append(r)
    zs = sorted(layers)
    if workers < 1 or len(zs) < workers:
        return [(r, 1) for r in bricks]
    out = []
    for run in np.array_split(np.arange(len(zs)), workers):
        first, last = layers[zs[run[0]]], layers[zs[run[-1]]]
        ranges = (
            (first[0][0][0], last[0][0][1]),
            (min(r[1][0] for r in first), max(r[1][1] for r in first)),
            (min(r[2][0] for r in first), max(r[2][1] for r in first)),
        )
        out.append((ranges, sum(len(layers[zs[k]]) for k in run)))
    return out


# ---------------------------------------------------------------- files, on the workers


def _layout(path: str, shape: Any, dtype: Any, volume_index: Any) -> dict:
    """Task: a volume file's shape (Z, Y, X), spacing (dz, dy, dx) and how to
    slice it, from its header alone."""
    from ..io import npy_shape, volumes

    p = Path(path)
    if not p.is_file():
        raise DataError(f"{path}: no such file (on worker {current_worker()})")
    name = p.name.lower()
    try:
        if name.endswith(".raw"):
            shp, dt = volumes.raw_layout(p, shape, dtype)
            need = math.prod(shp) * dt.itemsize
            if p.stat().st_size != need:
                raise DataError(f"{path}: {p.stat().st_size} bytes, but shape {shp} of {dt} needs {need}")
            return {"kind": "raw", "shape": shp, "dtype": dt.str, "spacing": (1.0, 1.0, 1.0)}
        if shape is not None or dtype is not None:
            raise ValueError(f"shape, dtype: only for .raw files, not {p.name}")
        if name.endswith(".npy"):
            shp = npy_shape(p)
            if len(shp) != 3:
                raise DataError(f"{path}: expected a 3-D volume, got shape {shp}")
            return {"kind": "npy", "shape": tuple(shp), "spacing": (1.0, 1.0, 1.0)}
        if name.endswith(volumes.NIBABEL_FORMATS):  # nibabel's proxy slices them alike
            with open(p, "rb"):  # nibabel says "Cannot work out file type" of a file it may not read
                pass
            try:
                # as read_volume finds them (a pair's other file, or a DataError naming it)
                img = volumes.nibabel_image(p)[0]
                s = tuple(int(v) for v in img.header.get_data_shape())
                zooms = tuple(float(z) for z in img.header.get_zooms())[:3]
                affine = np.asarray(img.affine, np.float64)
            except DataError:
                raise
            except volumes.nibabel_errors() as e:
                raise DataError(f"{path}: not a readable volume header: {type(e).__name__}: {e}") from e
            if len(s) < 3 or any(v != 1 for v in s[3:]) and volume_index is None:
                raise DataError(
                    f"{path}: expected a 3-D volume, got shape {s}"
                    + (
                        f"; choose one of its {s[3]} volumes: volume_index=T (--volume-index T)"
                        if len(s) == 4
                        else ""
                    )
                )
            # as read_volume returns it: the closest RAS+ order of its affine
            ornt = volumes.ras_orientation(affine)
            ras, rz = list(s[:3]), list(zooms)
            if ornt is not None:
                for axis, (to, _) in enumerate(ornt):
                    ras[int(to)], rz[int(to)] = s[axis], zooms[axis]
            return {
                "kind": "nifti",
                "shape": tuple(ras[::-1]),
                "spacing": tuple(rz[::-1]),
                "index": volume_index,
                "stored": s[:3],
                "ornt": None if ornt is None else ornt.tolist(),
            }
    except ClvisError:
        raise
    except OSError as e:
        if e.strerror is None:
            raise DataError(f"{path}: cannot read its header: {type(e).__name__}: {e}") from e
        # the worker's reason (a permission it lacks)
        raise DataError(f"{path}: cannot read it on worker {current_worker()}: {e.strerror}") from e
    except (ValueError, TypeError, ImportError) as e:
        raise DataError(f"{path}: cannot read its header: {type(e).__name__}: {e}") from e
    raise DataError(
        f"{path}: not a volume format the workers slice brick by brick (.npy, .raw, "
        f"{', '.join(volumes.NIBABEL_FORMATS)}); one device reads the others (clvis.read_volume; "
        "the command without --workers/--scheduler)"
    )


def _read_brick(spec: dict) -> np.ndarray:
    """A brick's samples as float32 [z, y, x]: sliced from the client's array
    or from a memory map of the file (only the brick's pages are read)."""
    (z0, z1), (y0, y1), (x0, x1) = spec["ranges"]
    src = spec["source"]
    if isinstance(src, np.ndarray):
        return np.ascontiguousarray(src, np.float32)
    path, lay = src
    try:
        if lay["kind"] == "npy":
            a = np.load(path, mmap_mode="r", allow_pickle=False)[z0:z1, y0:y1, x0:x1]
        elif lay["kind"] == "raw":
            m = np.memmap(path, dtype=np.dtype(lay["dtype"]), mode="r", shape=tuple(lay["shape"]))
            a = m[z0:z1, y0:y1, x0:x1]
        else:
            from ..io.volumes import nibabel_image

            proxy = nibabel_image(Path(path))[0].dataobj
            want = ((x0, x1), (y0, y1), (z0, z1))  # along R, A, S (the volume as read_volume gives it)
            ornt = lay.get("ornt")
            if ornt is None:
                sl = tuple(slice(lo, hi) for lo, hi in want)
            else:  # each stored axis: the range of it that lands in the brick
                sl = tuple(
                    slice(*want[int(to)]) if flip > 0 else slice(n - want[int(to)][1], n - want[int(to)][0])
                    for (to, flip), n in zip(ornt, lay["stored"], strict=True)
                )
            a = np.asarray(proxy[sl + ((lay["index"],) if lay.get("index") is not None else ())])
            a = a.reshape(a.shape[:3])
            if ornt is not None:
                from nibabel.orientations import apply_orientation

                a = apply_orientation(a, np.asarray(ornt))
            a = a.transpose(2, 1, 0)
        if a.dtype.kind not in "iuf":
            raise DataError(f"{path}: expected real numbers, got dtype {a.dtype}")
        out = np.ascontiguousarray(a, np.float32)
    except ClvisError:
        raise
    except (OSError, ValueError, TypeError, EOFError) as e:
        raise DataError(f"{path}: cannot read brick {spec['ranges']}: {type(e).__name__}: {e}") from e
    if not np.isfinite(out).all():
        raise DataError(f"{path}: non-finite samples in brick {spec['ranges']} (zfp cannot keep them)")
    return out


class _Handle:
    def __init__(self, spec: dict) -> None:
        self.spec = {k: v for k, v in spec.items() if k != "source" or not isinstance(v, np.ndarray)}
        self.worker = current_worker()
        self.compressed_bytes = 0

    @property
    def token(self) -> str:
        return self.spec["token"]


def _build_here(spec: dict) -> IsoRenderer:
    from .. import runtime

    data = _read_brick(spec)
    try:
        q = runtime.default_queue()
    except Exception as e:  # no platform, an ICD loader error, CLVIS_DEVICE matching nothing
        raise device_error(e) from e
    try:
        r = IsoRenderer(data, spec["rate"], spec["spacing"], spec["origin"], queue=q)
    except DeviceError as e:
        raise device_error(e) from e
    return REGISTRY.put(spec["token"], r)


def _build(spec: dict) -> _Handle:
    """Task: the brick's IsoRenderer, kept in this process."""
    h = _Handle(spec)
    h.compressed_bytes = len(_build_here(spec).volume.stream)
    return h


def _renderer(handle: _Handle, data: Any) -> IsoRenderer:
    r = REGISTRY.get(handle.token)
    if r is None:  # this process never built it (a worker lost, a task moved)
        spec = handle.spec if data is None else {**handle.spec, "source": data}
        r = _build_here(spec)
    return r


EMPTY_PLANES = {"rgba": 0.0, "t": np.inf}  # an IsoImage's planes where no ray hit


def footprint(spec: dict, camera: Camera, width: int, height: int) -> tuple[int, int, int, int] | None:
    """(first row, end row, first column, end column) of the pixels whose
    rays can meet the brick's box (the box of its samples projected, a pixel
    of margin for rounding), clipped to the frame; None when a corner is not
    in front of the eye (then the whole frame)."""
    (z0, z1), (y0, y1), (x0, x1) = spec["ranges"]
    dz, dy, dx = spec["spacing"]
    ox, oy, oz = spec["origin"]
    xs = (ox, ox + (x1 - x0 - 1) * dx)
    ys = (oy, oy + (y1 - y0 - 1) * dy)
    zs = (oz, oz + (z1 - z0 - 1) * dz)
    corners = np.array([[x, y, z, 1.0] for x in xs for y in ys for z in zs])
    clip = corners @ np.asarray(camera.matrix, np.float64).T
    w = clip[:, 3]
    if not camera.orthographic and (w <= 1e-9 * max(1.0, float(np.abs(w).max()))).any():
        return None
    u = (clip[:, 0] / w * 0.5 + 0.5) * width
    v = (0.5 - clip[:, 1] / w * 0.5) * height
    c0 = int(np.clip(np.floor(u.min()) - 1, 0, width))
    c1 = int(np.clip(np.ceil(u.max()) + 1, 0, width))
    r0 = int(np.clip(np.floor(v.min()) - 1, 0, height))
    r1 = int(np.clip(np.ceil(v.max()) + 1, 0, height))
    return r0, max(r0, r1), c0, max(c0, c1)


def window(camera: Camera, width: int, height: int, rect: tuple[int, int, int, int]) -> Camera:
    """The camera whose (c1 - c0) x (r1 - r0) image is the rectangle `rect`
    of `camera`'s width x height one: the same view and depth row, the
    projection followed by the clip-space scale and shift that maps the
    rectangle's NDC onto [-1, 1] (its rays are the frame's, rounded apart)."""
    r0, r1, c0, c1 = rect
    w, h = c1 - c0, r1 - r0
    m = np.eye(4)
    m[0, 0], m[0, 3] = width / w, width / w - 1 - 2 * c0 / w
    m[1, 1], m[1, 3] = height / h, 1 - height / h + 2 * r0 / h
    return Camera(
        camera.view, m @ camera.projection, camera.near, camera.far, camera.orthographic, camera.eye
    )


def render_one(handle: _Handle, data: Any, view: dict) -> _c.Partial:
    """The partial of one brick (cluster.render_partial composites a
    worker's): only the rectangle of the frame its box covers is rendered
    (view["footprints"], default on) and sent; depth and hit travel in the
    key, the brick's number as id."""
    W, H = view["width"], view["height"]
    rect = footprint(handle.spec, view["camera"], W, H) if view.get("footprints", True) else None
    rect = (0, H, 0, W) if rect is None else rect
    r0, r1, c0, c1 = rect
    number = np.uint32(handle.spec["number"])
    counts = {
        "bricks": handle.spec.get("bricks", 1),
        "renderers": 1,
        "passes": 0,
        "pixels": (r1 - r0) * (c1 - c0),
    }
    worker = current_worker()
    if r1 == r0 or c1 == c0:  # off screen
        key = np.full((r1 - r0, c1 - c0), _c.EMPTY_KEY, np.uint64)
        planes = {
            "rgba": np.zeros((r1 - r0, c1 - c0, 4), np.float32),
            "t": np.full((r1 - r0, c1 - c0), np.inf, np.float32),
        }
        return _c.Partial((r0, r1), key, planes, worker, counts=counts, cols=(c0, c1), empty=EMPTY_PLANES)
    cam = view["camera"] if rect == (0, H, 0, W) else window(view["camera"], W, H, rect)
    with aspect_checked():  # the client's render() checked the camera; a window keeps its aspect
        img = _renderer(handle, data).render(
            cam, c1 - c0, r1 - r0, view["isovalue"], speculation=view["speculation"]
        )
    counts["passes"] = int(img.stats.get("passes", 0))
    hit = on_host(img.hit)
    planes = {"rgba": on_host(img.rgba), "t": on_host(img.t)}
    key = _c.depth_keys(on_host(img.depth), np.full(hit.shape, number), hit)
    return _c.Partial((r0, r1), key, planes, worker, counts=counts, cols=(c0, c1), empty=EMPTY_PLANES)


class DistributedIsoRenderer(ClusterOwner):
    """A volume cut into bricks on Dask workers, rendered as one
    :class:`clvis.iso.IsoRenderer` renders it (the module doc says how).

    volume_or_bricks: a 3-D [z, y, x] array (bricks sliced on the client and
    sent to the workers; the client keeps the array, unchanged, to send a
    brick again when a worker is lost with it), or a volume file (.npy, .raw
    with `shape`/`dtype` as :func:`clvis.read_volume` takes them,
    .nii/.nii.gz) read brick by brick on the workers. rate: ZFP bits per
    value. spacing (dz, dy, dx): default the file's (NIfTI) or ones; origin:
    world (x, y, z) of sample [0, 0, 0]. brick: cells per brick edge, a
    multiple of 4 (one int or three). per_worker: one IsoRenderer per
    worker over the union of its bricks (:func:`worker_plan`: whole z
    layers of bricks, one slab per worker: one cache, one pass loop, one
    footprint), when the bricks have at least as many z layers as there
    are workers; False: one IsoRenderer per brick. client, workers,
    compositing, timeout, connect_timeout: as for
    :class:`clvis.distributed.DistributedRasterizer`, but "auto" (the
    default) takes the tree past ``composite.DIRECT_SEND_MAX_WORKERS_VOLUMES``
    workers (footprints' unions are cheaper to merge up a tree than frames).
    """

    direct_send_max = _c.DIRECT_SEND_MAX_WORKERS_VOLUMES

    def __init__(
        self,
        volume_or_bricks: Any,
        client: Any = None,
        *,
        rate: int = 8,
        spacing: Sequence[float] | None = None,
        origin: Sequence[float] = (0.0, 0.0, 0.0),
        brick: int | Sequence[int] = 64,
        shape: Sequence[int] | None = None,
        dtype: Any = None,
        volume_index: int | None = None,
        compositing: str = "auto",
        workers: int = 2,
        timeout: float = 300.0,
        connect_timeout: float = CONNECT_TIMEOUT,
        per_worker: bool = True,
    ) -> None:
        _c.schedule(compositing, 1, self.direct_send_max)  # a clear error for an unknown one
        self.compositing = compositing
        is_path = isinstance(volume_or_bricks, (str, os.PathLike))
        if not is_path:
            v = np.asarray(volume_or_bricks)
            if v.ndim != 3 or v.dtype.kind not in "iuf":
                raise ValueError(f"volume: expected a 3-D real array [Z, Y, X], got {v.dtype} {v.shape}")
        o = triple("origin", origin, positive=False)
        super().__init__(client, workers, timeout, connect_timeout)
        self._source = None if is_path else v
        try:
            if is_path:
                # absolute: workers started elsewhere read the file the client named
                path = os.path.abspath(volume_or_bricks)
                lay = self._gather(
                    [self.client.submit(_layout, path, shape, dtype, volume_index, pure=False)],
                    f"reading the header of {path}",
                )[0]
                self.volume_shape = tuple(lay["shape"])
                default_spacing = lay["spacing"]
            else:
                self.volume_shape = tuple(v.shape)
                default_spacing = (1.0, 1.0, 1.0)
            sp = triple("spacing", default_spacing if spacing is None else spacing, positive=True)
            self.spacing, self.origin = sp, o
            self.bricks = brick_plan(self.volume_shape, brick)
            ws: list[str | None] = [*sorted(connected_workers(self.client, self.timeout))] or [None]
            units = worker_plan(self.bricks, len(ws)) if per_worker else [(r, 1) for r in self.bricks]
            token = uuid.uuid4().hex
            self._specs: list[dict[str, Any]] = []
            for i, (ranges, count) in enumerate(units):
                (z0, _), (y0, _), (x0, _) = ranges
                self._specs.append(
                    {
                        "token": f"{token}-{i}",
                        "number": i,
                        "bricks": count,
                        "ranges": ranges,
                        "rate": rate,
                        "spacing": sp,
                        "origin": (o[0] + x0 * sp[2], o[1] + y0 * sp[1], o[2] + z0 * sp[0]),
                        "source": (path, lay) if is_path else None,
                    }
                )
            tokens = [s["token"] for s in self._specs]
            self.hold([], [], tokens)  # what close() lets go of if this fails
            # consecutive bricks (z-major: slabs) on the same worker: its
            # bricks' footprints make one compact region of the frame
            n = len(self._specs)
            place = [ws[i * len(ws) // n] for i in range(n)]
            arrays = [self._scatter(i, place[i]) for i in range(n)]
            handles = [self._submit_build(i, a, place[i]) for i, a in enumerate(arrays)]
            self.hold(handles, arrays, tokens)
            self._built = self._gather_built(
                self._handles,
                f"building {n} renderers of {len(self.bricks)} bricks",
                lambda i: self._submit_build(i, self._arrays[i]),
                [self._brick_name(i) for i in range(n)],
            )
            self.compressed_bytes = int(sum(h.compressed_bytes for h in self._built))
        except BaseException:
            self.close()
            raise

    def _scatter(self, i: int, worker: str | None = None) -> Any:
        """Brick i's samples sent to `worker` (None: any; a file's: None, read there)."""
        if self._source is None:
            return None
        sl = tuple(slice(a, b) for a, b in self._specs[i]["ranges"])
        return self.client.scatter(
            np.ascontiguousarray(self._source[sl], np.float32),
            workers=None if worker is None else [worker],
            hash=False,
            timeout=self.timeout,
        )

    def _submit_build(self, i: int, data: Any, worker: str | None = None) -> Any:
        if worker is None and data is not None:  # where the scatter put it
            worker = self._who_has([data]).get(data.key)
        near = self._pin(worker)
        return self.client.submit(_build_from, self._specs[i], data, pure=False, **near)

    def _recover(self) -> None:
        """Bricks of an array lost with a worker: sent again from the
        client's array and built again (file bricks: Dask builds them again)."""
        if self._source is None:
            return
        lost = self._lost()
        for i in lost:
            self._arrays[i] = self._scatter(i)
            self._handles[i] = self._submit_build(i, self._arrays[i])
        handles = [self._handles[i] for i in lost]
        try:
            rebuilt = self._gather_built(
                handles,
                f"rebuilding {len(lost)} lost bricks",
                lambda k: self._submit_build(lost[k], self._arrays[lost[k]]),
                [self._brick_name(i) for i in lost],
            )
        except ClusterError as e:
            raise ClusterError(f"{self._name_lost(lost)}: lost and not rebuilt: {e}") from None
        for i, f, h in zip(lost, handles, rebuilt, strict=True):
            self._handles[i], self._built[i] = f, h

    def _brick_name(self, i: int) -> str:
        """What renderer i renders, for an error: its samples, and the file."""
        spec = self._specs[i]
        src = spec["source"]
        return f"{src[0] + ' ' if src is not None else ''}samples {spec['ranges']}"

    def _lost(self) -> list[int]:
        """The renderers whose handle (or scattered samples) is lost now."""
        return [
            i
            for i, (h, a) in enumerate(zip(self._handles, self._arrays, strict=True))
            if h.status != "finished" or (a is not None and a.status != "finished")
        ]

    def _name_lost(self, lost: list[int]) -> str:
        gone = ", ".join(
            f"bricks {self._specs[i]['ranges']} (were on {self._built[i].worker})" for i in lost[:4]
        )
        return gone + (" ..." if len(lost) > 4 else "")

    def _lost_parts(self) -> str:
        lost = self._lost()
        return f"lost: {self._name_lost(lost)}" if lost else ""

    def render(
        self,
        camera: Camera,
        width: int,
        height: int,
        isovalue: float,
        *,
        speculation: bool = True,
        footprints: bool = True,
    ) -> IsoImage:
        """The complete image (every ray finished) of the whole volume.
        footprints: each brick renders, and sends, only the rectangle of the
        frame its box projects to (False: full frames, for comparison).
        ``stats``: bricks, passes (summed over bricks), pixels (rendered,
        summed over bricks), workers, compositing, seconds, bytes_sent (as
        ``DistributedRasterizer.render``'s)."""
        from ..limits import ISO, check_image_size

        self._check_open()
        if not isinstance(camera, Camera):
            raise TypeError(f"camera: expected a clvis.Camera, got {type(camera).__name__}")
        width, height = check_image_size(width, height, ISO)
        check_aspect(camera, width, height)
        if isinstance(isovalue, bool) or not isinstance(isovalue, (int, float, np.integer, np.floating)):
            raise TypeError(f"isovalue: expected a real number, got {type(isovalue).__name__}")
        view = {
            "camera": camera,
            "width": width,
            "height": height,
            "isovalue": float(isovalue),
            "speculation": bool(speculation),
            "footprints": bool(footprints),
        }
        whole, frame, sent, nworkers = self._frame(render_one, view)
        p = whole.planes
        hit = whole.key != _c.EMPTY_KEY
        return IsoImage(
            p["rgba"],
            _c.depths_of(whole.key),
            hit,
            p["t"],
            np.zeros(hit.shape, bool),
            1.0,
            {
                **whole.counts,
                "workers": nworkers,
                "compositing": self.frame_compositing,
                "seconds": frame_seconds(frame, whole.seconds),
                "bytes_sent": sent,
            },
            camera=camera,
        )


def _build_from(spec: dict, data: Any) -> _Handle:
    """Task: build a brick from its scattered samples (data) or its file."""
    return _build(spec if data is None else {**spec, "source": data})
