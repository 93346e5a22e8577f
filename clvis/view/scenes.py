"""What the viewer shows: a point cloud or a volume, in the modes its data allows.

A scene renders one view as a sequence of :class:`Frame` (one frame for a
point render, one per pass for a progressive isosurface); the server encodes
and sends each as it comes, and stops taking them once a newer view
supersedes the render. Renderers are made once (the point cloud and the
compressed volume stay on the device); the Gaussians and the post networks
are made when their mode is first chosen.

Point modes: ``points`` (the MACR Rasterizer's G-buffers, coloured by an
attribute through a colormap or by the points' RGB, point size), ``lidar``
(depth filter + the LiDAR U-Net), ``narvis`` (the NARVis network on the
G-buffers; clouds with a velocity), ``narvis-scan`` (NARVis for clouds without
one: the points' colours, depth and the splat radius plane of their
knn_sigma, computed once per cloud when the mode is first chosen),
``gaussians`` (Gaussians from the points, ray marched). Volume modes:
``iso`` (progressive isosurface: each pass as it completes), ``iso+infill``
(the in-fill network on each partial pass), ``gaussians`` (the volume's
Gaussians at a level of detail). A sparse volume (an OpenVDB grid,
:class:`SparseScene`): ``gaussians`` (its active voxels' Gaussians, never
made dense) and ``iso`` (``clvis iso FILE.vdb``'s isosurface: the grid made
dense when the mode is first chosen, where it fits in host memory). Split views
(``narvis|gaussians``, ``narvis-scan|gaussians``, ``infill|iso``): the fast
path's left half beside its slow target's right half, with the PSNR of the
whole frames.

Frames lie over images.BACKGROUND where what is covered is known (the
in-fill network gives its coverage); the LiDAR and NARVis networks predict
colour only, over black, and their frames (and the narvis splits) stay so.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..camera import Camera
from ..errors import DataError
from ..images import BACKGROUND
from ..io.volumes import otsu_level

if TYPE_CHECKING:  # clvis.post (onnxruntime) is imported only when a network is asked for
    from ..post import PostNetwork

__all__ = [
    "COLORMAPS",
    "DASK_MODES",
    "DaskPointScene",
    "DaskVolumeScene",
    "Frame",
    "PointScene",
    "Scene",
    "SparseScene",
    "VolumeScene",
    "psnr",
    "scene_for",
    "split",
    "view_frames",
]

COLORMAPS = ("viridis", "magma", "inferno", "plasma", "cividis", "turbo", "coolwarm", "gray")
_BG = np.array(BACKGROUND, np.uint8)
_BG32 = np.array((*BACKGROUND, 0), np.uint8).view(np.uint32)[0]  # as a pixel of an (H, W, 4) array
_ACTIVE32 = np.array((70, 40, 75, 0), np.uint8).view(np.uint32)[0]  # iso: rays still running
_MAX_POINT_SIZE = 16
#: a VolumeScene's modes
VOLUME_MODES = ("iso", "iso+infill", "gaussians", "infill|iso")
#: a SparseScene's modes of its grid made dense (a VolumeScene's but gaussians)
_SPARSE_ISO_MODES = tuple(m for m in VOLUME_MODES if m != "gaussians")
SPLIT_COMPLETION = 0.85  # infill|iso: the fast side stops at this fraction of the rays
# the held blocks the pool keeps (Scene._sized): about one largest page's
# (3840x2160) still and interaction sizes, however many pages are open
KEEP_PIXELS = 3840 * 2160 * 5 // 4
_FIT_SAMPLE = 20_000  # points the first view frames (every k-th)
#: the Gaussians an interaction frame of a gaussians mode draws at most (Potree's
#: default point budget): a fixed random subset, each sqrt(N / budget) times as
#: wide, so a surface keeps its cover while the camera moves (16 M Gaussians took
#: 5.7 s a frame on 2 cores); a still view shows that first, then draws them all
GAUSS_BUDGET = 1_000_000


@dataclass
class Frame:
    """One picture of a view: (H, W, 3) uint8, whether more follow for the
    same view, figures for the status line, and seconds per stage."""

    image: np.ndarray
    final: bool = True
    info: dict = field(default_factory=dict)
    times: dict = field(default_factory=dict)


class Scene:
    """Base: ``kind``, ``modes``, ``settings`` (what the page may change),
    ``choices`` (the values each setting takes), bounds ``lo``/``hi``."""

    kind = ""
    modes: list[str]
    settings: dict
    choices: dict
    lo: np.ndarray
    hi: np.ndarray
    fit_points: np.ndarray | None = None  # what the first view frames (None: the box)
    #: the first view's azimuth (Orbit's, degrees): from -x, -y; a scan in RAS+
    #: order (+y anterior) is seen from the front instead (VolumeScene anatomical)
    home_azimuth = -115.0
    #: where the scene's coordinates start in the file's (a point cloud's
    #: origin); the camera the page shows and takes is in the file's
    file_origin: np.ndarray = np.zeros(3)
    description = ""
    device = ""
    # the modes whose frames() yields one frame per pass (see view_frames: a
    # still view of these starts with a smaller first pass)
    progressive: frozenset[str] = frozenset()

    # the frame sizes whose held blocks the queue's pool keeps, the most recent last
    _sizes: tuple = ()
    #: how many sizes keep their held blocks: a still and an interaction size
    #: a page (the server sets it to twice the pages open)
    kept_sizes = 2
    _pool_queue: Any = None  # the queue whose pool _sized watches
    _trim = False  # _sized gave blocks back: view_frames trims the C heap after the frames

    def _sized(self, queue: Any, width: int, height: int) -> None:
        """Before a frame of `width` x `height`: when it is a size beyond the
        kept ones (``kept_sizes``, their pixels within KEEP_PIXELS: a page's
        window was resized, or a page opened), the queue's memory pool gives
        back the blocks it holds for reuse. The pool keeps a freed block of
        every size it has seen, so a window dragged through 70 sizes grew the
        server by 800 MB; the pages' still and interaction sizes keep theirs."""
        self._pool_queue = queue
        size = (width, height)
        if size in self._sizes:
            self._sizes = (*(s for s in self._sizes if s != size), size)
            return
        kept = (*self._sizes, size)[-max(1, self.kept_sizes) :]
        while len(kept) > 1 and sum(w * h for w, h in kept) > KEEP_PIXELS:
            kept = kept[1:]
        if len(kept) <= len(self._sizes):  # a size no longer kept: its blocks go back
            from ..runtime import free_held

            free_held(queue)
            self._trim = True  # and, after this frame, the old size's host arrays' pages (view_frames)
        self._sizes = kept

    def release(self, sizes: Any = ()) -> None:
        """A page went away (on the render thread): its frame `sizes` are no
        longer kept, and the pool gives back the blocks it holds (those of
        the other pages' sizes too: their next frames allocate them again)."""
        self._sizes = tuple(s for s in self._sizes if s not in set(sizes))
        if self._pool_queue is not None:
            from ..runtime import free_held

            free_held(self._pool_queue)

    def update(self, changes: dict) -> None:
        """Apply settings from the page (a dict); ValueError for anything else,
        an unknown key or value (a number must be finite: not a bool, a string,
        NaN, an infinity or an integer too large for a float)."""
        if not isinstance(changes, dict):
            raise ValueError(f"settings: expected an object, got {type(changes).__name__}")
        new = dict(self.settings)
        for key, value in changes.items():
            if key not in self.settings:
                raise ValueError(f"unknown setting {key!r}")
            allowed = self.choices.get(key)
            if isinstance(allowed, list) and value not in allowed:
                raise ValueError(f"{key}: expected one of {allowed}, got {value!r}")
            if isinstance(allowed, dict):  # a number range
                try:
                    if isinstance(value, bool) or not isinstance(value, (int, float)):
                        raise TypeError
                    if not math.isfinite(value):  # an int too large for a float: OverflowError
                        raise ValueError
                    value = type(self.settings[key])(value)
                except (TypeError, ValueError, OverflowError):
                    raise ValueError(f"{key}: expected a number, got {value!r:.40}") from None
                if not allowed["min"] <= value <= allowed["max"]:
                    raise ValueError(f"{key}: expected {allowed['min']}..{allowed['max']}, got {value!r}")
            new[key] = value
        self.settings = new

    def frames(
        self, camera: Camera, width: int, height: int, settings: dict, superseded: Callable[[], bool]
    ) -> Iterator[Frame]:
        raise NotImplementedError

    _gauss: dict[tuple, Any]

    def _gaussian_frames(
        self, key: tuple, make: Callable[[], tuple[Any, int]], camera, w, h, settings: dict, superseded
    ) -> Iterator[Frame]:
        """A gaussians mode's frames of one view. An interaction frame (the
        camera moving: settings["interacting"], the server's) of more than
        GAUSS_BUDGET Gaussians draws the budget's subset (_budget; info
        "gaussians" the count drawn, "of" all); a still view of that many
        starts with that frame at its size (not final, info "preview"), then,
        unless the view was superseded, draws them all."""
        if settings.get("interacting", False):
            yield self._gaussian_frame(key, make, camera, w, h, True)
            return
        first = self._gaussian_frame(key, make, camera, w, h, True)
        if "of" not in first.info:  # within the budget: that was the whole set
            yield first
            return
        first.final, first.info = False, {**first.info, "preview": "budget"}
        yield first
        if superseded():
            return
        try:  # the whole set, given up between its bands once a newer view supersedes it
            full = self._gaussian_frame(key, make, camera, w, h, False, superseded)
        except _Superseded:
            return
        yield full

    def _gaussian_frame(
        self,
        key: tuple,
        make: Callable[[], tuple[Any, int]],
        camera,
        w,
        h,
        interacting: bool = False,
        superseded: Callable[[], bool] | None = None,
    ) -> Frame:
        """A gaussians mode's frame: the renderer of `key` (made by `make`,
        (GaussianRenderer, count), when the key is new: the previous one goes
        first), its render, and the build's time apart from the render's;
        `interacting`, over GAUSS_BUDGET: the budget's subset. `superseded`:
        asked after each band of rows (_Superseded raised when it says so)."""
        t0 = time.perf_counter()
        if key not in self._gauss:
            self._gauss = {}
            self._gauss = {key: make()}
        renderer, count = self._gauss[key]
        info = {"gaussians": count}
        if interacting and count > GAUSS_BUDGET:
            if (key, "budget") not in self._gauss:
                self._gauss[(key, "budget")] = _budget(renderer, GAUSS_BUDGET)
            renderer, info = self._gauss[(key, "budget")], {"gaussians": GAUSS_BUDGET, "of": count}
        build = time.perf_counter() - t0

        def band(done: int, total: int) -> None:
            if superseded is not None and done < total and superseded():
                raise _Superseded

        img = renderer.render(camera, w, h, progress=band)
        times = {"render": time.perf_counter() - t0 - build}
        if build > 1e-3:
            times["build"] = build
        return Frame(img.to_uint8(BACKGROUND)[..., :3], info=info, times=times)

    def close(self) -> None:
        """Let go of what the scene holds outside this process (a Dask scene: its cluster)."""


