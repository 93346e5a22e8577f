"""`clvis view`: what it reads, its errors, and --measure (no browser: the
browser test is tests/view/test_browser.py)."""

import shutil
from pathlib import Path

import numpy as np
import pytest

import clvis
from clvis import cli
from clvis.cli import view as view_cmd

pytest.importorskip("tornado", reason="the view extra (tornado) is not installed")

DATA = Path(__file__).resolve().parents[1] / "data"


def _args(*argv):
    p, commands = cli._parser()
    return p.parse_args(["view", *argv])


def test_measure_prints_each_mode(capsys):
    assert cli.main(["view", "--dataset", "marschner-lobb", "--measure", "iso", "--size", "128x96"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("iso ")]
    assert len(rows) == 2 and "interaction" in rows[0] and "64x48" in rows[0] and "128x96" in rows[1]


def test_errors_are_one_line(capsys, tmp_path):
    assert cli.main(["view", str(tmp_path / "missing.ply")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert cli.main(["view", "--dataset", "marschner-lobb", "--measure", "points"]) == 2
    assert "no mode 'points'" in capsys.readouterr().err
    assert cli.main(["view", str(DATA / "pyvista_ant.ply"), "--dataset", "terrain"]) == 2
    assert "leave it out" in capsys.readouterr().err


def test_model_dir(capsys, tmp_path):
    """--model-dir: the network modes' models from a `clvis train --out`
    folder (a copy of the shipped in-fill model measures as the shipped one);
    a folder that is not one, and --model-dir on workers, are one line."""
    from clvis.post.infer import MODELS

    for f in MODELS.glob("infill.*"):
        shutil.copy(f, tmp_path / f.name)
    args = ["view", "--dataset", "marschner-lobb", "--measure", "iso+infill", "--size", "96x64"]
    assert cli.main([*args, "--model-dir", str(tmp_path)]) == 0
    assert "iso+infill" in capsys.readouterr().out
    assert cli.main([*args, "--model-dir", str(tmp_path / "nowhere")]) == 2
    assert f"model_dir: {tmp_path / 'nowhere'} is not a folder" in capsys.readouterr().err
    assert cli.main([*args, "--model-dir", str(tmp_path), "--workers", "1"]) == 2
    assert "--model-dir: on workers the viewer runs no network" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["pyvista_ant.ply", "laspy_simple.laz"])
def test_third_party_point_files(name, tmp_path):
    pytest.importorskip("laspy")
    path = tmp_path / name
    shutil.copy(DATA / name, path)
    scene = view_cmd.load_scene(_args(str(path)))
    assert scene.kind == "points" and "points" in scene.modes
    frame = next(scene.frames(_camera(scene), 64, 48, scene.settings, lambda: False))
    assert frame.image.shape == (48, 64, 3) and frame.image.std() > 0
    # no velocity in either file: NARVis for scans (the radius plane from their knn_sigma)
    assert "narvis-scan" in scene.modes and "narvis" not in scene.modes
    scene.update({"mode": "narvis-scan"})
    frame = next(scene.frames(_camera(scene), 64, 48, scene.settings, lambda: False))
    assert frame.image.shape == (48, 64, 3) and frame.image.std() > 0 and frame.times["build"] > 0


@pytest.mark.parametrize("suffix", [".pcd", ".xyz", ".e57"])
def test_point_files_of_every_reader_are_points(suffix, tmp_path):
    # a .pcd or .e57 was taken for a volume: "unknown volume format (expected .raw, ...)"
    from fuzz.seeds import _e57, _pcd

    path = tmp_path / f"cloud{suffix}"
    if suffix == ".pcd":
        _pcd(path, 300, binary=True)
    elif suffix == ".e57":
        _e57(pytest.importorskip("pye57"), path, 300)
    else:
        np.savetxt(path, np.random.default_rng(0).random((300, 3)))
    scene = view_cmd.load_scene(_args(str(path)))
    assert scene.kind == "points"


def test_a_scan_is_first_seen_from_the_front(tmp_path):
    """clvis view FILE.nii: a scan in RAS+ order (+y anterior) is first seen
    from the front (azimuth 115: from +y), not from behind (-115)."""
    nibabel = pytest.importorskip("nibabel")
    v = np.zeros((12, 12, 12), np.float32)
    v[3:9, 3:9, 3:9] = 1
    nibabel.save(nibabel.Nifti1Image(v, np.eye(4)), tmp_path / "s.nii")
    np.save(tmp_path / "s.npy", v)
    assert view_cmd.load_scene(_args(str(tmp_path / "s.nii"))).home_azimuth == 115.0
    assert view_cmd.load_scene(_args(str(tmp_path / "s.npy"))).home_azimuth == -115.0
    pytest.importorskip("distributed", reason="the distributed extra is not installed")
    scene = view_cmd.load_dask_scene(_args(str(tmp_path / "s.nii"), "--workers", "1", "--isovalue", "0.5"))
    try:  # on workers (they read it in RAS+ order too)
        assert scene.home_azimuth == 115.0
    finally:
        scene.close()


def test_a_file_of_neither_kind_is_named_as_such(tmp_path):
    """A file neither a volume nor points was "unknown volume format
    (expected .raw, ...)": the viewer takes both, and says both; a triangle
    mesh (.stl, .obj: a PyVista or Open3D user's) gets what to do with it."""
    # a malformed .npy: np.load's "EOF: reading array header ..." named no file
    bad = tmp_path / "bad.npy"
    bad.write_bytes(b"\x93NUMPY\x01\x00\x10\x00{garbage")
    with pytest.raises(clvis.DataError, match=f"^{bad}: malformed NPY file"):
        view_cmd.load_scene(_args(str(bad)))
    for name, mesh in (("shape.stl", True), ("notes.abc", False)):
        path = tmp_path / name
        path.write_bytes(b"solid x\nendsolid x\n")
        with pytest.raises(view_cmd.CliError) as e:
            view_cmd.load_scene(_args(str(path)))
        text = str(e.value)
        assert (
            text.startswith(f"{path}: unknown format (expected a volume: .vdb, .raw,")
            and "or points: .ply" in text
        )
        assert ("it is a triangle mesh" in text and "sample_points_uniformly" in text) == mesh


def test_vtk_files_go_by_their_dataset(tmp_path):
    """A .vtp, .vtu, .vts and a POLYDATA .vtk are points, a STRUCTURED_POINTS .vtk a volume."""
    pytest.importorskip("vtk", reason="vtk is in the test extra")
    from fuzz.seeds import vtk_point_set

    for suffix in ("vtp", "vtu", "vts", "vtk"):
        vtk_point_set(tmp_path / f"p.{suffix}", 204, "binary")
        assert view_cmd.load_scene(_args(str(tmp_path / f"p.{suffix}"))).kind == "points"
    (tmp_path / "v.vtk").write_text(
        "# vtk DataFile Version 3.0\nx\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 3 3 3\n"
        "POINT_DATA 27\nSCALARS s float 1\nLOOKUP_TABLE default\n"
        + " ".join(str(k) for k in range(27))
        + "\n"
    )
    assert view_cmd.load_scene(_args(str(tmp_path / "v.vtk"))).kind == "volume"


def test_embedded_points_beyond_host_memory_are_refused(monkeypatch):
    # --points up to 2^31: the cloud was made whatever the memory
    from clvis import DeviceError, runtime

    monkeypatch.setattr(runtime.memory, "host_available_bytes", lambda: 100 << 20)
    with pytest.raises(DeviceError, match=r"--points 2,000,000 \(the embedded terrain\): needs"):
        view_cmd.load_scene(_args("--dataset", "terrain", "--points", "2000000"))


def test_volume_files_npy_and_nifti(tmp_path):
    from clvis import datasets

    vol = datasets.marschner_lobb(24)["volume"]
    np.save(tmp_path / "v.npy", vol)
    np.save(tmp_path / "p.npy", np.random.default_rng(0).random((100, 3)).astype(np.float32))
    assert view_cmd.load_scene(_args(str(tmp_path / "v.npy"))).kind == "volume"
    assert view_cmd.load_scene(_args(str(tmp_path / "p.npy"))).kind == "points"
    nib = pytest.importorskip("nibabel")
    nib.save(nib.Nifti1Image(vol.transpose(2, 1, 0), np.diag([2.0, 2.0, 2.0, 1.0])), tmp_path / "v.nii.gz")
    scene = view_cmd.load_scene(_args(str(tmp_path / "v.nii.gz")))
    assert scene.kind == "volume" and np.allclose(scene.hi - scene.lo, 2.0 * 23)
    frames = list(scene.frames(_camera(scene, 48 / 32), 48, 32, scene.settings, lambda: False))
    assert frames[-1].final and frames[-1].info["completion"] == 1.0


def _camera(scene, aspect=4 / 3):
    from clvis.view import Orbit

    o = Orbit(scene.lo, scene.hi, points=scene.fit_points)
    return o.camera(aspect)


def test_ctrl_c_stops_the_viewer_with_one_line_and_status_0(tmp_path):
    """Ctrl-C is how a viewer stops: "stopped", exit status 0, not also
    "interrupted" and 130."""
    import signal
    import subprocess
    import sys
    import time

    np.save(tmp_path / "p.npy", np.random.default_rng(0).random((2000, 3)).astype(np.float32))
    proc = subprocess.Popen(
        [sys.executable, "-m", "clvis", "view", str(tmp_path / "p.npy"), "--no-browser"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        line = ""
        while "Ctrl-C stops" not in line and time.monotonic() < deadline:
            line = proc.stdout.readline()
            assert line or proc.poll() is None, proc.stderr.read()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert err.strip().splitlines()[-1] == "clvis view: stopped" and "interrupted" not in err


@pytest.mark.parametrize(
    "args, message",
    [
        (["--dataset", "marschner-lobb", "--points", "5"], "--points: the size of an embedded point cloud"),
        (["--dataset", "hurricane", "--isovalue", "3"], "--isovalue: for a volume's isosurface"),
        (["--dataset", "hurricane", "--rate", "4"], "--rate: for a volume's isosurface"),
        (["--connect-timeout", "3"], "--connect-timeout: the wait for a --scheduler"),
    ],
)
def test_options_the_scene_would_ignore_are_refused(capsys, args, message):
    """Options that the chosen scene does not use are an error, not ignored."""
    assert cli.main(["view", *args, "--measure", "points", "--no-browser"]) == 2
    assert message in capsys.readouterr().err


def test_an_address_it_cannot_listen_on_is_named(capsys):
    """--host that does not resolve: one line naming the host and port."""
    assert cli.main(["view", "--dataset", "marschner-lobb", "--host", "256.1.1.1", "--no-browser"]) == 2
    assert "--host 256.1.1.1 --port 0: cannot listen there" in capsys.readouterr().err


def test_view_vdb(capsys):
    """clvis view FILE.vdb [--grid]: the grid's Gaussians (--measure here);
    the options of dense volumes, points and workers are one line, as is
    --grid with another file."""
    vdb = str(DATA / "openvdb_small.vdb")
    assert cli.main(["view", vdb, "--grid", "density", "--measure", "--size", "96x64"]) == 0
    out = capsys.readouterr().out
    assert "openvdb_small.vdb: 26x28x25 voxels, 7,208 active in 44 leaves" in out  # from leaf-aligned corners
    assert [line.split()[0] for line in out.splitlines() if line.startswith("gaussians ")] == [
        "gaussians"
    ] * 2
    assert cli.main(["view", vdb, "--grid", "2", "--measure", "gaussians", "--size", "96x64"]) == 0  # "block"
    assert "160x160x160 voxels, 4,096,000 active" in capsys.readouterr().out
    # mode iso: the grid made dense, at --isovalue (else clvis iso's default) with --rate
    iso = ["--isovalue", "0.5", "--rate", "4", "--measure", "iso", "--size", "96x64"]
    assert cli.main(["view", vdb, *iso]) == 0
    out = capsys.readouterr().out
    assert "a level set" in out
    assert [ln.split()[0] for ln in out.splitlines() if ln.startswith("iso ")] == ["iso"] * 2
    for argv, msg in [
        (["--points", "5"], "--points: not for a .vdb"),
        (["--spacing", "1,1,1"], "--spacing: not for a .vdb"),
        (["--workers", "1"], "a .vdb is drawn on one device"),
        (["--grid", "nope"], "no grid named 'nope'"),
    ]:
        assert cli.main(["view", vdb, *argv, "--measure"]) == 2
        err = capsys.readouterr().err
        assert msg in err and len(err.strip().splitlines()) == 1, err
    assert cli.main(["view", str(DATA / "pyvista_ant.ply"), "--grid", "x", "--measure"]) == 2
    assert "--grid picks a grid of a .vdb file" in capsys.readouterr().err


def test_measure_of_every_mode_goes_on_past_one_the_data_is_too_large_for(monkeypatch, capsys):
    """clvis view big.vdb --measure (every mode): a grid too large to make dense
    refused its isosurface modes and stopped the measure, the Gaussians
    unmeasured; each refused mode is now a line and the others are measured.
    Named alone, the refused mode is the command's error, as before."""
    from clvis import runtime

    vdb = str(DATA / "openvdb_small.vdb")
    monkeypatch.setattr(runtime, "host_available_bytes", lambda: 100_000)
    assert cli.main(["view", vdb, "--measure", "--size", "48x32"]) == 0
    out = capsys.readouterr().out
    rows = {ln.split()[0]: ln for ln in out.splitlines()[2:]}
    assert "refused" not in rows["gaussians"]
    for mode in ("iso", "iso+infill", "infill|iso"):
        assert rows[mode].split()[1] == "refused:" and "host memory" in rows[mode], rows[mode]
    assert cli.main(["view", vdb, "--measure", "iso", "--size", "48x32"]) == 2
    assert "host memory" in capsys.readouterr().err
