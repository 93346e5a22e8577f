"""clvis train's smoke run (a few steps on tiny frames, through the CLI) and
the training pairs' rules."""

import json
import shutil

import numpy as np
import pytest

pytest.importorskip("torch", reason="the train extra (torch==2.13.0) is part of the test venv")

from clvis import post  # noqa: E402
from clvis.cli import main  # noqa: E402
from clvis.reference.post import pack as ref_pack  # noqa: E402
from clvis.training import data, train  # noqa: E402


@pytest.mark.parametrize("name", post.NAMES)
def test_train_smoke_through_the_cli(tmp_path, name, capsys):
    rc = main(
        [
            "train",
            name,
            "--steps",
            "3",
            "--size",
            "64",
            "--frames",
            "1",
            "--frame-size",
            "96x64",
            "--out",
            str(tmp_path),
            "--quiet",
            "--eval",  # the held-out suite: tests/post/test_eval.py
            "none",
            "--cache",  # not the user's cache directory
            str(tmp_path / "cache"),
            *(["--points", "20000"] if name == "narvis" else []),
        ]
    )
    assert rc == 0
    out = capsys.readouterr().out
    # a table of the held-out rows, not the card's dicts of 16-digit floats
    assert "push-pull dB" in out and "vs push-pull" in out and "{'" not in out, out
    card = json.loads((tmp_path / f"{name}.json").read_text())
    assert card["training"]["steps"] == 3 and card["files"]["fp32"]["max_abs_vs_torch"] < 1e-4
    assert train.sha256(tmp_path / f"{name}.onnx") == card["files"]["fp32"]["sha256"]
    net = post.load(name, directory=tmp_path)  # the folder clvis train wrote loads as shipped ones do
    assert net.card["seed"] == 0
    # NARVis exports the split form the shipped card has: the graph to the
    # head's logits, the head applied by clvis.post.kpn (issue 28)
    assert (net.head is not None) == (name in ("narvis", "narvis-scan")) == ("head" in card)
    if name in ("narvis", "narvis-scan"):
        shipped = json.loads((post.MODELS / "narvis.json").read_text())["head"]
        assert card["head"].keys() == shipped.keys() and card["head"]["kind"] == "kpn"
    if name == "narvis-scan":  # its frames went through the cache; its targets are 3DGS splats
        assert card["data"]["target_model"] == "splat" and "isotropic" in card["data"]["target"]
        assert card["data"]["train"] == list(data.SCAN_TRAIN)
        assert len(list((tmp_path / "cache").glob("narvis-narvis-scan-*.npz"))) == 2  # train, held out
        assert card["data"]["scan_lines"] == json.loads(json.dumps(train.SPECS[name]["scan_lines"]))
        # its frames are filtered as its pipeline filters what it reads (clvis.post.specs)
        assert card["data"]["depth_filter"] == list(post.specs.spec(name).depth_filter)


def test_scan_scenes_are_deterministic_scans_without_velocity():
    """Each narvis-scan generator: finite points with colours, no velocity,
    the radius knn_sigma of the points (what the target's Gaussians use),
    the same cloud for the same seed and another for another seed."""
    from clvis.gauss.points import knn_sigma

    assert not set(data.SCAN_TRAIN) & set(data.SCAN_HELD_OUT)
    for kind in data.SCAN_KINDS:
        a, b = data.scan_scene(kind, 3000, 5), data.scan_scene(kind, 3000, 5)
        c = a.cloud
        assert c.velocity is None and c.colors.shape == (3000, 4) and np.isfinite(c.positions).all()
        np.testing.assert_array_equal(c.positions, b.cloud.positions)
        np.testing.assert_array_equal(c.radius, knn_sigma(c.positions, 4))
        assert (c.radius > 0).all() and len(np.unique(c.colors[:, :3], axis=0)) > 8, kind
        assert not np.array_equal(c.positions, data.scan_scene(kind, 3000, 6).cloud.positions)
    with pytest.raises(ValueError, match="scene"):
        data.scan_scene("hurricane", 3000, 5)


def test_scan_lines_are_anisotropic_and_seeded():
    """scan_line_sample keeps the points of a uniform cloud nearest parallel
    vertical planes: their phase across the planes bunches (a uniform subset's
    does not), the gap between lines is many times the spacing along them,
    and the same seed keeps the same points (another seed others)."""
    from scipy.spatial import cKDTree

    from clvis.post.names import SCAN_GBUFFER_PLANES

    u = np.random.default_rng(0).uniform(0, 1, (80_000, 2))
    pos = np.c_[u, np.zeros(len(u))]
    keep, info = data.scan_line_sample(pos, 10_000, np.random.default_rng(1), (6.0, 6.0))
    assert len(keep) == 10_000 and (np.diff(keep) > 0).all()
    np.testing.assert_allclose(info["spacing"], np.sqrt(np.log(2) / (np.pi * 10_000)), rtol=0.15)  # Poisson's
    np.testing.assert_allclose(info["gap"], 6 * info["spacing"])
    assert info["normal"][2] == 0 and abs(np.linalg.norm(info["normal"]) - 1) < 1e-12

    def bunching(p):  # the mean resultant of the points' phases across the planes
        return abs(np.exp(2j * np.pi * (p @ info["normal"]) / info["gap"]).mean())

    assert bunching(pos[keep]) > 0.9 and bunching(pos[:10_000]) < 0.05
    along = np.median(cKDTree(pos[keep]).query(pos[keep], k=2)[0][:, 1])
    assert info["gap"] > 4 * along
    again, _ = data.scan_line_sample(pos, 10_000, np.random.default_rng(1), (6.0, 6.0))
    other, _ = data.scan_line_sample(pos, 10_000, np.random.default_rng(2), (6.0, 6.0))
    np.testing.assert_array_equal(keep, again)
    assert not np.array_equal(keep, other)
    with pytest.raises(ValueError, match="scan lines"):
        data.scan_line_sample(pos, 100_000, np.random.default_rng(1), (6.0, 6.0))
    # a scene on scan lines: n of oversample x n generated points, by seed
    a, b = (data.scan_scene("town", 3000, 5, (2.0, 8.0, 8)) for _ in range(2))
    np.testing.assert_array_equal(a.cloud.positions, b.cloud.positions)
    assert len(a.cloud.positions) == 3000 and "scan lines" in a.source
    full = data.town(24_000, 5)["positions"]
    assert np.isin(a.cloud.positions[:, 0], full[:, 0]).all()
    # scan_frames: a share 1 puts every scene on scan lines, 0 none
    lines = {"share": 1.0, "gap": (2.0, 8.0), "oversample": 8}
    on, off = (
        data.scan_frames(
            ("town",), 1, 2, 64, 48, SCAN_GBUFFER_PLANES, views=1, densities=(1, 1), scan_lines=s
        )
        for s in (lines, {**lines, "share": 0.0})
    )
    assert "scan lines" in on[0].source and "scan lines" not in off[0].source


def test_scan_pairs_are_registered():
    """A narvis-scan pair: the packed G-buffers of the view (rgb, depth, the
    radius plane) and the splat of isotropic Gaussians of sigma knn_sigma and
    the points' colours, rendered from the same camera; the Gaussians' own
    render is the target, and it covers the raster's holes."""
    from clvis.gauss import GaussianRenderer, gaussians_from_points
    from clvis.post.names import SCAN_GBUFFER_PLANES

    f = data.scan_frames(("photo_town",), 1, 2, 64, 48, SCAN_GBUFFER_PLANES, views=1, densities=(1, 1))[0]
    assert f.x.shape == (6, 48, 64) and f.rgb.shape == (48, 64, 3)
    rng = np.random.default_rng(2)  # scan_frames' draws, replayed
    rng.uniform(0, 0)
    sc = data.scan_scene("photo_town", int(data.SCAN_POINTS_PER_PIXEL * 64 * 48), int(rng.integers(0, 2**31)))
    cam = data.scan_cameras(sc, rng, 1, 64 / 48)[0]
    g = gaussians_from_points(sc.cloud, opacity=data.SCAN_OPACITY, color_by="rgb")  # sigma: knn, clamped
    np.testing.assert_allclose(g.scales[:, 0], sc.cloud.radius, rtol=1e-6)
    gr = GaussianRenderer(g, model="splat", colors=True)
    np.testing.assert_array_equal(f.rgb, np.clip(np.asarray(gr.render(cam, 64, 48).rgba)[..., :3], 0, 1))
    cov = f.x[3] > 0
    assert 0.05 < cov.mean() < 0.95 and (f.x[5][cov] > 0).all() and not f.x[5][~cov].any()
    assert (f.rgb.sum(-1) > 0).mean() > cov.mean()  # the Gaussians fill between the points
    # depth_filter: the same view's G-buffers through filter_gbuffers, the target unchanged
    from clvis.raster import filter_gbuffers

    ff = data.scan_frames(
        ("photo_town",), 1, 2, 64, 48, SCAN_GBUFFER_PLANES, views=1, densities=(1, 1), depth_filter=(2, 1.0)
    )[0]
    np.testing.assert_array_equal(ff.rgb, f.rgb)
    want = filter_gbuffers(sc.gbuffers(sc.rasterizer(), cam, 64, 48, SCAN_GBUFFER_PLANES), 2, 1.0)
    assert want.stats["depth_filter_removed"] > 0
    np.testing.assert_array_equal(ff.x[3] > 0, np.asarray(want.covered))


