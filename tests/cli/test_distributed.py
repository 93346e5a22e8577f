"""clvis render and clvis iso with --workers / --scheduler: tiles and volumes
rendered on Dask workers give the pictures of the single-process commands;
without the flags nothing changes; the errors."""

import os
import re
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from dask_cluster import TIMEOUT, distributed, http_like_server, local_cluster, silent_scheduler, web_server
from PIL import Image

from clvis import cli, datasets
from clvis.io import PointCloud, save_npz

SMALL = ["--size", "160x90", "--quiet", "--no-labels"]  # the images alone: exactly --size


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
    # a sampler's view: both frame the volume's box (the fit view of one
    # device frames the surface's voxels, which the client of workers reading
    # a FILE brick by brick does not have)
    args = ["iso", tmp_path / "ml.npy", "--isovalue", 0.5, "--rate", 16, "--view", "hemisphere:5", *SMALL]
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


def test_several_files_on_one_device_frame_as_on_workers(tiles, scheduler, tmp_path, capsys):
    """Several tiles without --workers load into one device renderer; the
    default (fit) view frames the same sample of the points either way, so
    the pictures are the same."""
    paths, _ = tiles
    rc, out, err = _run(capsys, "render", *paths, "--out", tmp_path / "s", *SMALL)
    assert rc == 0, err
    assert "clvis render: 3 tiles, 7,000 points" in out
    rc, out, err = _run(capsys, "render", *paths, "--scheduler", scheduler, "--out", tmp_path / "d", *SMALL)
    assert rc == 0, err
    for name in ("attribute-intensity.png", "depth.png"):
        a, b = _png(tmp_path / "d" / name), _png(tmp_path / "s" / name)
        assert (a[..., 3] > 0).sum() > 500
        np.testing.assert_array_equal(a, b)


def _las_tile(path, n, x0, rng, strays=0):
    """A LAS tile of point format 3 in UTM-like coordinates (RGB, intensity),
    with `strays` records at (0, 0, 0) far outside the rest."""
    laspy = pytest.importorskip("laspy")
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales, header.offsets = [0.01] * 3, [636000.0, 849000.0, 400.0]
    las = laspy.LasData(header)
    las.x = np.round(636000 + x0 + rng.random(n) * 200, 2)
    las.y = np.round(849000 + rng.random(n) * 150, 2)
    las.z = np.round(400 + rng.random(n) * 20, 2)
    if strays:
        las.x[:strays], las.y[:strays], las.z[:strays] = 0.0, 0.0, 0.0
    las.red, las.green, las.blue = rng.integers(0, 65536, (3, n)).astype(np.uint16)
    las.intensity = rng.integers(0, 65536, n)
    las.write(str(path))
    return path


def test_las_tiles_default_and_eye_views_equal_on_workers(scheduler, tmp_path, capsys):
    """Two georeferenced LAS tiles with colours and a few stray (0, 0, 0)
    records: the default picture (their colours, the fit view of the bulk,
    the note on the strays) and a view from --eye/--target in the files'
    coordinates are the same with and without workers, bit for bit."""
    rng = np.random.default_rng(7)
    a = _las_tile(tmp_path / "a.las", 3000, 0, rng)
    b = _las_tile(tmp_path / "b.las", 2000, 180, rng, strays=12)
    eye = ["--eye", "635900,848900,700", "--target", "636190,849075,410"]
    for name, view in (("fit", []), ("eye", eye)):
        args = ["render", a, b, *view, *SMALL]
        rc, out, err = _run(capsys, *args, "--out", tmp_path / name / "s")
        assert rc == 0, err
        rc, out_d, err_d = _run(capsys, *args, "--scheduler", scheduler, "--out", tmp_path / name / "d")
        assert rc == 0, err_d
        assert "on 2 Dask workers" in out_d
        if not view:  # the strays are left out of the frame on both, with one note
            assert "12 of 5,000 points lie far outside the rest" in err
            assert err_d == err
        for png in ("colors.png", "depth.png"):
            x, y = _png(tmp_path / name / "d" / png), _png(tmp_path / name / "s" / png)
            assert len(np.unique(x.reshape(-1, x.shape[-1]), axis=0)) > 50, (name, png)
            np.testing.assert_array_equal(x, y, err_msg=f"{name} {png}")


