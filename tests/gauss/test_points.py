"""Gaussians from point clouds (clvis.gauss.points): anisotropic along the
velocity, isotropic with kNN sizes, rotation frames, bad input."""

import numpy as np
import pytest

import clvis
from clvis.gauss.points import (
    KNN_CLAMP_PERCENTILE,
    frames_along,
    gaussians_from_points,
    knn_mean_distance,
    knn_sigma,
)
from clvis.io import PointCloud


def test_points_anisotropic():
    rng = np.random.default_rng(1)
    pos = rng.normal(size=(200, 3))
    vel = rng.normal(size=(200, 3))
    vel[0] = 0
    g = gaussians_from_points(pos, velocity=vel, stretch=250.0, scale=0.01)
    axis = g.rotations[:, :, 0]
    unit = vel / np.maximum(np.linalg.norm(vel, axis=1, keepdims=True), 1e-30)
    np.testing.assert_allclose(np.abs((axis[1:] * unit[1:]).sum(axis=1)), 1, atol=1e-6)
    np.testing.assert_allclose(g.scales[1:], np.tile([2.5, 0.01, 0.01], (199, 1)), rtol=1e-6)
    np.testing.assert_allclose(g.scales[0], [0.01] * 3, rtol=1e-6)  # zero velocity: isotropic
    np.testing.assert_allclose(g.values, np.linalg.norm(vel, axis=1), rtol=1e-6)
    cov = g.covariances[5].astype(np.float64)
    u = unit[5]
    assert np.isclose(u @ cov @ u, 2.5**2, rtol=1e-4)


def test_points_anisotropic_default_keeps_the_point_spacing_across():
    """Without a scale, a velocity-elongated Gaussian is as wide as the median
    4-NN distance across the flow and STRETCH (NARVis's) times that along it;
    it was the spacing along and the spacing / 250 across: needles that left
    `clvis gauss` of a velocity cloud almost blank."""
    from clvis.gauss.points import STRETCH
    from clvis.training.data import NARVIS_STRETCH

    rng = np.random.default_rng(5)
    pos = rng.uniform(size=(400, 3))
    g = gaussians_from_points(pos, velocity=rng.normal(size=(400, 3)))
    spacing = float(np.median(knn_mean_distance(pos)))
    assert STRETCH == NARVIS_STRETCH == 4.0
    np.testing.assert_allclose(g.scales, np.tile([STRETCH * spacing, spacing, spacing], (400, 1)), rtol=1e-5)
    g8 = gaussians_from_points(pos, velocity=rng.normal(size=(400, 3)), stretch=8)
    np.testing.assert_allclose(g8.scales[:, 0], 8 * spacing, rtol=1e-5)


def test_points_isotropic_knn():
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(2)
    pos = rng.uniform(size=(300, 3))
    g = gaussians_from_points(pos)
    d, _ = cKDTree(pos).query(pos, k=5)
    knn = d[:, 1:].mean(axis=1)
    np.testing.assert_allclose(g.scales[:, 0], np.minimum(knn, np.percentile(knn, 95)), rtol=1e-5)
    assert (g.scales[:, 0] == g.scales[:, 2]).all()
    assert knn_mean_distance(pos[:1]).tolist() == [0.0]
    cloud = PointCloud(pos, attributes={"intensity": np.arange(300.0)}, velocity=rng.normal(size=(300, 3)))
    g2 = gaussians_from_points(cloud, velocity="cloud", values="intensity")
    np.testing.assert_array_equal(g2.values, np.arange(300, dtype=np.float32))


