"""Benchmarks of clvis.raster (render + resolve) with their peers in one session.

A LiDAR-like terrain scan of 2^24 points (clvis.datasets.terrain), seen whole
at 1920x1080 from an oblique camera (Camera.fit), in three orders:

- "morton order": the cloud sorted along the Morton curve beforehand (as
  files from Potree-style tools are), rendered as it is;
- "random order": the same points shuffled;
- "culled view": the Morton-ordered cloud seen from close by, so most batches
  are culled without reading a point.

Per op: clvis render + resolve on device arrays (index, depth, rgba planes;
nothing read back), the NumPy reference render a user would write
(clvis.reference.raster.visibility: float32 projection, culling, key packing,
np.minimum.at), np.minimum.at alone on keys and pixel indices computed
beforehand (the scatter step only), and the device copy kernel over 16 bytes
per point (DESIGN.md's bytes model: xyz float + rgba), the bandwidth limit.

Eye-dome lighting (clvis.raster.edl) on a 1920x1080 frame of the same scene
(depth and rgba G-buffers on the device): clvis, its NumPy reference, and the
copy kernel over its 12 bytes per pixel (depth and rgba in, rgba out):

    clvis bench raster
"""

import numpy as np
import pyopencl.array as cla
import pytest
from benchutil import run, scaled

import clvis
from clvis import datasets
from clvis import primitives as P
from clvis.reference import raster as ref

N = scaled(1 << 24)
W, H = 1920, 1080
_cache = {}


def scene(queue):
    """(cloud in Morton order, the same shuffled, camera, close camera), once."""
    if "scene" not in _cache:
        d = datasets.terrain(N, seed=0)
        pos, colors = d["positions"], d["colors"]
        order = clvis.morton_order(pos, queue=queue)
        pos, colors = pos[order], colors[order]
        shuffle = np.random.default_rng(1).permutation(N)
        lo, hi = pos.min(axis=0), pos.max(axis=0)
        cam = clvis.Camera.fit(lo, hi, aspect=W / H)
        centre = (lo + hi) / 2
        close = clvis.Camera.look_at(
            centre + [0, -40, 60], centre + [0, 10, 0], (0, 0, 1), fov_y=50, aspect=W / H, near=1, far=2000
        )
        _cache["scene"] = (pos, colors, pos[shuffle], colors[shuffle], cam, close)
    return _cache["scene"]


def rasterizer(queue, which):
    key = ("r", which)
    if key not in _cache:
        pos, colors, spos, scolors, _, _ = scene(queue)
        p, c = (spos, scolors) if which == "random order" else (pos, colors)
        _cache[key] = clvis.Rasterizer(p, colors=c, morton=False, queue=queue)
    return _cache[key]


OPS = {
    "morton order": "raster[morton order]",
    "random order": "raster[random order]",
    "culled view": "raster[culled view]",
}
IMPLS = ["clvis", "numpy-reference", "numpy-minimum.at", "copy"]
CASES = [(o, i) for o in OPS for i in IMPLS if not (o == "culled view" and i == "numpy-minimum.at")]


@pytest.mark.parametrize("order,impl", CASES)
def test_raster(benchmark, queue, order, impl):
    pos, _, spos, _, cam, close = scene(queue)
    op = OPS[order]
    camera = close if order == "culled view" else cam
    points = spos if order == "random order" else pos
    model = 16 * N
    if impl == "clvis":
        r = rasterizer(queue, order)
        info = r.render(camera, W, H).stats  # warm-up, and the culling figures
        run(
            benchmark,
            lambda: r.render(camera, W, H, host=False),
            op=op,
            impl=impl,
            role="clvis",
            n=N,
            nbytes=model,
            queue=queue,
            batches=info["batches"],
            batches_drawn=info["batches_drawn"],
            points_read=info["points_read"],
        )
    elif impl == "numpy-reference":
        run(
            benchmark,
            lambda: ref.visibility(points, camera, W, H),
            op=op,
            impl="numpy reference render (np.minimum.at)",
            role="peer",
            n=N,
            nbytes=model,
            rounds=3,
        )
    elif impl == "numpy-minimum.at":
        pr = camera.project(points, W, H)
        idx = np.flatnonzero(pr.visible)
        pix = pr.py[idx].astype(np.int64) * W + pr.px[idx]
        keys = (ref.depth_key(pr.depth[idx]).astype(np.uint64) << np.uint64(32)) | idx.astype(np.uint64)
        vis = np.empty(W * H, np.uint64)

        def scatter():
            vis.fill(np.iinfo(np.uint64).max)
            np.minimum.at(vis, pix, keys)

        run(
            benchmark,
            scatter,
            op=op,
            impl="np.minimum.at alone (keys precomputed)",
            role="peer",
            n=N,
            nbytes=model,
            rounds=3,
        )
    else:
        src = _cache.get("copy")
        if src is None:
            src = _cache["copy"] = (cla.empty(queue, 4 * N, np.float32), cla.empty(queue, 4 * N, np.float32))
        run(
            benchmark,
            lambda: P.copy(src[0], out=src[1]),
            op=op,
            impl="copy kernel (16 B/point)",
            role="copy",
            n=N,
            nbytes=2 * src[0].nbytes,
            queue=queue,
        )


EDL_CASES = ["clvis", "numpy-reference", "copy"]


def edl_frame(queue):
    """The depth and rgba G-buffers of the scene's whole view, on the host."""
    if "edl" not in _cache:
        pos, colors, _, _, cam, _ = scene(queue)
        g = clvis.rasterize(pos, cam, W, H, colors=colors, queue=queue)
        _cache["edl"] = (g.depth, g.rgba)
    return _cache["edl"]


@pytest.mark.parametrize("impl", EDL_CASES)
def test_edl(benchmark, queue, impl):
    depth, rgba = edl_frame(queue)
    model = 12 * W * H
    if impl == "clvis":
        dd, rd = cla.to_device(queue, depth), cla.to_device(queue, rgba)
        clvis.raster.edl(dd, rd, queue=queue)  # builds the kernel
        run(
            benchmark,
            lambda: clvis.raster.edl(dd, rd, queue=queue),
            op="edl[1920x1080]",
            impl=impl,
            role="clvis",
            n=W * H,
            nbytes=model,
            queue=queue,
        )
    elif impl == "numpy-reference":
        run(
            benchmark,
            lambda: ref.edl.edl(depth, rgba),
            op="edl[1920x1080]",
            impl="numpy reference",
            role="peer",
            n=W * H,
            nbytes=model,
            rounds=3,
        )
    else:
        src = (cla.empty(queue, 3 * W * H, np.float32), cla.empty(queue, 3 * W * H, np.float32))
        run(
            benchmark,
            lambda: P.copy(src[0], out=src[1]),
            op="edl[1920x1080]",
            impl="copy kernel (12 B/pixel)",
            role="copy",
            n=W * H,
            nbytes=2 * src[0].nbytes,
            queue=queue,
        )