def test_narvis_frames_are_rendered_once_per_key(tmp_path):
    """train.cached_frames: the frames come back from the cache equal (arrays,
    seconds, source) without rendering; another key, a missing cache or an
    unreadable cache file render again."""
    calls = []

    def make(seed=0):
        calls.append(seed)
        rng = np.random.default_rng(seed)
        return [
            data.NarvisFrame(
                rng.random((9, 16, 32), dtype=np.float32),
                rng.random((16, 32, 3), dtype=np.float32),
                {"raster": 0.1, "gaussians": 2.5},
                f"flow view {i}",
            )
            for i in range(3)
        ]

    key = {"set": "flows", "seed": 0, "size": [32, 16]}
    a = train.cached_frames(tmp_path, key, make)
    b = train.cached_frames(tmp_path, key, make)
    assert calls == [0] and len(b) == 3
    for f, g in zip(a, b, strict=True):
        np.testing.assert_array_equal(f.x, g.x)
        np.testing.assert_array_equal(f.rgb, g.rgb)
        assert f.x.dtype == g.x.dtype == np.float32
        assert (f.seconds, f.source) == (g.seconds, g.source)
    train.cached_frames(tmp_path, {**key, "seed": 1}, lambda: make(1))
    assert calls == [0, 1] and len(list(tmp_path.glob("narvis-flows-*.npz"))) == 2
    train.cached_frames(None, key, make)
    assert calls == [0, 1, 0]
    for f in tmp_path.glob("narvis-flows-*.npz"):
        f.write_bytes(b"not an npz")
    logged = []
    c = train.cached_frames(tmp_path, key, make, logged.append)
    assert calls == [0, 1, 0, 0] and "unreadable" in logged[0]
    np.testing.assert_array_equal(c[0].x, a[0].x)
    assert len(train.cached_frames(tmp_path, key, make)) == 3 and calls == [0, 1, 0, 0]  # replaced
    for f in tmp_path.glob("narvis-flows-*.npz"):  # cut short (a copy or disk that failed): a bad zip
        f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])
    train.cached_frames(tmp_path, key, make)
    assert calls == [0, 1, 0, 0, 0]
    blocked = tmp_path / "file"  # a cache "directory" that is a file: nothing written, the frames returned
    blocked.write_bytes(b"")
    logged.clear()
    assert len(train.cached_frames(blocked / "sub", key, make, logged.append)) == 3
    assert calls == [0, 1, 0, 0, 0, 0] and "not written" in logged[0]


def test_frame_cache_sources_exist_and_cover_the_renderers():
    """Every path train._FRAME_SOURCES hashes exists (one that does not would
    drop out of the cache key unnoticed), the kernels are read where the
    runtime builds them from, and the cameras and primitives the frames go
    through are among them."""
    from clvis import runtime

    package = train.Path(train.__file__).resolve().parents[1]
    for name in train._FRAME_SOURCES:
        top, _, rest = name.partition("/")
        assert (package if top == "clvis" else runtime.KERNEL_ROOT).joinpath(rest).exists(), name
    for must in ("clvis/camera.py", "clvis/primitives.py", "clvis/post/names.py", "kernels_cl/primitives"):
        assert must in train._FRAME_SOURCES
    assert train._sources_digest() == train._sources_digest()


def test_narvis_storm_frames_are_cached_per_looks(tmp_path, monkeypatch):
    """The storm's cameras are drawn after the hurricane's looks: a run with
    looks and one without pick different storm views, so they must not share
    a cache entry (rendering stubbed: each frame records its camera)."""
    rendered = []

    def frames(scene, cams, w, h, planes, *, looks=None, progress=None, target="max_response"):
        rendered.append((scene, tuple(cams)))
        return [
            data.NarvisFrame(np.full((1, 2, 2), c, np.float32), np.zeros((2, 2, 3), np.float32), {}, scene)
            for c in cams
        ]

    monkeypatch.setattr(data, "narvis_scene", lambda kind, n, seed: kind)
    monkeypatch.setattr(data, "narvis_cameras", lambda sc, sampler, aspect=1.0: list(range(128)))
    monkeypatch.setattr(
        data,
        "narvis_looks",
        lambda sc, count, rng: [("viridis", (0.0, float(rng.random()))) for _ in range(count)],
    )
    monkeypatch.setattr(data, "narvis_frames", frames)

    def storm(looks):
        sets = train._narvis_sets(4, 3, 100, 0, (8, 8), ("rgb",), None, looks=looks, cache=tmp_path)
        return [float(f.x[0, 0, 0]) for f in sets["storm"]]

    plain, looked = storm(False), storm(True)
    assert plain != looked  # other cameras ...
    assert [s for s, _ in rendered].count("storm") == 2  # ... each rendered, not read from the other's entry
    assert storm(True) == looked and [s for s, _ in rendered].count("storm") == 2  # then from the cache


def test_train_stops_at_its_time_limit(tmp_path):
    """--time-limit: the run stops short of its steps when the time is up;
    the card says how many it made, and the loss curve ends there."""
    lines = []
    card = train.train(
        "infill",
        steps=10**6,
        size=64,
        out=tmp_path,
        frames=1,
        frame_size=(96, 64),
        time_limit=2,
        log=lines.append,
    )
    t = card["training"]
    assert 1 <= t["steps"] < t["steps_asked"] == 10**6 and t["time_limit_seconds"] == 2
    assert t["loss_curve"][-1][0] == t["steps"] and t["seconds"] < 30
    assert any("time limit" in line for line in lines)


def test_train_leaves_torchs_threads_and_random_state_as_it_found_them(tmp_path):
    """clvis.training.train set torch's thread count (every core, or
    CLVIS_TRAIN_THREADS) and seeded torch's default generator for the rest
    of the process: a notebook's own torch work after it ran on other
    threads and drew other numbers."""
    torch = pytest.importorskip("torch")
    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        torch.manual_seed(1234)
        want = torch.rand(3)
        torch.manual_seed(1234)
        train.train(
            "infill", steps=1, size=64, out=tmp_path, frames=1, frame_size=(96, 64), log=lambda _: None
        )
        assert torch.get_num_threads() == 1
        assert torch.equal(torch.rand(3), want)
    finally:
        torch.set_num_threads(threads)


def test_train_rejects_crops_larger_than_frames(tmp_path, capsys):
    assert main(["train", "infill", "--size", "512", "--frame-size", "96x64", "--out", str(tmp_path)]) == 2
    assert "larger than the frames" in capsys.readouterr().err