def test_look_options_on_workers_equal_one_device(tiles, scheduler, tmp_path, capsys):
    """--background, --range MIN,MAX and --edl work on workers as on one
    device; what cannot (percentiles, auto point size, the networks) is an
    error naming the option, never silently ignored."""
    paths, _ = tiles
    look = ["--background", "white", "--range", "0.2,0.8", "--edl", "1.5"]
    rc, out, err = _run(capsys, "render", *paths, *look, "--out", tmp_path / "s", *SMALL)
    assert rc == 0, err
    rc, out, err = _run(
        capsys, "render", *paths, *look, "--scheduler", scheduler, "--out", tmp_path / "d", *SMALL
    )
    assert rc == 0, err
    assert "range     intensity 0.2..0.8" in out and "edl       eye-dome lighting, strength 1.5" in out
    a, b = _png(tmp_path / "d" / "attribute-intensity.png"), _png(tmp_path / "s" / "attribute-intensity.png")
    np.testing.assert_array_equal(a, b)
    assert (a[0, 0, :3] == 255).all()  # the white background
    for extra, message in (
        (["--range", "p2,p98"], "--range pLO,pHI"),
        (["--point-size", "auto"], "--point-size auto"),
        (["--post", "lidar", "--depth-filter", "4"], "--post:"),
    ):
        rc, out, err = _run(capsys, "render", *paths, *extra, "--scheduler", scheduler, *SMALL)
        assert rc == 2 and err.startswith(f"clvis render: error: {message}"), (extra, err)


def test_rgb_first_on_workers_as_on_one_device(scheduler, tmp_path, capsys):
    """laspy's simple.laz (RGB and a varying intensity) as two tiles: its
    colours by default on workers too (they used to take intensity), the
    same picture as one device."""
    pytest.importorskip("laspy")
    import shutil
    from pathlib import Path

    src = Path(__file__).parents[1] / "data" / "laspy_simple.laz"
    paths = [tmp_path / "a.laz", tmp_path / "b.laz"]
    for p in paths:
        shutil.copy(src, p)
    rc, out, err = _run(capsys, "render", *paths, "--scheduler", scheduler, "--out", tmp_path / "d", *SMALL)
    assert rc == 0, err
    assert {p.name for p in (tmp_path / "d").iterdir()} == {"colors.png", "depth.png", "overview.png"}
    rc, out, err = _run(capsys, "render", *paths, "--out", tmp_path / "s", *SMALL)
    assert rc == 0 and "its colors" in out, err
    a, b = _png(tmp_path / "d" / "colors.png"), _png(tmp_path / "s" / "colors.png")
    assert (a[..., :3] != a[0, 0, :3]).any(axis=2).sum() > 100
    np.testing.assert_array_equal(a, b)
    rc, out, err = _run(capsys, "render", *paths, "--colormap", "magma", "--scheduler", scheduler, *SMALL)
    assert rc == 2 and "--colormap colours an attribute" in err, err  # it would do nothing


def test_classes_on_workers_say_they_use_a_colormap(scheduler, tmp_path, capsys):
    rng = np.random.default_rng(3)
    path = tmp_path / "c.npz"
    cls = rng.choice(np.array([2, 5, 6], np.uint8), 2000)
    save_npz(path, PointCloud(rng.random((2000, 3)), attributes={"classification": cls}))
    args = ["render", path, "--scheduler", scheduler, *SMALL]
    rc, out, err = _run(capsys, *args, "--out", tmp_path / "a")
    assert rc == 0, err
    assert "clvis render: note: on workers classification is coloured through viridis" in err
    rc, out, err = _run(capsys, *args, "--colormap", "tab10", "--out", tmp_path / "b")
    assert rc == 0 and "note" not in err


