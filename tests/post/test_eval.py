"""clvis eval: the held-out suites (families never trained on), the classical
splat NARVis is measured against, the cards' suite tables, and a CI-size
subset of each suite recomputed and held to what the shipped models reach.

The issue's targets (issue 21 §2) the shipped models MISS are stated here
with their measurements, each as a strict xfail: when a retrained model
meets one, its xfail passes and fails the run, so the mark must go."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from clvis import metrics as _metrics
from clvis import post
from clvis.cli import main
from clvis.errors import ClvisError
from clvis.training import data, flows
from clvis.training import evaluate as ev


def test_suites_hold_only_families_never_trained_on():
    for name in post.NAMES:
        assert not set(ev.FAMILIES[name]) & set(ev.TRAINED[name])
        for quick in (True, False):
            cases = ev.suite(name, quick)
            assert {c.family for c in cases} == set(ev.FAMILIES[name])
    assert not set(data.EVAL_VOLUMES) & set(data.TRAIN_VOLUMES)
    # the in-fill suite spans the sizes and volumes
    infill = ev.suite("infill")
    assert {c.size for c in infill} == {(320, 180), (640, 360), (1280, 720), (1920, 1080)}
    assert {c.setting for c in infill} == {32, 64, 128, 256}
    # the NARVis suite has both samplers and densities around the training's
    full = ev.suite("narvis")
    assert {c.sampler for c in full} == {"hemisphere", "grid"}
    assert {c.setting for c in full} == {0.25, 1.0, 4.0}
    with pytest.raises(ValueError, match="expected one of"):
        ev.suite("nope")
    # the specs name the generators clvis.training has
    assert ev.FAMILIES["infill"] == data.HELD_OUT_VOLUMES + data.EVAL_VOLUMES
    assert ev.TRAINED["infill"] == data.TRAIN_VOLUMES + data.MORE_TRAIN_VOLUMES  # --mix
    assert ev.FAMILIES["narvis"][:-1] == flows.FLOWS
    # NARVis trains on the hurricane and the training flows, none of them a
    # family of its suite (the hurricane through magma: a colormap never drawn)
    assert ev.TRAINED["narvis"] == ("hurricane", *flows.TRAIN_FLOWS)
    assert not set(flows.TRAIN_FLOWS) & set(flows.FLOWS)
    # the probe flows (bench/narvis_unseen.py) are in neither
    assert not set(flows.PROBE_FLOWS) & set(flows.FLOWS + flows.TRAIN_FLOWS)
    assert not {"magma", "magma_r"} & set(data.NARVIS_TRAIN_COLORMAPS)
    # narvis-scan: scan generators, held out and trained disjoint; densities
    # around the training's, a larger size too
    assert ev.FAMILIES["narvis-scan"] == data.SCAN_HELD_OUT
    assert ev.TRAINED["narvis-scan"] == data.SCAN_TRAIN
    # LiDAR trains on towns (the shipped model on height-coloured ones;
    # procedural textures are an option); the photographs stay held out
    from clvis.training.train import SPECS as TRAIN_SPECS

    assert ev.TRAINED["lidar"] == tuple(TRAIN_SPECS["lidar"]["scenes"]) == ("town",)
    scan = ev.suite("narvis-scan")
    assert {c.setting for c in scan} == {0.25, 1.0, 4.0} and {c.size for c in scan} == {
        (256, 256),
        (512, 512),
    }


def test_one_spec_per_network():
    from clvis.post import specs

    assert tuple(specs.SPECS) == post.NAMES
    for name in post.NAMES:
        s = specs.spec(name)
        assert s.name == name and s.title and s.baselines and s.eval_families
    with pytest.raises(ValueError, match="expected one of"):
        specs.spec("nope")
    with pytest.raises(TypeError, match="infill network takes an IsoImage"):
        specs.spec("infill").shape(np.zeros((4, 4, 4)))
    with pytest.raises(ValueError, match=r"\(H, W, 5\)"):
        specs.spec("lidar").shape(np.zeros((4, 4, 4), np.float32))


@pytest.mark.parametrize("kind", flows.FLOWS + flows.TRAIN_FLOWS + flows.PROBE_FLOWS)
def test_flows_are_finite_particles_with_a_velocity(kind):
    d = flows.flow(kind, 2000, 3)
    assert d["positions"].shape == d["velocity"].shape == (2000, 3)
    t = d["attributes"]["temperature"]
    assert t.shape == (2000,) and np.isfinite(d["positions"]).all() and np.isfinite(d["velocity"]).all()
    assert t.max() > t.min() and np.abs(d["velocity"]).max() > 0
    np.testing.assert_array_equal(d["positions"], flows.flow(kind, 2000, 3)["positions"])
    with pytest.raises(ValueError, match="flow"):
        flows.flow("nope", 2000, 3)


def test_photo_town_takes_its_colours_from_a_photograph():
    a, b = data.town(5000, 4), data.photo_town(5000, 4)
    np.testing.assert_array_equal(a["positions"], b["positions"])
    assert not np.array_equal(a["colors"], b["colors"])
    # a photograph has many more distinct colours than the town's ramp and roofs
    assert len(np.unique(b["colors"][:, :3], axis=0)) > 3 * len(np.unique(a["colors"][:, :3], axis=0))


def test_splat_draws_an_ellipse_along_the_velocity():
    rgb = np.zeros((31, 31, 3), np.float32)
    cov = np.zeros((31, 31), bool)
    rgb[15, 15], cov[15, 15] = (1.0, 0.5, 0.25), True
    vel = np.zeros((31, 31, 2))
    vel[15, 15] = (1.0, 0.0)  # along x
    out = ev.splat(rgb, cov, vel, radius=6)
    row, col = out[15, :, 0], out[:, 15, 0]
    assert (row > 0.25 * row[15]).sum() > (col > 0.25 * col[15]).sum() + 2  # longer along x than y
    np.testing.assert_allclose(out[15, 15] / out[15, 15, 0], (1.0, 0.5, 0.25), rtol=1e-6)  # its colour
    assert out[15, 15, 0] == pytest.approx(0.5)  # opacity 0.5 at its centre
    round_ = ev.splat(rgb, cov, None, radius=6)
    np.testing.assert_allclose(round_[15, :, 0], round_[:, 15, 0], atol=1e-7)
    assert not ev.splat(rgb, np.zeros_like(cov), vel).any()


def test_splat_takes_its_sigma_from_a_radius_plane():
    """narvis-scan's classical splat: round, each pixel's sigma the radius
    plane's (clipped to 0.5 .. radius / 2.5), NaN (empty) read as the least."""
    rgb = np.zeros((31, 31, 3), np.float32)
    cov = np.zeros((31, 31), bool)
    rgb[8, 8], rgb[22, 22], cov[8, 8], cov[22, 22] = (1, 1, 1), (1, 1, 1), True, True
    sigma = np.full((31, 31), np.nan, np.float32)
    sigma[8, 8], sigma[22, 22] = 0.7, 2.0
    out = ev.splat(rgb, cov, None, sigma=sigma, opacity=0.8, radius=6)
    small, big = out[8, 4:13, 0], out[22, 18:27, 0]
    assert out[8, 8, 0] == pytest.approx(0.8) and out[22, 22, 0] == pytest.approx(0.8)
    assert (big > 0.1).sum() > (small > 0.1).sum() + 2  # the wider sigma reaches further
    np.testing.assert_allclose(out[22, 18:27, 0], out[18:27, 22, 0], atol=1e-7)  # round
    huge, clipped = sigma.copy(), sigma.copy()
    huge[22, 22], clipped[22, 22] = 50.0, 2.4  # clipped to radius / 2.5
    np.testing.assert_allclose(
        ev.splat(rgb, cov, None, sigma=huge, radius=6), ev.splat(rgb, cov, None, sigma=clipped, radius=6)
    )
    assert not np.allclose(ev.splat(rgb, cov, None, sigma=huge, radius=6), out)