@pytest.mark.parametrize("model, size", [("infill", 48), ("lidar", 40), ("narvis", 32)])
def test_train_rejects_crops_the_network_cannot_take(tmp_path, capsys, model, size):
    """A crop that is no multiple of the network's stride (or too small for
    MS-SSIM's five scales) is refused before any frame is rendered (it used
    to fail inside torch's forward pass)."""
    assert main(["train", model, "--size", str(size), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"--size {size}: {model}'s crops must be a multiple of" in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())


def test_train_narvis_with_the_splat_target(tmp_path, capsys, monkeypatch):
    """`clvis train narvis --target splat --planes ...,radius --init`: a few
    steps on frames whose targets the splatting model rendered, from the
    shipped model (which takes the radius plane); the card says so and repeats
    it. `clvis render --post narvis --compare` then runs that model on a
    cloud without a radius (it computes GR's sigma for the plane)."""
    from clvis.post import infer

    rc = main(
        [
            *("train", "narvis", "--steps", "2", "--size", "64", "--frames", "1", "--frame-size", "96x64"),
            *("--out", str(tmp_path), "--quiet", "--eval", "none", "--points", "20000", "--target", "splat"),
            *("--planes", "rgb,depth,vel2d,radius", "--init", str(post.MODELS / "narvis.onnx")),
            "--no-cache",  # not the user's cache directory
        ]
    )
    assert rc == 0
    card = json.loads((tmp_path / "narvis.json").read_text())
    assert card["data"]["target_model"] == "splat" and "splatting" in card["data"]["target"]
    assert "--target splat" in card["command"] and card["training"]["steps"] == 2
    assert card["architecture"]["planes"] == ["rgb", "depth", "vel2d", "radius"] and card["channels_in"] == 10
    assert (
        "--planes rgb,depth,vel2d,radius" in card["command"]
        and card["training"]["init"]["file"] == "narvis.onnx"
    )
    capsys.readouterr()
    monkeypatch.setattr(infer, "MODELS", tmp_path)
    out_dir = tmp_path / "render"
    args = ["render", "--points", "20000", "--post", "narvis", "--compare", "--size", "96x64", "--quiet"]
    assert main([*args, "--out", str(out_dir)]) == 0
    assert "against the Gaussian renderer" in capsys.readouterr().out
    assert (out_dir / "post-narvis.png").is_file()
    assert main(["train", "narvis", "--planes", "depth,vel2d", "--out", str(tmp_path)]) == 2
    assert "lacks 'rgb'" in capsys.readouterr().err
    # was "depth_select: needs the 'depth' plane in planes", not naming the option
    assert main(["train", "narvis", "--planes", "rgb,vel2d", "--out", str(tmp_path)]) == 2
    assert "--planes rgb,vel2d: depth_select: needs the 'depth' plane" in capsys.readouterr().err


def test_train_target_is_narvis_only_and_checked(tmp_path, capsys):
    from clvis.cli import train as train_cli

    assert main(["train", "infill", "--target", "splat", "--out", str(tmp_path)]) == 2
    assert "narvis only" in capsys.readouterr().err
    assert main(["train", "narvis", "--target", "bvh", "--out", str(tmp_path)]) == 2
    with pytest.raises(ValueError, match="target"):
        train.train("narvis", steps=1, size=64, out=tmp_path, target="absorption")
    # the CLI's choices are the training's
    p = train_cli.add_parser(__import__("argparse").ArgumentParser().add_subparsers())
    assert next(a for a in p._actions if a.dest == "target").choices == data.NARVIS_TARGETS


def test_narvis_targets_render_with_the_chosen_model():
    """target="splat" renders the frames' targets with GaussianRenderer's
    splat model (the same image as rendering it directly), which differs
    from the default max-response image of the same view."""
    sc = data.narvis_scene("hurricane", 20_000, 3)
    cam = data.narvis_cameras(sc, "hemisphere", 48 / 40)[3]
    planes = ("rgb", "depth", "vel2d")
    mr = data.narvis_frames(sc, [cam], 48, 40, planes)[0]
    sp = data.narvis_frames(sc, [cam], 48, 40, planes, target="splat")[0]
    np.testing.assert_array_equal(mr.x, sp.x)  # the same G-buffers
    gr = sc.gaussian_renderer(model="splat")
    assert gr.model == "splat"
    want = np.clip(np.asarray(gr.render(cam, 48, 40).rgba)[..., :3], 0, 1)
    np.testing.assert_array_equal(sp.rgb, want)
    assert sp.rgb.sum() > 0 and np.abs(sp.rgb - mr.rgb).max() > 0.05
    with pytest.raises(ValueError, match="target"):
        sc.gaussian_renderer(model="absorption")


def test_iso_frames_are_deterministic_and_consistent():
    a = data.iso_frames(("waves",), 1, 3, 64, 48, views=1, n=24)[0]
    b = data.iso_frames(("waves",), 1, 3, 64, 48, views=1, n=24)[0]
    np.testing.assert_array_equal(a.rgb, b.rgb)
    for c in data.COMPLETIONS:
        np.testing.assert_array_equal(a.active[c], b.active[c])
        rgba, hit, active = a.planes(c)
        assert not (hit & active).any() and (rgba[active] == 0).all()
        # the candidate blocks left: 1..8 on each running ray, 0 elsewhere (the pairs' sixth plane)
        left = a.candidates_at(c)
        np.testing.assert_array_equal(left, b.candidates_at(c))
        assert left.dtype == np.uint8 and (left[~active] == 0).all() and (left[active] >= 1).all()
        assert left.max() <= 8
        x, _ = train._pack("infill", a, c)
        np.testing.assert_array_equal(x[5], np.minimum(left, 8) / np.float32(8))
        # the depth planes: the hits' t, where each running ray's next candidate block begins
        nxt = a.next_t[c]
        np.testing.assert_array_equal(nxt, b.next_t[c])
        assert np.isfinite(nxt[active]).all() and np.isinf(nxt[~active]).all()
        assert (nxt[active & a.hit] <= a.t[active & a.hit]).all()  # a block before the hit in it
        np.testing.assert_array_equal(
            x[6:], ref_pack.pack_iso(rgba, hit, active, candidates=left, depth=(a.t, nxt))[0, 6:]
        )
        assert x.shape[0] == 8 and train._pack("infill", a, c, channels=5)[0].shape[0] == 5
        # the hit prior (a 7-plane W-Net): the frame's finished hits per candidate block its render tested
        assert a.tested[c] == b.tested[c] > 0
        rate = a.crossing_rate(c)
        assert 0 < rate <= 1 and rate == (hit & ~active).sum() / a.tested[c]
        x7, _ = train._pack("infill", a, c, channels=7)
        np.testing.assert_array_equal(
            x7[6], ref_pack.pack_iso(rgba, hit, active, candidates=left, crossing_rate=rate)[0, 6]
        )
    assert a.active[0.85].any() and (a.candidates_at(0.85) > 1).any()
    # fewer rays run at higher completion
    assert a.active[0.85].sum() >= a.active[0.9].sum() >= a.active[0.95].sum()


def test_training_frames_crossing_rate_is_the_renders():
    """The hit prior a training frame packs is the one the network gets at
    run time: a frame's crossing rate at each completion equals that of the
    same view rendered by IsoRenderer.render(completion=c), read from the
    image (clvis.post.specs.image_crossing_rate); the frame's draws redone."""
    from clvis.iso import IsoRenderer
    from clvis.post.specs import image_crossing_rate

    f = data.iso_frames(("waves",), 1, 3, 64, 48, views=1, n=24)[0]
    rng = np.random.default_rng(3)
    vol, iso = data.procedural_volume("waves", rng, 24)
    step = 2.0 / 23
    r = IsoRenderer(vol, rate=8, spacing=(step, step, step), origin=(-1.0, -1.0, -1.0))
    cam = data.orbit_camera(rng, (-1, -1, -1), (1, 1, 1), 64 / 48, (0.45, 0.95))
    for c in data.COMPLETIONS:
        img = r.render(cam, 64, 48, iso, completion=c, speculation=False)
        np.testing.assert_array_equal(img.active, f.active[c])
        assert image_crossing_rate(img) == f.crossing_rate(c) > 0


@pytest.mark.parametrize("kind", data.MORE_TRAIN_VOLUMES)
def test_more_training_volumes_are_finite_and_deterministic(kind):
    """issue 21's added training families: never a family of the held-out suite."""
    assert kind not in data.HELD_OUT_VOLUMES + data.EVAL_VOLUMES + data.TRAIN_VOLUMES
    for n in (24, 40):
        v, iso = data.procedural_volume(kind, np.random.default_rng(5), n)
        assert v.shape == (n, n, n) and v.dtype == np.float32 and np.isfinite(v).all()
        # a surface of some extent, not a speck: 0.5-95 % of the samples inside
        assert v.min() < iso < v.max() and 0.005 < (v > iso).mean() < 0.95
        w, iso_w = data.procedural_volume(kind, np.random.default_rng(5), n)
        np.testing.assert_array_equal(v, w)
        assert iso == iso_w
        other, _ = data.procedural_volume(kind, np.random.default_rng(6), n)
        assert not np.array_equal(v, other)


def test_iso_frames_vary_what_the_network_must_not_learn():
    """The training's variety (data.IsoVariety): volume sides, frame sizes
    (never under `smallest`), speculation and surface colours drawn per
    volume / view, pairs at TRAIN_COMPLETIONS; deterministic by seed."""
    vary = data.IsoVariety(sides=(20, 28), scales=(1.0, 0.5), smallest=40, speculation=0.5, colors=1.0)

    def make(seed):
        return data.iso_frames(
            ("csg", "labels"), 4, seed, 96, 64, views=1, vary=vary, completions=data.TRAIN_COMPLETIONS
        )

    a, b = make(7), make(7)
    sizes = set()
    for f, g in zip(a, b, strict=True):
        np.testing.assert_array_equal(f.rgb, g.rgb)
        assert f.source == g.source and "colour" in f.source
        assert tuple(f.active) == data.TRAIN_COMPLETIONS
        assert f.active[0.8].sum() >= f.active[0.9].sum() >= f.active[0.97].sum()
        sizes.add(f.rgb.shape[:2])
        # the surface in a colour of its own, not the renderer's (0.9, 0.75, 0.4):
        # the hits' mean red / green ratio is not the renderer's
        hit = f.hit & (f.rgb.max(-1) < 0.95)  # off the white highlight
        if hit.sum() > 20:
            r, g_ = f.rgb[hit, 0].mean(), f.rgb[hit, 1].mean()
            assert abs(r / max(g_, 1e-6) - 0.9 / 0.75) > 0.02
    assert sizes <= {(64, 96), (40, 48)} and len(sizes) == 2
    assert [f.source for f in make(8)] != [f.source for f in a]


def test_acquisition_noise_is_smoothed_scaled_and_seeded():
    """IsoVariety.noisy: with probability `noise`, smoothed white noise of
    `noise_amp` x the volume's standard deviation; none (and no draw) at 0,
    so the frames drawn without it stay as they were."""
    vol, _ = data.procedural_volume("blobs", np.random.default_rng(3), 32)
    vary = data.IsoVariety(noise=1.0, noise_amp=(0.1, 0.1), noise_sigma=(1.0, 1.0))
    a, amp = vary.noisy(vol, np.random.default_rng(9))
    b, _ = vary.noisy(vol, np.random.default_rng(9))
    np.testing.assert_array_equal(a, b)
    assert amp == pytest.approx(0.1) and a.dtype == np.float32
    d = a.astype(np.float64) - vol
    assert d.std() == pytest.approx(0.1 * vol.std(), rel=1e-3)
    # smoothed: neighbouring voxels' noise is correlated (white noise's is not)
    assert np.corrcoef(d[:, :, 1:].ravel(), d[:, :, :-1].ravel())[0, 1] > 0.5
    assert abs(np.corrcoef(d[:, :, 0].ravel(), d[:, :, 16].ravel())[0, 1]) < 0.2  # but not far ones
    rng = np.random.default_rng(4)
    same, zero = data.IsoVariety().noisy(vol, rng)
    assert same is vol and zero == 0.0
    assert rng.random() == np.random.default_rng(4).random()  # nothing drawn
    # with probability 0.5, some volumes get noise and some do not
    half = data.IsoVariety(noise=0.5)
    got = [half.noisy(vol, np.random.default_rng(s))[1] > 0 for s in range(40)]
    assert 5 < sum(got) < 35


def test_procedural_texture_has_a_photographs_statistics():
    """data.procedural_texture: seeded, 0..255 RGB, its luminance spectrum
    falling with frequency as a photograph's (power ~ 1/f^2, not white),
    coloured (not grey); texture_town drapes it over a town."""
    a = data.procedural_texture(np.random.default_rng(1), 128)
    np.testing.assert_array_equal(a, data.procedural_texture(np.random.default_rng(1), 128))
    assert not np.array_equal(a, data.procedural_texture(np.random.default_rng(2), 128))
    assert a.shape == (128, 128, 3) and a.min() >= 0 and a.max() <= 255
    p = np.abs(np.fft.fft2(a.mean(-1) - a.mean())) ** 2
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(128), np.fft.fftfreq(128)))
    low, high = p[(f > 0.02) & (f < 0.05)].mean(), p[(f > 0.3) & (f < 0.45)].mean()
    assert low > 30 * high
    assert np.abs(a - a.mean(-1, keepdims=True)).mean() > 5  # not grey
    t = data.texture_town(20_000, 4)
    plain = data.town(20_000, 4)
    np.testing.assert_array_equal(t["positions"], plain["positions"])
    assert not np.array_equal(t["colors"], plain["colors"])


