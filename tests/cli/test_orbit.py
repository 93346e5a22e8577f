"""--orbit N [--movie FILE] on clvis render, iso and gauss (clvis.cli.orbit):
N frames around the data, written as they are made, a Ctrl-C leaving only
complete files; a movie where the encoder is installed, a clear error naming
the extra where not. Through main(), with exit status and stderr."""

import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from clvis import cli
from clvis.cli import orbit

DATA = Path(__file__).parents[1] / "data"
SIMPLE = DATA / "laspy_simple.laz"  # laspy's simple.laz: 1,065 points, RGB, classes

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def _main(capsys, *args):
    try:
        rc = cli.main([*map(str, args)])
    except SystemExit as e:
        rc = e.code
    out, err = capsys.readouterr()
    return rc, out, err


def _png(path):
    with Image.open(path) as im:
        return np.asarray(im)


def _frames(folder):
    return sorted(p.name for p in Path(folder).glob("orbit-*.png"))


def test_render_orbit_turns_around_the_cloud(tmp_path, capsys):
    pytest.importorskip("laspy")
    rc, out, err = _main(
        capsys,
        "render",
        SIMPLE,
        "--size",
        "96x64",
        "--point-size",
        "2",
        "--orbit",
        4,
        "--quiet",
        "--no-labels",
        "--out",
        tmp_path,
    )
    assert rc == 0, err
    assert _frames(tmp_path) == [f"orbit-{k:04d}.png" for k in range(4)]
    assert "orbit     4 frames, orbit-0000.png .. orbit-0003.png" in out
    frames = [_png(tmp_path / f"orbit-{k:04d}.png") for k in range(4)]
    # the first frame looks as colors.png does, from as far back as the whole turn needs
    for f in frames[1:]:
        assert f.shape == (64, 96, 4) and not np.array_equal(f, frames[0])
        assert (f[..., :3] != (24, 24, 28)).any(axis=2).sum() > 100  # the cloud stays in view
    assert not list(tmp_path.glob(".*"))  # no temporary file left


def test_turning_a_full_circle_gives_the_camera_back():
    import argparse

    from clvis import Camera

    args = argparse.Namespace(view=("fit", 0), up=None)
    cam = Camera.look_at((3, -4, 2), (0.5, 0.5, 0.5), (0, 0, 1), 40, 1.5, 0.1, 20)
    lo, hi = (0, 0, 0), (1, 1, 1)
    assert orbit.turn(cam, lo, hi, 360.0, args) is cam  # no turn: the camera itself, near and far too
    half = orbit.turn(cam, lo, hi, 180.0, args)
    back = orbit.turn(half, lo, hi, 180.0, args)
    np.testing.assert_allclose(back.eye, cam.eye, atol=1e-9)
    np.testing.assert_allclose(orbit.turn(cam, lo, hi, 120.0 + 240.0 - 1e-9, args).eye, cam.eye, atol=1e-6)
    np.testing.assert_allclose(half.eye, (-2, 5, 2), atol=1e-9)  # about the vertical through (0.5, 0.5)
    np.testing.assert_allclose(half.forward[2], cam.forward[2], atol=1e-9)


def _recorded_turns(monkeypatch):
    """orbit.turn wrapped: the list of (camera, lo, hi) of every frame turned."""
    real, seen = orbit.turn, []

    def turn(camera, lo, hi, degrees, args):
        cam = real(camera, lo, hi, degrees, args)
        seen.append((cam, lo, hi))
        return cam

    monkeypatch.setattr(orbit, "turn", turn)
    return seen


def _in_frame(cam, lo, hi, w, h):
    from clvis.camera import box_corners

    return bool(cam.project(box_corners(lo, hi), w, h).visible.all())


