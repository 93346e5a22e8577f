"""clvis render: embedded clouds, files, views, progress and its errors."""

import io
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from clvis import cli, datasets, post
from clvis.camera import fit_camera
from clvis.cli import _common, raster
from clvis.io import PointCloud, save_npz, write_ply

SMALL = ["--size", "160x90", "--quiet", "--no-labels"]  # the images alone: exactly --size


def _png(path):
    with Image.open(path) as im:
        return np.asarray(im)


def _assert_picture(path, size=(160, 90)):
    """A PNG of the given (W, H) with something drawn: opaque pixels of more than one color."""
    a = _png(path)
    assert (a.shape[1], a.shape[0]) == size, path.name
    assert a.ndim == 3 and a.shape[2] == 4, path.name
    drawn = a[a[..., 3] > 0]
    assert len(drawn) > 50, f"{path.name} is blank"
    assert len(np.unique(drawn.reshape(len(drawn), -1), axis=0)) > 1, f"{path.name} has one color"


def _render(capsys, *args):
    """(exit status, stdout, stderr) of clvis render; argparse's exits too."""
    try:
        rc = cli.main(["render", *map(str, args)])
    except SystemExit as e:
        rc = e.code
    out, err = capsys.readouterr()
    return rc, out, err


def test_render_hurricane(tmp_path, capsys):
    rc, out, err = _render(capsys, "--points", 20000, "--out", tmp_path, *SMALL)
    assert rc == 0, err
    assert err == ""  # --quiet; and no terminal here anyway
    names = ["attribute-temperature", "colors", "depth", "velocity-angle", "velocity-magnitude", "soft-z"]
    assert sorted(p.stem for p in tmp_path.iterdir()) == sorted(names + ["overview"])
    for name in names:
        _assert_picture(tmp_path / f"{name}.png")
    overview = _png(tmp_path / "overview.png")
    assert overview.shape[1] > 3 * 160 and overview.shape[0] > 2 * 90  # a 3 x 2 grid
    assert len(np.unique(overview.reshape(-1, overview.shape[2]), axis=0)) > 10
    assert "20,000 points" in out and "160x90" in out and "covered" in out
    assert "drawn" in out and "culled" in out and "M points/s" in out
    assert str(tmp_path) in out


def test_render_terrain_attribute_colormap(tmp_path, capsys):
    rc, out, err = _render(
        capsys,
        "--dataset",
        "terrain",
        "--points",
        20000,
        "--attribute",
        "intensity",
        "--colormap",
        "magma",
        "--soft-z",
        "off",
        "--out",
        tmp_path,
        *SMALL,
    )
    assert rc == 0, err
    names = {p.stem for p in tmp_path.iterdir()}
    assert names == {"attribute-intensity", "colors", "depth", "depth-filtered", "overview"}
    for name in names - {"overview"}:
        _assert_picture(tmp_path / f"{name}.png")
    assert "intensity (magma)" in out


def test_render_depth_filter_option(tmp_path, capsys):
    rc, _, err = _render(
        capsys, "--points", 5000, "--depth-filter", 3, "--soft-z", "1.05", "--out", tmp_path, *SMALL
    )
    assert rc == 0, err
    _assert_picture(tmp_path / "depth-filtered.png")
    _assert_picture(tmp_path / "soft-z.png")
    rc, _, err = _render(
        capsys,
        "--dataset",
        "terrain",
        "--points",
        5000,
        "--depth-filter",
        0,
        "--out",
        tmp_path / "off",
        *SMALL,
    )
    assert rc == 0, err
    assert not (tmp_path / "off" / "depth-filtered.png").exists()
    assert "note" not in err  # a folder of this render's PNGs only


def test_an_earlier_renders_pngs_left_in_the_folder_are_named(tmp_path, capsys):
    """A render into a folder where an earlier one wrote depth-filtered.png
    (or post-lidar.png, another attribute's PNG): those stayed beside this
    render's, which wrote no such panel, and read as its own; a note names
    them (they are kept: the user's to remove)."""
    base = ["--dataset", "terrain", "--points", 3000, "--out", tmp_path, *SMALL]
    rc, _, err = _render(capsys, *base, "--depth-filter", 2)
    assert rc == 0, err
    (tmp_path / "notes.png").write_bytes(b"")  # not one of clvis render's names: not named
    rc, _, err = _render(capsys, *base, "--depth-filter", 0, "--soft-z", "off")
    assert rc == 0, err
    note = f"clvis render: note: {tmp_path} also holds depth-filtered.png, soft-z.png from an earlier run"
    assert note in err, err
    assert (tmp_path / "depth-filtered.png").exists() and "notes.png" not in err