def test_lidar_pairs_are_registered():
    f = data.lidar_frames(("town",), 1, 4, 80, 60, views=1, dense_points=60_000)[0]
    kept = f.rgbda[..., 4] > 0
    assert kept.any()
    # a kept scan point is a point of the dense cloud: the dense render
    # covers its pixel
    assert (f.rgb[kept].sum(-1) > 0).mean() > 0.95


@pytest.mark.parametrize("kind", data.VOLUME_KINDS)
def test_procedural_volumes_have_a_surface(kind):
    v, iso = data.procedural_volume(kind, np.random.default_rng(0), 16)
    assert v.shape == (16, 16, 16) and v.dtype == np.float32 and v.min() < iso < v.max()


def test_narvis_pairs_are_registered():
    """The G-buffers and the Gaussian renderer's image of one view: the same
    camera, so the image is bright where points were drawn and black far
    from any; the storm is the hurricane's flow at another time."""
    sc = data.narvis_scene("hurricane", 30_000, 2)
    cams = data.narvis_cameras(sc, "hemisphere", 80 / 60)
    assert len(cams) == 128
    f = data.narvis_frames(sc, cams[10:11], 80, 60, ("rgb", "depth", "vel2d"))[0]
    assert f.x.shape == (9, 60, 80) and f.rgb.shape == (60, 80, 3)
    cov = f.x[3] > 0
    lum = f.rgb.sum(2)
    assert lum[cov].mean() > 5 * max(lum[~cov].mean(), 1e-3)
    assert 0.02 < cov.mean() < 0.9 and f.seconds["gaussians"] > 0
    grid = data.narvis_cameras(sc, "grid")
    assert 0 < len(grid) < 96
    storm = data.narvis_scene("storm", 30_000, 2)
    hur = sc.cloud
    # the same particles' radii and heights, turned about the axis by the flow
    np.testing.assert_allclose(
        np.hypot(*storm.cloud.positions[:, :2].T), np.hypot(*hur.positions[:, :2].T), rtol=1e-5
    )
    np.testing.assert_array_equal(storm.cloud.positions[:, 2], hur.positions[:, 2])
    assert not np.allclose(storm.cloud.positions[:, :2], hur.positions[:, :2], atol=1.0)


def test_narvis_augmentation_mirrors_the_velocity_where_the_layout_has_it():
    """Flips mirror v'x (left-right) and v'y (up-down) at their channels in
    the input's layout, whatever planes precede them (here no depth)."""
    import torch

    from clvis.post.names import gbuffer_channels

    layout = gbuffer_channels(("rgb", "vel2d"))
    vx = layout.index("vel_x")
    g = torch.Generator().manual_seed(0)
    x = torch.rand(1, len(layout), 8, 12, generator=g)
    x[:, 3] = 1.0  # every pixel covered
    y = torch.rand(1, 3, 8, 12, generator=g)
    seen = set()
    for seed in range(16):
        xo, yo = train._augment(x, y, np.random.default_rng(seed), "narvis", layout)
        for dims in ((), (3,), (2,), (2, 3)):
            if torch.equal(yo, torch.flip(y, dims) if dims else y):
                break
        else:
            raise AssertionError("the target was not flipped as a whole")
        seen.add(dims)
        xf = torch.flip(x, dims) if dims else x
        sx = -1.0 if 3 in dims else 1.0
        sy = -1.0 if 2 in dims else 1.0
        torch.testing.assert_close(xo[:, vx], sx * xf[:, vx])
        torch.testing.assert_close(xo[:, vx + 1], sy * xf[:, vx + 1])
        torch.testing.assert_close(xo[:, :3], xf[:, :3])
    assert len(seen) == 4


def test_narvis_looks_colour_both_renders_alike():
    """A random look (colormap, value range) colours the G-buffers and the
    Gaussian renderer's target the same way: both differ from the scene's
    default look, and magma (clvis eval's unseen colormap) is never drawn."""
    sc = data.narvis_scene("hurricane", 20_000, 3)
    looks = data.narvis_looks(sc, 40, np.random.default_rng(1))
    assert not any(c.startswith("magma") for c, _ in looks)
    assert len({c for c, _ in looks}) > 5
    lo, hi = sc.value_range
    for _, (a, b) in looks:
        assert lo - 0.21 * (hi - lo) <= a < b <= hi + 0.21 * (hi - lo)
    cam = data.narvis_cameras(sc, "hemisphere")[3]
    look = [("coolwarm", (lo, hi))]
    base = data.narvis_frames(sc, [cam], 48, 48, ("rgb", "depth", "vel2d"))[0]
    new = data.narvis_frames(sc, [cam], 48, 48, ("rgb", "depth", "vel2d"), looks=look)[0]
    covered = base.x[3] > 0
    assert covered.any()
    np.testing.assert_array_equal(base.x[3], new.x[3])  # the same points drawn
    assert np.abs(base.x[:3] - new.x[:3])[:, covered].mean() > 0.05  # other colours in...
    assert np.abs(base.rgb - new.rgb).mean() > 0.01  # ... and in the target
    with pytest.raises(ValueError, match="looks"):
        data.narvis_frames(sc, [cam], 48, 48, ("rgb",), looks=look * 2)


def test_narvis_flow_frames_vary_what_the_network_must_not_learn():
    """The training flows' frames: every flow of TRAIN_FLOWS, colormaps
    drawn from the training's (never magma), densities spread over the
    asked range, deterministic from the seed."""
    from clvis.training import flows

    a = train.narvis_flow_frames(1, 2, [48], [0.25, 4.0], 20_000, 3, 64, ("rgb", "depth", "vel2d"))
    b = train.narvis_flow_frames(1, 2, [48], [0.25, 4.0], 20_000, 3, 64, ("rgb", "depth", "vel2d"))
    assert len(a) == 2 * len(flows.TRAIN_FLOWS)
    kinds = {f.source.split(" ", 1)[0] for f in a}
    assert kinds == set(flows.TRAIN_FLOWS)
    for f, g in zip(a, b, strict=True):
        assert f.x.shape == (9, 48, 48) and f.rgb.shape == (48, 48, 3)
        np.testing.assert_array_equal(f.x, g.x)
    assert sum((f.x[3] > 0).any() for f in a) >= len(a) - 2
    # the particles a pixel of each scene: log-uniform over 16x
    dens = sorted({float(f.source.rsplit(", ", 1)[1].split("x")[0]) for f in a})
    assert len(dens) == len(flows.TRAIN_FLOWS) and 0.25 <= dens[0] and dens[-1] <= 4.0
    assert dens[-1] / dens[0] > 2
    # the colours differ between views of one scene (random looks)
    assert any(not np.array_equal(a[i].x[:3], a[i + 1].x[:3]) for i in range(0, len(a), 2))


def test_narvis_flow_frames_take_scenes_per_flow():
    """flow_scenes as {flow: scenes} (1 for a flow not named): the last
    flow's extra scenes come after the frames one scene of each gives,
    which stay as they were; a name that is no training flow is refused."""
    from clvis.training import flows

    planes = ("rgb", "depth", "vel2d")
    assert flows.TRAIN_FLOWS[-1] == "attractors"
    one = train.narvis_flow_frames(1, 1, [32], [0.25, 4.0], 20_000, 5, 32, planes)
    more = train.narvis_flow_frames({"attractors": 3}, 1, [32], [0.25, 4.0], 20_000, 5, 32, planes)
    assert len(more) == len(one) + 2
    assert [f.source.split(" ", 1)[0] for f in more[len(one) - 1 :]] == ["attractors"] * 3
    for f, g in zip(one, more, strict=False):
        assert f.source == g.source
        np.testing.assert_array_equal(f.x, g.x)
        np.testing.assert_array_equal(f.rgb, g.rgb)
    # the extra scenes are other scenes (other particles), not the first again
    assert not np.array_equal(more[-1].x, more[-3].x)
    with pytest.raises(ValueError, match="lorenz"):
        train.narvis_flow_frames({"lorenz": 2}, 1, [32], [0.25, 4.0], 20_000, 5, 32, planes)