@pytest.mark.parametrize("view", [[], ["--view", "hemisphere:3"], ["--view", "top"]])
def test_every_orbit_frame_holds_the_whole_box(tmp_path, capsys, monkeypatch, view):
    """The turntable is fitted over the whole turn, not its first view only:
    every frame's camera has the 8 corners of the data's box in the picture
    (a wide picture of a long strip cut it off at the sides it turned to)."""
    pytest.importorskip("laspy")
    seen = _recorded_turns(monkeypatch)
    rc, out, err = _main(
        capsys, "render", SIMPLE, *view, "--size", "160x48", "--orbit", 8, "--quiet", "--out", tmp_path / "r"
    )
    assert rc == 0, err
    assert len(seen) == 8 and all(_in_frame(cam, lo, hi, 160, 48) for cam, lo, hi in seen)

    seen.clear()
    gauss = ("gauss", "--lod", "low", *view, "--size", "96x32")
    rc, out, err = _main(capsys, *gauss, "--orbit", 6, "--quiet", "--out", tmp_path / "g")
    assert rc == 0, err
    assert seen and all(_in_frame(cam, lo, hi, 96, 32) for cam, lo, hi in seen)

    boxes = []
    real_iso = orbit.iso_orbit

    def iso_orbit(*a, **k):
        boxes.append(a[6])  # the isosurface's box, which each frame must hold
        return real_iso(*a, **k)

    monkeypatch.setattr(orbit, "iso_orbit", iso_orbit)
    seen.clear()
    rc, out, err = _main(
        capsys, "iso", *view, "--size", "128x40", "--orbit", 6, "--quiet", "--out", tmp_path / "i"
    )
    assert rc == 0, err
    (lo, hi), frames = boxes[0], [cam for cam, _, _ in seen]
    assert len(frames) == 6 and all(_in_frame(cam, lo, hi, 128, 40) for cam in frames)


def test_iso_and_gauss_orbit(tmp_path, capsys):
    # with --eye the camera stays where it was put: the first frame is iso.png's
    eye = ("--eye", "3,-4,2")
    rc, out, err = _main(
        capsys, "iso", *eye, "--size", "64x48", "--orbit", 3, "--quiet", "--out", tmp_path / "i"
    )
    assert rc == 0, err
    assert _frames(tmp_path / "i") == ["orbit-0000.png", "orbit-0001.png", "orbit-0002.png"]
    a, b = _png(tmp_path / "i" / "orbit-0000.png"), _png(tmp_path / "i" / "iso.png")
    np.testing.assert_array_equal(a, b)  # the first frame is iso.png's view, band and all
    gauss = ("gauss", "--lod", "low", *eye, "--size", "48x48")
    rc, out, err = _main(capsys, *gauss, "--orbit", 2, "--quiet", "--out", tmp_path / "g")
    assert rc == 0, err
    assert _frames(tmp_path / "g") == ["orbit-0000.png", "orbit-0001.png"]
    np.testing.assert_array_equal(_png(tmp_path / "g" / "orbit-0000.png"), _png(tmp_path / "g" / "gauss.png"))
    rc, out, err = _main(capsys, *gauss, "--orbit", 2, "--out", tmp_path / "g2")
    assert rc == 0 and "PNGs to " in out and " and 2 orbit frames" in out, out  # as render says it


@pytest.mark.parametrize(
    "args, message",
    [
        (["--movie", "x.mp4"], "--movie encodes the --orbit frames; add --orbit N"),
        (["--orbit", "3", "--movie", "x.avi"], "--movie x.avi: expected a video file name ending .mp4"),
        (["--orbit", "1"], "argument --orbit: expected an integer in 2..3,600"),
        (["--fps", "10"], "--fps is the --movie's frame rate"),
    ],
)
def test_orbit_errors(tmp_path, capsys, args, message):
    for command in ("render", "iso", "gauss"):
        rc, out, err = _main(capsys, command, *args, "--size", "32x32", "--out", tmp_path / command)
        assert rc == 2 and message in err, (command, err)
        assert not (tmp_path / command).exists()  # refused before any work


def test_movie_without_the_encoder_names_the_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # import fails: not installed
    rc, out, err = _main(
        capsys, "iso", "--orbit", 2, "--movie", tmp_path / "a.mp4", "--size", "32x32", "--out", tmp_path / "o"
    )
    assert rc == 2 and out == ""
    assert "--movie needs the movie extra" in err and "pip install '.[movie]'" in err
    assert err.count("\n") == 1 and not (tmp_path / "o").exists()


