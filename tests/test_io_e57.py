"""The .e57 reader (clvis.io.e57, through pye57): scans joined in the file's
coordinates, colours and intensity, invalid points left out, the header's
point counts checked against the file's size, clean errors, and the extra
named when pye57 is missing. `clvis render` on an E57 file through main()."""

import sys

import numpy as np
import pytest

import clvis
from clvis import cli
from clvis.errors import DataError

pye57 = pytest.importorskip("pye57", reason="the e57 extra (pye57) is in the test extra")
RGB = ("colorRed", "colorGreen", "colorBlue")


def _write(path, scans):
    f = pye57.E57(str(path), mode="w")
    for s in scans:
        f.write_scan_raw(s)
    f.close()
    return path


def _scan(n, seed, x0=631_000.0, colours=True):
    rng = np.random.default_rng(seed)
    s = {
        "cartesianX": x0 + rng.random(n) * 50,
        "cartesianY": 4_830_000.0 + rng.random(n) * 40,
        "cartesianZ": 120.0 + rng.random(n) * 5,
        "intensity": rng.random(n).astype(np.float32),
    }
    if colours:
        s.update({k: rng.integers(0, 256, n).astype(np.uint8) for k in RGB})
    return s


def test_scans_join_in_the_files_coordinates(tmp_path):
    a, b = _scan(500, 1), _scan(300, 2, x0=631_100.0)
    path = _write(tmp_path / "two.e57", [a, b])
    c = clvis.read_points(path)
    assert len(c) == 800 and c.colors is not None and "intensity" in c.attributes
    world = c.positions.astype(np.float64) + c.origin
    want = np.stack(
        [np.concatenate([a[k], b[k]]) for k in ("cartesianX", "cartesianY", "cartesianZ")], axis=1
    )
    np.testing.assert_allclose(world, want, atol=0.02)  # float32 relative to the origin: cm
    assert c.origin[0] > 630_000  # the offset is kept, positions stay small
    np.testing.assert_array_equal(c.colors[:500, 0], a["colorRed"])
    np.testing.assert_allclose(c.attributes["intensity"][500:], b["intensity"])


def test_invalid_points_are_left_out_and_colours_optional(tmp_path):
    s = _scan(100, 3, colours=False)
    s["cartesianInvalidState"] = (np.arange(100) % 10 == 0).astype(np.int8)
    c = clvis.read_points(_write(tmp_path / "inv.e57", [s]))
    assert len(c) == 90 and c.colors is None


def test_bad_files_are_clean_errors(tmp_path):
    junk = tmp_path / "junk.e57"
    junk.write_bytes(b"ASTM-E57" + bytes(2000))
    with pytest.raises(DataError, match="junk.e57: not a readable E57 file"):
        clvis.read_points(junk)
    good = _write(tmp_path / "good.e57", [_scan(200, 4)]).read_bytes()
    cut = tmp_path / "cut.e57"
    cut.write_bytes(good[: len(good) // 2])
    with pytest.raises(DataError, match="cut.e57"):
        clvis.read_points(cut)


def test_a_header_declaring_more_points_than_the_file_holds(tmp_path, monkeypatch):
    from clvis.io import e57

    path = _write(tmp_path / "few.e57", [_scan(50, 5)])
    monkeypatch.setattr(e57, "MAX_POINTS_PER_BYTE", 50 / path.stat().st_size / 2)
    with pytest.raises(DataError, match="declares 50 points in a file of"):
        clvis.read_points(path)


def test_missing_pye57_names_the_extra(tmp_path, monkeypatch):
    path = _write(tmp_path / "a.e57", [_scan(20, 6)])
    monkeypatch.setitem(sys.modules, "pye57", None)
    with pytest.raises(ImportError, match=r'pip install "\.\[e57\]"'):
        clvis.read_points(path)


def test_clvis_render_reads_e57(tmp_path, capsys):
    path = _write(tmp_path / "scan.e57", [_scan(2000, 7)])
    rc = cli.main(["render", str(path), "--size", "96x64", "--quiet", "--out", str(tmp_path / "o")])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert "2,000 points, its colors" in out and "(the file's coordinates)" in out
    junk = tmp_path / "bad.e57"
    junk.write_bytes(b"not an e57 file at all")
    rc = cli.main(["render", str(junk), "--out", str(tmp_path / "p")])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("clvis render: error: ") and "bad.e57" in err and err.count("\n") == 1