def _broken_write(path_arg):
    """A writer that leaves part of a file at the path it is given, then fails."""

    def write(*args, **kwargs):
        from pathlib import Path

        Path(str(args[path_arg])).write_bytes(b"partial")
        raise RuntimeError("the writer failed")

    return write


def test_exports_and_cards_replace_their_files_atomically(tmp_path, monkeypatch):
    """clvis train's .onnx files (fp32, fp16, int8) and card, and clvis eval's
    --write-card: a failed overwrite keeps the previous file and leaves no
    temporary one (a full disk names the card)."""
    import errno
    import os

    import onnx
    import onnxruntime.quantization
    import torch

    import clvis.io.files as files
    from clvis.post.infer import MODELS
    from clvis.training import evaluate

    class Net(torch.nn.Module):
        channels_in, stride = 2, 4

        def __init__(self):
            super().__init__()
            self.conv = torch.nn.Conv2d(2, 3, 1)

        def forward(self, x):
            return self.conv(x)

    fp32, fp16, int8 = (tmp_path / f"n{s}.onnx" for s in ("", ".fp16", ".int8"))
    train.export_onnx(Net(), fp32)
    train._to_fp16(fp32, fp16)
    calibration = [np.random.default_rng(i).random((1, 2, 8, 8), np.float32) for i in range(2)]
    train._to_int8(fp32, int8, calibration)
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["n.fp16.onnx", "n.int8.onnx", "n.onnx"]
    before = {p: p.read_bytes() for p in (fp32, fp16, int8)}
    for p in before:  # graphs onnxruntime loads
        assert train._session(p).get_inputs()[0].name == "planes"
    with monkeypatch.context() as m:
        m.setattr(torch.onnx, "export", _broken_write(2))
        with pytest.raises(RuntimeError, match="the writer failed"):
            train.export_onnx(Net(), fp32)
        m.setattr(onnx, "save", _broken_write(1))
        with pytest.raises(RuntimeError, match="the writer failed"):
            train._to_fp16(fp32, fp16)
        m.setattr(onnxruntime.quantization, "quantize_static", _broken_write(1))
        with pytest.raises(RuntimeError, match="the writer failed"):
            train._to_int8(fp32, int8, calibration)
    assert {p: p.read_bytes() for p in before} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == names  # no .tmp, no .pre.onnx

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    card = tmp_path / "n.json"
    train.write_card(card, {"a": 1})
    for p in MODELS.glob("lidar.json"):
        (tmp_path / p.name).write_bytes(p.read_bytes())
    shipped = (tmp_path / "lidar.json").read_bytes()
    result = {"model": "lidar", "quick": True, "seconds": 1.0, "rows": []}
    with monkeypatch.context() as m:
        m.setattr(files.os, "fsync", full)
        with pytest.raises(OSError, match="n.json") as info:
            train.write_card(card, {"a": 2})
        assert info.value.errno == errno.ENOSPC
        with pytest.raises(OSError, match="lidar.json"):
            evaluate.write_card(result, tmp_path)
    assert json.loads(card.read_text()) == {"a": 1}
    assert (tmp_path / "lidar.json").read_bytes() == shipped
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*names, "n.json", "lidar.json"])
    assert evaluate.write_card(result, tmp_path) == tmp_path / "lidar.json"
    assert json.loads((tmp_path / "lidar.json").read_text())["held_out_suite"]["rows"] == []


def test_batch_mixes_its_extra_pairs_at_their_share():
    """_batch's extra pairs: each crop from them with probability `share`;
    without them the draws are the release run's (no draw more)."""
    main_pairs = [(np.zeros((1, 8, 8), np.float16), np.zeros((1, 8, 8), np.float16))]
    extra = [(np.ones((1, 8, 8), np.float16), np.ones((1, 8, 8), np.float16))]
    share = [
        float(train._batch(main_pairs, 400, 4, np.random.default_rng(1), extra, s)[0].mean())
        for s in (0.0, 0.3, 1.0)
    ]
    assert share[0] == 0.0 and share[2] == 1.0 and 0.22 < share[1] < 0.38, share
    rng_a, rng_b = np.random.default_rng(2), np.random.default_rng(2)
    train._batch(main_pairs * 3, 5, 4, rng_a)
    for _ in range(5):  # the draws of the code before --mix: a pair, then its crop's corner
        rng_b.integers(0, 3), rng_b.integers(0, 5), rng_b.integers(0, 5)
    assert rng_a.random() == rng_b.random()


def test_init_loads_an_onnx_export_of_the_same_network(tmp_path):
    """--init: the shipped in-fill ONNX's weights start the run (torch then
    computes what onnxruntime computes on the file); another network's file
    is refused."""
    import torch

    net = train.TRAINERS["infill"].build(**train.SPECS["infill"]["arch"])
    train.load_onnx_weights(net, post.MODELS / "infill.onnx")
    x = np.random.default_rng(0).random((1, net.channels_in, 64, 64), dtype=np.float32)
    with torch.no_grad():
        ref = net.eval()(torch.from_numpy(x)).numpy()
    assert np.abs(train._run(post.MODELS / "infill.onnx", x) - ref).max() < 1e-4
    with pytest.raises(ValueError, match="not this network's weights"):
        train.load_onnx_weights(net, post.MODELS / "lidar.onnx")
    (tmp_path / "x.onnx").write_text("no model")
    with pytest.raises(ValueError, match="not an ONNX model"):
        train.load_onnx_weights(net, tmp_path / "x.onnx")


def test_init_starts_from_an_export_with_its_batch_norms_folded():
    """The LiDAR U-Net's export folds its batch norms into the convolutions
    ("onnx::Conv_N" initializers): --init matches the graph's convolutions to
    the network's in the order they run, puts each folded bias in its norm,
    and freezes the norms; the network then computes what onnxruntime
    computes on the file, in eval mode and in training mode alike."""
    import torch

    net = train.TRAINERS["lidar"].build(**train.SPECS["lidar"]["arch"])
    train.load_onnx_weights(net, post.MODELS / "lidar.onnx")
    assert net.frozen_norms
    rng = np.random.default_rng(0)
    x = rng.random((1, net.channels_in, 64, 64), dtype=np.float32)
    x[:, 3] = rng.random((64, 64)) < 0.2  # the kept mask
    want = train._run(post.MODELS / "lidar.onnx", x)
    with torch.no_grad():
        got = net.eval()(torch.from_numpy(x)).numpy()
        train.train_mode(net)
        trained = net(torch.from_numpy(x)).numpy()
    assert np.abs(got - want).max() < 1e-4 and np.abs(trained - want).max() < 1e-4
    other = train.TRAINERS["lidar"].build(**{**train.SPECS["lidar"]["arch"], "width": 4})
    with pytest.raises(ValueError, match="not this network's weights"):
        train.load_onnx_weights(other, post.MODELS / "lidar.onnx")


def test_init_adds_the_infill_candidates_plane_at_zero(tmp_path):
    """--init of the in-fill W-Net with its candidates plane (6 channels)
    from a 5-channel file: each U-Net's first convolution gets a zero column
    for the new channel, the rest is the file's, so the network computes
    the file's (onnxruntime's, within float rounding) whatever the plane
    holds, and the plane's weights still learn."""
    import torch

    from clvis.post import nets

    old = nets.InfillWNet()
    torch.manual_seed(3)
    with torch.no_grad():
        for p in old.parameters():  # (the zero last layers too: a network that is not push-pull)
            p.add_(0.05 * torch.randn_like(p))
    train.export_onnx(old, tmp_path / "infill.onnx")
    new = nets.InfillWNet(candidates=True)
    train.load_onnx_weights(new, tmp_path / "infill.onnx")
    assert new.channels_in == 6 and old.channels_in == 5
    rng = np.random.default_rng(0)
    x = rng.random((1, 6, 64, 64), dtype=np.float32)
    x[:, 4] = x[:, 4] > 0.6  # the running rays
    with torch.no_grad():
        ref = old.eval()(torch.from_numpy(x[:, :5])).numpy()
        got = [
            new.eval()(torch.from_numpy(np.concatenate([x[:, :5], x[:, 5:] * k], 1))).numpy() for k in (0, 1)
        ]
    assert np.abs(train._run(tmp_path / "infill.onnx", x[:, :5]) - ref).max() < 1e-4
    assert np.abs(ref - x[:, :4]).max() > 0.05  # the running pixels are filled
    for g in got:
        np.testing.assert_array_equal(g, ref)
    for u in (new.first, new.second):
        w = u.enc[0][0].weight.detach().numpy()
        assert w.shape[1] == 6 + 4 and (w[:, 5] == 0).all()
    np.testing.assert_array_equal(
        new.first.enc[0][0].weight.detach().numpy()[:, [0, 1, 2, 3, 4, 6, 7, 8, 9]],
        old.first.enc[0][0].weight.detach().numpy(),
    )
    new.train()(torch.from_numpy(x)).sum().backward()
    assert new.first.enc[0][0].weight.grad[:, 5].abs().sum() > 0


