"""clvis render and clvis iso with --workers / --scheduler: tiles and volumes
rendered on Dask workers give the pictures of the single-process commands;
without the flags nothing changes; the errors."""

import numpy as np
import pytest
from dask_cluster import TIMEOUT, distributed, local_cluster
from PIL import Image

from clvis import cli, datasets
from clvis.io import PointCloud, save_npz

SMALL = ["--size", "160x90", "--quiet"]


def _png(path):
    with Image.open(path) as im:
        return np.asarray(im)


def _run(capsys, *args):
    try:
        rc = cli.main([*map(str, args)])
    except SystemExit as e:
        rc = e.code
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def scheduler():
    with local_cluster() as cluster, distributed.Client(cluster, timeout=TIMEOUT) as c:
        c.wait_for_workers(2, timeout=TIMEOUT)
        yield cluster.scheduler_address


@pytest.fixture(scope="module")
def tiles(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("tiles")
    rng = np.random.default_rng(0)
    paths = []
    for i, n in enumerate((3000, 0, 4000)):
        p = rng.uniform(0, 1, (n, 3)) * [4, 3, 1] + [i, 0, 0]
        cloud = PointCloud(p, attributes={"intensity": rng.random(n).astype(np.float32)})
        paths.append(tmp / f"t{i}.npz")
        save_npz(paths[-1], cloud)
    whole = tmp / "whole.npz"
    save_npz(
        whole,
        PointCloud(
            np.concatenate([np.load(p)["positions"] for p in paths]),
            attributes={"intensity": np.concatenate([np.load(p)["intensity"] for p in paths])},
        ),
    )
    return paths, whole


def test_render_tiles_on_a_scheduler_equals_one_process(tiles, scheduler, tmp_path, capsys):
    paths, whole = tiles
    view = ["--view", "top"]
    rc, out, err = _run(
        capsys, "render", *paths, "--scheduler", scheduler, "--out", tmp_path / "d", *view, *SMALL
    )
    assert rc == 0, err
    assert "3 tiles, 7,000 points, on 2 Dask workers" in out and "sent" in out
    rc, out, err = _run(capsys, "render", whole, "--out", tmp_path / "s", *view, *SMALL)
    assert rc == 0, err
    for name in ("attribute-intensity.png", "depth.png"):
        a, b = _png(tmp_path / "d" / name), _png(tmp_path / "s" / name)
        assert (a[..., 3] > 0).sum() > 500
        np.testing.assert_array_equal(a, b)


def test_render_workers_starts_a_local_cluster(tiles, tmp_path, capsys):
    paths, _ = tiles
    rc, out, err = _run(capsys, "render", *paths, "--workers", 1, "--out", tmp_path, *SMALL)
    assert rc == 0, err
    assert "on 1 Dask workers" in out and (tmp_path / "overview.png").is_file()


def test_iso_on_a_scheduler(scheduler, tmp_path, capsys):
    v = datasets.marschner_lobb(33)["volume"]
    np.save(tmp_path / "ml.npy", v)
    args = ["iso", tmp_path / "ml.npy", "--isovalue", 0.5, "--rate", 16, *SMALL]
    rc, out, err = _run(capsys, *args, "--scheduler", scheduler, "--brick", 8, "--out", tmp_path / "d")
    assert rc == 0, err
    assert "bricks      64 of 8^3 cells on 2 Dask workers" in out
    rc, out, err = _run(capsys, *args, "--out", tmp_path / "s")
    assert rc == 0, err
    a, b = _png(tmp_path / "d" / "iso.png"), _png(tmp_path / "s" / "iso.png")
    assert a.shape == b.shape
    # shading and depths agree to float rounding (bricks enter their own boxes): colours within 2 levels
    assert np.abs(a.astype(int) - b.astype(int)).max() <= 2


def test_errors(tiles, scheduler, tmp_path, capsys):
    paths, _ = tiles
    rc, out, err = _run(capsys, "render", *paths, "--out", tmp_path, *SMALL)
    assert rc == 2 and "3 files: several tiles render together on Dask workers" in err
    rc, out, err = _run(capsys, "render", *paths, "--workers", 1, "--scheduler", scheduler)
    assert rc == 2 and "not allowed with argument" in err
    rc, out, err = _run(capsys, "render", paths[0], tmp_path / "missing.las", "--scheduler", scheduler)
    assert rc == 2 and "missing.las: no such file" in err
    rc, out, err = _run(capsys, "render", *paths, "--scheduler", scheduler, "--attribute", "nope", *SMALL)
    assert rc == 2 and "t0.npz: no attribute 'nope'" in err
    rc, out, err = _run(capsys, "render", "--workers", 1)
    assert rc == 2 and "give at least one" in err
    np.save(tmp_path / "v.npy", np.zeros((8, 8, 8), np.float32))
    rc, out, err = _run(capsys, "iso", tmp_path / "v.npy", "--scheduler", scheduler)
    assert rc == 2 and "--isovalue: needed with a FILE on workers" in err
    rc, out, err = _run(
        capsys, "iso", tmp_path / "v.npy", "--scheduler", scheduler, "--isovalue", 0, "--brick", 6
    )
    assert rc == 2 and "--brick: 6 is not a multiple of 4" in err
