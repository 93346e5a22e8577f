"""clvis.IsoRenderer (the progressive pass loop: macrocell traversal with
speculation, grouping, the LRU block cache, block raytracing, resolve)
against the dense NumPy reference clvis.reference.iso.render of the decoded
volume: the same hit mask and depths within 1e-4 of the volume diagonal on
the reference's reliable pixels, on every device and both work shapes,
with and without 64-bit atomics."""

import numpy as np
import pytest

import clvis
from clvis import Camera, datasets, iso, runtime, zfp
from clvis._arrays import to_device
from clvis.reference import iso as ref
from clvis.reference.iso import traverse as ref_traverse

W, H = 48, 40


def _cam(eye=(2.2, -2.6, 1.8), target=(0, 0, 0), **kw):
    return Camera.look_at(eye, target, (0, 0, 1), fov_y=40, aspect=W / H, near=0.05, far=20, **kw)


def _check(img, zv, cam, iso_value, spacing, origin, w=W, h=H):
    want = ref.render(zfp.decode(zv), cam, w, h, iso_value, spacing=spacing, origin=origin)
    a = ref.agreement(want, img.hit, img.depth)
    assert a["ok"], a
    both = img.hit & want.hit
    np.testing.assert_allclose(img.rgba[both], want.rgba[both], atol=2e-3)
    assert (img.rgba[~img.hit] == 0).all() and np.isinf(img.depth[~img.hit]).all()
    return want


_ML = datasets.marschner_lobb(41)
_TURB = datasets.turbulence(36)


@pytest.mark.parametrize("speculation", [False, True], ids=["no-spec", "spec"])
@pytest.mark.parametrize("name", ["marschner-lobb", "turbulence"])
def test_matches_reference(queue, name, speculation):
    d = _ML if name == "marschner-lobb" else _TURB
    zv = zfp.compress(d["volume"], 16)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    img = r.render(_cam(), W, H, 0.5, speculation=speculation)
    want = _check(img, zv, _cam(), 0.5, d["spacing"], d["origin"])
    assert want.hit.mean() > 0.2 and not img.active.any() and img.completion == 1.0
    st = img.stats
    assert st["passes"] == len(st["active_per_pass"]) >= 2
    assert st["blocks_decoded"] <= zv.nblocks and st["cache_slots"] >= 1


def test_speculation_cuts_passes(queue):
    d = _TURB
    zv = zfp.compress(d["volume"], 12)
    plain = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    a = plain.render(_cam(), W, H, 0.5, speculation=False)
    b = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue).render(
        _cam(), W, H, 0.5, speculation=True
    )
    assert b.stats["passes"] < a.stats["passes"]
    np.testing.assert_array_equal(a.hit, b.hit)
    np.testing.assert_array_equal(a.depth, b.depth)


def test_speculation_schedules_same_image(queue):
    """The cpu and gpu profiles' speculation schedules (render.PROFILES) give
    the same image bit for bit: the candidates do not depend on the passes."""
    import clvis.iso.render as render_mod

    d = _TURB
    zv = zfp.compress(d["volume"], 12)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    imgs = []
    for profile in ("gpu", "cpu"):
        p = render_mod.PROFILES[profile]
        r._spec = (p["spec_div"], p["spec_first"])
        r.reset_cache()
        img = r.render(_cam(), W, H, 0.5)
        st = img.stats
        assert st["n_spec_per_pass"] == [
            r._n_spec(W * H, 1, a, i) for i, a in enumerate(st["active_per_pass"])
        ]
        imgs.append(img)
    assert imgs[0].stats["n_spec_per_pass"] != imgs[1].stats["n_spec_per_pass"]
    assert imgs[0].hit.mean() > 0.2
    for name in ("hit", "depth", "t", "rgba"):
        np.testing.assert_array_equal(getattr(imgs[1], name), getattr(imgs[0], name))