def test_several_files_match_attributes_by_name(tmp_path, capsys):
    rng = np.random.default_rng(1)
    a = PointCloud(rng.uniform(0, 1, (300, 3)), attributes={"i": rng.random(300), "k": rng.random(300)})
    b = PointCloud(rng.uniform(0, 1, (200, 3)) + 5, attributes={"k": rng.random(200), "i": rng.random(200)})
    c = PointCloud(rng.uniform(0, 1, (100, 3)), attributes={"k": rng.random(100)})
    for name, cloud in (("a", a), ("b", b), ("c", c)):
        save_npz(tmp_path / f"{name}.npz", cloud)
    rc, out, err = _run(
        capsys, "render", tmp_path / "a.npz", tmp_path / "b.npz", "--out", tmp_path / "o", *SMALL
    )
    assert rc == 0 and "2 tiles, 500 points, colored by i" in out, err
    rc, out, err = _run(
        capsys,
        "render",
        tmp_path / "a.npz",
        tmp_path / "c.npz",
        "--attribute",
        "i",
        "--out",
        tmp_path,
        *SMALL,
    )
    assert rc == 2 and "c.npz: no attribute 'i'; it has k" in err


def test_several_files_too_large_for_one_device_point_to_workers(tmp_path, capsys, monkeypatch):
    """Tiles that do not fit one device are an error that says so and names
    --workers/--scheduler (Dask is started only when asked)."""
    from types import SimpleNamespace

    from clvis import runtime

    rng = np.random.default_rng(4)
    for name in ("a", "b"):
        save_npz(tmp_path / f"{name}.npz", PointCloud(rng.uniform(0, 1, (400, 3))))
    tiny = SimpleNamespace(device=SimpleNamespace(global_mem_size=20_000, name="a tiny device "))
    monkeypatch.setattr(runtime, "default_queue", lambda *a, **k: tiny)
    rc, out, err = _run(capsys, "render", tmp_path / "a.npz", tmp_path / "b.npz", "--out", tmp_path, *SMALL)
    assert rc == 2 and "2 files, 800 points: more than one device holds (a tiny device)" in err, err
    assert "render them on Dask workers (--workers N or --scheduler ADDRESS)" in err
    assert not list(tmp_path.glob("*.png"))


def test_one_file_on_several_workers_says_so(tiles, tmp_path, capsys):
    paths, _ = tiles
    rc, out, err = _run(capsys, "render", paths[0], "--workers", 2, "--out", tmp_path, *SMALL)
    assert rc == 0, err
    assert "on 1 Dask workers" in out and "1 file on 2 workers: a file is one partition" in out


def test_a_refused_scheduler_fails_in_seconds(tiles, tmp_path, capsys):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    t0 = time.monotonic()
    rc, out, err = _run(capsys, "render", tiles[0][0], "--scheduler", f"tcp://127.0.0.1:{port}", *SMALL)
    assert rc == 2 and f"scheduler tcp://127.0.0.1:{port}: cannot connect" in err
    assert time.monotonic() - t0 < 5


def test_a_silent_scheduler_fails_after_connect_timeout(tiles, tmp_path, capsys):
    """A port that accepts and never speaks Dask: --connect-timeout bounds the wait."""
    with silent_scheduler() as address:
        t0 = time.monotonic()
        rc, out, err = _run(
            capsys, "render", tiles[0][0], "--scheduler", address, "--connect-timeout", 2, *SMALL
        )
        assert rc == 2 and f"scheduler {address}: not reached within connect_timeout=2 s" in err, err
        assert time.monotonic() - t0 < 20


