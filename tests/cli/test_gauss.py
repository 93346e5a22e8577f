"""clvis gauss and the demo's gauss part, the explosion dataset, and Gaussians
from point clouds."""

import numpy as np
import pytest
from PIL import Image

import clvis
from clvis import cli, datasets
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
        assert im.width >= 3 * 64 and im.height > 48      # labelled, over colour bars


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
