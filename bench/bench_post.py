"""Benchmarks of the post family: the shipped networks on onnxruntime's CPU
provider (one intra-op thread per core, spinning off: clvis.post.load's
settings) at fp32, fp16 and int8, per frame through clvis.post's pack ->
IO binding -> unpack path, against torch eager on the same input, push-pull
(the classical baseline) and the slow path each network replaces, in one
session.

The networks are timed alone (``guard=False``) and, fp32, with their guard
(``fp32+guard``: clvis.post.guard's self-check, LiDAR's default).

- infill[...]: an IsoImage of a held-out gyroid volume (64^3) stopped at 85 %
  (no speculation); the slow path is IsoRenderer.render to 100 % (with
  speculation, cold cache), and "render to 85 % + network" is the fast path
  whole.
- lidar[...]: the depth-filtered render of a sparse scan of the terrain
  (the held-out scene); the slow path is the dense render (3 M points, 3 x 3
  pixel points).

- narvis[...]: the G-buffers of the hurricane (2 M particles) from a
  hemisphere view never trained on; the slow path is the Gaussian renderer
  of the velocity-elongated Gaussians (the paper's "GR"), and "MACR +
  NARVis" (render, resolve, pack, inference, kernel-prediction head,
  unpack) is the fast path whole. The
  wider configurations (NPBG's 16..256, the paper's text's 64..1024) are
  timed with random weights (their speed does not depend on them).
- narvis-scan[...]: the G-buffers (colour, depth, the kNN radius plane) of
  a held-out LAS-like aerial strip scan (4 points a pixel) from an oblique
  view; the slow path is the Gaussian renderer's 3DGS splat of its
  isotropic kNN Gaussians (the target it was trained on); "fp32+filter" is
  its pipeline whole: the spec's depth filter on the G-buffers, then the
  network; "fast" is that after rasterizing the G-buffers, against GR.
- narvis head[...]: the kernel-prediction head alone (clvis.post.kpn's
  kernels, applied since issue 28 to the logits the graph stops at), on the
  same frame's tensors, against its NumPy reference.
- narvis sub-pixel rule[...]: the blend toward the raster where GR's sigma
  is under a pixel, held back where the window looks like a volume
  (clvis.post.subpixel, after the head, the shipped spec's parameters), on
  the same frame's tensors, against its NumPy reference.

Sizes 512x512, 960x720 and 1280x720 (narvis: 512x512, the paper's;
CLVIS_BENCH_SCALE shrinks them). Each row records its median in ms and the
load average; issue 21's speed budgets (the fp32 rows' medians, and the
fast path against GR) are clvis.benchreport's "post" targets, printed as
met or missed.

    clvis bench post
"""

import os

import benchutil
import numpy as np
import pytest
from benchutil import scaled

from clvis import benchreport, datasets, post
from clvis.errors import DataError
from clvis.training import data

SIDE = min(1.0, scaled(1 << 20) / (1 << 20)) ** 0.5
SIZES = {
    k: (max(64, round(w * SIDE)), max(64, round(h * SIDE)))
    for k, (w, h) in {"512x512": (512, 512), "960x720": (960, 720), "1280x720": (1280, 720)}.items()
}
IMPLS = ("fp32", "fp16", "int8", "torch", "pushpull", "slow")
_cache: dict = {}


def run(benchmark, fn, **kw):
    """benchutil.run, then the row's median in ms and the load average
    (info "median_ms", "load_average"): the budgets (clvis.benchreport's
    "post" targets) are on the median wall time."""
    benchutil.run(benchmark, fn, **kw)
    stats = getattr(benchmark, "stats", None)
    if stats is not None:  # not under --benchmark-disable
        benchmark.extra_info["median_ms"] = 1e3 * stats.stats.median
    benchmark.extra_info["load_average"] = list(os.getloadavg())


def _iso(queue, w, h):
    key = ("iso", w, h)
    if key not in _cache:
        from clvis.iso import IsoRenderer

        rng = np.random.default_rng(20)
        n = max(16, round(64 * SIDE))
        vol, iso = data.procedural_volume("gyroid", rng, n)
        r = IsoRenderer(vol, spacing=(2 / (n - 1),) * 3, origin=(-1, -1, -1), queue=queue)
        cam = data.orbit_camera(rng, (-1, -1, -1), (1, 1, 1), w / h, (0.5, 0.7))
        img = r.render(cam, w, h, iso, completion=0.85, speculation=False)
        _cache[key] = (r, cam, iso, img)
    return _cache[key]