def test_ctrl_c_during_the_orbit_leaves_complete_frames(tmp_path, capsys, monkeypatch):
    real = orbit.turn
    calls = []

    def turn(*a, **k):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(orbit, "turn", turn)
    rc, out, err = _main(capsys, "iso", "--size", "48x32", "--orbit", 5, "--quiet", "--out", tmp_path)
    assert rc == 130 and err.strip().endswith("clvis iso: interrupted")
    assert f"interrupted after 2 of 5 orbit frames (orbit-0000.png .. orbit-0001.png) in {tmp_path}" in err
    assert _frames(tmp_path) == ["orbit-0000.png", "orbit-0001.png"]
    for name in _frames(tmp_path):
        assert _png(tmp_path / name).shape[1] == 48  # complete PNGs
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_shorter_turntable_removes_the_frames_an_earlier_one_left(tmp_path, capsys):
    """orbit-%04d.png in a folder holding a longer turntable's frames: the
    ones past this run's are removed once the run is done (a movie of the
    pattern would mix them), and that is said; other files are left alone."""
    args = ("iso", "--size", "48x32", "--quiet", "--out", tmp_path)
    rc, out, err = _main(capsys, *args, "--orbit", 5)
    assert rc == 0, err
    assert "earlier" not in err
    others = ["orbit-00007.png", "orbit-0009.jpg", "my-orbit-0008.png", "orbit-0006.png.bak"]
    for name in others:
        (tmp_path / name).write_bytes(b"mine")
    (tmp_path / "orbit-0007.png").mkdir()  # not a frame clvis wrote
    rc, out, err = _main(capsys, *args, "--orbit", 2)
    assert rc == 0, err
    assert f"clvis: removed 3 stale orbit frames from an earlier run in {tmp_path}" in err
    assert _frames(tmp_path) == ["orbit-0000.png", "orbit-00007.png", "orbit-0001.png", "orbit-0007.png"]
    assert all((tmp_path / name).read_bytes() == b"mine" for name in others)
    assert (tmp_path / "orbit-0007.png").is_dir()
    rc, out, err = _main(capsys, *args, "--orbit", 3)
    assert rc == 0 and "earlier" not in err


def test_frames_that_cannot_be_removed_are_named(tmp_path, capsys, monkeypatch):
    args = ("iso", "--size", "48x32", "--quiet", "--out", tmp_path)
    rc, out, err = _main(capsys, *args, "--orbit", 4)
    assert rc == 0, err
    real = Path.unlink

    def unlink(self, *a, **k):
        if self.name == "orbit-0003.png":
            raise PermissionError(13, "Permission denied")
        return real(self, *a, **k)

    monkeypatch.setattr(Path, "unlink", unlink)
    rc, out, err = _main(capsys, *args, "--orbit", 2)
    assert rc == 0, err
    assert "removed 1 stale orbit frame from an earlier run" in err
    assert (
        "warning: 1 orbit frame of an earlier, longer turntable could not be removed and stay in "
        f"{tmp_path} (orbit-0003.png .. orbit-0003.png)" in err
    )


def test_an_interrupted_turntable_removes_nothing(tmp_path, capsys, monkeypatch):
    args = ("iso", "--size", "48x32", "--quiet", "--out", tmp_path)
    rc, out, err = _main(capsys, *args, "--orbit", 4)
    assert rc == 0, err
    real = orbit.turn

    def turn(camera, lo, hi, degrees, a):
        if degrees:
            raise KeyboardInterrupt
        return real(camera, lo, hi, degrees, a)

    monkeypatch.setattr(orbit, "turn", turn)
    rc, out, err = _main(capsys, *args, "--orbit", 2)
    assert rc == 130
    assert f"2 orbit frames of an earlier, longer turntable stay in {tmp_path}" in err
    assert _frames(tmp_path) == [f"orbit-{k:04d}.png" for k in range(4)]


def test_movie(tmp_path, capsys):
    iio = pytest.importorskip("imageio.v2", reason="the movie extra (imageio) is in the test extra")
    pytest.importorskip("imageio_ffmpeg", reason="the movie extra (imageio-ffmpeg) is in the test extra")
    movie = tmp_path / "turn" / "iso.mp4"
    rc, out, err = _main(
        capsys,
        "iso",
        "--size",
        "63x47",
        "--orbit",
        6,
        "--movie",
        movie,
        "--fps",
        12,
        "--quiet",
        "--out",
        tmp_path / "o",
    )
    assert rc == 0, err
    assert f"movie     {movie}" in out
    with iio.get_reader(str(movie)) as r:
        frames = [f for f in r]
        assert r.get_meta_data()["fps"] == 12
    h, w = _png(tmp_path / "o" / "orbit-0000.png").shape[:2]  # 63 wide, 47 + the label band high
    assert w == 63 and len(frames) == 6
    assert frames[0].shape == (h + h % 2, 64, 3)  # odd sides padded to even
    assert not [p for p in movie.parent.iterdir() if p.name.startswith(".")]


def test_orbit_progress_as_other_stages(tmp_path, capsys):
    """--progress shows the orbit's frames as its other stages (on stderr, the
    last redraw naming every frame done)."""
    pytest.importorskip("laspy")
    rc, out, err = _main(
        capsys, "render", SIMPLE, "--size", "48x32", "--orbit", 3, "--progress", "--out", tmp_path
    )
    assert rc == 0, err
    assert "clvis render: orbit: frame 3/3" in err.replace("\r", "\n")
    assert "orbit     3 frames" in out and "frame 3/3" not in out  # the report on stdout, progress not
