"""Options that would do nothing are errors, one NaN rule for render and
gauss, and camera errors a command line user can act on. Through main(),
with exit status and stderr, on third-party files where the case came from one."""

from pathlib import Path

import numpy as np
import pytest

from clvis import cli
from clvis.io import PointCloud, read_points, save_npz

DATA = Path(__file__).parents[1] / "data"
SIMPLE = DATA / "laspy_simple.laz"  # laspy's simple.laz: 1,065 points, classes 1 and 2
ANT = DATA / "pyvista_ant.ply"  # pyvista's ant.ply: 486 vertices
SMALL = ["--size", "64x48", "--quiet"]

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def _main(capsys, *args):
    try:
        rc = cli.main([*map(str, args)])
    except SystemExit as e:
        rc = e.code
    out, err = capsys.readouterr()
    return rc, out, err


def test_brick_without_workers_is_an_error(tmp_path, capsys):
    rc, out, err = _main(capsys, "iso", "--brick", "32", "--out", tmp_path, *SMALL)
    assert rc == 2 and out == ""
    assert err.startswith("clvis iso: error: --brick") and "--workers" in err
    assert err.count("\n") == 1
    assert not list(tmp_path.iterdir())


def test_lod_on_a_point_cloud_is_an_error(tmp_path, capsys):
    rc, out, err = _main(capsys, "gauss", ANT, "--lod", "low", "--out", tmp_path, *SMALL)
    assert rc == 2, err
    assert err.startswith("clvis gauss: error: --lod:") and "point cloud" in err
    assert not list(tmp_path.iterdir())
    # without --lod the same file renders
    rc, out, err = _main(capsys, "gauss", ANT, "--out", tmp_path, *SMALL)
    assert rc == 0, err
    assert (tmp_path / "points.png").is_file()


def test_lod_on_a_file_of_gaussians_is_an_error(tmp_path, capsys):
    from clvis import datasets
    from clvis.gauss import SparseVolume, gaussians_from_volume

    e = datasets.explosion()
    sv = SparseVolume.from_dense(e["volume"][::4, ::4, ::4], threshold=0.0)
    path = tmp_path / "g.npz"
    gaussians_from_volume(sv, lod="low").save(path)
    rc, out, err = _main(capsys, "gauss", path, "--lod", "medium", "--out", tmp_path / "o", *SMALL)
    assert rc == 2 and "--lod:" in err and "Gaussians" in err


def test_render_and_gauss_drop_nan_points_alike(tmp_path, capsys):
    """One rule: points with a NaN or infinite coordinate are left out, and
    both commands say how many (gauss used to refuse the file render drew)."""
    cloud = read_points(ANT)
    p = cloud.positions.astype(np.float64) + cloud.origin
    p[[3, 10, 11]] = [np.nan, 0, 0], [0, np.inf, 0], [0, 0, -np.inf]
    path = tmp_path / "nan.npz"
    save_npz(path, PointCloud(p))
    for cmd in ("render", "gauss"):
        rc, out, err = _main(capsys, cmd, path, "--out", tmp_path / cmd, *SMALL)
        assert rc == 0, (cmd, err)
        assert "dropped   3 points with a NaN or infinite coordinate (never drawn)" in out, (cmd, out)


def test_camera_errors_have_one_prefix_and_no_api_advice(tmp_path, capsys):
    # an eye 1e30 away: a view volume of zero size in float64
    rc, out, err = _main(capsys, "render", SIMPLE, "--eye", "1e30,0,0", "--out", tmp_path, *SMALL)
    assert rc == 2
    line = err.strip()
    assert line.startswith("clvis render: error: camera: ") and line.count("camera:") == 1, line
    assert "Camera." not in line and "--eye" in line
    assert err.count("\n") == 1


def _png(path):
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im)


def test_every_png_that_maps_values_has_its_bar_or_legend(tmp_path, capsys):
    """Each panel PNG that maps values to colours (an attribute, the classes,
    depth; Gaussians through a transfer function) is labelled over its colour
    bar or legend, as its tile in the overview; --no-labels: the image alone."""
    from clvis import colormap, images

    w, h = 240, 135
    size = ["--size", f"{w}x{h}", "--quiet"]
    rc, out, err = _main(capsys, "render", SIMPLE, "--attribute", "z", *size, "--out", tmp_path / "z")
    assert rc == 0, err
    band = images.label_height(w)
    for name in ("attribute-z", "depth", "soft-z"):  # soft z: the attribute's colours, its bar
        a = _png(tmp_path / "z" / f"{name}.png")
        assert a.shape[1] == w and a.shape[0] > h + band, name
    a = _png(tmp_path / "z" / "attribute-z.png")
    ramp = a[band + h + 1, :, :3]  # the bar's first row under the image
    lut = colormap.lut("viridis")[:, :3]
    assert (np.abs(ramp[0].astype(int) - lut[0]).max() <= 2) and (
        np.abs(ramp[-1].astype(int) - lut[-1]).max() <= 2
    )
    assert _png(tmp_path / "z" / "colors.png").shape[:2] == (h, w)  # the file's own colours: no bar
    rc, out, err = _main(
        capsys, "render", SIMPLE, "--attribute", "classification", *size, "--out", tmp_path / "c"
    )
    assert rc == 0, err
    c = _png(tmp_path / "c" / "attribute-classification.png")
    legend = c[band + h :]
    # the legend's swatches: ASPRS class 2 (ground) in its palette colour
    ground = tuple(int(v) for v in colormap.class_palette()[2, :3])
    assert (legend[..., :3] == ground).all(axis=-1).any()
    rc, out, err = _main(
        capsys, "render", SIMPLE, "--attribute", "z", *size, "--no-labels", "--out", tmp_path / "b"
    )
    assert rc == 0, err
    for name in ("attribute-z", "depth", "colors"):
        assert _png(tmp_path / "b" / f"{name}.png").shape[:2] == (h, w), name
    rc, out, err = _main(capsys, "iso", "--size", "64x48", "--quiet", "--no-labels", "--out", tmp_path / "i")
    assert rc == 0 and _png(tmp_path / "i" / "iso.png").shape[:2] == (48, 64)
    rc, out, err = _main(capsys, "gauss", ANT, "--attribute", "z", *SMALL, "--out", tmp_path / "g")
    assert rc == 0, err
    g = _png(tmp_path / "g" / "points.png")
    assert g.shape[1] == 64 and g.shape[0] > 48 + images.label_height(64)