class _Superseded(Exception):
    """A frame given up part-way: a newer view superseded it (_gaussian_frames)."""


def _budget(renderer: Any, budget: int) -> Any:
    """A renderer of `budget` of `renderer`'s Gaussians (a fixed random
    subset, in their order), each sqrt(N / budget) times as wide (the area a
    Gaussian stands for on a surface grows by N / budget), with the same
    transfer function over the whole set's value range (the subset's own
    would shift the colours) and the same model, density and queue."""
    from .. import GaussianRenderer, TransferFunction
    from ..colormap import value_range

    g = renderer.gaussians
    pick = np.sort(np.random.default_rng(0).choice(g.n, budget, replace=False))
    sub = g.subset(pick)
    sub.scales = (sub.scales * np.float32(math.sqrt(g.n / budget))).astype(np.float32)
    tf = renderer.transfer_function
    fixed = TransferFunction(
        tf.colormap,
        opacity=tf.opacity_points,
        value_range=tf.value_range if tf.value_range is not None else value_range(g.values),
        entries=tf.entries,
    )
    return GaussianRenderer(
        sub, fixed, model=renderer.model, k=renderer.k, density=renderer.density, queue=renderer.queue
    )


def _over_background(rgb: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8: `rgb` where `covered`, the background elsewhere.
    rgb: (H, W, 3) or (H, W, 4) uint8 (the fourth channel ignored); from four
    channels the result is the RGB view of an (H, W, 4) array, made by one
    pass over 32-bit pixels (server.encode_jpeg reads that layout as is)."""
    if rgb.shape[-1] == 4:
        px = np.where(covered, np.ascontiguousarray(rgb).view(np.uint32)[..., 0], _BG32)
        return px.view(np.uint8).reshape(px.shape + (4,))[..., :3]
    out = np.empty(covered.shape + (3,), np.uint8)
    out[...] = _BG
    np.copyto(out, rgb, where=covered[..., None])
    return out


def _float_rgb8(rgba: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8 of float colours in [0, 1]: each channel rint(255 v),
    clipped to 0..255 (the alpha channel too; callers use the first three)."""
    f = np.multiply(rgba, np.float32(255), dtype=np.float32)
    np.rint(f, out=f)
    np.clip(f, 0, 255, out=f)
    return f.astype(np.uint8)


def _premultiplied_over_background(rgba8: np.ndarray) -> np.ndarray:
    """A network's RGBA8 picture (colour premultiplied over black) over the background."""
    if rgba8[..., 3].min(initial=255) == 255:  # opaque everywhere (NARVis, LiDAR): the colour itself
        return rgba8[..., :3]
    a = rgba8[..., 3:4].astype(np.float32) / 255
    rgb = rgba8[..., :3].astype(np.float32) + (1 - a) * _BG.astype(np.float32)
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8)


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two uint8 pictures (inf where they are equal)."""
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def split(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """The left half of `left` beside the right half of `right`, a light line between."""
    out = right.copy()
    w = out.shape[1]
    out[:, : w // 2] = left[:, : w // 2]
    out[:, max(w // 2 - 1, 0) : w // 2 + 1] = (200, 200, 200)
    return out


class PointScene(Scene):
    """A point cloud (a clvis.PointCloud)."""

    kind = "points"

    def __init__(self, cloud: Any, description: str = "points", model_dir: Any = None) -> None:
        """model_dir: where its networks' models are (clvis train --out; None:
        the package's), loaded when a network's mode is first chosen."""
        from .. import PointCloud, Rasterizer

        self.model_dir = _model_dir(model_dir)

        if not isinstance(cloud, PointCloud):
            cloud = PointCloud(np.asarray(cloud))
        if len(cloud.positions) == 0:
            raise DataError(f"{description}: no points to show")
        self.cloud = cloud
        self.file_origin = np.asarray(cloud.origin, np.float64)
        pos = cloud.positions
        finite = np.isfinite(pos).all(axis=1)
        if not finite.any():
            raise DataError(f"{description}: no point has finite coordinates")
        # the Gaussian modes' points: those the rasterizer draws (a NaN or
        # infinite coordinate makes no Gaussian and no kNN neighbour)
        self._finite = None if finite.all() else finite
        self._gauss_cloud = cloud if self._finite is None else cloud.subset(finite)
        self.lo, self.hi = (
            pos[finite].min(axis=0).astype(np.float64),
            pos[finite].max(axis=0).astype(np.float64),
        )
        step = max(1, len(pos) // _FIT_SAMPLE)
        sample = pos[::step]
        self.fit_points = sample[np.isfinite(sample).all(axis=1)].astype(np.float64)
        attrs = dict(cloud.attributes) if cloud.attributes else {"z": pos[:, 2]}
        self.attributes = list(attrs)
        self._raster_attrs = None if cloud.attributes else attrs  # None: the cloud's own
        self.raster = Rasterizer(cloud, attributes=attrs) if not cloud.attributes else Rasterizer(cloud)
        self.device = self.raster.queue.device.name.strip()
        self.description = f"{description}: {len(cloud.positions):,} points"
        self._source = description
        self._velocity_checked = False
        colours = (["rgb"] if cloud.colors is not None else []) + self.attributes
        # the NARVis model the cloud's planes allow (as clvis render --post narvis):
        # narvis with a velocity, narvis-scan without one
        self.narvis = "narvis" if cloud.velocity is not None else "narvis-scan"
        self.modes = ["points", "lidar", self.narvis, "gaussians", f"{self.narvis}|gaussians"]
        self.settings = {"mode": "points", "color_by": colours[0], "colormap": "viridis", "point_size": 1}
        self.choices = {
            "mode": self.modes,
            "color_by": colours,
            "colormap": list(COLORMAPS),
            "point_size": {"min": 1, "max": _MAX_POINT_SIZE},
        }
        self._nets: dict[str, Any] = {}
        # one entry: "gaussians" mode's (renderer, count) by ("gaussians",
        # colour, colormap), or the split mode's (NarvisScene, renderer) by
        # ("split", attribute, colormap)
        self._gauss: dict[tuple[str, ...], Any] = {}
        #: narvis-scan's splat radius (the points' knn_sigma), once per cloud
        self.scan_radius: np.ndarray | None = None
        #: GR's base sigma (clvis.training.data.narvis_sigma of the points
        #: drawn), once per cloud: a narvis model with the radius plane reads
        #: it as every point's radius
        self.flow_sigma: float | None = None

    def _scan_raster(self) -> float:
        """Make the Rasterizer narvis-scan reads, once: the cloud's knn_sigma
        (clvis.training.data.SCAN_K, what the network was trained on; a radius
        the cloud brings is not used) as the per-point radius, so that every
        render resolves GBuffers.radius_px. It replaces the plain one (the same
        pictures, plus that plane). Returns the seconds it took (0: made before)."""
        if self.scan_radius is not None:
            return 0.0
        from .. import Rasterizer
        from ..gauss.points import knn_sigma
        from ..training.data import SCAN_K

        t0 = time.perf_counter()
        if self._finite is None:
            radius = knn_sigma(self.cloud.positions, SCAN_K)
        else:  # the points drawn; the others' radius is never read
            radius = np.zeros(len(self.cloud.positions), np.float32)
            radius[self._finite] = knn_sigma(self._gauss_cloud.positions, SCAN_K)
        self.raster = Rasterizer(
            self.cloud, attributes=self._raster_attrs, radius=radius, queue=self.raster.queue
        )
        self.scan_radius = radius
        return time.perf_counter() - t0

    def _flow_raster(self) -> float:
        """Make the Rasterizer a narvis model with the radius plane reads,
        once: GR's sigma (clvis.training.data.narvis_sigma of the points
        drawn, what the network was trained on; a radius the cloud brings is
        not used) as every point's radius. A model without that plane keeps
        the plain one. Returns the seconds it took (0: made before or not needed)."""
        if self.flow_sigma is not None or "radius" not in self._net("narvis").planes:
            return 0.0
        from .. import Rasterizer
        from ..training.data import narvis_radius, narvis_sigma

        t0 = time.perf_counter()
        sigma = narvis_sigma(self._gauss_cloud.positions)
        radius = narvis_radius(self.cloud.positions, sigma)
        self.raster = Rasterizer(
            self.cloud, attributes=self._raster_attrs, radius=radius, queue=self.raster.queue
        )
        self.flow_sigma = sigma
        return time.perf_counter() - t0

    def _check_velocity(self) -> None:
        """DataError naming the file, the velocity and the first point drawn
        whose velocity is NaN or infinite, before the narvis modes read it (the
        network's input check said only "vel_x: 1 covered pixels ...")."""
        if not self._velocity_checked:
            from ..io.cloud import check_finite

            v = self.cloud.velocity
            check_finite(
                f"{self._source}: velocity",
                v if self._finite is None else np.where(self._finite[:, None], v, 0),
            )
            self._velocity_checked = True

    def _net(self, name: str):
        if name not in self._nets:
            from .. import post  # onnxruntime: only when a network is asked for

            self._nets[name] = post.load(name, queue=self.raster.queue, directory=self.model_dir)
        return self._nets[name]

    def _render(self, camera, w, h, s, point_size=None, **kw):
        attr = None if s["color_by"] == "rgb" else s["color_by"]
        ps = s["point_size"] if point_size is None else point_size
        return self.raster.render(
            camera, w, h, color_by=attr, colormap=s["colormap"], point_size=ps, planes=[], **kw
        )

    def frames(
        self, camera: Camera, width: int, height: int, settings: dict, superseded: Callable[[], bool]
    ) -> Iterator[Frame]:
        mode = settings["mode"]
        self._sized(self.raster.queue, width, height)
        t0 = time.perf_counter()
        if mode == "gaussians":
            yield from self._gaussians(camera, width, height, settings, superseded)
            return
        if mode in ("narvis", "narvis|gaussians"):
            self._check_velocity()
        if mode == "narvis|gaussians":
            yield self._split(camera, width, height, settings)
            return
        if mode == "narvis-scan|gaussians":
            yield self._scan_split(camera, width, height, settings)
            return
        info: dict[str, Any] = {"points": len(self.cloud.positions)}
        if mode == "points":
            # rgba and coverage only: no screen velocity; index, depth and rgba read back
            g = self._render(camera, width, height, settings, screen_velocity=False)
            info["points read"] = g.stats.get("points_read", 0)
            t1 = time.perf_counter()
            image = _over_background(g.rgba, g.index != 0xFFFFFFFF)
            yield Frame(image, info=info, times={"render": t1 - t0})
            return
        from .. import depth_filter

        build = {"narvis-scan": self._scan_raster, "narvis": self._flow_raster}.get(mode, lambda: 0.0)()
        t0 += build
        # the networks read the G-buffers where they are (host=False: nothing
        # read back, nothing uploaded again; narvis-scan: its depth filter
        # reads the planes back once, _prefiltered); NARVis needs the screen
        # velocity, narvis-scan the radius plane (every render of the scan
        # Rasterizer)
        g = self._render(camera, width, height, settings, 1, screen_velocity=mode == "narvis", host=False)
        src = depth_filter(g) if mode == "lidar" else g
        self.raster.queue.finish()  # the render's own time in "render", not in "post"
        t1 = time.perf_counter()
        net = self._net(mode)
        if mode == "narvis-scan":
            rgba, scale = self._scan_picture(net, src, camera, width, height, settings)
            if scale > 1:
                info["post scale"] = scale
        else:
            rgba = net(src)
        t2 = time.perf_counter()
        info["inference ms"] = round(1e3 * net.stats.get("inference", 0.0), 1)
        times = {"render": t1 - t0, "post": t2 - t1}
        if build > 1e-3:
            times["build"] = build
        yield Frame(_premultiplied_over_background(rgba), info=info, times=times)

    def _split(self, camera, w, h, s):
        """MACR + NARVis (left) beside its slow target, the Gaussian renderer
        over the velocity-elongated Gaussians it was trained on (right), with
        the PSNR of the whole frames (both over black, as the network predicts)."""
        from ..colormap import value_range
        from ..training.data import NARVIS_ATTRIBUTE, NarvisScene

        attr = s["color_by"] if s["color_by"] != "rgb" else NARVIS_ATTRIBUTE
        if attr not in self.cloud.attributes:
            attr = self.attributes[0]
        key = ("split", attr, s["colormap"])
        t0 = time.perf_counter()
        self._flow_raster()
        if key not in self._gauss:
            vr = value_range(self.cloud.attributes[attr])
            ns = NarvisScene(self._gauss_cloud, attr, vr, s["colormap"], "view", self.flow_sigma)
            self._gauss = {key: (ns, ns.gaussian_renderer(queue=self.raster.queue))}
        build = time.perf_counter() - t0
        ns, gr = self._gauss[key]
        net = self._net("narvis")
        t1 = time.perf_counter()
        g = ns.gbuffers(self.raster, camera, w, h, net.planes)
        ta = time.perf_counter()
        fast = net(g)[..., :3]
        t2 = time.perf_counter()
        slow = gr.render(camera, w, h).to_uint8((0, 0, 0))[..., :3]
        t3 = time.perf_counter()
        times = {"render": (ta - t1) + (t3 - t2), "post": t2 - ta}
        if build > 1e-3:
            times["build"] = build
        info = {"psnr dB": round(psnr(fast, slow), 2), "fast ms": round(1e3 * (t2 - t1), 1)}
        info["slow ms"] = round(1e3 * (t3 - t2), 1)
        return Frame(split(fast, slow), info=info, times=times)

    def _scan_split(self, camera, w, h, s):
        """MACR + narvis-scan (left) beside its slow target, the 3DGS splat of
        the isotropic Gaussians it was trained on (right: sigma the radius
        plane's knn_sigma, clvis.training.data.ScanScene, in the colours the
        points are drawn in: their RGB or the attribute through the colormap),
        with the PSNR of the whole frames (both over black)."""
        from ..training.data import ScanScene

        key = ("scan-split", s["color_by"], s["colormap"] if s["color_by"] != "rgb" else "")
        t0 = time.perf_counter()
        self._scan_raster()
        if key not in self._gauss:
            from ..io import PointCloud

            keep = slice(None) if self._finite is None else self._finite
            radius = self.scan_radius
            assert radius is not None  # made by _scan_raster above
            cloud = PointCloud(self.cloud.positions[keep], colors=self._colours(s)[keep], radius=radius[keep])
            ss = ScanScene(cloud, "landscape", "view")
            self._gauss = {key: ss.gaussian_renderer(queue=self.raster.queue)}
        build = time.perf_counter() - t0
        gr = self._gauss[key]
        net = self._net("narvis-scan")
        t1 = time.perf_counter()
        g = self._render(camera, w, h, s, 1, screen_velocity=False, host=False)
        self.raster.queue.finish()
        ta = time.perf_counter()
        picture, scale = self._scan_picture(net, g, camera, w, h, s)
        fast = picture[..., :3]
        t2 = time.perf_counter()
        slow = gr.render(camera, w, h).to_uint8((0, 0, 0))[..., :3]
        t3 = time.perf_counter()
        times = {"render": (ta - t1) + (t3 - t2), "post": t2 - ta}
        if build > 1e-3:
            times["build"] = build
        info = {"psnr dB": round(psnr(fast, slow), 2), "fast ms": round(1e3 * (t2 - t1), 1)}
        info["slow ms"] = round(1e3 * (t3 - t2), 1)
        if scale > 1:
            info["post scale"] = scale
        return Frame(split(fast, slow), info=info, times=times)

    def _scan_picture(self, net, g, camera, w, h, s) -> tuple[np.ndarray, int]:
        """narvis-scan's picture of the view whose full-size device G-buffers
        are `g`, and the scale it was made at: its depth filter first (the
        planes come back once, _prefiltered), then, where the view is sparser
        on screen than its training frames (PostNetwork.render_scale, read off
        those host planes: no further read-back), the same through a frame
        rendered that many times smaller, resized up smoothed."""
        gf = _prefiltered(net, g)
        scale = net.render_scale(gf)
        if scale == 1:
            return net(gf), 1
        from ..post import SCALED_SMOOTH, resized

        sw, sh = round(w / scale), round(h / scale)
        small = self._render(camera.with_aspect(sw / sh), sw, sh, s, 1, screen_velocity=False, host=False)
        return resized(net(_prefiltered(net, small)), w, h, smooth=SCALED_SMOOTH), scale

    def _colours(self, s) -> np.ndarray:
        """(N, 4) uint8: the points' colours as the Rasterizer draws them with
        settings `s` (their RGB, or the attribute through the colormap over its
        finite range)."""
        if s["color_by"] == "rgb":
            return np.asarray(self.cloud.colors)
        from ..colormap import apply, lut, value_range

        values = (self.cloud.attributes or {"z": self.cloud.positions[:, 2]})[s["color_by"]]
        return apply(values, lut(s["colormap"]), *value_range(values))

    def _gaussians(self, camera, w, h, s, superseded):
        from .. import GaussianRenderer, TransferFunction, gaussians_from_points

        # the colormap matters to an attribute's colours, not to the points' RGB
        key = ("gaussians", s["color_by"], s["colormap"] if s["color_by"] != "rgb" else "")

        def make():
            gs = gaussians_from_points(self._gauss_cloud, color_by=s["color_by"])
            return GaussianRenderer(gs, TransferFunction(s["colormap"]), queue=self.raster.queue), gs.n

        return self._gaussian_frames(key, make, camera, w, h, s, superseded)


class VolumeScene(Scene):
    """A volume [z, y, x], compressed with ZFP and raycast progressively; the
    isovalue by default Otsu's threshold of its samples, as ``clvis iso`` and
    ``clvis view FILE`` choose it (the middle of the range showed a few blobs
    of a scan: ``clvis.view(array)`` drew other surfaces than the commands)."""

    kind = "volume"

    def __init__(
        self,
        volume: Any,
        spacing: Any = (1.0, 1.0, 1.0),
        origin: Any = (0.0, 0.0, 0.0),
        isovalue: float | None = None,
        rate: int = 8,
        description: str = "volume",
        model_dir: Any = None,
        *,
        modes: Any = None,
        anatomical: bool = False,
    ) -> None:
        """model_dir: where the in-fill network's model is (clvis train --out;
        None: the package's), loaded when an in-fill mode is first chosen.
        modes: the modes offered, some of VOLUME_MODES in their order (None:
        all); without gaussians the volume is not kept on the host (the
        compressed copy on the device draws the others). anatomical: a scan
        in RAS+ order (+y anterior: read_volume's NIfTI, MGH, Analyze), first
        seen from the front (its face), not from behind."""
        from .. import IsoRenderer

        if modes is None:
            modes = VOLUME_MODES
        if isinstance(modes, str) or not set(modes) <= set(VOLUME_MODES) or not modes:
            raise ValueError(f"modes: expected some of {VOLUME_MODES}, got {modes!r}")

        self.model_dir = _model_dir(model_dir)
        if anatomical:
            self.home_azimuth = 115.0  # from -x, +y: the face, as the commands' default view

        data = np.asarray(volume)
        if data.ndim != 3:
            raise DataError(f"{description}: expected a 3-D volume [z, y, x], got shape {data.shape}")
        data = np.ascontiguousarray(data, np.float32)
        finite = data[np.isfinite(data)]
        if finite.size == 0:
            raise DataError(f"{description}: no finite sample")
        vmin, vmax = float(finite.min()), float(finite.max())
        isovalue = _isovalue(isovalue)
        if isovalue is None:
            isovalue = otsu_level(finite)
        # the gaussians mode's samples (None: not offered)
        self.volume: np.ndarray | None = data if "gaussians" in modes else None
        self.spacing, self.origin = tuple(spacing), tuple(origin)
        self.iso = IsoRenderer(data, rate, spacing, origin)
        self.device = self.iso.queue.device.name.strip()
        self.lo = np.asarray(origin, np.float64)
        self.hi = self.lo + (np.array(data.shape[::-1]) - 1) * np.asarray(spacing, np.float64)[::-1]
        self.description = f"{description}: {'x'.join(map(str, data.shape[::-1]))} samples"
        self.modes = [m for m in VOLUME_MODES if m in modes]
        self.progressive = frozenset(("iso", "iso+infill"))
        self.settings = {"mode": self.modes[0], "isovalue": float(isovalue), "lod": "medium"}
        self.choices = {
            "mode": self.modes,
            "isovalue": {"min": vmin, "max": vmax},
            "lod": ["low", "medium", "high"],
        }
        self._infill: PostNetwork | None = None
        self._gauss: dict[tuple, Any] = {}

    def frames(
        self, camera: Camera, width: int, height: int, settings: dict, superseded: Callable[[], bool]
    ) -> Iterator[Frame]:
        mode = settings["mode"]
        self._sized(self.iso.queue, width, height)
        if mode == "gaussians":
            yield from self._gaussians(camera, width, height, settings, superseded)
            return
        if mode == "infill|iso":
            yield self._split(camera, width, height, settings)
            return
        if mode == "iso+infill" and self._infill is None:
            from .. import post

            self._infill = post.load("infill", queue=self.iso.queue, directory=self.model_dir)
        from .._arrays import on_host

        t0 = time.perf_counter()
        n = 0
        for img in self.iso.passes(camera, width, height, settings["isovalue"]):
            n += 1
            t1 = time.perf_counter()
            times = {"render": t1 - t0}
            done = not img.active.any()
            info = {"pass": n, "completion": round(float(img.completion), 4)}
            if mode == "iso+infill" and not done:
                assert self._infill is not None  # loaded above for this mode
                rgba = self._infill(img)
                image = _premultiplied_over_background(rgba)
                times["post"] = time.perf_counter() - t1
            else:
                hit = on_host(img.hit)
                rgb = _float_rgb8(on_host(img.rgba))
                if not done:  # rays still running: their colour (one 32-bit pixel each)
                    rgb.view(np.uint32)[..., 0][on_host(img.active) & ~hit] = _ACTIVE32
                    hit = hit | on_host(img.active)
                image = _over_background(rgb, hit)
            yield Frame(image, final=done, info=info, times=times)
            if superseded():
                return
            t0 = time.perf_counter()

    def _split(self, camera, w, h, s):
        """The render stopped at SPLIT_COMPLETION of the rays with the in-fill
        network (left) beside the complete render (right), and their PSNR:
        one frame, final. The fast side's passes go without speculation, as
        the in-fill network's pairs and clvis eval's were made (a pass tests
        one candidate block a ray: the completion grows in small steps); with
        it the second pass already finished 97-99 % of the rays, and the left
        half was in-fill over 1-3 % instead of 15 %."""
        from .._arrays import on_host

        if self._infill is None:
            from .. import post

            self._infill = post.load("infill", queue=self.iso.queue, directory=self.model_dir)
        t0 = time.perf_counter()
        part = self.iso.render(camera, w, h, s["isovalue"], completion=SPLIT_COMPLETION, speculation=False)
        t1 = time.perf_counter()
        fast = _premultiplied_over_background(self._infill(part))
        t2 = time.perf_counter()
        full = self.iso.render(camera, w, h, s["isovalue"])
        slow = _over_background(_float_rgb8(on_host(full.rgba)), on_host(full.hit))
        t3 = time.perf_counter()
        info = {
            "psnr dB": round(psnr(fast, slow), 2),
            "fast ms": round(1e3 * (t2 - t0), 1),
            "slow ms": round(1e3 * (t3 - t2), 1),
            # each side's fraction of the rays: the fast one's stop, the slow one complete
            "fast completion": round(float(part.completion), 3),
            "slow completion": round(float(full.completion), 3),
        }
        return Frame(split(fast, slow), info=info, times={"render": (t1 - t0) + (t3 - t2), "post": t2 - t1})

    def _gaussians(self, camera, w, h, s, superseded):
        from .. import GaussianRenderer, gaussians_from_volume

        def make():
            assert self.volume is not None  # kept where the mode is offered
            gs = gaussians_from_volume(
                self.volume, s["lod"], threshold=s["isovalue"], spacing=self.spacing, origin=self.origin
            )
            if gs.n == 0:
                raise DataError(f"no voxel above the isovalue {s['isovalue']:g}: no Gaussians")
            return GaussianRenderer(gs, queue=self.iso.queue), gs.n

        return self._gaussian_frames((s["lod"], s["isovalue"]), make, camera, w, h, s, superseded)


class SparseScene(Scene):
    """A sparse volume (clvis.SparseVolume: read_vdb's OpenVDB grid): mode
    ``gaussians``, the Gaussians of its active voxels (Sharma & Schmalstieg),
    never made dense: its level of detail, and ``threshold``: the active
    voxels above it are drawn (at its least value, the default: every active
    voxel, a level set's negative values too). The colours span the grid's
    active values whatever the threshold, so a colour keeps its value as the
    threshold moves. The Gaussians are made when a level of detail or a
    threshold is first shown (the last one kept). A grid of class "fog
    volume" is drawn as a fog (clvis.gauss.render.FOG_OPACITY: its low values
    faint, so their shell does not hide the bright inside).

    Mode ``iso``: the isosurface ``clvis iso FILE.vdb`` draws, at
    ``isovalue`` (default :func:`clvis.gauss.default_isovalue`: 0 for a level
    set, else Otsu's of the dense volume, read from the leaves): the grid
    made dense (:func:`clvis.gauss.dense_volume`: its inactive voxels the
    grid's background) into a :class:`VolumeScene` when the mode is first
    chosen, whose progressive iso mode draws it. A dense volume beyond host
    memory is refused then (a DeviceError: the page's status line shows it),
    and the gaussians mode goes on as before. Modes ``iso+infill`` and
    ``infill|iso``: the in-fill network on that isosurface, as a volume's
    (VolumeScene)."""

    kind = "sparse volume"

    def __init__(
        self,
        volume: Any,
        colormap: str = "viridis",
        description: str = "sparse volume",
        model_dir: Any = None,
        isovalue: float | None = None,
        rate: int = 8,
    ) -> None:
        """model_dir: where the in-fill network's model is (the iso modes';
        None: the package's). isovalue, rate: the iso modes' first isovalue
        (None: default_isovalue's) and ZFP bits per value (VolumeScene's)."""
        from .. import runtime
        from ..gauss.sparse import SparseVolume, default_isovalue

        if not isinstance(volume, SparseVolume):
            raise TypeError(f"volume: expected a clvis.SparseVolume, got {type(volume).__name__}")
        if colormap not in COLORMAPS:
            raise ValueError(f"colormap: expected one of {', '.join(COLORMAPS)}, got {colormap!r}")
        self.model_dir = _model_dir(model_dir)
        if volume.n_active == 0:
            raise DataError(f"{description}: no active voxel")
        isovalue = _isovalue(isovalue)
        values = volume.leaf_values()[volume.active_masks()]
        self.sparse, self.colormap, self.rate = volume, colormap, rate
        self.vmin, self.vmax = float(values.min()), float(values.max())
        # the dense volume's range: the background too where a voxel is not active
        ilo, ihi = self.vmin, self.vmax
        if volume.n_active < math.prod(volume.shape) and math.isfinite(volume.background):
            ilo, ihi = min(ilo, volume.background), max(ihi, volume.background)
        self.queue = runtime.default_queue()
        self.device = self.queue.device.name.strip()
        spacing = np.asarray(volume.spacing, np.float64)[::-1]  # (dx, dy, dz)
        self.lo = np.asarray(volume.origin, np.float64)
        self.hi = self.lo + (np.array(volume.shape[::-1]) - 1) * spacing
        kind = f", a {volume.grid_class}" if volume.grid_class else ""
        self.description = (
            f"{description}: {'x'.join(map(str, volume.shape[::-1]))} voxels, "
            f"{volume.n_active:,} active in {volume.n_leaves:,} leaves{kind}"
        )
        self._source = description
        self.modes = ["gaussians", *_SPARSE_ISO_MODES]
        self.progressive = frozenset(("iso", "iso+infill"))
        if isovalue is None:
            isovalue = default_isovalue(volume)
        self.settings = {
            "mode": "gaussians",
            "lod": "medium",
            "threshold": self.vmin,
            "isovalue": float(isovalue),
        }
        self.choices = {
            "mode": self.modes,
            "lod": ["low", "medium", "high"],
            "threshold": {"min": self.vmin, "max": self.vmax},
            "isovalue": {"min": ilo, "max": ihi},
        }
        self._gauss: dict[tuple, Any] = {}
        self._dense: VolumeScene | None = None  # the iso mode's, made when it is first chosen

    def _iso_scene(self) -> VolumeScene:
        """The grid made dense as a VolumeScene, once (DeviceError, before it
        is made, where it would not fit in host memory)."""
        if self._dense is None:
            from ..gauss.sparse import dense_volume

            sv = self.sparse
            data = dense_volume(sv, f"{self._source}: the grid", "mode gaussians")
            self._dense = VolumeScene(
                data,
                sv.spacing,
                sv.origin,
                self.settings["isovalue"],
                self.rate,
                description=self._source,
                model_dir=self.model_dir,
                # no gaussians: the dense copy goes once, compressed, on the device
                modes=list(_SPARSE_ISO_MODES),
            )
        return self._dense

    def frames(
        self, camera: Camera, width: int, height: int, settings: dict, superseded: Callable[[], bool]
    ) -> Iterator[Frame]:
        if settings["mode"] in _SPARSE_ISO_MODES:
            dense = self._iso_scene()
            dense.kept_sizes = self.kept_sizes
            try:
                yield from dense.frames(
                    camera,
                    width,
                    height,
                    {"mode": settings["mode"], "isovalue": settings["isovalue"]},
                    superseded,
                )
            finally:
                if dense._trim:  # its pool gave blocks back: view_frames trims the heap after
                    dense._trim, self._trim = False, True
            return
        from .. import GaussianRenderer, TransferFunction, gaussians_from_volume
        from ..gauss.render import FOG_OPACITY

        self._sized(self.queue, width, height)
        threshold = settings["threshold"]

        def make():
            sv = self.sparse if threshold <= self.vmin else self.sparse.restricted(threshold=threshold)
            gs = gaussians_from_volume(sv, settings["lod"], queue=self.queue)
            if gs.n == 0:
                raise DataError(f"no active voxel above the threshold {threshold:g}: no Gaussians")
            # one value (an occupancy grid): at the top of the colours, not the darkest bottom
            lo = self.vmin if self.vmax > self.vmin else self.vmax - max(abs(self.vmax), 1.0)
            # a fog (the grid's class): its low values faint, its bright inside shown
            fog = FOG_OPACITY if self.sparse.grid_class == "fog volume" else None
            tf = TransferFunction(self.colormap, value_range=(lo, self.vmax), opacity=fog)
            return GaussianRenderer(gs, tf, queue=self.queue), gs.n

        yield from self._gaussian_frames(
            (settings["lod"], threshold), make, camera, width, height, settings, superseded
        )

    def release(self, sizes: Any = ()) -> None:
        super().release(sizes)
        if self._dense is not None:
            self._dense.release(sizes)


def view_frames(
    scene: Scene,
    camera: Camera,
    width: int,
    height: int,
    settings: dict,
    superseded: Callable[[], bool],
    preview: tuple[Camera, int, int] | None = None,
) -> Iterator[Frame]:
    """The frames of one view: ``scene.frames``, led, for a mode in
    ``scene.progressive`` and a `preview` (camera, width, height; the server
    gives the interaction size for a still view), by the first pass at that
    size (``final`` False, ``info["preview"]`` its size), so that a frame is on
    the screen after a pass over a quarter of the pixels; then the passes at
    full size, the last of which is the still frame (unchanged)."""
    if preview is not None and settings.get("mode") in scene.progressive:
        cam, w, h = preview
        if (w, h) != (width, height):
            passes = scene.frames(cam, w, h, settings, superseded)
            first = next(passes, None)
            close = getattr(passes, "close", None)  # a generator: let its passes go
            if close is not None:
                close()
            if first is not None:
                first.final = False
                first.info = {**first.info, "preview": f"{w}x{h}"}
                yield first
                if superseded():
                    return
    yield from scene.frames(camera, width, height, settings, superseded)
    if scene._trim:  # a new size's frames are done: the C heap's free pages go back (trim_heap)
        from ..runtime.memory import trim_heap

        scene._trim = False
        trim_heap()


# the modes a Dask scene renders on the workers (clvis.distributed); the others
# (the networks, the Gaussians, the split views) run on one device only
DASK_MODES = {"points": ["points"], "volume": ["iso"]}


def _dask_info(stats: dict) -> dict:
    sec = stats["seconds"]
    return {
        "workers": stats["workers"],
        "compositing": stats["compositing"],
        "busiest worker ms": round(1e3 * (sec["render"] + sec["composite"]), 1),
    }


class DaskPointScene(Scene):
    """A point cloud rendered on Dask workers (a
    :class:`clvis.distributed.DistributedRasterizer`): mode ``points`` only,
    the same G-buffers as :class:`PointScene`'s bit for bit. sources,
    client, workers, connect_timeout, fields: the DistributedRasterizer's
    (files read on the workers, or dask arrays with ``colors``/``attributes``/
    ``velocity`` in ``options``). :meth:`close` stops the cluster started here."""

    kind = "points"

    def __init__(
        self, sources: Any, client: Any = None, *, description: str = "points", **options: Any
    ) -> None:
        from ..distributed import DistributedRasterizer

        self.dr = DistributedRasterizer(sources, client, **options)
        try:
            if self.dr.bounds is None:
                raise DataError(f"{description}: no point has finite coordinates")
            lo, hi = self.dr.bounds
            self.lo, self.hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
            self.file_origin = np.asarray(self.dr.origin, np.float64)
            self.fit_points = self.dr.sample(_FIT_SAMPLE).astype(np.float64)
        except BaseException:
            self.dr.close()
            raise
        names = list(self.dr.attribute_names)
        colours = names or ["rgb"]
        self.description = f"{description}: {self.dr.n:,} points"
        self.device = f"Dask workers ({self.dr.client.scheduler.address})"
        self.modes = list(DASK_MODES["points"])
        self.settings = {"mode": "points", "color_by": colours[0], "colormap": "viridis", "point_size": 1}
        self.choices = {
            "mode": self.modes,
            "color_by": colours,
            "colormap": list(COLORMAPS),
            "point_size": {"min": 1, "max": _MAX_POINT_SIZE},
        }

    def frames(
        self, camera: Camera, width: int, height: int, settings: dict, superseded: Callable[[], bool]
    ) -> Iterator[Frame]:
        from .._arrays import on_host

        t0 = time.perf_counter()
        attr = None if settings["color_by"] == "rgb" else settings["color_by"]
        g = self.dr.render(
            camera,
            width,
            height,
            color_by=attr,
            colormap=settings["colormap"],
            point_size=settings["point_size"],
            planes=[],
        )
        t1 = time.perf_counter()
        image = _over_background(on_host(g.rgba), on_host(g.index) != 0xFFFFFFFF)
        info = {"points": self.dr.n, "points read": g.stats.get("points_read", 0), **_dask_info(g.stats)}
        yield Frame(image, info=info, times={"render": t1 - t0})

    def close(self) -> None:
        self.dr.close()


class DaskVolumeScene(Scene):
    """A volume cut into bricks on Dask workers (a
    :class:`clvis.distributed.iso.DistributedIsoRenderer`): mode ``iso``, one
    complete frame per view (the workers' passes are not streamed one by
    one), the single device's image up to the distributed iso's tolerance
    (the same hits, depths within 1e-4 of the diagonal). source: a 3-D array
    or a volume file (read brick by brick on the workers); ``vrange``: the
    isovalue slider's (min, max) (default the isovalue ± 1 for a file, whose
    samples are never read here). :meth:`close` stops the cluster started here."""

    kind = "volume"

    def __init__(
        self,
        source: Any,
        client: Any = None,
        *,
        isovalue: float,
        vrange: tuple[float, float] | None = None,
        description: str = "volume",
        **options: Any,
    ) -> None:
        from ..distributed.iso import DistributedIsoRenderer

        self.dr = DistributedIsoRenderer(source, client, **options)
        self.lo = np.asarray(self.dr.origin, np.float64)
        spacing = np.asarray(self.dr.spacing, np.float64)[::-1]
        self.hi = self.lo + (np.array(self.dr.volume_shape[::-1]) - 1) * spacing
        shape = "x".join(map(str, self.dr.volume_shape[::-1]))
        self.description = f"{description}: {shape} samples in {len(self.dr.bricks)} bricks"
        self.device = f"Dask workers ({self.dr.client.scheduler.address})"
        if vrange is None:
            vrange = (float(isovalue) - 1.0, float(isovalue) + 1.0)
        self.modes = list(DASK_MODES["volume"])
        self.settings = {"mode": "iso", "isovalue": float(isovalue)}
        self.choices = {"mode": self.modes, "isovalue": {"min": vrange[0], "max": vrange[1]}}
        self.last: Any = None  # the last IsoImage (tests compare it with one device's)

    def frames(
        self, camera: Camera, width: int, height: int, settings: dict, superseded: Callable[[], bool]
    ) -> Iterator[Frame]:
        from .._arrays import on_host

        t0 = time.perf_counter()
        img = self.last = self.dr.render(camera, width, height, settings["isovalue"])
        t1 = time.perf_counter()
        rgb = _float_rgb8(on_host(img.rgba))
        info = {"bricks": len(self.dr.bricks), "completion": 1.0, **_dask_info(img.stats)}
        yield Frame(_over_background(rgb, on_host(img.hit)), info=info, times={"render": t1 - t0})

    def close(self) -> None:
        self.dr.close()


def _isovalue(isovalue: Any) -> float | None:
    """A scene's isovalue argument: None (the scene's default) or a finite real number."""
    if isovalue is None:
        return None
    if isinstance(isovalue, bool) or not isinstance(isovalue, (int, float, np.integer, np.floating)):
        raise TypeError(f"isovalue: expected a real number, got {type(isovalue).__name__}")
    if not math.isfinite(isovalue):
        raise ValueError(f"isovalue: expected a finite number, got {isovalue!r}")
    return float(isovalue)


def _model_dir(directory: Any) -> Path | None:
    """A scene's model_dir: None, or an existing folder (checked up front:
    its networks load when their mode is first chosen, in the render worker)."""
    if directory is None:
        return None
    if not isinstance(directory, (str, os.PathLike)):
        raise TypeError(f"model_dir: expected a folder's path or None, got {type(directory).__name__}")
    path = Path(directory)
    if not path.is_dir():
        raise DataError(f"model_dir: {path} is not a folder (clvis train --out writes one)")
    return path


def scene_for(obj: Any, **kwargs: Any) -> Scene:
    """A scene for `obj`: a Scene as is, a clvis.PointCloud or (N, 3) positions
    (points), a 3-D array [z, y, x] (a volume; kwargs: spacing, origin,
    isovalue, rate), a clvis.Volume (read_volume's, with its spacing and
    origin unless kwargs give them), a clvis.SparseVolume (read_vdb's: its
    Gaussians and its isosurface; kwargs: colormap, isovalue, rate), a VTK
    dataset (a pyvista mesh, point set or image: clvis.from_vtk's cloud or
    volume) or an Open3D point cloud or triangle mesh (clvis.from_open3d's
    cloud). A path is refused, naming the readers. kwargs for all:
    description, model_dir (where the networks' models are: clvis train --out)."""
    from .. import PointCloud
    from ..gauss.sparse import SparseVolume
    from ..io.objects import from_open3d, from_vtk, is_open3d_geometry, is_vtk_dataset
    from ..io.volumes import Volume

    if isinstance(obj, Scene):
        return obj
    if is_vtk_dataset(obj):  # a VTK dataset (a pyvista mesh or image): its points or its volume
        obj = from_vtk(obj)
    elif is_open3d_geometry(obj):  # an Open3D cloud or mesh: its points (another geometry: TypeError)
        obj = from_open3d(obj)
    if isinstance(obj, PointCloud):
        return PointScene(obj, **kwargs)
    if isinstance(obj, SparseVolume):  # read_vdb's: as Gaussians (never dense) or its isosurface
        return SparseScene(obj, **kwargs)
    if isinstance(obj, Volume):  # read_volume's: its spacing and origin unless given
        kwargs.setdefault("spacing", obj.spacing)
        kwargs.setdefault("origin", obj.origin)
        kwargs.setdefault("anatomical", obj.affine is not None)  # a scan in RAS+ order: its face first
        if obj.path is not None:
            kwargs.setdefault("description", str(obj.path))
        return VolumeScene(obj.data, **kwargs)
    if isinstance(obj, (str, bytes, os.PathLike)):
        raise TypeError(
            f"clvis.view: expected data, got a path ({obj!r}): clvis.read_points or "
            "clvis.read_volume reads it"
        )
    a = np.asarray(obj)
    if a.ndim == 2 and a.shape[1] == 3:
        return PointScene(PointCloud(a), **kwargs)
    if a.ndim == 3:
        return VolumeScene(a, **kwargs)
    raise TypeError(
        f"clvis.view: expected a clvis.PointCloud, (N, 3) positions or a 3-D volume, "
        f"got {type(obj).__name__} of shape {getattr(a, 'shape', None)}"
    )


def _prefiltered(net, g):
    """The network's input as its pipeline has it: narvis-scan's G-buffers
    through its spec's depth filter (clvis.raster.filter_gbuffers: far-side
    points seen through a sparse near surface removed; the planes come back
    to the host), every other network's as they are."""
    if net.spec.depth_filter is None:
        return g
    from ..raster import filter_gbuffers

    return filter_gbuffers(g, *net.spec.depth_filter)