@pytest.mark.parametrize("profile", ["cpu", "gpu"])
def test_n_spec_within_the_tile_budget(profile):
    """_n_spec: the pass's items stay within tile_plan's n x max(s, 2); the gpu
    profile's schedule is the paper's."""
    import clvis.iso.render as render_mod

    p = render_mod.PROFILES[profile]
    r = object.__new__(iso.IsoRenderer)
    r._spec = (p["spec_div"], p["spec_first"])
    for n in (1, 7, 100, 262144):
        for s in (1, 2, 3, 64):
            for n_active in {min(2, n), max(1, n // 3), max(1, n - 1), n}:
                for done in (0, 1):
                    k = r._n_spec(n, s, n_active, done)
                    assert 1 <= k <= render_mod.MAX_SPEC and n_active * k <= n * max(s, 2)
                    if profile == "gpu":
                        paper = min(64, max(1, n * s // n_active))
                        assert k == (max(paper, 2) if done == 0 else paper)


def test_without_int64_atomics_same_image(device):
    d = _ML
    zv = zfp.compress(d["volume"], 16)
    imgs = []
    for flag in (True, False):
        with runtime.configure(int64_atomics=flag):
            q = runtime.queue_for(device)
            r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=q)
            img = r.render(_cam(), W, H, 0.5, speculation=True)
            assert img.stats["int64_atomics"] == (flag and runtime.capabilities(q).int64_atomics)
            imgs.append(img)
    np.testing.assert_array_equal(imgs[0].hit, imgs[1].hit)
    np.testing.assert_array_equal(imgs[0].depth, imgs[1].depth)
    np.testing.assert_array_equal(imgs[0].rgba, imgs[1].rgba)


@pytest.mark.parametrize("flip", range(8))
def test_view_order_kernels_match_the_reference(queue, flip):
    """pass.cl's item_keys and group_info against clvis.reference.iso.traverse.view_key."""
    from clvis.reference.iso.traverse import view_key

    nb = (7, 5, 6)
    rng = np.random.default_rng(flip)
    blocks = rng.integers(0, 7 * 5 * 6, 300).astype(np.uint32)
    index = rng.permutation(300)[:257].astype(np.uint32)
    r = iso.IsoRenderer(np.zeros((24, 20, 28), np.float32), queue=queue)
    order = (*(np.uint32(v) for v in nb), np.uint32(flip))
    cb, ix = (to_device(queue, "test", a) for a in (blocks, index))
    keys = runtime.empty(queue, 257, np.uint32, "keys")
    r._launch("item_keys", 257, cb.base_data, ix.base_data, np.uint32(257), *order, keys.base_data)
    want = view_key(blocks[index], nb, flip)
    assert np.array_equal(keys.get(), want)
    sk = np.sort(want)
    starts = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1]]).astype(np.uint32)
    sk_d, st_d = (to_device(queue, "test", a) for a in (sk, starts))
    g = starts.size
    gb, gc = (runtime.empty(queue, g, np.uint32, "groups") for _ in range(2))
    args = (sk_d.base_data, st_d.base_data, np.uint32(g), np.uint32(257), *order, gb.base_data, gc.base_data)
    r._launch("group_info", g, *args)
    assert np.array_equal(gb.get(), view_key(sk[starts], nb, flip))
    assert np.array_equal(gc.get(), np.diff(np.r_[starts, 257]))


def test_group_order_does_not_change_the_image(queue, monkeypatch):
    """Every view order of the groups (pass.cl) gives the image bit for bit:
    with 64-bit atomics raytrace.cl skips the items behind a nearer hit, the
    more the nearer the order is to front to back; the winners are the same."""
    import clvis.iso.render as render_mod

    d = _TURB
    zv = zfp.compress(d["volume"], 12)
    cam = _cam()
    assert render_mod.view_flips(cam, zv.shape, d["spacing"], d["origin"]) == 0b101  # -x, +y, -z
    imgs = []
    for flip in range(8):
        monkeypatch.setattr(render_mod, "view_flips", lambda *a, f=flip: f)
        r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
        imgs.append(r.render(cam, W, H, 0.5, speculation=True, start_speculation=4))
    assert imgs[0].hit.mean() > 0.2
    for img in imgs[1:]:
        for name in ("hit", "depth", "t", "rgba"):
            np.testing.assert_array_equal(getattr(img, name), getattr(imgs[0], name))


