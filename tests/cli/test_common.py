"""What the commands share: the size rule, argument types, the camera options."""

import argparse

import numpy as np
import pytest
from PIL import Image

from clvis import cli
from clvis.cli import _common
from clvis.raster import MAX_IMAGE_SIDE


def test_one_size_rule():
    assert _common.MAX_SIDE == MAX_IMAGE_SIDE == 32768
    assert _common.MAX_SIDE**2 <= _common.MAX_PIXELS == 2**31 - 1  # 32-bit pixel indices
    assert _common.size("32768x32768") == (32768, 32768)
    assert _common.size(" 640 × 480 ") == (640, 480)
    for bad in ("32769x1", "0x5", "-5x5", "5x", "axb"):
        with pytest.raises(argparse.ArgumentTypeError):
            _common.size(bad)


def test_counts_and_reals():
    assert _common.count(1, 10)("1e1") == 10 and _common.count(1, 10)("1_0") == 10
    for bad in ("11", "0", "1.5", "nan", "x"):
        with pytest.raises(argparse.ArgumentTypeError):
            _common.count(1, 10)(bad)
    assert _common.real(0.0)("0") == 0.0
    for bad in ("-0.1", "inf", "nan"):
        with pytest.raises(argparse.ArgumentTypeError):
            _common.real(0.0)(bad)


def test_glue_values():
    p = argparse.ArgumentParser()
    p.add_argument("--eye")
    p.add_argument("--quiet", action="store_true")
    p.add_argument("file", nargs="?")
    glued = _common.glue_values(p, ["--eye", "-1,2,3", "--eye", "--quiet", "--", "--eye", "-x"])
    assert glued == ["--eye=-1,2,3", "--eye", "--quiet", "--", "--eye", "-x"]


def _args(**kw):
    fit = _common.FitView(direction=(-0.6, 1.0, -0.45), fov_y=35.0)
    base = {"view": ("fit", 0), "eye": None, "target": None, "up": None, "fov": None, "fit_view": fit}
    return argparse.Namespace(**{**base, **kw})


LO, HI = np.zeros(3), np.array([2.0, 4.0, 1.0])


def test_camera_default_is_the_commands_fit():
    from clvis import Camera

    cam = _common.camera_from_args(_args(), LO, HI, 64, 48)
    want = Camera.fit(LO, HI, direction=(-0.6, 1.0, -0.45), aspect=64 / 48, fov_y=35.0)
    assert np.allclose(cam.forward, want.forward) and np.allclose(cam.projection[:2], want.projection[:2])
    corners = np.array([[x, y, z] for x in (LO[0], HI[0]) for y in (LO[1], HI[1]) for z in (LO[2], HI[2])])
    p = cam.project(corners, 64, 48)  # the box's corners, not its sphere, fill the frame
    assert p.visible.all() and min(p.sx.min(), 64 - p.sx.max(), p.sy.min(), 48 - p.sy.max()) < 3


def test_camera_eye_target_up_fov():
    cam = _common.camera_from_args(_args(eye=(10.0, -3.0, 2.0), fov=20.0), LO, HI, 64, 48)
    assert np.allclose(cam.eye, (10, -3, 2))
    centre = 0.5 * (LO + HI)
    assert np.allclose(cam.forward, (centre - cam.eye) / np.linalg.norm(centre - cam.eye))
    assert np.isclose(np.degrees(2 * np.arctan(1 / cam.projection[1, 1])), 20.0)
    corners = np.array([[x, y, z] for x in (0, 2) for y in (0, 4) for z in (0, 1)], np.float32)
    assert cam.project(corners, 64, 48).depth.min() > cam.near  # the box lies in [near, far]
    assert cam.project(corners, 64, 48).depth.max() < cam.far
    cam = _common.camera_from_args(_args(target=(2.0, 4.0, 1.0), up=(0.0, 1.0, 1.0)), LO, HI, 64, 48)
    assert np.allclose(cam.forward, (np.array([2, 4, 1]) - cam.eye) / np.linalg.norm([2, 4, 1] - cam.eye))


@pytest.mark.parametrize("view", ["top", "front", "side"])
def test_camera_axis_views_stay_orthographic(view):
    cam = _common.camera_from_args(
        _args(
            view=(view, 0),
            eye=(1.0, 2.0, 50.0) if view == "top" else None,
            up=(1.0, 0.0, 0.0) if view == "top" else None,
        ),
        LO,
        HI,
        64,
        48,
    )
    assert cam.orthographic


def test_camera_samplers_take_fov():
    cam = _common.camera_from_args(_args(view=("hemisphere", 3), fov=25.0), LO, HI, 64, 48)
    assert np.isclose(np.degrees(2 * np.arctan(1 / cam.projection[1, 1])), 25.0)


@pytest.mark.parametrize("view", ["fit", "front"])
def test_camera_straight_down_without_up_is_north_up(view):
    """--eye straight above the target with no --up (a look from above, in
    perspective) was an error ("up: [0, 0, 1] is parallel to the view
    direction ... check --up"), the default up being +z: it is +y, north
    up, as --view top's, where the default lies along the view."""
    centre = 0.5 * (LO + HI)
    eye = (float(centre[0]), float(centre[1]), 50.0)
    cam = _common.camera_from_args(_args(view=(view, 0), eye=eye), LO, HI, 64, 48)
    assert np.allclose(cam.forward, (0, 0, -1))
    top = _common.camera_from_args(_args(view=("top", 0)), LO, HI, 64, 48)
    right = cam.view[0, :3]  # the camera's right and up in the world, as --view top's
    assert np.allclose(right, top.view[0, :3]) and np.allclose(cam.view[1, :3], top.view[1, :3])
    with pytest.raises(_common.CliError, match="up: .* is parallel to the view direction"):
        _common.camera_from_args(_args(view=(view, 0), eye=eye, up=(0.0, 0.0, 1.0)), LO, HI, 64, 48)


def test_camera_up_along_the_view_is_one_line(capsys, tmp_path):
    rc = cli.main(["iso", "--view", "top", "--up", "0,0,1", "--size", "16x16", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("clvis iso: error: camera: up") and err.count("\n") == 1


def _picture(path):
    with Image.open(path) as im:
        return np.asarray(im)


@pytest.mark.parametrize(
    "command, extra, png",
    [
        ("iso", [], "iso.png"),
        ("gauss", ["--lod", "low", "--no-labels"], "low.png"),
        ("render", ["--points", "3000", "--quiet", "--soft-z", "off", "--no-labels"], "depth.png"),
    ],
)
def test_every_command_takes_the_camera_options(tmp_path, capsys, command, extra, png):
    pictures = {}
    for name, opts in {
        "fit": [],
        "top": ["--view", "top"],
        "eye": ["--eye", "-40,-60,25", "--fov", "30"],
        "hemi": ["--view", "hemisphere:40", "--up", "0,0,1"],
    }.items():
        rc = cli.main([command, *extra, *opts, "--size", "40x30", "--out", str(tmp_path / name)])
        err = capsys.readouterr().err
        assert rc == 0, err
        pictures[name] = _picture(tmp_path / name / png)
        pictures[name] = pictures[name][-30:]  # iso.png: under its label band
        assert pictures[name].shape[:2] == (30, 40)
    assert not np.array_equal(pictures["fit"], pictures["top"])
    assert not np.array_equal(pictures["fit"], pictures["eye"])
