"""clvis.post.guard: the in-fill and LiDAR networks' self-check against
their classical fills (withheld pixels, per-tile scores, bilinear weights),
on synthetic frames with stand-in networks (garbage ones fall back to
push-pull, perfect ones are kept), and through PostNetwork's call."""

import time

import numpy as np
import pytest

from clvis import post
from clvis.errors import DataError
from clvis.post import guard
from clvis.training import data


def _psnr(a, b):
    return float(10 * np.log10(1 / np.mean((np.clip(a, 0, 1) - b) ** 2)))


def test_withheld_is_a_fixed_hashed_subset_of_the_known_pixels():
    rng = np.random.default_rng(0)
    known = rng.random((200, 300)) < 0.4
    a = guard.withheld(known, 0.1)
    np.testing.assert_array_equal(a, guard.withheld(known.copy(), 0.1))  # no random state
    assert not (a & ~known).any()
    assert a.sum() == pytest.approx(0.1 * known.sum(), rel=0.1)
    assert guard.withheld(known, 0.2).sum() > 1.5 * a.sum()
    for bad in (0.0, 1.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="fraction"):
            guard.withheld(known, bad)


@pytest.mark.parametrize("size", [1, 2, 3])
def test_points_withheld_whole_by_their_index(size):
    """Points drawn size x size pixels, the later over the earlier, and a
    flat region where neighbouring points share one colour (what the
    values cannot tell apart): by the point index every pixel a withheld
    point shows goes with it, about the fraction of the points, none of the
    pixels not known, the same every run."""
    rng = np.random.default_rng(size)
    h, w, n = 120, 160, 2000
    index = np.full((h, w), 0xFFFFFFFF, np.uint32)
    ys, xs = rng.integers(0, h - size, n), rng.integers(0, w - size, n)
    for i, (y, x) in enumerate(zip(ys, xs, strict=True)):
        index[y : y + size, x : x + size] = i
    known = index != 0xFFFFFFFF
    held = guard.points_withheld(known, index, 0.1)
    assert not (held & ~known).any()
    taken = np.unique(index[held])
    for i in taken:
        np.testing.assert_array_equal(held[index == i], True)
    shown = np.unique(index[known])
    assert len(taken) == pytest.approx(0.1 * len(shown), rel=0.25)
    np.testing.assert_array_equal(held, guard.points_withheld(known.copy(), index.copy(), 0.1))
    assert guard.points_withheld(known, index, 0.3).sum() > 2 * held.sum()
    for bad in (0.0, 1.0, float("nan")):
        with pytest.raises(ValueError, match="fraction"):
            guard.points_withheld(known, index, bad)