@pytest.mark.parametrize("completion", [0.85, 0.9, 0.95])
def test_partial_completion(queue, completion):
    d = _TURB
    zv = zfp.compress(d["volume"], 12)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    full = r.render(_cam(), W, H, 0.5, speculation=False)
    part = r.render(_cam(), W, H, 0.5, speculation=False, completion=completion)
    assert part.completion >= completion
    assert part.stats["passes"] <= full.stats["passes"]
    # finished rays are final: a partial image agrees with the full one where it has hits
    np.testing.assert_array_equal(part.depth[part.hit], full.depth[part.hit])
    assert not (part.hit & part.active).any()


@pytest.mark.parametrize("host", [True, False], ids=["host", "device"])
def test_candidates_left_match_the_reference(queue, host):
    """IsoImage.candidates: without speculation a pass takes one candidate
    block per running ray, so after pass P a running ray has P of its
    candidates behind it; the plane is then min(all - P, CANDIDATES), all =
    the ray's candidate blocks (the reference traversal from its box entry),
    and 0 where the ray is not running. Over tiles too (the tiles not traced
    yet read 0). IsoImage.next_t: the t of that ray's next candidate, the
    reference's (P+1)-th (+inf where the ray is not running)."""
    d = _TURB
    zv = zfp.compress(d["volume"], 12)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    g = iso.macrocell_grids(zv, queue=queue)
    fine, coarse = g.fine, g.coarse
    buf = clvis.camera.ray_buffer(_cam(), W, H)
    rt, enters = ref_traverse.init_rays(buf, W, H, zv.shape, d["spacing"], d["origin"])
    ids = np.nonzero(enters)[0]
    blocks, block_t, after = ref_traverse.macro_traverse(
        zv.shape, d["spacing"], d["origin"], 0.5, buf, W, fine, coarse, ids, rt, iso.traverse.MAX_SPEC
    )
    assert np.isinf(after[ids]).all()  # every candidate listed
    total = np.zeros(W * H, np.int64)
    total[ids] = (blocks != ref_traverse.NO_BLOCK).sum(axis=1)
    row = np.full(W * H, -1, np.int64)
    row[ids] = np.arange(len(ids))
    tiles = 5 * W
    seen = 0
    for img in r.passes(_cam(), W, H, 0.5, speculation=False, tile_pixels=tiles, host=host):
        plain = _got(img) if not host else img
        got, got_t = plain.candidates.ravel(), plain.next_t.ravel()
        active = (img.active.get() if not host else img.active).ravel()
        assert got.dtype == np.uint8 and got_t.dtype == np.float32
        st = img.stats
        ti = max(i for i, n in enumerate(st["passes_per_tile"]) if n)
        want = np.zeros(W * H, np.int64)
        want_t = np.full(W * H, np.inf, np.float32)
        if st["passes_per_tile"][ti] and active[ti * tiles : (ti + 1) * tiles].any():
            sl = slice(ti * tiles, (ti + 1) * tiles)
            done = st["passes_per_tile"][ti]
            left = total[sl] - done
            want[sl] = np.where(active[sl], np.minimum(left, iso.CANDIDATES), 0)
            run = np.nonzero(active[sl])[0] + ti * tiles
            want_t[run] = block_t[row[run], done]
            seen += int(active[sl].sum())
        # the finished tiles and those not traced yet: 0 (the traced tile's running rays: >= 1)
        np.testing.assert_array_equal(got, want)
        np.testing.assert_allclose(got_t, want_t, rtol=1e-5)
    assert seen > 100 and (total > iso.CANDIDATES).any()