def test_metrics_module():
    a = np.random.default_rng(0).random((32, 32, 3)).astype(np.float32)
    assert _metrics.metrics(a, a) == {"psnr": math.inf, "ssim": pytest.approx(1.0)}
    assert _metrics.metrics(a * 0.9, a)["psnr"] < 40
    with pytest.raises(ValueError, match="H, W, 3"):
        _metrics.metrics(a[..., :2], a[..., :2])
    # uint8 pictures (what the networks return) are 0..255: the same scores as their floats
    u = np.rint(a * 255).astype(np.uint8)
    v = np.clip(u.astype(np.int16) + 9, 0, 255).astype(np.uint8)
    assert _metrics.metrics(v, u) == pytest.approx(_metrics.metrics(v / 255.0, u / 255.0))
    assert 25 < _metrics.metrics(v, u)["psnr"] < 30
    assert _metrics.metrics(u, a)["psnr"] > 45  # one of each
    with pytest.raises(TypeError, match="int16"):
        _metrics.metrics(u.astype(np.int16), a)
    with pytest.raises(ValueError, match=r"\[\.\.\., :3\]"):
        _metrics.metrics(np.dstack([u, u[..., :1]]), u)


def test_eval_cli_parses(capsys):
    assert main(["eval", "--help"]) == 0
    out = capsys.readouterr().out
    assert "held-out suite" in out and "--guard, --no-guard" in out
    assert main(["eval", "nope"]) == 2