def _lidar(queue, w, h):
    key = ("lidar", w, h)
    if key not in _cache:
        from clvis.raster import Rasterizer, depth_filter

        n = max(20_000, round(3_000_000 * SIDE**2))
        cloud = datasets.terrain(n, 31)
        pos, col = cloud["positions"], cloud["colors"]
        keep = np.random.default_rng(1).random(n) < 0.08
        dense = Rasterizer(pos, colors=col, queue=queue)
        scan = Rasterizer(pos[keep], colors=col[keep], queue=queue)
        from clvis import Camera

        cam = Camera.look_at((-150, -200, 160), (0, 0, 0), (0, 0, 1), 50, w / h, 1.0, 2000)
        f = depth_filter(scan.render(cam, w, h, planes=[]))
        _cache[key] = (dense, scan, cam, f)
    return _cache[key]


def _narvis(queue, w, h):
    key = ("narvis", w, h)
    if key not in _cache:
        n = max(20_000, round(2_000_000 * SIDE**2))
        scene = data.narvis_scene("hurricane", n, 0)
        cam = data.narvis_cameras(scene, "hemisphere", w / h)[41]  # an odd azimuth: never trained on
        ras = scene.rasterizer(queue=queue)
        gr = scene.gaussian_renderer(queue=queue)
        planes = post.load("narvis").planes
        g = scene.gbuffers(ras, cam, w, h, planes)
        _cache[key] = (scene, ras, gr, cam, g)
    return _cache[key]


def _scan(queue, w, h):
    key = ("narvis-scan", w, h)
    if key not in _cache:
        scene = data.scan_scene("aerial", round(data.SCAN_POINTS_PER_PIXEL * w * h), 0)
        cam = data.scan_cameras(scene, np.random.default_rng(1), 1, w / h)[0]
        ras = scene.rasterizer(queue=queue)
        gr = scene.gaussian_renderer(queue=queue)
        g = scene.gbuffers(ras, cam, w, h, post.load("narvis-scan").planes)
        _cache[key] = (scene, ras, gr, cam, g)
    return _cache[key]


def _wide(widths):
    """An ONNX file of the NARVis U-Net at other widths (random weights)."""
    pytest.importorskip("torch")
    pytest.importorskip("onnx")
    import tempfile
    from pathlib import Path

    from clvis.post import nets
    from clvis.training.train import export_onnx

    key = ("wide", widths)
    if key not in _cache:
        card = post.load("narvis").card["architecture"]
        net = nets.build("narvis", planes=card["planes"], widths=widths, up=card.get("up", "bilinear")).eval()
        # the folder is removed with the process (its finalizer), not left in /tmp
        if "tmp" not in _cache:
            _cache["tmp"] = tempfile.TemporaryDirectory(prefix="clvis-bench-")
        path = Path(_cache["tmp"].name) / f"wide-{'-'.join(map(str, widths))}.onnx"
        export_onnx(net, path)
        _cache[key] = (path, nets.count_parameters(net))
    return _cache[key]


def _torch_net(name):
    """The shipped architecture in torch eager (its weights do not change
    the time: random ones)."""
    pytest.importorskip("torch")
    from clvis.post import nets

    if ("torch", name) not in _cache:
        _cache[("torch", name)] = nets.build(name, **post.load(name).card["architecture"]).eval()
    return _cache[("torch", name)]


NARVIS_IMPLS = (*IMPLS, "fast", "16-256", "64-1024", "head", "head-numpy", "subpixel", "subpixel-numpy")
CASES = [(n, s, i) for n in ("infill", "lidar") for s in SIZES for i in (*IMPLS, "fp32+guard")]
CASES += [("narvis", "512x512", i) for i in NARVIS_IMPLS]
CASES += [
    ("narvis-scan", "512x512", i)
    for i in ("fp32", "fp32+filter", "fp32+guard", "fp16", "pushpull", "splat", "splat-numpy", "slow", "fast")
]


