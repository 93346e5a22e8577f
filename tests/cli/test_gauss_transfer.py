"""clvis gauss's transfer function on volumes through cli.main: --range and
--opacity, and the default for a volume FILE (a scan) that keeps its dense
noisy background clear instead of an opaque cube: a synthetic scan (a bright
ball in noise, where the claim is exact) and nibabel's anatomical.nii (a real
MRI; skipped when nibabel is absent)."""

import os

import numpy as np
import pytest
from PIL import Image

from clvis import cli

OLD_DEFAULT = ["--opacity", "0:0.05,0.35:0.35,1:1"]  # the opacity used before, over min..max


def _alpha(path):
    with Image.open(path) as im:
        return np.asarray(im)[..., 3].astype(float) / 255


def _run(capsys, *args):
    # --no-labels: the panels alone at --size (the tests read their pixels)
    rc = cli.main(["gauss", *args, "--no-labels"])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    """A 40^3 scan: noise 50..150 everywhere (every voxel active at the
    default threshold > 0), a ball of radius 9 at 1000 in the middle."""
    rng = np.random.default_rng(3)
    z, y, x = np.mgrid[:40, :40, :40]
    v = rng.uniform(50, 150, (40, 40, 40))
    v[(x - 19.5) ** 2 + (y - 19.5) ** 2 + (z - 19.5) ** 2 < 81] = 1000 + rng.uniform(-50, 50)
    path = tmp_path_factory.mktemp("scan") / "scan.npy"
    np.save(path, v.astype(np.float32))
    return str(path)


def test_scan_background_stays_clear(tmp_path, capsys, scan):
    """Default: the range starts at Otsu's level, so the noise is transparent
    and only the ball shows; the old default (min..max, a floor of 0.05)
    made the noisy box an opaque cube."""
    args = [scan, "--lod", "high", "--size", "64x64", "--transparent"]
    rc, out, err = _run(capsys, *args, "--out", str(tmp_path / "new"))
    assert rc == 0, err
    assert "transfer  range" in out and "Otsu's background level" in out
    rc, out, err = _run(capsys, *args, "--range=50,1050", *OLD_DEFAULT, "--out", str(tmp_path / "old"))
    assert rc == 0, err
    assert "range 50..1050" in out
    new, old = _alpha(tmp_path / "new" / "high.png"), _alpha(tmp_path / "old" / "high.png")
    box = old > 0.05  # the box's silhouette
    ball = new > 0.5
    assert box.mean() > 0.3 and ball.any()
    assert old[box].mean() > 0.8  # the cube
    assert ball.sum() < 0.5 * box.sum()  # the ball, not the cube
    assert new[box & ~ball].mean() < 0.1  # the background clear around it


def test_opacity_zero_draws_nothing_and_range_shows(tmp_path, capsys, scan):
    rc, out, err = _run(
        capsys,
        scan,
        "--lod",
        "low",
        "--size",
        "48x48",
        "--transparent",
        "--opacity",
        "0:0,1:0",
        "--out",
        str(tmp_path),
    )
    assert rc == 0, err
    assert (_alpha(tmp_path / "low.png") == 0).all()
    rc, out, err = _run(
        capsys, scan, "--lod", "low", "--size", "48x48", "--range", "p2,p98", "--out", str(tmp_path)
    )
    assert rc == 0, err
    line = next(ln for ln in out.splitlines() if "transfer" in ln)
    assert "range p2..p98 of the samples" in line
    lo, hi = (float(v) for v in line.rsplit(": ", 1)[1].split(".."))
    assert 50 < lo < 60 and 150 < hi <= 1050, line


def test_embedded_default_says_it_is_drawn_as_a_fog(tmp_path, capsys):
    rc, out, err = _run(capsys, "--lod", "low", "--size", "32x32", "--out", str(tmp_path))
    assert rc == 0, err
    line = next(ln for ln in out.splitlines() if "transfer" in ln)
    assert "the embedded explosion drawn as a fog" in line


