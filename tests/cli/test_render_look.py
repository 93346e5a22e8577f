"""clvis render on files nobody here wrote: what it shows by default (the
file's RGB, the bulk of the cloud framed), and the options that change the
look (--point-size auto, --edl, the class palette, --range, --background,
--eye/--target in the file's coordinates). Through main(), with exit
status and stderr."""

import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from clvis import cli
from clvis.io import PointCloud, read_points, save_npz

DATA = Path(__file__).parents[1] / "data"
SIMPLE = DATA / "laspy_simple.laz"  # 1,065 points, RGB, classes 1 and 2, UTM coordinates
APPEND_BUG = DATA / "laspy_append_bug.laz"  # 37,807 points; 2 records at (0, 0, 0)
SIMPLE14 = DATA / "laspy_simple1_4_every8th.las"  # simple1_4.las's every 8th record: RGB, intensity all 0
SMALL = ["--size", "160x90", "--quiet", "--no-labels"]  # the images alone: exactly --size
MID = ["--size", "480x270", "--quiet", "--no-labels"]

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def _render(capsys, *args):
    try:
        rc = cli.main(["render", *map(str, args)])
    except SystemExit as e:
        rc = e.code
    out, err = capsys.readouterr()
    return rc, out, err


def _png(path):
    with Image.open(path) as im:
        return np.asarray(im)


def _covered(path):
    return int((_png(path)[..., 3] > 0).sum())


@pytest.fixture(autouse=True)
def _laspy():
    pytest.importorskip("laspy")


def test_rgb_first(tmp_path, capsys):
    rc, out, err = _render(capsys, SIMPLE, "--out", tmp_path, *SMALL)
    assert rc == 0, err
    assert "1,065 points, its colors" in out
    assert not (tmp_path / "attribute-intensity.png").exists()
    a = _png(tmp_path / "colors.png")
    cloud = read_points(SIMPLE)
    drawn = a[(a[..., :3] != (24, 24, 28)).any(axis=2)][:, :3]
    # the pixels hold the file's own colours
    file_colors = {tuple(c) for c in cloud.colors[:, :3]}
    assert len(drawn) > 50 and all(tuple(c) in file_colors for c in drawn)


def test_rgb_first_when_intensity_is_all_zero(tmp_path, capsys):
    """laspy's simple1_4.las (LAS 1.4, point format 7; every 8th record kept):
    its intensity is 0 everywhere, so colouring by it drew one flat colour
    under a "0 ... 0" bar; its RGB is shown now, as the tools users know do."""
    cloud = read_points(SIMPLE14)
    assert np.ptp(cloud.attributes["intensity"]) == 0 and np.ptp(cloud.colors[:, :3]) > 0
    rc, out, err = _render(capsys, SIMPLE14, "--transparent", "--out", tmp_path, *SMALL)
    assert rc == 0, err
    assert "2,825 points, its colors" in out
    assert {p.name for p in tmp_path.iterdir()} == {"colors.png", "depth.png", "soft-z.png", "overview.png"}
    a = _png(tmp_path / "colors.png")
    drawn = a[a[..., 3] > 0][:, :3]
    assert len(drawn) > 500 and len({tuple(c) for c in drawn}) > 50  # many colours, not one
    assert {tuple(c) for c in drawn} <= {tuple(c) for c in cloud.colors[:, :3]}


def test_ply_with_rgb_and_a_property_shows_its_rgb(tmp_path, capsys):
    """A PLY as photogrammetry and stereo tools write it (x y z, red green blue
    uchar, and one more property such as confidence): its colours, not the
    property, by default; the property on request."""
    from plyfile import PlyData, PlyElement

    rng = np.random.default_rng(4)
    n = 3000
    v = np.zeros(
        n, [(c, "f4") for c in "xyz"] + [(c, "u1") for c in ("red", "green", "blue")] + [("confidence", "f4")]
    )
    for c in "xyz":
        v[c] = rng.random(n)
    for c in ("red", "green", "blue"):
        v[c] = rng.integers(0, 256, n)
    v["confidence"] = rng.random(n)
    PlyData([PlyElement.describe(v, "vertex")]).write(str(tmp_path / "stereo.ply"))
    rc, out, err = _render(capsys, tmp_path / "stereo.ply", "--out", tmp_path / "a", *SMALL)
    assert rc == 0, err
    assert "3,000 points, its colors" in out and not (tmp_path / "a" / "attribute-confidence.png").exists()
    rc, out, err = _render(
        capsys, tmp_path / "stereo.ply", "--attribute", "confidence", "--out", tmp_path / "b", *SMALL
    )
    assert rc == 0 and "colored by confidence" in out, err