@pytest.mark.parametrize("planes", [5, 6])
def test_infill_init_adds_the_hit_prior_plane_at_zero(tmp_path, planes):
    """A 7-plane W-Net (candidates and hit prior) from a 5- or 6-plane file:
    zero columns for the planes the file lacks, so it computes the file's
    network whatever those planes hold; their weights still learn. A hit
    prior without the candidates plane is refused."""
    import torch

    from clvis.post import nets

    old = nets.InfillWNet(candidates=planes == 6)
    torch.manual_seed(4)
    with torch.no_grad():
        for p in old.parameters():
            p.add_(0.05 * torch.randn_like(p))
    train.export_onnx(old, tmp_path / "infill.onnx")
    new = nets.InfillWNet(candidates=True, prior=True)
    assert new.channels_in == 7
    train.load_onnx_weights(new, tmp_path / "infill.onnx")
    rng = np.random.default_rng(1)
    x = rng.random((1, 7, 64, 64), dtype=np.float32)
    x[:, 4] = x[:, 4] > 0.6
    with torch.no_grad():
        ref = old.eval()(torch.from_numpy(x[:, :planes])).numpy()
        got = new.eval()(torch.from_numpy(x)).numpy()
    np.testing.assert_array_equal(got, ref)
    for u in (new.first, new.second):
        w = u.enc[0][0].weight.detach().numpy()
        assert w.shape[1] == 7 + 4 and (w[:, planes:7] == 0).all()
    new.train()(torch.from_numpy(x)).sum().backward()
    assert new.first.enc[0][0].weight.grad[:, 6].abs().sum() > 0
    with pytest.raises(ValueError, match="candidates=True"):
        nets.InfillWNet(prior=True)


def test_init_with_an_added_plane_starts_as_the_shipped_narvis(tmp_path):
    """--init with one more input plane (the shipped narvis's planes +
    "temperature"; the shipped model itself was started so, from its
    predecessor without "radius"): the shipped
    NARVis's weights (its KPN trunk's, under "net."), the new channel passed
    through by the first layer into encoder weights of zero: the network
    computes what the shipped one does whatever the new plane holds (within
    float rounding), and that plane's first-layer column and encoder weights
    are the only ones not the file's. A file without a card naming its planes,
    or planes that are not the start of the new layout, is refused."""
    import shutil

    import torch

    card = json.loads((post.MODELS / "narvis.json").read_text())["architecture"]
    arch = {**train.SPECS["narvis"]["arch"], "planes": card["planes"]}
    old = train.TRAINERS["narvis"].build(**arch)
    train.load_onnx_weights(old, post.MODELS / "narvis.onnx")
    new = train.TRAINERS["narvis"].build(**{**arch, "planes": [*arch["planes"], "temperature"]})
    train.load_onnx_weights(new, post.MODELS / "narvis.onnx")
    assert new.channels_in == old.channels_in + 1 and new.layout[-1] == "temperature"
    rng = np.random.default_rng(0)
    x = rng.random((1, new.channels_in, 32, 48), dtype=np.float32)
    x[:, 3] = x[:, 3] > 0.4  # the coverage
    with torch.no_grad():
        ref = old.eval()(torch.from_numpy(x[:, :-1])).numpy()
        got = [
            new.eval()(torch.from_numpy(np.concatenate([x[:, :-1], x[:, -1:] * k], 1))).numpy()
            for k in (0, 9)
        ]
    assert np.abs(ref).max() > 0.05
    for g in got:
        assert np.abs(g - ref).max() < 1e-5
    w = new.inject.weight.detach().numpy()
    c = old.channels_in
    np.testing.assert_array_equal(w[:c, :c], old.inject.weight.detach().numpy())
    assert (w[:c, c:] == 0).all() and (w[c, :c] == 0).all() and w[c, c, 0, 0] == 1
    assert (new.enc[2].features.weight.detach().numpy()[:, -1] == 0).all()
    # the net still learns the plane: the encoder's weights on it have a gradient
    x_t = torch.from_numpy(x)
    new.train()(x_t).sum().backward()
    assert new.enc[0].features.weight.grad[:, -1].abs().sum() > 0
    shutil.copy(post.MODELS / "narvis.onnx", tmp_path / "narvis.onnx")
    with pytest.raises(ValueError, match="without its card"):
        train.load_onnx_weights(new, tmp_path / "narvis.onnx")
    (tmp_path / "narvis.json").write_text(json.dumps({"architecture": {"planes": ["rgb", "vel2d"]}}))
    with pytest.raises(ValueError, match="not the first channels"):
        train.load_onnx_weights(new, tmp_path / "narvis.onnx")


def test_narvis_radius_plane_is_grs_sigma():
    """The flow scenes' clouds carry radius = GR's base sigma (one function,
    data.narvis_sigma, for both): the rasterizer's radius plane is that
    sigma projected to pixels, and GR's Gaussians are made of the same
    number (across the flow; x NARVIS_STRETCH along it)."""
    sc = data.narvis_flow_scene("abc", 4000, 3)
    sigma = data.narvis_sigma(sc.cloud.positions)
    assert sigma > 0 and sc.gr_sigma() == sigma
    np.testing.assert_array_equal(sc.cloud.radius, np.full(4000, sigma, np.float32))
    hur = data.narvis_scene("hurricane", 5000, 1)
    assert hur.gr_sigma() == data.narvis_sigma(hur.cloud.positions) == hur.cloud.radius[0]
    # a scene without a sigma computes the same one
    bare = data.NarvisScene(sc.cloud, sc.attribute, sc.value_range, sc.colormap, "bare")
    assert bare.gr_sigma() == sigma
    gr = bare.gaussian_renderer()
    scales = np.sort(np.asarray(gr.gaussians.scales), axis=1)
    np.testing.assert_allclose(scales[:, 0], sigma, rtol=1e-6)
    cam = data.narvis_cameras(sc, "hemisphere", 48 / 40)[3]
    g = sc.gbuffers(sc.rasterizer(), cam, 48, 40, ("rgb", "depth", "vel2d", "radius"))
    r = np.asarray(g.radius_px)[np.asarray(g.covered)]
    assert len(r) and (r > 0).all()


def test_train_infill_mixed_and_from_a_model_says_so_in_its_card(tmp_path, capsys):
    """clvis train infill --init --mix --lr: a smoke run; the card names the
    starting file (sha256, its command), the variety pairs and the rate."""
    init = post.MODELS / "infill.onnx"
    args = ["train", "infill", "--steps", "2", "--size", "64", "--frames", "1", "--frame-size", "96x64"]
    args += ["--out", str(tmp_path), "--quiet", "--eval", "none", "--init", str(init), "--mix", "0.5"]
    assert main(args + ["--lr", "0.0003"]) == 0
    card = json.loads((tmp_path / "infill.json").read_text())
    t, mix = card["training"], card["data"]["mix"]
    assert t["init"]["sha256"] == train.sha256(init) and t["init"]["file"] == "infill.onnx"
    assert t["init"]["command"] == json.loads((post.MODELS / "infill.json").read_text())["command"]
    assert t["optimizer"].startswith("Adam lr 0.0003,")
    assert "--init" in card["command"] and "--mix 0.5" in card["command"]
    assert mix["share"] == 0.5 and mix["kinds"] == list(data.TRAIN_VOLUMES + data.MORE_TRAIN_VOLUMES)
    assert mix["volumes"] == 1 and mix["frames"] == 2 and mix["pairs"] == 2 * len(data.TRAIN_COMPLETIONS)
    capsys.readouterr()
    for bad, says in (
        (["--mix", "1.5"], "between 0 and 1"),
        (["--lr", "0"], "learning rate"),
        (["--init", str(tmp_path / "none.onnx")], "no such file"),
    ):
        assert main(args[:-4] + bad) == 2
        assert says in capsys.readouterr().err
    lidar = ["train", "lidar", "--frames", "1", "--frame-size", "96x64", "--size", "64", "--mix", "0.5"]
    assert main(lidar + ["--out", str(tmp_path)]) == 2
    assert "infill only" in capsys.readouterr().err


def test_narvis_frames_give_their_scenes_buffers_back():
    """Scenes of different sizes rendered one after another in one process
    (clvis train narvis's flows) leave nothing in the default queue's
    memory pool: no freed block kept back (each scene grew the pool by its
    Gaussians and G-buffers; 16 flow scenes at 96 x 96 took the RSS from
    0.49 to 1.33 GB) and no array kept alive; the frames are those a
    renderer gives directly."""
    from clvis import runtime

    pool = runtime.allocator(runtime.default_queue())
    planes = ("rgb", "depth", "vel2d")
    active = pool.active_blocks
    for n in (3000, 9000):
        sc = data.narvis_flow_scene("abc", n, 7)
        cam = data.narvis_cameras(sc, "hemisphere", 40 / 32)[3]
        f = data.narvis_frames(sc, [cam], 40, 32, planes)[0]
        assert pool.held_blocks == 0 and pool.active_blocks == active
    want = np.clip(np.asarray(sc.gaussian_renderer().render(cam, 40, 32).rgba)[..., :3], 0, 1)
    np.testing.assert_array_equal(f.rgb, want)
    assert f.rgb.sum() > 0


