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
beforehand (the scatter step only), the same float32 projection and scatter
compiled by numba on 2 threads (each thread a z-buffer of its half of the
points, then a parallel min of the two: what compiled code on the same cores
does; the visibility buffer only, checked equal to clvis's winners), and the
device copy kernel over 16 bytes
per point (DESIGN.md's bytes model: xyz float + rgba), the bandwidth limit.

Eye-dome lighting (clvis.raster.edl) on a 1920x1080 frame of the same scene
(depth and rgba G-buffers on the device): clvis, its NumPy reference, and the
copy kernel over its 12 bytes per pixel (depth and rgba in, rgba out).

Reading the scan a render starts from, as text (a Leica .pts of 2^21 of the
terrain's points: x y z intensity r g b, the count first; a host op, bytes =
the file's): clvis.read_points, Open3D's o3d.io.read_point_cloud (C++, what
an Open3D user calls; it keeps positions and colours) and np.loadtxt of the
same rows (the parser clvis's reader is built on, alone):

    clvis bench raster
"""

import numpy as np
import pyopencl.array as cla
import pytest
from benchutil import run, scaled, threads

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
IMPLS = ["clvis", "numpy-reference", "numpy-minimum.at", "numba", "copy"]
NUMBA_THREADS = 2
_numba = {}


def numba_render():
    """The numba peer, compiled once: (render(pos, m, d, consts, vis, bufs), merge)."""
    if not _numba:
        import numba

        @numba.njit(parallel=True, cache=False)
        def render(pos, m, d, c, bufs, vis):
            # c: near, far, W, H, 0.5, 1 as float32; every step in float32, no fma
            near, far, fw, fh, half, one = c[0], c[1], c[2], c[3], c[4], c[5]
            W = np.int64(fw)
            n = pos.shape[0]
            nt = bufs.shape[0]
            per = (n + nt - 1) // nt
            for t in numba.prange(nt):
                buf = bufs[t]
                buf[:] = np.uint64(0xFFFFFFFFFFFFFFFF)
                depth = np.empty(1024, np.float32)
                bits = depth.view(np.uint32)
                pix = np.empty(1024, np.int64)
                for s0 in range(t * per, min(n, (t + 1) * per), 1024):
                    s1 = min(s0 + 1024, n, (t + 1) * per)
                    for i in range(s0, s1):
                        x, y, z = pos[i, 0], pos[i, 1], pos[i, 2]
                        cx = ((m[0] * x + m[1] * y) + m[2] * z) + m[3]
                        cy = ((m[4] * x + m[5] * y) + m[6] * z) + m[7]
                        cw = ((m[12] * x + m[13] * y) + m[14] * z) + m[15]
                        dd = ((d[0] * x + d[1] * y) + d[2] * z) + d[3]
                        r = one / cw
                        sx = ((cx * r) * half + half) * fw
                        sy = (half - (cy * r) * half) * fh
                        ok = (
                            np.isfinite(x)
                            and np.isfinite(y)
                            and np.isfinite(z)
                            and dd >= near
                            and dd <= far
                            and cw > 0
                            and sx >= 0
                            and sx < fw
                            and sy >= 0
                            and sy < fh
                        )
                        depth[i - s0] = dd
                        pix[i - s0] = np.int64(sy) * W + np.int64(sx) if ok else -1
                    for i in range(s0, s1):
                        p = pix[i - s0]
                        if p >= 0:
                            b = bits[i - s0]
                            k = (~b) if b & np.uint32(0x80000000) else (b | np.uint32(0x80000000))
                            key = (np.uint64(k) << np.uint64(32)) | np.uint64(i)
                            if key < buf[p]:
                                buf[p] = key
            for p in numba.prange(vis.shape[0]):
                v = bufs[0, p]
                for t in range(1, nt):
                    v = min(v, bufs[t, p])
                vis[p] = v

        _numba["render"] = render
    return _numba["render"]


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
    elif impl == "numba":
        with threads(numba=NUMBA_THREADS):  # numba's count given back after the case
            render = numba_render()
            f32 = np.float32
            m = camera.matrix.astype(f32).ravel()
            d = camera.depth_row.astype(f32)
            c = np.array([camera.near, camera.far, W, H, 0.5, 1.0], f32)
            bufs = np.empty((NUMBA_THREADS, W * H), np.uint64)
            vis = np.empty(W * H, np.uint64)
            render(points, m, d, c, bufs, vis)  # compile, and check the winners against clvis's
            want = rasterizer(queue, order).render(camera, W, H).index.ravel()
            assert np.array_equal((vis & np.uint64(0xFFFFFFFF)).astype(np.uint32), want)
            run(
                benchmark,
                lambda: render(points, m, d, c, bufs, vis),
                op=op,
                impl=f"numba parallel ({NUMBA_THREADS} threads, visibility only)",
                role="peer",
                n=N,
                nbytes=model,
                rounds=5,
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


TEXT_N = scaled(1 << 21)
TEXT_CASES = ["clvis.read_points", "open3d", "numpy-loadtxt"]


def text_scan(tmp_path_factory):
    """A .pts file of TEXT_N terrain points, written once."""
    if "pts" not in _cache:
        d = datasets.terrain(TEXT_N, seed=0)
        path = tmp_path_factory.mktemp("text") / "scan.pts"
        rng = np.random.default_rng(2)
        with open(path, "w") as f:
            f.write(f"{TEXT_N}\n")
            np.savetxt(
                f,
                np.c_[
                    d["positions"] + [635000.0, 848000.0, 400.0],
                    rng.integers(-2048, 2048, TEXT_N),
                    d["colors"][:, :3],
                ],
                fmt=["%.4f"] * 3 + ["%d"] * 4,
            )
        _cache["pts"] = path
    return _cache["pts"]


@pytest.mark.parametrize("impl", TEXT_CASES)
def test_read_text_cloud(benchmark, tmp_path_factory, impl):
    path = text_scan(tmp_path_factory)
    nbytes = path.stat().st_size
    op = "read[.pts]"
    if impl == "clvis.read_points":
        fn, role = (lambda: clvis.read_points(path)), "clvis-host"
    elif impl == "open3d":
        o3d = pytest.importorskip("open3d", reason="open3d-cpu is in the test extra")
        fn, role = (lambda: o3d.io.read_point_cloud(str(path), format="pts")), "peer"
    else:
        fn, role = (lambda: np.loadtxt(path, skiprows=1, comments="#")), "peer"
    run(benchmark, fn, op=op, impl=impl, role=role, n=TEXT_N, nbytes=nbytes, rounds=3)