def test_render_progress(tmp_path, capsys):
    rc, _, err = _render(capsys, "--points", 5000, "--size", "64x36", "--progress", "--out", tmp_path)
    assert rc == 0
    lines = err.splitlines()
    for stage in (
        "generating hurricane",
        "uploading + Morton order",
        "rendering + resolving",
        "soft z",
        "writing PNGs",
    ):
        assert any(stage in line and line.rstrip().endswith(")") and " s " in line for line in lines), (
            stage,
            err,
        )
    assert "\r" not in err  # not a terminal: one line per stage
    rc, _, err = _render(
        capsys, "--points", 5000, "--size", "64x36", "--progress", "--quiet", "--out", tmp_path
    )
    assert rc == 0 and err == ""


def test_progress_on_a_terminal(monkeypatch):
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    stream = Terminal()
    monkeypatch.setattr(sys, "stderr", stream)
    progress = _common.Progress(True)
    with progress.stage("reading x.ply"):
        pass
    with pytest.raises(RuntimeError), progress.stage("rendering"):
        raise RuntimeError
    text = stream.getvalue()
    assert text.startswith("\r\x1b[K") and "reading x.ply" in text
    assert text.endswith("\n") and "failed" in text.splitlines()[-1]
    assert _common.Progress(False).stage("x").__enter__() is None


def _small_cloud(n=5000):
    d = datasets.hurricane(n, seed=1)
    return PointCloud(
        d["positions"],
        colors=d["colors"],
        velocity=d["velocity"],
        attributes={"pressure": d["attributes"]["pressure"]},
    )


def test_render_ply_file(tmp_path, capsys):
    path = tmp_path / "storm.ply"
    write_ply(path, _small_cloud())
    rc, out, err = _render(capsys, path, "--attribute", "pressure", "--out", tmp_path / "png", *SMALL)
    assert rc == 0, err
    for name in ("attribute-pressure", "colors", "depth", "velocity-angle", "soft-z"):
        _assert_picture(tmp_path / "png" / f"{name}.png")
    assert f"{path}, 5,000 points" in out


def test_render_las_file(tmp_path, capsys):
    """A LAS file has more attributes than the G-buffers hold: only the colored one travels."""
    laspy = pytest.importorskip("laspy")
    d = datasets.terrain(5000, seed=2)
    las = laspy.create(point_format=3, file_version="1.2")
    las.header.offsets = [500_000.0, 5_000_000.0, 0.0]  # UTM-like: clvis keeps an origin
    las.header.scales = [0.01, 0.01, 0.01]
    las.x = d["positions"][:, 0] + 500_000.0
    las.y = d["positions"][:, 1] + 5_000_000.0
    las.z = d["positions"][:, 2]
    las.intensity = (d["attributes"]["intensity"] * 65535).astype(np.uint16)
    las.classification = d["attributes"]["classification"]
    for i, c in enumerate(("red", "green", "blue")):
        setattr(las, c, d["colors"][:, i].astype(np.uint16) << 8)
    path = tmp_path / "scan.las"
    las.write(path)
    rc, out, err = _render(capsys, path, "--view", "top", "--out", tmp_path / "png", *SMALL)
    assert rc == 0, err
    assert "its colors" in out  # RGB first, as Open3D, PyVista, Potree and CloudCompare show it
    assert {p.stem for p in (tmp_path / "png").iterdir()} == {"colors", "depth", "soft-z", "overview"}
    rc, out, err = _render(
        capsys, path, "--view", "top", "--attribute", "intensity", "--out", tmp_path / "i", *SMALL
    )
    assert rc == 0, err
    assert "colored by intensity" in out
    for name in ("attribute-intensity", "colors", "depth"):
        _assert_picture(tmp_path / "i" / f"{name}.png")
    # the bounds in the file's own coordinates, the origin an internal detail
    (line,) = [t for t in out.splitlines() if t.startswith("  bounds")]
    x, y, _ = (float(part.split("..")[0]) for part in line.split()[1:6:2])
    assert 499_000 < x < 501_000 and 4_999_000 < y < 5_001_000 and "(the file's coordinates)" in line
    rc, out, err = _render(capsys, path, "--attribute", "classification", "--out", tmp_path / "c", *SMALL)
    assert rc == 0, err
    assert "colored by classification (ASPRS classes:" in out
    _assert_picture(tmp_path / "c" / "attribute-classification.png")


def test_render_third_party_laz(tmp_path, capsys):
    """laspy's own sample (13 attributes): colored by intensity, and with
    --point-size the sparse scan covers more of the image."""
    pytest.importorskip("laspy")
    path = Path(__file__).parents[1] / "data" / "laspy_simple.laz"
    # --transparent: empty pixels keep alpha 0, so coverage can be counted
    rc, out, err = _render(capsys, path, "--view", "top", "--transparent", "--out", tmp_path / "one", *SMALL)
    assert rc == 0, err
    assert "its colors" in out and "dropped" not in out  # the file has RGB
    one = _png(tmp_path / "one" / "colors.png")[..., 3] > 0
    rc, out, err = _render(
        capsys, path, "--view", "top", "--point-size", 3, "--transparent", "--out", tmp_path / "three", *SMALL
    )
    assert rc == 0, err
    assert "points 3x3 pixels" in out
    three = _png(tmp_path / "three" / "colors.png")[..., 3] > 0
    assert three.sum() > 3 * one.sum() and (three | one).sum() == three.sum()
    _assert_picture(tmp_path / "three" / "colors.png")


