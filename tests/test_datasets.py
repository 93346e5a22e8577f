"""clvis.datasets: shapes, determinism, and the physics the hurricane promises."""

import numpy as np
import pytest

from clvis import datasets

N = 200_000


@pytest.fixture(scope="module")
def storm():
    return datasets.hurricane(N, seed=3)


def _cylindrical(storm):
    p, v = storm["positions"].astype(np.float64), storm["velocity"].astype(np.float64)
    r = np.hypot(p[:, 0], p[:, 1])
    v_t = (p[:, 0] * v[:, 1] - p[:, 1] * v[:, 0]) / r
    u_r = (p[:, 0] * v[:, 0] + p[:, 1] * v[:, 1]) / r
    return r, p[:, 2], v_t, u_r, v[:, 2]


def _check_layout(d, n, attributes):
    assert d["positions"].shape == (n, 3) and d["positions"].dtype == np.float32
    assert d["colors"].shape == (n, 4) and d["colors"].dtype == np.uint8
    assert set(d["attributes"]) == set(attributes)
    for name, dtype in attributes.items():
        a = d["attributes"][name]
        assert a.shape == (n,) and a.dtype == dtype, name


@pytest.mark.parametrize("n", [0, 1, 2, 7, 1000])
def test_hurricane_layout(n):
    d = datasets.hurricane(n)
    _check_layout(d, n, {"pressure": np.float32, "temperature": np.float32, "speed": np.float32})
    assert d["velocity"].shape == (n, 3) and d["velocity"].dtype == np.float32


@pytest.mark.parametrize("n", [0, 1, 2, 7, 1000])
def test_terrain_layout(n):
    d = datasets.terrain(n)
    _check_layout(d, n, {"intensity": np.float32, "classification": np.uint8})
    assert d["velocity"] is None


@pytest.mark.parametrize("make", [datasets.hurricane, datasets.terrain])
def test_deterministic_per_seed(make):
    a, b, c = make(5000, seed=11), make(5000, seed=11), make(5000, seed=12)
    for key in ("positions", "colors"):
        np.testing.assert_array_equal(a[key], b[key])
    for name in a["attributes"]:
        np.testing.assert_array_equal(a["attributes"][name], b["attributes"][name])
    assert not np.array_equal(a["positions"], c["positions"])


def test_hurricane_finite_and_in_box(storm):
    for a in [storm["positions"], storm["velocity"], *storm["attributes"].values()]:
        assert np.isfinite(a).all()
    p = storm["positions"]
    assert (np.hypot(p[:, 0], p[:, 1]) <= 100.001).all()
    assert p[:, 2].min() >= 0 and p[:, 2].max() <= 15
    assert (storm["colors"][:, 3] == 255).all()
    speed = np.linalg.norm(storm["velocity"], axis=1)
    np.testing.assert_allclose(storm["attributes"]["speed"], speed, rtol=1e-6)


def test_hurricane_has_a_clear_eye(storm):
    r = np.hypot(storm["positions"][:, 0], storm["positions"][:, 1])
    assert (r > 20).all()
    assert np.mean(r < 50) > 0.4  # eyewall and inner bands hold most particles


def test_tangential_wind_peaks_near_radius_of_maximum_wind(storm):
    r, z, v_t, _, _ = _cylindrical(storm)
    low = z < 1.0
    edges = np.arange(20.0, 101.0, 5.0)
    which = np.digitize(r[low], edges) - 1
    mean = np.array([v_t[low][which == k].mean() for k in range(len(edges) - 1)])
    peak = edges[np.argmax(mean)] + 2.5
    assert abs(peak - datasets.R_MAX_WIND) <= 5.0
    assert mean[-1] < 0.6 * mean.max()  # decays outward
    assert 40 < mean.max() < 80  # m/s, a strong hurricane


def test_rotation_is_counter_clockwise_seen_from_above(storm):
    _, _, v_t, _, _ = _cylindrical(storm)
    assert np.mean(v_t > 0) > 0.99
    p, v = storm["positions"], storm["velocity"]
    assert np.mean(p[:, 0] * v[:, 1] - p[:, 1] * v[:, 0]) > 0  # z angular momentum


def test_inflow_below_outflow_aloft_updraft_in_eyewall(storm):
    r, z, _, u_r, w = _cylindrical(storm)
    assert u_r[z < 1.0].mean() < -3.0
    assert u_r[z > 13.0].mean() > 3.0
    assert w[(r < 45) & (z > 3) & (z < 10)].mean() > 0.5


def test_pressure_lowest_at_centre(storm):
    r, z, _, _, _ = _cylindrical(storm)
    p = storm["attributes"]["pressure"].astype(np.float64)
    low = z < 2.0
    # pressure ~ a + b z + c r near the surface: rises outward, falls upward
    (_, b, c), *_ = np.linalg.lstsq(
        np.stack([np.ones(low.sum()), z[low], r[low]], axis=1), p[low], rcond=None
    )
    assert c > 0 and b < 0
    assert r[np.argmin(np.where(low, p - b * z, np.inf))] < 40  # height-corrected minimum
    assert p.max() < 1010.0 and p[z < 0.1].min() > 930.0  # hPa, a deep but real low


def test_temperature_falls_with_height_and_core_is_warm(storm):
    r, z, _, _, _ = _cylindrical(storm)
    t = storm["attributes"]["temperature"]
    layer = np.minimum(z.astype(int), 14)
    means = np.array([t[layer == k].mean() for k in range(15)])
    assert (np.diff(means) < 0).all()
    upper = (z > 8) & (z < 12)
    assert t[upper & (r < 35)].mean() > t[upper & (r > 70)].mean() + 3.0


def test_terrain_classes_and_heights():
    d = datasets.terrain(50_000, seed=1)
    p, cls = d["positions"], d["attributes"]["classification"]
    assert set(np.unique(cls)) == {datasets.GROUND, datasets.HIGH_VEGETATION, datasets.BUILDING}
    assert np.isfinite(p).all()
    assert np.abs(p[:, :2]).max() <= 200.0
    ground = cls == datasets.GROUND
    assert p[~ground, 2].mean() > p[ground, 2].mean() + 5.0
    i = d["attributes"]["intensity"]
    assert i.min() >= 0 and i.max() <= 1
    assert (d["colors"][:, 3] == 255).all()


@pytest.mark.parametrize("make", [datasets.hurricane, datasets.terrain])
def test_bad_n(make):
    with pytest.raises(ValueError, match="n"):
        make(-1)
    for bad in (2.5, "10", True, None):
        with pytest.raises(TypeError, match="n"):
            make(bad)
    assert make(np.int64(3))["positions"].shape == (3, 3)


def test_explosion():
    e = datasets.explosion()
    v = e["volume"]
    assert v.shape == (96, 96, 96) and v.dtype == np.float32
    assert 0.05 < (v > 0).mean() < 0.3 and v.max() <= 1 and v.min() >= 0
    np.testing.assert_array_equal(v, datasets.explosion()["volume"])  # closed form: deterministic
    assert np.allclose(np.array(e["origin"]) + (np.array(v.shape[::-1]) - 1) * e["spacing"][::-1], 1.0)
    with pytest.raises(ValueError, match="shape"):
        datasets.explosion((1, 4, 4))
