"""The shipped networks, run with onnxruntime (never torch).

``load(name, precision="fp32", providers=None)`` gives a :class:`PostNetwork`
whose call takes a renderer's own output and returns an RGBA8 picture:

- "infill": an IsoImage (or anything with ``rgba``, ``hit`` and ``active``),
  e.g. ``IsoRenderer.render(..., completion=0.85, host=False)``; the rays
  still running are filled in, the finished pixels come back as they were.
  Alpha is the surface's coverage (premultiplied colour over black).
- "lidar": a FilteredImage (``depth_filter(g)``: numpy, or device planes
  for ``host=False`` G-buffers) or its ``rgbda`` array (H, W, 5), numpy or
  device; alpha 255.
- "narvis": rasterizer G-buffers (``Rasterizer.render``'s GBuffers, numpy
  or ``host=False``) with the planes the card names (``planes``: by default
  the colour, depth and screen velocity, so the cloud needs a velocity;
  a model whose planes include "radius" reads GR's sigma in pixels: a
  Rasterizer given ``radius=clvis.training.data.narvis_radius(positions)``;
  ``attribute_planes``: the attributes among them, what ``render(planes=)``
  needs to resolve); returns the Gaussian renderer's image of the same view
  as the network predicts it (RGB premultiplied over black, alpha 255).
- "narvis-scan": the same for clouds without velocity (scans): G-buffers
  with the colour, depth and radius planes, from a Rasterizer given
  ``radius=clvis.gauss.points.knn_sigma(positions)`` (GBuffers.radius_px);
  returns the image of isotropic Gaussians of that sigma splatted as 3DGS
  does. Its pipeline filters the G-buffers first (``spec.depth_filter``:
  ``clvis.raster.filter_gbuffers(g, *net.spec.depth_filter)``, as ``clvis
  render``, ``clvis eval`` and the viewer do): on a close view of a sparse
  surface the raster shows its far side through the gaps, which the 3DGS
  splat hides; post does not import the raster family, so the call does
  not filter by itself.

One frame, the data on the device until onnxruntime needs it: the pack
kernel (clvis.post.pack) reads device planes where they are (a numpy plane
is uploaded once) and writes the network's NCHW float32 input into a buffer
allocated host-visible (ALLOC_HOST_PTR); onnxruntime reads it and writes its
output into a second such buffer, both mapped and bound by pointer (IO
binding), and the unpack kernel turns the output into RGBA8 where it lies,
cropping the padding off; the picture is read back. On a CPU device the
maps copy nothing; on a GPU (onnxruntime has no OpenCL provider) the input's
map is the frame's one read-back of the tensor and the output's unmap its
one upload. Per pixel that is C_in x 4 bytes down, C_out x 4 up and the
picture's 4 down (tests/post/test_transfers.py holds the documented
pipelines to it).

A card with a ``head`` entry (the shipped NARVis: ``{"kind": "kpn", ...}``)
describes a graph that stops at its head's logits: onnxruntime writes the
logits (K + 2 channels) and the nearness plane into host-visible buffers
and clvis.post.kpn's kernels apply the kernel-prediction head where they
lie (the RGB output of the full graph within float rounding, without the
head's ~300 full-size graph operations); C_out above is then the logits'
and the nearness plane's channels. A card without one (a full graph, as
NARVis cards were before issue 28) loads and runs as it was.

``stats`` holds the last call's seconds per stage (pack, inference, with a
head its kernels' "head", unpack).

``net(image, guard=True)`` (the default where the spec says so: LiDAR)
checks the network against its classical fills on this frame
(clvis.post.guard): the planes are read back, the network and push-pull
(narvis-scan: the classical splat) run on the input with some known pixels
withheld and on the whole of it, and
the frame is blended, tile by tile, toward whichever did best; ``stats``
then adds ``guard`` (its own seconds) and ``guard_NAME``, the share of the
tiles each candidate took.

onnxruntime runs on its CPU provider by default (CUDA's first when the
installed onnxruntime has it), with one intra-op thread per core and its
worker threads' spinning off, since it alternates with OpenCL work.
"fp16" is meant for GPU providers (on CPUs it is slower than fp32); "int8"
(static QDQ quantization, per-channel weights) ships only where it lost at
most 0.3 dB on the held-out frames (the card says how much).

Each model's card (``NAME.json``) is checked against its file (sha256)
before the file is used; a missing, changed or unreadable file raises
DataError naming it. Inputs: at most ``MAX_SIDE`` pixels a side and
``MAX_PIXELS`` pixels (the networks' activations at that size take about
2.5 GB for the LiDAR U-Net).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import typing
from pathlib import Path
from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import limits
from .._arrays import buffer_of, resolve_queue, to_host
from ..errors import DataError
from . import guard as guard_mod
from .inputs import GBuffersLike, IsoImageLike, IsoPlanes, PostInput
from .kpn import KPNHead
from .names import GBUFFER_PLANES, gbuffer_channels
from .pack import padded_shape, unpack_rgba8
from .specs import image_crossing_rate, spec
from .subpixel import subpixel_blend

__all__ = ["MAX_PIXELS", "MAX_SIDE", "MODELS", "PRECISIONS", "PostNetwork", "load", "sha256"]

MODELS = Path(__file__).resolve().parent / "models"
PRECISIONS = ("fp32", "fp16", "int8")
MAX_SIDE = limits.POST_INFER.max_side  # 8192 (why: clvis.limits)
MAX_PIXELS = limits.POST_INFER.max_pixels  # 2^25


def sha256(path: str | os.PathLike) -> str:
    """The file's sha256, hex: what a model card records and load checks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _card(directory: Path, name: str) -> dict:
    path = directory / f"{name}.json"
    try:
        card = json.loads(path.read_text())
    except FileNotFoundError:
        raise DataError(f"{path}: no model card for {name!r} (train one with `clvis train {name}`)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DataError(f"{path}: unreadable model card ({e})") from None
    if not isinstance(card, dict) or not isinstance(card.get("files"), dict) or "stride" not in card:
        raise DataError(f"{path}: not a clvis model card (no files or stride)")
    _check_card(path, card)
    return card


def _check_card(path: Path, card: dict) -> None:
    """The fields load() and the packers trust, each of the type and range they
    need: DataError naming the field (an edited card, not a Python traceback)."""

    def whole(key: str, lo: int, hi: int) -> None:
        v = card.get(key)
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise DataError(
                f"{path}: model card field {key!r} must be a whole number in {lo}..{hi}, got {v!r}"
            )

    whole("stride", 1, 1024)
    if card["stride"] & (card["stride"] - 1):
        raise DataError(f"{path}: model card field 'stride' must be a power of two, got {card['stride']}")
    whole("channels_in", 1, 64)
    whole("channels_out", 1, 64)
    for precision, entry in card["files"].items():
        if not isinstance(entry, dict) or not all(
            isinstance(entry.get(k), str) for k in ("file", "sha256") if entry.get("file") is not None
        ):
            raise DataError(
                f"{path}: model card entry files[{precision!r}] must give a file name and its sha256"
            )
        name = entry.get("file")
        if name is not None and (not name or Path(name).name != name):
            raise DataError(f"{path}: model card file {name!r} must be a plain file name beside the card")
    head = card.get("head")
    if head is not None:
        _check_head(path, head)
    arch = card.get("architecture", {})
    planes = arch.get("planes", ()) if isinstance(arch, dict) else None
    if planes is None or not isinstance(planes, (list, tuple)) or not all(isinstance(p, str) for p in planes):
        raise DataError(f"{path}: model card field 'architecture' must be a dict whose 'planes' are names")


def _check_network(path: Path, card: dict, network: Any) -> None:
    """The card is one of `network`'s (clvis.post.specs): its name, where it
    gives one, and its output channels. Another network's card and graph
    copied in as NAME.json (lidar's as infill's: its graph loads and runs on
    infill's 5-channel pack) would otherwise make a picture of garbage."""
    named = card.get("name", network.name)
    if named != network.name:
        raise DataError(f"{path}: the model card is for {named!r}, not {network.name!r}")
    planes = tuple(card.get("architecture", {}).get("planes") or ())
    try:
        accepted = network.channels_in(planes)
    except ValueError as e:
        raise DataError(f"{path}: model card field 'architecture': {e}") from None
    if card["channels_in"] not in accepted:
        raise DataError(
            f"{path}: model card field 'channels_in' is {card['channels_in']}; {network.name}"
            + (f" with planes {list(planes)}" if planes else "")
            + f" takes {' or '.join(map(str, accepted))}"
        )
    if card["channels_out"] != network.channels_out:
        raise DataError(
            f"{path}: model card field 'channels_out' is {card['channels_out']}; "
            f"{network.name} writes {network.channels_out}"
        )


def _check_head(path: Path, head: Any) -> None:
    """A card's "head" entry: a kernel-prediction head clvis.post.kpn applies."""
    if not isinstance(head, dict) or head.get("kind") != "kpn":
        raise DataError(f"{path}: model card field 'head' must be a dict with kind 'kpn', got {head!r}")
    ds = head.get("depth_select")
    if not isinstance(ds, bool):
        raise DataError(f"{path}: model card field head.depth_select must be true or false, got {ds!r}")
    want = ["logits", "nearness"] if ds else ["logits"]
    if head.get("outputs") != want:
        raise DataError(f"{path}: model card field head.outputs must be {want}, got {head.get('outputs')!r}")
    try:
        KPNHead(
            head.get("kernels"),
            depth_select=ds,
            depth_scale=head.get("depth_scale", 20.0),
            logit_bound=head.get("logit_bound", 6.0),
        )
    except (TypeError, ValueError) as e:
        raise DataError(f"{path}: model card field 'head': {e}") from None


def _providers(providers: list[str] | None) -> list[str]:
    import onnxruntime as ort

    available = ort.get_available_providers()
    if providers is None:
        return [p for p in ("CUDAExecutionProvider", "CPUExecutionProvider") if p in available]
    if isinstance(providers, str) or not all(isinstance(p, str) for p in providers):
        raise TypeError("providers: expected a list of onnxruntime provider names")
    missing = [p for p in providers if p not in available]
    if missing:
        raise ValueError(f"providers: {missing} not in this onnxruntime (it has {available})")
    return list(providers)


def _map(queue: cl.CommandQueue, a: cla.Array, flags: cl.map_flags) -> tuple[np.ndarray, cl.MemoryMap]:
    """The float32 device array `a`'s buffer mapped (blocking) as a host
    array, and its map (``release()`` unmaps it)."""
    # pyopencl's stub says the call returns the array; it returns (array, event),
    # the array's base the map
    mapped, _ = typing.cast(
        "tuple[np.ndarray, cl.Event]",
        cl.enqueue_map_buffer(queue, buffer_of(a), flags, 0, a.shape, np.dtype(np.float32), is_blocking=True),
    )
    return mapped, typing.cast(cl.MemoryMap, mapped.base)


class PostNetwork:
    """A shipped network on onnxruntime: call it on a renderer's output
    (see the module doc). ``card``: its model card; ``stats``: the last
    call's seconds per stage."""

    def __init__(
        self,
        name: str,
        precision: str,
        directory: Path,
        providers: list[str] | None,
        threads: int | None,
        queue: cl.CommandQueue | None,
    ) -> None:
        import onnxruntime as ort

        self.name, self.precision = name, precision
        #: the network's spec (clvis.post.specs): input check, pack, baselines
        self.spec = spec(name)
        self.card = card = _card(directory, name)
        _check_network(directory / f"{name}.json", card, self.spec)
        entry = card["files"].get(precision) or {}
        if not entry.get("file"):
            change = entry.get("psnr_change_db")
            said = "none was made" if change is None else f"it changed PSNR by {change:+.2f} dB"
            shipped = ", ".join(k for k, v in card["files"].items() if (v or {}).get("file"))
            raise DataError(
                f"{name}: no {precision} variant (int8 ships only where it loses at most 0.3 dB; "
                f"the card says {said}); shipped: {shipped}"
            )
        self.path = path = directory / entry["file"]
        if not path.is_file():
            raise DataError(f"{path}: model file missing")
        if sha256(path) != entry.get("sha256"):
            raise DataError(f"{path}: does not match its model card's sha256 (changed or corrupt)")
        so = ort.SessionOptions()
        so.intra_op_num_threads = threads if threads is not None else (os.cpu_count() or 1)
        so.inter_op_num_threads = 1
        so.add_session_config_entry("session.intra_op.allow_spinning", "0")
        so.add_session_config_entry("session.inter_op.allow_spinning", "0")
        # this session's own log (not onnxruntime's process-wide default): fatal
        # only, since its errors come back as clvis errors; a foreign graph's
        # warnings and errors otherwise went to stderr in colour before them
        so.log_severity_level = 4
        chosen = _providers(providers)
        try:
            self.session = ort.InferenceSession(str(path), so, providers=chosen)
        except Exception as e:  # onnxruntime's own errors: a corrupt or foreign graph
            raise DataError(f"{path}: onnxruntime cannot load it ({str(e).splitlines()[0]})") from None
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        head = card.get("head")
        #: the kernel-prediction head applied to the graph's logits
        #: (clvis.post.kpn), None for a graph whose output is the image
        self.head = (
            None
            if head is None
            else KPNHead(
                head["kernels"],
                depth_select=head["depth_select"],
                depth_scale=head.get("depth_scale", 20.0),
                logit_bound=head.get("logit_bound", 6.0),
            )
        )
        wanted = (
            [(None, card.get("channels_out"))]
            if self.head is None
            else [("logits", self.head.channels)] + [("nearness", 1)] * self.head.depth_select
        )
        if (
            len(inputs) != 1
            or len(outputs) != len(wanted)
            or len(inputs[0].shape) != 4
            or inputs[0].shape[1] != card.get("channels_in")
            or any(
                len(o.shape) != 4
                or name not in (None, o.name)
                or o.shape[1] not in (c, None)
                and not isinstance(o.shape[1], str)
                for o, (name, c) in zip(outputs, wanted, strict=False)
            )
        ):
            raise DataError(f"{path}: its graph is not the one its card describes")
        self._in, self._out = inputs[0].name, outputs[0].name
        self._outs = [o.name for o in outputs]
        self.stride = int(card["stride"])
        self.channels_in = int(card["channels_in"])
        self.planes = tuple(card.get("architecture", {}).get("planes") or ())
        #: the attribute planes the network reads: a render for it resolves
        #: these alone (``Rasterizer.render(..., planes=net.attribute_planes,
        #: host=False)``); empty for in-fill and LiDAR
        self.attribute_planes = tuple(p for p in self.planes if p not in GBUFFER_PLANES)
        self.channels_out = int(card["channels_out"])
        self.queue = resolve_queue(queue)
        self.stats: dict[str, float] = {}
        #: the call's default for ``guard`` (clvis.post.guard): the spec's
        #: (on for LiDAR, off for in-fill and narvis-scan; NARVis has none)
        self.guard = bool(self.spec.guard)
        #: the spec's sub-pixel rule (clvis.post.subpixel: NARVis's output
        #: blended toward the raster where GR's sigma is under a pixel),
        #: applied after every run where the network reads the radius plane;
        #: set False to see the network's own output
        self.subpixel = self.spec.subpixel is not None and "radius" in self.planes
        self._radius_channel = (
            gbuffer_channels(self.planes).index("radius_px") if "radius" in self.planes else -1
        )
        self._depth_channel = gbuffer_channels(self.planes).index("depth") if "depth" in self.planes else None
        self._buffers: dict[tuple[int, int], tuple[cla.Array, cla.Array]] = {}
        #: the graph's outputs where a head is applied to them (logits, nearness)
        self._graph_out: dict[tuple[int, int], list[cla.Array]] = {}

    def __repr__(self) -> str:
        return f"PostNetwork({self.name!r}, {self.precision}, {self.session.get_providers()[0]})"

    def _buffers_for(self, hp: int, wp: int) -> tuple[cla.Array, cla.Array]:
        """The host-visible (ALLOC_HOST_PTR) input and output tensors of a
        size, as device arrays (kept for the next frame of the same size);
        with a head, the output is the head's (a device array) and the
        graph's outputs are host-visible (:meth:`_graph_outputs`)."""
        key = (hp, wp)
        if key not in self._buffers:
            self._buffers.clear()
            self._graph_out.clear()
            if self.head is None:
                t = self._host_visible(hp, wp, self.channels_in, self.channels_out)
                self._buffers[key] = t[0], t[1]
            else:
                channels = [self.head.channels] + [1] * self.head.depth_select
                (planes, *graph) = self._host_visible(hp, wp, self.channels_in, *channels)
                self._graph_out[key] = graph
                output = cla.empty(self.queue, (1, self.channels_out, hp, wp), np.float32)
                self._buffers[key] = planes, output
        return self._buffers[key]

    def _host_visible(self, hp: int, wp: int, *channels: int) -> tuple[cla.Array, ...]:
        flags = cl.mem_flags.READ_WRITE | cl.mem_flags.ALLOC_HOST_PTR
        tensors = []
        for c in channels:
            shape = (1, c, hp, wp)
            data = cl.Buffer(self.queue.context, flags, int(np.prod(shape)) * 4)
            tensors.append(cla.Array(self.queue, shape, np.float32, data=data))
        return tuple(tensors)

    def _graph_outputs(self, hp: int, wp: int) -> list[cla.Array]:
        """The tensors onnxruntime writes for a size: the output itself, or,
        with a head, its logits (and nearness)."""
        planes, output = self._buffers_for(hp, wp)
        return [output] if self.head is None else self._graph_out[(hp, wp)]

    def _size(self, image: PostInput) -> tuple[int, int]:
        """(H, W) of an input the network takes; TypeError/ValueError/DataError else."""
        h, w = self.spec.shape(image)
        if h == 0 or w == 0:
            raise DataError(f"image: empty ({h} x {w} pixels)")
        if max(h, w) > MAX_SIDE or h * w > MAX_PIXELS:
            raise DataError(
                f"image: {w} x {h} pixels is beyond the networks' maximum "
                f"({MAX_SIDE} a side, {MAX_PIXELS} pixels)"
            )
        return h, w

    def _run(self, image: PostInput) -> tuple[cla.Array, int, int]:
        """(output, H, W): the network's output, in this object's host-visible
        device array (reused by the next frame of the same size), and the
        image's size."""
        t0 = time.perf_counter()
        h, w = self._size(image)
        planes, output = self._buffers_for(*padded_shape(h, w, self.stride))
        q, s = self.queue, self.stride
        # device planes are packed as they are; a host plane is uploaded once.
        # each pack reads its input check back, so the kernel is done on return
        self.spec.pack(image, self.planes, s, planes, q)
        t1 = time.perf_counter()
        # onnxruntime reads the input and writes the output through host
        # pointers to the two host-visible buffers (IO binding): on a CPU
        # device no copy; on a GPU the input's map is a read-back and the
        # output's unmap the upload the unpack kernel needs
        graph = self._graph_outputs(*planes.shape[2:])
        mapped_in, map_in = _map(q, planes, cl.map_flags.READ)
        maps: list[cl.MemoryMap] = []
        try:
            io = self.session.io_binding()
            io.bind_input(self._in, "cpu", 0, np.float32, list(planes.shape), mapped_in.ctypes.data)
            for name, tensor in zip(self._outs, graph, strict=True):
                mapped_out, map_out = _map(q, tensor, cl.map_flags.WRITE_INVALIDATE_REGION)
                maps.append(map_out)
                io.bind_output(name, "cpu", 0, np.float32, list(tensor.shape), mapped_out.ctypes.data)
            self.session.run_with_iobinding(io)
        except Exception as e:  # a graph that loads but fails when run (onnxruntime's errors)
            raise DataError(
                f"{self.path}: onnxruntime failed running it ({str(e).splitlines()[0]})"
            ) from None
        finally:
            for m in maps:
                m.release()
            map_in.release()
        t2 = time.perf_counter()
        self.stats = {"pack": t1 - t0, "inference": t2 - t1}
        if self.head is not None:  # the head where onnxruntime wrote its logits
            self.head(planes, *graph, out=output, queue=q)
            q.finish()
            self.stats["head"] = time.perf_counter() - t2
        if self.subpixel and self.spec.subpixel is not None:
            t3 = time.perf_counter()
            lo, hi, reach = self.spec.subpixel
            subpixel_blend(
                planes,
                output,
                radius_channel=self._radius_channel,
                lo=lo,
                hi=hi,
                reach=reach,
                depth_channel=self._depth_channel,
                volume=self.spec.subpixel_volume if self._depth_channel is not None else None,
                out=output,
                queue=q,
            )
            q.finish()
            self.stats["subpixel"] = time.perf_counter() - t3
        return output, h, w

    def infer(self, image: PostInput) -> np.ndarray:
        """The network's raw output for `image`: (1, C, Hp, Wp) float32 (C: 4
        for infill, 3 for lidar and narvis), padded to the stride."""
        return self._run(image)[0].get()

    def __call__(self, image: PostInput, *, guard: bool | None = None) -> np.ndarray:
        """(H, W, 4) uint8 RGBA: the network's picture of `image` (the unpack
        kernel reads the network's output where onnxruntime wrote it; the
        picture is the one read-back).

        guard: check the network against its classical fills on this frame
        and take, tile by tile, the one that did best (clvis.post.guard; the
        planes are read back and the network runs twice); None: the
        network's default (:attr:`guard`). In-fill, LiDAR and narvis-scan only."""
        if guard is None:
            guard = self.guard
        if not isinstance(guard, bool):
            raise TypeError(f"guard: expected True, False or None, got {guard!r}")
        if guard:
            return self._guarded(image)
        output, h, w = self._run(image)
        t0 = time.perf_counter()
        rgba = unpack_rgba8(output, h, w, queue=self.queue)
        picture = rgba.get() if isinstance(rgba, cla.Array) else rgba
        self.stats["unpack"] = time.perf_counter() - t0
        return picture

    def render_scale(self, gbuffers: GBuffersLike) -> int:
        """The factor to render this view's G-buffers smaller by for this
        network (its picture then resized up to the view with
        :func:`resized`): the spec's ``render_scale`` of the view's median
        splat radius over its covered pixels (``gbuffers``: the view at full
        size as the network reads it, after its spec's depth filter; host or
        device, with the radius plane). 1 for a
        network without a training radius range (all but narvis-scan), a
        view without the radius plane or without a covered pixel; at most
        what keeps MIN_SCALED_SIDE pixels a side (and so the view's aspect
        within 1 %)."""
        h, w = gbuffers.index.shape[:2]
        scale = self.spec.render_scale(self.median_radius_px(gbuffers))
        return max(1, min(scale, min(w, h) // MIN_SCALED_SIDE))

    def median_radius_px(self, gbuffers: GBuffersLike) -> float:
        """The view's median splat radius in pixels over its covered pixels
        (``gbuffers``: host or device, with the radius plane); NaN for a
        network without a training radius range, a view without the radius
        plane or without a covered pixel."""
        radius = getattr(gbuffers, "radius_px", None)  # GBuffers' (clvis.raster), when resolved
        if self.spec.radius_px_trained is None or radius is None:
            return float("nan")
        covered = to_host(gbuffers.index) != 0xFFFFFFFF
        if not covered.any():
            return float("nan")
        return float(np.median(to_host(radius)[covered]))

    def _host(self, image: PostInput) -> np.ndarray:
        """The network's output for `image` as (H, W, C) float32 on the host."""
        output, h, w = self._run(image)
        return np.ascontiguousarray(np.moveaxis(output.get()[0, :, :h, :w], 0, -1))

    def _guarded(self, image: PostInput) -> np.ndarray:
        if self.spec.guard is None:
            raise ValueError(
                f"guard: the {self.name} network has no guard (in-fill, LiDAR and narvis-scan have)"
            )
        t0 = time.perf_counter()
        self._size(image)  # TypeError / DataError before any read-back
        stats: dict[str, float] = {"pack": 0.0, "inference": 0.0}

        def timed(x: PostInput) -> np.ndarray:
            out = self._host(x)
            for k in stats:
                stats[k] += self.stats[k]
            return out

        if self.name == "infill":
            planes = typing.cast(IsoImageLike, image)
            rgba = np.asarray(to_host(planes.rgba), np.float32)
            hit = to_host(planes.hit).astype(bool)
            active = to_host(planes.active).astype(bool)
            if not np.isfinite(rgba[hit & ~active][:, :3]).all():
                raise DataError("rgba: a hit pixel with a NaN or infinite r, g or b")
            # the candidates plane: read back only for a model that takes it (channels_in 6, 7)
            cand = getattr(planes, "candidates", None) if self.channels_in >= 6 else None
            left = None if cand is None else np.asarray(to_host(cand), np.uint8)
            if left is not None and left.shape == active.shape:
                # the withheld finished rays run with their nearest running
                # ray's count, not 0 (a ray with no block left misses)
                left = guard_mod.nearest_running(left, active)
            # the hit-prior plane (channels_in 7): the whole frame's crossing rate, not the reduced planes'
            rate = image_crossing_rate(planes) if self.channels_in == 7 else None
            # the depth planes (channels_in 8): the withheld finished rays, run
            # as running ones, take their nearest running ray's next_t too (the
            # reduced hit mask leaves their own t out of DEPTH)
            t = nxt = None
            t_plane, next_plane = getattr(planes, "t", None), getattr(planes, "next_t", None)
            if self.channels_in == 8 and t_plane is not None and next_plane is not None:
                t = np.asarray(to_host(t_plane), np.float32)
                nxt = np.asarray(to_host(next_plane), np.float32)
                if nxt.shape == active.shape:
                    nxt = guard_mod.nearest_running(nxt, active, "next_t")

            def run_iso(values: np.ndarray, hit: np.ndarray, active: np.ndarray) -> np.ndarray:
                return timed(IsoPlanes(values, hit, active, left, rate, t, nxt))

            frame, share = guard_mod.infill(run_iso, rgba, hit, active, self.queue)
        elif self.name == "narvis-scan":
            g = typing.cast(GBuffersLike, image)
            host = _ScanPlanes(g, self.planes)

            def run_scan(index: np.ndarray) -> np.ndarray:
                return timed(host.covering(index))

            frame, share = guard_mod.narvis_scan(run_scan, host.index, host.rgba, host.radius_px)
        else:
            rgbda = np.asarray(to_host(getattr(image, "rgbda", image)), np.float32)
            # a FilteredImage's point index: the guard withholds whole points by it
            index = getattr(image, "index", None)
            index = None if index is None else np.asarray(to_host(index))
            if index is not None and index.shape != rgbda.shape[:2]:
                raise ValueError(f"index: shape {index.shape} differs from the rgbda's {rgbda.shape[:2]}")
            frame, share = guard_mod.lidar(timed, rgbda, self.queue, index)
        t1 = time.perf_counter()
        v = np.nan_to_num(np.clip(frame, np.float32(0), np.float32(1)), nan=0.0)
        picture = np.rint(v * np.float32(255)).astype(np.uint8)
        if picture.shape[2] == 3:
            picture = np.concatenate([picture, np.full(picture.shape[:2] + (1,), 255, np.uint8)], axis=2)
        t2 = time.perf_counter()
        self.stats = {
            **stats,
            "unpack": t2 - t1,
            "guard": t1 - t0 - stats["pack"] - stats["inference"],  # unpack apart
            **{f"guard_{k}": v for k, v in share.items()},
        }
        return picture


class _ScanPlanes:
    """Host copies of the G-buffer planes narvis-scan reads (the guard's
    inputs to the network); :meth:`covering` gives them with another index
    plane (the guard's withheld pixels marked empty)."""

    def __init__(self, g: GBuffersLike, planes: tuple[str, ...]) -> None:
        for name in ("index", "rgba", "attributes"):
            if not hasattr(g, name):
                raise TypeError(f"gbuffers: expected clvis.raster.GBuffers, got {type(g).__name__}")
        self.index = np.asarray(to_host(g.index))
        self.rgba = np.asarray(to_host(g.rgba))
        if self.index.dtype != np.uint32 or self.index.ndim != 2:
            raise DataError(f"index: expected (H, W) uint32, got {self.index.dtype} {self.index.shape}")
        r = getattr(g, "radius_px", None)
        if r is None:
            raise DataError(
                "planes: the G-buffers have no 'radius' plane (the narvis-scan guard's splat reads it: "
                "a cloud with radius=knn_sigma)"
            )
        self.radius_px = np.asarray(to_host(r), np.float32)
        self.depth = None if g.depth is None else np.asarray(to_host(g.depth))
        attrs = g.attributes or {}
        self.attributes = {k: np.asarray(to_host(attrs[k])) for k in planes if k in attrs}
        self.vel2d = self.vel_angle = self.vel_speed = None

    def covering(self, index: np.ndarray) -> _ScanPlanes:
        out = object.__new__(_ScanPlanes)
        out.__dict__.update(self.__dict__)
        out.index = index
        return out


def load(
    name: str,
    precision: str = "fp32",
    providers: list[str] | None = None,
    *,
    directory: str | os.PathLike | None = None,
    threads: int | None = None,
    queue: cl.CommandQueue | None = None,
) -> PostNetwork:
    """The shipped network `name` ("infill", "lidar", "narvis", "narvis-scan") at `precision`
    ("fp32", "fp16", "int8"), on onnxruntime with `providers` (default: CUDA's
    when present, then the CPU's). directory: where NAME.json and its files
    are (default: the models shipped in clvis/post/models; a `clvis train
    --out` folder works too); threads: onnxruntime's intra-op threads
    (default: one per core)."""
    spec(name)  # ValueError for a name no network has
    if precision not in PRECISIONS:
        raise ValueError(f"precision: expected one of {PRECISIONS}, got {precision!r}")
    d = MODELS if directory is None else Path(directory)
    return PostNetwork(name, precision, d, providers, threads, queue)


#: a network's frame rendered smaller (PostNetwork.render_scale) keeps this
#: many pixels a side at least
MIN_SCALED_SIDE = 64
#: ... and its picture is smoothed by a Gaussian of this standard deviation
#: (its own pixels) as it is resized up (resized's smooth): under the
#: smallest median splat radius a scaled frame can have (half of
#: radius_px_trained's top, 1.65 px), so never wider than the Gaussians it
#: draws. On narvis-scan's training kinds at sparse densities: +0.61 dB and
#: SSIM +0.040 over bilinear alone, every frame better (bench/results/README.md)
SCALED_SMOOTH = 1.0


def resized(picture: np.ndarray, width: int, height: int, *, smooth: float = 0.0) -> np.ndarray:
    """An (h, w, C) uint8 picture (a network's, rendered smaller:
    :meth:`PostNetwork.render_scale`) resized to (height, width, C):
    Pillow's bilinear filter, each channel on its own (so an alpha channel
    weighs nothing in; Pillow's RGBA resize would premultiply it). smooth:
    a Gaussian of that standard deviation, in the picture's own pixels, first
    (Pillow's GaussianBlur): SCALED_SMOOTH for a network's smaller frame, a
    reconstruction filter wider than bilinear's, so the blocks the network
    draws at the small size do not come out as squares."""
    from PIL import Image, ImageFilter

    a = np.asarray(picture)
    if a.ndim != 3 or a.dtype != np.uint8 or 0 in a.shape:
        raise ValueError(f"picture: expected an (h, w, C) uint8 array, got {a.dtype} {a.shape}")
    width, height = limits.check_image_size(width, height, limits.POST_PACK)
    if isinstance(smooth, bool) or not isinstance(smooth, (int, float)) or not 0 <= smooth <= 64:
        raise ValueError(f"smooth: expected a standard deviation in pixels, 0..64, got {smooth!r}")
    out = np.empty((height, width, a.shape[2]), np.uint8)
    for c in range(a.shape[2]):
        band = Image.fromarray(np.ascontiguousarray(a[..., c]), mode="L")
        if smooth > 0:
            band = band.filter(ImageFilter.GaussianBlur(float(smooth)))
        out[..., c] = np.asarray(band.resize((width, height), Image.Resampling.BILINEAR))
    return out
