"""clvis iso on the embedded volumes and on files, and its errors."""

import numpy as np
import pytest
from PIL import Image

from clvis import cli, datasets, images


@pytest.mark.parametrize("dataset", ["marschner-lobb", "turbulence"])
def test_iso_embedded(tmp_path, capsys, dataset):
    assert cli.main(["iso", "--dataset", dataset, "--size", "64x48", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "passes" in out and "blocks" in out and "completion 1.000" in out
    with Image.open(tmp_path / "iso.png") as im:
        assert im.size == (64, 48 + images.label_height(64)) and np.asarray(im).std() > 1


def test_iso_partial_marks_active_rays(tmp_path, capsys):
    assert (
        cli.main(
            [
                "iso",
                "--dataset",
                "turbulence",
                "--no-speculation",
                "--completion",
                "0.5",
                "--size",
                "64x48",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    with Image.open(tmp_path / "iso.png") as im:
        a = np.asarray(im)
    assert ((a[..., 0] == 255) & (a[..., 1] == 0) & (a[..., 2] == 255)).any()  # magenta: still running


def test_iso_files(tmp_path, capsys):
    v = datasets.marschner_lobb(20)["volume"]
    np.save(tmp_path / "v.npy", v)
    assert (
        cli.main(
            [
                "iso",
                str(tmp_path / "v.npy"),
                "--isovalue",
                "0.5",
                "--rate",
                "12",
                "--size",
                "40x30",
                "--out",
                str(tmp_path / "a"),
            ]
        )
        == 0
    )
    assert (tmp_path / "a" / "iso.png").is_file()
    (v * 255).astype(np.uint8).tofile(tmp_path / "ml_20x20x20_uint8.raw")
    assert (
        cli.main(
            ["iso", str(tmp_path / "ml_20x20x20_uint8.raw"), "--size", "40x30", "--out", str(tmp_path / "b")]
        )
        == 0
    )


@pytest.mark.parametrize(
    "args,message",
    [
        (["nope.raw"], "no such file"),
        (["--rate", "40"], "--rate"),
        (["--completion", "0"], "--completion"),
    ],
)
def test_iso_errors(tmp_path, capsys, args, message):
    assert cli.main(["iso", *args, "--size", "16x16", "--out", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("command", ["iso", "view"])
def test_volume_with_nan_samples_names_the_file(tmp_path, capsys, command):
    # a resampled NIfTI (nibabel's resampled_anat_moved.nii: NaN outside the
    # field of view) said "volume: 153 non-finite values ..." without the file
    if command == "view":
        pytest.importorskip("tornado", reason="the view extra (tornado) is not installed")
    v = datasets.marschner_lobb(12)["volume"].copy()
    v[0, 0, :3] = np.nan
    v[5, 6, 7] = np.inf
    path = tmp_path / "nan v.npy"
    np.save(path, v)
    args = ["--size", "16x16"] + (
        ["--out", str(tmp_path / "o")] if command == "iso" else ["--measure", "iso"]
    )
    assert cli.main([command, str(path), *args]) == 2
    err = capsys.readouterr().err
    assert (
        f"clvis {command}: error: {path}: 4 NaN or infinite samples, the first at [z, y, x] = (0, 0, 0): nan"
        in err
    )
    assert not (tmp_path / "o").exists()


def test_a_masked_scan_with_nan_outside_is_drawn(tmp_path, capsys):
    """NaN samples alone (a masked scan's outside, as SPM and nilearn write
    it; they were refused, so such a scan could not be drawn) are drawn as
    empty: set below every sample, said on stderr; the picture is that of
    the same volume with its outside at that value, the default isovalue
    Otsu's of the finite samples. clvis view draws it too."""
    pytest.importorskip("tornado", reason="the view extra (tornado) is not installed")
    z, y, x = np.mgrid[:24, :24, :24]
    r = np.sqrt((x - 11.5) ** 2 + (y - 11.5) ** 2 + (z - 11.5) ** 2)
    v = (2.0 + np.sin(x / 3.0) + np.cos(y / 4.0)).astype(np.float32)  # tissue: 0.1 .. 4
    v[r > 9] = np.nan  # the mask's outside
    np.save(tmp_path / "masked.npy", v)
    lo, hi = float(np.nanmin(v)), float(np.nanmax(v))
    np.save(tmp_path / "filled.npy", np.where(np.isnan(v), np.float32(lo - 1e-3 * (hi - lo)), v))
    from clvis.io.volumes import otsu_level

    iso = f"{otsu_level(v):.9g}"
    for name in ("masked", "filled"):
        argv = ["iso", str(tmp_path / f"{name}.npy"), "--size", "48x48", "--no-labels", "--isovalue", iso]
        assert cli.main([*argv, "--out", str(tmp_path / name)]) == 0
    err = capsys.readouterr().err
    assert (
        f"clvis iso: {tmp_path / 'masked.npy'}: {int(np.isnan(v).sum()):,} NaN samples (a mask's outside)"
        in err
    )
    with Image.open(tmp_path / "masked" / "iso.png") as a, Image.open(tmp_path / "filled" / "iso.png") as b:
        a, b = np.asarray(a), np.asarray(b)
    np.testing.assert_array_equal(a, b)
    assert (np.abs(a[..., :3].astype(int) - images.BACKGROUND).sum(axis=2) > 30).mean() > 0.2  # a ball drawn
    assert (
        cli.main(["iso", str(tmp_path / "masked.npy"), "--size", "32x32", "--out", str(tmp_path / "d")]) == 0
    )
    assert f"isovalue {otsu_level(v):.6g}" in capsys.readouterr().out  # Otsu's of the finite samples
    assert cli.main(["view", str(tmp_path / "masked.npy"), "--size", "32x32", "--measure", "iso"]) == 0
    assert "NaN samples (a mask's outside) drawn as empty" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["iso", "view"])
def test_a_single_slice_names_the_file_and_what_draws_it(tmp_path, capsys, command):
    if command == "view":
        pytest.importorskip("tornado", reason="the view extra (tornado) is not installed")
    path = tmp_path / "slice.npy"
    np.save(path, np.random.default_rng(0).random((1, 16, 16)).astype(np.float32))
    args = ["--size", "16x16"] + (
        ["--out", str(tmp_path / "o")] if command == "iso" else ["--measure", "iso"]
    )
    assert cli.main([command, str(path), *args]) == 2
    err = capsys.readouterr().err
    assert (
        f"clvis {command}: error: {path}: shape (1, 16, 16) (z, y, x): an isosurface lies between samples"
        in err
    )
    assert not (tmp_path / "o").exists()


def test_iso_bad_raw(tmp_path, capsys):
    (tmp_path / "x_4x4x4_uint8.raw").write_bytes(b"\0" * 10)
    assert cli.main(["iso", str(tmp_path / "x_4x4x4_uint8.raw"), "--out", str(tmp_path)]) == 2
    assert "x_4x4x4_uint8.raw" in capsys.readouterr().err


def test_iso_infill(tmp_path, capsys):
    """--infill: the image stays on the device for the network; iso.png (its
    colour, hit and active planes read back) is the plain render's."""
    args = ["iso", "--dataset", "turbulence", "--no-speculation", "--completion", "0.8", "--size", "64x48"]
    assert cli.main([*args, "--out", str(tmp_path / "plain")]) == 0
    assert cli.main([*args, "--infill", "--out", str(tmp_path / "net")]) == 0
    out = capsys.readouterr().out
    assert "in-fill" in out and "iso-infill.png" in out
    with Image.open(tmp_path / "plain" / "iso.png") as a, Image.open(tmp_path / "net" / "iso.png") as b:
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    with Image.open(tmp_path / "net" / "iso-infill.png") as im:
        a = np.asarray(im)
    assert a.shape[1] == 64 and a.std() > 1
    assert not ((a[..., 0] == 255) & (a[..., 1] == 0) & (a[..., 2] == 255)).any()  # no magenta left
    # clvis render's spelling, --post infill, is --infill (argparse read it as --post-guard)
    assert cli.main([*args, "--post", "infill", "--out", str(tmp_path / "post")]) == 0
    with Image.open(tmp_path / "post" / "iso-infill.png") as im:
        np.testing.assert_array_equal(np.asarray(im), a)
    # --post-guard: the network checked against push-pull and the partial
    # image (clvis.post.guard); the finished rays' pixels stay the network's
    assert cli.main([*args, "--infill", "--post-guard", "--no-labels", "--out", str(tmp_path / "g")]) == 0
    assert cli.main([*args, "--infill", "--no-post-guard", "--no-labels", "--out", str(tmp_path / "n")]) == 0
    with (
        Image.open(tmp_path / "g" / "iso-infill.png") as g,
        Image.open(tmp_path / "n" / "iso-infill.png") as n,
    ):
        g, n = np.asarray(g), np.asarray(n)
    assert g.shape == n.shape and (g == n).all(axis=-1).mean() > 0.8
    assert cli.main([*args, "--post-guard", "--out", str(tmp_path / "x")]) == 2
    assert "--post-guard guards the in-fill network: add --infill" in capsys.readouterr().err


def test_iso_infill_compare(tmp_path, capsys):
    """--compare: the view rendered to completion (iso-complete.png, no rays
    left running) and the network, push-pull and the partial image scored
    against it; the fills recover most of what the partial image lacks."""
    args = ["iso", "--dataset", "turbulence", "--no-speculation", "--completion", "0.8", "--size", "96x64"]
    assert cli.main([*args, "--infill", "--compare", "--no-labels", "--out", str(tmp_path / "c")]) == 0
    out = capsys.readouterr().out
    assert "against the complete render (completion 1.000" in out and "iso-complete.png" in out
    got = {
        line.split()[0]: tuple(float(v) for v in line.split()[1::2])
        for line in out.splitlines()
        if line.strip().split(" ")[0] in ("network", "push-pull", "partial")
    }
    assert set(got) == {"network", "push-pull", "partial"}
    for name in ("network", "push-pull"):
        psnr, ssim = got[name]
        assert psnr > got["partial"][0] + 3 and 0 < ssim <= 1, (name, got)
    with Image.open(tmp_path / "c" / "iso-complete.png") as im:
        a = np.asarray(im)
    assert a.shape[:2] == (64, 96) and a.std() > 1
    assert not ((a[..., 0] == 255) & (a[..., 1] == 0) & (a[..., 2] == 255)).any()  # every ray finished
    assert cli.main([*args, "--compare", "--out", str(tmp_path / "x")]) == 2
    assert "--compare scores the in-fill network against the complete render: add --infill" in (
        capsys.readouterr().err
    )
    assert cli.main([*args, "--infill", "--compare", "--orbit", "2", "--out", str(tmp_path / "x")]) == 2
    assert "--compare scores one view" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_the_fit_view_frames_the_surface_not_the_volume(tmp_path, capsys):
    """A small sphere in a corner of its volume fills the fit view's picture
    (the view frames the voxels the surface passes, not the volume's box)."""
    z, y, x = np.mgrid[0:64, 0:64, 0:64].astype(np.float32)
    vol = np.sqrt((z - 8) ** 2 + (y - 9) ** 2 + (x - 10) ** 2)  # distance to a point near a corner
    np.save(tmp_path / "ball.npy", vol)
    rc = cli.main(
        [
            "iso",
            str(tmp_path / "ball.npy"),
            "--isovalue",
            "5",
            "--size",
            "160x120",
            "--no-labels",
            "--quiet",
            "--out",
            str(tmp_path / "o"),
        ]
    )
    capsys.readouterr()
    assert rc == 0
    rgba = np.asarray(Image.open(tmp_path / "o" / "iso.png"))
    drawn = (rgba[..., :3].astype(int) - rgba[0, 0, :3]).any(axis=2)
    assert drawn.mean() > 0.2, drawn.mean()  # the ball's box seen whole: a quarter or more of the frame
    rows, cols = np.flatnonzero(drawn.any(axis=1)), np.flatnonzero(drawn.any(axis=0))
    # and about the middle of the picture
    assert abs((rows[0] + rows[-1]) / 2 - 60) < 15 and abs((cols[0] + cols[-1]) / 2 - 80) < 20


def test_iso_infill_reads_a_model_dir(tmp_path, capsys):
    """--model-dir: a `clvis train --out` folder's in-fill model, not the
    shipped one (the CLI had no way to run a retrained network)."""
    import shutil

    from clvis.post.infer import MODELS

    mine = tmp_path / "mine"
    mine.mkdir()
    for f in MODELS.glob("infill.*"):
        shutil.copy(f, mine / f.name)
    args = ["iso", "--dataset", "turbulence", "--no-speculation", "--completion", "0.8", "--size", "64x48"]
    assert cli.main([*args, "--infill", "--model-dir", str(mine), "--out", str(tmp_path / "a")]) == 0
    assert cli.main([*args, "--infill", "--out", str(tmp_path / "b")]) == 0
    with (
        Image.open(tmp_path / "a" / "iso-infill.png") as a,
        Image.open(tmp_path / "b" / "iso-infill.png") as b,
    ):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    capsys.readouterr()
    for f in MODELS.glob("lidar.*"):  # another network's model where infill's was
        shutil.copy(f, mine / f.name.replace("lidar", "infill", 1))
    assert cli.main([*args, "--infill", "--model-dir", str(mine), "--out", str(tmp_path / "c")]) == 2
    assert f"{mine / 'infill.json'}: the model card is for 'lidar', not 'infill'" in capsys.readouterr().err
    assert cli.main([*args, "--model-dir", str(mine), "--out", str(tmp_path / "d")]) == 2
    assert "--model-dir: where the in-fill network's model is: add --infill" in capsys.readouterr().err


def test_iso_of_an_openvdb_grid(tmp_path, capsys):
    """clvis iso FILE.vdb [--grid]: the grid made dense (read_vdb_volume),
    a level set's default isovalue 0 (its surface, seen from outside over
    the background filled in as its outside), a fog's Otsu's; the options of
    other files, --grid with them and workers are one line each."""
    from pathlib import Path

    vdb = str(Path(__file__).resolve().parents[1] / "data" / "openvdb_small.vdb")
    assert cli.main(["iso", vdb, "--size", "64x64", "--no-labels", "-o", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert "openvdb_small.vdb (grid 'surface', a level set), isovalue 0," in out
    hit = np.asarray(Image.open(tmp_path / "s" / "iso.png").convert("RGB")).astype(float)
    drawn = (np.abs(hit - images.BACKGROUND).sum(axis=2) > 30).mean()
    assert 0.2 < drawn < 0.9, drawn  # a sphere in the frame, not a box of the background fill
    assert cli.main(["iso", vdb, "--grid", "density", "--size", "48x48", "-o", str(tmp_path / "d")]) == 0
    assert "(grid 'density'), isovalue 0." in capsys.readouterr().out  # Otsu's, of a fog ball 0..1
    for argv, msg in [
        ([vdb, "--shape", "4x4x4"], "--shape: not for a .vdb"),
        ([vdb, "--workers", "1"], "a .vdb is read and made dense on one device"),
        ([vdb, "--grid", "nope"], "no grid named 'nope'"),
    ]:
        assert cli.main(["iso", *argv, "-o", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert msg in err and len(err.strip().splitlines()) == 1, err
    assert cli.main(["iso", "--grid", "a", "-o", str(tmp_path / "x")]) == 2
    assert "--grid picks a grid of a .vdb FILE" in capsys.readouterr().err


def test_iso_file_help_names_the_vdb_it_reads(capsys):
    """clvis iso reads an OpenVDB grid (README: clvis iso smoke.vdb --grid
    density), but its FILE help and description named every volume format
    but .vdb: they name it now."""
    assert cli.main(["iso", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    usage = text.split("positional arguments:")[1].split("options:")[0]
    assert ".vdb" in usage
    assert "OpenVDB float grid (.vdb" in text.split("positional arguments:")[0]


def test_an_earlier_runs_infill_left_in_the_folder_is_named(tmp_path, capsys):
    """A plain render into a folder where an --infill run wrote iso-infill.png:
    it stayed beside the new iso.png and read as this run's; a note names it."""
    base = ["iso", "--size", "64x48", "--out", str(tmp_path)]
    assert cli.main([*base, "--completion", "0.8", "--no-speculation", "--infill"]) == 0
    assert "earlier run" not in capsys.readouterr().err
    assert cli.main(base) == 0
    err = capsys.readouterr().err
    assert f"clvis iso: note: {tmp_path} also holds iso-infill.png from an earlier run" in err


def test_a_scan_in_ras_order_is_seen_from_the_front(tmp_path, monkeypatch, capsys):
    """A NIfTI scan is read in RAS+ order (+y anterior): the default view and
    --view front looked along +y, at the back of the head. They now look at
    its face (the default view's y reversed, front along -y), in clvis iso,
    clvis gauss and the viewer's first view; the same samples as a .npy (no
    anatomy known) keep the generic views."""
    nibabel = pytest.importorskip("nibabel")
    import clvis
    from clvis.cli import _common
    from clvis.cli import iso as iso_cmd

    i, j, k = np.mgrid[:24, :24, :24].astype(np.float32) - 11.5
    head = ((i / 8) ** 2 + (j / 10) ** 2 + (k / 11) ** 2 < 1).astype(np.float32) * 100
    nibabel.save(nibabel.Nifti1Image(head, np.diag([2.0, 2.0, 2.0, 1.0])), tmp_path / "head.nii")
    np.save(tmp_path / "head.npy", np.ascontiguousarray(head.transpose(2, 1, 0)))  # [z, y, x]
    seen = []
    real = _common.camera_from_args

    def spy(args, lo, hi, *a, **kw):
        cam = real(args, lo, hi, *a, **kw)
        seen.append(float(cam.eye[1] - 0.5 * (lo[1] + hi[1])))  # the eye's side along y
        return cam

    monkeypatch.setattr(iso_cmd, "camera_from_args", spy)
    for name, view in [(f, v) for f in ("head.nii", "head.npy") for v in ([], ["--view", "front"])]:
        argv = ["iso", str(tmp_path / name), "--isovalue", "50", "--size", "32x32", *view]
        assert cli.main([*argv, "--out", str(tmp_path / "o")]) == 0, capsys.readouterr().err
    assert seen[0] > 0 and seen[1] > 0  # the scan: from the front (anterior, +y)
    assert seen[2] < 0 and seen[3] < 0  # an array: from -y, as before
    pytest.importorskip("distributed", reason="the distributed extra is not installed")
    argv = ["iso", str(tmp_path / "head.nii"), "--isovalue", "50", "--size", "32x32", "--workers", "1"]
    assert cli.main([*argv, "--out", str(tmp_path / "w")]) == 0, capsys.readouterr().err
    assert seen[4] > 0  # on workers too (they read it in RAS+ order as well)
    scene = clvis.view.scene_for(clvis.read_volume(tmp_path / "head.nii"))  # the viewer: its face first
    assert scene.home_azimuth == 115.0
    assert clvis.view.scene_for(np.load(tmp_path / "head.npy")).home_azimuth == -115.0