def test_passes_are_progressive(queue):
    d = _ML
    zv = zfp.compress(d["volume"], 16)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    prev = None
    for img in r.passes(_cam(), W, H, 0.5, speculation=False):
        if prev is not None:
            assert (img.hit >= prev.hit).all() and img.completion >= prev.completion
            assert img.active.sum() <= prev.active.sum()
        prev = img
    assert prev.completion == 1.0


def test_held_pass_images_keep_their_own_stats(queue):
    """Each image of passes() keeps the counts as of its pass: a held image's
    per-pass lists do not grow with the passes after it (the in-fill's
    crossing rate reads items_per_pass), and they equal a render stopped at
    that image's completion."""
    d = _ML
    zv = zfp.compress(d["volume"], 16)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    held = list(r.passes(_cam(), W, H, 0.5, speculation=False))
    assert len(held) >= 3
    for i, img in enumerate(held):
        assert img.stats["passes"] == i + 1
        for key in ("active_per_pass", "n_spec_per_pass", "items_per_pass", "passes_per_tile"):
            v = img.stats[key]
            assert len(v) == (1 if key == "passes_per_tile" else i + 1), key
            assert all(v is not other.stats[key] for other in held if other is not img), key
    again = r.render(_cam(), W, H, 0.5, completion=held[1].completion, speculation=False)
    assert again.stats["items_per_pass"] == held[1].stats["items_per_pass"]


def test_camera_inside_and_orthographic(queue):
    d = _TURB
    zv = zfp.compress(d["volume"], 16)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    inside = _cam(eye=(0.1, -0.2, 0.05), target=(1, 1, 0.3))
    _check(r.render(inside, W, H, 0.5), zv, inside, 0.5, d["spacing"], d["origin"])
    ortho = Camera.ortho((0, 0, 5), (0, 0, 0), (0, 1, 0), height=2.5, aspect=W / H, near=0.0, far=20)
    _check(r.render(ortho, W, H, 0.5), zv, ortho, 0.5, d["spacing"], d["origin"])


def test_small_cache_grows(queue):
    d = _ML
    zv = zfp.compress(d["volume"], 16)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], cache_capacity=4, queue=queue)
    img = r.render(_cam(), W, H, 0.5)
    _check(img, zv, _cam(), 0.5, d["spacing"], d["origin"])
    assert img.stats["cache_slots"] > 4


def test_nothing_to_hit(queue):
    d = _ML
    zv = zfp.compress(d["volume"], 8)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    img = r.render(_cam(), W, H, 7.0)  # outside the value range
    assert not img.hit.any() and img.stats["blocks_decoded"] == 0
    away = _cam(eye=(0, -6, 0), target=(0, -9, 0))
    img = r.render(away, W, H, 0.5)  # no ray meets the volume
    assert not img.hit.any() and img.stats["passes"] == 0 and img.stats["rays_entering"] == 0
    _same(_got(r.render(away, W, H, 0.5, host=False)), img)  # the empty image on the device


def test_dense_input_and_bad_arguments(queue):
    v = datasets.marschner_lobb(17)["volume"]
    r = iso.IsoRenderer(v, rate=16, queue=queue)
    assert r.volume.rate == 16
    with pytest.raises(TypeError, match="camera"):
        r.render("cam", W, H, 0.5)
    with pytest.raises(ValueError, match="completion"):
        r.render(_cam(), W, H, 0.5, completion=0)
    with pytest.raises(ValueError, match="isovalue"):
        r.render(_cam(), W, H, float("nan"))
    with pytest.raises(ValueError, match="width"):
        r.render(_cam(), 0, H, 0.5)
    with pytest.raises(clvis.DataError):
        iso.IsoRenderer(np.zeros((1, 8, 8), np.float32), queue=queue)
    with pytest.raises(ValueError, match="spacing"):
        iso.IsoRenderer(v, spacing=(1, 0, 1), queue=queue)


