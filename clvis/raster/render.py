"""Point rasterization into multi-attribute G-buffers.

The compute rasterizer of Schütz, Kerbl and Wimmer (2021, 2022) as NARVis
uses it ("MACR": render, then resolve):

1. render: every point is projected; a 64-bit ``atom_min`` of
   ``depth key << 32 | index`` into a W×H visibility buffer keeps the nearest
   point of each pixel, ties to the lowest index (deterministic). An early-z
   read skips points that cannot win. Devices without 64-bit atomics take two
   passes (32-bit depth min, then index min among the points at that depth)
   that give the same buffer bit for bit.
2. resolve: per pixel, the winner's data into G-buffers — index, depth,
   RGBA (per-point colors, or a transfer function of an attribute through a
   matplotlib colormap), up to 8 float32/uint8 attributes, the screen-space
   velocity with its angle and magnitude, and the splat radius in pixels.

Optional: a soft z-buffer (the colors of every point within a relative depth
tolerance of the nearest, averaged), and :func:`depth_filter` (the LiDAR
paper's hierarchical filter of background points seen through holes).

Points are processed in batches of ``batch_size`` consecutive points with a
bounding box each; batches the camera cannot see are skipped without reading
a point. :class:`Rasterizer` keeps a cloud on the device (optionally in Morton
order, so batches are compact and early-z rejects most points) for rendering
many views (it captures the runtime options, 64-bit atomics and tuning
profile, when made: later configure() calls apply to Rasterizers made after
them); :func:`rasterize` is the one-call form. Kernels:
``kernels_cl/raster/render.cl`` and ``resolve.cl`` (this module drives both:
MACR is render, then resolve); the Morton order (``morton.cl``) is
:mod:`clvis.raster.morton`'s. NumPy definitions: ``clvis.reference.raster``.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import colormap as _colormap
from .. import runtime
from .._arrays import is_device, resolve_queue, to_host
from ..camera import Camera, check_aspect
from ..images import Picture, rgba8
from .inputs import (
    MAX_ATTRIBUTES,
    RasterInput,
    check_camera,
    check_point_size,
    check_size,
    soft_tolerance,
)
from .morton import morton_gather, morton_order

__all__ = [
    "EMPTY",
    "VIS_DTYPE",
    "GBuffers",
    "Rasterizer",
    "rasterize",
]

EMPTY = np.uint32(0xFFFFFFFF)  # index of an empty pixel
BATCH_SIZE = 10240
_F32_MAX = float(np.finfo(np.float32).max)
# a visibility word as two uints (little-endian ulong: dkey << 32 | id)
VIS_DTYPE = np.dtype([("id", "<u4"), ("dkey", "<u4")])
# local size of the per-batch kernels: one work-item walking a batch on CPUs,
# a group striding through it on GPUs
# (VEC: float8 projection in render.cl); "item_wg": the fixed local size of the
# one-work-item-per-pixel/point kernels (a driver-chosen one would make PoCL
# compile a work-group function per image size)
PROFILES = {"cpu": {"L": 1, "VEC": 8, "item_wg": 64}, "gpu": {"L": 256, "VEC": 1, "item_wg": 256}}


@dataclasses.dataclass(repr=False)
class GBuffers(Picture):
    """The G-buffers of one view, [H, W] planes, row 0 on top.

    index: uint32, the winning point (its index in the caller's order), or
    ``EMPTY`` (0xFFFFFFFF). depth: float32 view depth, +inf where empty.
    rgba: uint8 [H, W, 4], (0, 0, 0, 0) where empty. attributes: name → plane
    (float32, NaN where empty; uint8, 0 where empty). vel2d: float32 [H, W, 2]
    screen velocity in pixels per unit time (x right, y down), vel_angle
    (atan2(vy, vx), radians) and vel_speed (its length), NaN where empty;
    radius_px: the splat radius in pixels. Planes the cloud has no data for
    (and the velocity planes of ``render(screen_velocity=False)``) are None.
    stats: points, batches, batches_drawn, points_read, and points_nonfinite
    (points never drawn because a coordinate is NaN or infinite).
    ``to_uint8(background=None)`` and ``save_png(path)``: the rgba plane as
    a picture, as for every image type (:class:`clvis.images.Picture`).
    """

    index: np.ndarray | cla.Array
    depth: np.ndarray | cla.Array
    rgba: np.ndarray | cla.Array
    attributes: Mapping[str, np.ndarray | cla.Array]
    vel2d: np.ndarray | cla.Array | None = None
    vel_angle: np.ndarray | cla.Array | None = None
    vel_speed: np.ndarray | cla.Array | None = None
    radius_px: np.ndarray | cla.Array | None = None
    stats: dict[str, Any] = dataclasses.field(default_factory=dict)

    def to_uint8(self, background: Sequence[int] | None = None) -> np.ndarray:
        """(H, W, 4) uint8 RGBA: the rgba plane (transparent where empty), or over
        the RGB `background` (0..255 each)."""
        if self.rgba is None:
            raise ValueError("to_uint8: these G-buffers have no rgba plane (render(planes=...) left it out)")
        rgba = to_host(self.rgba)
        return rgba8(rgba, background)

    @property
    def covered(self) -> np.ndarray | cla.Array:
        """bool [H, W]: a point was drawn there."""
        return self.index != EMPTY

    @property
    def shape(self) -> tuple[int, int]:
        h, w = self.index.shape
        return h, w


class Rasterizer:
    """A point cloud on the device, ready to render from many cameras.

    cloud_or_positions: a ``clvis.PointCloud`` (its colors, attributes,
    velocity and radius are used unless given here) or positions, float32
    (N, 3) (float64, float16 and integers are converted; a ``pyopencl.array.Array`` stays on the
    device). colors: uint8 (N, 4) or (N, 3). attributes: up to 8 name → (N,)
    arrays (uint8/bool kept as uint8, other numbers as float32); a
    PointCloud's own attributes may be more (a LAS file has 13 or more).
    Attributes stay on the host until a render needs them: the one colored
    by, and the planes resolved (``render(planes=)``), each uploaded once.
    velocity: (N, 3) per point; radius: (N,) world radius per point.

    morton=True reorders the points along a Morton curve on the device (the
    radix sort of 30-bit codes): batches become compact boxes that frustum
    culling can skip, and early-z rejects most points. Indices in the output
    still refer to the caller's order, and ties still go to the lowest of
    them, so the result does not depend on the order.
    """

    def __repr__(self) -> str:
        has = [w for w, h in (("colors", self.has_colors), ("velocity", self.has_velocity)) if h]
        attrs = f", attributes={list(self.attribute_names)}" if self.attribute_names else ""
        return (
            f"Rasterizer({self.n:,} points{''.join(', ' + w for w in has)}{attrs}, "
            f"device={self.queue.device.name.strip()!r})"
        )

    def __init__(
        self,
        cloud_or_positions: Any,
        *,
        colors: Any = None,
        attributes: Mapping[str, Any] | None = None,
        velocity: Any = None,
        radius: Any = None,
        morton: bool = True,
        batch_size: int = BATCH_SIZE,
        queue: cl.CommandQueue | None = None,
    ) -> None:
        if (
            isinstance(batch_size, bool)
            or not isinstance(batch_size, (int, np.integer))
            or not 1 <= batch_size <= 1 << 24
        ):
            raise ValueError(f"batch_size: expected an int in [1, 2^24], got {batch_size!r}")
        inp = RasterInput(cloud_or_positions, colors, attributes, velocity, radius)
        self.queue = q = resolve_queue(queue, positions=inp.positions)
        self.config = runtime.capture(q)
        with runtime.pinned(self.config):
            self._setup(inp, morton, int(batch_size))

    def _setup(self, inp, morton, batch_size):
        q = self.queue
        # the kernels of a render, for the options captured (render.cl's per
        # point size: built when first asked for)
        self._kernels = {
            name: runtime.get_kernel(q, "raster/resolve.cl", name, {}, runtime.EXACT_FP)
            for name in ("resolve", "resolve_attributes")
        }
        self._splat_kernels: dict = {}
        self._render_kernels(1)
        self.n = n = inp.n
        self.batch_size = batch_size
        self.nbatches = -(-n // self.batch_size)
        self.attribute_names = list(inp.names)  # the caller's order
        self._f32_names, self._u8_names = list(inp.f32), list(inp.u8)
        self._host_attr = {**inp.f32, **inp.u8}  # uploaded when a render needs them
        self._ranges: dict = {}
        self._tf_cache: dict = {}  # name -> float32 device copy (color_by)
        self._planes_cache: tuple | None = None  # (names, f32 device, u8 device): the last planes
        self._nonfinite: int | cla.Array = 0
        self._luts: dict = {}
        self.has_colors = inp.colors is not None
        self.has_velocity = inp.velocity is not None
        self.has_radius = inp.radius is not None

        pos = self._upload("positions", inp.positions)
        self.ids: cla.Array | None = None
        self.inv: cla.Array | None = None
        # render.cl's walk: its coherent bit (see coherent)
        self._coherent: bool | None = True if morton and n > 1 else None
        if morton and n > 1:
            perm = typing.cast(cla.Array, morton_order(pos, queue=q))  # device in, device out
            self.ids = perm
            self.positions, self.inv = morton_gather(q, pos, perm)
        else:
            self.positions = pos
        self.bounds = _batch_bounds(q, self.positions, self.batch_size)
        if n:  # per batch, read back with the first stats
            self._nonfinite = runtime.empty(q, self.nbatches, np.uint32, "non-finite counts")
            k = runtime.get_kernel(
                q, "raster/render.cl", "batch_nonfinite", _render_defines(q), runtime.EXACT_FP
            )
            runtime.launch(
                q,
                k,
                *_items(q, self.nbatches),
                self.positions.base_data,
                np.uint32(n),
                np.uint32(self.batch_size),
                self._nonfinite.base_data,
            )
        self.colors = self._upload("colors", inp.colors)
        self.velocity = self._upload("velocity", inp.velocity)
        self.radius = self._upload("radius", inp.radius)

    @property
    def coherent(self) -> bool:
        """Whether the points lie in spatially coherent batches (Morton-ordered
        here, or sorted so by the caller): then each batch's box spans less
        than half the cloud's (the sum of its three sides against the
        cloud's), and render.cl's walk sets its coherent bit, the 8-point
        early-z that pays only when most points are rejected. Judged once,
        from the batch boxes (read back at the first call)."""
        if self._coherent is None:
            self._coherent = _coherent_batches(self.bounds.get()) if self.n > 1 else False
        return self._coherent

    def _render_kernels(self, point_size: int) -> dict:
        """render.cl's kernels for POINT_SIZE = point_size (one build each)."""
        ks = self._splat_kernels.get(point_size)
        if ks is None:
            q = self.queue
            with runtime.pinned(self.config):
                passes = (
                    ("render_visibility",) if self.config.int64_atomics else ("render_depth", "render_index")
                )
                defines = _render_defines(q)
                if point_size != 1:
                    defines["POINT_SIZE"] = point_size
                ks = self._splat_kernels[point_size] = {
                    name: runtime.get_kernel(q, "raster/render.cl", name, defines, runtime.EXACT_FP)
                    for name in passes + ("soft_accumulate",)
                }
        return ks

    @property
    def nonfinite(self) -> int:
        """How many points have a NaN or infinite coordinate (never drawn);
        counted on the device when the Rasterizer was made, read once."""
        if not isinstance(self._nonfinite, int):
            self._nonfinite = int(self._nonfinite.get().astype(np.int64).sum())
        return self._nonfinite

    def _planes(self, planes) -> list[str]:
        """The attribute planes a render resolves, checked."""
        if planes is None:
            return list(self.attribute_names) if len(self.attribute_names) <= MAX_ATTRIBUTES else []
        if isinstance(planes, str):
            planes = [planes]
        names = list(planes)
        for name in names:
            if name not in self._host_attr:
                raise ValueError(
                    f"planes: no attribute {name!r}; the cloud has "
                    f"{', '.join(self.attribute_names) or 'none'}"
                )
        if len(set(names)) != len(names):
            raise ValueError(f"planes: {names} names an attribute twice")
        if len(names) > MAX_ATTRIBUTES:
            raise ValueError(
                f"planes: {len(names)} given; at most {MAX_ATTRIBUTES} attribute planes a render"
            )
        return names

    def _plane_buffers(self, names):
        """(f32 names, u8 names, f32 device, u8 device): the planes' values
        interleaved per point as resolve.cl reads them, uploaded for the last
        selection (a render with the same planes uploads nothing)."""
        f32 = [m for m in names if m in self._f32_names]
        u8 = [m for m in names if m in self._u8_names]
        key = (tuple(f32), tuple(u8))
        if self._planes_cache is None or self._planes_cache[0] != key:
            self._planes_cache = None  # let the old buffers go first
            df = (
                self._upload_async("attributes", np.stack([self._host_attr[m] for m in f32], axis=1))
                if f32
                else None
            )
            du = (
                self._upload_async("attributes", np.stack([self._host_attr[m] for m in u8], axis=1))
                if u8
                else None
            )
            self._planes_cache = (key, df, du)
        return f32, u8, self._planes_cache[1], self._planes_cache[2]

    def _upload_async(self, name, a):
        """A host array to a new device array without waiting for earlier
        renders (pyopencl keeps `a` alive until the copy is done)."""
        d = runtime.empty(self.queue, a.shape, a.dtype, name)
        if a.size:
            d.set(np.ascontiguousarray(a), queue=self.queue, async_=True)
        return d

    def _upload(self, name, a):
        if a is None:
            return None
        if is_device(a):
            if a.context.int_ptr != self.queue.context.int_ptr:
                raise ValueError(f"{name}: the device array belongs to another OpenCL context")
            return a if not a.offset else a.copy()
        d = runtime.empty(self.queue, a.shape, a.dtype, name)
        if a.size:
            d.set(np.ascontiguousarray(a), queue=self.queue)
        return d

    # ------------------------------------------------------------------
    def _program_args(self, camera, width, height):
        cam, near, far = check_camera(camera)
        width, height = check_size(width, height)
        return cam, near, far, width, height

    def visibility(
        self, camera: Camera, width: int, height: int, *, point_size: int = 1
    ) -> tuple[cla.Array, cla.Array]:
        """Run the render pass only: the (H, W) uint64 visibility buffer
        (``dkey << 32 | index``, all ones where empty) and the per-batch
        drawn flags (uint8), both on the device. point_size: as in render."""
        cam, near, far, W, H = self._program_args(camera, width, height)
        ps = check_point_size(point_size)
        check_aspect(camera, W, H)
        with runtime.pinned(self.config):
            vis, drawn, _ = self._render(cam, near, far, W, H, ps)
        return vis, drawn

    def _render(self, cam, near, far, W, H, point_size):
        q = self.queue
        vis = runtime.fill(q, runtime.empty(q, (H, W), np.uint64, "visibility buffer"), np.uint64(2**64 - 1))
        drawn = runtime.empty(q, max(self.nbatches, 1), np.uint8, "batch flags")
        cam_d = self._camera_device(cam)
        if self.n == 0:
            runtime.fill_zero(q, drawn)
            return vis, drawn, cam_d
        L = _local_size(q)
        # walk batches backwards when that visits the points of each Morton
        # cell nearest first (render.cl's ABI comment): far fewer atomics; the
        # 8-point early-z only for a Morton-ordered cloud, where it pays
        f = cam[16:19].astype(np.float64)  # the depth row: the view direction
        walk = np.uint32(int(f[0] + 2 * f[1] + 4 * f[2] < 0) | (2 if self.coherent else 0))
        args = (
            self.positions.base_data,
            _arg(self.ids),
            np.uint32(self.n),
            np.uint32(self.batch_size),
            self.bounds.base_data,
            cam_d.base_data,
            near,
            far,
            np.uint32(W),
            np.uint32(H),
            vis.base_data,
            drawn.base_data,
            walk,
        )
        G = self.nbatches * L
        kernels = self._render_kernels(point_size)
        passes = ("render_visibility",) if self.config.int64_atomics else ("render_depth", "render_index")
        for name in passes:
            runtime.launch(q, kernels[name], G, L, *args)
        return vis, drawn, cam_d

    def _camera_device(self, cam):
        d = runtime.empty(self.queue, cam.size, np.float32, "camera")
        d.set(cam, queue=self.queue, async_=True)  # no wait for earlier renders (host=False)
        return d

    def _lut(self, name):
        lut = self._luts.get(name)
        if lut is None:
            host = np.ascontiguousarray(_colormap.lut(name))
            lut = self._luts[name] = self._upload("colormap", host)
        return lut

    def _tf(self, color_by, colormap, value_range):
        """(color_mode, tf_src, stride, offset, lut, lut_n, vmin, scale)."""
        if color_by is None:
            if colormap != "viridis":  # unused, but a misspelt name says so (no upload)
                _colormap.lut(colormap, 1)
            return (1 if self.has_colors else 0), None, 0, 0, None, 0, np.float32(0), np.float32(0)
        if color_by not in self._host_attr:
            raise ValueError(
                f"color_by: no attribute {color_by!r}; the cloud has "
                f"{', '.join(self.attribute_names) or 'none'}"
            )
        if value_range is None:
            vr = self._ranges.get(color_by)
            if vr is None:
                vr = self._ranges[color_by] = _colormap.value_range(self._host_attr[color_by])
        else:
            vr = tuple(float(v) for v in value_range)
            # finite as float32 too: the kernels take vmin as a float
            if len(vr) != 2 or not all(math.isfinite(v) and abs(v) <= _F32_MAX for v in vr) or vr[0] > vr[1]:
                raise ValueError(
                    f"value_range: expected finite (vmin, vmax) with vmin <= vmax, got {value_range!r}"
                )
        vmin, vmax = vr
        scale = np.float32(0.0 if vmax == vmin else 1.0 / (vmax - vmin))
        lut = self._lut(colormap)
        src = self._tf_cache.get(color_by)  # its own float32 copy (a uint8 attribute converted)
        if src is None:
            src = self._tf_cache[color_by] = self._upload_async(
                "attributes", self._host_attr[color_by].astype(np.float32)
            )
        return 2, src, 1, 0, lut, lut.shape[0], np.float32(vmin), scale

    def render(
        self,
        camera: Camera,
        width: int,
        height: int,
        *,
        color_by: str | None = None,
        colormap: str = "viridis",
        value_range: tuple[float, float] | None = None,
        soft_z: bool | float | None = None,
        planes: Any = None,
        point_size: int = 1,
        screen_velocity: bool = True,
        host: bool = True,
    ) -> GBuffers:
        """Render and resolve one view; numpy G-buffers (host=False: the planes
        stay on the device as ``pyopencl.array.Array``, nothing is read back,
        and stats is empty).

        color_by: an attribute name to color by through `colormap` (matplotlib
        name) over `value_range` (default: the attribute's finite min and max);
        else the cloud's colors, else white. soft_z: None (off), True (factor
        1.01) or a factor >= 1: rgba becomes the mean color of every point
        within factor × the nearest depth of its pixel (needs near > 0).

        planes: the attributes resolved into ``GBuffers.attributes``, a list
        of at most 8 names (``[]``: none). Default (None): every attribute of
        the cloud when it has at most 8; a cloud with more (a LAS file) gets
        none unless they are named here. Coloring by an attribute does not
        need its plane.

        point_size: 1..64; each point covers point_size × point_size pixels
        around its own, clipped to the image (even sizes reach one pixel
        further right and down: px - (N-1)//2 .. px + N//2), depth-tested per
        pixel like a point of size 1. A point whose own pixel is outside the
        image draws nothing.

        screen_velocity: False leaves out the screen velocity planes of a cloud
        with a velocity (vel2d, vel_angle and vel_speed are None, as for a
        cloud without one): a picture that needs only rgba, depth and index
        skips the per-pixel gather of the winner's position and velocity.
        """
        cam, near, far, W, H = self._program_args(camera, width, height)
        ps = check_point_size(point_size)
        tol = soft_tolerance(soft_z, camera)
        names = self._planes(planes)
        tf = self._tf(color_by, colormap, value_range)
        focal = np.float32(0.5 * H * float(np.asarray(camera.projection)[1, 1]))
        vel = self.has_velocity and bool(screen_velocity)
        with runtime.pinned(self.config):
            f32, u8, df, du = self._plane_buffers(names)
            self._check_memory(W, H, len(f32), len(u8), tol is not None and self.n > 0, host, vel)
            check_aspect(camera, W, H)  # the arguments are good and the image fits: the render goes on
            vis, drawn, cam_d = self._render(cam, near, far, W, H, ps)
            out = self._resolve(
                vis, cam_d, W, H, focal, tf, tol, near, far, ps, f32, u8, df, du, vel, camera.orthographic
            )
        if not host:
            return _gbuffers(out, f32, u8, names, lambda a: a)
        g = _gbuffers(out, f32, u8, names, lambda a: a.get())
        d = drawn.get()[: self.nbatches].astype(bool)
        sizes = np.minimum(self.batch_size, self.n - np.arange(self.nbatches) * self.batch_size)
        g.stats = {
            "points": self.n,
            "batches": self.nbatches,
            "batches_drawn": int(d.sum()),
            "points_read": int(sizes[d].sum()) if self.nbatches else 0,
            "points_nonfinite": self.nonfinite,
        }
        return g

    def _check_memory(
        self, W: int, H: int, nf: int, nu: int, soft: bool, host: bool, velocity: bool = True
    ) -> None:
        """Device and host bytes of one render, checked before anything is
        allocated: the visibility buffer (8 B a pixel), the soft z accumulation
        (20), index, depth, rgba (4 each), the attribute planes (4 or 1 each),
        velocity (8 + 4 + 4) and radius (4); with host=True every plane but the
        visibility buffer and the accumulation is read back."""
        npix = W * H
        vel = self.has_velocity and velocity
        planes = 12 + 4 * nf + nu + (16 if vel else 0) + (4 if self.has_radius else 0)
        device = npix * (8 + (20 if soft else 0) + planes)
        runtime.check_memory(
            self.queue, f"raster image {W}x{H}", device_bytes=device, host_bytes=npix * planes if host else 0
        )

    def _resolve(
        self,
        vis,
        cam_d,
        W,
        H,
        focal,
        tf,
        tol,
        near,
        far,
        point_size,
        f32_names,
        u8_names,
        attr_f32,
        attr_u8,
        velocity=True,
        ortho=False,
    ):
        q = self.queue
        npix = W * H
        color_mode, tf_buf, stride, offset, lut, lut_n, vmin, scale = tf
        accum = None
        if tol is not None and self.n:
            accum = runtime.zeros(q, npix * 5, np.uint32, "soft z accumulation")
            L = _local_size(q)
            runtime.launch(
                q,
                self._render_kernels(point_size)["soft_accumulate"],
                self.nbatches * L,
                L,
                self.positions.base_data,
                _arg(self.ids),
                np.uint32(self.n),
                np.uint32(self.batch_size),
                self.bounds.base_data,
                cam_d.base_data,
                near,
                far,
                np.uint32(W),
                np.uint32(H),
                vis.base_data,
                np.float32(tol),
                np.uint32(color_mode),
                _arg(self.colors),
                _arg(tf_buf),
                np.uint32(stride),
                np.uint32(offset),
                _arg(lut),
                np.uint32(lut_n),
                vmin,
                scale,
                accum.base_data,
            )
        # 4: radius_px of an orthographic camera (no division by the depth)
        flags = (1 if self.has_velocity and velocity else 0) | ((6 if ortho else 2) if self.has_radius else 0)
        nf, nu = len(f32_names), len(u8_names)
        e = runtime.empty
        out: dict[str, cla.Array | None] = {
            "index": e(q, (H, W), np.uint32, "index buffer"),
            "depth": e(q, (H, W), np.float32, "depth buffer"),
            "rgba": e(q, (H, W, 4), np.uint8, "rgba buffer"),
            "f32": e(q, (nf, H, W), np.float32, "attribute planes") if nf else None,
            "u8": e(q, (nu, H, W), np.uint8, "attribute planes") if nu else None,
            "vel": e(q, (H, W, 2), np.float32, "velocity planes") if flags & 1 else None,
            "angle": e(q, (H, W), np.float32, "velocity angle") if flags & 1 else None,
            "speed": e(q, (H, W), np.float32, "velocity magnitude") if flags & 1 else None,
            "radius": e(q, (H, W), np.float32, "radius plane") if flags & 2 else None,
        }
        runtime.launch(
            q,
            self._kernels["resolve"],
            *_items(q, npix),
            vis.base_data,
            np.uint32(W),
            np.uint32(H),
            np.uint32(color_mode),
            _arg(self.colors),
            _arg(tf_buf),
            np.uint32(stride),
            np.uint32(offset),
            _arg(lut),
            np.uint32(lut_n),
            vmin,
            scale,
            _arg(accum),
            _arg(out["index"]),
            _arg(out["depth"]),
            _arg(out["rgba"]),
        )
        if flags or nf or nu:
            runtime.launch(
                q,
                self._kernels["resolve_attributes"],
                *_items(q, npix),
                vis.base_data,
                np.uint32(W),
                np.uint32(H),
                self.positions.base_data,
                _arg(self.inv),
                cam_d.base_data,
                focal,
                np.uint32(flags),
                np.uint32(nf),
                _arg(attr_f32),
                np.uint32(nu),
                _arg(attr_u8),
                _arg(self.velocity),
                _arg(self.radius),
                _arg(out["f32"]),
                _arg(out["u8"]),
                _arg(out["vel"]),
                _arg(out["angle"]),
                _arg(out["speed"]),
                _arg(out["radius"]),
            )
        return out


_arg = runtime.arg


def _local_size(queue) -> int:
    return runtime.local_size(queue, PROFILES[runtime.tuning_profile(queue)]["L"])


def _items(queue, n: int) -> tuple[int, int]:
    """(global, local) sizes for one work-item per element of n."""
    return runtime.items(queue, n, PROFILES[runtime.tuning_profile(queue)]["item_wg"])


def _render_defines(queue) -> dict:
    return {"VEC": PROFILES[runtime.tuning_profile(queue)]["VEC"]}


def _coherent_batches(bounds: np.ndarray) -> bool:
    """True when the median batch box (rows: min xyz, max xyz; empty batches
    have min > max) spans less than half of the cloud's box, side sums
    compared."""
    b = bounds.astype(np.float64)
    lo, hi = b[:, :3], b[:, 3:]
    full = (lo <= hi).all(axis=1)
    if full.sum() < 2:
        return False
    lo, hi = lo[full], hi[full]
    span = (hi.max(axis=0) - lo.min(axis=0)).sum()
    if not np.isfinite(span) or span <= 0:
        return False
    return bool(np.median((hi - lo).sum(axis=1)) < 0.5 * span)


def _batch_bounds(queue, positions, batch: int) -> cla.Array:
    n = positions.shape[0]
    nb = -(-n // batch)
    bounds = runtime.empty(queue, (max(nb, 1), 6), np.float32, "batch bounds")
    if n:
        k = runtime.get_kernel(
            queue, "raster/render.cl", "batch_bounds", _render_defines(queue), runtime.EXACT_FP
        )
        runtime.launch(
            queue,
            k,
            *_items(queue, nb),
            positions.base_data,
            np.uint32(n),
            np.uint32(batch),
            bounds.base_data,
        )
    return bounds


def _gbuffers(out, f32_names, u8_names, order, get) -> GBuffers:
    def g(a):
        return None if a is None else get(a)

    attrs = {}
    f32, u8 = g(out["f32"]), g(out["u8"])
    for i, name in enumerate(f32_names):
        attrs[name] = f32[i]
    for i, name in enumerate(u8_names):
        attrs[name] = u8[i]
    attrs = {name: attrs[name] for name in order}  # the order asked for
    return GBuffers(
        index=g(out["index"]),
        depth=g(out["depth"]),
        rgba=g(out["rgba"]),
        attributes=attrs,
        vel2d=g(out["vel"]),
        vel_angle=g(out["angle"]),
        vel_speed=g(out["speed"]),
        radius_px=g(out["radius"]),
    )


def rasterize(
    cloud_or_positions: Any,
    camera: Camera,
    width: int,
    height: int,
    *,
    colors: Any = None,
    attributes: Mapping[str, Any] | None = None,
    velocity: Any = None,
    radius: Any = None,
    soft_z: bool | float | None = None,
    color_by: str | None = None,
    colormap: str = "viridis",
    value_range: tuple[float, float] | None = None,
    morton: bool = False,
    batch_size: int = BATCH_SIZE,
    planes: Any = None,
    point_size: int = 1,
    queue: cl.CommandQueue | None = None,
) -> GBuffers:
    """Render and resolve one view of a point cloud: :class:`Rasterizer`
    (``cloud_or_positions``, colors, attributes, velocity, radius, morton,
    batch_size) followed by its ``render`` (camera, size, color_by, colormap,
    value_range, soft_z, planes, point_size). For many views of one cloud,
    keep a Rasterizer."""
    r = Rasterizer(
        cloud_or_positions,
        colors=colors,
        attributes=attributes,
        velocity=velocity,
        radius=radius,
        morton=morton,
        batch_size=batch_size,
        queue=queue,
    )
    return r.render(
        camera,
        width,
        height,
        color_by=color_by,
        colormap=colormap,
        value_range=value_range,
        soft_z=soft_z,
        planes=planes,
        point_size=point_size,
    )