def test_iso_and_lidar_frames_give_their_scenes_buffers_back():
    """The in-fill's and the LiDAR's training frames, volume after volume
    (other sides) and scene after scene (other point counts), leave no
    freed block in the default queue's pool and no array alive."""
    from clvis import runtime

    pool = runtime.allocator(runtime.default_queue())
    active = pool.active_blocks
    data.iso_frames(("waves", "blobs"), 2, 3, 64, 48, views=1, vary=data.IsoVariety(sides=(24, 32)))
    assert pool.held_blocks == 0 and pool.active_blocks == active
    data.lidar_frames(("town",), 2, 5, 64, 48, views=1, dense_points=50_000)
    assert pool.held_blocks == 0 and pool.active_blocks == active


def test_lidar_frames_draw_the_scan_at_its_point_size():
    """point_size: the scan's points drawn that many pixels a side before
    the depth filter (the same dense target); (lo, hi): drawn per view."""
    kw = {"views": 1, "dense_points": 20_000, "sparse": (0.1, 0.1)}
    one = data.lidar_frames(("town",), 1, 3, 96, 72, **kw)[0]
    three = data.lidar_frames(("town",), 1, 3, 96, 72, point_size=3, **kw)[0]
    np.testing.assert_array_equal(one.rgb, three.rgb)
    kept = [int((f.rgbda[..., 4] > 0).sum()) for f in (one, three)]
    assert kept[1] > 2 * kept[0] > 0, kept
    drawn = data.lidar_frames(("town",), 1, 3, 96, 72, point_size=(3, 3), **kw)[0]
    assert int((drawn.rgbda[..., 4] > 0).sum()) > 2 * kept[0]


def test_infill_planes_choose_the_w_nets_inputs(capsys):
    """--planes for the in-fill: the W-Net's optional planes by name."""
    assert train.infill_planes(["candidates", "depth"]) == {"candidates": True, "prior": False, "depth": True}
    assert train.infill_planes(["candidates"]) == {"candidates": True, "prior": False, "depth": False}
    assert train.infill_planes([]) == {"candidates": False, "prior": False, "depth": False}
    for bad, message in (
        (["depth"], "after the candidates plane"),
        (["candidates", "prior", "depth"], "not both"),
        (["colour"], "optional planes are"),
    ):
        with pytest.raises(ValueError, match=message):
            train.infill_planes(bad)
    for planes, channels in ((["candidates", "depth"], 8), (["candidates", "prior"], 7), ([], 5)):
        assert train.TRAINERS["infill"].build(**train.infill_planes(planes)).channels_in == channels
    from clvis import cli

    assert cli.main(["train", "infill", "--planes", "depth", "--steps", "1"]) == 2
    assert (
        "--planes depth: planes: prior and depth come after the candidates plane" in capsys.readouterr().err
    )


def _tiny_infill(out, **kw):
    args = {"steps": 1, "size": 64, "out": out, "frames": 1, "frame_size": (96, 64), "log": lambda _: None}
    return train.train("infill", **{**args, **kw})


def _folder(path):
    return {p.name: p.read_bytes() for p in sorted(path.iterdir())}


@pytest.mark.parametrize("stage", ["_to_fp16", "write_card"])
def test_a_run_stopped_while_exporting_keeps_the_previous_model_whole(tmp_path, monkeypatch, stage):
    """Ctrl-C (or any failure) after NAME.onnx was written and before the
    card: the folder held the new NAME.onnx beside the previous model's card
    and variants (post.load: "does not match its model card's sha256"; the
    previous model lost). Now the folder is as it was, no temporary file."""
    _tiny_infill(tmp_path)
    before = _folder(tmp_path)
    assert sorted(before) == ["infill.fp16.onnx", "infill.int8.onnx", "infill.json", "infill.onnx"]

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(train, stage, interrupted)
    with pytest.raises(KeyboardInterrupt):
        _tiny_infill(tmp_path, seed=1)  # another model: other bytes
    assert _folder(tmp_path) == before
    post.load("infill", directory=tmp_path)


def test_onnxruntime_failing_while_exporting_is_one_error_and_writes_nothing(tmp_path, monkeypatch):
    """The release run's int8 calibration (its held-out frames whole, 1280x720)
    ran out of memory under an 8 GB limit: onnxruntime's Fail came out of
    clvis train as a traceback and left infill.onnx and infill.fp16.onnx
    without a card; then it was one error and nothing written, the trained
    model lost for its optional int8 variant. Now that variant is not made
    (said, and in the card) and the model is written; onnxruntime's other
    failures are one error and write nothing."""
    from onnxruntime.capi.onnxruntime_pybind11_state import Fail

    def oom(*args, **kwargs):
        raise Fail("[ONNXRuntimeError] : 1 : FAIL : bfc_arena.cc:360 Failed to allocate memory")

    monkeypatch.setattr(train, "_to_int8", oom)
    said: list[str] = []
    card = _tiny_infill(tmp_path, log=said.append)
    assert "int8 not made: onnxruntime ran out of memory calibrating on 96x64 frames" in said
    assert card["files"]["int8"] == {
        "file": None,
        "psnr_change_db": None,
        "skipped": "out of memory calibrating",
    }
    assert sorted(p.name for p in tmp_path.iterdir()) == ["infill.fp16.onnx", "infill.json", "infill.onnx"]
    post.load("infill", directory=tmp_path)
    for p in list(tmp_path.iterdir()):
        p.unlink()
    monkeypatch.setattr(train, "_to_int8", lambda *a: (_ for _ in ()).throw(Fail("bad graph")))
    rc = main(
        ["train", "infill", "--steps", "1", "--size", "64", "--frames", "1", "--frame-size", "96x64"]
        + ["--out", str(tmp_path), "--eval", "none", "--quiet"]
    )
    assert rc == 2 and list(tmp_path.iterdir()) == []


def test_a_new_model_replaces_all_of_the_previous_ones_files(tmp_path, monkeypatch):
    """An int8 that loses too much is not shipped: the previous model's int8
    goes too (the new card names none), the rest is the new model's."""
    _tiny_infill(tmp_path)
    monkeypatch.setattr(train, "INT8_MAX_LOSS_DB", -1.0)  # every int8 loses too much
    card = _tiny_infill(tmp_path, seed=1)
    assert card["files"]["int8"]["file"] is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["infill.fp16.onnx", "infill.json", "infill.onnx"]
    post.load("infill", directory=tmp_path)
    post.load("infill", "fp16", directory=tmp_path)


def test_init_with_weights_that_are_not_finite_is_refused(tmp_path):
    """An --init file with NaN weights trained on and then failed in the
    int8 calibration with onnxruntime's AssertionError("scale issue"), a
    traceback."""
    import onnx
    from onnx import numpy_helper

    from clvis.post.infer import MODELS

    m = onnx.load(str(MODELS / "infill.onnx"))
    first = m.graph.initializer[0]
    a = numpy_helper.to_array(first).copy()
    a.flat[0] = np.nan
    first.CopyFrom(numpy_helper.from_array(a, first.name))
    onnx.save(m, str(tmp_path / "nan.onnx"))
    out = tmp_path / "out"
    with pytest.raises(ValueError, match="nan.onnx: weights that are not finite"):
        _tiny_infill(out, init=tmp_path / "nan.onnx")
    assert not out.exists()


def test_a_diverged_run_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(train, "_loss_fn", lambda weights, crop: lambda pred, target: (pred * np.nan).mean())
    with pytest.raises(ValueError, match="training diverged: weights that are not finite after 1 steps"):
        _tiny_infill(tmp_path)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["infill", "lidar"])
def test_init_from_an_int8_export_says_so(name):
    # was "not this network's weights (missing [...])": it is, quantized
    from clvis.post.infer import MODELS

    spec = train.SPECS[name]
    net = train.TRAINERS[name].build(**spec["arch"])
    with pytest.raises(ValueError, match=rf"{name}\.int8\.onnx: a quantized \(int8\) export"):
        train.load_onnx_weights(net, MODELS / f"{name}.int8.onnx")


@pytest.mark.parametrize(
    "change,message",
    [
        ({"steps": 0}, "steps: expected a whole number of at least 1, got 0"),
        ({"steps": -3}, "steps: expected"),
        ({"steps": 1.5}, "steps: expected"),
        ({"frames": -1}, "frames: expected"),
        ({"frames": 0}, "frames: expected"),
        ({"seed": -1}, "seed: expected"),
        ({"time_limit": 0}, "time_limit: expected a positive number of seconds, got 0"),
        ({"time_limit": -1.0}, "time_limit: expected"),
        ({"time_limit": float("nan")}, "time_limit: expected"),
    ],
)
def test_train_checks_its_counts(tmp_path, change, message):
    # steps=0 or -3 exported an untrained network with its card; time_limit=0
    # raised ZeroDivisionError, -1 or nan was no limit; frames=-1 failed in numpy
    out = tmp_path / "out"
    with pytest.raises(ValueError, match=message):
        _tiny_infill(out, **change)
    assert not out.exists() or list(out.iterdir()) == []


def test_init_of_another_network_fails_before_the_data_is_rendered(tmp_path, monkeypatch):
    # the file was read after rendering the training frames (90 s at the
    # release run's sizes on a quiet machine) and the out folder made
    from clvis.post.infer import MODELS

    def rendered(*args, **kwargs):
        raise AssertionError("rendered the data first")

    monkeypatch.setattr(train, "_frames", rendered)
    out = tmp_path / "out"
    with pytest.raises(ValueError, match="lidar.onnx: not this network's weights"):
        _tiny_infill(out, init=MODELS / "lidar.onnx")
    assert not out.exists()