def test_anatomical_mri(tmp_path, capsys):
    """nibabel's anatomical.nii: the default range starts at Otsu's level and
    ends at the 99.5th percentile (its brightest voxel, 30393, is 2.3 times
    that), and the picture shows more contrast than min..max with the old
    opacity, whose colours all sat at the bottom of the bar."""
    nibabel = pytest.importorskip("nibabel")
    f = os.path.join(os.path.dirname(nibabel.__file__), "tests", "data", "anatomical.nii")
    args = [f, "--lod", "high", "--size", "96x96"]
    rc, out, err = _run(capsys, *args, "--out", str(tmp_path / "new"))
    assert rc == 0, err
    line = next(ln for ln in out.splitlines() if "transfer" in ln)
    lo, hi = float(line.split("range ")[1].split(" ")[0]), float(line.split("..")[1].split(" ")[0])
    assert 7000 < lo < 8000 and 12000 < hi < 14000, line
    rc, out, err = _run(capsys, *args, "--range=5,30393", *OLD_DEFAULT, "--out", str(tmp_path / "old"))
    assert rc == 0, err

    def contrast(path):
        with Image.open(path) as im:
            a = np.asarray(im)[..., :3].astype(float)
        covered = np.abs(a - [24, 24, 28]).sum(axis=2) > 30
        return a[covered].sum(axis=1).std()

    # 1.39x from the front, where a scan is now seen from (over 1.5x from behind, as it was)
    assert contrast(tmp_path / "new" / "high.png") > 1.3 * contrast(tmp_path / "old" / "high.png")


@pytest.mark.parametrize(
    "args,message",
    [
        (["--opacity", "0:0,1"], "--opacity"),
        (["--opacity", "1:0,0:1"], "ascend"),
        (["--opacity", "0:2"], "--opacity"),
        (["--range", "3"], "--range"),
        (["--range", "p5,p200"], "--range"),
    ],
)
def test_errors(tmp_path, capsys, args, message):
    rc, _, err = _run(capsys, *args, "--size", "16x16", "--out", str(tmp_path))
    assert rc == 2 and message in err, err


def test_range_on_rgb_points_is_an_error(tmp_path, capsys):
    path = os.path.join(os.path.dirname(__file__), "..", "data", "laspy_simple.laz")
    rc, _, err = _run(capsys, path, "--range", "0,1", "--size", "16x16", "--out", str(tmp_path))
    assert rc == 2 and "own colours" in err and len(err.strip().splitlines()) == 1
    rc, _, err = _run(capsys, path, "--colormap", "magma", "--size", "16x16", "--out", str(tmp_path))
    assert rc == 2 and err.startswith("clvis gauss: error: --colormap: ") and "own colours" in err, err
    assert not os.listdir(tmp_path)  # nothing drawn: it would have done nothing
    rc, _, err = _run(
        capsys, path, "--attribute", "z", "--colormap", "magma", "--size", "16x16", "--out", str(tmp_path)
    )
    assert rc == 0, err


def _fog_ball(tmp_path):
    """A fog ball: density 1 - r / 30 over 64^3 (most of it low values)."""
    z, y, x = np.mgrid[:64, :64, :64]
    r = np.sqrt((x - 31.5) ** 2 + (y - 31.5) ** 2 + (z - 31.5) ** 2)
    path = tmp_path / "fog.npy"
    np.save(path, np.clip(1 - r / 30, 0, 1).astype(np.float32))
    return str(path)


def _luminance(path):
    """The mean luminance (0..1) of a --transparent picture's drawn pixels."""
    with Image.open(path) as im:
        a = np.asarray(im).astype(float) / 255
    drawn = a[..., 3] > 0.5
    return float((a[..., :3][drawn] @ [0.2126, 0.7152, 0.0722]).mean())


