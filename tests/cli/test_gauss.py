"""clvis gauss and the demo's gauss part, the explosion dataset, and Gaussians
from point clouds."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import clvis
from clvis import cli, datasets
from clvis.io import PointCloud, save_npz, write_ply


def test_gauss_default(tmp_path, capsys):
    assert cli.main(["gauss", "--size", "64x48", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    for lod in ("low", "medium", "high"):
        assert lod in out
        with Image.open(tmp_path / f"{lod}.png") as im:
            # labelled over its colour bar, as its tile in gauss.png
            assert im.width == 64 and im.height > 48
            assert np.asarray(im).std() > 1  # not blank
    assert (
        cli.main(["gauss", "--size", "64x48", "--lod", "low", "--no-labels", "--out", str(tmp_path / "b")])
        == 0
    )
    with Image.open(tmp_path / "b" / "low.png") as im:
        assert im.size == (64, 48)  # the image alone
    with Image.open(tmp_path / "gauss.png") as im:
        assert im.width >= 3 * 64 and im.height > 48  # labelled, over colour bars


@pytest.mark.parametrize("method", ["tiles", "bvh"])
def test_gauss_method(tmp_path, capsys, method):
    """--method picks the renderer; both give the same picture."""
    args = ["gauss", "--lod", "low", "--size", "40x32", "--model", "max_response", "--method", method]
    assert cli.main([*args, "--out", str(tmp_path / method)]) == 0
    out = capsys.readouterr().out
    assert f"method    {method}" in out and ("keys/G" in out) == (method == "tiles")
    other = "bvh" if method == "tiles" else "tiles"
    assert cli.main([*args[:-1], other, "--out", str(tmp_path / other)]) == 0
    with Image.open(tmp_path / method / "low.png") as a, Image.open(tmp_path / other / "low.png") as b:
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_gauss_splat(tmp_path, capsys):
    assert (
        cli.main(["gauss", "--lod", "low", "--size", "40x32", "--model", "splat", "--out", str(tmp_path)])
        == 0
    )
    assert "splat model" in capsys.readouterr().out
    with Image.open(tmp_path / "low.png") as im:
        assert np.asarray(im).std() > 1
    assert cli.main(["gauss", "--model", "splat", "--method", "bvh", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--model splat (3D Gaussian Splatting's rasterizer) draws on tiles" in err and "method=" not in err


def test_gauss_files(tmp_path, capsys):
    e = datasets.explosion((20, 24, 28))
    np.save(tmp_path / "v.npy", e["volume"])
    assert (
        cli.main(
            [
                "gauss",
                str(tmp_path / "v.npy"),
                "--lod",
                "high",
                "--model",
                "max_response",
                "--size",
                "32x32",
                "--out",
                str(tmp_path / "a"),
            ]
        )
        == 0
    )
    assert (tmp_path / "a" / "high.png").is_file()
    g = clvis.gaussians_from_volume(e["volume"], lod="low", threshold=0.0)
    g.save(tmp_path / "g.npz")
    assert cli.main(["gauss", str(tmp_path / "g.npz"), "--size", "32x32", "--out", str(tmp_path / "b")]) == 0
    assert (tmp_path / "b" / "file.png").is_file()
    rng = np.random.default_rng(0)
    write_ply(tmp_path / "p.ply", PointCloud(rng.normal(size=(500, 3)), velocity=rng.normal(size=(500, 3))))
    assert cli.main(["gauss", str(tmp_path / "p.ply"), "--size", "32x32", "--out", str(tmp_path / "c")]) == 0
    assert (tmp_path / "c" / "points.png").is_file()


@pytest.mark.parametrize(
    "args,message",
    [
        (["nope.vdb"], "no such file"),
        (["--lod", "ultra"], "--lod"),
        (["--method", "raster"], "--method"),
    ],
)
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
    assert "empty.npy: no sample above 0" in capsys.readouterr().err


BACKGROUND = np.array([0.06, 0.06, 0.08]) * 255  # clvis gauss's background, grey level ~16.7


@pytest.mark.parametrize("name", ["laspy_simple.laz", "pyvista_ant.ply"])
def test_gauss_point_cloud_is_seen(tmp_path, capsys, name):
    """A point cloud gives a picture well above the background: mean grey level
    at least 10 above the background's (~16.7) and a tenth of the pixels 40
    above it. (Points without velocity once all had value 0, drawn black, the
    cloud's rgb ignored: brightest pixel 20, mean at the background's.) Now
    27-30 on average here, a fifth of the frame well lit."""
    path = Path(__file__).parents[1] / "data" / name
    assert cli.main(["gauss", str(path), "--size", "96x96", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "build" in out and "render ms" in out
    with Image.open(tmp_path / "points.png") as im:
        a = np.asarray(im).astype(np.float64)
    bg = BACKGROUND.mean()
    assert a.mean() >= bg + 10
    assert (a.mean(axis=2) >= bg + 40).mean() >= 0.1


def test_gauss_attribute(tmp_path, capsys):
    path = Path(__file__).parents[1] / "data" / "laspy_simple.laz"
    assert (
        cli.main(["gauss", str(path), "--attribute", "intensity", "--size", "48x48", "--out", str(tmp_path)])
        == 0
    )
    assert "intensity through inferno" in capsys.readouterr().out
    with Image.open(tmp_path / "points.png") as im:
        assert np.asarray(im).astype(np.float64).mean() >= BACKGROUND.mean() + 10
    assert cli.main(["gauss", str(path), "--attribute", "nope", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--attribute" in err and "'nope'" in err and "intensity" in err
    assert cli.main(["gauss", "--attribute", "intensity", "--out", str(tmp_path)]) == 2
    assert "point clouds" in capsys.readouterr().err


@pytest.mark.parametrize("suffix", [".ply", ".npz"])
def test_gauss_non_finite_velocity_or_attribute_names_file_attribute_and_point(tmp_path, capsys, suffix):
    # "nanvel.ply: velocity: NaN or infinite components" named no point;
    # an infinite attribute said "--attribute: values: row 77 ..." without the file
    rng = np.random.default_rng(1)
    n = 300
    v = rng.random((n, 3))
    v[123, 1] = np.nan
    t = rng.random(n)
    t[77] = np.inf
    cloud = PointCloud(rng.random((n, 3)), velocity=v, attributes={"temp": t})
    path = tmp_path / f"nan vel{suffix}"
    write_ply(path, cloud) if suffix == ".ply" else save_npz(path, cloud)
    assert cli.main(["gauss", str(path), "--size", "32x32", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{path}: velocity: point 123 is [" in err and ", nan, " in err and "(1 of 300 points)" in err
    v[123, 1] = 0.5
    cloud = PointCloud(cloud.positions, velocity=v, attributes={"temp": t})
    write_ply(path, cloud) if suffix == ".ply" else save_npz(path, cloud)
    args = ["gauss", str(path), "--attribute", "temp", "--size", "32x32", "--out", str(tmp_path / "o")]
    assert cli.main(args) == 2
    err = capsys.readouterr().err
    assert f"{path}: attribute 'temp': point 77 is inf, not finite (1 of 300 points)" in err
    assert not (tmp_path / "o").exists()


def test_gauss_one_pixel_wide_has_no_colour_bar(tmp_path, capsys):
    # --size 1x1 failed after rendering: "width: a colour bar needs at least 2 columns, got 1"
    path = Path(__file__).parents[1] / "data" / "pyvista_ant.ply"
    assert cli.main(["gauss", str(path), "--size", "1x1", "--out", str(tmp_path)]) == 0, (
        capsys.readouterr().err
    )
    assert (tmp_path / "points.png").is_file()


@pytest.mark.parametrize("suffix", [".pcd", ".xyz"])
def test_gauss_reads_the_point_files_render_reads(tmp_path, capsys, suffix):
    # .pcd, .e57 and .xyz/.txt/.csv clouds were "unknown format" to clvis gauss
    from fuzz.seeds import _pcd

    path = tmp_path / f"cloud{suffix}"
    if suffix == ".pcd":
        _pcd(path, 300, binary=False)
    else:
        np.savetxt(path, np.random.default_rng(0).random((300, 3)))
    assert cli.main(["gauss", str(path), "--size", "32x24", "--out", str(tmp_path / "o")]) == 0
    assert (tmp_path / "o" / "points.png").is_file(), capsys.readouterr().err


def test_gauss_lod_is_checked_by_argparse(capsys):
    from clvis.cli import gauss as cg

    assert cg._lods(" high, low ") == ["high", "low"]
    assert cli.main(["gauss", "--lod", "low,ultra"]) == 2
    err = capsys.readouterr().err
    assert "argument --lod" in err and "ultra" in err


def test_gauss_progress_on_stderr(tmp_path, capsys):
    assert cli.main(["gauss", "--lod", "low", "--size", "40x40", "--progress", "--out", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert "building kernels" in err and "1,600 / 1,600 rays" in err
    assert cli.main(["gauss", "--lod", "low", "--size", "40x40", "--out", str(tmp_path)]) == 0
    err = capsys.readouterr().err  # not a terminal: no progress, and no note (the explosion drawn as a fog)
    assert err == ""


def test_gauss_embedded_explosion_is_drawn_as_a_fog(tmp_path, capsys):
    """The embedded explosion (a density field) by default through the fog
    transfer function the dark-picture note suggests (under the volume
    defaults 81 % of its pixels were the darkest colours, and the note came
    with clvis gauss's first run): no note, and its inside drawn bright;
    --opacity given takes over, and the default dark picture returns."""
    argv = ["gauss", "--lod", "medium", "--size", "64x64", "--no-labels"]
    assert cli.main([*argv, "--out", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    assert "the embedded explosion drawn as a fog" in out and "note" not in err
    fog = _bright(tmp_path / "medium.png")
    assert cli.main([*argv, "--opacity", "0:0.05,0.35:0.35,1:1", "--out", str(tmp_path / "dark")]) == 0
    assert "note" not in capsys.readouterr().err  # the user's --opacity: never a note
    assert fog > 2 * _bright(tmp_path / "dark" / "medium.png")


def test_gauss_fog_volume_grid_is_drawn_as_a_fog(tmp_path, capsys):
    """A .vdb grid of class "fog volume" (tests/data/openvdb_fog.vdb, written
    by OpenVDB) is drawn as the embedded explosion is: under the volume
    defaults its shell of low values hid the bright inside (the picture
    mostly the darkest colours); --opacity given takes over."""
    path = Path(__file__).parents[1] / "data" / "openvdb_fog.vdb"
    argv = ["gauss", str(path), "--lod", "medium", "--size", "64x64", "--no-labels"]
    assert cli.main([*argv, "--out", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    assert "a fog volume (the grid's class) drawn as a fog" in out and "note" not in err
    assert cli.main([*argv, "--opacity", "0:0.05,0.35:0.35,1:1", "--out", str(tmp_path / "dark")]) == 0
    assert "drawn as a fog" not in capsys.readouterr().out

    def p90(path):  # the luminance of the picture's brightest tenth
        rgb = np.asarray(Image.open(path).convert("RGB"), np.float64) / 255
        return np.percentile(rgb @ [0.2126, 0.7152, 0.0722], 90)

    assert p90(tmp_path / "medium.png") > 2 * p90(tmp_path / "dark" / "medium.png")  # 0.27 against 0.11


def test_gauss_level_set_grid_names_clvis_iso_for_its_surface(tmp_path, capsys):
    """A .vdb level set is drawn as Gaussians of its narrow band (the band's
    outside in front, not its zero crossing), and the transfer line names
    the command that draws its surface, with the grid picked."""
    path = Path(__file__).parents[1] / "data" / "openvdb_small.vdb"
    argv = ["gauss", str(path), "--lod", "low", "--size", "32x32", "--out", str(tmp_path)]
    assert cli.main(argv) == 0
    assert f"narrow band (its distances); clvis iso {path} draws its surface" in capsys.readouterr().out
    assert cli.main([*argv, "--grid", "surface"]) == 0
    assert f"clvis iso {path} --grid surface draws" in capsys.readouterr().out
    assert cli.main([*argv, "--grid", "density"]) == 0  # no class: nothing said
    assert "narrow band" not in capsys.readouterr().out


def _bright(path) -> float:
    """The fraction of a picture's pixels brighter than mid-grey (luminance)."""
    from PIL import Image

    rgb = np.asarray(Image.open(path).convert("RGB"), np.float64) / 255
    return float(((rgb @ [0.2126, 0.7152, 0.0722]) > 0.4).mean())


def _lit(path) -> float:
    """The fraction of a --no-labels picture's pixels well above the background."""
    with Image.open(path) as im:
        a = np.asarray(im.convert("RGB")).astype(np.float64)
    return float((np.abs(a - BACKGROUND).sum(axis=2) > 30).mean())


def test_gauss_frames_the_bulk_of_a_cloud_with_stray_points(tmp_path, capsys):
    """laspy's simple.las with 3 points moved to (0, 0, 0), 10^6 m away: the
    view framed every Gaussian and points.png was background only; it frames
    the bulk now, as clvis render does, with render's note (gauss's name)."""
    cloud = clvis.read_points(Path(__file__).parents[1] / "data" / "laspy_simple.laz")
    world = cloud.positions.astype(np.float64) + cloud.origin
    np.save(tmp_path / "bulk.npy", world)
    world[[5, 500, 1000]] = 0.0
    np.save(tmp_path / "stray.npy", world)
    small = ["--size", "80x60", "--no-labels"]
    assert cli.main(["gauss", str(tmp_path / "stray.npy"), *small, "--out", str(tmp_path / "s")]) == 0
    err = capsys.readouterr().err
    # (the strays' x: -0.05, float32's step 0.06 from the bulk's origin, which keeps the bulk exact)
    note = "clvis gauss: note: 3 of 1,065 points lie far outside the rest (the cloud spans -0.05.."
    assert err.startswith(note), err
    assert "the view frames the bulk (--eye/--target to look elsewhere)" in err
    assert cli.main(["gauss", str(tmp_path / "bulk.npy"), *small, "--out", str(tmp_path / "b")]) == 0
    assert "note" not in capsys.readouterr().err
    stray, bulk = _lit(tmp_path / "s" / "points.png"), _lit(tmp_path / "b" / "points.png")
    assert bulk > 0.2 and stray > 0.5 * bulk, (stray, bulk)  # was 0 of the frame


def test_gauss_colours_by_z_in_the_files_coordinates(tmp_path, capsys, monkeypatch):
    """A cloud far from the origin, no colours, no velocity: coloured by its
    z, which --range, the summary and the colour bar give in the file's
    coordinates (they were relative to the cloud's internal origin: "z -
    1000000000", and --range 1000000000.5,1000000001.5 saturated every point)."""
    from clvis import images

    bars = []
    colorbar = images.colorbar
    monkeypatch.setattr(images, "colorbar", lambda *a, **k: bars.append(a[1:3]) or colorbar(*a, **k))
    rng = np.random.default_rng(3)
    pos = rng.random((400, 3)) * [10, 10, 2]
    np.save(tmp_path / "far.npy", pos + [0, 0, 1e9])
    np.save(tmp_path / "near.npy", pos)
    small = ["--size", "48x48", "--no-labels"]
    for name, rng_ in (("far", "1000000000.5,1000000001.5"), ("near", "0.5,1.5")):
        args = ["gauss", str(tmp_path / f"{name}.npy"), *small, "--range", rng_, "-o", str(tmp_path / name)]
        assert cli.main(args) == 0
        out = capsys.readouterr().out
        assert "colour    z through inferno" in out, out
        assert f"transfer  range {rng_.replace(',', '..')}" in out, out
    assert bars == [(1000000000.5, 1000000001.5), (0.5, 1.5)]  # gauss.png's (--no-labels: not points.png)
    # the same picture: the range is the same z in both files' coordinates
    with Image.open(tmp_path / "far" / "points.png") as a, Image.open(tmp_path / "near" / "points.png") as b:
        assert np.abs(np.asarray(a).astype(int) - np.asarray(b)).mean() < 1
    # percentiles are of the z's, shown in the file's coordinates too
    args = ["gauss", str(tmp_path / "far.npy"), *small, "--range", "p0,p100", "--out", str(tmp_path / "p")]
    assert cli.main(args) == 0
    (lo, hi), z = bars[-1], pos[:, 2] + 1e9
    assert abs(lo - z.min()) < 1e-3 and abs(hi - z.max()) < 1e-3, (lo, hi)
    assert "of the samples: 1e+09" in capsys.readouterr().out


def test_gauss_all_nan_volume_names_the_file(tmp_path, capsys):
    np.save(tmp_path / "nan.npy", np.full((6, 6, 6), np.nan, np.float32))
    assert cli.main(["gauss", str(tmp_path / "nan.npy"), "--size", "32x32", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "nan.npy" in err and "no finite value" in err, err


def test_gauss_frames_the_whole_volume(tmp_path, capsys):
    """An L-shaped mask seen from the front fills the panel without touching
    its edges (the view framed every LOD's 1-sigma boxes and cut the L's
    splats on every side)."""
    v = np.zeros((24, 24, 24), np.float32)  # [z, y, x]; the front view looks along +y
    v[2:22, 8:16, 2:8] = 1.0  # the upright bar
    v[2:8, 8:16, 2:22] = 1.0  # the foot
    np.save(tmp_path / "l.npy", v)
    args = ["gauss", str(tmp_path / "l.npy"), "--lod", "high", "--view", "front", "--no-labels"]
    assert cli.main([*args, "--size", "96x96", "--out", str(tmp_path)]) == 0
    with Image.open(tmp_path / "high.png") as im:
        a = np.asarray(im.convert("RGB")).astype(np.float64).mean(axis=2)
    lit = a > BACKGROUND.mean() + 12
    assert lit.mean() > 0.15  # the L is drawn
    border = np.concatenate([lit[0], lit[-1], lit[:, 0], lit[:, -1]])
    assert border.mean() < 0.05, border.mean()  # and not cut at the panel's edges (was 0.60)


def test_gauss_velocity_cloud_covers_as_much_as_without(tmp_path, capsys):
    """5,000 points with a random velocity: their Gaussians were needles 1/250
    of the point spacing thick (almost nothing drawn); now as wide as the
    spacing across the velocity, they cover about what the same points
    without a velocity do."""
    rng = np.random.default_rng(7)
    pos = rng.normal(size=(5000, 3))
    write_ply(tmp_path / "vel.ply", PointCloud(pos, velocity=rng.normal(size=(5000, 3))))
    write_ply(tmp_path / "plain.ply", PointCloud(pos))
    lit = {}
    for name in ("vel", "plain"):
        args = ["gauss", str(tmp_path / f"{name}.ply"), "--size", "80x60", "--no-labels"]
        assert cli.main([*args, "--out", str(tmp_path / name)]) == 0
        lit[name] = _lit(tmp_path / name / "points.png")
    capsys.readouterr()
    assert lit["plain"] > 0.1 and lit["vel"] > 0.6 * lit["plain"], lit


@pytest.mark.parametrize(
    "args,message",
    [
        # --density 0 drew three empty panels
        (["--density", "0"], "argument --density: expected a number > 0 (finite), got '0'"),
        # options the input or model does not use were ignored (the same image)
        (["--model", "splat", "--density", "500"], "--density: the absorption model's extinction scale"),
        (["--model", "max_response", "--density", "5"], "--model max_response does not use it"),
        (["--model", "splat", "--k", "1"], "--k: the k-buffer of the ray models"),
        (["POINTS", "--threshold", "100"], "--threshold: a volume's voxels above it are active; "),
        (["GAUSSIANS", "--threshold", "1"], "a file of Gaussians, drawn as they are (leave --threshold out)"),
    ],
)
def test_gauss_refuses_options_that_do_not_apply(tmp_path, capsys, args, message):
    write_ply(tmp_path / "p.ply", PointCloud(np.random.default_rng(0).normal(size=(50, 3))))
    clvis.gaussians_from_volume(datasets.explosion((8, 8, 8))["volume"], lod="low").save(tmp_path / "g.npz")
    files = {"POINTS": str(tmp_path / "p.ply"), "GAUSSIANS": str(tmp_path / "g.npz")}
    args = [files.get(a, a) for a in args]
    assert cli.main(["gauss", *args, "--size", "16x16", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("clvis gauss: error: ") and message in err and "Traceback" not in err, err
    assert not (tmp_path / "o").exists()


def test_gauss_k_sizes_the_tile_renderers_buffer(tmp_path):
    """--k sized only the BVH march's k-buffer: with the tiles (the default)
    it was ignored; it sizes the tile renderer's pending hits now (the same
    image)."""
    from clvis.cli.gauss import render_panels

    sv = clvis.SparseVolume.from_dense(datasets.explosion((16, 16, 16))["volume"], threshold=0.0)
    imgs = [render_panels(["low"], sv, None, 24, 24, k=k, method="tiles")[0][2] for k in (3, None)]
    assert imgs[0].stats["kp"] == 3 and imgs[1].stats["kp"] != 3
    np.testing.assert_array_equal(imgs[0].rgba, imgs[1].rgba)


def test_gauss_refuses_a_level_given_twice(tmp_path, capsys):
    """--lod low,low rendered the low level twice and listed low.png twice."""
    assert cli.main(["gauss", "--lod", "low,high,low", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "argument --lod: low given more than once in 'low,high,low'" in err, err


def test_gauss_names_a_directory_as_render_does(tmp_path, capsys):
    """A directory was 'unknown format (expected ...)'; gauss names it as
    clvis render and clvis view do."""
    (tmp_path / "adir").mkdir()
    for command in ("gauss", "render"):
        assert cli.main([command, str(tmp_path / "adir"), "--out", str(tmp_path / "o")]) == 2
        assert capsys.readouterr().err == (
            f"clvis {command}: error: {tmp_path / 'adir'}: not a regular file (a directory)\n"
        )


def test_gauss_file_help_names_every_format_it_reads(capsys):
    """The positional FILE's help named .vdb, .npy, .npz and 'point cloud'
    while the description lists every volume and point format: it names
    them all now."""
    from clvis.io.points import POINT_SUFFIXES
    from clvis.io.volumes import FORMATS

    assert cli.main(["gauss", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    usage = text.split("positional arguments:")[1].split("options:")[0]
    for suffix in (".vdb", *FORMATS, *POINT_SUFFIXES):
        assert f"{suffix}," in usage or f"{suffix})" in usage, suffix


def test_array_is_for_a_vtk_volume_file(tmp_path, capsys):
    """--array picks a VTK volume's array (a name the file lacks is listed);
    without a file, or with a point set, it is refused, not ignored."""
    vtk_uniform = Path(__file__).resolve().parents[1] / "data" / "pyvista_uniform.vtk"
    out = ["--size", "64x48", "--out", str(tmp_path / "o")]
    assert cli.main(["gauss", str(vtk_uniform), "--array", "nope", *out]) == 2
    assert "no array 'nope' (point arrays: Spatial Point Data; cell arrays: Spatial Cell Data)" in (
        capsys.readouterr().err
    )
    assert cli.main(["gauss", "--array", "v", *out]) == 2
    assert "--array picks a data array of a VTK volume FILE" in capsys.readouterr().err
    pts = tmp_path / "p.npy"
    np.save(pts, np.random.default_rng(0).random((50, 3)))
    assert cli.main(["gauss", str(pts), "--array", "v", *out]) == 2
    assert "--array picks a data array of a VTK volume" in capsys.readouterr().err


def test_gauss_frames_a_point_cloud_as_render_does(tmp_path, capsys):
    """One point file, one default view: clvis gauss drew a point cloud from
    the volumes' direction (front left, 40 degrees) while clvis render drew it
    from the south-south-west through a 60-degree lens, so the two pictures of
    one file showed different sides of it. Now the shapes of gauss's
    points.png and render's colors.png (each cut to its lit box: gauss frames
    the splats' box, render the points) mostly coincide."""
    rng = np.random.default_rng(3)
    # an L of two unequal slabs: seen from another side, another shape
    a = rng.uniform((0, 0, 0), (10, 2, 1), size=(6000, 3))
    b = rng.uniform((0, 2, 0), (2, 6, 3), size=(3000, 3))
    write_ply(
        tmp_path / "l.ply", PointCloud(np.concatenate([a, b]), colors=np.full((9000, 3), 200, np.uint8))
    )
    size = ["--size", "144x96", "--no-labels"]
    assert cli.main(["gauss", str(tmp_path / "l.ply"), *size, "--out", str(tmp_path / "g")]) == 0
    assert cli.main(["render", str(tmp_path / "l.ply"), *size, "--out", str(tmp_path / "r")]) == 0
    capsys.readouterr()

    def shape(path):
        with Image.open(path) as im:
            lit = np.asarray(im.convert("L")) > 60
        ys, xs = np.nonzero(lit)
        box = Image.fromarray(255 * lit[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1].astype(np.uint8))
        return np.asarray(box.resize((24, 16), Image.Resampling.BOX)) > 50  # render's points are sparse

    g, r = shape(tmp_path / "g" / "points.png"), shape(tmp_path / "r" / "colors.png")
    iou = (g & r).sum() / max((g | r).sum(), 1)
    assert iou > 0.65, iou  # 0.81; was 0.44


def _vdb_file(tmp_path, first=True):
    """A .vdb of two float grids (written by tinyvdb from a hand-made template,
    as tests/gauss/test_lod.py's): 'temperature', 5 voxels (not with
    first=False); 'density', a 16^3 block at the origin valued x - 8 (8
    leaves, half of them <= 0, as a level set's inside is) and one voxel
    20,000 voxels out along each axis (1.3 * 10^13 voxels dense)."""
    pytest.importorskip("tinyvdb")
    from gauss.test_lod import _scale_translate, _write_vdb

    block = np.argwhere(np.ones((16, 16, 16)))[:, ::-1]
    ijk = np.concatenate([block, [[20000, 20000, 20000]]])
    vals = np.concatenate([block[:, 0] - 8.0, [5.0]])
    names = ("temperature", "density") if first else ("density",)
    grids = [(name, "Tree_float_5_4_3", _scale_translate((0.5, 0.5, 0.5), (0, 0, 0))) for name in names]
    fill = {len(names) - 1: (ijk, vals)} | ({0: (block[:5], np.ones(5))} if first else {})
    return _write_vdb(tmp_path, "two", grids, fill)


def _leaves(out: str) -> int:
    line = next(x for x in out.splitlines() if x.strip().startswith("volume"))
    return int(line.split(",")[-1].split()[0])


def test_gauss_vdb_grid(tmp_path, capsys):
    """--grid picks a .vdb's grid by name or index (it was always the first
    float grid, with no way to name another)."""
    path = _vdb_file(tmp_path)
    base = ["gauss", str(path), "--lod", "low", "--size", "32x32", "--quiet"]
    assert cli.main([*base, "--out", str(tmp_path / "a")]) == 0
    assert _leaves(capsys.readouterr().out) == 1  # the first float grid: temperature
    for grid in ("density", "1"):
        assert cli.main([*base, "--grid", grid, "--out", str(tmp_path / "b")]) == 0
        out = capsys.readouterr().out
        assert _leaves(out) == 9 and "grid" in out.splitlines()[0]
    assert cli.main([*base, "--grid", "nope", "--out", str(tmp_path / "e")]) == 2
    err = capsys.readouterr().err
    assert "no grid named 'nope'" in err and "'density'" in err and not (tmp_path / "e").exists()
    assert cli.main(["gauss", "--grid", "density", "--out", str(tmp_path / "f")]) == 2
    assert "--grid picks a grid of a .vdb FILE" in capsys.readouterr().err


def test_gauss_vdb_threshold_and_spacing_stay_sparse(tmp_path, capsys):
    """--threshold and --spacing work on the sparse grid (they made it dense:
    out of host memory for a grid spanning 20,000 voxels an axis), and
    --spacing alone keeps every active voxel (it dropped those <= 0)."""
    path = _vdb_file(tmp_path, first=False)
    base = ["gauss", str(path), "--lod", "low", "--size", "32x32", "--quiet"]
    assert cli.main([*base, "--spacing", "2,2,2", "--out", str(tmp_path / "c")]) == 0
    assert _leaves(capsys.readouterr().out) == 9
    assert cli.main([*base, "--threshold", "0", "--out", str(tmp_path / "d")]) == 0
    assert _leaves(capsys.readouterr().out) == 5  # x > 8: the 4 leaves of x 8..15, and the far voxel
    with Image.open(tmp_path / "d" / "low.png") as im:
        assert np.asarray(im).std() > 1


def test_gauss_vdb_far_from_the_origin_is_drawn_as_near_it(tmp_path, capsys):
    """A grid placed at map coordinates (translation 500,000, 4,000,000, 100;
    0.25 voxels) is drawn as the same grid at the origin: its float32
    Gaussians lost their detail there and the view showed a dot. --eye and
    --target stay in the file's coordinates."""
    pytest.importorskip("tinyvdb")
    from gauss.test_lod import _scale_translate, _write_vdb

    zyx = np.argwhere(np.ones((16, 16, 16)))
    ijk, vals = zyx[:, ::-1], 1.0 + zyx[:, 2] / 16.0
    lit = []
    for name, t in (("near", (0.0, 0.0, 0.0)), ("far", (500000.0, 4000000.0, 100.0))):
        grids = [("density", "Tree_float_5_4_3", _scale_translate((0.25, 0.25, 0.25), t))]
        path = _write_vdb(tmp_path, name, grids, {0: (ijk, vals)})
        args = ["gauss", str(path), "--lod", "high", "--size", "48x48", "--no-labels", "--quiet"]
        assert cli.main([*args, "--out", str(tmp_path / name)]) == 0
        lit.append(_lit(tmp_path / name / "high.png"))
        eye = ",".join(f"{c + 2:.17g}" for c in np.add(t, [-6.0, -8.0, 5.0]))  # in the file's coordinates
        target = ",".join(f"{c + 2:.17g}" for c in t)
        assert (
            cli.main([*args, "--eye", eye, "--target", target, "--out", str(tmp_path / f"{name}-eye")]) == 0
        )
        lit.append(_lit(tmp_path / f"{name}-eye" / "high.png"))
    capsys.readouterr()
    assert lit[0] > 0.2 and lit[1] > 0.2
    np.testing.assert_allclose(lit[2:], lit[:2], atol=0.02)


def test_gauss_a_volume_file_with_nothing_active_names_the_file(tmp_path, capsys):
    """It said 'no Gaussians: the volume has no active voxel', naming neither
    the file nor the threshold."""
    path = tmp_path / "low.npy"
    np.save(path, -np.ones((8, 8, 8), np.float32))
    assert cli.main(["gauss", str(path), "--out", str(tmp_path / "a")]) == 2
    assert f"{path}: no sample above 0 (the default --threshold)" in capsys.readouterr().err
    assert cli.main(["gauss", str(path), "--threshold", "2", "--out", str(tmp_path / "a")]) == 2
    assert f"{path}: no active voxel above --threshold 2" in capsys.readouterr().err
    vdb = _vdb_file(tmp_path, first=False)
    assert cli.main(["gauss", str(vdb), "--threshold", "50", "--out", str(tmp_path / "a")]) == 2
    assert f"{vdb}: no active voxel above --threshold 50" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()


def test_gauss_says_when_the_picture_is_nearly_empty(tmp_path, capsys):
    """Three voxels of a 128^3 volume at 32x32 draw 1 pixel: a blank PNG
    looked like a broken render; a note on stderr says why and what draws
    more. A picture with something in it gets no note."""
    v = np.zeros((128, 128, 128), np.float32)
    v[3, 5, 7] = v[120, 100, 90] = v[60, 64, 70] = 1
    np.save(tmp_path / "tiny.npy", v)
    small = ["--size", "32x32", "--out"]
    assert cli.main(["gauss", str(tmp_path / "tiny.npy"), *small, str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err
    assert "clvis gauss: note: the picture is nearly empty: 1 of 1,024 pixels drawn at 32x32" in err
    assert "a larger --size, a closer view" in err and "--lod low" in err
    # a point cloud's Gaussians have no level of detail: --lod is refused for them, so not offered
    (tmp_path / "few.xyz").write_text("0 0 0\n1 0 0\n0 1 0\n")
    away = ["--eye", "0.5,0.5,5", "--target", "0.5,0.5,10"]  # the camera turned away from them
    assert cli.main(["gauss", str(tmp_path / "few.xyz"), *away, *small, str(tmp_path / "c")]) == 0
    err = capsys.readouterr().err
    assert "clvis gauss: note: the picture is empty" in err and "--lod" not in err, err
    v[40:90, 40:90, 40:90] = 1
    np.save(tmp_path / "block.npy", v)
    assert cli.main(["gauss", str(tmp_path / "block.npy"), *small, str(tmp_path / "b")]) == 0
    assert "empty" not in capsys.readouterr().err


def test_gauss_micro_scale_volume_fills_the_frame_as_at_spacing_1(tmp_path, capsys):
    """A volume of micrometre voxels given in metres (--spacing 1e-6) is drawn
    as the same volume at spacing 1: the camera's floor on the framed size
    was an absolute 1e-4, which drew the 1.6e-5-wide volume as a dot (0.2 %
    of the pixels drawn, against 22 %)."""
    z, y, x = np.mgrid[:16, :16, :16]
    v = np.clip(1 - np.sqrt((x - 7.5) ** 2 + (y - 7.5) ** 2 + (z - 7.5) ** 2) / 7, 0, 1)
    np.save(tmp_path / "ball.npy", v.astype(np.float32))
    alpha = {}
    for s in ("1", "1e-6"):
        args = ["gauss", str(tmp_path / "ball.npy"), "--spacing", f"{s},{s},{s}", "--lod", "high"]
        assert (
            cli.main([*args, "--size", "48x48", "--no-labels", "--transparent", "--out", str(tmp_path / s)])
            == 0
        )
        with Image.open(tmp_path / s / "high.png") as im:
            alpha[s] = np.asarray(im)[..., 3] > 10
    capsys.readouterr()
    assert alpha["1"].mean() > 0.1
    assert abs(alpha["1e-6"].mean() - alpha["1"].mean()) < 0.02 * alpha["1"].mean()
    assert (alpha["1e-6"] != alpha["1"]).mean() < 0.01  # the same picture


def test_attribute_for_a_volume_names_every_point_format(tmp_path, capsys):
    """--attribute with a volume FILE: the message listed .ply, .las, .laz,
    .npy and .npz as the point clouds, while .pcd, .e57, .xyz, .vtp and the
    rest take --attribute too."""
    from clvis.io.points import POINT_SUFFIXES

    raw = tmp_path / "v_4x4x4_float32.raw"
    np.ones((4, 4, 4), np.float32).tofile(raw)
    assert cli.main(["gauss", str(raw), "--attribute", "x", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "--attribute is for point clouds" in err
    for suffix in POINT_SUFFIXES:
        assert suffix in err, suffix
    # a volume under a point cloud's suffix (a 3-D .npy, a legacy .vtk of STRUCTURED_POINTS): --attribute
    # was ignored without a word
    np.save(tmp_path / "v.npy", np.ones((4, 4, 4), np.float32))
    vtk_volume = Path(__file__).resolve().parents[1] / "data" / "pyvista_uniform.vtk"
    for volume in (tmp_path / "v.npy", vtk_volume):
        assert cli.main(["gauss", str(volume), "--attribute", "x", "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert f"--attribute colours a point cloud's Gaussians; {volume} is a volume" in err, err
    saved = tmp_path / "g.npz"  # Gaussians saved with clvis.Gaussians.save: drawn as saved
    clvis.gaussians_from_points(clvis.PointCloud(np.random.default_rng(1).random((20, 3)))).save(saved)
    assert cli.main(["gauss", str(saved), "--attribute", "x", "--out", str(tmp_path / "o")]) == 2
    assert f"{saved} holds Gaussians, drawn as saved" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "option", [["--spacing", "1,1,2"], ["--shape", "4x4x4"], ["--dtype", "uint8"], ["--volume-index", "0"]]
)
def test_volume_options_with_a_point_cloud_are_refused(tmp_path, capsys, option):
    """A volume file's options with a point cloud (or saved Gaussians) were
    ignored without a word; --lod and --threshold were refused already."""
    ply = Path(__file__).resolve().parents[1] / "data" / "pyvista_ant.ply"
    assert cli.main(["gauss", str(ply), *option, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{option[0]}: for a volume file; {ply} is a point cloud, one Gaussian a point" in err, err
    assert not (tmp_path / "o").exists()


def test_an_earlier_runs_levels_left_in_the_folder_are_named(tmp_path, capsys):
    """--lod low into a folder where a run of every level wrote medium.png and
    high.png: those stayed beside the new low.png and gauss.png and read as
    this run's; a note names them (kept: the user's to remove)."""
    np.save(tmp_path / "v.npy", np.random.default_rng(4).random((16, 16, 16)).astype(np.float32))
    base = ["gauss", str(tmp_path / "v.npy"), "--size", "24x24", "--out", str(tmp_path / "o")]
    assert cli.main(base) == 0
    assert "earlier run" not in capsys.readouterr().err
    assert cli.main([*base, "--lod", "low"]) == 0
    err = capsys.readouterr().err
    assert f"clvis gauss: note: {tmp_path / 'o'} also holds high.png, medium.png from an earlier run" in err
