"""clvis gauss and the demo's gauss part, the explosion dataset, and Gaussians
from point clouds."""

import numpy as np
import pytest
from PIL import Image

import clvis
from clvis import cli, datasets
from clvis.gauss.points import frames_along, gaussians_from_points, knn_mean_distance
from clvis.io import PointCloud, write_ply


def test_gauss_default(tmp_path, capsys):
    assert cli.main(["gauss", "--size", "64x48", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    for lod in ("low", "medium", "high"):
        assert lod in out
        with Image.open(tmp_path / f"{lod}.png") as im:
            assert im.size == (64, 48)
            assert np.asarray(im).std() > 1          # not blank
    with Image.open(tmp_path / "gauss.png") as im:
        assert im.size == (3 * 64, 48)


def test_gauss_files(tmp_path, capsys):
    e = datasets.explosion((20, 24, 28))
    np.save(tmp_path / "v.npy", e["volume"])
    assert cli.main(["gauss", str(tmp_path / "v.npy"), "--lod", "high", "--model", "max_response",
                     "--size", "32x32", "--out", str(tmp_path / "a")]) == 0
    assert (tmp_path / "a" / "high.png").is_file()
    g = clvis.gaussians_from_volume(e["volume"], lod="low", threshold=0.0)
    g.save(tmp_path / "g.npz")
    assert cli.main(["gauss", str(tmp_path / "g.npz"), "--size", "32x32", "--out", str(tmp_path / "b")]) == 0
    assert (tmp_path / "b" / "file.png").is_file()
    rng = np.random.default_rng(0)
    write_ply(tmp_path / "p.ply", PointCloud(rng.normal(size=(500, 3)), velocity=rng.normal(size=(500, 3))))
    assert cli.main(["gauss", str(tmp_path / "p.ply"), "--size", "32x32", "--out", str(tmp_path / "c")]) == 0
    assert (tmp_path / "c" / "points.png").is_file()


@pytest.mark.parametrize("args,message", [
    (["nope.vdb"], "no such file"),
    (["--lod", "ultra"], "--lod"),
])
def test_gauss_errors(tmp_path, capsys, args, message):
    assert cli.main(["gauss", *args, "--out", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err


def test_gauss_bad_npy(tmp_path, capsys):
    np.save(tmp_path / "flat.npy", np.zeros((4, 4)))
    assert cli.main(["gauss", str(tmp_path / "flat.npy"), "--out", str(tmp_path)]) == 2
    assert "3-D" in capsys.readouterr().err
    (tmp_path / "junk.npy").write_bytes(b"not numpy")
    assert cli.main(["gauss", str(tmp_path / "junk.npy"), "--out", str(tmp_path)]) == 2
    assert "junk.npy" in capsys.readouterr().err
    np.save(tmp_path / "empty.npy", np.zeros((8, 8, 8), np.float32))
    assert cli.main(["gauss", str(tmp_path / "empty.npy"), "--out", str(tmp_path)]) == 2
    assert "no active voxel" in capsys.readouterr().err


def test_explosion():
    e = datasets.explosion()
    v = e["volume"]
    assert v.shape == (96, 96, 96) and v.dtype == np.float32
    assert 0.05 < (v > 0).mean() < 0.3 and v.max() <= 1 and v.min() >= 0
    np.testing.assert_array_equal(v, datasets.explosion()["volume"])     # closed form: deterministic
    assert np.allclose(np.array(e["origin"]) + (np.array(v.shape[::-1]) - 1) * e["spacing"][::-1], 1.0)
    with pytest.raises(ValueError, match="shape"):
        datasets.explosion((1, 4, 4))


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