def test_a_dark_fog_says_which_options_show_its_inside(tmp_path, capsys):
    """A fog ball under the default transfer function is a dark purple disc
    (its shell of low values hides the bright inside): a note on stderr says
    so and names the options that show it; with them the picture is bright
    and the note is gone. A bright ball in a noisy scan gets no note."""
    fog = _fog_ball(tmp_path)
    args = [fog, "--lod", "high", "--size", "64x64", "--transparent"]
    rc, out, err = _run(capsys, *args, "--out", str(tmp_path / "dark"))
    assert rc == 0, err
    note = [line for line in err.splitlines() if "note: the picture is mostly dark" in line]
    assert len(note) == 1, err
    assert "the lowest quarter of the colours" in note[0] and "--range" in note[0]
    options = note[0].split("shows the inside: ", 1)[1].split(" (or", 1)[0].split()
    assert options[0] == "--density" and options[2] == "--opacity", options
    rc, out, err = _run(capsys, *args, *options, "--out", str(tmp_path / "bright"))
    assert rc == 0, err
    assert "note" not in err
    dark, bright = _luminance(tmp_path / "dark" / "high.png"), _luminance(tmp_path / "bright" / "high.png")
    assert dark < 0.15 and bright > 2 * dark, (dark, bright)
    rc, out, err = _run(capsys, fog, *args[1:], "--opacity", "0:0,1:1", "--out", str(tmp_path / "given"))
    assert rc == 0 and "note" not in err  # the user's own transfer function: nothing said


def test_a_bright_volume_gets_no_dark_note(tmp_path, capsys, scan):
    rc, out, err = _run(capsys, scan, "--lod", "high", "--size", "64x64", "--out", str(tmp_path))
    assert rc == 0 and "note" not in err, err


def test_a_level_set_gets_no_dark_note(tmp_path, capsys):
    """OpenVDB's level-set sphere (values -3..3 about its surface): a bright
    surface, no note."""
    pytest.importorskip("tinyvdb")
    vdb = os.path.join(os.path.dirname(__file__), "..", "data", "openvdb_small.vdb")
    rc, out, err = _run(capsys, vdb, "--grid", "surface", "--size", "64x64", "--out", str(tmp_path))
    assert rc == 0 and "note" not in err, err


def test_data_of_one_value_is_drawn_in_the_top_colour(tmp_path, capsys):
    """A volume of one value (an occupancy or mask grid): its own min..max
    put it at the bottom of the colours, the darkest, almost transparent
    under the volumes' opacity ramp (a near-black box); now at the top,
    said on the transfer line. --range given keeps the user's choice."""
    path = tmp_path / "mask.npy"
    np.save(path, np.full((24, 24, 24), 0.5, np.float32))
    rc, out, err = _run(capsys, str(path), "--lod", "medium", "--size", "48x48", "--out", str(tmp_path / "a"))
    assert rc == 0, err
    assert "every active voxel is 0.5: drawn in the top colour (range -0.5..0.5)" in out
    top = _luminance(tmp_path / "a" / "medium.png")
    assert top > 0.5  # a bright box
    rc, out, err = _run(
        capsys,
        str(path),
        "--lod",
        "medium",
        "--size",
        "48x48",
        "--range",
        "0.5,1.5",
        "--out",
        str(tmp_path / "b"),
    )
    assert rc == 0 and "top colour" not in out, err
    assert _luminance(tmp_path / "b" / "medium.png") < 0.15  # the bottom colour, near-transparent: dark


def _luminance(path) -> float:
    """The mean luminance (0..1) of the middle quarter of a picture."""
    with Image.open(path) as im:
        rgb = np.asarray(im.convert("RGB"), np.float64) / 255
    h, w = rgb.shape[:2]
    return float((rgb[h // 4 : 3 * h // 4, w // 4 : 3 * w // 4] @ [0.2126, 0.7152, 0.0722]).mean())
