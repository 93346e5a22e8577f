"""Images to and from the networks' tensors (post family), for ONNX Runtime.

The networks take one NCHW float32 tensor (batch 1) whose height and width
are multiples of their stride. The padding pixels past the image: the
in-fill's are finished rays that missed (0); the LiDAR and NARVis tensors
reflect the image past its last row and column (numpy's "symmetric" pad),
so the network sees the scan go on, not an empty band.
:func:`pack_iso` builds the in-fill network's input from an iso image,
:func:`pack_rgbda` the LiDAR U-Net's from a depth-filtered point image,
:func:`pack_gbuffers` the NARVis U-Net's from rasterizer G-buffers, and
:func:`unpack_rgba8` turns a network's output into an 8-bit RGBA picture. The
exact definitions are the docstrings of :mod:`clvis.reference.post.pack`; the
kernels are ``kernels_cl/post/pack.cl`` and give its results bit for bit.

Arrays: numpy in, numpy out; device arrays in (any of them), a device array
out on the same queue. ``out=`` takes a caller's C-contiguous
``pyopencl.array.Array`` (no offset) of the result's shape and dtype, e.g. one
over a host-visible ``ALLOC_HOST_PTR`` buffer that the caller maps after
``queue.finish()`` and hands to onnxruntime's IO binding; the function then
returns ``out`` itself. The input checks read back at most 16 bytes.

Sizes: at most ``MAX_SIDE`` (32768) per padded side and ``MAX_PIXELS``
(2^28) padded pixels, so a 5-channel tensor stays below 2^31 elements.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import limits, runtime
from .._arrays import buf, check_array, is_device, positive_int, resolve_queue, result, to_device, to_host
from ..errors import DataError
from .inputs import GBuffersLike
from .names import GBUFFER_PLANES, gbuffer_channels

__all__ = [
    "CANDIDATES_CAP",
    "MAX_PIXELS",
    "crossing_rate",
    "MAX_SIDE",
    "pack_gbuffers",
    "pack_iso",
    "pack_rgbda",
    "padded_shape",
    "unpack_rgba8",
]

MAX_SIDE = limits.POST_PACK.max_side  # 32768 a padded side (why: clvis.limits)
MAX_PIXELS = limits.POST_PACK.max_pixels  # 2^28 padded pixels
#: pack_iso's CANDIDATES channel saturates here (the renderer's count limit, clvis.iso.CANDIDATES)
CANDIDATES_CAP = 8

_SRC = "post/pack.cl"

# -D work shapes per tuning profile: pixels per work-item (ITEMS) and the
# local size (WG, rgbda_range's reduction width). Both give the same results;
# the tests run both on every device.
PROFILES = {
    "cpu": {"ITEMS": 16, "WG": 16},
    "gpu": {"ITEMS": 1, "WG": 256},
}


def padded_shape(height: int, width: int, stride: int = 1) -> tuple[int, int]:
    """(Hp, Wp): height and width rounded up to multiples of stride."""
    stride = positive_int("stride", stride)
    return -(-int(height) // stride) * stride, -(-int(width) // stride) * stride


def _check_size(name: str, h: int, w: int, hp: int, wp: int) -> None:
    if h == 0 or w == 0:
        raise DataError(f"{name}: empty ({h} x {w} pixels); a network input needs at least one pixel")
    if max(hp, wp) > MAX_SIDE or hp * wp > MAX_PIXELS:
        raise DataError(
            f"{name}: {h} x {w} pixels ({hp} x {wp} padded); at most {MAX_SIDE} per side and 2^28 pixels"
        )


def _check_out(out: Any, queue: cl.CommandQueue, shape: tuple[int, ...], dtype: type) -> cla.Array:
    if not is_device(out):
        raise TypeError(f"out: expected a pyopencl.array.Array, got {type(out).__name__}")
    if out.dtype != np.dtype(dtype) or tuple(out.shape) != shape:
        raise ValueError(
            f"out: expected shape {shape} {np.dtype(dtype).name}, got {tuple(out.shape)} {out.dtype.name}"
        )
    if not out.flags.c_contiguous or out.offset:
        raise ValueError("out: expected a C-contiguous array without an offset (a whole buffer)")
    if out.context.int_ptr != queue.context.int_ptr:
        raise ValueError("out: the device array belongs to another OpenCL context than the queue")
    return out


def _target(out: Any, queue: cl.CommandQueue, shape: tuple[int, ...], dtype: type, what: str) -> cla.Array:
    if out is None:
        return runtime.empty(queue, shape, dtype, what)
    return _check_out(out, queue, shape, dtype)


def _launcher(queue: cl.CommandQueue) -> tuple[Any, int, int]:
    prof = PROFILES[runtime.tuning_profile(queue)]
    items, wg = prof["ITEMS"], runtime.local_size(queue, prof["WG"])
    defines = {"ITEMS": items, "WG": wg}

    def launch(name: str, pixels: int, *args: Any) -> None:
        k = runtime.get_kernel(queue, _SRC, name, defines, runtime.EXACT_FP)
        runtime.launch(queue, k, *runtime.items(queue, -(-pixels // items), wg), *args)

    return launch, items, wg


def _mask(queue: cl.CommandQueue, name: str, m: Any) -> cla.Array:
    d = to_device(queue, name, m)
    return d.view(np.uint8) if d.dtype == np.bool_ else d


def pack_iso(
    rgba: Any,
    hit: Any,
    active: Any,
    *,
    candidates: Any = None,
    crossing_rate: float | None = None,
    depth: tuple[Any, Any] | None = None,
    stride: int = 1,
    out: cla.Array | None = None,
    queue: cl.CommandQueue | None = None,
) -> np.ndarray | cla.Array:
    """The in-fill network's input: (1, 5, Hp, Wp) float32 = R, G, B, HIT,
    ACTIVE; with `candidates`, (1, 6, Hp, Wp): + CANDIDATES; with
    `crossing_rate` too, (1, 7, Hp, Wp): + HIT_PRIOR; with `depth` (and
    `candidates`, not `crossing_rate`), (1, 8, Hp, Wp): + DEPTH, NEXT.

    rgba: H x W x 4 float32 (an IsoImage's shaded colour; alpha unused); hit,
    active: H x W bool or uint8 (nonzero = true). Hp, Wp: H, W rounded up to
    multiples of `stride`. At pixels that are hit and not active: the colour's
    r, g, b and HIT 1; elsewhere 0, 0, 0, 0. ACTIVE: 1 where active, else 0.
    candidates: H x W uint8 (an IsoImage's ``candidates``: the candidate
    blocks left on each running ray); CANDIDATES = min(candidates,
    CANDIDATES_CAP) / CANDIDATES_CAP where active, else 0 (CANDIDATES_CAP 8).
    crossing_rate: rho in [0, 1], the frame's finished hits per candidate
    block tested (:func:`crossing_rate`); HIT_PRIOR = 1 - (1 - rho)^k where
    active, k = min(candidates, CANDIDATES_CAP), else 0: the chance that a
    running ray with k blocks left ends on the surface. The blocks tested are
    the render's pass items: with speculation they include candidates past a
    ray's hit, and their number follows the device's speculation schedule
    (about 7-8 % more items, so a lower rate, on the CPU profile than on the
    GPU one for the same view); without speculation they do not depend on it.
    depth: (t, next_t), H x W float32 each (an IsoImage's ``t`` and
    ``next_t``: a finished hit's ray parameter, where a running ray's next
    candidate block begins); with lo, hi the extremes of the finite t where
    hit and not active and the finite next_t where active (computed on the
    device, iso_depth_range), DEPTH = (t - lo) / (hi - lo) at those finished
    hits and NEXT = (next_t - lo) / (hi - lo) at those running rays, in
    float32; 0 elsewhere, and everywhere when hi - lo is not > 0: the frame's
    depths on one scale in [0, 1], where a running ray may end beside the
    surfaces its neighbours show.
    Padding pixels: all 0. A non-finite r, g or b at a hit pixel (active or
    not) raises DataError after the kernel ran.
    """
    t_plane, next_plane = (None, None) if depth is None else _pair("depth", depth)
    queue = resolve_queue(
        queue, rgba=rgba, hit=hit, active=active, candidates=candidates, t=t_plane, next_t=next_plane, out=out
    )
    host = not any(is_device(a) for a in (rgba, hit, active, candidates, t_plane, next_plane))
    rgba = check_array("rgba", rgba, dtypes=[np.float32], ndim=3)
    hit = check_array("hit", hit, dtypes=[np.bool_, np.uint8], ndim=2)
    active = check_array("active", active, dtypes=[np.bool_, np.uint8], ndim=2)
    masks = [("hit", hit), ("active", active)]
    if crossing_rate is not None:
        if candidates is None:
            raise ValueError("crossing_rate: the hit-prior plane needs candidates")
        if isinstance(crossing_rate, bool) or not isinstance(crossing_rate, (int, float, np.floating)):
            raise TypeError(f"crossing_rate: expected a number, got {type(crossing_rate).__name__}")
        if not 0.0 <= float(crossing_rate) <= 1.0:  # NaN fails too
            raise ValueError(f"crossing_rate: expected a number in [0, 1], got {crossing_rate}")
    if candidates is not None:
        candidates = check_array("candidates", candidates, dtypes=[np.uint8], ndim=2)
        masks.append(("candidates", candidates))
    if depth is not None:
        if candidates is None or crossing_rate is not None:
            raise ValueError("depth: the depth planes come after the candidates plane, without crossing_rate")
        t_plane = check_array("depth[0] (t)", t_plane, dtypes=[np.float32], ndim=2)
        next_plane = check_array("depth[1] (next_t)", next_plane, dtypes=[np.float32], ndim=2)
        masks += [("depth[0] (t)", t_plane), ("depth[1] (next_t)", next_plane)]
    h, w, c = (int(s) for s in rgba.shape)
    if c != 4:
        raise ValueError(f"rgba: expected 4 channels, got shape {tuple(rgba.shape)}")
    for name, m in masks:
        if tuple(m.shape) != (h, w):
            raise ValueError(f"{name}: shape {tuple(m.shape)} differs from rgba's {(h, w)}")
    hp, wp = padded_shape(h, w, stride)
    _check_size("rgba", h, w, hp, wp)
    channels = 5 if candidates is None else 8 if depth is not None else 6 if crossing_rate is None else 7
    dst = _target(out, queue, (1, channels, hp, wp), np.float32, "pack_iso output")
    bad = runtime.zeros(queue, 1, np.uint32, "pack_iso input check")
    launch, _, _ = _launcher(queue)
    u32 = np.uint32
    rgba_d, hit_d, active_d = (
        to_device(queue, "rgba", rgba),
        _mask(queue, "hit", hit),
        _mask(queue, "active", active),
    )
    launch(
        "pack_iso",
        hp * wp,
        buf(rgba_d),
        buf(hit_d),
        buf(active_d),
        u32(w),
        u32(h),
        u32(wp),
        u32(hp),
        buf(dst),
        buf(bad),
    )
    if candidates is not None:
        cand_d = to_device(queue, "candidates", candidates)
        launch(
            "pack_count",
            hp * wp,
            buf(cand_d),
            buf(active_d),
            u32(CANDIDATES_CAP),
            u32(w),
            u32(h),
            u32(wp),
            u32(hp),
            u32(5),
            buf(dst),
        )
        if crossing_rate is not None:
            launch(
                "pack_prior",
                hp * wp,
                buf(cand_d),
                buf(active_d),
                np.float32(np.float32(1) - np.float32(crossing_rate)),
                u32(CANDIDATES_CAP),
                u32(w),
                u32(h),
                u32(wp),
                u32(hp),
                u32(6),
                buf(dst),
            )
    if depth is not None:
        t_d, next_d = to_device(queue, "t", t_plane), to_device(queue, "next_t", next_plane)
        stats = runtime.zeros(queue, 2, np.uint32, "pack_iso depth range")
        launch(
            "iso_depth_range",
            h * w,
            buf(t_d),
            buf(next_d),
            buf(hit_d),
            buf(active_d),
            np.uint64(h * w),
            buf(stats),
        )
        launch(
            "pack_depth",
            hp * wp,
            buf(t_d),
            buf(next_d),
            buf(hit_d),
            buf(active_d),
            u32(w),
            u32(h),
            u32(wp),
            u32(hp),
            u32(6),
            buf(stats),
            buf(dst),
        )
    nonfinite = int(bad.get()[0])
    if nonfinite:
        raise DataError(f"rgba: {nonfinite} hit pixels with a NaN or infinite r, g or b")
    return dst if out is not None else result(dst, host)


def _pair(name: str, v: Any) -> tuple[Any, Any]:
    if not isinstance(v, (tuple, list)) or len(v) != 2:
        raise TypeError(f"{name}: expected a pair of planes (t, next_t), got {type(v).__name__}")
    return v[0], v[1]


def crossing_rate(hit: Any, active: Any, tested: int) -> float:
    """A frame's crossing rate, pack_iso's `crossing_rate`: its finished rays
    that hit (hit and not active) per candidate block the render has tested
    (`tested`: its pass items, the sum of IsoImage.stats["items_per_pass"]),
    at most 1; 0 where nothing was tested. hit, active: H x W bool or uint8,
    numpy or device arrays (read back)."""
    if isinstance(tested, bool) or not isinstance(tested, (int, np.integer)):
        raise TypeError(f"tested: expected an integer count, got {type(tested).__name__}")
    if tested < 0:
        raise ValueError(f"tested: expected a count >= 0, got {tested}")
    hit = check_array("hit", hit, dtypes=[np.bool_, np.uint8], ndim=2)
    active = check_array("active", active, dtypes=[np.bool_, np.uint8], ndim=2)
    h = np.asarray(to_host(hit)).astype(bool)
    a = np.asarray(to_host(active)).astype(bool)
    if h.shape != a.shape:
        raise ValueError(f"active: shape {a.shape} differs from hit's {h.shape}")
    hits = int(np.count_nonzero(h & ~a))
    return min(hits / int(tested), 1.0) if tested > 0 else 0.0


def pack_rgbda(
    rgbda: Any, *, stride: int = 1, out: cla.Array | None = None, queue: cl.CommandQueue | None = None
) -> np.ndarray | cla.Array:
    """The LiDAR U-Net's input: (1, 5, Hp, Wp) float32 = R, G, B, A, D.

    rgbda: H x W x 5 float32 [r, g, b, depth, alpha] (a FilteredImage's rgbda:
    depth +inf where removed or empty, alpha 0 or 1). A pixel is kept where
    alpha > 0 and its depth is finite: R, G, B, A as given and
    D = (depth - dmin) / (dmax - dmin) in float32, dmin and dmax the kept
    depths' extremes in this frame, computed on the device by a reduction
    kernel (rgbda_range; no host round trip), D = 0 where dmax == dmin.
    Elsewhere R = G = B = A = 0, D = -1; padding reflects the image. No kept pixel
    at all gives an all-empty tensor, not an error. A NaN anywhere, or a
    depth of -inf where alpha > 0, raises DataError after the kernels ran.
    """
    queue = resolve_queue(queue, rgbda=rgbda, out=out)
    host = not is_device(rgbda)
    rgbda = check_array("rgbda", rgbda, dtypes=[np.float32], ndim=3)
    h, w, c = (int(s) for s in rgbda.shape)
    if c != 5:
        raise ValueError(
            f"rgbda: expected 5 channels [r, g, b, depth, alpha], got shape {tuple(rgbda.shape)}"
        )
    hp, wp = padded_shape(h, w, stride)
    _check_size("rgbda", h, w, hp, wp)
    dst = _target(out, queue, (1, 5, hp, wp), np.float32, "pack_rgbda output")
    stats = runtime.zeros(queue, 4, np.uint32, "pack_rgbda depth range")
    src = to_device(queue, "rgbda", rgbda)
    launch, _, _ = _launcher(queue)
    u32 = np.uint32
    launch("rgbda_range", h * w, buf(src), np.uint64(h * w), buf(stats))
    launch("pack_rgbda", hp * wp, buf(src), u32(w), u32(h), u32(wp), u32(hp), buf(stats), buf(dst))
    nan, neg = (int(v) for v in stats.get()[:2])
    if nan or neg:
        raise DataError(
            f"rgbda: {nan} NaN values and {neg} pixels with alpha > 0 and depth -inf; "
            "values must be numbers, a depth finite or +inf (empty)"
        )
    return dst if out is not None else result(dst, host)


def _gbuffer_sources(gbuffers: GBuffersLike, planes: tuple[str, ...]) -> list[tuple[str, Any, int, int]]:
    """(channel name, float32 array, element offset, step) of each channel
    after R, G, B and the coverage, in the tensor's order; DataError for a
    plane the G-buffers lack."""
    out: list[tuple[str, Any, int, int]] = []

    def need(name: str, what: str, a: Any) -> Any:
        if a is None:
            raise DataError(f"planes: the G-buffers have no {name!r} plane ({what})")
        return a

    if "depth" in planes:
        out.append(("depth", need("depth", "depth", gbuffers.depth), 0, 1))
    if "vel2d" in planes:
        why = "the cloud has no velocity"
        v = need("vel2d", why, gbuffers.vel2d)
        out += [("vel_x", v, 0, 2), ("vel_y", v, 1, 2)]
        out.append(("vel_angle", need("vel2d", why, gbuffers.vel_angle), 0, 1))
        out.append(("vel_speed", need("vel2d", why, gbuffers.vel_speed), 0, 1))
    if "radius" in planes:
        why = (
            "the cloud has no radius: Rasterizer(..., radius=) or PointCloud.radius; narvis reads "
            "clvis.training.data.narvis_radius(positions), "
            "narvis-scan clvis.gauss.points.knn_sigma(positions)"
        )
        out.append(("radius_px", need("radius", why, getattr(gbuffers, "radius_px", None)), 0, 1))
    attrs = gbuffers.attributes or {}
    for p in planes:
        if p in GBUFFER_PLANES:
            continue
        if p not in attrs:
            have = ", ".join(attrs) or "none"
            raise DataError(
                f"planes: the G-buffers have no attribute plane {p!r} (they have: {have}; "
                "render(planes=[...]) resolves a cloud's attributes)"
            )
        a = attrs[p]
        out.append((p, a if a.dtype == np.float32 else a.astype(np.float32), 0, 1))
    return out


def pack_gbuffers(
    gbuffers: GBuffersLike,
    planes: Any = ("rgb", "depth", "vel2d"),
    *,
    stride: int = 1,
    out: cla.Array | None = None,
    queue: cl.CommandQueue | None = None,
) -> np.ndarray | cla.Array:
    """The NARVis U-Net's input: (1, C, Hp, Wp) float32 from rasterizer
    G-buffers (a clvis.raster.GBuffers, numpy or ``host=False`` device
    planes), the channels of ``clvis.post.names.gbuffer_channels(planes)``.

    R, G, B = the colour / 255 and COVERAGE = 1 where a point was drawn;
    then, where named, the view depth, the screen velocity (v'x, v'y, its
    angle, |v'|), the splat radius in pixels ("radius": ``radius_px``) and
    any attribute planes, raw (the network normalises them
    in its graph). Every channel is 0 at empty pixels; padding reflects the
    image. A plane
    the G-buffers lack, or a NaN or infinite value at a covered pixel, raises
    DataError naming it (after the kernels ran).
    """
    layout = gbuffer_channels(planes)
    planes = tuple([planes] if isinstance(planes, str) else planes)
    for name in ("index", "rgba", "attributes"):
        if not hasattr(gbuffers, name):
            raise TypeError(f"gbuffers: expected clvis.raster.GBuffers, got {type(gbuffers).__name__}")
    index, rgba = gbuffers.index, gbuffers.rgba
    queue = resolve_queue(queue, index=index, rgba=rgba, out=out)
    host = not is_device(index)
    index = check_array("index", index, dtypes=[np.uint32], ndim=2)
    rgba = check_array("rgba", rgba, dtypes=[np.uint8], ndim=3)
    h, w = (int(s) for s in index.shape)
    if tuple(rgba.shape) != (h, w, 4):
        raise ValueError(f"rgba: expected shape {(h, w, 4)} (the index plane's), got {tuple(rgba.shape)}")
    sources = _gbuffer_sources(gbuffers, planes)
    for name, a, _, step in sources:
        want = (h, w, 2) if step == 2 else (h, w)
        if tuple(a.shape) != want:
            raise ValueError(f"{name}: expected shape {want} (the index plane's), got {tuple(a.shape)}")
    hp, wp = padded_shape(h, w, stride)
    _check_size("gbuffers", h, w, hp, wp)
    dst = _target(out, queue, (1, len(layout), hp, wp), np.float32, "pack_gbuffers output")
    bad = runtime.zeros(queue, len(sources) or 1, np.uint32, "pack_gbuffers input check")
    launch, _, _ = _launcher(queue)
    u32 = np.uint32
    idx = to_device(queue, "index", index)
    dims = (u32(w), u32(h), u32(wp), u32(hp))
    launch("pack_rgb_coverage", hp * wp, buf(to_device(queue, "rgba", rgba)), buf(idx), *dims, buf(dst))
    # each plane crosses to the device once: vel2d's x and y channels are
    # two sources over one array
    uploaded: dict[int, cla.Array] = {}
    for c, (name, a, offset, step) in enumerate(sources):
        src = uploaded.get(id(a))
        if src is None:
            src = uploaded[id(a)] = to_device(queue, name, check_array(name, a, dtypes=[np.float32]))
        launch(
            "pack_plane",
            hp * wp,
            buf(src),
            np.uint64(offset),
            u32(step),
            buf(idx),
            *dims,
            u32(4 + c),
            buf(dst),
            buf(bad),
        )
    counts = bad.get()
    for (name, *_), n in zip(sources, counts, strict=False):
        if n:
            raise DataError(f"{name}: {int(n)} covered pixels with a NaN or infinite value")
    return dst if out is not None else result(dst, host)


def unpack_rgba8(
    nchw: Any,
    height: int,
    width: int,
    *,
    out: cla.Array | None = None,
    queue: cl.CommandQueue | None = None,
) -> np.ndarray | cla.Array:
    """A network's output as an 8-bit picture: height x width x 4 uint8.

    nchw: (1, C, Hp, Wp) float32, C = 3 (RGB) or 4 (RGBA); the top-left
    height x width pixels are kept (height <= Hp, width <= Wp). Each value v
    becomes rint(clamp(v, 0, 1) * 255) (half to even) and NaN 0; alpha is 255
    when C = 3.
    """
    queue = resolve_queue(queue, nchw=nchw, out=out)
    host = not is_device(nchw)
    nchw = check_array("nchw", nchw, dtypes=[np.float32], ndim=4)
    n, c, hp, wp = (int(s) for s in nchw.shape)
    if n != 1 or c not in (3, 4):
        raise ValueError(f"nchw: expected shape (1, 3 or 4, H, W), got {tuple(nchw.shape)}")
    height, width = positive_int("height", height), positive_int("width", width)
    if height > hp:
        raise ValueError(f"height: {height} is more than the tensor's {hp} rows")
    if width > wp:
        raise ValueError(f"width: {width} is more than the tensor's {wp} columns")
    _check_size("nchw", hp, wp, hp, wp)
    dst = _target(out, queue, (height, width, 4), np.uint8, "unpack_rgba8 output")
    launch, items, _ = _launcher(queue)
    u32 = np.uint32
    launch(
        "unpack_rgba8",
        height * -(-width // items) * items,  # a work-item a row segment of `items` pixels
        buf(to_device(queue, "nchw", nchw)),
        u32(c),
        u32(wp),
        u32(hp),
        u32(width),
        u32(height),
        buf(dst),
    )
    return dst if out is not None else result(dst, host)