def test_a_port_where_no_dask_scheduler_answers(tiles, capsys):
    """A web server's reply read as a Dask message: "out of host memory:
    Unable to allocate 3.07 EiB" before."""
    with http_like_server() as hostport:
        rc, out, err = _run(capsys, "render", tiles[0][0], "--scheduler", hostport, *SMALL)
    assert rc == 2 and err.count("\n") == 1, err
    assert f"scheduler {hostport}: what answered there is not a Dask scheduler" in err


def test_a_web_server_that_waits_for_a_request_is_no_scheduler_in_seconds(tiles, tmp_path, capsys):
    """`python -m http.server` as --scheduler: "not reached within
    connect_timeout=10 s" after 10 s before; now one line saying what
    answered, in seconds."""
    with web_server(tmp_path) as hostport:
        t0 = time.monotonic()
        rc, out, err = _run(capsys, "render", tiles[0][0], "--scheduler", hostport, *SMALL)
        took = time.monotonic() - t0
    assert rc == 2 and err.count("\n") == 1, err
    assert (
        f"scheduler {hostport}: what answered there is not a Dask scheduler (it said 'HTTP/1.0 200 OK')"
        in err
    )
    assert took < 5


def test_a_cluster_timeout_says_what_it_waited_for(tiles, capsys, monkeypatch):
    """Every OSError of the renderer was "--scheduler ADDRESS: cannot reach
    it", ClusterTimeout (a TimeoutError) included: "--scheduler None:
    cannot reach it (building 2 Rasterizers: ... not done ...)" with
    --workers."""
    import clvis.distributed
    from clvis.errors import ClusterTimeout

    def timed_out(*a, **k):
        raise ClusterTimeout("building 2 Rasterizers: 1 of 2 tasks not done within timeout=300 s")

    monkeypatch.setattr(clvis.distributed, "DistributedRasterizer", timed_out)
    rc, out, err = _run(capsys, "render", *tiles[0], "--workers", 2, *SMALL)
    assert rc == 2 and err == (
        "clvis render: error: building 2 Rasterizers: 1 of 2 tasks not done within timeout=300 s\n"
    )


def test_workers_beyond_the_cores_are_refused(tiles, tmp_path, capsys, monkeypatch):
    """--workers 4096 started 4096 worker processes (on any machine)."""
    from clvis.distributed import cluster

    def refuse(workers, **kw):
        raise AssertionError(f"a LocalCluster of {workers} workers was started")

    monkeypatch.setattr(cluster, "start_cluster", refuse)
    most = cluster.local_workers_max()
    np.save(tmp_path / "v.npy", np.zeros((8, 8, 8), np.float32))
    for args in (["render", tiles[0][0]], ["iso", tmp_path / "v.npy", "--isovalue", 0]):
        rc, out, err = _run(capsys, *args, "--workers", most + 1, *SMALL)
        assert rc == 2, err
        assert err.startswith(f"clvis {args[0]}: error: --workers {most + 1}: at most {most} on this machine")


def test_volume_files_the_workers_cannot_slice_say_what_to_do(scheduler, tmp_path, capsys):
    """A .vtk volume (one device reads it) was an "unknown volume format";
    a 4-D NIfTI named volume_index, not --volume-index."""
    nibabel = pytest.importorskip("nibabel")
    vtk = tmp_path / "v.vtk"
    vtk.write_text("# vtk DataFile Version 3.0\n")
    rc, out, err = _run(capsys, "iso", vtk, "--scheduler", scheduler, "--isovalue", 0, *SMALL)
    assert rc == 2 and "v.vtk: not a volume format the workers slice brick by brick" in err, err
    assert "without --workers/--scheduler" in err
    nii = tmp_path / "4d.nii"
    nibabel.save(nibabel.Nifti1Image(np.zeros((8, 8, 8, 2), np.float32), np.eye(4)), nii)
    rc, out, err = _run(capsys, "iso", nii, "--scheduler", scheduler, "--isovalue", 0, *SMALL)
    assert rc == 2 and "choose one of its 2 volumes: volume_index=T (--volume-index T)" in err, err


