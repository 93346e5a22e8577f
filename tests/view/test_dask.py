"""The viewer's Dask mode (clvis view --workers/--scheduler) on a real
two-worker LocalCluster: a points frame equals the single device's bit for
bit, an iso frame equals it within the distributed iso's tolerance (the same
hits on the reference's reliable pixels, depths within 1e-4 of the
diagonal); closing the viewer stops the workers it started; the CLI's
errors."""

import json
import time

import numpy as np
import pytest
from dask_cluster import TIMEOUT, distributed, local_cluster

import clvis
from clvis import cli, datasets, zfp
from clvis.distributed.cluster import connected_workers
from clvis.reference import iso as ref
from clvis.view import DaskPointScene, DaskVolumeScene, Orbit, PointScene, Viewer, ViewServer, VolumeScene
from clvis.view.scenes import psnr

pytest.importorskip("tornado", reason="the view extra (tornado) is not installed")
da = pytest.importorskip("dask.array")
psutil = pytest.importorskip("psutil")  # a dependency of dask.distributed


@pytest.fixture(scope="module")
def client():
    with local_cluster() as cluster, distributed.Client(cluster, timeout=TIMEOUT) as c:
        c.wait_for_workers(2, timeout=TIMEOUT)
        yield c


def _first(scene, camera, w, h):
    frames = list(scene.frames(camera, w, h, dict(scene.settings), lambda: False))
    return frames[-1]


def _children():
    """This process's children but multiprocessing's own helpers (the
    resource tracker, the forkserver: one per process, not workers)."""
    out = set()
    for p in psutil.Process().children(recursive=True):
        try:
            cmd = " ".join(p.cmdline())
        except psutil.Error:  # gone meanwhile
            continue
        if "resource_tracker" not in cmd and "forkserver" not in cmd:
            out.add(p.pid)
    return out


def test_points_frame_is_the_single_devices_and_closing_stops_the_workers():
    rng = np.random.default_rng(3)
    n = 6001
    pos = rng.uniform(0, 1, (n, 3)).astype(np.float32) * [4, 3, 1]
    pos[3100:3200] = pos[:100]  # ties across the two blocks
    pos = pos.astype(np.float32)
    att = rng.random(n).astype(np.float32)
    before = _children()
    scene = DaskPointScene(
        da.from_array(pos, chunks=(3001, 3)),
        attributes={"t": da.from_array(att, chunks=3001)},
        workers=2,
        timeout=TIMEOUT,
    )
    viewer = Viewer(ViewServer(scene))
    try:
        started = _children() - before
        assert len(connected_workers(scene.dr.client)) == 2
        assert started, "no worker processes were started"
        single = PointScene(clvis.PointCloud(pos, attributes={"t": att}))
        np.testing.assert_array_equal(scene.lo, single.lo)
        np.testing.assert_array_equal(scene.hi, single.hi)
        cam = Orbit(scene.lo, scene.hi, points=scene.fit_points).camera(64 / 48)
        for settings in ({}, {"point_size": 3, "colormap": "magma"}):
            scene.update(settings)
            single.update(settings)
            got, want = _first(scene, cam, 64, 48), _first(single, cam, 64, 48)
            assert got.info["workers"] >= 1  # the workers holding partitions (Dask places them)
            assert (got.image != want.image).any(axis=2).sum() == 0
            assert (got.image != np.array(clvis.images.BACKGROUND, np.uint8)).any()
        with pytest.raises(ValueError, match="mode: expected one of"):
            scene.update({"mode": "lidar"})  # not on workers
    finally:
        viewer.close()
    assert scene.dr.closed
    deadline = time.monotonic() + TIMEOUT
    while (left := started & _children()) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not left, f"worker processes left behind: {[psutil.Process(p).cmdline() for p in left]}"


def test_iso_frame_is_the_single_devices_within_the_tolerance(client):
    d = datasets.marschner_lobb(41)
    v, sp, org = d["volume"], d["spacing"], d["origin"]
    rate, w, h = 16, 48, 40
    single = VolumeScene(v, sp, org, 0.5, rate)
    scene = DaskVolumeScene(
        v,
        client,
        isovalue=0.5,
        vrange=(float(v.min()), float(v.max())),
        rate=rate,
        spacing=sp,
        origin=org,
        brick=20,
        timeout=TIMEOUT,
    )
    viewer = Viewer(ViewServer(scene))
    try:
        assert scene.modes == ["iso"] and len(scene.dr.bricks) > 1
        np.testing.assert_allclose(scene.hi, single.hi)
        cam = Orbit(scene.lo, scene.hi).camera(w / h)
        got = _first(scene, cam, w, h)
        want = _first(single, cam, w, h)
        assert want.final and got.final and got.info["workers"] >= 1
        img, one = scene.last, single.iso.render(cam, w, h, 0.5)
        exact = ref.render(zfp.decode(single.iso.volume), cam, w, h, 0.5, spacing=sp, origin=org)
        assert ref.agreement(exact, img.hit, img.depth)["ok"]
        rel = ref.reliable(exact)
        assert (img.hit[rel] == one.hit[rel]).all()
        # the frames: the same picture but for float32 rounding on the unreliable pixels
        diff = np.abs(got.image.astype(int) - want.image.astype(int)).max(axis=2)
        assert (diff[rel] <= 1).all()
        assert psnr(got.image, want.image) > 35
        # a frame the cluster cannot render is a message in the page, and the viewer goes on
        sent = []
        viewer.server._send_text = sent.append
        scene.dr.close()  # as if the workers were gone for good
        viewer.server.request()
        deadline = time.monotonic() + TIMEOUT
        while not sent and time.monotonic() < deadline:
            time.sleep(0.05)
        assert sent and json.loads(sent[0])["type"] == "error" and "ClusterError" in sent[0], sent
        assert viewer.server.scheduler.thread.is_alive() and viewer.server.thread.is_alive()
    finally:
        viewer.close()
    assert scene.dr.closed and client.status == "running"  # a cluster given is the caller's


def _run(capsys, *args):
    try:
        rc = cli.main([*map(str, args)])
    except SystemExit as e:
        rc = e.code
    out, err = capsys.readouterr()
    return rc, out, err


def test_cli_errors(capsys, client, tmp_path):
    addr = client.scheduler.address
    rc, _, err = _run(
        capsys, "view", "--dataset", "hurricane", "--points", 2000, "--scheduler", addr, "--measure", "lidar"
    )
    assert rc != 0 and "mode 'lidar' is not rendered on Dask workers" in err
    assert "leave out --workers/--scheduler" in err
    np.save(tmp_path / "v.npy", np.zeros((8, 8, 8), np.float32))
    for args, msg in (
        (["--workers", 2, "--scheduler", addr], "not allowed with argument"),
        (["--workers", 0], "--workers"),
        (["--workers", 2, "--brick", 6], "--brick: 6 is not a multiple of 4"),
        ([tmp_path / "v.npy", "--workers", 2], "--isovalue: needed with a volume FILE on workers"),
        ([tmp_path / "none.ply", "--workers", 2], "no such file"),
    ):
        rc, _, err = _run(capsys, "view", *args, "--no-browser")
        assert rc != 0 and msg in err, (args, err)


def test_cli_measures_a_points_frame_on_the_workers(capsys, client):
    rc, out, err = _run(
        capsys,
        "view",
        "--dataset",
        "terrain",
        "--points",
        4000,
        "--scheduler",
        client.scheduler.address,
        "--measure",
        "--size",
        "96x64",
    )
    assert rc == 0, err
    assert "on Dask workers" in out and "points        interaction" in out and "still" in out