def test_attribute_z_bar_in_the_files_coordinates(tmp_path, capsys, monkeypatch):
    """--attribute z: the colour bar reads the file's heights (simple.laz:
    406.59..586.38 m), not heights above the internal origin (0..179.79)."""
    from clvis import images

    bars = []
    real = images.colorbar

    def spy(lut, vmin, vmax, width, **kw):
        bars.append((kw.get("title", ""), vmin, vmax))
        return real(lut, vmin, vmax, width, **kw)

    monkeypatch.setattr(images, "colorbar", spy)
    rc, out, err = _render(
        capsys, SIMPLE, "--attribute", "z", "--size", "160x90", "--quiet", "--out", tmp_path
    )
    assert rc == 0, err
    # the bounds too, at the precision the file's values have (not 586.3799933)
    assert "x 406.59..586.38 (the file's coordinates)" in out, out
    z = [(lo, hi) for title, lo, hi in bars if title == "z"]
    assert z and all(abs(lo - 406.59) < 0.01 and abs(hi - 586.38) < 0.01 for lo, hi in z), bars


def test_constant_colors_and_attributes_passed_over(tmp_path, capsys):
    """A cloud whose colours are all one colour and whose intensity is all 0
    (laspy's simple1_4.las) is coloured by the first attribute that varies."""
    rng = np.random.default_rng(0)
    p = rng.random((500, 3)).astype(np.float32)
    cloud = PointCloud(
        p,
        colors=np.zeros((500, 3), np.uint8),
        attributes={"intensity": np.zeros(500, np.float32), "gps_time": rng.random(500)},
    )
    save_npz(tmp_path / "c.npz", cloud)
    rc, out, err = _render(capsys, tmp_path / "c.npz", "--out", tmp_path / "o", *SMALL)
    assert rc == 0, err
    assert "colored by gps_time" in out


def test_robust_framing(tmp_path, capsys):
    """Two records at (0, 0, 0) in a UTM-coordinate file: before, the default
    view held 2 covered pixels; the bulk is framed now, with a note."""
    rc, out, err = _render(capsys, APPEND_BUG, "--transparent", "--out", tmp_path, *SMALL)
    assert rc == 0, err
    assert "note: 2 of 37,807 points lie far outside the rest" in err
    covered = int(out.split("covered")[1].split("of")[0].replace(",", ""))
    assert covered > 100  # was 2 of 14,400 before the bulk was framed
    assert _covered(tmp_path / "colors.png") == covered


def test_sparse_cloud_notes_how_little_it_covers(tmp_path, capsys):
    """laspy's simple.laz (1,065 points) at 1 px on a 1600x900 image covers
    under 1/1000 of it: a note says so and names --point-size auto, which
    draws it large enough (and then says nothing)."""
    big = ["--size", "1600x900", "--quiet", "--no-labels"]
    rc, out, err = _render(capsys, SIMPLE, "--out", tmp_path / "one", *big)
    assert rc == 0, err
    assert re.search(
        r"note: the points cover [\d,]+ of 1,440,000 pixels \(0\.0\d* %\); --point-size auto", err
    ), err
    rc, out, err = _render(capsys, SIMPLE, "--point-size", "auto", "--out", tmp_path / "auto", *big)
    assert rc == 0 and "note" not in err, err