def test_a_volume_read_from_a_file_brings_its_spacing_and_origin(queue):
    """IsoRenderer(clvis.read_volume(path)): the Volume's data, spacing and
    origin (the same image as passing them), given ones win; zfp.compress
    takes its data; a path is refused, naming read_volume."""
    from clvis.io import Volume

    v = datasets.marschner_lobb(17)["volume"]
    vol = Volume(v, (0.5, 1.0, 2.0), (-3.0, 1.0, 0.25))
    cam = Camera.fit((-3, 1, 0.25), (29, 17, 8.25), aspect=W / H)
    got = iso.IsoRenderer(vol, rate=16, queue=queue)
    assert got.spacing == (0.5, 1.0, 2.0) and got.origin == (-3.0, 1.0, 0.25)
    want = iso.IsoRenderer(v, 16, (0.5, 1.0, 2.0), (-3.0, 1.0, 0.25), queue=queue)
    a, b = got.render(cam, W, H, 0.5), want.render(cam, W, H, 0.5)
    assert a.hit.sum() > 100
    np.testing.assert_array_equal(a.hit, b.hit)
    np.testing.assert_array_equal(a.rgba, b.rgba)
    assert iso.IsoRenderer(vol, spacing=(1, 1, 1), queue=queue).spacing == (1.0, 1.0, 1.0)
    assert bytes(zfp.compress(vol, 8).stream) == bytes(zfp.compress(v, 8).stream)
    with pytest.raises(TypeError, match="read_volume"):
        iso.IsoRenderer("scan.nii.gz", queue=queue)


def test_hits_lie_on_the_marching_cubes_mesh(queue):
    """The renderer's hit points (o + t d) against scikit-image's mesh of the decoded volume."""
    from meshes import mesh_distance as _mesh_distance
    from skimage.measure import marching_cubes

    from clvis.camera import ray_buffer
    from clvis.reference.camera import camera_rays

    d = datasets.marschner_lobb(64)
    zv = zfp.compress(d["volume"], 16)
    vol, sp, org = zfp.decode(zv), d["spacing"], d["origin"]
    w, h = 96, 80
    cam = Camera.look_at((2.2, -2.9, 2.0), (0, 0, 0), (0, 0, 1), fov_y=40, aspect=w / h, near=0.1, far=20)
    img = iso.IsoRenderer(zv, spacing=sp, origin=org, queue=queue).render(cam, w, h, 0.5)
    o, dd = camera_rays(ray_buffer(cam, w, h), w, h)
    hit = img.hit.ravel()
    pts = o[hit].astype(np.float64) + img.t.ravel()[hit, None] * dd[hit].astype(np.float64)
    verts, faces, _, _ = marching_cubes(vol, 0.5, spacing=sp)
    dist = _mesh_distance(pts, verts[:, ::-1] + np.asarray(org), faces) / sp[0]
    assert hit.sum() > 1000
    assert dist.mean() < 0.1 and dist.max() < 0.6, (dist.mean(), dist.max())


def test_empty_volume(queue):
    zv = zfp.compress(np.zeros((20, 24, 28), np.float32), 8)
    img = iso.IsoRenderer(zv, queue=queue).render(_cam(eye=(40, -30, 30), target=(14, 12, 10)), W, H, 0.5)
    assert not img.hit.any() and img.stats["blocks_decoded"] == 0 and img.completion == 1.0


@pytest.mark.parametrize("axis", [0, 2])
def test_surface_on_block_and_coarse_boundaries(queue, axis):
    """A plane exactly on sample 16: a ZFP block boundary and a coarse-cell boundary."""
    n = 33
    idx = np.arange(n, dtype=np.float32) - 16
    vol = np.broadcast_to(idx.reshape([-1 if a == axis else 1 for a in range(3)]), (n, n, n))
    zv = zfp.compress(np.ascontiguousarray(vol), 32)  # lossless enough for integers
    cam = Camera.look_at((45, -20, 38), (16, 16, 16), (0, 0, 1), fov_y=40, aspect=W / H, near=0.1, far=200)
    img = iso.IsoRenderer(zv, queue=queue).render(cam, W, H, 0.0)
    want = ref.render(zfp.decode(zv), cam, W, H, 0.0)
    np.testing.assert_array_equal(img.hit, want.hit)
    assert want.hit.mean() > 0.2
    np.testing.assert_allclose(img.depth[img.hit], want.depth[want.hit], rtol=0, atol=1e-4 * want.diagonal)