@pytest.mark.parametrize("name", post.NAMES)
def test_shipped_cards_carry_their_suite_table(name):
    """Each shipped card holds its quick suite (``clvis eval NAME --quick
    --write-card``): every held-out family, every baseline."""
    card = json.loads((post.MODELS / f"{name}.json").read_text())
    suite = card["held_out_suite"]
    # what the card's model saw: the training's families (the shipped NARVis
    # U-Net predates the training flows: the hurricane alone), none in the suite
    assert suite["trained_on"] and set(suite["trained_on"]) <= set(ev.TRAINED[name])
    assert not set(suite["trained_on"]) & set(ev.FAMILIES[name])
    # scored as the network is called by default: with its guard or without
    assert suite.get("guard", False) == bool(post.load(name, threads=1).guard)
    rows = suite["rows"]
    assert {r["family"] for r in rows} == set(ev.FAMILIES[name])
    for r in rows:
        assert set(ev.BASELINES[name]) | {"network"} <= set(r)
    assert "| family |" in ev.table({"model": name, "rows": rows})


# the rows of each shipped card's quick suite where the network is below the
# best classical baseline (issue 21 §2's "never below the baseline": MISSED
# on these), with (PSNR, SSIM) margins as measured; a card may not add a row
# here nor fall more than 0.25 dB / 0.01 further on one
KNOWN_BELOW = {
    # in-fill: none since the W-Net with the depth planes (stop 48). The
    # 6-plane model before it was below push-pull on the shapes' 85 and 90 %
    # rows by 0.70 dB (the same frame: both snapshots fall on the same pass),
    # the depth model's first run (d1) by 0.13 dB; the full suite's rows
    # below went from 6 to 7 of 105, then 5 with 32^3 volumes in the
    # variety (stop 49; bench/results/README.md).
    "infill": {},
    # LiDAR: none since its tensor pads past the frame by reflection (the
    # quick suite's 240 rows were padded to 256 with an empty band: photo 3 %
    # 3 px went from +0.05 dB / -0.001 SSIM to +0.10 / +0.001) and its guard
    # withholds whole points (clvis.post.guard.points_withheld). Before: the card
    # is scored with its guard (on by default): push-pull on
    # the terrain, where the U-Net alone is 4.94 dB / 0.011 SSIM below it;
    # every method is scored as its 8-bit picture (clvis.metrics.as_picture), so
    # the guard's push-pull ties push-pull there (it was 0.01 dB below when
    # only the network's picture was rounded). Points drawn 3 pixels a side
    # on the photographs: the model trained on 1..3-pixel scans is 0.05 dB
    # over push-pull but 0.001 below its SSIM (the model trained on 1-pixel
    # scans alone: -1.64 dB / -0.046; one trained on towns under procedural
    # textures too, not shipped: +0.40 dB / +0.002, bench/results/README.md)
    "lidar": {},
    # narvis (4000 steps with the 'attractors' flow, 4000 from it with the
    # radius plane, 4000 more with a heavier MS-SSIM loss, then 4000 more):
    # none (the least margin: Lorenz grid +1.51 dB over the splat). The
    # model three runs back was 0.008 below the raster's SSIM on the Lorenz
    # attractor's hemisphere view (+2.16 dB); this one is +2.54 dB / +0.011
    "narvis": {},
    # narvis-scan (4000 steps, 61 min on 1 thread, then 4000 more from it
    # at a lower rate three times, 21 + 19 + 19 min, the last on frames
    # through its depth filter): none (object +1.69 dB / +0.045 over the
    # splat of the filtered G-buffers, aerial +2.46 / +0.019, terrain
    # +6.63). Unfiltered, the model before: object +3.36 / +0.005 over the
    # plain splat; two runs back object +3.22 / -0.003; three: aerial +0.04
    # / -0.009, object +3.31 / -0.008.
    "narvis-scan": {},
}