def test_render_npz_positions_only(tmp_path, capsys):
    path = tmp_path / "cloud.npz"
    save_npz(path, PointCloud(_small_cloud().positions))
    rc, out, err = _render(capsys, path, "--soft-z", "off", "--out", tmp_path / "png", *SMALL)
    assert rc == 0, err
    assert {p.stem for p in (tmp_path / "png").iterdir()} == {"attribute-z", "depth", "overview"}
    _assert_picture(tmp_path / "png" / "attribute-z.png")
    assert "colored by z (viridis)" in out
    rc, out, err = _render(capsys, path, "--attribute", "x", "--out", tmp_path / "x", *SMALL)
    assert rc == 0, err
    _assert_picture(tmp_path / "x" / "attribute-x.png")


def test_render_colors_only(tmp_path, capsys):
    cloud = _small_cloud()
    path = tmp_path / "cloud.npz"
    save_npz(path, PointCloud(cloud.positions, colors=cloud.colors))
    rc, out, err = _render(capsys, path, "--out", tmp_path / "png", *SMALL)
    assert rc == 0, err
    assert {p.stem for p in (tmp_path / "png").iterdir()} == {"colors", "depth", "soft-z", "overview"}
    _assert_picture(tmp_path / "png" / "colors.png")
    assert "its colors" in out


@pytest.mark.parametrize(
    "view", ["fit", "top", "front", "side", "hemisphere:0", "hemisphere:127", "grid:0", "grid:383"]
)
def test_render_views(tmp_path, capsys, view):
    path = tmp_path / "cloud.npz"
    save_npz(path, _small_cloud(20000))
    rc, out, err = _render(capsys, path, "--view", view, "--soft-z", "off", "--out", tmp_path / "png", *SMALL)
    assert rc == 0, err
    assert f"view      {view}, 160x90" in out
    a = _png(tmp_path / "png" / "depth.png")
    assert a.shape == (90, 160, 4)
    if not view.startswith("grid"):  # a grid camera may look past the cloud
        _assert_picture(tmp_path / "png" / "colors.png")  # the cloud's RGB, shown first


@pytest.mark.parametrize("view", ["fit", "top", "front", "side", "hemisphere:3", "grid:7"])
def test_render_degenerate_clouds(tmp_path, capsys, view):
    """One point far from the origin, and a cloud with NaN rows: still a picture."""
    one = tmp_path / "one.npy"
    np.save(one, np.array([[1000.0, -2000.0, 50.0]], np.float32))
    rc, out, err = _render(capsys, one, "--view", view, "--out", tmp_path / "one", *SMALL)
    assert rc == 0, err
    assert "one.npy, 1 point, colored by" in out
    if view in ("fit", "top", "front", "side"):
        assert "covered   1 of" in out
        # one value to colour (z, depth): the colormaps' middle, not their dark ends
        from clvis.colormap import lut

        for name, cmap in (("attribute-z", "viridis"), ("depth", "magma")):
            with Image.open(tmp_path / "one" / f"{name}.png") as im:
                px = np.asarray(im.convert("RGB")).reshape(-1, 3)
            middle = lut(cmap)[len(lut(cmap)) // 2, :3].astype(int)
            assert (np.abs(px.astype(int) - middle).max(axis=1) <= 12).any(), name
    nan = tmp_path / "nan.npy"
    p = _small_cloud(1000).positions.copy()
    p[::7] = np.nan
    np.save(nan, p)
    rc, out, err = _render(capsys, nan, "--view", view, "--out", tmp_path / "nan", *SMALL)
    assert rc == 0, err
    assert "dropped   143 points with a NaN or infinite coordinate" in out
    allnan = tmp_path / "allnan.npy"
    np.save(allnan, np.full((3, 3), np.nan, np.float32))
    rc, _, err = _render(capsys, allnan, "--view", view, "--out", tmp_path / "allnan", *SMALL)
    assert rc == 2 and "no point has finite coordinates" in err


def test_fit_frames_every_point():
    cloud = _small_cloud(20000)
    lo, hi = cloud.bounds()
    for w, h in ((1920, 1080), (100, 400)):
        fit = raster._FIT
        cam = fit_camera(cloud.positions, lo, hi, direction=fit.direction, fov_y=fit.fov_y, aspect=w / h)
        visible = cam.project(cloud.positions, w, h).visible
        assert visible.all()
        # and tightly: the points reach within a few pixels of two sides
        p = cam.project(cloud.positions, w, h)
        margin = min(p.sx.min(), w - p.sx.max(), p.sy.min(), h - p.sy.max())
        assert margin < 0.05 * max(w, h)


def test_shrink_keeps_points():
    a = np.zeros((4, 6, 4), np.uint8)
    a[3, 5] = (10, 20, 30, 255)
    a[0, 0] = (1, 2, 3, 100)
    a[1, 1] = (4, 5, 6, 200)
    s = raster._shrink(a, 2)
    assert s.shape == (2, 3, 4)
    assert tuple(s[1, 2]) == (10, 20, 30, 255) and tuple(s[0, 0]) == (4, 5, 6, 200)
    assert s[..., 3].astype(bool).sum() == 2


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["--attribute", "nope", "--points", "1000"],
            (
                "no attribute 'nope' in the embedded hurricane; it has pressure, temperature, speed and the "
                "coordinates x, y, z"
            ),
        ),
        (["--size", "12by4"], "argument --size: expected WIDTHxHEIGHT"),
        (["--size", "0x10"], "argument --size: width and height must lie in"),
        (["--view", "grid:384"], "argument --view: grid:K needs K in 0..383"),
        (["--view", "diagonal"], "argument --view: expected fit, top"),
        (["--colormap", "viridiss"], "unknown colormap 'viridiss'"),
        (["--points", "-5"], "argument --points: expected a positive integer"),
        (["--soft-z", "0.5"], "argument --soft-z: expected a factor >= 1"),
        (["--depth-filter", "x"], "argument --depth-filter: expected pyramid levels"),
        (["--point-size", "0"], "argument --point-size: expected auto or a positive integer in 1..64"),
        (["--point-size", "65"], "argument --point-size: expected auto or a positive integer in 1..64"),
        (["--dataset", "moon"], "argument --dataset: invalid choice"),
        (["--post", "infill"], "--post infill: the in-fill network fills an isosurface's unfinished rays"),
        (["missing.ply"], "missing.ply: no such file"),
        (["cloud.ply", "--points", "10"], "--dataset and --points choose an embedded cloud"),
    ],
)
def test_render_errors(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    write_ply(tmp_path / "cloud.ply", _small_cloud(100))
    rc, _, err = _render(capsys, *args, "--size", "32x18")
    assert rc == 2
    assert err.startswith("clvis render: error: ") and message in err, err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "clvis-render").exists()  # nothing written