def test_install_puts_the_previous_model_back_when_a_move_fails(tmp_path, monkeypatch):
    """_install's every os.replace failing in turn (a full or vanishing disk,
    an interrupt between two moves): the folder keeps the previous model."""
    import os

    out = tmp_path / "out"
    out.mkdir()
    old = {"infill.json": b"old card", "infill.onnx": b"old fp32", "infill.int8.onnx": b"old int8", "x": b"x"}
    for k, v in old.items():
        (out / k).write_bytes(v)
    files = {"fp32": {"file": "infill.onnx"}, "fp16": {"file": "infill.fp16.onnx"}, "int8": {"file": None}}
    real = os.replace
    for fail_at in range(1, 10):
        stage = train._staging(out, "infill")
        for k in ("infill.json", "infill.onnx", "infill.fp16.onnx"):
            (stage / k).write_bytes(b"new " + k.encode())

        def replace(a, b, calls=[], fail_at=fail_at):  # noqa: B006 (its own list per pass)
            calls.append(a)
            if len(calls) == fail_at:
                raise KeyboardInterrupt
            real(a, b)

        monkeypatch.setattr(train.os, "replace", replace)
        try:
            train._install(stage, out, "infill", files)
        except KeyboardInterrupt:
            monkeypatch.setattr(train.os, "replace", real)
            assert {p.name: p.read_bytes() for p in out.iterdir() if p != stage} == old, fail_at
            shutil.rmtree(stage)
            continue
        monkeypatch.setattr(train.os, "replace", real)
        shutil.rmtree(stage)
        break
    assert fail_at > 3  # it did fail part-way a few times before it got through
    assert {p.name: p.read_bytes() for p in out.iterdir()} == {
        "infill.json": b"new infill.json",
        "infill.onnx": b"new infill.onnx",
        "infill.fp16.onnx": b"new infill.fp16.onnx",
        "x": b"x",
    }


def test_train_stopped_in_its_eval_says_the_model_is_written(tmp_path, monkeypatch, capsys):
    # Ctrl-C in --eval quick said "interrupted" alone, after the model and its
    # card had been written
    from clvis.training import evaluate

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(evaluate, "evaluate", interrupted)
    args = ["train", "infill", "--steps", "1", "--size", "64", "--frames", "1", "--frame-size", "96x64"]
    assert main([*args, "--out", str(tmp_path), "--quiet"]) == 130
    err = capsys.readouterr().err
    assert f"{tmp_path}/infill.onnx and its card are written; its held-out suite is not" in err
    assert f"clvis eval infill --model-dir {tmp_path} --quick --write-card" in err
    post.load("infill", directory=tmp_path)


# a `clvis train infill` run in another process (the tiny run above), with
# `patch` run first inside it: what a run killed or still going does
_CHILD = """
import os, signal, sys, time
from pathlib import Path
from clvis.cli import main
from clvis.training import train
out = sys.argv[1]
{patch}
sys.exit(main(["train", "infill", "--steps", "1", "--size", "64", "--frames", "1",
               "--frame-size", "96x64", "--out", out, "--eval", "none", "--quiet"]))
"""


def _child(out, patch):
    import os
    import subprocess
    import sys
    from pathlib import Path

    import clvis

    env = {**os.environ, "PYTHONPATH": str(Path(clvis.__file__).parents[1]), "CLVIS_TRAIN_THREADS": "1"}
    code = _CHILD.format(patch=patch)
    return subprocess.Popen(
        [sys.executable, "-c", code, str(out)], env=env, stderr=subprocess.PIPE, text=True
    )


def test_a_killed_runs_staging_folder_is_removed_by_the_next_run(tmp_path, capsys):
    """A run SIGKILLed (or a power cut) after exporting left its hidden
    staging folder in --out for ever, the next runs into the same folder
    beside it. Now the next run removes it and says so; it leaves what is
    not clearly such a folder: a live run's, one holding other files,
    another network's, a link."""
    import os
    import signal

    out = tmp_path / "out"
    killed = _child(out, "train._install = lambda *a: os.kill(os.getpid(), signal.SIGKILL)")
    assert killed.wait(timeout=600) == -signal.SIGKILL, killed.stderr.read()
    (stale,) = out.glob(".infill.*.train.tmp")
    assert {p.name for p in stale.iterdir()} >= {"infill.onnx", "infill.fp16.onnx", "infill.json"}
    live = train._staging(out, "infill")  # this (live) process's
    (live / "infill.onnx").write_bytes(b"x")
    user = out / ".infill.abcdefgh.train.tmp"  # the name, and a file train does not write
    user.mkdir()
    (user / "notes.txt").write_text("mine")
    lidar = out / ".lidar.abcdefgh.train.tmp"  # another network's: not this run's to judge
    lidar.mkdir()
    link = out / ".infill.linklink.train.tmp"
    link.symlink_to(tmp_path)
    args = ["train", "infill", "--steps", "1", "--size", "64", "--frames", "1", "--frame-size", "96x64"]
    assert main([*args, "--out", str(out), "--eval", "none", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert not stale.exists()
    assert f"clvis train: removed {stale}: the staging folder of a run stopped" in err, err
    assert f"left {live}: its run (pid {os.getpid()} on" in err and "may still be running" in err
    assert f"left {user}: holds notes.txt, which clvis train does not write there" in err
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["infill.fp16.onnx", "infill.int8.onnx", "infill.json", "infill.onnx", live.name, user.name]
        + [lidar.name, link.name]
    )
    assert (user / "notes.txt").read_text() == "mine" and link.is_symlink() and lidar.is_dir()
    post.load("infill", directory=out)


def test_a_folder_of_a_run_killed_while_moving_its_model_in_is_left(tmp_path):
    """Killed between two of _install's moves: previous/ holds the model it
    was replacing, which is not thrown away; the folder is left and said."""
    import subprocess
    import sys

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # a pid no process has now
    stage = train._staging(tmp_path, "infill")
    owner = json.loads((stage / train._OWNER).read_text())
    (stage / train._OWNER).write_text(json.dumps({**owner, "pid": dead.pid}))
    (stage / "previous").mkdir()
    (stage / "previous" / "infill.json").write_text("{}")
    said = []
    with train.claim(tmp_path, "infill", said.append):
        assert (tmp_path / ".infill.train.lock").exists()
    assert said == [
        f"left {stage}: a run stopped while moving its model in; previous/ there holds the model it "
        f"was replacing (move its files back into {tmp_path}, or remove the folder)"
    ]
    assert (stage / "previous" / "infill.json").exists() and not (tmp_path / ".infill.train.lock").exists()
    (stage / "previous" / "infill.json").unlink()  # an empty previous/: the run's, dead
    with train.claim(tmp_path, "infill", said.append):
        pass
    assert said[1] == f"removed {stage}: the staging folder of a run stopped before it could remove it"
    assert list(tmp_path.iterdir()) == []


def test_a_second_run_into_the_same_folder_is_refused_while_the_first_runs(tmp_path, capsys):
    """Two runs of one network into one --out at once interleaved their
    installs (the second's files among the first's). Now the second is
    refused at once, naming the first; the first goes on and installs its
    model, and leaves no lock file; other networks are not held up."""
    import socket
    import time

    out = tmp_path / "out"
    wait = (  # in its data's rendering, holding the folder, until the test says go
        "real = train._frames\n"
        "def paused(*a, **k):\n"
        "    Path(out).parent.joinpath('ready').touch()\n"
        "    while not Path(out).parent.joinpath('go').exists():\n"
        "        time.sleep(0.05)\n"
        "    return real(*a, **k)\n"
        "train._frames = paused"
    )
    first = _child(out, wait)
    try:
        t0 = time.monotonic()
        while not (tmp_path / "ready").exists():
            assert first.poll() is None, first.stderr.read()
            assert time.monotonic() - t0 < 600
            time.sleep(0.1)
        args = ["train", "infill", "--steps", "1", "--size", "64", "--frames", "1", "--frame-size", "96x64"]
        assert main([*args, "--out", str(out), "--eval", "none", "--quiet"]) == 2
        err = capsys.readouterr().err
        host = socket.gethostname()
        assert err.startswith(
            f"clvis train: error: {out}: another clvis train infill is writing its model there "
            f"(pid {first.pid} on {host}, since "
        ), err
        assert err.endswith(" UTC); wait for it to end, or give another --out\n") and err.count("\n") == 1, (
            err
        )
        assert not list(out.glob(".infill.*.train.tmp"))  # refused before it made anything
        # another network into the same folder meanwhile: not held up
        assert main(["train", "lidar", *args[2:], "--out", str(out), "--eval", "none", "--quiet"]) == 0
    finally:
        (tmp_path / "go").touch()
    assert first.wait(timeout=600) == 0, first.stderr.read()
    # the two models (an int8 where it kept its PSNR), no lock file, no staging folder
    names = {p.name for p in out.iterdir()} - {"infill.int8.onnx", "lidar.int8.onnx"}
    assert names == {f"{n}{v}" for n in ("infill", "lidar") for v in (".json", ".onnx", ".fp16.onnx")}, names
    post.load("infill", directory=out)
    post.load("lidar", directory=out)