@pytest.mark.parametrize("name", post.NAMES)
def test_shipped_cards_hold_their_suite_margins(name):
    card = json.loads((post.MODELS / f"{name}.json").read_text())
    margins = ev.margins({"model": name, "rows": card["held_out_suite"]["rows"]})
    for label, dp, ds in margins:
        if label in KNOWN_BELOW[name]:
            kp, ks = KNOWN_BELOW[name][label]
            assert dp >= kp - 0.25 and ds >= ks - 0.01, label
        else:
            assert dp >= 0 and ds >= 0, f"{label}: {dp:+.2f} dB, SSIM {ds:+.3f} below the best baseline"
    assert set(KNOWN_BELOW[name]) <= {m[0] for m in margins}


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(
            n,
            marks=pytest.mark.xfail(
                strict=True, reason="target missed: see KNOWN_BELOW (rows of the quick suites)"
            ),
        )
        if KNOWN_BELOW[n]
        else n
        for n in post.NAMES
    ],
)
def test_shipped_cards_never_below_their_baseline(name):
    """Issue 21 §2: PSNR and SSIM >= the best classical baseline on every
    row of the suite. Met by the LiDAR card (with its guard); the others
    miss it on the rows of KNOWN_BELOW (a strict xfail each)."""
    card = json.loads((post.MODELS / f"{name}.json").read_text())
    margins = ev.margins({"model": name, "rows": card["held_out_suite"]["rows"]})
    assert all(dp >= 0 and ds >= 0 for _, dp, ds in margins)


# ---------------------------------------------------------------------------
# the CI subset: one case of each suite, recomputed (~1 min on 2 cores)

CI_CASES = {
    "infill": ev.Case("shapes", (320, 180), 64),
    "lidar": ev.Case("photo", (320, 240), 0.05),
    "narvis": ev.Case("jet", (128, 128), 1.0, "hemisphere"),
    "narvis-scan": ev.Case("aerial", (128, 128), 1.0, "views"),
}


@pytest.fixture(scope="module")
def ci_rows():
    out = {}
    for name, case in CI_CASES.items():
        rows = ev.evaluate(name, cases=[case], log=None)["rows"]
        out[name] = {r["setting"]: r for r in rows}
    return out


def _margin(row, baseline, key="psnr"):
    return row["network"][key] - row[baseline][key]


def test_ci_infill_on_shapes(ci_rows):
    """Distance fields of random shapes (never trained on), 320 x 180.
    Measured (Intel CPU), since a ray with no candidate block left is
    finished at once (traverse.cl: 90 % is reached in the pass that reaches
    85 %, 95 % one pass earlier than before), with the model fine-tuned on
    such frames, then with the candidates plane (IsoImage.candidates), then
    with acquisition noise and 1920x1080 frames in its variety: 85 % and
    90 %: 36.4 dB / 0.982 (push-pull 31.9, input 25.0); 95 %: 44.1 / 0.995
    (push-pull 34.2, input 33.7). With the depth planes (stop 48): 35.6 /
    0.981 and 43.3 / 0.995; and 32^3 volumes in the variety (stop 49): 36.0 /
    0.982 and 43.9 / 0.995. The model before: 36.5 / 0.983 and 43.8 /
    0.995; without the plane: 36.3 / 0.982 and 43.1 / 0.995; the model
    before that: 35.7 / 0.981 and 42.2 / 0.994.
    Before all three: 85 %: 35.3 (push-pull 29.9); 90 %: 41.3 (32.7); 95 %:
    45.6 (34.5)."""
    r = ci_rows["infill"]
    a, b, c = r["64^3 at 85%"], r["64^3 at 90%"], r["64^3 at 95%"]
    assert a["network"]["psnr"] > 25 and a["network"]["ssim"] > 0.95 and _margin(a, "pushpull") > 3
    assert _margin(b, "pushpull") > 3 and b["network"]["ssim"] > 0.975
    assert _margin(c, "pushpull") > 6 and c["network"]["ssim"] > 0.99