def test_knn_distance_is_each_points_own_whatever_the_query_order():
    """knn_mean_distance queries in the k-d tree's leaf order and scatters the
    answers back: every point gets its own neighbours' mean distance, exactly
    (brute force over all pairs of distinct points), copies of a point (the
    origin three times) and a line of points included: copies are one point."""
    rng = np.random.default_rng(9)
    pos = np.concatenate(
        [rng.uniform(size=(400, 3)), np.zeros((3, 3)), np.c_[np.arange(20.0), np.zeros((20, 2))]]
    )
    pos = pos[rng.permutation(len(pos))]
    d = np.sqrt(((pos[:, None, :] - pos[None, :, :]) ** 2).sum(-1))
    d[d == 0] = np.inf  # a point's copies are the point (its own distance too)
    brute = np.sort(d, axis=1)[:, :4].mean(axis=1).astype(np.float32)
    got = knn_mean_distance(pos)
    np.testing.assert_allclose(got, brute, rtol=1e-6, atol=1e-7)
    origin = np.all(pos == 0, axis=1)
    assert origin.sum() == 4 and (got[origin] == got[origin][0]).all() and got[origin][0] > 0


def test_isolated_points_are_clamped():
    """A dense cloud and a few far outliers: the outliers' kNN distance is their
    gap to the scene (~100), not the sampling; clamped to the 95th percentile
    of the kNN distances, they are no wider than the cloud's own Gaussians."""
    rng = np.random.default_rng(4)
    dense = rng.uniform(0, 1, (2000, 3))
    outliers = np.array([[100.0, 0, 0], [0, -80.0, 0], [0, 0, 120.0], [60.0, 60.0, 60.0]])
    pos = np.concatenate([dense, outliers])
    g = gaussians_from_points(pos)
    knn = knn_mean_distance(pos)
    assert knn[-4:].min() > 50  # unclamped: huge
    cap = np.percentile(knn, KNN_CLAMP_PERCENTILE)
    assert cap < 0.2
    np.testing.assert_allclose(g.scales[-4:], cap, rtol=1e-6)
    assert g.scales.max() <= cap * (1 + 1e-6)
    np.testing.assert_allclose(g.scales[:-4, 0], np.minimum(knn[:-4], cap), rtol=1e-5)  # float32 positions
    lo, hi = g.bounds()
    extent = pos.max(axis=0) - pos.min(axis=0)
    assert ((hi - lo) <= extent + 6 * cap * 1.001).all()  # the points plus 3 sigma, not 3 x 100 more


def test_colours_and_attributes():
    rng = np.random.default_rng(5)
    pos = rng.uniform(size=(100, 3))
    rgb = rng.integers(0, 256, (100, 3)).astype(np.uint8)
    inten = rng.uniform(0, 500, 100)
    cloud = PointCloud(pos, colors=rgb, attributes={"intensity": inten})
    g = gaussians_from_points(cloud)  # colours by default
    np.testing.assert_array_equal(g.colors, rgb)
    np.testing.assert_array_equal(g.values, pos[:, 2].astype(np.float32))  # elevation: never all zero
    g = gaussians_from_points(cloud, color_by="intensity")
    assert g.colors is None
    np.testing.assert_array_equal(g.values, inten.astype(np.float32))
    np.testing.assert_array_equal(gaussians_from_points(cloud, color_by="rgb").colors, rgb)
    z = pos[:, 2].astype(np.float32)
    np.testing.assert_array_equal(gaussians_from_points(cloud, color_by="z").values, z)
    assert gaussians_from_points(cloud, values="intensity").colors is None  # values given: tf colours
    plain = gaussians_from_points(PointCloud(pos))  # no colours: elevation
    assert plain.colors is None and plain.values.std() > 0
    np.testing.assert_array_equal(gaussians_from_points(pos).values, pos[:, 2].astype(np.float32))
    with pytest.raises(ValueError, match="no attribute 'nope'.*intensity"):
        gaussians_from_points(cloud, color_by="nope")
    with pytest.raises(ValueError, match="no colours"):
        gaussians_from_points(PointCloud(pos), color_by="rgb")
    with pytest.raises(ValueError, match="one of them"):
        gaussians_from_points(cloud, color_by="z", values=np.zeros(100))
    with pytest.raises(TypeError, match="color_by"):
        gaussians_from_points(cloud, color_by=3)


@pytest.mark.parametrize(
    "k,error",
    [
        (0, ValueError),
        (-1, ValueError),
        (65, ValueError),
        (10**9, ValueError),
        (2.5, TypeError),
        ("4", TypeError),
        (True, TypeError),
    ],
)
def test_bad_k(k, error):
    with pytest.raises(error, match="k"):
        gaussians_from_points(np.zeros((5, 3)), k=k)
    with pytest.raises(error, match="k"):
        knn_mean_distance(np.zeros((5, 3)), k=k)