def test_lidar_guard_withholds_whole_points_given_the_index(queue):
    """guard.lidar with the point index: the pixels withheld from the network's
    input are whole points (a FilteredImage's index), without it single pixels."""
    truth, rgbda, kept = _lidar_frame(96, 128)
    index = np.where(kept, (np.arange(kept.size).reshape(kept.shape) // 2).astype(np.uint32), 0xFFFFFFFF)
    seen = []

    def run(x):
        seen.append(x[..., 4] > 0)
        return x[..., :3]

    guard.lidar(run, rgbda, queue, index)
    withheld = [kept & ~k for k in seen if (kept & ~k).any()]
    assert withheld
    got = withheld[0]
    np.testing.assert_array_equal(got, guard.points_withheld(kept, index, guard.PARAMS["lidar"]["fraction"]))
    seen.clear()
    guard.lidar(run, rgbda, queue)
    assert any((kept & ~k).any() and not np.array_equal(kept & ~k, got) for k in seen)


def test_ring_withholds_the_known_pixels_beside_the_holes():
    holes = np.zeros((40, 40), bool)
    holes[20, 10:30] = True
    known = ~holes
    r = guard.ring(known, holes, 3)
    assert not (r & holes).any()
    assert r[17:24, 7:33].sum() == 7 * 26 - 20 and not r[:17].any() and not r[24:].any()
    assert not guard.ring(known, np.zeros_like(holes), 3).any()
    with pytest.raises(ValueError, match="width"):
        guard.ring(known, holes, 0)


def test_nearest_running_gives_finished_pixels_their_nearest_running_rays_count():
    active = np.zeros((5, 9), bool)
    active[2, 1] = active[2, 7] = True
    cand = np.zeros((5, 9), np.uint8)
    cand[2, 1], cand[2, 7] = 3, 9
    got = guard.nearest_running(cand, active)
    assert got.dtype == np.uint8 and got.shape == cand.shape
    np.testing.assert_array_equal(got[:, :4], 3)  # nearer (2, 1)
    np.testing.assert_array_equal(got[:, 5:], 9)  # nearer (2, 7)
    np.testing.assert_array_equal(got[active], cand[active])  # running rays keep their own
    # nothing running, or everything: the plane as it was (a copy)
    for a in (np.zeros_like(active), np.ones_like(active)):
        out = guard.nearest_running(cand, a)
        np.testing.assert_array_equal(out, cand)
        assert out is not cand
    with pytest.raises(ValueError, match="candidates"):
        guard.nearest_running(cand[:4], active)


def test_tile_weights_take_the_lowest_error_the_network_keeping_ties():
    mask = np.ones((64, 64), bool)
    e_net = np.full((64, 64), 1.0)
    e_pp = np.full((64, 64), 1.0)
    e_pp[:32, :32] = 0.1  # push-pull better in the first tile
    w = guard.tile_weights([e_net, e_pp], mask, tile=32, prior=0.0)
    assert w.shape == (2, 2, 2) and w.dtype == np.float32
    np.testing.assert_array_equal(w[1], [[1, 0], [0, 0]])  # ties stay with the network
    np.testing.assert_array_equal(w.sum(0), 1)
    # a margin: push-pull must beat the network's error by it
    e_pp[:32, :32] = 0.95
    assert guard.tile_weights([e_net, e_pp], mask, tile=32, prior=0.0, margin=0.1)[1].sum() == 0
    assert guard.tile_weights([e_net, e_pp], mask, tile=32, prior=0.0, margin=0.0)[1, 0, 0] == 1
    # a tile with nothing withheld follows the frame's own scores
    sparse = np.zeros((64, 64), bool)
    sparse[:32, :32] = True
    e_pp[:32, :32] = 0.1
    w = guard.tile_weights([e_net, e_pp], sparse, tile=32, prior=4.0)
    np.testing.assert_array_equal(w[1], 1)


def test_interpolated_weights_have_no_seams():
    w = np.zeros((2, 3, 4), np.float32)
    w[0] = 1
    w[:, 1, 2] = (0, 1)
    up = guard.interpolate(w, 90, 120, tile=32)
    assert up.shape == (2, 90, 120)
    np.testing.assert_allclose(up.sum(0), 1, atol=1e-6)
    assert up[1, 47:49, 79:81].min() > 0.96  # around a tile's centre (47.5, 79.5) its weight
    assert up[1, 5, 5] == 0 and up[1, 48, 40] == 0
    # bilinear between centres: a step of at most 1 / tile from pixel to pixel
    assert np.abs(np.diff(up[1], axis=0)).max() <= 1 / 32 + 1e-6
    assert np.abs(np.diff(up[1], axis=1)).max() <= 1 / 32 + 1e-6


def _smooth_picture(h, w):
    y, x = np.mgrid[0:h, 0:w] / np.float32(max(h, w))
    return np.stack([0.5 + 0.4 * np.sin(6 * x), 0.5 + 0.4 * np.cos(5 * y), 0.3 + 0.3 * x * y], -1).astype(
        np.float32
    )


def _lidar_frame(h=160, w=224, density=0.1):
    truth = _smooth_picture(h, w)
    kept = np.random.default_rng(3).random((h, w)) < density
    rgbda = np.zeros((h, w, 5), np.float32)
    rgbda[..., :3] = np.where(kept[..., None], truth, 0)
    rgbda[..., 3] = np.where(kept, 10.0, np.inf)
    rgbda[..., 4] = kept
    return truth, rgbda, kept


def test_lidar_guard_drops_a_garbage_network_for_pushpull(queue):
    """A network that outputs noise ends within 0.5 dB of push-pull; a
    perfect one is kept as it is."""
    truth, rgbda, kept = _lidar_frame()
    pp = np.asarray(post.pushpull(np.ascontiguousarray(rgbda[..., :3]), kept, queue=queue))
    rng = np.random.default_rng(1)
    garbage = lambda x: rng.random(truth.shape).astype(np.float32)  # noqa: E731
    out, share = guard.lidar(garbage, rgbda, queue)
    assert out.shape == truth.shape and share["pushpull"] > 0.95
    assert _psnr(out, truth) >= _psnr(pp, truth) - 0.5 and _psnr(garbage(None), truth) < 12
    perfect = lambda x: truth  # noqa: E731
    out, share = guard.lidar(perfect, rgbda, queue)
    assert share == {"network": 1.0, "pushpull": 0.0}
    np.testing.assert_array_equal(out, truth)


def test_lidar_guard_keeps_pushpull_off_the_empty_frame(queue):
    """Push-pull extrapolates a scan's colours into every empty pixel; the
    guard's push-pull candidate is black beyond its reach of every kept
    point (a cloud in the left third of the frame, the rest empty sky), so
    a tile that takes it paints no halo there, while the holes inside the
    cloud are filled."""
    from scipy.ndimage import distance_transform_edt

    h, w = 160, 448
    truth, rgbda, kept = _lidar_frame(h, w)
    kept[:, w // 3 :] = False
    rgbda[~kept] = (0, 0, 0, np.inf, 0)
    rng = np.random.default_rng(1)
    garbage = lambda x: rng.random(truth.shape).astype(np.float32)  # noqa: E731
    out, share = guard.lidar(garbage, rgbda, queue)
    assert share["pushpull"] > 0.95
    p = guard.PARAMS["lidar"]
    spacing = np.sqrt(kept.size / kept.sum())
    reach = max(guard.REACH_MIN, p["reach"] * w, p["spacing"] * spacing)
    d = distance_transform_edt(~kept)
    far = d > reach + 64  # past the reach and the blend's tile
    assert far.sum() > 0.4 * far.size and np.abs(out[far]).max() == 0.0
    pp = np.asarray(post.pushpull(np.ascontiguousarray(rgbda[..., :3]), kept, queue=queue))
    assert pp[far].max() > 0.1  # push-pull alone paints there
    inside = ~kept & (d < reach)
    inside[:, w // 3 - 64 :] = False  # away from the tiles that straddle the edge
    assert np.abs(out[inside] - truth[inside]).mean() < 0.05


def test_lidar_guard_leaves_no_fringe_beside_the_cloud_and_fills_its_holes(queue):
    """Within its reach of the cloud push-pull blurs the scan's colours out
    past the cloud's edge (a fringe as wide as the reach, 32 pixels at
    1280x720 on a real scan) as much as into its holes. Outside the cloud's
    footprint the guard's push-pull candidate is black nearer: farther than
    `edge` x the kept points' local spacing (2 pixels at this edge), while a
    hole inside the cloud narrower than twice the reach is filled as
    before."""
    from scipy.ndimage import distance_transform_edt

    h, w = 256, 768
    truth, rgbda, kept = _lidar_frame(h, w, density=0.5)
    y, x = np.mgrid[0:h, 0:w]
    kept &= x < w // 2
    hole = np.hypot(y - h / 2, x - w / 4) < 16  # 32 pixels across
    kept &= ~hole
    rgbda[~kept] = (0, 0, 0, np.inf, 0)
    garbage = lambda x: np.full(truth.shape, 0.5, np.float32)  # noqa: E731
    out, share = guard.lidar(garbage, rgbda, queue)
    assert share["pushpull"] > 0.95
    p = guard.PARAMS["lidar"]
    reach = max(guard.REACH_MIN, p["reach"] * w, p["spacing"] * np.sqrt(kept.size / kept.sum()))
    edge = p["edge"] * np.sqrt(1 / (0.5 * 0.5))  # half the window kept, at half the density
    assert reach > 19 and edge < 7
    d = distance_transform_edt(~kept)
    pp = np.asarray(post.pushpull(np.ascontiguousarray(rgbda[..., :3]), kept, queue=queue))
    fringe = (x >= w // 2) & (d > edge + 3) & (d < reach - 2)  # 2-3: the 2 x 2 blocks' rounding
    fringe[:64] = fringe[-64:] = False  # away from the tiles that straddle the cloud's corners
    assert fringe.sum() > 500 and pp[fringe].min() > 0.1  # push-pull alone paints there
    assert np.abs(out[fringe]).max() == 0.0
    assert np.abs(out[hole] - truth[hole]).mean() < 0.1 and out[hole].sum(-1).min() > 0.1


def _iso_frame(h=144, w=192, band=3):
    """A shaded disc on black, the rays in a band around its rim running."""
    y, x = np.mgrid[0:h, 0:w]
    r = np.hypot(y - h / 2, x - w / 2)
    rim = min(h, w) / 3
    hit = r < rim
    truth = np.where(hit[..., None], _smooth_picture(h, w), 0).astype(np.float32)
    active = np.abs(r - rim) < band
    rgba = np.concatenate([truth, hit[..., None].astype(np.float32)], -1)
    rgba[active] = 0
    return truth, rgba, hit & ~active, active


def test_infill_guard_drops_a_garbage_network_and_keeps_a_perfect_one(queue):
    truth, rgba, hit, active = _iso_frame()
    rng = np.random.default_rng(2)

    def garbage(values, hit_, active_):
        return np.where(active_[..., None], rng.random(values.shape, np.float32), values)

    out, share = guard.infill(garbage, rgba, hit, active, queue)
    pp = np.asarray(post.pushpull(rgba, ~active, queue=queue))
    assert out.shape == rgba.shape and share["network"] < 0.05
    assert _psnr(out[..., :3], truth) >= _psnr(pp[..., :3], truth) - 0.5
    np.testing.assert_array_equal(out[~active], rgba[~active])  # the finished rays, exactly

    full = np.concatenate([truth, (np.abs(truth).sum(-1) > 0)[..., None]], -1).astype(np.float32)

    def perfect(values, hit_, active_):
        return np.where(active_[..., None], full, values)

    out, share = guard.infill(perfect, rgba, hit, active, queue)
    assert share["network"] == 1.0
    np.testing.assert_array_equal(out, full)


def _iso_input():
    f = data.iso_frames(("shapes",), 1, 7, 160, 96, views=1, n=32)[0]
    rgba, hit, active = f.planes(0.9)
    return f, post.IsoPlanes(
        rgba, hit, active, f.candidates_at(0.9), f.crossing_rate(0.9), f.t, f.next_t[0.9]
    )


def test_network_call_with_the_guard(queue):
    f, x = _iso_input()
    net = post.load("infill", queue=queue, threads=1)
    a = net(x, guard=True)
    assert {"pack", "inference", "unpack", "guard", "guard_network", "guard_pushpull", "guard_input"} <= set(
        net.stats
    )
    t0 = time.perf_counter()
    b = net(x, guard=True)
    wall = time.perf_counter() - t0
    # the stages split the call's time: none counted twice
    assert sum(net.stats[k] for k in ("pack", "inference", "unpack", "guard")) <= wall
    np.testing.assert_array_equal(a, b)  # deterministic
    assert a.shape == (96, 160, 4) and a.dtype == np.uint8
    plain = net(x, guard=False)
    done = ~x.active
    np.testing.assert_array_equal(a[done], plain[done])  # the finished rays as the network leaves them
    assert net(x).tolist() == (a if net.guard else plain).tolist()
    with pytest.raises(TypeError, match="guard"):
        net(x, guard="yes")
    with pytest.raises(TypeError, match="IsoImage"):
        net(np.zeros((8, 8, 4), np.float32), guard=True)
    bad = post.IsoPlanes(x.rgba.copy(), x.hit, x.active)
    bad.rgba[x.hit & done] = np.nan
    with pytest.raises(DataError, match="NaN"):
        net(bad, guard=True)


def test_guarded_call_runs_withheld_rays_with_their_nearest_running_rays_count(queue, monkeypatch):
    # the withheld finished rays go to the network as running ones: with the
    # count of blocks left of the nearest running ray, not their own 0 (to the
    # network, a ray with no block left misses)
    f, x = _iso_input()
    net = post.load("infill", queue=queue, threads=1)
    assert net.channels_in >= 6
    seen = []
    host = net._host

    def spy(planes):
        seen.append((np.asarray(planes.active, bool).copy(), np.asarray(planes.candidates).copy()))
        return host(planes)

    monkeypatch.setattr(net, "_host", spy)
    net(x, guard=True)
    active = np.asarray(x.active, bool)
    want = guard.nearest_running(np.asarray(x.candidates), active)
    reduced = [(a, c) for a, c in seen if (a & ~active).any()]
    assert reduced, "the guard ran the network on a reduced input"
    for a, c in reduced:
        held = a & ~active
        np.testing.assert_array_equal(c[a], want[a])
        assert (c[held] > 0).mean() > 0.5  # their running neighbours have blocks left
        np.testing.assert_array_equal(c[active], np.asarray(x.candidates)[active])


def test_lidar_network_call_with_the_guard(queue):
    _, rgbda, _ = _lidar_frame(96, 128)
    net = post.load("lidar", queue=queue, threads=1)
    a = net(rgbda, guard=True)
    assert a.shape == (96, 128, 4) and (a[..., 3] == 255).all()
    np.testing.assert_array_equal(a, net(rgbda, guard=True))
    with pytest.raises(ValueError, match=r"\(H, W, 5\)"):
        net(rgbda[..., :4], guard=True)


def _scan_planes(h=128, w=160, density=0.5):
    """G-buffer planes of a smooth picture drawn by about `density` of the
    pixels, each a point of sigma 1 pixel."""
    truth = _smooth_picture(h, w)
    covered = np.random.default_rng(4).random((h, w)) < density
    index = np.where(covered, np.arange(h * w, dtype=np.uint32).reshape(h, w), np.uint32(0xFFFFFFFF))
    rgba = np.zeros((h, w, 4), np.uint8)
    rgba[covered] = np.concatenate([np.rint(truth[covered] * 255), np.full((covered.sum(), 1), 255)], -1)
    radius = np.where(covered, np.float32(1.0), np.float32(np.nan)).astype(np.float32)
    return truth, index, rgba, radius


def test_narvis_scan_guard_drops_a_garbage_network_for_the_splat():
    """Scored on each candidate's own frame with some points withheld
    against its frame of them all: a network whose frame changes with the
    input's every point (noise) gives the frame to the classical splat; one
    whose frame is steady is kept as it is."""
    from clvis.post.splat import splat

    truth, index, rgba, radius = _scan_planes()
    covered = index != np.uint32(0xFFFFFFFF)
    rgb = np.where(covered[..., None], rgba[..., :3] / np.float32(255), 0).astype(np.float32)
    sp = splat(rgb, covered, None, opacity=0.8, sigma=radius)
    rng = np.random.default_rng(1)
    seen = []

    def garbage(ix):
        seen.append(int((ix != np.uint32(0xFFFFFFFF)).sum()))
        return rng.random(truth.shape).astype(np.float32)

    out, share = guard.narvis_scan(garbage, index, rgba, radius)
    assert share["splat"] > 0.95 and out.shape == truth.shape
    assert _psnr(out, truth) > _psnr(garbage(index), truth) + 5
    assert np.abs(out - sp).mean() < 0.01  # the splat's frame
    # the network ran on the full input and on it with a hashed share withheld
    frac = guard.PARAMS["narvis-scan"]["fraction"]
    assert seen[0] == covered.sum() and seen[1] == pytest.approx((1 - frac) * covered.sum(), rel=0.05)
    steady = lambda ix: truth  # noqa: E731
    out, share = guard.narvis_scan(steady, index, rgba, radius)
    assert share == {"network": 1.0, "splat": 0.0}
    np.testing.assert_array_equal(out, truth)
    with pytest.raises(TypeError, match="unknown"):
        guard.narvis_scan(steady, index, rgba, radius, ring=8)
    # the splat candidate draws the targets' opacity (post cannot import training)
    assert guard.PARAMS["narvis-scan"]["opacity"] == data.SCAN_OPACITY


def test_narvis_scan_network_call_with_the_guard(queue):
    """narvis-scan's call with its guard, on a real scan frame: the guard's
    stats, the same picture each time; the network's own default is the
    spec's."""
    from clvis.post.specs import spec

    sc = data.scan_scene("town", 12_000, 5)
    cam = data.scan_cameras(sc, np.random.default_rng(5), 1, 96 / 64)[0]
    net = post.load("narvis-scan", queue=queue, threads=1)
    g = sc.gbuffers(sc.rasterizer(queue=queue), cam, 96, 64, net.planes)
    assert net.guard is bool(spec("narvis-scan").guard)
    a = net(g, guard=True)
    assert a.shape == (64, 96, 4) and (a[..., 3] == 255).all()
    assert {"guard", "guard_network", "guard_splat"} <= set(net.stats)
    np.testing.assert_array_equal(a, net(g, guard=True))


def test_narvis_has_no_guard():
    net = post.load("narvis", threads=1)
    assert net.guard is False
    with pytest.raises(ValueError, match="no guard"):
        net(object(), guard=True)


def test_lidar_guard_reach_mask_on_empty_and_covered_frames():
    """The reach mask of a frame without a kept point is all far (push-pull
    has nothing to extrapolate); of a frame whose points are nowhere far
    apart, nothing is far nor outside the footprint (scipy's transform of an
    array without a zero is not a distance: a covered frame once came out
    with its border blacked)."""
    none = np.zeros((40, 64), bool)
    assert guard._beyond(none, 16.0, 3.0, guard.EDGE_MIN).all()
    covered = np.ones((64, 96), bool)
    covered[:, :12] = False  # a strip 12 pixels wide along the border: within the reach
    assert not guard._beyond(covered, 16.0, 3.0, guard.EDGE_MIN).any()
    one = np.zeros((40, 64), bool)
    one[20, 10] = True
    far = guard._beyond(one, 16.0, 3.0, guard.EDGE_MIN)
    assert far[20, 40] and not far[20, 12]  # far past the reach; the point's own neighbourhood kept