def test_ci_lidar_guard_on_the_terrain():
    """The smooth terrain at 3 %, 320 x 240 (never trained on), where the
    U-Net alone loses to push-pull (measured: 24.9 dB / 0.873 against
    push-pull's 30.05 / 0.885; the model before, trained on 1-pixel scans
    alone: 25.1 / 0.875): with its guard (clvis.post.guard, the
    default) the call takes push-pull there (30.05 / 0.885) and keeps the
    U-Net on the photographs (test_ci_lidar_on_photographs)."""
    case = ev.Case("terrain", (320, 240), 0.03)
    on, off = (ev.evaluate("lidar", cases=[case], guard=g, log=None)["rows"][0] for g in (True, False))
    # within 0.1 dB of the better of the U-Net alone and push-pull
    best = max(off["network"]["psnr"], on["pushpull"]["psnr"])
    assert on["network"]["psnr"] > best - 0.1 and _margin(on, "pushpull", "ssim") > -0.005
    for k in ("input", "pushpull"):  # the baselines do not depend on the guard
        assert on[k] == off[k]


def test_ci_infill_95_is_not_below_its_input(ci_rows):
    """Issue 21 §2 at 95 % on the CI frame. It was missed (a strict xfail):
    the network (45.6 dB) was 21 dB below the raw partial image (66.7 dB),
    whose running rays were nearly all background rays, many of them with no
    candidate block left, which it painted. Such a ray cannot hit and is now
    finished at once (traverse.cl), so 95 % is reached one pass earlier and
    no sure miss is shown as a hole: measured 44.1 dB against the input's
    33.7 (43.8 with the model before, 43.1 without the candidates plane, 42.2 with the model before
    that; the same pass's hits as the old 90 % frame, where the network had
    41.3). Running rays that will miss with candidates left can still be
    painted; this frame does not show it."""
    assert _margin(ci_rows["infill"]["64^3 at 95%"], "input") >= 0


def test_ci_lidar_on_photographs(ci_rows):
    """A town under a photograph (never trained on), 5 % scan, 320 x 240.
    Measured: 15.6 dB / 0.432 (push-pull 14.1 / 0.412, input 6.0; the
    model before: 15.7 / 0.431). The target's + 0.02 SSIM over push-pull is
    met by 0.020 only: not held."""
    r = ci_rows["lidar"]["5% scan"]
    assert _margin(r, "input") > 6 and _margin(r, "pushpull") > 1 and _margin(r, "pushpull", "ssim") > 0


def test_ci_narvis_on_a_jet(ci_rows):
    """A round jet (never trained on), hemisphere view, 128 x 128 at the
    training's particles a pixel. Measured (the kernel-prediction model):
    30.8 dB / 0.858 against GR (plain rasterization 23.7 / 0.733, push-pull
    13.8, classical splat 28.1 / 0.849; the U-Net shipped before it: 25.1 /
    0.784, 3.0 dB below the splat). The shipped model (two runs of 4000
    steps more): 32.2 / 0.911."""
    r = ci_rows["narvis"]["1x points"]
    assert r["network"]["psnr"] > 29 and _margin(r, "pushpull") > 6


def test_ci_narvis_meets_its_targets_on_a_jet(ci_rows):
    """Issue 21 §2 on the CI jet: not below the classical splat, 6 dB over
    the plain rasterization, SSIM >= 0.82 (met: +2.7 dB, +7.1 dB, 0.858;
    the shipped model +4.0 dB, +8.5 dB, 0.911)."""
    r = ci_rows["narvis"]["1x points"]
    assert _margin(r, "splat") >= 1 and _margin(r, "splat", "ssim") >= 0
    assert _margin(r, "raster") >= 6 and r["network"]["ssim"] >= 0.82


