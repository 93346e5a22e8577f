"""One object per shipped network (the inference side): what it takes and
how that is checked, how it is packed into the network's input tensor, its
output channels, the classical baselines it is scored against and the
held-out families ``clvis eval`` scores it on. A new network is one more
NetworkSpec subclass and a line in SPECS (and, for training, its entry in
clvis.training.train; no torch here).

PostNetwork (clvis.post.infer) asks its spec for the input check and the
pack; ``clvis eval`` (clvis.training.evaluate) reads the baselines and
families from here. A spec is generic in what its network reads (the
Protocols of clvis.post.inputs): ``shape`` checks any object at run time,
``pack`` takes one that passed.
"""

from __future__ import annotations

import math
from typing import Any, Generic, TypeVar

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from ..errors import DataError
from .inputs import GBuffersLike, IsoImageLike, LidarInput
from .names import NAMES, gbuffer_channels
from .pack import crossing_rate, pack_gbuffers, pack_iso, pack_rgbda

__all__ = ["SPECS", "NetworkSpec", "spec"]

#: what a network reads (a Protocol of clvis.post.inputs)
InputT = TypeVar("InputT")


class NetworkSpec(Generic[InputT]):
    """The inference-side description of one network (subclass per network)."""

    name: str = ""
    #: what the network's call takes, for error messages and docs
    takes: str = ""
    #: its name in pictures and tables
    title: str = ""
    #: output channels (RGB, or RGB and coverage)
    channels_out: int = 3
    #: the classical methods it must beat, by the names clvis eval uses
    baselines: tuple[str, ...] = ()
    #: generator families of its held-out suite (never in its training)
    eval_families: tuple[str, ...] = ()
    #: the families its shipped training used
    trained_families: tuple[str, ...] = ()
    #: whether its call checks it against its classical fills by default
    #: (clvis.post.guard; PostNetwork.guard); None: it has no guard
    guard: bool | None = None
    #: (levels, filter_strength) of the depth filter its pipeline runs on
    #: the G-buffers before it (clvis.raster.filter_gbuffers: far-side points
    #: seen through a sparse near surface leave the frame); ``clvis render``
    #: and ``clvis eval`` apply it, a caller of ``net(g)`` filters ``g``
    #: itself (post does not import the raster family). None: no filter
    depth_filter: tuple[int, float] | None = None
    #: (lo, hi, reach): the sub-pixel rule of a network that reads the radius
    #: plane (clvis.post.subpixel: its output blended toward the raster's
    #: colours, weight 1 where the window's mean sigma is <= lo pixels, 0 at
    #: >= hi); None: none
    subpixel: tuple[float, float, int] | None = None
    #: (lo, hi): the range of its training frames' median splat radius in
    #: pixels (the radius plane's median over the covered pixels of a frame;
    #: bench/scan_radius_range.py measures it); None: not measured
    radius_px_trained: tuple[float, float] | None = None
    #: (tau, c_lo, c_hi, f_lo, f_hi): the sub-pixel rule's volume score, read
    #: where the network also takes the depth plane (clvis.post.subpixel: the
    #: blend held back where the window is densely covered and its colours
    #: vary between neighbours at one depth); None: the sigma rule alone
    subpixel_volume: tuple[float, float, float, float, float] | None = None

    def channels_in(self, planes: tuple[str, ...]) -> tuple[int, ...]:
        """The input channels its pack writes for a model card's planes (each
        count a card's channels_in may give); ValueError for planes it cannot
        take."""
        raise NotImplementedError

    def shape(self, image: object) -> tuple[int, int]:
        """(H, W) of an input; TypeError / ValueError where it is not one."""
        raise NotImplementedError

    def unlike_training(self, median_radius_px: float) -> str | None:
        """Why a frame whose covered pixels' median splat radius is
        `median_radius_px` lies far outside what the network trained on
        (over twice the training frames' largest median, or under half their
        smallest), or None. Its output there may be worse than the classical
        splat (``clvis render --compare`` scores both)."""
        if self.radius_px_trained is None or not np.isfinite(median_radius_px):
            return None
        lo, hi = self.radius_px_trained
        if lo / 2 <= median_radius_px <= 2 * hi:
            return None
        side = "sparser" if median_radius_px > 2 * hi else "denser"
        return (
            f"the points' median splat radius is {median_radius_px:.2f} pixels, far outside the "
            f"{lo:g}-{hi:g} pixels of the {self.name} network's training frames (the cloud is "
            f"{side} on screen than any it learned from); its picture may be worse than the "
            f"classical splat: --compare scores both"
        )

    def render_scale(self, median_radius_px: float) -> int:
        """The factor to render a frame's G-buffers smaller by (the
        network's picture then resized up to the frame) so that its covered
        pixels' median splat radius, `median_radius_px` at full size, comes
        within the training frames' range: ceil(median / hi) where the median
        is over hi (radius_px_trained), else 1. A cloud sparser on screen
        than any training frame gives Gaussians wider than the network's
        kernels reach, which it draws as squares; a smaller frame brings them
        back into reach (bench/results/README.md, narvis-scan on sparse
        clouds). 1 for a network without a measured range."""
        if self.radius_px_trained is None or not np.isfinite(median_radius_px):
            return 1
        hi = self.radius_px_trained[1]
        return max(1, math.ceil(median_radius_px / hi)) if median_radius_px > hi else 1

    def pack(
        self, image: InputT, planes: tuple[str, ...], stride: int, out: cla.Array, queue: cl.CommandQueue
    ) -> None:
        """Write the network's NCHW input for `image` (one :meth:`shape`
        accepted) into `out` (the pack kernels of clvis.post.pack; device
        planes are read where they are)."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<post network spec {self.name!r}: takes {self.takes}>"


def _shape_of(a: Any) -> tuple[int, ...]:
    return tuple(a.shape if hasattr(a, "shape") else np.shape(a))


class InfillSpec(NetworkSpec[IsoImageLike]):
    name = "infill"
    title = "in-fill W-Net"
    takes = "an IsoImage (rgba, hit, active)"
    channels_out = 4
    baselines = ("input", "pushpull")
    eval_families = ("gyroid", "turbulence", "noise", "shapes", "layers")
    #: the shipped W-Net's frames and (its --mix) the variety frames of four more
    trained_families = ("waves", "ripples", "blobs", "sinusoids", "metaballs", "csg", "labels")
    #: off: on its training families the guard costs 0.6 dB and on the CI
    #: frame of shapes it picks push-pull over the partial image it should
    #: keep (bench/results/post-guard.md)
    guard = False

    def channels_in(self, planes: tuple[str, ...]) -> tuple[int, ...]:
        return (5, 6, 7, 8)  # pack_iso: base, + candidates, + the hit prior, or + the depths

    def shape(self, image: Any) -> tuple[int, int]:
        if not all(hasattr(image, k) for k in ("rgba", "hit", "active")):
            raise TypeError(f"image: the infill network takes an IsoImage, got {type(image).__name__}")
        shape = _shape_of(image.rgba)
        if len(shape) != 3 or shape[2] != 4:
            raise ValueError(f"rgba: expected (H, W, 4), got shape {shape}")
        return int(shape[0]), int(shape[1])

    def pack(
        self,
        image: IsoImageLike,
        planes: tuple[str, ...],
        stride: int,
        out: cla.Array,
        queue: cl.CommandQueue,
    ) -> None:
        # a model card's channels_in 6: the candidates plane (InfillWNet(candidates=True));
        # 7: the hit-prior plane too (InfillWNet(prior=True)), from the frame's crossing rate;
        # 8: the candidates and the depth planes (InfillWNet(depth=True)), from t and next_t
        candidates = rate = depth = None
        if out.shape[1] >= 6:
            candidates = getattr(image, "candidates", None)
            if candidates is None:
                raise DataError(
                    "image: this in-fill model reads the candidate blocks left on each running ray "
                    "(IsoImage.candidates, from IsoRenderer); the image has none"
                )
        if out.shape[1] == 7:
            rate = image_crossing_rate(image)
        if out.shape[1] == 8:
            t, next_t = getattr(image, "t", None), getattr(image, "next_t", None)
            if t is None or next_t is None:
                raise DataError(
                    "image: this in-fill model reads the hits' t and where each running ray's next "
                    "candidate block begins (IsoImage.t and .next_t, from IsoRenderer); the image has "
                    + ("neither" if t is None and next_t is None else "no t" if t is None else "no next_t")
                )
            depth = (t, next_t)
        pack_iso(
            image.rgba,
            image.hit,
            image.active,
            candidates=candidates,
            crossing_rate=rate,
            depth=depth,
            stride=stride,
            out=out,
            queue=queue,
        )


def image_crossing_rate(image: Any) -> float:
    """The crossing rate of an IsoImage (clvis.post.pack.crossing_rate): its
    finished hits per candidate block its render tested, the blocks counted
    from its ``stats["items_per_pass"]``; an image with a ``crossing_rate``
    attribute (the guard's reduced planes, training frames) gives its own;
    DataError where it has neither."""
    fixed = getattr(image, "crossing_rate", None)
    if fixed is not None:
        if isinstance(fixed, bool) or not isinstance(fixed, (int, float, np.floating)):
            raise TypeError(f"image.crossing_rate: expected a number, got {type(fixed).__name__}")
        return float(fixed)  # pack_iso checks its range
    tested = (getattr(image, "stats", None) or {}).get("items_per_pass")
    if tested is None:
        raise DataError(
            "image: this in-fill model reads the frame's crossing rate, from the candidate blocks "
            'its render tested (IsoImage.stats["items_per_pass"], from IsoRenderer); the image has none'
        )
    return crossing_rate(image.hit, image.active, int(sum(int(t) for t in tested)))


class LidarSpec(NetworkSpec[LidarInput]):
    name = "lidar"
    title = "LiDAR RGBDA U-Net"
    takes = "a FilteredImage or its rgbda (H, W, 5)"
    baselines = ("input", "pushpull")
    eval_families = ("terrain", "photo")
    trained_families = ("town",)
    #: on: push-pull where the U-Net loses to it (the terrain), the U-Net
    #: elsewhere (bench/results/post-guard.md)
    guard = True

    def channels_in(self, planes: tuple[str, ...]) -> tuple[int, ...]:
        return (5,)  # pack_rgbda

    def shape(self, image: Any) -> tuple[int, int]:
        rgbda = getattr(image, "rgbda", image)
        if not isinstance(rgbda, (np.ndarray, cla.Array)):
            raise TypeError(
                f"image: the lidar network takes a FilteredImage or its rgbda, got {type(image).__name__}"
            )
        shape = tuple(rgbda.shape)
        if len(shape) != 3 or shape[2] != 5:
            raise ValueError(f"rgbda: expected (H, W, 5) [r, g, b, depth, alpha], got shape {shape}")
        return int(shape[0]), int(shape[1])

    def pack(
        self, image: LidarInput, planes: tuple[str, ...], stride: int, out: cla.Array, queue: cl.CommandQueue
    ) -> None:
        pack_rgbda(getattr(image, "rgbda", image), stride=stride, out=out, queue=queue)


class NarvisSpec(NetworkSpec[GBuffersLike]):
    name = "narvis"
    title = "NARVis kernel-predicting U-Net (G-buffers -> Gaussians)"
    takes = "rasterizer G-buffers (GBuffers)"
    baselines: tuple[str, ...] = ("raster", "pushpull", "splat")
    eval_families: tuple[str, ...] = ("convection", "lorenz", "jet", "ring", "hurricane/magma")
    #: the hurricane and clvis.training.flows.TRAIN_FLOWS
    trained_families: tuple[str, ...] = (
        "hurricane",
        "abc",
        "abc-lines",
        "taylor-green",
        "double-gyre",
        "burgers",
        "vortices",
        "turbulence",
        "attractors",
    )
    #: chosen on training-family frames only (the hurricane at 256 x 256,
    #: attractors, abc-lines, burgers, abc, turbulence: bench/results/README.md)
    subpixel: tuple[float, float, int] | None = (0.2, 0.6, 16)
    #: chosen on training-family frames only (issue 21 narvis21h: TRAIN_FLOWS
    #: and the hurricane at 0.25x-4x, both samplers: bench/results/README.md)
    subpixel_volume: tuple[float, float, float, float, float] | None = (0.005, 0.02, 0.04, 0.9, 0.95)

    def channels_in(self, planes: tuple[str, ...]) -> tuple[int, ...]:
        return (len(gbuffer_channels(planes)),)

    def shape(self, image: Any) -> tuple[int, int]:
        if not all(hasattr(image, k) for k in ("index", "rgba", "depth", "attributes")):
            raise TypeError(
                f"image: the {self.name} network takes rasterizer G-buffers (GBuffers), "
                f"got {type(image).__name__}"
            )
        shape = tuple(image.index.shape)
        if len(shape) != 2:
            raise ValueError(f"index: expected (H, W), got shape {shape}")
        return int(shape[0]), int(shape[1])

    def pack(
        self,
        image: GBuffersLike,
        planes: tuple[str, ...],
        stride: int,
        out: cla.Array,
        queue: cl.CommandQueue,
    ) -> None:
        pack_gbuffers(image, planes, stride=stride, out=out, queue=queue)


class NarvisScanSpec(NarvisSpec):
    """NARVis for clouds without velocity (LAS/LAZ/PLY scans): the colour,
    the depth and the splat radius plane (GBuffers.radius_px: each point's
    mean 4-NN distance projected to pixels) -> the image of isotropic
    Gaussians of that sigma, splatted as 3DGS does (the paper's Morro Bay
    mapping). The same KPN graph and head as narvis; its own weights."""

    name = "narvis-scan"
    title = "NARVis-scan kernel-predicting U-Net (scan G-buffers -> isotropic Gaussians)"
    takes = "rasterizer G-buffers with the radius plane (a cloud with radius=knn_sigma)"
    #: splat: each covered pixel drawn as a round Gaussian of the radius
    #: plane's sigma (clvis.post.splat)
    #: filtered-splat: the splat of the depth-filtered G-buffers (the
    #: network's own input, :attr:`depth_filter`)
    baselines = ("raster", "pushpull", "splat", "filtered-splat")
    #: the depth filter before the network (4 levels, strength 1.4). Picked
    #: on views of the training families (town, photo_town, shapes; 24 views,
    #: two seeds) among strengths 1.025-2.0 with the shipped network: 1.4 had
    #: the best mean (+0.06 / +0.19 dB over the unfiltered G-buffers) with the
    #: worst view at -0.54 dB; 1.025 (the LiDAR default) cost -1.48 dB on
    #: average, removing grazing surface points; >= 2 removes nearly nothing
    #: (bench/results/README.md, 2026-11-29)
    depth_filter = (4, 1.4)
    #: clvis.training.data.SCAN_HELD_OUT
    eval_families = ("terrain", "aerial", "object")
    #: clvis.training.data.SCAN_TRAIN
    trained_families = ("town", "photo_town", "shapes")
    #: its isotropic splat targets were not measured under the rule: none
    subpixel = None
    #: the training frames' median radius: 0.35-3.28 pixels over 36 frames of
    #: the three training kinds at 0.25x / 1x / 4x SCAN_POINTS_PER_PIXEL,
    #: 256 and 512 pixels square (bench/scan_radius_range.py)
    radius_px_trained = (0.35, 3.3)
    subpixel_volume = None
    #: off: the guard against the classical splat (clvis.post.guard.narvis_scan),
    #: measured on the 4000-step model before this one, fixed the object
    #: 512x512 row (SSIM -0.089 -> +0.025) but cost that row 2.3 dB, the
    #: object family's mean margin 0.75 dB and the shapes training family
    #: 0.50 dB, and left the aerial row below (bench/results/README.md,
    #: 2026-11-28 session 7)
    guard = False


SPECS: dict[str, NetworkSpec[Any]] = {
    s.name: s for s in (InfillSpec(), LidarSpec(), NarvisSpec(), NarvisScanSpec())
}
assert tuple(SPECS) == NAMES, "clvis.post.names.NAMES and SPECS name the same networks"


def spec(name: str) -> NetworkSpec[Any]:
    """The spec of network `name`; ValueError for an unknown name."""
    try:
        return SPECS[name]
    except (KeyError, TypeError):
        raise ValueError(f"name: expected one of {NAMES}, got {name!r}") from None