def test_ctrl_c_during_the_knn_tree_build_lands_before_the_build_ends(monkeypatch):
    """A SIGINT 50 ms into cKDTree's build (C, GIL released) raises
    KeyboardInterrupt while the build still runs: the build waited for it
    (~3.6 s at 2M points under load: clvis render --post narvis, the viewer's radii)."""
    import os
    import signal
    import threading
    import time

    import scipy.spatial

    real = scipy.spatial.cKDTree
    built = threading.Event()
    ended: list[float] = []

    def tree(p, *a, **kw):
        threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT)).start()
        try:
            return real(p, *a, **kw)
        finally:
            ended.append(time.perf_counter())
            built.set()

    monkeypatch.setattr(scipy.spatial, "cKDTree", tree)
    p = np.random.default_rng(0).random((600_000, 3))
    # Python's own handler, whatever this process was started with (a shell's
    # background job starts with SIGINT ignored)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            knn_mean_distance(p)
        interrupted = time.perf_counter()
    finally:
        signal.signal(signal.SIGINT, previous)
    assert built.wait(60)  # the build ends in the background; its result is dropped
    assert interrupted < ended[0], f"the interrupt came {interrupted - ended[0]:.2f} s after the build"


def test_non_finite_velocity_or_attribute_names_the_first_point():
    # the message said "velocity: NaN or infinite components", no point; an
    # infinite attribute "values: row 77", not which attribute
    from clvis.io import PointCloud

    rng = np.random.default_rng(0)
    p = rng.random((50, 3))
    v = rng.random((50, 3))
    v[[12, 30], 1] = np.nan, np.inf
    with pytest.raises(
        clvis.DataError, match=r"velocity: point 12 is \[.*, nan, .*\], not finite \(2 of 50 points\)"
    ):
        gaussians_from_points(PointCloud(p, velocity=v), velocity="cloud")
    t = rng.random(50)
    t[7] = -np.inf
    cloud = PointCloud(p, velocity=rng.random((50, 3)), attributes={"temp": t})
    for kw in ({"color_by": "temp"}, {"values": "temp"}):
        with pytest.raises(clvis.DataError, match=r"attribute 'temp': point 7 is -inf, not finite \(1 of 50"):
            gaussians_from_points(cloud, velocity="cloud", **kw)


def test_points_bad_input():
    with pytest.raises(clvis.DataError, match="point 1"):
        gaussians_from_points(np.array([[0, 0, 0], [np.nan, 0, 0]]))
    with pytest.raises(ValueError, match="velocity"):
        gaussians_from_points(np.zeros((3, 3)), velocity=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="stretch"):
        gaussians_from_points(np.zeros((3, 3)), velocity=np.ones((3, 3)), stretch=0)
    with pytest.raises(ValueError, match="cloud"):
        gaussians_from_points(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="no velocity"):
        gaussians_from_points(PointCloud(np.zeros((3, 3))), velocity="cloud")
    with pytest.raises(TypeError, match="real numbers"):
        gaussians_from_points(np.zeros((3, 3), np.complex64))
    with pytest.raises(TypeError, match="read_points"):
        gaussians_from_points("scan.las")


def test_frames_are_rotations():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(100, 3))
    v[:3] = [[0, 0, 0], [1, 0, 0], [0, 0, -2]]
    r = frames_along(v).astype(np.float64)
    np.testing.assert_allclose(
        np.einsum("nji,njk->nik", r, r), np.broadcast_to(np.eye(3), (100, 3, 3)), atol=1e-6
    )
    np.testing.assert_allclose(np.linalg.det(r), 1, atol=1e-6)