@pytest.mark.parametrize(
    "name, content, message",
    [
        (
            "bad.ply",
            b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nend_header\n",
            "PLY file",
        ),
        ("bad.npz", b"not a zip", "malformed NPZ file"),
        ("cloud.e58", b"1 2 3\n", "unknown point cloud format '.e58'"),
        ("empty.npy", None, "holds no points"),
    ],
)
def test_render_unreadable_files(tmp_path, capsys, name, content, message):
    path = tmp_path / name
    if content is None:
        np.save(path, np.zeros((0, 3), np.float32))
    else:
        path.write_bytes(content)
    rc, _, err = _render(capsys, path, "--out", tmp_path / "png")
    assert rc == 2
    assert err.startswith(f"clvis render: error: {path}") and message in err, err
    assert err.count("\n") == 1
    assert not (tmp_path / "png").exists()


def test_render_error_exit_status(tmp_path):
    """The real process: exit status 2, one line on stderr, no traceback."""
    env = dict(os.environ)
    root = str(Path(cli.__file__).resolve().parent.parent)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")]))
    r = subprocess.run(
        [sys.executable, "-m", "clvis.cli", "render", "nowhere.las"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert r.returncode == 2
    assert r.stderr == "clvis render: error: nowhere.las: no such file\n"
    assert r.stdout == ""


@pytest.mark.parametrize(
    "args,panel",
    [
        (["--post", "narvis"], "post-narvis"),
        (["--dataset", "terrain", "--depth-filter", 3, "--post", "lidar"], "post-lidar"),
        (["--post", "lidar"], "post-lidar"),  # the depth filter comes on by itself
    ],
    ids=["narvis", "lidar", "lidar-default-filter"],
)
def test_render_post(tmp_path, capsys, args, panel):
    """--post runs the network on the device path (a render of the planes it
    reads) and writes its picture beside the host render's panels."""
    rc, out, err = _render(capsys, "--points", 20000, *args, "--out", tmp_path, *SMALL)
    assert rc == 0, err
    _assert_picture(tmp_path / f"{panel}.png")
    assert "a frame from render to picture, G-buffers on the device" in out


def test_render_post_narvis_picks_the_model_the_planes_allow(tmp_path, capsys):
    """--post narvis on laspy's real sample scan (no velocity) runs
    narvis-scan (its kNN splat radius plane) and says so on stderr; on the
    hurricane (a velocity) it runs narvis and says that; --post narvis-scan
    names it outright, --compare scores it against its isotropic Gaussians."""
    pytest.importorskip("laspy")
    path = Path(__file__).parents[1] / "data" / "laspy_simple.laz"
    rc, out, err = _render(capsys, path, "--view", "top", "--post", "narvis", "--out", tmp_path / "a", *SMALL)
    assert rc == 0, err
    assert "--post narvis: " in err and "model narvis-scan (no velocity" in err
    assert "PostNetwork('narvis-scan'" in out
    # its pipeline: the depth filter before the network (clvis.post.specs)
    assert re.search(
        r"through its depth filter \(4 levels, strength 1.4; [\d,]+ far-side points removed\)", out
    )
    assert "warning" not in err  # its median splat radius is inside the training's
    assert "the splat radius plane" not in err  # 1,065 points: well under KNN_NOTE_SECONDS
    _assert_picture(tmp_path / "a" / "post-narvis-scan.png")
    assert not (tmp_path / "a" / "post-narvis.png").exists()
    rc, out, err = _render(
        capsys, path, "--view", "top", "--post", "narvis-scan", "--compare", "--out", tmp_path / "b", *SMALL
    )
    assert rc == 0, err
    assert "--post narvis:" not in err and "PostNetwork('narvis-scan'" in out
    assert "compare   against the Gaussian renderer" in out
    _assert_picture(tmp_path / "b" / "post-narvis-scan.png")
    _assert_picture(tmp_path / "b" / "gaussians.png")
    rc, out, err = _render(capsys, "--points", 20000, "--post", "narvis", "--out", tmp_path / "c", *SMALL)
    assert rc == 0, err
    assert "model narvis (it has a velocity" in err and "PostNetwork('narvis'" in out
    _assert_picture(tmp_path / "c" / "post-narvis.png")
    # narvis-scan's guard (off by default) against the classical splat
    rc, out, err = _render(capsys, path, "--post", "narvis", "--post-guard", "--out", tmp_path / "d", *SMALL)
    assert rc == 0, err
    _assert_picture(tmp_path / "d" / "post-narvis-scan.png")


def test_render_post_narvis_scan_warns_of_a_cloud_far_sparser_than_its_training(tmp_path, capsys):
    """A few hundred points at 320x240 (pyvista's nut.ply: tens of pixels
    apart) are splats far wider than any narvis-scan trained on: the render
    still runs, and says so with the measured radius; at full size
    (--post-scale 1) it warns, and by default it renders the network's frame
    as much smaller as keeps 64 pixels a side and says that."""
    pos = np.random.default_rng(3).random((300, 3)).astype(np.float32)
    np.save(tmp_path / "sparse.npy", pos)
    args = ["--post", "narvis-scan", "--out", tmp_path, "--size", "320x240", "--quiet"]
    rc, out, err = _render(capsys, tmp_path / "sparse.npy", *args, "--post-scale", "1")
    assert rc == 0, err
    m = re.search(r"--post narvis-scan: warning: the points' median splat radius is ([\d.]+) pixels", err)
    assert m and float(m.group(1)) > 2 * post.specs.spec("narvis-scan").radius_px_trained[1], err
    assert "smaller" not in err + out
    _assert_picture(tmp_path / "post-narvis-scan.png", (320, 240))
    rc, out, err = _render(capsys, tmp_path / "sparse.npy", *args)
    assert rc == 0, err
    said = f"its frame rendered 3x smaller and resized up: the points' median splat radius, {m.group(1)} "
    assert said in err
    assert "at 107x80 (3x smaller, resized up)" in out
    _assert_picture(tmp_path / "post-narvis-scan.png", (320, 240))


def test_render_post_narvis_scan_renders_a_sparse_cloud_smaller(tmp_path, capsys):
    """laspy's simple.las at 480x320 (1,065 points, a median splat radius of
    8 pixels, over the 3.3 of narvis-scan's training frames): at full size
    the network draws its wide Gaussians as squares; its frame rendered 3x
    smaller (auto) and resized up scores 6 dB more against the Gaussian
    renderer (15.1 -> 21.3 dB, SSIM 0.46 -> 0.75)."""
    pytest.importorskip("laspy")
    path = Path(__file__).parents[1] / "data" / "laspy_simple.laz"
    scores = {}
    for scale in ("1", "auto"):
        rc, out, err = _render(
            capsys, path, "--post", "narvis-scan", "--compare", "--post-scale", scale,
            "--size", "480x320", "--quiet", "--out", tmp_path / scale,
        )  # fmt: skip
        assert rc == 0, err
        m = re.search(r"narvis-scan network ([\d.]+) dB, SSIM ([\d.]+)", out)
        assert m, out
        scores[scale] = float(m.group(1)), float(m.group(2))
    assert "its frame rendered 3x smaller" in err and "warning" not in err
    assert scores["auto"][0] > scores["1"][0] + 4 and scores["auto"][1] > scores["1"][1] + 0.2, scores
    rc, _, err = _render(capsys, path, "--post-scale", "2", "--out", tmp_path / "x", *SMALL)
    assert rc == 2 and "--post-scale scales a post network's frame: add --post" in err
    rc, _, err = _render(capsys, path, "--post", "narvis", "--post-scale", "0", "--out", tmp_path, *SMALL)
    assert rc == 2 and "--post-scale: expected a whole number 1..64 or auto, got '0'" in err


@pytest.mark.parametrize("name", ["brain.nii.gz", "grid.vti", "v.raw"])
def test_render_of_a_volume_file_says_which_commands_read_it(tmp_path, capsys, name):
    # "unknown point cloud format '.gz'; expected one of .ply, ..." of a NIfTI
    path = tmp_path / name
    path.write_bytes(b"\0" * 64)
    rc, _, err = _render(capsys, path, "--out", tmp_path / "o", *SMALL)
    assert rc == 2
    kind = name[name.index(".") :]
    assert f"{path}: a volume file ({kind}), not a point cloud; clvis iso, clvis gauss and clvis view" in err


@pytest.mark.parametrize(
    "name", ["cloud-binary.vtp", "cloud-binary42.vtk", "cloud-zlib.vtu", "cloud-appended.vts"]
)
def test_render_reads_vtk_point_sets(tmp_path, capsys, name):
    """A .vtp, a .vtu, a .vts and a legacy POLYDATA .vtk (pyvista's
    globe.vtk's kind) are point clouds: rendered, their RGB point data the
    colours."""
    pytest.importorskip("vtk", reason="vtk is in the test extra")
    from fuzz.seeds import vtk_point_set

    path = tmp_path / name
    vtk_point_set(path, 400, name.split("-")[1].split(".")[0])
    rc, out, err = _render(capsys, path, "--out", tmp_path / "o", *SMALL)
    assert rc == 0, err
    _assert_picture(tmp_path / "o" / "colors.png")


def test_render_of_a_vtk_volume_says_which_commands_read_it(tmp_path, capsys):
    # a .vtk is read by its DATASET: STRUCTURED_POINTS is a volume
    path = tmp_path / "grid.vtk"
    path.write_text(
        "# vtk DataFile Version 3.0\nx\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 1 1\n"
        "POINT_DATA 2\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2\n"
    )
    rc, _, err = _render(capsys, path, "--out", tmp_path / "o", *SMALL)
    assert rc == 2
    assert f"{path}: a volume file (.vtk), not a point cloud; clvis iso, clvis gauss and clvis view" in err


@pytest.mark.parametrize(
    "args",
    [["--out", "/proc/self/clvis-out"], ["--orbit", "2", "--movie", "/proc/self/orbit.mp4"]],
    ids=["out", "movie"],
)
def test_render_refuses_an_unwritable_folder_before_rendering(tmp_path, capsys, args):
    # a folder no file can be made in (read-only; /proc/self for root too) failed
    # when the first PNG was written, after the render; a --movie there after every
    # frame, naming its temporary ".orbit.partial.mp4" ("No such file or directory")
    if not Path("/proc/self").is_dir():
        pytest.skip("no /proc/self here to stand for a read-only folder")
    path = Path(__file__).parents[1] / "data" / "pyvista_ant.ply"
    rc, out, err = _render(
        capsys, path, *(["--out", tmp_path / "o"] if args[0] != "--out" else []), *args, *SMALL
    )
    assert rc == 2
    assert "no file can be made in /proc/self" in err and "partial" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("dataset", ["hurricane", "terrain"])
def test_render_points_beyond_host_memory_are_refused_before_making_them(
    tmp_path, capsys, monkeypatch, dataset
):
    # --points 4000000000 made the hurricane until the OOM killer ended it (6 min, status 137)
    from clvis import runtime

    monkeypatch.setattr(runtime.memory, "host_available_bytes", lambda: 100 << 20)
    rc, _, err = _render(capsys, "--dataset", dataset, "--points", "2000000", "--out", tmp_path / "o", *SMALL)
    assert rc == 2
    assert f"--points 2,000,000 (the embedded {dataset}): needs" in err and "only 0.10 GB is available" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("dataset", ["hurricane", "terrain"])  # a colour bar; a class legend
def test_render_one_pixel_wide_has_no_bar_or_legend(tmp_path, capsys, dataset):
    # --size 1x1 rendered, then failed drawing the panel's frame: "width: a colour
    # bar needs at least 2 columns, got 1" ("a legend" for the terrain's classes)
    rc, _, err = _render(capsys, "--dataset", dataset, "--points", "3000", "--size", "1x3", "--out", tmp_path)
    assert rc == 0, err
    assert _png(tmp_path / "overview.png").shape[1] >= 1
    assert (
        tmp_path / ("attribute-classification.png" if dataset == "terrain" else "attribute-temperature.png")
    ).is_file()


@pytest.mark.parametrize("suffix", [".ply", ".npz"])
def test_render_post_narvis_names_the_first_non_finite_velocity(tmp_path, capsys, suffix):
    """A NaN velocity of a point drawn: the file, the velocity and the point
    (it was "vel_x: 1 covered pixels with a NaN or infinite value"); one of a
    point never drawn (a NaN coordinate) is not the network's business."""
    from clvis.io import PointCloud, save_npz, write_ply

    rng = np.random.default_rng(4)
    n = 2000
    pos, v = rng.random((n, 3)), rng.random((n, 3))
    pos[3, 0] = v[3, 2] = np.nan  # never drawn
    v[123, 1] = np.nan
    cloud = PointCloud(pos, velocity=v, attributes={"t": rng.random(n)})
    path = tmp_path / f"vel{suffix}"
    write_ply(path, cloud) if suffix == ".ply" else save_npz(path, cloud)
    rc, _, err = _render(
        capsys, path, "--post", "narvis", "--attribute", "t", "--out", tmp_path / "a", *SMALL
    )
    assert rc == 2
    assert f"{path.name}: velocity: point 123 is [" in err and "nan" in err and "(1 of 2,000 points)" in err


def test_render_post_narvis_scan_drops_non_finite_points(tmp_path, capsys):
    """A cloud with NaN / infinite coordinates renders as it does without
    --post (those points dropped, said so): narvis-scan's kNN radius plane is
    of the finite points (it failed with scipy's 'data must be finite')."""
    rng = np.random.default_rng(3)
    pos = rng.random((3000, 3)).astype(np.float32)
    pos[5, 0], pos[17, 2] = np.nan, np.inf
    path = tmp_path / "holes.npy"
    np.save(path, pos)
    rc, out, err = _render(capsys, path, "--post", "narvis", "--out", tmp_path / "a", *SMALL)
    assert rc == 0, err
    assert "model narvis-scan" in err and "dropped   2 points with a NaN or infinite coordinate" in out
    _assert_picture(tmp_path / "a" / "post-narvis-scan.png")


def test_render_compare_narvis_scan_in_the_colours_drawn(tmp_path, capsys):
    """--compare's narvis-scan target is splatted in the colours the network's
    points were drawn in: a scan whose RGB is all black is coloured by its
    intensity, and so is its target (it was black: the scores meant nothing);
    a cloud without colours, coloured by z, is compared too (it was refused)."""
    laspy = pytest.importorskip("laspy")
    d = datasets.terrain(4000, seed=5)
    las = laspy.create(point_format=3, file_version="1.2")  # red = green = blue = 0
    las.header.scales = [0.01, 0.01, 0.01]
    las.x, las.y, las.z = d["positions"].T
    las.intensity = (d["attributes"]["intensity"] * 65535).astype(np.uint16)
    path = tmp_path / "black.las"
    las.write(path)
    npy = tmp_path / "bare.npy"
    np.save(npy, d["positions"])
    for src, what in ((path, "colored by intensity"), (npy, "colored by z")):
        out_dir = tmp_path / src.stem
        rc, out, err = _render(
            capsys, src, "--view", "top", "--post", "narvis", "--compare", "--out", out_dir, *SMALL
        )
        assert rc == 0, err
        assert what in out and "model narvis-scan" in err
        _assert_picture(out_dir / "gaussians.png")
        net_db = float(re.search(r"narvis-scan network +([-\d.]+) dB", out).group(1))
        assert net_db > 15, out  # against a black target: ~10 dB
        # the speed against GR as a ratio >= 1, "faster" or "slower" (it said "0.2x faster")
        ratio = re.search(r"ms: ([\d.]+)x (faster|slower)", out)
        assert ratio and float(ratio.group(1)) >= 1.0, out


def test_render_post_narvis_scan_says_when_its_knn_radius_is_slow(tmp_path, capsys, monkeypatch):
    """The kNN radius plane is computed on every call (seconds for a big LAS):
    over KNN_NOTE_SECONDS the command says how long it took on stderr (with
    --quiet too: it is not the progress display), unless the progress display
    shows that stage's time already."""
    pytest.importorskip("laspy")
    from clvis.cli import raster

    path = Path(__file__).parents[1] / "data" / "laspy_simple.laz"
    monkeypatch.setattr(raster, "KNN_NOTE_SECONDS", 0.0)  # any time is over it
    rc, _, err = _render(capsys, path, "--view", "top", "--post", "narvis", "--out", tmp_path / "a", *SMALL)
    assert rc == 0, err
    got = re.search(
        r"--post narvis: the splat radius plane \(mean 4-NN distance of ([\d,]+) points\) "
        r"took ([\d.]+) s; it is computed on every call",
        err,
    )
    assert got, err
    assert int(got.group(1).replace(",", "")) == 1065 and float(got.group(2)) >= 0
    shown = ["--size", "160x90", "--no-labels", "--progress"]  # the progress display, into a pipe
    rc, _, err = _render(capsys, path, "--post", "narvis-scan", "--out", tmp_path / "b", *shown)
    assert rc == 0, err
    assert "splat radius plane (mean 4-NN distance)" in err and "took" not in err


def test_render_post_narvis_scan_times_the_knn_not_scipys_import(tmp_path):
    """The kNN radius note times knn_sigma, not the first import of
    scipy.spatial (a fresh command on 4 points said 'took 1.0 s; it is
    computed on every call'): here that import is made to take 2 s."""
    np.save(tmp_path / "four.npy", np.random.default_rng(0).random((4, 3)))
    code = (
        "import importlib.abc, sys, time\n"
        "class Slow(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'scipy.spatial':\n"
        "            time.sleep(2)\n"
        "        return None\n"
        "sys.meta_path.insert(0, Slow())\n"
        "from clvis.cli import main\n"
        "sys.exit(main(sys.argv[1:]))\n"
    )
    args = ["render", "four.npy", "--post", "narvis", "--out", "png", *SMALL]
    r = subprocess.run(
        [sys.executable, "-c", code, *args], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0, r.stderr
    assert "model narvis-scan" in r.stderr and "the splat radius plane" not in r.stderr, r.stderr


def test_render_post_guard(tmp_path, capsys):
    """--post-guard / --no-post-guard: the LiDAR network with and without its
    self-check (clvis.post.guard; on by default); refused without --post and
    for narvis, which has none."""
    base = ["--dataset", "terrain", "--points", 20000, "--depth-filter", 3, "--post", "lidar", *SMALL]
    for flag in ("--post-guard", "--no-post-guard"):
        rc, out, err = _render(capsys, *base, flag, "--out", tmp_path / flag)
        assert rc == 0, err
        _assert_picture(tmp_path / flag / "post-lidar.png")
    rc, _, err = _render(capsys, "--post-guard", "--out", tmp_path, *SMALL)
    assert rc == 2 and "--post-guard guards a post network: add --post lidar" in err
    rc, _, err = _render(capsys, "--post", "narvis", "--post-guard", "--out", tmp_path, *SMALL)
    assert rc == 2 and "the narvis network has no guard" in err


def test_post_lidar_with_the_filter_off(tmp_path, capsys):
    """--post lidar --depth-filter 0: the network needs the filtered image."""
    rc, out, err = _render(
        capsys, "--points", 2000, "--post", "lidar", "--depth-filter", 0, "--out", tmp_path, *SMALL
    )
    assert rc == 2 and "--depth-filter 0 turns the filter off" in err


def test_point_colors_panel_names_a_colour_the_file_gives_every_point():
    """LAS files store RGB 0 where no photograph was taken (laspy's plane.laz):
    the colours panel says so rather than look like a failed render."""
    from clvis.cli.raster import _colors_title

    assert _colors_title(np.zeros((5, 3), np.float32)) == "point colors (all (0, 0, 0) in the file)"
    assert _colors_title(np.full((5, 4), 0.5, np.float32)) == "point colors (all (0.5, 0.5, 0.5) in the file)"
    varied = np.zeros((5, 3), np.float32)
    varied[2, 1] = 1.0
    assert _colors_title(varied) == "point colors"
    assert _colors_title(None) == "point colors"


def test_render_says_when_a_given_camera_sees_no_point(tmp_path, capsys):
    """A camera looking away from a georeferenced cloud (e.g. one given in
    the cloud's local coordinates): the note says where the points are, not
    to draw bigger points."""
    world = np.random.default_rng(1).uniform((635_000, 4_850_000, 100), (635_300, 4_850_200, 160), (2000, 3))
    path = tmp_path / "utm.npz"
    np.savez(path, positions=world)
    args = ("--eye", "-400,-300,300", "--target", "150,100,30", "--out", tmp_path / "png", *SMALL)
    rc, out, err = _render(capsys, path, *args)
    assert rc == 0, err
    assert "no point is in view of this camera; --eye and --target are in the file's coordinates" in err
    assert "points span 635" in err and "--point-size auto" not in err


def test_render_post_reads_a_model_dir(tmp_path, capsys):
    """--model-dir: a `clvis train --out` folder's model, not the shipped one
    (the CLI had no way to run a retrained network: only post.load(directory=))."""
    import shutil

    from clvis.post.infer import MODELS

    mine = tmp_path / "mine"
    mine.mkdir()
    for f in MODELS.glob("lidar.*"):
        shutil.copy(f, mine / f.name)
    args = ["--points", 20000, "--post", "lidar", "--no-post-guard", *SMALL]
    rc, out, err = _render(capsys, *args, "--model-dir", mine, "--out", tmp_path / "a")
    assert rc == 0, err
    rc, out, err = _render(capsys, *args, "--out", tmp_path / "b")
    assert rc == 0, err
    np.testing.assert_array_equal(
        _png(tmp_path / "a" / "post-lidar.png"), _png(tmp_path / "b" / "post-lidar.png")
    )
    (mine / "lidar.onnx").unlink()
    rc, out, err = _render(capsys, *args, "--model-dir", mine, "--out", tmp_path / "c")
    assert rc == 2 and err == f"clvis render: error: {mine / 'lidar.onnx'}: model file missing\n"
    rc, out, err = _render(capsys, "--points", 20000, "--model-dir", mine, *SMALL, "--out", tmp_path / "d")
    assert rc == 2 and "--model-dir: where a post network's model is: add --post" in err