def test_point_size_auto_and_edl(tmp_path, capsys):
    rc, out, err = _render(capsys, SIMPLE, "--transparent", "--out", tmp_path / "one", *MID)
    assert rc == 0, err
    rc, out, err = _render(
        capsys, SIMPLE, "--point-size", "auto", "--transparent", "--out", tmp_path / "auto", *MID
    )
    assert rc == 0, err
    assert "(auto:" in out and "pixels apart" in out
    n = int(re.search(r"points (\d+)x\d+ pixels \(auto", out).group(1))
    assert 2 <= n <= 16
    assert _covered(tmp_path / "auto" / "colors.png") > 3 * _covered(tmp_path / "one" / "colors.png")
    rc, out, err = _render(
        capsys, SIMPLE, "--point-size", "auto", "--edl", "--transparent", "--out", tmp_path / "edl", *MID
    )
    assert rc == 0, err
    assert "eye-dome lighting, strength 1" in out
    plain, shaded = _png(tmp_path / "auto" / "colors.png"), _png(tmp_path / "edl" / "colors.png")
    np.testing.assert_array_equal(plain[..., 3], shaded[..., 3])  # the same pixels
    assert (shaded[..., :3] <= plain[..., :3]).all()  # only ever darker
    assert (shaded[..., :3] < plain[..., :3]).any(axis=2).sum() > 20
    rc, out, err = _render(capsys, SIMPLE, "--edl", "3", "--out", tmp_path / "edl3", *MID)
    assert rc == 0 and "strength 3" in out


def test_class_palette_and_legend(tmp_path, capsys):
    from clvis.colormap import class_palette

    rc, out, err = _render(
        capsys, SIMPLE, "--attribute", "classification", "--transparent", "--out", tmp_path, *SMALL
    )
    assert rc == 0, err
    assert "colored by classification (ASPRS classes: 2)" in out
    a = _png(tmp_path / "attribute-classification.png")
    drawn = {tuple(c) for c in a[a[..., 3] > 0][:, :3]}
    table = class_palette()
    assert drawn == {tuple(table[1, :3]), tuple(table[2, :3])}  # unclassified, ground
    # the overview carries the legend: the overview is taller than panel + label + nothing
    rc, out, err = _render(
        capsys,
        SIMPLE,
        "--attribute",
        "classification",
        "--colormap",
        "viridis",
        "--out",
        tmp_path / "v",
        *SMALL,
    )
    assert rc == 0 and "classification (viridis)" in out  # a colormap asked for: continuous


def test_range_and_background(tmp_path, capsys):
    rc, out, err = _render(
        capsys, SIMPLE, "--attribute", "z", "--range", "p5,p95", "--out", tmp_path / "p", *SMALL
    )
    assert rc == 0, err
    lo, hi = (float(v) for v in out.split("range     z ")[1].split()[0].split(".."))
    z = read_points(SIMPLE)
    zw = z.positions[:, 2].astype(np.float64) + z.origin[2]
    assert abs(lo - np.percentile(zw, 5)) < 0.01 and abs(hi - np.percentile(zw, 95)) < 0.01
    rc, out, err = _render(
        capsys,
        SIMPLE,
        "--attribute",
        "z",
        "--range",
        "410,420",
        "--background",
        "white",
        "--out",
        tmp_path / "v",
        *SMALL,
    )
    assert rc == 0, err
    assert "range     z 410..420" in out
    a = _png(tmp_path / "v" / "attribute-z.png")
    assert (a[..., :3] == 255).all(axis=2).sum() > 0.5 * a.shape[0] * a.shape[1]  # a white background
    viridis_end = tuple(np.asarray(__import__("clvis").colormap.lut("viridis")[-1, :3]))
    # most points lie above 420 m: they take the top colour
    assert ((a[..., :3] == viridis_end).all(axis=2)).sum() > 20


def test_eye_in_file_coordinates(tmp_path, capsys):
    """--eye and --target are the file's coordinates: an eye above the scan
    looking at its centre sees it."""
    cloud = read_points(SIMPLE)
    lo, hi = cloud.bounds()
    c = 0.5 * (lo + hi) + cloud.origin
    eye = f"{c[0]:.2f},{c[1] - 400:.2f},{c[2] + 400:.2f}"
    target = f"{c[0]:.2f},{c[1]:.2f},{c[2]:.2f}"
    rc, out, err = _render(
        capsys, SIMPLE, "--eye", eye, "--target", target, "--transparent", "--out", tmp_path, *SMALL
    )
    assert rc == 0, err
    assert _covered(tmp_path / "colors.png") > 100