@pytest.mark.parametrize("f", [knn_mean_distance, knn_sigma], ids=lambda f: f.__name__)
def test_knn_bad_positions(f):
    """The kNN radius names what is wrong with its positions (it fed scipy's
    'data must be finite' to the CLI) and never returns a NaN or inf."""
    with pytest.raises(
        clvis.DataError, match=r"positions: point 1 has a NaN or infinite coordinate \(1 of 3"
    ):
        f(np.array([[0, 0, 0], [np.nan, 0, 0], [1, 1, 1]]))
    with pytest.raises(clvis.DataError, match="point 2 has a NaN or infinite"):
        f(np.array([[0, 0, 0], [1, 0, 0], [0, -np.inf, 1]], np.float32))
    with pytest.raises(clvis.DataError, match="overflow float32"):
        f(np.array([[1.7e308, 0, 0], [-1.7e308, 0, 0], [0, 0, 0]]))
    with pytest.raises(clvis.DataError, match="overflow float32"):
        f(np.array([[3e38, 0, 0], [-3e38, 0, 0]], np.float32))
    for bad in (np.zeros((4, 2)), np.zeros(3), np.zeros((2, 3, 1))):
        with pytest.raises(ValueError, match=r"positions: expected shape \(N, 3\)"):
            f(bad)
    for bad in ("abc", np.array([[None, None, None]]), np.zeros((2, 3), bool), None):
        with pytest.raises(TypeError, match="positions: expected"):
            f(bad)


@pytest.mark.parametrize("f", [knn_mean_distance, knn_sigma], ids=lambda f: f.__name__)
def test_knn_degenerate_clouds(f):
    """Fewer points than k + 1, duplicates (zero distances), a single point,
    none: finite, >= 0, the mean over the neighbours there are."""
    assert f(np.zeros((0, 3))).shape == (0,)
    np.testing.assert_array_equal(f(np.ones((1, 3))), [0])
    np.testing.assert_array_equal(f(np.ones((1000, 3))), np.zeros(1000))
    d = f(np.array([[0, 0, 0], [3, 0, 0]], np.float32))
    np.testing.assert_allclose(d, [3, 3])
    four = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 4]], np.float64)
    d = f(four, 4)  # 3 neighbours each, not 4
    assert np.isfinite(d).all() and (d > 0).all()
    np.testing.assert_allclose(knn_mean_distance(four, 4)[0], (1 + 2 + 4) / 3, rtol=1e-6)
    # each point five times (merged scans): the copies are one point, so its
    # Gaussian is as wide as the single cloud's (they were 0: nothing drawn)
    single = np.random.default_rng(0).random((50, 3))
    # (knn_sigma's clamp, a percentile over every point, moves by the interpolation alone)
    np.testing.assert_allclose(f(np.repeat(single, 5, axis=0), 4), np.repeat(f(single, 4), 5), rtol=1e-4)
    # distance 0 without being copies (the square underflows): merged once, not forever
    tiny = np.array([[0.0, 0.0, 0.0], [1e-200, 0.0, 0.0], [1.0, 1.0, 1.0]])
    assert np.isfinite(f(tiny, 1)).all()
    g = gaussians_from_points(np.ones((10, 3)))  # one distinct point: a width a view shows (next test)
    assert np.isfinite(g.scales).all() and (np.asarray(g.scales) > 0).all()


def test_one_distinct_point_gets_a_gaussian_a_view_shows():
    """One point, or copies of one point, have no spacing to size their
    Gaussians by: sigma was 0, a Gaussian of no width, and clvis gauss drew
    an empty picture. Now sigma is the smallest extent a camera frames
    around the point (clvis.camera.min_extent), isotropic and along a
    velocity alike; a cloud of two distinct points keeps its spacing."""
    from clvis.camera import min_extent

    one = np.array([[1.0, 2.0, 3.0]], np.float32)
    for cloud in (one, np.repeat(one, 50, axis=0)):
        g = gaussians_from_points(cloud)
        np.testing.assert_allclose(g.scales, min_extent(cloud[0]), rtol=1e-6)
        v = gaussians_from_points(cloud, velocity=np.tile([1.0, 0.0, 0.0], (len(cloud), 1)))
        assert (v.scales > 0).all()
    two = gaussians_from_points(np.array([[0, 0, 0], [2, 0, 0]], np.float32))
    np.testing.assert_allclose(two.scales, 2.0)
