"""clvis iso's surface options through cli.main: --color-by (a second field
at the hits, with a colour bar), several isovalues composited (with a
legend), --surface-color, the warnings for a constant volume and an isovalue
at the end of the range, the note when speculation stops far past
--completion, and the errors. On third-party files: pyvista's uniform.vtk
(tests/data, point scalars x*y*z) and nibabel's anatomical.nii (an MRI; the
tests that need it skip when nibabel is absent)."""

import os

import numpy as np
import pytest
from PIL import Image

from clvis import cli, images

DATA = os.path.join(os.path.dirname(__file__), "..", "data")
UNIFORM = os.path.join(DATA, "pyvista_uniform.vtk")
W, H = 96, 72
BACKGROUND = np.array(images.BACKGROUND)


def _png(path):
    with Image.open(path) as im:
        return np.asarray(im)[..., :3].astype(int)


def _surface(a):
    """The pixels that are not background (under the label band, above any bar)."""
    return np.abs(a - BACKGROUND).sum(axis=2) > 30


def _run(capsys, *args):
    rc = cli.main(["iso", *args])
    out, err = capsys.readouterr()
    return rc, out, err


def test_color_by_itself_gives_the_isovalue(tmp_path, capsys):
    """pyvista's x*y*z coloured by itself: every hit lies on the surface, so
    the colours span the isovalue alone (at ZFP rate 32, near lossless)."""
    rc, out, err = _run(
        capsys,
        UNIFORM,
        "--isovalue",
        "100",
        "--rate",
        "32",
        "--color-by",
        UNIFORM,
        "--size",
        f"{W}x{H}",
        "--out",
        str(tmp_path),
    )
    assert rc == 0, err
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("colour"))
    lo, hi = (float(v) for v in line.rsplit("range ", 1)[1].split(".."))
    assert 99.99 <= lo <= hi <= 100.01, line
    a = _png(tmp_path / "iso.png")
    assert a.shape[0] > H + images.label_height(W)  # the colour bar under the image


