"""Gaussian ray marching over a device LBVH (kernels_cl/gauss/march.cl).

Every Gaussian a ray meets is composited front to back in the order of the
ray parameter t of its closest approach (3D Gaussian Ray Tracing's k-buffer
rounds: each round traverses the BVH for the K nearest hits beyond the last
one composited). Two compositing models:

- ``"max_response"`` (3DGRT): alpha = min(0.99, opacity * tf_alpha * exp(-m^2 / 2)),
  m the Mahalanobis distance at the closest approach along the ray (t >= 0).
- ``"absorption"`` (Sharma & Schmalstieg's density model): alpha =
  1 - exp(-density * opacity * tf_alpha * I), I the line integral of the
  Gaussian over the ray's t >= 0 in closed form (erfc). The transmittance
  after all Gaussians is exact; colours are composited per Gaussian in
  hit order.

A ray hits a Gaussian when m <= cutoff (3 by default) at t >= 0; the ray
starts on the camera's near plane. Compositing stops once the transmittance
T < 1e-3. ``rgba`` is premultiplied colour with alpha = 1 - T; ``depth`` is
the view depth (the camera's depth row) of the hit that first brought T
below 0.5, +inf where T never got there.

Colours: by default the transfer function maps each Gaussian's value to an
rgb colour and an opacity factor. Gaussians with their own colours
(``Gaussians.colors``, e.g. a point cloud's rgb) are composited with those
instead (march.cl's COLOR 1); the transfer function still scales opacity.

Memory: an image is rendered in bands of rows, each a march launch over the
same BVH writing its own per-ray buffers (rgba, depth, ray stats: 28 bytes a
ray), read back into the host image before the next band; the device holds
one band's buffers whatever the image size (the tuning profile's
``tile_rays``). ``runtime.check_memory`` is asked before the host image and
the band buffers are allocated, so an impossible size is a DeviceError
naming both figures (a size past :data:`clvis.limits.GAUSS`, 2^32 - 1 pixels,
is a ValueError before that). host=False keeps the whole image on the device: one band.

A GaussianRenderer captures the runtime options (tuning profile, 64-bit
atomics) and its kernels when it is made (runtime.capture). Timings in its
stats come from OpenCL event profiling; nothing waits for the device unless
the caller reads results back (host=True) or a timing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TypedDict

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import limits, runtime
from .._arrays import buffer_of, nonnegative_int, positive_int, resolve_queue, to_host
from ..camera import Camera, check_aspect, ray_buffer
from ..colormap import TransferFunction
from ..errors import DeviceError
from ..images import Picture, float_rgba8
from ..limits import check_image_size
from .bvh import build_bvh
from .gaussians import Gaussians, gather_records, gaussian_records
from .tiles import PROFILES as TILE_PROFILES
from .tiles import render_tiles

__all__ = [
    "LIMITS",
    "MODELS",
    "SPLAT",
    "GaussianImage",
    "GaussianRenderer",
    "render_gaussians",
]

MODELS = {"max_response": 0, "absorption": 1}  # the ray models (march.cl, tiles.cl)
SPLAT = "splat"  # 3DGS's rasterizer (splat.cl), tiles only
METHODS = ("tiles", "bvh")
LIMITS = limits.GAUSS  # image sizes (why: clvis.limits)
MAX_K = 64
#: a fog's transfer function opacity, points (x along the value range, alpha):
#: low over the bottom of the range, so a density's shell of low values does
#: not hide its bright inside (clvis gauss and the viewer draw a grid of
#: class "fog volume", and clvis gauss the embedded explosion, through it)
FOG_OPACITY = ((0.0, 0.0), (0.35, 0.05), (0.7, 0.35), (1.0, 1.0))
TILE = 8


@dataclass(repr=False)
class GaussianImage(Picture):
    """A rendered frame: ``rgba`` (H, W, 4) float32 premultiplied, alpha = 1 - T;
    ``depth`` (H, W) float32 view depth where T first fell below 0.5 (+inf
    elsewhere); ``hits`` and ``rounds`` (H, W) uint32 per ray (Gaussians
    composited, k-buffer rounds); ``stats`` a dict. With ``host=False``
    rgba and depth are device arrays and hits and rounds None.
    ``to_uint8(background=None)`` and ``save_png(path)``: the picture, as for
    every image type (:class:`clvis.images.Picture`)."""

    rgba: np.ndarray | cla.Array
    depth: np.ndarray | cla.Array
    hits: np.ndarray | None
    rounds: np.ndarray | None
    stats: dict = field(default_factory=dict)

    def to_uint8(self, background: Sequence[int] | None = None) -> np.ndarray:
        """(H, W, 4) uint8 RGBA, straight alpha (transparent where no Gaussian
        covers a pixel), or over the RGB `background` (0..255 each)."""
        rgba = to_host(self.rgba)
        return float_rgba8(rgba, background, premultiplied=True)


class _Profile(TypedDict):
    march_wg: int
    k: int
    k0: int
    tile_rays: int
    method: str


# per tuning profile: work-items per group of the march kernel (a divisor of
# 64), the default k-buffer size and the first round's k (K0). CPUs: fewer,
# longer rounds pay (a round re-traverses the BVH), but a first round of 16
# lets rays that turn opaque early stop early (PoCL, 256^2: the explosion's
# high LOD 90 -> 45 ms; 10^5 overlapping translucent Gaussians 490 -> 530 ms).
# GPUs: 3DGRT's k = 16 keeps the buffer in registers.
# "tile_rays": rays per band of rows at most (28 bytes each on the device);
# a CPU gains nothing from larger launches and a band is the progress step,
# a GPU wants enough rays in flight to fill it.
PROFILES: dict[str, _Profile] = {
    "cpu": {"march_wg": 8, "k": 64, "k0": 16, "tile_rays": 1 << 18, "method": "tiles"},
    "gpu": {"march_wg": 64, "k": 16, "k0": 16, "tile_rays": 1 << 21, "method": "tiles"},
}
RAY_BYTES = 28  # per ray: rgba float4, depth float, stats uint2


def _real(name: str, v) -> float:
    """v as a float: TypeError for strings, bool and other non-numbers."""
    if isinstance(v, (str, bytes, bool, np.bool_)) or not isinstance(
        v, (int, float, np.integer, np.floating)
    ):
        raise TypeError(f"{name}: expected a number, got {type(v).__name__}")
    return float(v)


class GaussianRenderer:
    """Gaussians on the device with their LBVH, for many views.

    Parameters
    ----------
    gaussians : clvis.Gaussians
    transfer_function : TransferFunction (default viridis, opacity 1)
    model : "max_response" or "absorption" (see the module doc), or "splat":
        the forward pass of 3D Gaussian Splatting (EWA-projected 2D Gaussians
        sorted by their mean's depth per tile; clvis.gauss.tiles, splat.cl)
    k : hits per k-buffer round (1..64); None: the tuning profile's (64 on CPUs, 16 on GPUs)
    cutoff : hit radius in standard deviations (Mahalanobis), also the BVH boxes'
    density : extinction scale of the absorption model (per world unit)
    colors : None (default): the Gaussians' own colours when they have them,
        else the transfer function's; True: their own (ValueError if they
        have none); False: the transfer function's.
    method : "tiles" (the Gaussians binned to screen tiles and sorted per
        tile, clvis.gauss.tiles), "bvh" (march.cl over an LBVH) or None: the
        tuning profile's (the faster one measured). Both give the same image.
    kp : the tile renderer's pending-hit buffer (1..64); None: its profile's.
    """

    def __repr__(self) -> str:
        return (
            f"GaussianRenderer({self.n:,} Gaussians, model={self.model!r}, density={self.density}, "
            f"{self.transfer_function!r}, device={self.queue.device.name.strip()!r})"
        )

    def __init__(
        self,
        gaussians: Gaussians,
        transfer_function: TransferFunction | None = None,
        model: str = "max_response",
        k: int | None = None,
        cutoff: float = 3.0,
        density: float = 1.0,
        queue: cl.CommandQueue | None = None,
        *,
        colors: bool | None = None,
        method: str | None = None,
        kp: int | None = None,
    ) -> None:
        if not isinstance(gaussians, Gaussians):
            raise TypeError(f"gaussians: expected clvis.Gaussians, got {type(gaussians).__name__}")
        if model not in MODELS and model != SPLAT:
            raise ValueError(f"model: expected one of {', '.join([*MODELS, SPLAT])}, got {model!r}")
        self.queue = q = resolve_queue(queue)
        self.config = runtime.capture(q)
        prof = self._profile = PROFILES[self.config.tuning]
        if model == "splat" and method is None:
            method = "tiles"
        method = prof["method"] if method is None else method
        if method not in METHODS:
            raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
        if model == "splat" and method != "tiles":
            raise ValueError("model='splat' (3DGS's rasterizer) needs method='tiles'")
        self.method = method
        kp = TILE_PROFILES[self.config.tuning]["kp"] if kp is None else nonnegative_int("kp", kp)
        if not 1 <= kp <= MAX_K:
            raise ValueError(f"kp: expected 1..{MAX_K}, got {kp}")
        self.kp = kp
        self.lanes: int | None = None  # tile_render (1) or tile_render8 (8); None: the profile's
        k = prof["k"] if k is None else nonnegative_int("k", k)
        if not 1 <= k <= MAX_K:
            raise ValueError(f"k: expected 1..{MAX_K}, got {k}")
        cutoff, density = _real("cutoff", cutoff), _real("density", density)
        if colors is None:
            colors = gaussians.colors is not None
        elif not isinstance(colors, bool):
            raise TypeError(f"colors: expected True, False or None, got {type(colors).__name__}")
        elif colors and gaussians.colors is None:
            raise ValueError("colors=True: the Gaussians have no colours")
        self.colors = colors
        if not (np.isfinite(cutoff) and cutoff > 0):
            raise ValueError(f"cutoff: expected a positive finite number, got {cutoff!r}")
        if not (np.isfinite(density) and density >= 0):
            raise ValueError(f"density: expected a finite number >= 0, got {density!r}")
        if transfer_function is None:
            transfer_function = TransferFunction()
        if not isinstance(transfer_function, TransferFunction):
            raise TypeError(
                "transfer_function: expected a clvis.TransferFunction, got "
                f"{type(transfer_function).__name__}"
            )
        self.gaussians, self.model, self.k = gaussians, model, k
        self.cutoff, self.density, self.transfer_function = cutoff, density, transfer_function
        n = gaussians.n
        if n >= 2**31:
            raise DeviceError(f"gaussians: {n} Gaussians; at most 2^31 - 1")
        self.n = n
        with runtime.pinned(self.config):
            self._setup(gaussians)

    def _setup(self, gaussians: Gaussians) -> None:
        q, n, prof = self.queue, self.n, self._profile
        flags = runtime.EXACT_FP
        self._march = (
            None
            if self.method == "tiles"
            else runtime.get_kernel(
                q,
                "gauss/march.cl",
                "march",
                {
                    "K": self.k,
                    "K0": min(self.k, prof["k0"]),
                    "MODEL": MODELS[self.model],
                    "COLOR": int(self.colors),
                },
                flags,
            )
        )
        self._march_wg = runtime.local_size(q, prof["march_wg"])
        first = runtime.marker(q)
        records, boxes, last = gaussian_records(q, gaussians, self.cutoff)
        # own colours: uchar4 by Gaussian id (the kernel indexes them through
        # the leaf order it already reads), alpha 255 and unused
        self._colors: cla.Array | None = None
        if self.colors and n and gaussians.colors is not None:  # (colors=True: they have some)
            rgba8 = np.full((n, 4), 255, np.uint8)
            rgba8[:, :3] = gaussians.colors
            self._colors = runtime.empty(q, (n, 4), np.uint8, "Gaussian colours")
            self._colors.set(rgba8, queue=q)
        self._upload_events = (first, last or runtime.marker(q))
        self._dummy = runtime.zeros(q, 64, np.float32, "empty BVH") if n == 0 else None
        bvh = build_bvh(boxes[:n] if n else np.zeros((0, 6), np.float32), queue=q)
        # the tile renderer keeps only the BVH's Morton leaf order: a tile's
        # records then lie close in memory (2 M Gaussians are 112 MB of records)
        self.bvh = None if self.method == "tiles" else bvh
        self.order = bvh.order if n else runtime.zeros(q, 1, np.uint32, "empty order")
        self.records = gather_records(q, records, bvh.order, n)

    @property
    def upload_seconds(self) -> float | None:
        """Device time of the upload and the Gaussian records (event profiling; waits for them)."""
        return runtime.seconds(*self._upload_events)

    @property
    def build_seconds(self) -> float | None:
        """Device time of the BVH build (event profiling; waits for it); None for method="tiles"."""
        return None if self.bvh is None else self.bvh.build_seconds

    @property
    def nbytes(self) -> int:
        """Device bytes the renderer holds: the Gaussian records and the BVH
        (method="tiles": the records and their order)."""
        if self.bvh is None:
            return runtime.nbytes(self.records, self._dummy, self._colors, self.order)
        return runtime.nbytes(self.records, self._dummy, self._colors) + self.bvh.nbytes

    def _buf(self, a: cla.Array | None) -> cl.MemoryObjectHolder | cl.SVMPointer:
        b = runtime.arg(a)
        if b is None:  # no Gaussians: the kernels still take a buffer
            assert self._dummy is not None
            return buffer_of(self._dummy)
        return b

    def band_rows(self, width: int, height: int) -> int:
        """Rows per band for a width x height image: the tuning profile's
        tile_rays over the width, a multiple of 8 (the kernel's tiles), at
        least 8, at most the image."""
        rows = max(8, self._profile["tile_rays"] // max(width, 1) // TILE * TILE)
        return min(rows, height)

    def render(
        self,
        camera: Camera,
        width: int,
        height: int,
        *,
        transfer_function: TransferFunction | None = None,
        host: bool = True,
        tile_rows: int | None = None,
        progress: Callable[[int, int], None] | None = None,
        max_keys: int | None = None,
    ) -> GaussianImage:
        """One frame; see the module doc for what the planes hold.

        The image is rendered in bands of `tile_rows` rows (default
        :meth:`band_rows`); `progress(rays_done, rays_total)` is called after
        each band is read back. host=False leaves ``rgba`` and ``depth`` on
        the device (pyopencl arrays on the renderer's queue, for a pipeline
        such as post-processing), renders one band and reads nothing back:
        ``hits`` and ``rounds`` are then None and ``stats["ray_stats"]`` is the
        (H, W, 2) uint32 device array of both.

        method="tiles": tile_rows is unused; the image is rendered in bands of
        tile rows holding at most `max_keys` keys (default: the tuning
        profile's ``tile_keys``), and of at most ``tile_rays`` rays when read
        back. stats add keys, keys_per_gaussian, candidates_per_pixel (the
        mean length of a pixel's tile list) and the device time split
        bin_s (count, scan, keys), sort_s, tile_render_s (ranges, render)."""
        q = self.queue
        w, h = check_image_size(width, height, LIMITS)
        cam = ray_buffer(camera, w, h)
        tf = transfer_function or self.transfer_function
        if not isinstance(tf, TransferFunction):
            raise TypeError(f"transfer_function: expected a clvis.TransferFunction, got {type(tf).__name__}")
        rows = (
            h
            if not host
            else self.band_rows(w, h)
            if tile_rows is None
            else min(positive_int("tile_rows", tile_rows), h)
        )
        if progress is not None and not callable(progress):
            raise TypeError(f"progress: expected a callable, got {type(progress).__name__}")
        if max_keys is not None:
            max_keys = positive_int("max_keys", max_keys)
        check_aspect(camera, w, h)  # the arguments are good: the render goes on
        if self.method == "tiles":
            with runtime.pinned(self.config):
                return _tiles_image(self, camera, w, h, tf, host, max_keys, progress)
        tmin, tscale = tf.limits(self.gaussians.values)
        table = tf.table()
        what = f"Gaussian image {w}x{h}"
        runtime.check_memory(
            q, what, device_bytes=w * rows * RAY_BYTES, host_bytes=w * h * RAY_BYTES if host else 0
        )
        runtime.check_alloc(q, w * rows * 16, f"{what}: rgba of {rows} rows")
        start = runtime.marker(q)
        camd = runtime.empty(q, cam.size, np.float32, "camera rays")
        camd.set(cam, queue=q, async_=True)  # no wait for earlier renders (host=False)
        tfd = runtime.empty(q, table.shape, np.float32, "transfer function")
        tfd.set(table, queue=q, async_=True)
        rgba = runtime.empty(q, (rows, w, 4), np.float32, "rgba")
        depth = runtime.empty(q, (rows, w), np.float32, "depth")
        stats = runtime.empty(q, (rows, w, 2), np.uint32, "ray stats")
        bvh = self.bvh
        assert bvh is not None and self._march is not None  # method == "bvh" (tiles returned above)
        march = self._march
        nodes = bvh.nodes if self.n else None
        fixed = (
            self._buf(nodes),
            self._buf(bvh.leaf_boxes if self.n else None),
            self.records.base_data,
            self._buf(bvh.order if self.n else None),
            np.uint32(self.n),
            camd.base_data,
            np.uint32(w),
            np.uint32(h),
            tfd.base_data,
            np.uint32(table.shape[0]),
            tmin,
            tscale,
            np.float32(self.cutoff * self.cutoff),
            np.float32(self.density),
            # COLOR 0 never reads the colours: any buffer stands in
            self.records.base_data if self._colors is None else self._colors.base_data,
        )

        def band(y0: int, n_rows: int) -> cl.Event:
            tiles = (-(-w // TILE)) * (-(-n_rows // TILE))
            return runtime.launch(
                q,
                march,
                tiles * TILE * TILE,
                self._march_wg,
                *fixed,
                np.uint32(y0),
                np.uint32(n_rows),
                rgba.base_data,
                depth.base_data,
                stats.base_data,
            )

        if not host:
            end = band(0, h)
            # nothing waits: the timings are None until the device is done
            # with them (then runtime.seconds(*info["events"]) gives render_s)
            info = {
                "gaussians": self.n,
                "model": self.model,
                "k": self.k,
                "bvh_build_s": runtime.seconds(*bvh.events, wait=False),
                "render_s": None,
                "events": (start, end),
                "rays": w * h,
                "bvh_nodes": max(self.n - 1, 0),
                "ray_stats": stats,
                "bands": 1,
            }
            return GaussianImage(rgba, depth, None, None, info)
        out_rgba = np.empty((h, w, 4), np.float32)
        out_depth = np.empty((h, w), np.float32)
        out_stats = np.empty((h, w, 2), np.uint32)
        render_s: float | None = 0.0
        bands = 0
        for y0 in range(0, h, rows):
            n_rows = min(rows, h - y0)
            ev = band(y0, n_rows)
            for dst, src in ((out_rgba, rgba), (out_depth, depth), (out_stats, stats)):
                cl.enqueue_copy(q, dst[y0 : y0 + n_rows], buffer_of(src), wait_for=[ev])
            t = runtime.seconds(start if bands == 0 else ev, ev)  # the uploads count with band 0
            render_s = None if t is None or render_s is None else render_s + t
            bands += 1
            if progress is not None:
                progress(min(w * (y0 + n_rows), w * h), w * h)
        hits, rounds = out_stats[..., 0], out_stats[..., 1]
        info = {
            "gaussians": self.n,
            "model": self.model,
            "k": self.k,
            "bvh_build_s": self.build_seconds,
            "render_s": render_s,
            "rays": w * h,
            "hits_per_ray_mean": float(hits.mean()),
            "hits_per_ray_max": int(hits.max()),
            "rounds_per_ray_mean": float(rounds.mean()),
            "bvh_nodes": max(self.n - 1, 0),
            "bands": bands,
            "band_rows": rows,
        }
        return GaussianImage(out_rgba, out_depth, hits, rounds, info)


def _tiles_image(r: GaussianRenderer, camera, w, h, tf, host, max_keys, progress) -> GaussianImage:
    rgba, depth, stats, tinfo = render_tiles(
        r, camera, w, h, tf, host=host, max_keys=max_keys, progress=progress
    )
    info = {
        "gaussians": r.n,
        "model": r.model,
        "k": r.k,
        "bvh_build_s": None,
        "rays": w * h,
        "bvh_nodes": 0,
        "band_rows": None,
        **tinfo,
    }
    if not host:
        info["render_s"] = None
        info["ray_stats"] = stats
        return GaussianImage(rgba, depth, None, None, info)
    hits, rounds = stats[..., 0], stats[..., 1]
    info["hits_per_ray_mean"] = float(hits.mean())
    info["hits_per_ray_max"] = int(hits.max())
    info["rounds_per_ray_mean"] = float(rounds.mean())
    return GaussianImage(rgba, depth, hits, rounds, info)


def render_gaussians(
    gaussians: Gaussians,
    camera: Camera,
    width: int,
    height: int,
    *,
    transfer_function: TransferFunction | None = None,
    model: str = "max_response",
    k: int | None = None,
    cutoff: float = 3.0,
    density: float = 1.0,
    queue: cl.CommandQueue | None = None,
    colors: bool | None = None,
    method: str | None = None,
) -> GaussianImage:
    """One frame of `gaussians`: a :class:`GaussianRenderer` and its ``render``."""
    r = GaussianRenderer(
        gaussians,
        transfer_function,
        model=model,
        k=k,
        cutoff=cutoff,
        density=density,
        queue=queue,
        colors=colors,
        method=method,
    )
    return r.render(camera, width, height)