def test_ci_narvis_scan_on_an_aerial_scan(ci_rows):
    """A LAS-like aerial strip scan (a generator never in its training), one
    view at 128 x 128, 4 points a pixel, against the 3DGS splat of its
    isotropic kNN Gaussians. Measured (the shipped narvis-scan, whose last
    run trained on depth-filtered frames): 30.67 dB / 0.870 (the models
    before it: 30.55 / 0.870, 30.21 / 0.867, 28.85 / 0.848 and 29.07 /
    0.845; the classical splat with the radius plane 24.36 / 0.727,
    push-pull 16.30 / 0.537, plain rasterization 13.25 / 0.238); its depth
    filter removes no point of this view, so the splat of the filtered
    G-buffers is the splat's. Its full suite has no row below (the least
    margin: aerial 256 x 256 at 1x, +2.68 dB / +0.040)."""
    r = ci_rows["narvis-scan"]["1x points"]
    assert r["network"]["psnr"] > 28 and r["network"]["ssim"] > 0.82
    assert _margin(r, "splat") > 3.5 and _margin(r, "splat", "ssim") > 0.08
    assert _margin(r, "filtered-splat") > 3.5 and _margin(r, "filtered-splat", "ssim") > 0.08
    assert _margin(r, "raster") > 6 and _margin(r, "pushpull") > 6


def test_narvis_scan_reads_the_depth_filtered_gbuffers():
    """narvis-scan's suite gives the network its pipeline's input: the
    G-buffers through the spec's depth filter (on a close view of the
    scanned object its far side shows through the near surface's gaps and
    the filter empties those pixels), and scores the splat of the same
    filtered G-buffers beside the splat of the raw ones; with the filter
    off (depth_filter=None) the network reads the raw G-buffers."""
    from clvis.training import data

    planes = json.loads((post.MODELS / "narvis-scan.json").read_text())["architecture"]["planes"]
    case = ev.Case("object", (96, 96), 0.25, "views", 2)
    filtered = list(ev._frames("narvis-scan", case, 5, planes))
    raw = list(ev._frames("narvis-scan", case, 5, planes, depth_filter=None))
    removed = 0
    for (_, x, t, base), (_, x0, t0, base0) in zip(filtered, raw, strict=True):
        assert set(base) == set(ev.BASELINES["narvis-scan"]) and set(base0) == set(base) - {"filtered-splat"}
        np.testing.assert_array_equal(t, t0)
        np.testing.assert_array_equal(base["splat"], base0["splat"])
        n = x.stats["depth_filter_removed"]
        removed += n
        assert "depth_filter_removed" not in x0.stats
        assert np.asarray(x.covered).sum() == np.asarray(x0.covered).sum() - n
        # the filtered splat is the splat of the network's input
        cov = np.asarray(x.covered)
        rgb = np.where(cov[..., None], np.asarray(x.rgba)[..., :3] / np.float32(255), 0).astype(np.float32)
        want = ev.splat(rgb, cov, None, opacity=data.SCAN_OPACITY, sigma=np.asarray(x.radius_px))
        np.testing.assert_array_equal(base["filtered-splat"], want)
    assert removed > 0


@pytest.mark.parametrize(
    "name, case",
    [
        ("narvis", ev.Case("ring", (48, 40), 0.25, "hemisphere", frames=1)),
        ("narvis-scan", ev.Case("object", (48, 40), 0.25, "views", frames=1)),
    ],
)
def test_eval_gives_each_case_scene_buffers_back(name, case):
    """`clvis eval narvis` renders 40 cases' scenes one after another in one
    process; the default queue's memory pool kept a freed block of each
    size, so the full suite grew past 21 GB here and was killed. After each
    case nothing is held back and no array is left alive."""
    from clvis import runtime

    pool = runtime.allocator(runtime.default_queue())
    planes = json.loads((post.MODELS / f"{name}.json").read_text())["architecture"]["planes"]
    active = pool.active_blocks
    for seed in (1, 2):
        frames = 0
        for _label, _x, target, _base in ev._frames(name, case, seed, planes):
            frames += 1
            assert target.shape == (40, 48, 3)
        assert frames == 1
        assert pool.held_blocks == 0 and pool.active_blocks == active