@pytest.mark.parametrize("name,size,impl", CASES, ids=[f"{n}-{s}-{i}" for n, s, i in CASES])
def test_post(benchmark, queue, name, size, impl):
    w, h = SIZES[size]
    op = f"{name}[{size}]"
    if name == "infill":
        r, cam, iso, image = _iso(queue, w, h)
    elif name == "lidar":
        dense, scan, cam, image = _lidar(queue, w, h)
    elif name == "narvis-scan":
        scene, ras, gr, cam, image = _scan(queue, w, h)
    else:
        scene, ras, gr, cam, image = _narvis(queue, w, h)
    if name == "narvis-scan" and impl in ("splat", "splat-numpy"):
        return _scan_splat(benchmark, queue, impl, w, h, image)
    if name == "narvis-scan" and impl == "fp32+filter":
        return _scan_filtered(benchmark, queue, op, w, h, image)
    if name == "narvis-scan" and impl == "fast":
        return _scan_fast(benchmark, queue, op, w, h, scene, ras, cam)
    if name == "narvis" and impl in ("head", "head-numpy"):
        return _narvis_head(benchmark, queue, impl, w, h, image)
    if name == "narvis" and impl in ("subpixel", "subpixel-numpy"):
        return _narvis_subpixel(benchmark, queue, impl, w, h, image)
    if name == "narvis" and impl in ("fast", "16-256", "64-1024"):
        return _narvis_extra(benchmark, queue, impl, op, w, h, scene, ras, cam, image)
    if impl in ("fp32", "fp16", "int8", "fp32+guard"):
        precision, guard = impl.split("+")[0], impl.endswith("+guard")
        try:
            net = post.load(name, precision, queue=queue)
        except DataError:  # int8 not shipped (it lost more than 0.3 dB)
            pytest.skip(f"{name}: no {impl} variant shipped (see its card)")
        net(image, guard=guard)
        run(
            benchmark,
            lambda: net(image, guard=guard),
            op=op,
            impl=f"onnxruntime {precision}" + (" with its guard (clvis.post.guard)" if guard else ""),
            role="clvis" if impl == "fp32" else "clvis-host",
            n=w * h,
            nbytes=w * h * (5 * 4 + 4),
            rounds=5,
        )
        benchmark.extra_info["stages"] = dict(net.stats)  # the last timed round's
    elif impl == "torch":
        torch = pytest.importorskip("torch")
        net = _torch_net(name)
        x = torch.rand(1, net.channels_in, -(-h // net.stride) * net.stride, -(-w // net.stride) * net.stride)

        def eager():
            with torch.no_grad():
                return net(x)

        with benchutil.threads(torch=os.cpu_count() or 1):  # torch's count given back after the case
            run(
                benchmark,
                eager,
                op=op,
                impl="torch eager (fp32)",
                role="peer",
                n=w * h,
                nbytes=w * h * 24,
                rounds=3,
            )
    elif impl == "pushpull":
        if name == "infill":
            known = np.where((image.hit & ~image.active)[..., None], image.rgba, 0).astype(np.float32)
            valid = ~image.active
        elif name in ("narvis", "narvis-scan"):
            known = np.ascontiguousarray(image.rgba[..., :3] / np.float32(255))
            valid = image.covered
        else:
            known = np.ascontiguousarray(image.rgbda[..., :3])
            valid = image.rgbda[..., 4] > 0
        run(
            benchmark,
            lambda: post.pushpull(known, valid, queue=queue),
            op=op,
            impl="push-pull (OpenCL)",
            role="peer",
            n=w * h,
            nbytes=known.nbytes * 2,
            rounds=5,
        )
    else:
        if name == "infill":

            def slow():
                r.reset_cache()
                return r.render(cam, w, h, iso)

            impl_name = "IsoRenderer to 100 % (the slow path)"
        elif name in ("narvis", "narvis-scan"):
            gr.render(cam, w, h)

            def slow():
                return gr.render(cam, w, h)

            impl_name = f"Gaussian renderer, {gr.n:,} Gaussians (the slow path)"
        else:

            def slow():
                return dense.render(cam, w, h, point_size=3, planes=[])

            impl_name = "dense render (the slow path)"
        run(benchmark, slow, op=op, impl=impl_name, role="peer", n=w * h, nbytes=w * h * 24, rounds=3)


def _scan_filtered(benchmark, queue, op, w, h, image):
    """narvis-scan's pipeline as clvis render and clvis eval run it: its
    spec's depth filter on the G-buffers (clvis.raster.filter_gbuffers: the
    mask on the device, the planes selected on the host), then the network."""
    from clvis.raster import filter_gbuffers

    net = post.load("narvis-scan", queue=queue)
    levels, strength = net.spec.depth_filter

    def frame():
        return net(filter_gbuffers(image, levels, strength, queue=queue))

    frame()
    run(
        benchmark,
        frame,
        op=op,
        impl=f"depth filter ({levels} levels, strength {strength:g}) + onnxruntime fp32",
        role="clvis-host",
        n=w * h,
        nbytes=w * h * (5 * 4 + 4),
        rounds=5,
    )
    benchmark.extra_info["stages"] = dict(net.stats)


def _scan_fast(benchmark, queue, op, w, h, scene, ras, cam):
    """narvis-scan's fast path whole, as "MACR + NARVis" is NARVis's: the
    scan's G-buffers rasterized (colour, depth, the kNN radius plane; left
    on the device), its spec's depth filter, then the network; against the
    Gaussian renderer of the same isotropic Gaussians (the "slow" row)."""
    net = post.load("narvis-scan", queue=queue)
    _fast_path(benchmark, queue, op, benchreport.SCAN_FAST, w, h, scene, ras, cam, net, net.spec.depth_filter)


def _fast_path(benchmark, queue, op, impl, w, h, scene, ras, cam, net, prefilter=None):
    """A fast path whole: the G-buffers rasterized (left on the device), the
    depth filter (levels, strength) when given, the network; its stages'
    seconds in extra_info "stages"."""
    import time

    from clvis.raster import filter_gbuffers

    stages = {}

    def fast():
        t0 = time.perf_counter()
        g = scene.gbuffers(ras, cam, w, h, net.planes, host=False)
        queue.finish()
        t1 = time.perf_counter()
        if prefilter is not None:
            g = filter_gbuffers(g, *prefilter, queue=queue)
        t2 = time.perf_counter()
        out = net(g)
        stages.update(render=t1 - t0, **({"filter": t2 - t1} if prefilter else {}), **net.stats)
        return out

    fast()
    run(
        benchmark,
        fast,
        op=op,
        impl=impl,
        role="clvis-host",
        n=w * h,
        nbytes=w * h * 24,
        rounds=5,
        stages=stages,
    )


def _narvis_head(benchmark, queue, impl, w, h, image):
    """The kernel-prediction head alone (issue 28: it left the ONNX graph):
    clvis.post.kpn's kernels on the frame's device tensors where
    onnxruntime wrote them, against its NumPy reference on the host."""
    from clvis.reference.post.kpn import kpn_head

    net = post.load("narvis", queue=queue)
    net(image)
    hp, wp = post.padded_shape(h, w, net.stride)
    planes, output = net._buffers_for(hp, wp)
    graph = net._graph_outputs(hp, wp)
    head = net.head
    assert head is not None
    op = f"narvis head[{w}x{h}]"
    if impl == "head":
        run(
            benchmark,
            lambda: head(planes, *graph, out=output, queue=queue),
            op=op,
            impl="kpn head (OpenCL: clvis.post.kpn)",
            role="clvis",
            n=w * h,
            nbytes=hp * wp * 4 * (4 + head.channels + 1 + 3),
            queue=queue,
            rounds=7,
        )
        return
    x, logits, near = (t.get() for t in (planes, *graph))
    run(
        benchmark,
        lambda: kpn_head(
            x,
            logits,
            near,
            head.kernels,
            depth_select=head.depth_select,
            depth_scale=head.depth_scale,
            logit_bound=head.logit_bound,
        ),
        op=op,
        impl="kpn head NumPy reference (float64)",
        role="peer",
        n=w * h,
        nbytes=hp * wp * 4 * (4 + head.channels + 1 + 3),
        rounds=3,
    )


def _scan_splat(benchmark, queue, impl, w, h, g):
    """The classical splat alone (clvis.post.splat: narvis-scan's eval
    baseline and its guard's candidate, which runs it twice) on the frame's
    covered colours with the radius plane as sigma, the guard's call,
    against its NumPy reference (the scatter it was until splat44)."""
    from clvis.post.splat import splat
    from clvis.reference.post.splat import splat as splat_numpy

    covered = np.asarray(g.covered)
    rgb = np.where(covered[..., None], np.asarray(g.rgba)[..., :3] / np.float32(255), np.float32(0))
    rgb = rgb.astype(np.float32)
    sigma = np.asarray(g.radius_px, np.float32)
    kw = dict(opacity=data.SCAN_OPACITY, sigma=sigma)
    op = f"narvis-scan splat[{w}x{h}]"
    if impl == "splat":
        splat(rgb, covered, None, queue=queue, **kw)
        fn, name, role, rounds = (lambda: splat(rgb, covered, None, queue=queue, **kw)), "OpenCL", "clvis", 5
    else:
        fn, name, role, rounds = (lambda: splat_numpy(rgb, covered, None, **kw)), "NumPy reference", "peer", 3
    run(
        benchmark,
        fn,
        op=op,
        impl=f"classical splat ({name})",
        role=role,
        n=w * h,
        nbytes=w * h * 32,
        rounds=rounds,
    )


def _narvis_subpixel(benchmark, queue, impl, w, h, image):
    """NARVis's sub-pixel rule alone (clvis.post.subpixel, after the head)
    on the same frame's device tensors, against its NumPy reference."""
    from clvis.post.subpixel import subpixel_blend
    from clvis.reference.post import subpixel as ref

    net = post.load("narvis", queue=queue)
    net(image)
    hp, wp = post.padded_shape(h, w, net.stride)
    planes, output = net._buffers_for(hp, wp)
    lo, hi, reach = net.spec.subpixel
    c, dc, vol = net._radius_channel, net._depth_channel, net.spec.subpixel_volume
    op = f"narvis sub-pixel rule[{w}x{h}]"
    # terms: 6 plane floats read (the neighbours' cached), 32 bytes written; rows: 32 read, 32 written;
    # blend: 2 x 32 read (sliding), 6 floats read, 3 written
    nbytes = hp * wp * (6 * 4 + 32 + 64 + 64 + 9 * 4)
    if impl == "subpixel":
        run(
            benchmark,
            lambda: subpixel_blend(
                planes,
                output,
                radius_channel=c,
                lo=lo,
                hi=hi,
                reach=reach,
                depth_channel=dc,
                volume=vol,
                out=output,
                queue=queue,
            ),
            op=op,
            impl="sub-pixel rule (OpenCL: clvis.post.subpixel)",
            role="clvis",
            n=w * h,
            nbytes=nbytes,
            queue=queue,
            rounds=7,
        )
        return
    x, y = planes.get(), output.get()
    run(
        benchmark,
        lambda: ref.subpixel_blend(x, y, c, lo, hi, reach, dc, vol),
        op=op,
        impl="sub-pixel rule NumPy reference (float64)",
        role="peer",
        n=w * h,
        nbytes=nbytes,
        rounds=3,
    )


def _narvis_extra(benchmark, queue, impl, op, w, h, scene, ras, cam, image):
    """The fast path whole, and the wider configurations' inference."""
    if impl == "fast":
        net = post.load("narvis", queue=queue)
        _fast_path(benchmark, queue, op, benchreport.NARVIS_FAST, w, h, scene, ras, cam, net)
        return
    import onnxruntime as ort

    first = int(impl.split("-")[0])  # "16-256": 16, 32, 64, 128, 256
    widths = tuple(first << i for i in range(5))
    path, params = _wide(widths)
    so = ort.SessionOptions()
    so.intra_op_num_threads = os.cpu_count() or 1
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    s = ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])
    x = np.asarray(post.pack_gbuffers(image, post.load("narvis").planes, stride=16))
    s.run(None, {"planes": x})
    run(
        benchmark,
        lambda: s.run(None, {"planes": x}),
        op=op,
        impl=f"onnxruntime fp32, widths {widths[0]}..{widths[-1]} ({params / 1e6:.2f} M parameters)",
        role="peer",
        n=w * h,
        nbytes=x.nbytes,
        rounds=3,
    )
