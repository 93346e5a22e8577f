"""The workload tests/oclgrind/audit.py runs under Oclgrind: small cases of
every kernel of every family, through the public Python API, in one
configuration (tuning profile, 64-bit atomics on or off).

    oclgrind --data-races --check-api python tests/oclgrind/cases.py cpu int64 [CASE ...]
    oclgrind ... python tests/oclgrind/cases.py cpu int64 --serve

(--serve: the case names come on stdin, one a line, each run as it arrives,
until stdin closes; the audit hands them to several such workloads at once.)

It prints to stderr, where Oclgrind writes its diagnostics, a line
``@@case <name>`` before each case (so the audit can say which case a
diagnostic came from), ``@@error <json>`` (the case and its traceback) when
a case raises, ``@@time <name> <seconds>`` after each case, and at the end
``@@launched <json>``: how often each kernel was enqueued, by name, and
``@@case-kernels <json>``: which kernels each case enqueued. Sizes
are tiny (Oclgrind interprets every work-item) but give several work-groups
in both work shapes, so cross-group accesses are seen.
Results are not checked here: tests/ does that.
"""

from __future__ import annotations

import json
import sys
import time
import traceback
import warnings

import numpy as np
import pyopencl as cl

MARK = "@@"


def _note(kind: str, text: str) -> None:
    sys.stderr.flush()
    sys.stderr.write(f"{MARK}{kind} {text}\n")
    sys.stderr.flush()


# ---------------------------------------------------------------------------
# launch record: every enqueue goes through pyopencl.enqueue_nd_range_kernel
# (clvis.runtime.launch looks it up on the module at each call)

LAUNCHED: dict[str, int] = {}
BY_CASE: dict[str, set[str]] = {}  # case -> the kernels it enqueued
_current = ["(start)"]
_enqueue = cl.enqueue_nd_range_kernel


def _recording_enqueue(queue, kernel, *args, **kw):
    name = kernel.function_name
    LAUNCHED[name] = LAUNCHED.get(name, 0) + 1
    BY_CASE.setdefault(_current[0], set()).add(name)
    return _enqueue(queue, kernel, *args, **kw)


cl.enqueue_nd_range_kernel = _recording_enqueue

# imported after the patch, so that nothing binds the original first
import clvis
import clvis.post
from clvis import Camera, runtime
from clvis.gauss import GaussianRenderer, Gaussians, SparseVolume, build_bvh, lod_table
from clvis.gauss.points import frames_along
from clvis.iso import BlockCache, IsoRenderer

# ---------------------------------------------------------------------------
# cases: each takes the queue and runs a few public calls

CASES = []


def case(fn):
    CASES.append(fn)
    return fn


def _rng(seed=0):
    return np.random.default_rng(seed)


@case
def scan(q):
    rng = _rng(1)
    # several groups in both work shapes (the gpu shape's tile is 2048)
    for n in (1, 100, 2500):
        clvis.scan(rng.integers(-1000, 1000, n).astype(np.int32), queue=q)
    clvis.scan(rng.integers(0, 1000, 300).astype(np.uint32), exclusive=False, queue=q)
    clvis.scan(rng.random(300).astype(np.float32), queue=q)
    clvis.scan(rng.integers(0, 2**40, 300).astype(np.uint64), return_total=True, queue=q)
    clvis.scan(rng.integers(-(2**40), 2**40, 300).astype(np.int64), queue=q)
    # scan_chained's look-back fallback (a -D variant, testing only)
    import clvis.primitives as prim

    prim._SCAN_TEST_FALLBACK = True
    try:
        clvis.scan(rng.integers(0, 9, 700).astype(np.uint32), queue=q)
    finally:
        prim._SCAN_TEST_FALLBACK = False


@case
def compact(q):
    rng = _rng(2)
    for n in (1, 300, 2500):
        x = rng.integers(-100, 100, n).astype(np.int32)
        f = rng.random(n) < 0.4
        clvis.compact(x, f, queue=q)
        clvis.compact_indices(f, queue=q)
    clvis.compact(rng.random((200, 3)).astype(np.float32), rng.integers(0, 3, 200).astype(np.uint16), queue=q)
    clvis.compact(rng.integers(0, 255, 150).astype(np.uint8), np.ones(150, np.bool_), queue=q)