@pytest.mark.parametrize(
    "args, message",
    [
        (["--range", "5"], "argument --range: expected MIN,MAX"),
        (["--range", "3,1"], "argument --range: expected MIN,MAX"),
        (["--range", "p2,p101"], "argument --range: expected MIN,MAX"),
        (["--background", "mauve-ish"], "argument --background: expected a colour"),
        (["--background", "300,0,0"], "argument --background: expected a colour"),
        (["--edl", "0"], "argument --edl: expected an eye-dome lighting strength"),
        (["--edl", "nan"], "argument --edl: expected an eye-dome lighting strength"),
        (["--point-size", "big"], "argument --point-size: expected auto or a positive integer"),
        (["--range", "0,1"], "--range scales an attribute; the cloud is shown in its own colours"),
        (["--colormap", "magma"], "--colormap colours an attribute; the cloud is shown in its own colours"),
        (["--transparent", "--background", "black"], "--transparent and --background"),
        (["--attribute", "classification", "--range", "0,1"], "--range: classification is shown by class"),
    ],
)
def test_errors(tmp_path, capsys, args, message):
    rc, out, err = _render(capsys, SIMPLE, *args, "--out", tmp_path, *SMALL)
    assert rc == 2
    assert message in err and err.count("\n") == 1


def test_text_and_pcd_files(tmp_path, capsys):
    """A text export of laspy's sample (x y z r g b, UTM coordinates) renders
    in its RGB, framed in the file's coordinates; a PCD file too."""
    cloud = read_points(SIMPLE)
    xyz = cloud.positions.astype(np.float64) + cloud.origin
    rows = np.concatenate([xyz, cloud.colors[:, :3]], axis=1)
    np.savetxt(tmp_path / "scan.xyz", rows, fmt=["%.2f", "%.2f", "%.2f", "%d", "%d", "%d"])
    rc, out, err = _render(capsys, tmp_path / "scan.xyz", "--out", tmp_path / "x", *SMALL)
    assert rc == 0, err
    assert "1,065 points, its colors" in out and "bounds    635619.85.." in out
    rec = np.zeros(len(xyz), [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
    for k, c in enumerate("xyz"):
        rec[c] = cloud.positions[:, k]
    col = cloud.colors.astype(np.uint32)
    rec["rgb"] = (col[:, 0] << 16) | (col[:, 1] << 8) | col[:, 2]
    head = (
        "VERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\n"
        f"WIDTH {len(rec)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(rec)}\nDATA binary\n"
    )
    (tmp_path / "scan.pcd").write_bytes(head.encode() + rec.tobytes())
    rc, out, err = _render(capsys, tmp_path / "scan.pcd", "--out", tmp_path / "p", *SMALL)
    assert rc == 0, err
    assert "its colors" in out
    rc, out, err = _render(capsys, tmp_path / "nothing.pcd", "--out", tmp_path / "n", *SMALL)
    assert rc == 2 and "no such file" in err


@pytest.mark.parametrize("command", [["render", "--points", "100"], ["iso"], ["gauss"]])
def test_out_naming_a_file(tmp_path, capsys, command):
    """--out naming a file (or a path below one) stops before any work."""
    f = tmp_path / "afile"
    f.write_text("")
    for out in (f, f / "sub"):
        try:
            rc = cli.main([*command, "--out", str(out), "--quiet"])
        except SystemExit as e:
            rc = e.code
        _, err = capsys.readouterr()
        assert rc == 2 and "not a folder" in err and err.count("\n") == 1


def test_infill_without_completion(tmp_path, capsys):
    """--infill with every ray finishing would do nothing: an error first."""
    try:
        rc = cli.main(["iso", "--infill", "--size", "32x32", "--quiet", "--out", str(tmp_path)])
    except SystemExit as e:
        rc = e.code
    _, err = capsys.readouterr()
    assert rc == 2 and "--infill fills the rays still running" in err
    assert not any(tmp_path.iterdir())  # before any work


@pytest.mark.parametrize("command", [["render", "--points", "100"], ["iso"], ["gauss"]])
def test_o_naming_an_image(tmp_path, capsys, command):
    """-o is --out; -o picture.png (a habit from single-image tools) stops
    before any work, suggests a folder and makes nothing."""
    out = tmp_path / "sub" / "picture.png"
    try:
        rc = cli.main([*command, "-o", str(out), "--quiet"])
    except SystemExit as e:
        rc = e.code
    _, err = capsys.readouterr()
    assert rc == 2 and "names an image" in err and f"-o {tmp_path / 'sub' / 'picture'}" in err
    assert not (tmp_path / "sub").exists()


@pytest.mark.parametrize(
    "command, last",
    [(["render", "--points", "100"], "overview.png"), (["iso"], "iso.png"), (["gauss"], "gauss.png")],
)
def test_folder_in_the_way_writes_nothing(tmp_path, capsys, command, last):
    """A folder named like a command's last image is refused before any PNG
    is written: the outputs appear all or none."""
    (tmp_path / last).mkdir()
    rc = cli.main([*command, "--size", "32x24", "--out", str(tmp_path), "--quiet"])
    _, err = capsys.readouterr()
    assert rc == 2 and f"{last}: not a file" in err and err.count("\n") == 1
    assert [p.name for p in tmp_path.iterdir()] == [last]


def test_colour_names_are_the_css_ones_beside_clvis_own():
    """--background / --surface-color take the CSS names matplotlib and
    PyVista take (red, tomato), #RGB beside #RRGGBB and R,G,B; clvis's own
    darkgrey stays the UI's grey; anything else is refused."""
    import argparse

    from clvis.cli.raster import _colour

    assert _colour("red") == (255, 0, 0)
    assert _colour("Tomato") == (255, 99, 71)
    assert _colour("#FFF") == (255, 255, 255) and _colour("#e04020") == (224, 64, 32)
    assert _colour("10, 20, 30") == (10, 20, 30)
    assert _colour("darkgrey") == (24, 24, 28)  # the UI's, not CSS's (169, 169, 169)
    for bad in ("mauve-ish", "#ff", "#12345", "300,0,0", "#ffffff80"):
        with pytest.raises(argparse.ArgumentTypeError, match="expected a colour"):
            _colour(bad)


def test_attribute_radius_and_speed_colour_by_the_clouds_planes(tmp_path, capsys):
    """A file's "radius" and "velocity" arrays become the cloud's planes, not
    attributes: --attribute radius and --attribute speed (|velocity|)
    colour by them in render and gauss; a missing name lists them."""
    from clvis import cli
    from clvis.io import PointCloud, save_npz

    rng = np.random.default_rng(4)
    n = 400
    path = tmp_path / "planes.npz"
    save_npz(
        path, PointCloud(rng.random((n, 3)), radius=rng.random(n) * 0.05, velocity=rng.normal(size=(n, 3)))
    )
    for name in ("radius", "speed"):
        rc, out, err = _render(capsys, str(path), "--attribute", name, "--out", tmp_path / name, *SMALL)
        assert rc == 0 and f"colored by {name}" in out, (out, err)
        assert (tmp_path / name / f"attribute-{name}.png").is_file()
        assert (
            cli.main(
                ["gauss", str(path), "--attribute", name, "--size", "64x48", "--out", str(tmp_path / "g")]
            )
            == 0
        )
        assert f"colour    {name} through" in capsys.readouterr().out
    rc, out, err = _render(capsys, str(path), "--attribute", "velocity", "--out", tmp_path / "v", *SMALL)
    assert rc == 2 and "no attribute 'velocity'" in err and "radius, speed" in err
    assert cli.main(["gauss", str(path), "--attribute", "nope", "--out", str(tmp_path / "g")]) == 2
    assert "--attribute: no attribute 'nope' in" in capsys.readouterr().err


def test_post_panel_over_black_is_said_with_background(tmp_path, capsys):
    """The LiDAR network predicts colour alone: with --background its panel
    stays over black, and clvis render says so rather than ignore it."""
    rc, out, err = _render(
        capsys, SIMPLE, "--post", "lidar", "--background", "white", "--out", tmp_path, *SMALL
    )
    assert rc == 0, err
    assert "note: post-lidar.png is the lidar network's opaque frame over black" in err
    assert "--background applies to the other pictures" in err


def test_a_file_given_twice_is_refused(tmp_path, capsys):
    """render A A would draw every point twice: refused, naming it."""
    rc, out, err = _render(
        capsys, SIMPLE, str(Path(SIMPLE).parent / ".." / "data" / Path(SIMPLE).name), *SMALL
    )
    assert rc == 2 and "given twice" in err, err