def test_ctrl_c_on_workers_prints_one_line_and_leaves_no_workers(tmp_path):
    """SIGINT to the whole process group (a terminal's Ctrl-C) once the
    LocalCluster's workers run: one line on stderr, exit status 130, and no
    process of the group left."""
    rng = np.random.default_rng(2)
    paths = []
    for i in range(2):
        paths.append(tmp_path / f"big{i}.npz")
        save_npz(paths[-1], PointCloud(rng.uniform(0, 1, (300_000, 3)) + [i, 0, 0]))
    cmd = [sys.executable, "-m", "clvis", "render", *map(str, paths), "--workers", "2"]
    cmd += ["--size", "1600x1200", "--out", str(tmp_path / "o"), "--quiet"]
    p = subprocess.Popen(
        cmd, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        deadline = time.monotonic() + TIMEOUT
        while len(_group(p.pid)) < 3 and p.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)  # the worker processes have started
        while p.poll() is None and time.monotonic() < deadline:  # one is enough; more are harmless
            os.killpg(p.pid, signal.SIGINT)
            try:
                p.wait(1.0)
            except subprocess.TimeoutExpired:
                pass
        out, err = p.communicate(timeout=TIMEOUT)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 130, err
    # a worker whose kernel build the signal reached may leave its OpenCL
    # compiler's lines (native code on the inherited stderr, not Python's:
    # clang's "1 error generated.", or PoCL's linker interrupted: "error:
    # unable to execute command: Interrupt", "error: linker command failed
    # due to signal ...", "Final linking of kernel NAME failed."); clvis
    # itself says one line, and no traceback
    native = (
        r"\d+ errors? generated\.",
        r"error: unable to execute command: Interrupt",
        r"error: linker command failed due to signal.*",
        r"Final linking of kernel \w+ failed\.",
    )
    lines = [ln for ln in err.splitlines() if not any(re.fullmatch(pat, ln) for pat in native)]
    assert lines == ["clvis render: interrupted; the Dask workers started here were stopped"], err
    deadline = time.monotonic() + 10
    while _group(p.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not _group(p.pid)


def test_ctrl_c_while_the_local_cluster_starts_stops_the_command(tmp_path):
    """SIGINT to the whole process group (a terminal's Ctrl-C) while the
    LocalCluster of --workers starts: it was ignored then (so that the
    workers inherited the ignoring), and the render ran to its end. Now:
    exit status 130 within seconds, one line, no PNG written, no process of
    the group left."""
    path = tmp_path / "t.npz"
    save_npz(path, PointCloud(np.random.default_rng(1).uniform(0, 1, (2000, 3))))
    out_dir = tmp_path / "o"
    cmd = [sys.executable, "-m", "clvis", "render", str(path), "--workers", "1", "--out", str(out_dir)]
    p = subprocess.Popen(
        [*cmd, "--quiet"], start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        deadline = time.monotonic() + TIMEOUT
        # the cluster's start has begun: its first process (multiprocessing's
        # resource tracker, then the worker, which joins a second or more later)
        while len(_group(p.pid)) < 2 and p.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        sent = time.monotonic()
        os.killpg(p.pid, signal.SIGINT)
        out, err = p.communicate(timeout=TIMEOUT)
        took = time.monotonic() - sent
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 130, err
    assert err.splitlines() == ["clvis render: interrupted; the Dask workers started here were stopped"], err
    assert took < 15, f"{took:.1f} s from the Ctrl-C to the exit"
    assert not (out_dir.exists() and list(out_dir.iterdir()))
    deadline = time.monotonic() + 10
    while _group(p.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not _group(p.pid)


def _group(pgid):
    """The processes of process group pgid."""
    out = subprocess.run(["pgrep", "-g", str(pgid)], capture_output=True, text=True).stdout
    return out.split()