@case
def radix_sort(q):
    rng = _rng(3)
    # every pass runs the same kernels: key_bits keeps the pass count (and
    # Oclgrind's time) down where the key type allows it
    for n in (3, 2500):  # the gpu shape's tile is 1024 keys
        k = rng.integers(0, 2**12, n).astype(np.uint32)
        clvis.radix_sort(k, np.arange(n, dtype=np.uint32), key_bits=12, queue=q)
    clvis.radix_sort(rng.standard_normal(300).astype(np.float32), queue=q)
    clvis.radix_sort(
        rng.integers(-(2**31), 2**31, 100).astype(np.int32), rng.random(100).astype(np.float32), queue=q
    )
    clvis.radix_sort(rng.integers(0, 2**36, 200, dtype=np.uint64), key_bits=36, queue=q)
    clvis.radix_sort(rng.standard_normal(50), queue=q)
    # the CPU shape's MSD-first path (radix_bucket_lsd), at a size it would
    # otherwise leave to the LSD passes; key_bits 20 and 44 take a 12-bit top
    # digit (4096 buckets, most of them empty, the last one included)
    msd, clvis.primitives.MSD_MIN_N = clvis.primitives.MSD_MIN_N, 0
    try:
        k = rng.integers(0, 2**20, 700).astype(np.uint32)
        clvis.radix_sort(k, np.arange(700, dtype=np.uint32), key_bits=20, queue=q)
        k = rng.integers(0, 2**44, 300, dtype=np.uint64)
        k[::2] |= np.uint64((2**44 - 1) & ~(2**32 - 1))
        clvis.radix_sort(k, np.arange(300, dtype=np.uint32), key_bits=44, queue=q)
        clvis.radix_sort(rng.integers(0, 2**40, 300, dtype=np.uint64) | np.uint64(5 << 16), queue=q)
        # 32-bit pairs: the staged top-digit scatter (8 bits, non-temporal
        # lines), then 2 passes of 12 bits a bucket (forced on these tiny
        # buckets by BUCKET_SLACK)
        slack, clvis.primitives.BUCKET_SLACK = clvis.primitives.BUCKET_SLACK, -12
        try:
            k = rng.integers(0, 2**32, 700, dtype=np.uint32)
            clvis.radix_sort(k, np.arange(700, dtype=np.uint32), queue=q)
        finally:
            clvis.primitives.BUCKET_SLACK = slack
    finally:
        clvis.primitives.MSD_MIN_N = msd


@case
def histogram(q):
    rng = _rng(4)
    clvis.histogram(rng.integers(0, 16, 300).astype(np.int32), 16, queue=q)  # local bins
    clvis.histogram(rng.integers(0, 300, 2500).astype(np.uint32), 300, queue=q)
    clvis.histogram(rng.integers(0, 1000, 300).astype(np.uint32), 1000, queue=q)  # global: n < bins
    clvis.histogram(rng.integers(0, 5000, 300).astype(np.int32), 4000, check=False, queue=q)


@case
def copy(q):
    from clvis.primitives import copy as dcopy

    rng = _rng(5)
    dcopy(rng.random(257).astype(np.float32), queue=q)
    dcopy(rng.integers(0, 255, 13).astype(np.uint8), queue=q)


# --- raster ------------------------------------------------------------------


def _raster_cam(w, h, eye=(0.3, -6.0, 1.2)):
    return Camera.look_at(eye, (0.0, 0.0, 0.0), (0, 0, 1), fov_y=50.0, aspect=w / h, near=0.5, far=20.0)


