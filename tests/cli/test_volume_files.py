"""The volume-file options iso and gauss share (--spacing, --shape, --dtype,
--volume-index), the default isovalue of a scan, and the formats gauss reads,
on nibabel's bundled NIfTI files and on generated ones."""

import gzip
import os
import warnings

import numpy as np
import pytest
from PIL import Image

from clvis import cli, datasets

nibabel = pytest.importorskip("nibabel")
NIB = os.path.join(os.path.dirname(nibabel.__file__), "tests", "data")
DATA = os.path.join(os.path.dirname(__file__), "..", "data")


def _png(path):
    with Image.open(path) as im:
        return np.asarray(im)


def test_iso_default_isovalue_shows_a_scan(tmp_path, capsys):
    """nibabel's anatomical.nii (a real MRI): Otsu's threshold shows a surface
    over a large part of the frame, where the middle of the range gives blobs."""
    assert (
        cli.main(["iso", os.path.join(NIB, "anatomical.nii"), "--size", "96x72", "--out", str(tmp_path)]) == 0
    )
    out = capsys.readouterr().out
    a = _png(tmp_path / "iso.png")[-72:]  # under the label band
    surface = (np.abs(a[..., :3].astype(int) - [20, 20, 26]).sum(axis=2) > 30).mean()
    assert surface > 0.15, (surface, out)


