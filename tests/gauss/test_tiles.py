"""clvis.gauss.tiles (tiles.cl): the tile renderer gives the BVH renderer's
image and the brute force's, on every device and both work shapes.

Tolerances: against the BVH march (the same float32 hit tests, alphas and
compositing order) 1e-5 per channel: tile_render8 evaluates exp/erfc in
float8 lanes, whose last bit may differ from the scalar functions; tile_render
(the "gpu" profile) is bit for bit. Against the brute force (float64
exp/erfc and compositing) 1e-3, as tests/gauss/test_render.py."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import clvis
from clvis.camera import Camera, ray_buffer
from clvis.colormap import TransferFunction
from clvis.gauss import render as gr
from clvis.gauss import tiles as gt
from clvis.gauss.gaussians import Gaussians
from clvis.gauss.points import frames_along
from clvis.reference.gauss import tiles as ref_tiles

from .test_render import _cam, _check, _coloured, _random

W, H = 37, 29  # not multiples of the tiles


def _pair(queue, g, cam, w=W, h=H, tf=None, max_keys=None, kp=None, **kw):
    """tiles and bvh images of the same renderer settings; asserts they agree."""
    tf = tf or TransferFunction("jet")
    a = gr.GaussianRenderer(g, tf, method="tiles", kp=kp, queue=queue, **kw).render(
        cam, w, h, max_keys=max_keys
    )
    b = gr.GaussianRenderer(g, tf, method="bvh", queue=queue, **kw).render(cam, w, h)
    np.testing.assert_allclose(a.rgba, b.rgba, rtol=0, atol=1e-5)
    # the same Gaussians composited, and the same depth but where T ended within float noise of 0.5
    near_half = np.abs(b.rgba[..., 3] - 0.5) < 1e-4
    np.testing.assert_array_equal(a.hits, b.hits)
    np.testing.assert_array_equal(a.depth[~near_half], b.depth[~near_half])
    return a, b


@pytest.mark.parametrize("model", ["max_response", "absorption"])
@pytest.mark.parametrize("colored", [False, True], ids=["tf", "own"])
def test_same_image_as_bvh_and_brute_force(queue, model, colored):
    g = _random(300, seed=1)
    if colored:
        g = _coloured(g, seed=5)
    a, _ = _pair(queue, g, _cam(w=W, h=H), model=model)
    assert a.stats["method"] == "tiles" and a.stats["keys"] > 300
    assert (a.rgba[..., 3] > 0.05).mean() > 0.3  # the scene is seen
    img, _ = _check(queue, g, _cam(), model=model)  # the default method (tiles) against the brute force
    assert img.stats["method"] == gr.PROFILES[img_tuning(queue)]["method"]


def img_tuning(queue):
    return gr.GaussianRenderer(_random(1), queue=queue).config.tuning


@pytest.mark.parametrize("kp", [1, 2, 5, 64])
def test_pending_overflow_rounds(queue, kp):
    """Many Gaussians pending at once: a small buffer walks the list in rounds, same image."""
    n = 400
    rng = np.random.default_rng(2)
    means = np.stack([rng.normal(0, 0.3, n), rng.uniform(-2, 2, n), rng.normal(0, 0.3, n)], axis=1)
    g = Gaussians(means, np.full((n, 3), 0.4), values=rng.uniform(0, 1, n), opacities=np.full(n, 0.01))
    a, _ = _pair(queue, g, _cam(eye=(0, -8, 0), w=20, h=16), w=20, h=16, kp=kp)
    assert a.hits.max() > 100
    if kp < 5:
        assert a.rounds.max() > 1


@pytest.mark.parametrize("model", ["max_response", "absorption"])
def test_near_plane_and_eye_inside(queue, model):
    """Gaussians crossing the near plane, around the eye (every tile) and behind it."""
    around = _random(150, seed=4, spread=1.0)
    big = Gaussians([[0.0, 0.1, 0.0]], [[2.0, 1.5, 1.0]], values=[0.5], opacities=[0.3])
    side = Gaussians([[1.5, 0.05, 0.2]], [[0.3, 0.2, 0.3]], values=[0.2], opacities=[0.8])
    g = Gaussians.concatenate([around, big, side])
    cam = _cam(eye=(0.0, 0.0, 0.0), target=(0, 1, 0), near=0.1, w=W, h=H)
    a, _ = _pair(queue, g, cam, model=model)
    assert a.rgba[..., 3].min() > 0.1
    _check(queue, g, cam, w=W, h=H, model=model)


def test_huge_and_tiny(queue):
    """A Gaussian larger than the view, needles, flat discs and sub-pixel ones."""
    rng = np.random.default_rng(7)
    n = 120
    tiny = Gaussians(
        rng.normal(size=(n, 3)),
        rng.uniform(1e-4, 3e-3, (n, 3)),
        frames_along(rng.normal(size=(n, 3))),
        rng.uniform(0, 1, n),
        np.full(n, 0.9),
    )
    flat = Gaussians(
        rng.normal(size=(20, 3)),
        np.column_stack([rng.uniform(0.2, 0.6, 20), rng.uniform(0.2, 0.6, 20), np.full(20, 1e-6)]),
        frames_along(rng.normal(size=(20, 3))),
        rng.uniform(0, 1, 20),
        np.full(20, 0.5),
    )
    huge = Gaussians([[0.2, 1.0, -0.1]], [[30.0, 20.0, 40.0]], values=[0.7], opacities=[0.05])
    g = Gaussians.concatenate([tiny, flat, huge])
    for model in ("max_response", "absorption"):
        a, _ = _pair(queue, g, _cam(w=W, h=H), model=model)
        _check(queue, g, _cam(w=W, h=H), w=W, h=H, model=model)


def test_orthographic(queue):
    g = _random(200, seed=8)
    cam = Camera.ortho((0.2, -6, 0.5), (0, 0, 0), (0, 0, 1), height=5.0, aspect=W / H, near=0.5, far=20)
    _pair(queue, g, cam)
    _check(queue, g, cam, w=W, h=H)


@pytest.mark.parametrize("max_keys", [1, 50, 400])
def test_bands_bound_the_keys(queue, max_keys):
    """A key budget splits the frame into bands of tile rows: the same image."""
    g = _random(200, seed=9)
    cam = _cam(w=64, h=70)
    r = gr.GaussianRenderer(g, method="tiles", queue=queue)
    whole = r.render(cam, 64, 70)
    done = []
    banded = r.render(cam, 64, 70, max_keys=max_keys, progress=lambda a, b: done.append(a))
    np.testing.assert_array_equal(banded.rgba, whole.rgba)
    np.testing.assert_array_equal(banded.depth, whole.depth)
    assert banded.stats["key_bands"] > 1 and len(done) == banded.stats["bands"] and done[-1] == 64 * 70
    bands = gt.tile_lists(r, cam, 64, 70, max_keys=max_keys)
    assert len(bands) == banded.stats["key_bands"]
    for a, b, keys, _, _ in bands:
        assert len(keys) <= max_keys or b - a == 1


def test_device_output(queue):
    g = _random(100, seed=10)
    r = gr.GaussianRenderer(g, method="tiles", queue=queue)
    host = r.render(_cam(w=W, h=H), W, H)
    dev = r.render(_cam(w=W, h=H), W, H, host=False)
    np.testing.assert_array_equal(dev.rgba.get(), host.rgba)
    np.testing.assert_array_equal(dev.depth.get(), host.depth)
    np.testing.assert_array_equal(dev.stats["ray_stats"].get()[..., 0], host.hits)


def test_empty_and_one(queue):
    empty = Gaussians(np.zeros((0, 3)), np.zeros((0, 3)))
    img = gr.GaussianRenderer(empty, method="tiles", queue=queue).render(_cam(w=W, h=H), W, H)
    assert (img.rgba == 0).all() and np.isinf(img.depth).all() and img.stats["keys"] == 0
    one = Gaussians([[0, 0, 0]], [[0.5, 0.2, 0.8]], values=[1.0])
    _pair(queue, one, _cam(w=W, h=H))
    behind = Gaussians([[0, -9, 0]], [[0.3] * 3], values=[0.0])
    img = gr.GaussianRenderer(behind, method="tiles", queue=queue).render(
        _cam(eye=(0, -6, 0), w=W, h=H), W, H
    )
    assert (img.rgba == 0).all() and img.stats["keys"] == 0


def test_keys_hold_every_hit_and_bound_its_depth(queue):
    """Against the brute force's hits: every (tile, Gaussian) with a hit has a
    key, and the key's depth bound is at most the hit's depth; the ranges are
    the reference's; the footprint is tight (few keys without a hit)."""
    g = _random(150, seed=12, scale=(0.05, 0.4))
    w, h = 40, 33
    cam = _cam(w=w, h=h)
    r = gr.GaussianRenderer(g, method="tiles", queue=queue)
    ((a, b, keys, ids, ranges),) = gt.tile_lists(r, cam, w, h)
    ts = gt.PROFILES[r.config.tuning]["ts"]
    tiles_x, tiles_y = -(-w // ts), -(-h // ts)
    assert (a, b) == (0, tiles_y)
    np.testing.assert_array_equal(ranges, ref_tiles.ranges(keys, tiles_x * tiles_y))
    assert len(keys) > 100 and np.all(keys[1:] >= keys[:-1])
    tile = (keys >> np.uint64(32)).astype(np.int64)
    bound = {(int(t), int(i)): float(d) for t, i, d in zip(tile, ids, ref_tiles.key_depth(keys), strict=True)}
    assert len(bound) == len(keys)  # one key per (tile, Gaussian)
    hits = ref_tiles.hit_depths(g.means, g.scales, g.rotations, ray_buffer(cam, w, h), w, h, ts)
    assert len(hits) > 500
    for t, i, depth in hits:
        assert (t, i) in bound, f"tile {t} lacks Gaussian {i}"
        assert bound[(t, i)] <= depth, f"tile {t}, Gaussian {i}: bound {bound[(t, i)]} > hit depth {depth}"
    needed = {(t, i) for t, i, _ in hits}
    assert len(needed) / len(bound) > 0.5


def _needles(n, seed):
    """Thin Gaussians lying across the screen's diagonals (NARVis's
    velocity-elongated particles, exaggerated): their bounding rectangles
    hold many tiles that their ellipses miss."""
    rng = np.random.default_rng(seed)
    axes = np.column_stack([rng.choice([-1.0, 1.0], n), rng.normal(0, 0.1, n), np.ones(n)])
    scales = np.column_stack([rng.uniform(0.2, 0.5, n), rng.uniform(0.01, 0.03, (n, 2))])
    return Gaussians(
        rng.uniform(-1, 1, (n, 3)), scales, frames_along(axes), rng.uniform(0, 1, n), rng.uniform(0.3, 0.9, n)
    )


@pytest.mark.parametrize("model", ["max_response", "absorption"])
def test_needles_keep_only_the_tiles_their_ellipse_meets(queue, model):
    """Binning tests each projected ellipse against each tile row exactly
    (clvis_ellipse_row), not its bounding rectangle: every tile with a hit
    keeps the Gaussian, over 80 % of the kept (tile, Gaussian) pairs have a
    hit (93 % with 8-pixel tiles, 90 % with 16; their bounding rectangles
    would keep 1.3x / 1.7x as many: 72 % / 53 %), and the image is the BVH
    march's."""
    g = _needles(60, 21)
    w, h = 64, 48
    cam = _cam(w=w, h=h)
    r = gr.GaussianRenderer(g, method="tiles", model=model, queue=queue)
    ((_, _, keys, ids, _),) = gt.tile_lists(r, cam, w, h)
    ts = gt.PROFILES[r.config.tuning]["ts"]
    tile = (keys >> np.uint64(32)).astype(np.int64)
    kept = set(zip(tile.tolist(), ids.tolist(), strict=True))
    needed = ref_tiles.required_tiles(g.means, g.scales, g.rotations, ray_buffer(cam, w, h), w, h, ts)
    assert len(needed) > 50 and needed <= kept
    assert len(needed) / len(kept) > 0.8, (len(needed), len(kept))
    a, _ = _pair(queue, g, cam, w, h, model=model)
    assert (a.hits > 0).mean() > 0.1


def test_bad_input(queue):
    g = _random(10)
    with pytest.raises(ValueError, match="method: expected one of tiles, bvh"):
        gr.GaussianRenderer(g, method="raster", queue=queue)
    with pytest.raises(ValueError, match="kp: expected 1..64"):
        gr.GaussianRenderer(g, kp=0, queue=queue)
    with pytest.raises(TypeError, match="kp"):
        gr.GaussianRenderer(g, kp="4", queue=queue)
    r = gr.GaussianRenderer(g, method="tiles", queue=queue)
    with pytest.raises(ValueError, match="max_keys"):
        r.render(_cam(w=W, h=H), W, H, max_keys=0)
    with pytest.raises(ValueError, match="not 'tiles'"):
        gt.tile_lists(gr.GaussianRenderer(g, method="bvh", queue=queue), _cam(), W, H)


def test_impossible_size_is_a_device_error(queue, monkeypatch):
    from clvis import runtime

    r = gr.GaussianRenderer(_random(10), method="tiles", queue=queue)
    monkeypatch.setattr(runtime.memory, "host_available_bytes", lambda: 10**6)
    with pytest.raises(clvis.DeviceError, match=r"GB on the device and .* GB on the host"):
        r.render(_cam(w=4000, h=4000), 4000, 4000)


@settings(max_examples=15, deadline=None)
@given(
    n=st.integers(1, 60),
    seed=st.integers(0, 10_000),
    kp=st.sampled_from([1, 3, 16]),
    model=st.sampled_from(["max_response", "absorption"]),
)
def test_property(n, seed, kp, model):
    """Random scenes and views (the eye inside the cloud too): tiles == bvh."""
    rng = np.random.default_rng(seed)
    g = _random(n, seed=seed, spread=float(rng.uniform(0.3, 3)), scale=(0.02, 0.6))
    eye = rng.normal(size=3) * float(rng.uniform(0.5, 8))
    cam = _cam(eye=tuple(eye), target=tuple(rng.normal(size=3)), w=19, h=17)
    _pair(clvis.default_queue(), g, cam, w=19, h=17, kp=kp, model=model)


def test_cpu_profile_builds_without_compiler_chatter():
    """PoCL's clang printed "7 warnings generated." to the user's terminal
    for tile_render8's long8 helpers (-Wpsabi on an x86 target without
    AVX-512): tiles.cl with the cpu profile's defines builds with no warning
    in its log on every PoCL device."""
    import warnings

    import pyopencl as cl

    from clvis.runtime import program

    devices = [d for p in cl.get_platforms() if "portable" in p.name.lower() for d in p.get_devices()]
    if not devices:
        pytest.skip("no PoCL device")
    source = (program.KERNEL_ROOT / "gauss" / "tiles.cl").read_text()
    defines = {"TS": 8, "KP": 64, "MODEL": 0, "COLOR": 0, "KEYS8": 1}
    for d in devices:
        opts = program.build_options(d, defines, ())
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", cl.CompilerWarning)
            prg = cl.Program(cl.Context([d]), source).build(opts, cache_dir=False)  # a fresh log
        log = prg.get_build_info(d, cl.program_build_info.LOG)
        assert "warning" not in log.lower(), log[:2000]