def test_write_card_needs_the_model_dir(tmp_path, monkeypatch, capsys):
    """`clvis eval NAME --write-card` without --model-dir rewrote the shipped
    card, clvis/post/models/NAME.json: a pip-installed clvis's own file.
    Now it is refused before scoring, with the line that writes the
    shipped card on purpose (the release flow: --model-dir naming their
    folder), which records the command as before; another folder's card
    records --model-dir."""
    from clvis.post import infer

    shipped, mine = tmp_path / "shipped", tmp_path / "mine"
    for d in (shipped, mine):
        d.mkdir()
        (d / "infill.json").write_bytes((post.MODELS / "infill.json").read_bytes())
    monkeypatch.setattr(infer, "MODELS", shipped)  # the package's folder, as the CLI finds it
    calls = []

    def scored(name, model_dir=None, quick=False, **kw):
        calls.append(model_dir)
        return {"model": name, "rows": [], "seconds": 1.0, "quick": quick, "guard": False}

    monkeypatch.setattr(ev, "evaluate", scored)
    before = (shipped / "infill.json").read_bytes()
    assert main(["eval", "infill", "--quick", "--write-card", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err == (
        "clvis eval: error: --write-card: give --model-dir DIR, the folder of the card to write; the "
        f"shipped infill card is the installed package's (to rewrite it on purpose: --model-dir {shipped})\n"
    )
    assert calls == [] and (shipped / "infill.json").read_bytes() == before
    with pytest.raises(ValueError, match="model_dir: the folder of the card to write"):
        ev.write_card(scored("infill"), None)
    assert (shipped / "infill.json").read_bytes() == before
    for d, command in (
        (shipped, ["clvis", "eval", "infill", "--quick"]),
        (mine, ["clvis", "eval", "infill", "--model-dir", str(mine), "--quick"]),
    ):
        assert main(["eval", "infill", "--model-dir", str(d), "--quick", "--write-card", "--quiet"]) == 0
        assert f"card: {d / 'infill.json'}" in capsys.readouterr().out
        assert json.loads((d / "infill.json").read_text())["held_out_suite"]["command"] == command


def test_write_card_holds_the_folder_as_clvis_train_does(tmp_path, monkeypatch, capsys):
    """`clvis eval NAME --model-dir DIR --write-card` holds NAME in DIR (clvis
    train's lock) from before the model is read until its table is in the
    card: while a clvis train of NAME writes there it is refused, naming the
    run, before scoring (it scored the old model and wrote its table into
    the card of the new one); while it scores, a clvis train of NAME into DIR
    is refused naming it; the lock file goes with it. Another network is not
    held up."""
    from clvis.training import train

    d = tmp_path / "mine"
    d.mkdir()
    (d / "infill.json").write_bytes((post.MODELS / "infill.json").read_bytes())
    seen = []

    def scored(name, model_dir=None, quick=False, **kw):
        # scoring: a training run of the same network into the folder is refused, naming this
        with pytest.raises(ClvisError) as e:
            with train.claim(Path(model_dir), name, lambda s: None):
                pass
        seen.append(str(e.value))
        with train.claim(Path(model_dir), "lidar", lambda s: None):  # another network: not held up
            pass
        return {"model": name, "rows": [], "seconds": 1.0, "quick": quick, "guard": False}

    monkeypatch.setattr(ev, "evaluate", scored)
    argv = ["eval", "infill", "--model-dir", str(d), "--quick", "--write-card", "--quiet"]
    with train.claim(d, "infill", lambda s: None):  # a clvis train of infill writing there
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith(
            f"clvis eval: error: {d}: another clvis train infill is writing its model there (pid "
        )
        assert err.endswith("; wait for it to end, or give another --model-dir\n") and seen == []
    before = json.loads((d / "infill.json").read_text()).get("held_out_suite")
    assert main(argv) == 0
    assert len(seen) == 1 and seen[0].startswith(
        f"{d}: another clvis eval --write-card infill is writing its card there (pid "
    ), seen
    assert seen[0].endswith("; wait for it to end, or give another --out")
    after = json.loads((d / "infill.json").read_text())["held_out_suite"]
    assert after != before and after["rows"] == [] and not list(d.glob(".*.train.lock"))