def test_iso_four_d_nifti_needs_an_index(tmp_path, capsys):
    f = os.path.join(NIB, "example4d.nii.gz")
    assert cli.main(["iso", f, "--size", "40x30", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "4-D" in err and "--volume-index" in err and len(err.strip().splitlines()) == 1
    assert cli.main(["iso", f, "--volume-index", "1", "--size", "40x30", "--out", str(tmp_path)]) == 0
    assert cli.main(["iso", f, "--volume-index", "2", "--size", "40x30", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "outside 0..1" in err and "--volume-index" in err


def test_iso_of_compressed_and_mixed_case_analyze_pairs(tmp_path, capsys):
    """clvis iso reads a .hdr.gz/.img.gz pair and a pair in mixed case
    (scan.Hdr with SCAN.IMG) as read_volume does; a missing half is one
    line naming it; clvis render says such a pair is a volume."""
    v = datasets.marschner_lobb(20)["volume"].astype(np.float32)
    nibabel.save(nibabel.AnalyzeImage(v.transpose(2, 1, 0), np.eye(4)), tmp_path / "ml.hdr.gz")
    (tmp_path / "scan.Hdr").write_bytes(gzip.decompress((tmp_path / "ml.hdr.gz").read_bytes()))
    (tmp_path / "SCAN.IMG").write_bytes(gzip.decompress((tmp_path / "ml.img.gz").read_bytes()))
    for name in ("ml.hdr.gz", "ml.img.gz", "scan.Hdr", "SCAN.IMG"):
        out = tmp_path / name.replace(".", "-")
        args = ["iso", str(tmp_path / name), "--isovalue", "0.5", "--size", "40x30", "--out", str(out)]
        assert cli.main(args) == 0, capsys.readouterr().err
        assert _png(out / "iso.png").std() > 1
    assert cli.main(["render", str(tmp_path / "ml.hdr.gz")]) == 2
    assert "a volume file (.hdr.gz), not a point cloud" in capsys.readouterr().err
    (tmp_path / "SCAN.IMG").unlink()
    assert cli.main(["iso", str(tmp_path / "scan.Hdr"), "--size", "40x30", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "scan.Hdr: an Analyze header; its data file scan.img is missing" in err
    assert len(err.strip().splitlines()) == 1


def test_raw_shape_dtype_and_spacing(tmp_path, capsys):
    v = datasets.marschner_lobb(20)["volume"].astype(np.float32)
    raw = tmp_path / "blob.raw"  # no shape or type in the name
    v.tofile(raw)
    assert cli.main(["iso", str(raw), "--size", "32x24", "--out", str(tmp_path)]) == 2
    assert "blob.raw" in capsys.readouterr().err
    args = [
        "iso",
        str(raw),
        "--shape",
        "20x20x20",
        "--dtype",
        "float32",
        "--isovalue",
        "0.5",
        "--size",
        "32x24",
        "--out",
        str(tmp_path),
    ]
    assert cli.main(args) == 0
    capsys.readouterr()
    assert cli.main(args + ["--spacing", "1,1,4"]) == 0
    assert cli.main(["iso", str(raw), "--shape", "20x20", "--size", "32x24"]) == 2
    assert "XxYxZ" in capsys.readouterr().err
    assert cli.main(["iso", "--spacing", "1,0,1", "--size", "32x24"]) == 2
    assert "positive" in capsys.readouterr().err
    np.save(tmp_path / "v.npy", v)
    assert cli.main(["iso", str(tmp_path / "v.npy"), "--shape", "20x20x20", "--size", "32x24"]) == 2
    assert "for .raw files" in capsys.readouterr().err


def test_iso_isovalue_outside_range_warns(tmp_path, capsys):
    assert cli.main(["iso", "--isovalue", "7", "--size", "32x24", "--out", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert "outside the data range" in err and "[" in err


def test_all_nan_volume_is_one_clvis_error(tmp_path, capsys):
    np.save(tmp_path / "nan.npy", np.full((8, 8, 8), np.nan, np.float32))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy RuntimeWarning before the error
        assert cli.main(["iso", str(tmp_path / "nan.npy"), "--size", "32x24"]) == 2
    err = capsys.readouterr().err
    assert "no finite sample" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("kind", ["nifti", "raw", "npy-volume", "npy-points", "laz", "ply"])
def test_gauss_reads_every_format(tmp_path, capsys, kind):
    v = datasets.marschner_lobb(16)["volume"].astype(np.float32)
    if kind == "nifti":
        path, extra = os.path.join(NIB, "anatomical.nii"), ["--threshold", "3000"]
    elif kind == "raw":
        path, extra = str(tmp_path / "m_16x16x16_float32.raw"), ["--threshold", "0.5"]
        v.tofile(path)
    elif kind == "npy-volume":
        path, extra = str(tmp_path / "v.npy"), ["--threshold", "0.5"]
        np.save(path, v)
    elif kind == "npy-points":
        path, extra = str(tmp_path / "p.npy"), []
        np.save(path, np.random.default_rng(0).normal(size=(300, 3)).astype(np.float32))
    elif kind == "laz":
        path, extra = os.path.join(DATA, "laspy_simple.laz"), []
    else:
        path, extra = os.path.join(DATA, "pyvista_ant.ply"), []
    lod = ["--lod", "low"] if kind not in ("npy-points", "laz", "ply") else []  # points: no LODs
    assert cli.main(["gauss", path, *lod, "--size", "48x48", "--out", str(tmp_path / "o"), *extra]) == 0, (
        capsys.readouterr().err
    )
    assert _png(tmp_path / "o" / "gauss.png").std() > 1


@pytest.mark.parametrize(
    "name", ["cloud-zlib.vtp", "cloud-ascii.vtk", "cloud-appended64.vtu", "cloud-binary.vts"]
)
def test_gauss_and_iso_of_vtk_point_sets(tmp_path, capsys, name):
    """gauss makes a Gaussian a point of a .vtp, .vtu, .vts or a POLYDATA .vtk; iso,
    which reads volumes, says which commands read one (it said "only
    DATASET STRUCTURED_POINTS is a volume", and render "a volume file")."""
    pytest.importorskip("vtk", reason="vtk is in the test extra")
    from fuzz.seeds import vtk_point_set

    path = tmp_path / name
    vtk_point_set(path, 300, name.split("-")[1].split(".")[0])
    assert cli.main(["gauss", str(path), "--size", "48x48", "--out", str(tmp_path / "o")]) == 0, (
        capsys.readouterr().err
    )
    assert _png(tmp_path / "o" / "gauss.png").std() > 1
    assert cli.main(["iso", str(path), "--size", "48x48", "--out", str(tmp_path / "i")]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "clvis render, clvis gauss and clvis view read it" in err


def test_gauss_unknown_format_lists_formats(tmp_path, capsys):
    # (.txt is a point cloud to clvis gauss, as to clvis render: a suffix no reader has)
    f = tmp_path / "x.dat"
    f.write_text("hello")
    assert cli.main(["gauss", str(f)]) == 2
    err = capsys.readouterr().err
    for ext in (".vdb", ".raw", ".npy", ".nii", ".nii.gz", ".npz", ".ply", ".las", ".laz", ".pcd", ".txt"):
        assert ext in err