def _cloud(n, seed):
    rng = _rng(seed)
    pos = rng.normal(size=(n, 3)).astype(np.float32)
    pos[::37] = np.nan  # non-finite points are skipped
    # duplicates: ties in depth go to the lowest index
    pos[n // 2 : n // 2 + 20] = pos[:20]
    return pos


@case
def rasterize(q):
    rng = _rng(6)
    n, w, h = 300, 16, 12
    pos = _cloud(n, 6)
    colors = rng.integers(0, 256, (n, 4)).astype(np.uint8)
    attrs = {"temp": rng.random(n).astype(np.float32), "cls": rng.integers(0, 5, n).astype(np.uint8)}
    vel = rng.normal(size=(n, 3)).astype(np.float32)
    radius = rng.uniform(0.01, 0.1, n).astype(np.float32)
    # Morton order (morton_order: codes, iota, radix sort; then gather, invert)
    r = clvis.Rasterizer(
        pos,
        colors=colors,
        attributes=attrs,
        velocity=vel,
        radius=radius,
        morton=True,
        batch_size=100,
        queue=q,
    )
    front, back = _raster_cam(w, h), _raster_cam(w, h, (-0.3, 6.0, -1.2))  # batch walk reverse = 0, 1
    r.render(front, w, h, soft_z=True)  # colors
    r.render(back, w, h, color_by="temp", soft_z=1.05)  # a float attribute through the colormap
    r.render(front, w, h, color_by="cls")  # a uint8 attribute
    # input order, white points, soft z; colors and radius only
    clvis.rasterize(pos, _raster_cam(8, 8), 8, 8, soft_z=True, batch_size=50, queue=q)
    clvis.rasterize(
        pos[:40],
        _raster_cam(32, 24),
        32,
        24,
        colors=colors[:40, :3],
        radius=radius[:40],
        morton=False,
        queue=q,
    )
    # squares of 3 pixels (POINT_SIZE 3) at the image's edges, soft z too; non-finite points counted
    bad = pos.copy()
    bad[::7] = np.nan
    r = clvis.Rasterizer(bad, colors=colors, batch_size=64, queue=q)
    r.render(front, w, h, point_size=3, soft_z=True)
    r.render(back, w, h, point_size=2)


@case
def depth_filter(q):
    rng = _rng(7)
    h, w = 24, 20
    depth = np.where(rng.random((h, w)) < 0.6, rng.uniform(2, 20, (h, w)), np.inf).astype(np.float32)
    for levels in (0, 1, 3):
        clvis.raster.depth_filter_mask(depth, levels, 1.05, edge_threshold=0.01, queue=q)
    clvis.raster.depth_filter_mask(depth[:7, :5], 2, queue=q)
    g = clvis.rasterize(_cloud(300, 8), _raster_cam(w, h), w, h, queue=q)
    clvis.depth_filter(g, 2, queue=q)
    # device planes in: the kept depth and colour are made by depth_kept
    gd = clvis.Rasterizer(_cloud(300, 8), queue=q).render(_raster_cam(w, h), w, h, host=False)
    clvis.depth_filter(gd, 2)
    clvis.depth_filter(gd.depth, 1)
    rgba = rng.integers(0, 256, (h, w, 3)).astype(np.uint8)
    clvis.raster.rgbda(rgba, depth, rng.random((h, w)) < 0.5, queue=q)


@case
def edl(q):
    rng = _rng(8)
    h, w = 19, 23  # not a multiple of any work-group size: items past the end
    depth = np.where(rng.random((h, w)) < 0.7, rng.uniform(2, 20, (h, w)), np.inf).astype(np.float32)
    rgba = rng.integers(0, 256, (h, w, 4)).astype(np.uint8)
    for radius in (1, 3, 30):  # 30: every neighbour outside the image
        clvis.raster.edl(depth, rgba, 1.0, radius, queue=q)


# --- iso ---------------------------------------------------------------------


def _volume(n=13, seed=9):
    """A sphere-ish field with noise: [z, y, x] float32, edge blocks partial."""
    zz, yy, xx = np.mgrid[:n, : n + 2, : n + 5].astype(np.float32)
    c = (n - 1) / 2
    r = np.sqrt((xx - c) ** 2 + (yy - c) ** 2 + (zz - c) ** 2) / c
    return (1.0 - r + 0.05 * _rng(seed).standard_normal(r.shape)).astype(np.float32)


def _iso_cam(w, h, eye=(30.0, -26.0, 18.0)):
    return Camera.look_at(eye, (6.0, 6.0, 6.0), (0, 0, 1), fov_y=40, aspect=w / h, near=0.05, far=200)


@case
def zfp(q):
    zv = clvis.zfp.compress(_volume(), 12)
    clvis.zfp.decode(zv, queue=q)
    clvis.zfp.decode_blocks(zv, [0, 3, zv.nblocks - 1, 1], queue=q, host=True)
    ids = runtime.empty(q, 3, np.uint32, "ids")
    ids.set(np.array([2, zv.nblocks + 5, 0], np.uint32))  # an out-of-range id: a NaN brick
    clvis.zfp.decode_blocks(zv, ids, queue=q, host=True)


@case
def iso_render(q):
    zv = clvis.zfp.compress(_volume(), 16)
    w, h = 16, 12
    # a 2-slot cache: it grows, and evicts in later passes
    r = IsoRenderer(zv, cache_capacity=2, queue=q)
    r.render(_iso_cam(w, h), w, h, 0.3, speculation=True)
    r = IsoRenderer(zv, spacing=(1.0, 0.9, 1.1), origin=(-1.0, 0.0, 0.5), queue=q)
    r.render(_iso_cam(8, 8, (-20.0, 30.0, -10.0)), 8, 8, 0.5, completion=0.9, speculation=False)
    # tiles of 37 pixels: every kernel starts mid-row at a tile's first pixel
    r.render(_iso_cam(w, h), w, h, 0.3, tile_pixels=37)
    # the image on the device (tile_image, mark_active, mark_candidates): tiles stopped early,
    # and the passes' snapshots with tiles not started yet
    r.render(_iso_cam(w, h), w, h, 0.3, completion=0.5, speculation=False, tile_pixels=37, host=False)
    for _ in r.passes(_iso_cam(w, h), w, h, 0.3, tile_pixels=97, host=False):
        pass


@case
def iso_surface(q):
    """sample_hits (surface.cl): hits from a render, a field on another grid
    reaching past the box on one side and short of it on the other (NaN
    hits), a host and a device image, and a size off the work-group size."""
    zv = clvis.zfp.compress(_volume(), 16)
    w, h = 17, 13
    cam = _iso_cam(w, h)
    img = IsoRenderer(zv, queue=q).render(cam, w, h, 0.3)
    field = _volume(5, seed=12)[:, :6, :7]
    clvis.iso.sample_hits(img, cam, field, (3.0, 2.5, 2.0), (0.5, -0.5, 0.0), queue=q)
    dev = IsoRenderer(zv, queue=q).render(cam, w, h, 0.3, host=False)
    clvis.iso.sample_hits(dev, cam, np.ones((2, 2, 2), np.float32), (12.0, 14.0, 17.0), queue=q)


@case
def iso_cache(q):
    """The LRU cache through evictions: fewer slots than needed blocks."""
    zv = clvis.zfp.compress(_volume(), 8)
    nb = zv.nblocks
    cache = BlockCache(zv, 3, queue=q)
    rng = _rng(10)
    for _ in range(3):
        needed = np.zeros(nb, np.uint8)
        needed[rng.choice(nb, 2, replace=False)] = 1
        cache.update(needed)
    needed = np.zeros(nb, np.uint32)
    needed[:5] = 1  # more than the capacity: the cache grows
    cache.update(needed)
    clvis.iso.mark_blocks(np.array([0, 2, 3], np.uint32), zv, queue=q)


# --- gauss -------------------------------------------------------------------


def _gaussians(n, seed=11):
    rng = _rng(seed)
    means = rng.normal(size=(n, 3))
    scales = rng.uniform(0.05, 0.3, size=(n, 3))
    rot = frames_along(rng.normal(size=(n, 3)))
    return Gaussians(means, scales, rot, rng.uniform(-1, 2, n), rng.uniform(0.05, 0.9, n))


def _gauss_cam(w, h):
    return Camera.look_at(
        (0.3, -6.0, 1.2), (0, 0, 0), (0, 0, 1), fov_y=50.0, aspect=w / h, near=0.1, far=50.0
    )


@case
def gauss_lod(q):
    rng = _rng(12)
    vol = rng.random((12, 10, 19)).astype(np.float32)
    sv = SparseVolume.from_dense(vol, threshold=0.6, spacing=(1.0, 0.5, 2.0), origin=(1.0, 2.0, 3.0))
    for lod in ("low", "medium", "high"):
        clvis.gaussians_from_volume(sv, lod, queue=q)
    lod_table(sv, queue=q)
    full = rng.random((9, 9, 9)).astype(np.float32)  # every voxel active: tiles of one value
    full[:] = 0.5
    clvis.gaussians_from_volume(full, "medium", queue=q)


@case
def gauss_bvh(q):
    rng = _rng(13)
    for n in (1, 3, 300):
        lo = rng.normal(size=(n, 3)).astype(np.float32)
        hi = lo + rng.uniform(0, 0.2, (n, 3)).astype(np.float32)
        if n == 300:
            lo[50:60] = lo[0]  # equal Morton codes
            hi[50:60] = hi[0]
        build_bvh(np.concatenate([lo, hi], axis=1), queue=q)


@case
def gauss_render(q):
    g = _gaussians(120)
    w, h = 16, 12
    GaussianRenderer(g, model="max_response", queue=q, method="bvh").render(_gauss_cam(w, h), w, h)
    # k=3: several k-buffer rounds per ray
    GaussianRenderer(g, model="absorption", k=3, density=2.0, queue=q, method="bvh").render(
        _gauss_cam(9, 7), 9, 7
    )
    GaussianRenderer(_gaussians(1, 14), queue=q, method="bvh").render(_gauss_cam(8, 8), 8, 8)
    # per-Gaussian colours (COLOR 1), in bands of 5 rows
    coloured = _gaussians(60, 15)
    coloured = Gaussians(
        coloured.means,
        coloured.scales,
        coloured.rotations,
        coloured.values,
        coloured.opacities,
        colors=_rng(15).integers(0, 256, (60, 3)).astype(np.uint8),
    )
    GaussianRenderer(coloured, queue=q, method="bvh").render(_gauss_cam(w, h), w, h, tile_rows=5)


@case
def gauss_tiles(q):
    """The tile renderer: count, scan, keys, sort, ranges, gather_records, render (tile_render8
    under the cpu shape, tile_render under the gpu one)."""
    g = _gaussians(80, 16)
    w, h = 19, 13  # partial tiles on both edges
    GaussianRenderer(g, queue=q, method="tiles").render(_gauss_cam(w, h), w, h)
    # kp=2: pending overflow, rounds over the lists; key budget: bands of tile rows
    GaussianRenderer(g, model="absorption", density=2.0, kp=2, queue=q, method="tiles").render(
        _gauss_cam(w, 40), w, 40, max_keys=20
    )
    # the eye inside a Gaussian (every tile), one behind it, own colours
    around = Gaussians(
        [[0.3, -6.0, 1.2], [0.3, -9.0, 1.2], [0.0, 0.0, 0.0]],
        [[1.0, 1.0, 1.0], [0.2, 0.2, 0.2], [0.5, 0.3, 0.4]],
        values=[0.1, 0.5, 0.9],
        opacities=[0.2, 0.9, 0.9],
        colors=[[255, 0, 0], [0, 255, 0], [0, 0, 255]],
    )
    GaussianRenderer(around, queue=q, method="tiles").render(_gauss_cam(9, 7), 9, 7)
    # the splatting model (splat.cl; splat_count8 / splat_keys8 under the cpu shape, 3 and 80
    # Gaussians: idle lanes), own colours, in two bands
    GaussianRenderer(around, queue=q, model="splat").render(_gauss_cam(9, 7), 9, 7)
    GaussianRenderer(g, queue=q, model="splat").render(_gauss_cam(w, 40), w, 40, max_keys=20)
    GaussianRenderer(Gaussians(np.zeros((0, 3)), np.zeros((0, 3))), queue=q, method="tiles").render(
        _gauss_cam(8, 8), 8, 8
    )


# --- post --------------------------------------------------------------------


@case
def post_pushpull(q):
    rng = _rng(21)
    for (h, w), channels in (((19, 23), 3), ((1, 9), 1), ((7, 1), 5)):
        img = rng.random((h, w, channels)).astype(np.float32)
        valid = rng.random((h, w)) < 0.4
        img[~valid] = np.nan
        clvis.post.pushpull(img, valid, queue=q)
    clvis.post.pushpull(img, valid.astype(np.uint8), levels=0, queue=q)
    clvis.post.pushpull(np.ones((1, 1, 2), np.float32), np.ones((1, 1), bool), queue=q)


@case
def post_splat(q):
    from clvis.post.splat import splat

    rng = _rng(23)
    h, w = 13, 17
    rgb = rng.random((h, w, 3)).astype(np.float32)
    cov = rng.random((h, w)) < 0.4
    cov[0, 0] = cov[h - 1, w - 1] = True  # sources at the corners: the gather's bounds
    vel = rng.normal(size=(h, w, 2)).astype(np.float32)
    splat(rgb, cov, vel, radius=3, queue=q)
    splat(rgb, cov, None, radius=1, sigma=rng.random((h, w)).astype(np.float32), queue=q)


@case
def post_pack(q):
    rng = _rng(22)
    h, w = 13, 19
    rgba = rng.random((h, w, 4)).astype(np.float32)
    hit, active = rng.random((h, w)) < 0.6, rng.random((h, w)) < 0.2
    for stride in (1, 8):
        clvis.post.pack_iso(rgba, hit, active, stride=stride, queue=q)
    # the candidates plane (pack_count), counts past the cap too
    cand = rng.integers(0, 12, (h, w)).astype(np.uint8)
    clvis.post.pack_iso(rgba, hit, active, candidates=cand, stride=8, queue=q)
    # the hit-prior plane (pack_prior)
    clvis.post.pack_iso(rgba, hit, active, candidates=cand, crossing_rate=0.3, stride=8, queue=q)
    # the depth planes (iso_depth_range, pack_depth), non-finite values among them; none at all
    t = rng.uniform(0, 9, (h, w)).astype(np.float32)
    nxt = np.where(rng.random((h, w)) < 0.2, np.inf, rng.uniform(1, 12, (h, w))).astype(np.float32)
    clvis.post.pack_iso(rgba, hit, active, candidates=cand, depth=(t, nxt), stride=8, queue=q)
    none = np.full((h, w), np.inf, np.float32)
    clvis.post.pack_iso(rgba, hit, active, candidates=cand, depth=(none, none), queue=q)
    x = np.zeros((h, w, 5), np.float32)
    keep = rng.random((h, w)) < 0.5
    x[..., :3] = rng.random((h, w, 3))
    x[..., 3] = np.where(keep, rng.uniform(1, 50, (h, w)), np.inf)
    x[..., 4] = keep
    packed = clvis.post.pack_rgbda(x, stride=8, queue=q)
    clvis.post.pack_rgbda(x[:1, :3], queue=q)
    clvis.post.pack_rgbda(x[:1, :3], stride=8, queue=q)  # padding past twice the image: mirrored again
    for channels in (3, 4):
        clvis.post.unpack_rgba8(packed[:, :channels].copy(), h, w, queue=q)
    # G-buffers of a small cloud with a velocity: pack_rgb_coverage, pack_plane
    from clvis.raster import Rasterizer

    pos = rng.uniform(-1, 1, (300, 3)).astype(np.float32)
    vel = rng.normal(0, 1, (300, 3)).astype(np.float32)
    ras = Rasterizer(pos, attributes={"t": pos[:, 2]}, velocity=vel, queue=q)
    g = ras.render(_raster_cam(w, h), w, h, color_by="t")
    for stride in (1, 16):
        clvis.post.pack_gbuffers(g, ("rgb", "depth", "vel2d", "t"), stride=stride, queue=q)


@case
def post_kpn(q):
    """The kernel-prediction head (kpn_blocks, kpn_apply): scales with s = 1
    and s > 1, with and without depth_select, a grid of blocks whose edge
    candidates fall outside it."""
    from clvis.post.kpn import kpn_head

    rng = _rng(23)
    h, w = 16, 24
    x = rng.random((1, 9, h, w)).astype(np.float32)
    x[0, 3] = rng.random((h, w)) < 0.4
    for kernels, depth_select in ((((3, 1), (3, 2), (3, 4), (3, 8)), True), (((5, 1), (3, 2)), False)):
        k = sum(a * a for a, _ in kernels) + 1 + int(depth_select)
        logits = rng.normal(0, 3, (1, k, h, w)).astype(np.float32)
        near = (rng.random((1, 1, h, w)) * x[:, 3:4]).astype(np.float32) if depth_select else None
        kpn_head(x, logits, near, kernels=kernels, depth_select=depth_select, queue=q)


@case
def post_subpixel(q):
    """NARVis's sub-pixel rule (subpixel_terms, subpixel_rows, subpixel_blend),
    with and without the volume score: windows clipped at every edge (reach
    larger than the image on one axis), pixels whose window covers nothing,
    neighbours off the image, on host and device arrays in place."""
    import pyopencl.array as cl_array

    from clvis.post.subpixel import subpixel_blend

    rng = _rng(29)
    h, w = 13, 21
    planes = rng.random((1, 6, h, w)).astype(np.float32)
    planes[0, 3] = rng.random((h, w)) < 0.6
    planes[0, 3, :, :5] = 0  # a band with no coverage in its windows
    planes[0, 5] *= 1.2
    planes[0, 4] = 10 + rng.choice([0.0, 0.01, 1.0], (h, w))
    image = rng.random((1, 3, h, w)).astype(np.float32)
    subpixel_blend(planes, image, radius_channel=5, lo=0.2, hi=0.6, reach=2, queue=q)
    vol = (0.005, 0.2, 0.5, 0.3, 0.8)
    subpixel_blend(
        planes, image, radius_channel=5, lo=0.2, hi=0.6, reach=2, depth_channel=4, volume=vol, queue=q
    )
    d_planes, d_image = cl_array.to_device(q, planes), cl_array.to_device(q, image)
    subpixel_blend(
        d_planes,
        d_image,
        radius_channel=5,
        lo=0.2,
        hi=0.6,
        reach=16,
        depth_channel=4,
        volume=vol,
        out=d_image,
        queue=q,
    )


def _served():
    """The cases named on stdin, as they arrive (an unknown name: an error)."""
    by_name = {fn.__name__: fn for fn in CASES}
    for line in sys.stdin:
        name = line.strip()
        if name:
            yield by_name.get(name) or _unknown(name)


def _unknown(name: str):
    def unknown(q):
        raise ValueError(f"cases.py: no case {name!r}")

    unknown.__name__ = name
    return unknown


def main(argv: list[str]) -> int:
    if len(argv) < 3 or argv[1] not in ("cpu", "gpu") or argv[2] not in ("int64", "no-int64"):
        print("usage: cases.py cpu|gpu int64|no-int64 [CASE ... | --serve]", file=sys.stderr)
        return 2
    tuning, int64 = argv[1], argv[2] == "int64"
    serve = argv[3:] == ["--serve"]
    only = set() if serve else set(argv[3:])
    warnings.simplefilter("ignore")  # compiler warnings are not what this run looks for
    platforms = cl.get_platforms()
    names = [p.name for p in platforms]
    if names != ["Oclgrind"]:
        print(f"cases.py: expected only the Oclgrind platform, got {names}", file=sys.stderr)
        return 2
    device = platforms[0].get_devices()[0]
    failed = 0
    with runtime.configure(tuning=tuning, int64_atomics=int64):
        q = runtime.queue_for(device)
        for fn in _served() if serve else CASES:
            if only and fn.__name__ not in only:
                continue
            _note("case", fn.__name__)
            _current[0] = fn.__name__
            t0 = time.perf_counter()
            try:
                fn(q)
                q.finish()
            except Exception:  # noqa: BLE001  (reported, and the run goes on)
                failed += 1
                _note("error", json.dumps({"case": fn.__name__, "traceback": traceback.format_exc()}))
            _note("time", f"{fn.__name__} {time.perf_counter() - t0:.2f}")
        _note("case", "(end)")
    _note("launched", json.dumps(LAUNCHED, sort_keys=True))
    _note("case-kernels", json.dumps({c: sorted(k) for c, k in sorted(BY_CASE.items())}))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
