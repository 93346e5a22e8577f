"""Gaussians from point clouds (clvis.gauss.points): anisotropic along the
velocity, isotropic with kNN sizes, rotation frames, bad input."""

import numpy as np
import pytest

import clvis
from clvis.gauss.points import frames_along, gaussians_from_points, knn_mean_distance
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
    np.testing.assert_allclose(g.scales[0], [0.01] * 3, rtol=1e-6)       # zero velocity: isotropic
    np.testing.assert_allclose(g.values, np.linalg.norm(vel, axis=1), rtol=1e-6)
    cov = g.covariances[5].astype(np.float64)
    u = unit[5]
    assert np.isclose(u @ cov @ u, 2.5 ** 2, rtol=1e-4)


def test_points_isotropic_knn():
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(2)
    pos = rng.uniform(size=(300, 3))
    g = gaussians_from_points(pos)
    d, _ = cKDTree(pos).query(pos, k=5)
    np.testing.assert_allclose(g.scales[:, 0], d[:, 1:].mean(axis=1), rtol=1e-5)
    assert (g.scales[:, 0] == g.scales[:, 2]).all()
    assert knn_mean_distance(pos[:1]).tolist() == [0.0]
    cloud = PointCloud(pos, attributes={"intensity": np.arange(300.0)}, velocity=rng.normal(size=(300, 3)))
    g2 = gaussians_from_points(cloud, velocity="cloud", values="intensity")
    np.testing.assert_array_equal(g2.values, np.arange(300, dtype=np.float32))


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


def test_frames_are_rotations():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(100, 3))
    v[:3] = [[0, 0, 0], [1, 0, 0], [0, 0, -2]]
    r = frames_along(v).astype(np.float64)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", r, r), np.broadcast_to(np.eye(3), (100, 3, 3)),
                               atol=1e-6)
    np.testing.assert_allclose(np.linalg.det(r), 1, atol=1e-6)