def test_color_by_another_grid(tmp_path, capsys):
    """A field on another grid (the x index of a 4 x 5 x 7 grid) stretched over
    the box: the colours run along x; --range and --colormap apply, a bar
    is drawn; a plain render of the same surface is sand-coloured."""
    x = np.broadcast_to(np.linspace(0.0, 9.0, 7, dtype=np.float32), (4, 5, 7)).copy()
    np.save(tmp_path / "x.npy", x)
    args = [UNIFORM, "--isovalue", "100", "--size", f"{W}x{H}"]
    rc, out, err = _run(
        capsys,
        *args,
        "--color-by",
        str(tmp_path / "x.npy"),
        "--colormap",
        "gray",
        "--range",
        "0,9",
        "--out",
        str(tmp_path / "c"),
    )
    assert rc == 0, err
    assert "range 0..9" in out
    rc, _, err = _run(capsys, *args, "--out", str(tmp_path / "p"))
    assert rc == 0, err
    lab = images.label_height(W)
    coloured, plain = _png(tmp_path / "c" / "iso.png"), _png(tmp_path / "p" / "iso.png")
    assert coloured.shape[0] > plain.shape[0] == H + lab
    c, p = coloured[lab : lab + H], plain[lab:]
    on = _surface(p)
    assert on.sum() > 100
    # the same surface (save its darkest greys, near the background)
    assert not (_surface(c) & ~on).any() and (_surface(c) & on).sum() > 0.9 * on.sum()
    grey = c[on]
    assert (np.abs(grey[:, 0] - grey[:, 2]) <= 1).all()  # gray colormap: r == b (the highlight white)
    assert (np.abs(p[on][:, 0] - p[on][:, 2]) > 20).mean() > 0.9  # sand: r well above b
    # along x (to the right in this view, at least on average) the grey grows
    cols = np.nonzero(on.any(axis=0))[0]
    left = c[:, cols[: len(cols) // 3]][on[:, cols[: len(cols) // 3]]][:, 0].mean()
    right = c[:, cols[-len(cols) // 3 :]][on[:, cols[-len(cols) // 3 :]]][:, 0].mean()
    assert abs(left - right) > 20, (left, right)


def test_color_by_nifti(tmp_path, capsys):
    """nibabel's anatomical MRI coloured by another of its scans (a different
    grid, stretched over the box): rc 0, the colour line and a bar."""
    nibabel = pytest.importorskip("nibabel")
    nib = os.path.join(os.path.dirname(nibabel.__file__), "tests", "data")
    rc, out, err = _run(
        capsys,
        os.path.join(nib, "anatomical.nii"),
        "--color-by",
        os.path.join(nib, "reoriented_anat_moved.nii"),
        "--range",
        "p2,p98",
        "--size",
        f"{W}x{H}",
        "--out",
        str(tmp_path),
    )
    assert rc == 0, err
    assert "reoriented_anat_moved.nii at the hits through viridis" in out
    a = _png(tmp_path / "iso.png")
    assert a.shape[0] > H + images.label_height(W)


def test_color_by_a_scan_is_placed_by_the_affines(tmp_path, capsys):
    """Two scans of a subject rarely share a grid or a box: --color-by
    stretched the field's grid over FILE's box, whatever their affines said,
    and coloured the surface by the wrong places (nibabel's anatomical.nii by
    its resliced, moved copy: mostly the background's 0). Now a NIfTI field
    is placed by the two affines in the scanner's world. FILE: a ball of
    radius 8 mm on a 2 mm grid; the field: the world x coordinate, on FILE's
    own grid (the reference), on a coarser grid over a larger, shifted box,
    and on a grid turned 30 degrees about z (resampled onto FILE's grid):
    the values on the surface span the same range."""
    nibabel = pytest.importorskip("nibabel")

    def scan(name, shape, affine, values):
        ijk = np.indices(shape).reshape(3, -1)  # (i, j, k): x fastest in the returned [z, y, x]
        world = (affine[:3, :3] @ ijk + affine[:3, 3:]).reshape(3, *shape)
        path = tmp_path / name
        nibabel.save(nibabel.Nifti1Image(values(world).astype(np.float32), affine), path)
        return str(path)

    ball = np.diag([2.0, 2.0, 2.0, 1.0])
    ball[:3, 3] = -20.0
    volume = scan("ball.nii", (21, 21, 21), ball, lambda w: np.sqrt((w**2).sum(axis=0)))
    coarse = np.diag([3.0, 3.0, 3.0, 1.0])
    coarse[:3, 3] = (-31.0, -26.0, -29.0)
    turn = np.eye(4)
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    turn[:3, :3] = [[2 * c, -2 * s, 0], [2 * s, 2 * c, 0], [0, 0, 2]]
    turn[:3, 3] = (-2.0, -30.0, -22.0)
    ranges = {}
    for name, shape, affine in (
        ("same.nii", (21, 21, 21), ball),
        ("coarse.nii", (22, 19, 20), coarse),
        ("turned.nii", (24, 24, 23), turn),
    ):
        field = scan(name, shape, affine, lambda w: w[0])
        rc, out, err = _run(
            capsys, volume, "--isovalue", "8", "--rate", "32", "--color-by", field,
            "--size", f"{W}x{H}", "--out", str(tmp_path / ("out-" + name)),
        )  # fmt: skip
        assert rc == 0, err
        assert (
            "the field placed by the files' affines (a VTK image's spacing and origin), in the world" in out
        )
        line = next(ln for ln in out.splitlines() if ln.strip().startswith("colour"))
        lo, hi = (float(v) for v in line.rsplit("range ", 1)[1].split(".."))
        ranges[name] = lo, hi
    lo, hi = ranges["same.nii"]
    assert hi - lo > 8, ranges  # the ball's visible side spans much of its 16 mm
    for name in ("coarse.nii", "turned.nii"):
        np.testing.assert_allclose(ranges[name], ranges["same.nii"], atol=0.05, err_msg=name)


def test_color_by_a_vtk_image_is_placed_by_its_spacing_and_origin(tmp_path, capsys):
    """Two VTK images (.vti) of one region on other grids: the field was
    stretched over FILE's box whatever their spacing and origin said; it is
    now placed by them. FILE: a ball of radius 8 on a grid of 2 from -20; the
    field: the world x coordinate on FILE's grid and on a grid of 3 over a
    larger, shifted box: the values on the surface span the same range."""
    vtk = pytest.importorskip("vtk", reason="vtk is in the test extra")
    from vtk.util import numpy_support

    def image(name, shape, step, origin, values):
        nz, ny, nx = shape
        z, y, x = np.meshgrid(
            *(o + step * np.arange(n) for o, n in zip(origin[::-1], shape, strict=True)), indexing="ij"
        )
        img = vtk.vtkImageData()
        img.SetDimensions(nx, ny, nz)
        img.SetSpacing(step, step, step)
        img.SetOrigin(*origin)
        a = numpy_support.numpy_to_vtk(values(x, y, z).astype(np.float32).ravel(), deep=True)
        a.SetName("v")
        img.GetPointData().SetScalars(a)
        w = vtk.vtkXMLImageDataWriter()
        w.SetFileName(str(tmp_path / name))
        w.SetInputData(img)
        assert w.Write() == 1
        return str(tmp_path / name)

    volume = image(
        "ball.vti", (21, 21, 21), 2.0, (-20.0, -20.0, -20.0), lambda x, y, z: np.sqrt(x**2 + y**2 + z**2)
    )
    ranges = {}
    for name, shape, step, origin in (
        ("same.vti", (21, 21, 21), 2.0, (-20.0, -20.0, -20.0)),
        ("coarse.vti", (20, 19, 22), 3.0, (-31.0, -26.0, -29.0)),
    ):
        field = image(name, shape, step, origin, lambda x, y, z: x)
        rc, out, err = _run(
            capsys, volume, "--isovalue", "8", "--rate", "32", "--color-by", field,
            "--size", f"{W}x{H}", "--out", str(tmp_path / ("out-" + name)),
        )  # fmt: skip
        assert rc == 0, err
        assert "placed by the files' affines (a VTK image's spacing and origin)" in out, out
        line = next(ln for ln in out.splitlines() if ln.strip().startswith("colour"))
        ranges[name] = tuple(float(v) for v in line.rsplit("range ", 1)[1].split(".."))
    assert ranges["same.vti"][1] - ranges["same.vti"][0] > 8, ranges
    np.testing.assert_allclose(ranges["coarse.vti"], ranges["same.vti"], atol=0.05)
    # a scan beside a VTK image: a scanner's RAS world and the image's own frame are not one
    # world (they were placed by both as if they were): laid as files without one are
    nibabel = pytest.importorskip("nibabel")
    ball = np.sqrt(sum(g**2 for g in np.meshgrid(*[np.arange(21) * 2.0 - 20] * 3, indexing="ij")))
    nibabel.save(
        nibabel.Nifti1Image(ball.astype(np.float32), np.diag([2.0, 2.0, 2.0, 1.0])), tmp_path / "b.nii"
    )
    rc, out, err = _run(
        capsys, str(tmp_path / "b.nii"), "--isovalue", "8", "--color-by", str(tmp_path / "same.vti"),
        "--size", f"{W}x{H}", "--out", str(tmp_path / "mixed"),
    )  # fmt: skip
    assert rc == 0, err
    assert "the field on the same grid" in out, out


def test_color_by_a_scan_whose_affine_is_singular_is_laid_as_one_without(tmp_path, capsys):
    """A field whose header's sform is all zeros (a broken file nibabel still
    reads) cannot be placed by its affine: numpy's LinAlgError ended the
    command with 'error: Singular matrix', naming neither file; the field is
    laid as a file without an affine is (the same grid here)."""
    nibabel = pytest.importorskip("nibabel")
    import struct

    values = np.random.default_rng(2).random((10, 9, 8)).astype(np.float32)
    volume = tmp_path / "v.nii"
    nibabel.save(nibabel.Nifti1Image(values, np.diag([2.0, 2.0, 2.0, 1.0])), volume)
    img = nibabel.Nifti1Image(values, np.diag([2.0, 2.0, 2.0, 1.0]))
    img.header.set_sform(np.diag([2.0, 2.0, 2.0, 1.0]), code=2)
    field = tmp_path / "broken.nii"
    nibabel.save(img, field)
    raw = bytearray(field.read_bytes())
    raw[280:328] = struct.pack("<12f", *([0.0] * 12))  # srow_x, srow_y, srow_z: a singular sform
    field.write_bytes(bytes(raw))
    rc, out, err = _run(
        capsys, str(volume), "--isovalue", "0.5", "--color-by", str(field),
        "--size", f"{W}x{H}", "--out", str(tmp_path / "o"),
    )  # fmt: skip
    assert rc == 0, err
    assert "the field on the same grid" in out, out


def test_color_by_a_4d_series_picks_its_volume(tmp_path, capsys):
    """A 4-D --color-by file needs --color-by-volume-index (FILE's
    --volume-index is not the field's, and the error says which option)."""
    nibabel = pytest.importorskip("nibabel")
    series = tmp_path / "series.nii"
    field = np.random.default_rng(2).random((6, 7, 8, 3)).astype(np.float32)
    nibabel.save(nibabel.Nifti1Image(field, np.eye(4)), series)
    base = [UNIFORM, "--color-by", str(series), "--size", f"{W}x{H}", "--out", str(tmp_path)]
    rc, out, err = _run(capsys, *base)
    assert rc == 2 and "--color-by: " in err and "choose one: --color-by-volume-index T" in err, err
    rc, out, err = _run(capsys, *base, "--color-by-volume-index", "3")
    assert rc == 2 and "--color-by-volume-index: 3 is outside 0..2" in err, err
    rc, out, err = _run(capsys, *base, "--color-by-volume-index", "2")
    assert rc == 0, err
    rc, out, err = _run(capsys, UNIFORM, "--color-by-volume-index", "2", "--out", str(tmp_path))
    assert rc == 2 and "--color-by-volume-index picks a volume of a field: add --color-by" in err


def test_array_picks_the_vtk_array_and_the_summary_names_it(tmp_path, capsys):
    """clvis iso FILE.vti: the summary names the array read (the default, or
    --array's); --array on another format is refused."""
    from vtkmodules.util import numpy_support as ns
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

    img = vtkImageData()
    img.SetDimensions(12, 12, 12)
    z, y, x = np.mgrid[:12, :12, :12] / 11.0 * 2 - 1
    for name, v in (("r2", x**2 + y**2 + z**2), ("xcoord", x)):
        arr = ns.numpy_to_vtk(np.ascontiguousarray(v, np.float32).ravel(), deep=True)
        arr.SetName(name)
        img.GetPointData().AddArray(arr)
    w = vtkXMLImageDataWriter()
    path = tmp_path / "two.vti"
    w.SetFileName(str(path))
    w.SetInputData(img)
    assert w.Write() == 1
    base = ["--size", f"{W}x{H}", "--out", str(tmp_path / "o")]
    rc, out, err = _run(capsys, str(path), *base)
    assert rc == 0 and "two.vti (array r2)" in out, (out, err)
    rc, out, err = _run(capsys, str(path), "--array", "xcoord", *base)
    assert rc == 0 and "two.vti (array xcoord), isovalue 0," in out, (out, err)
    rc, out, err = _run(capsys, str(path), "--array", "nope", *base)
    assert rc == 2 and "no array 'nope' (point arrays: r2, xcoord)" in err
    np.save(tmp_path / "v.npy", np.zeros((4, 4, 4), np.float32))
    rc, out, err = _run(capsys, str(tmp_path / "v.npy"), "--array", "r2", *base)
    assert rc == 2 and "--array picks a data array of a VTK file" in err


def test_several_isovalues(tmp_path, capsys):
    """Two isovalues of x*y*z: two surfaces in their colours, the nearer in
    front, a legend under the image, each one's passes printed."""
    red, blue = (255, 0, 0), (0, 0, 255)
    rc, out, err = _run(
        capsys,
        UNIFORM,
        "--isovalue",
        "30,300",
        "--surface-color",
        "255,0,0",
        "--surface-color",
        "blue",
        "--size",
        f"{W}x{H}",
        "--out",
        str(tmp_path),
    )
    assert rc == 0, err
    assert "isovalues 30, 300" in out and out.count("  passes  ") == 2 and out.count("  isovalue    ") == 2
    a = _png(tmp_path / "iso.png")
    lab = images.label_height(W)
    assert a.shape[0] > H + lab  # the legend
    img = a[lab : lab + H]
    reddish = (img[..., 0] > 2 * img[..., 2] + 20) & (img[..., 0] > 40)
    bluish = (img[..., 2] > 2 * img[..., 0] + 20) & (img[..., 2] > 40)
    assert reddish.sum() > 20 and bluish.sum() > 20, (reddish.sum(), bluish.sum())
    legend = a[lab + H :]
    for c in (red, blue):
        assert (np.abs(legend - c).sum(axis=2) == 0).any()  # each swatch


def test_constant_volume_warns_and_draws_nothing(tmp_path, capsys):
    np.save(tmp_path / "c.npy", np.full((8, 9, 10), 3.0, np.float32))
    for iso in ("3", "1"):
        rc, out, err = _run(
            capsys,
            str(tmp_path / "c.npy"),
            "--isovalue",
            iso,
            "--size",
            f"{W}x{H}",
            "--out",
            str(tmp_path / iso),
        )
        assert rc == 0, err
        assert "warning: the volume is constant (3)" in err and "nothing rendered" in out
        a = _png(tmp_path / iso / "iso.png")[images.label_height(W) :]
        assert not _surface(a).any()
    # --infill on it: nothing to fill (the image never went to the device),
    # no note about the stop, both pictures written and named
    rc, out, err = _run(
        capsys,
        str(tmp_path / "c.npy"),
        "--infill",
        "--completion",
        "0.3",
        "--size",
        f"{W}x{H}",
        "--out",
        str(tmp_path / "fill"),
    )
    assert rc == 0, err
    assert "warning: the volume is constant (3)" in err and "well past" not in err
    assert "iso-infill.png" in out
    for name in ("iso.png", "iso-infill.png"):
        assert not _surface(_png(tmp_path / "fill" / name)[images.label_height(W) :]).any()


@pytest.mark.parametrize("scale", [1e22, 1e-22])
def test_values_past_float32s_shading_range_warn(tmp_path, capsys, scale):
    z, y, x = np.mgrid[-1:1:12j, -1:1:12j, -1:1:12j]
    v = ((np.sqrt(x * x + y * y + z * z) - 0.6) * scale).astype(np.float32)
    np.save(tmp_path / "v.npy", v)
    rc, _, err = _run(
        capsys, str(tmp_path / "v.npy"), "--isovalue", "0", "--size", "32x24", "--out", str(tmp_path)
    )
    assert rc == 0 and "float32 gradients" in err and "scale the values" in err, err
    np.save(tmp_path / "ok.npy", (v / scale).astype(np.float32))
    rc, _, err = _run(
        capsys, str(tmp_path / "ok.npy"), "--isovalue", "0", "--size", "32x24", "--out", str(tmp_path)
    )
    assert rc == 0 and "float32" not in err


def test_isovalue_at_the_end_of_the_range_warns(tmp_path, capsys):
    v = np.zeros((12, 12, 12), np.float32)
    v[4:8, 4:8, 4:8] = 1.0
    np.save(tmp_path / "v.npy", v)
    rc, _, err = _run(
        capsys, str(tmp_path / "v.npy"), "--isovalue", "0", "--size", "32x24", "--out", str(tmp_path)
    )
    assert rc == 0 and "is the data's minimum" in err
    rc, _, err = _run(
        capsys, str(tmp_path / "v.npy"), "--isovalue", "1", "--size", "32x24", "--out", str(tmp_path)
    )
    assert rc == 0 and "is the data's maximum" in err
    rc, _, err = _run(
        capsys, str(tmp_path / "v.npy"), "--isovalue", "0.5", "--size", "32x24", "--out", str(tmp_path)
    )
    assert rc == 0 and "warning" not in err


def test_completion_stop_far_past_the_target_is_noted(tmp_path, capsys):
    """The README's turbulence example: with speculation the first passes
    finish far more than 85 % (a note says so); --no-speculation stops near it."""
    base = ["--dataset", "turbulence", "--completion", "0.85", "--size", "128x72", "--out", str(tmp_path)]
    rc, out, err = _run(capsys, *base)
    assert rc == 0
    done = float(out.split("completion ")[1].split(",")[0])
    assert done > 0.9 and "well past --completion 0.85" in err and "--no-speculation" in err
    rc, out, err = _run(capsys, *base, "--no-speculation")
    assert rc == 0 and "well past" not in err
    done = float(out.split("completion ")[1].split(",")[0])
    assert 0.85 <= done < 0.9, out


@pytest.mark.parametrize(
    "args,message",
    [
        (["--colormap", "gray"], "--colormap colours the surface by a field: add --color-by"),
        (["--range", "0,1"], "--range colours the surface by a field"),
        (["--color-by", "nope.npy"], "--color-by: nope.npy: no such file"),
        (["--isovalue", "0.3,0.3"], "distinct"),
        (["--isovalue", "0.3,x"], "--isovalue"),
        (["--isovalue", "0.3,0.6", "--surface-color", "blue"], "once per isovalue"),
        (["--surface-color", "nocolour"], "--surface-color"),
        (["--isovalue", "0.3,0.6", "--completion", "0.8", "--infill"], "--infill: not with 2 isovalues"),
        (
            ["--surface-color", "blue", "--completion", "0.8", "--infill"],
            "--infill: not with --surface-color",
        ),
        (["--isovalue", "0.3,0.6", "--workers", "1"], "--isovalue: one value on workers"),
        # the in-fill network's options on workers (they were ignored: iso.png alone was written)
        (["--infill", "--workers", "1"], "--infill: the in-fill network fills the rays a one-device render"),
        (["--post", "infill", "--workers", "1"], "--infill: the in-fill network fills the rays"),
        (["--compare", "--workers", "1"], "--compare: the in-fill network fills the rays"),
        # clvis render's spelling: --post infill is --infill (it was read as --post-guard)
        (["--post", "infill"], "--infill fills the rays still running when the render stops"),
        (["--post", "lidar"], "argument --post: invalid choice: 'lidar'"),
    ],
)
def test_errors(tmp_path, capsys, args, message):
    rc, _, err = _run(capsys, *args, "--size", "16x16", "--out", str(tmp_path))
    assert rc == 2 and message in err, err
    assert len(err.strip().splitlines()) == 1