def _other(queue, int64):
    """Options unlike those in force: the other atomics path and work shape."""
    return {"int64_atomics": not int64, "tuning": "gpu" if runtime.tuning_profile(queue) == "cpu" else "cpu"}


def _assert_same(got, want):
    for name in ("rgba", "depth", "hit", "t", "active"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


@pytest.mark.parametrize("int64", [True, False], ids=["int64", "no-int64"])
def test_configure_between_passes(queue, int64):
    """A renderer keeps the options it was made with: configure() between the
    passes of passes() (once a 64-bit-atomics kernel given a NULL hit-key
    buffer, a crash) changes nothing in the image."""
    d = _ML
    zv = zfp.compress(d["volume"], 16)
    with runtime.configure(int64_atomics=int64):
        r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    want = r.render(_cam(), W, H, 0.5)
    stream = r.cache.stream
    r.reset_cache()
    # a cold cache over the same device stream (no re-upload of the volume)
    assert r.cache.stream is stream and r.cache.occupied == r.cache.decoded_total == 0
    images = []
    saved = runtime.options()
    try:
        for img in r.passes(_cam(), W, H, 0.5):
            images.append(img)
            runtime.set_options(**_other(queue, runtime.options().int64_atomics))
    finally:
        runtime.set_options(tuning=saved.tuning, int64_atomics=saved.int64_atomics)
    assert len(images) >= 2
    _assert_same(images[-1], want)
    assert images[-1].stats["int64_atomics"] == r.config.int64_atomics == want.stats["int64_atomics"]
    # and a renderer made now takes the options now in force
    with runtime.configure(**_other(queue, int64)) as o:
        r2 = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
        assert r2.config.tuning == o.tuning
        assert r2.config.int64_atomics == (
            o.int64_atomics and runtime.capabilities(queue).int64_atomics_native
        )
        _assert_same(r2.render(_cam(), W, H, 0.5), want)


def test_configure_from_another_thread(queue, options_flipping):
    """configure() from another thread during renders: the same image, no crash."""
    d = _ML
    zv = zfp.compress(d["volume"], 16)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    want = r.render(_cam(), W, H, 0.5)
    with options_flipping() as flips:
        for _ in range(3):
            r.reset_cache()
            _assert_same(r.render(_cam(), W, H, 0.5), want)
            *_, last = r.passes(_cam(), W, H, 0.5)
            _assert_same(last, want)
    assert flips[0] > 2


def test_stats_timings_and_bytes(queue):
    """seconds from event profiling; device bytes from the arrays held."""
    d = _ML
    zv = zfp.compress(d["volume"], 16)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"], queue=queue)
    st = r.render(_cam(), W, H, 0.5).stats
    assert st["seconds"] > 0
    dev = st["device_bytes"]
    assert dev["block cache"] == r.cache.nbytes and dev["compressed volume"] >= zv.nbytes
    assert dev["macrocell grids"] == r.grids.fine.nbytes + r.grids.coarse.nbytes
    assert dev["rays and image"] >= W * H * (4 + 1 + 4 + 4 + 16 + 4) and dev["pass items"] > 0


def _same(a, b):
    for name in ("rgba", "depth", "hit", "t", "active", "candidates", "next_t"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("tile_pixels", [W, 3 * W, 97], ids=["row", "rows", "part-rows"])
def test_tiles_give_the_untiled_image(queue, tile_pixels):
    """Rays are independent and each is computed from its image pixel, so a
    tiled render is the untiled one bit for bit: hits, t, depths, colours."""
    d = _ML
    r = iso.IsoRenderer(d["volume"], 8, d["spacing"], d["origin"], queue=queue)
    whole = r.render(_cam(), W, H, 0.5)
    assert whole.stats["tiles"] == 1
    tiled = r.render(_cam(), W, H, 0.5, tile_pixels=tile_pixels)
    assert tiled.stats["tiles"] == -(-W * H // tile_pixels) == len(tiled.stats["passes_per_tile"])
    assert sum(tiled.stats["passes_per_tile"]) == tiled.stats["passes"]
    assert tiled.stats["rays_entering"] == whole.stats["rays_entering"]
    _same(tiled, whole)
    assert tiled.completion == whole.completion == 1.0


def test_tiles_complete_each_tile(queue):
    """completion < 1 holds per tile: every tile (so the image) reaches it; a
    finished ray's pixel is the complete render's, a running ray has no hit."""
    d = _TURB
    r = iso.IsoRenderer(d["volume"], 8, d["spacing"], d["origin"], queue=queue)
    full = r.render(_cam(), W, H, 0.5, speculation=False)
    part = r.render(_cam(), W, H, 0.5, completion=0.6, speculation=False, tile_pixels=5 * W)
    st = part.stats
    assert st["tiles"] == 8 and all(f >= 0.6 for f in st["completion_per_tile"])
    assert 0.6 <= part.completion < 1.0 and part.active.any()
    done = ~part.active
    for name in ("rgba", "depth", "hit", "t"):
        np.testing.assert_array_equal(getattr(part, name)[done], getattr(full, name)[done], err_msg=name)
    assert not part.hit[part.active].any() and np.isinf(part.depth[part.active]).all()
    # the global fraction: rays finished over rays entering
    assert part.completion == pytest.approx(1 - part.active.sum() / st["rays_entering"])


def test_passes_and_progress_over_tiles(queue):
    d = _ML
    r = iso.IsoRenderer(d["volume"], 8, d["spacing"], d["origin"], queue=queue)
    seen = []
    images = list(r.passes(_cam(), W, H, 0.5, tile_pixels=10 * W, progress=seen.append))
    assert len(images) == len(seen) == images[-1].stats["passes"]
    assert [p["passes"] for p in seen] == list(range(1, len(seen) + 1))
    assert all(p["tiles"] == 4 for p in seen) and seen[-1]["tile"] == 4
    done = [p["rays_done"] for p in seen]
    assert done == sorted(done) and done[-1] == seen[-1]["rays_total"] == images[-1].stats["rays_entering"]
    fr = [im.completion for im in images]
    assert fr == sorted(fr) and fr[-1] == 1.0
    # tiles not started yet: no hits, their entering rays active
    first = images[0]
    assert not first.hit[10:].any() and first.active[10:].any()
    _same(images[-1], r.render(_cam(), W, H, 0.5))


@pytest.mark.parametrize(
    "kw",
    [{}, {"completion": 0.6, "speculation": False}, {"completion": 0.6, "tile_pixels": 97}],
    ids=["whole", "partial", "partial-tiles"],
)
def test_device_image_is_the_host_image(queue, kw):
    """host=False: the planes stay on the device (pass.cl's tile_image and
    mark_active write each tile into them) and equal the host image bit for
    bit, after every pass too; hit and active are bool, as on the host."""
    import pyopencl.array as cla

    d = _TURB
    r = iso.IsoRenderer(d["volume"], 8, d["spacing"], d["origin"], queue=queue)
    host = r.render(_cam(), W, H, 0.5, **kw)
    dev = r.render(_cam(), W, H, 0.5, host=False, **kw)
    assert dev.completion == host.completion and dev.stats["passes"] == host.stats["passes"]
    for name in ("rgba", "depth", "hit", "t", "active", "candidates", "next_t"):
        a = getattr(dev, name)
        assert isinstance(a, cla.Array) and a.dtype == getattr(host, name).dtype
    _same(_got(dev), host)
    if kw.get("completion", 1) < 1:
        assert host.active.any()
    passes = list(r.passes(_cam(), W, H, 0.5, host=False, **kw))
    want = list(r.passes(_cam(), W, H, 0.5, **kw))
    assert len(passes) == len(want) > 1
    for got, ref_image in zip(passes, want, strict=True):  # each a snapshot of its pass
        _same(_got(got), ref_image)


def _got(image):
    """A device IsoImage's planes read back."""
    planes = [getattr(image, k).get() for k in ("rgba", "depth", "hit", "t", "active")]
    return type(image)(*planes, 1.0, {}, image.candidates.get(), image.next_t.get())


def test_tile_plan_and_memory_check(queue, monkeypatch):
    r = iso.IsoRenderer(_ML["volume"], 8, queue=queue)
    t, nbytes = r.tile_plan(8192, 8192)
    assert t % 8192 == 0 and nbytes <= iso.render.TILE_BYTES
    assert r.tile_plan(8192, 8192, speculation=False)[0] > t
    assert r.tile_plan(100, 10, tile_pixels=7) == (
        7,
        7 * (iso.render.PIXEL_BYTES + 2 * iso.render.ITEM_BYTES),
    )
    with pytest.raises(ValueError, match="32-bit"):
        r.render(_cam(), 65536, 32768, 0.5)
    monkeypatch.setattr(runtime.memory, "host_available_bytes", lambda: 2 * 10**9)
    with pytest.raises(clvis.DeviceError, match="on the host") as e:
        r.render(_cam(), 46340, 46340, 0.5)  # just under 2^31 pixels: 56 GB of host image
    assert "on the device" in str(e.value)
    with pytest.raises(TypeError, match="tile_pixels"):
        r.render(_cam(), W, H, 0.5, tile_pixels=2.5)


def test_isovalue_must_be_a_number(queue):
    r = iso.IsoRenderer(_ML["volume"], 8, queue=queue)
    for bad in ("0.5", b"0.5", True, None):
        with pytest.raises(TypeError, match="isovalue"):
            r.render(_cam(), 4, 4, bad)
    with pytest.raises(TypeError, match="completion"):
        r.render(_cam(), 4, 4, 0.5, completion="1")
    assert r.render(_cam().with_aspect(1.0), 4, 4, np.float32(0.5)).hit.shape == (4, 4)


_MEMORY_CHILD = """
import resource, sys
import clvis
from clvis import Camera, datasets, iso
d = datasets.marschner_lobb(64)
r = iso.IsoRenderer(d["volume"], 8, d["spacing"], d["origin"])
lo = d["origin"]
cam = Camera.fit(lo, [o + 63 * s for o, s in zip(lo, d["spacing"][::-1])])
img = r.render(cam, 2048, 2048, 0.5, tile_pixels=2048 * 64)
assert img.completion == 1.0 and img.hit.any() and img.stats["tiles"] == 32
with open("/proc/self/status") as f:  # VmHWM: this process's own peak, in kB
    print(next(line.split()[1] for line in f if line.startswith("VmHWM:")))
"""


def test_large_render_stays_in_bounded_memory(tmp_path):
    """A 2048x2048 render in tiles of 64 rows: the child's peak resident set
    (PoCL's device memory is host memory) stays under 1 GB; about 0.35 GB
    measured, of which the host image is 0.11 GB."""
    import os
    import subprocess
    import sys

    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(
            [os.path.dirname(os.path.dirname(clvis.__file__)), os.environ.get("PYTHONPATH", "")]
        ),
    )
    # the child's own peak, VmHWM of its own address space: getrusage's
    # ru_maxrss is not it (RUSAGE_CHILDREN: the largest child's so far, which an
    # earlier child can set; the child's RUSAGE_SELF: Linux carries the spawning
    # process's peak across a vfork + exec, 11.7 GB in a whole-suite run)
    if not os.path.exists("/proc/self/status"):
        pytest.skip("needs Linux's /proc/self/status for the child's own peak resident set")
    out = subprocess.run(
        [sys.executable, "-c", _MEMORY_CHILD],
        check=True,
        env=env,
        timeout=600,
        capture_output=True,
        text=True,
    ).stdout
    peak_kb = int(out.split()[-1])
    assert 10_000 < peak_kb < 1_000_000, f"peak RSS {peak_kb / 1e6:.2f} GB"
