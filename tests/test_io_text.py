"""The ASCII (.xyz/.txt/.csv) and PCD point cloud readers: what they read,
and a clear DataError naming the file for what they cannot."""

import sys

import numpy as np
import pytest

from clvis.errors import DataError
from clvis.io import read_points


def _write(path, text):
    path.write_text(text)
    return path


def test_xyz_no_header(tmp_path):
    c = read_points(_write(tmp_path / "a.xyz", "1 2 3\n4 5 6\n\n7 8 9.5\n"))
    np.testing.assert_allclose(c.positions + c.origin, [[1, 2, 3], [4, 5, 6], [7, 8, 9.5]])
    assert c.colors is None and not c.attributes
    c = read_points(_write(tmp_path / "b.txt", "1 2 3 0.5\n4 5 6 0.7\n"))
    np.testing.assert_allclose(c.attributes["intensity"], [0.5, 0.7])
    c = read_points(_write(tmp_path / "c.xyz", "1\t2\t3\t255\t0\t10\n4\t5\t6\t0\t128\t0\n"))
    np.testing.assert_array_equal(c.colors[:, :3], [[255, 0, 10], [0, 128, 0]])
    c = read_points(_write(tmp_path / "d.txt", "1 2 3 -1200 255 0 10\n4 5 6 -900 0 128 0\n"))  # PTS
    np.testing.assert_array_equal(c.attributes["intensity"], [-1200, -900])
    assert c.colors is not None
    c = read_points(_write(tmp_path / "e.txt", "1 2 3 0.1 0.2 0.3 0.4 0.5\n"))
    assert list(c.attributes) == [f"column_{k}" for k in range(4, 9)]


def test_csv_with_header_and_utm_coordinates(tmp_path):
    text = (
        "X,Y,Z,Red,Green,Blue,Classification\n"
        "636001.76,848935.20,406.26,10,20,30,2\n"
        "636002.01,848936.00,407.00,40,50,60,5\n"
    )
    c = read_points(_write(tmp_path / "a.csv", text))
    np.testing.assert_allclose(c.origin, [636001.76, 848935.20, 406.26])
    np.testing.assert_allclose(c.positions[1], [0.25, 0.8, 0.74], atol=1e-5)  # float32 keeps the centimetres
    np.testing.assert_array_equal(c.colors[:, :3], [[10, 20, 30], [40, 50, 60]])
    np.testing.assert_array_equal(c.attributes["classification"], [2, 5])
    # CloudCompare's commented header, semicolons
    c = read_points(_write(tmp_path / "b.txt", "//X;Y;Z;R;G;B\n1;2;3;1;2;3\n"))
    np.testing.assert_array_equal(c.colors[0, :3], [1, 2, 3])
    # comments, and colours as fractions
    c = read_points(_write(tmp_path / "c.xyz", "# a scan\nx y z r g b\n0 0 0 0.5 1 0.25\n"))
    np.testing.assert_array_equal(c.colors[0, :3], [128, 255, 64])


def test_comment_markers_among_the_points(tmp_path):
    """'#', '//' and '%' comments between the points (and after them on a
    line) are skipped; a file whose points hold none is parsed with '#'
    alone, in numpy's C loop (three markers sent every line through Python:
    2.1 of 3.4 s of a 2 M-point .xyz), whatever its header or BOM held."""
    from clvis.io import ascii

    c = read_points(_write(tmp_path / "a.xyz", "1 2 3\n// a note\n4 5 6 % here\n% more\n7 8 9 # end\n"))
    np.testing.assert_allclose(c.positions + c.origin, [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    path = tmp_path / "b.txt"
    path.write_bytes(b"\xef\xbb\xbf// 100% scan\n//X Y Z\n1 2 3\n# a note\n4 5 6\n")
    np.testing.assert_allclose(read_points(path).positions, [[0, 0, 0], [3, 3, 3]])
    assert ascii._comments(path, len(b"\xef\xbb\xbf// 100% scan\n//X Y Z\n")) == "#"
    assert ascii._comments(path, 0) == ["#", "//", "%"]


@pytest.mark.parametrize(
    "name, text, message",
    [
        ("a.xyz", "", "no point in the file"),
        ("b.xyz", "# only a comment\n", "no point in the file"),
        ("c.xyz", "1 2\n3 4\n", "2 columns; a point needs x, y, z"),
        ("d.xyz", "1 2 3\n4 5 six\n", "line 2, column 3: expected a number, got 'six'"),
        (
            "e.xyz",
            "1 2 3\n4 5 6 7\n",
            r"line 2 holds 4 values, line 1 3: every point needs the same columns$",
        ),
        (  # numpy counts rows of values: the line said is the file's
            "e2.csv",
            "x,y,z\n1,2,3\n# a note\n\n4,5,6\n7,8\n",
            r"line 6 holds 2 values, line 2 3: every point needs the same columns$",
        ),
        (
            "e3.txt",
            "2\n1 2 3 0 1 2 3\n4 5 6 0 1 2 3\n",
            r"line 2 holds 7 values, line 1 1: .* \(a point count first, as a Leica .pts file holds",
        ),
        ("f.csv", "x,y,z,i\n1,2,3\n", "the header names 4 columns"),
        ("g.csv", "a,b,c\n1,2,3\n", "no x column"),
        ("h.csv", "x,y,z,x\n1,2,3,4\n", "names a column twice"),
        ("i.xyz", "x y z r g b\n1 2 3 300000 0 0\n", "colours must be finite numbers"),
        ("j.xyz", "\0\1\2 binary", "binary data"),
        ("k.pts", "3\n1 2 3\n4 5 6\n", "its first line declares 3 points; the file holds 2"),
        # numpy's row of values (0 first) past comments and blank lines: the file's line 6
        ("o.xyz", "x y z\n1 2 3\n# c\n\n# d\n4 abc 6\n", "line 6, column 2: expected a number, got 'abc'"),
        (
            "l.pts",
            "2\n1 2 3 0 1 2 3\n4 5 6 0 1 2 3\n1\n7 8 9 0 1 2 3\n",
            "line 4 holds one value: a PTS file of several",
        ),
        (
            "l2.pts",
            "2\n1 2 3\n4 5 6\n\n# scan 2\n1\n7 8 9\n",
            "line 6 holds one value: a PTS file of several",
        ),
        ("m.xyzn", "1 2 3 0 0 1 5\n", "7 columns; a .xyzn file holds x y z nx ny nz"),
        ("n.xyzrgb", "1 2 3 0.5 0.5\n", "5 columns; a .xyzrgb file holds x y z red green blue"),
    ],
)
def test_text_errors(tmp_path, name, text, message):
    """(.pts: its count line checked, and a second scan's count refused, not
    misread: it was a malformed-file error naming numpy's rows; .xyzn and
    .xyzrgb: their columns are their suffix's; a row of another column
    count named by its line in the file, not numpy's row of values, and
    without numpy's advice to "use `usecols`", a keyword clvis has not)"""
    path = _write(tmp_path / name, text)
    with pytest.raises(DataError, match=message) as e:
        read_points(path)
    assert str(path) in str(e.value) and "usecols" not in str(e.value)


def test_a_quoted_header_names_the_columns(tmp_path):
    """R's write.csv and spreadsheets quote a CSV's column names
    ("X","Y","Z",...): the header was read as a line of values and refused
    ('line 1: expected numbers')."""
    c = read_points(
        _write(tmp_path / "r.csv", '"X","Y","Z","Red","Green","Blue","Intensity"\n1,2,3,255,0,10,7\n')
    )
    np.testing.assert_allclose(c.positions + c.origin, [[1, 2, 3]])
    np.testing.assert_array_equal(c.colors[:, :3], [[255, 0, 10]])
    np.testing.assert_array_equal(c.attributes["intensity"], [7])
    c = read_points(_write(tmp_path / "s.txt", "'x' 'y' 'z' 'temperature'\n1 2 3 4\n"))
    np.testing.assert_array_equal(c.attributes["temperature"], [4])


def test_pts_xyzn_xyzrgb_by_their_suffix(tmp_path):
    """Leica's .pts (its point count first: it was read as a cloud of one
    column and refused) and Open3D's .xyzn and .xyzrgb (unknown suffixes):
    the columns their suffix names; colours in 0..1 or 0..255."""
    c = read_points(_write(tmp_path / "a.pts", "2\n1 2 3 -1200 255 0 10\n4 5 6 -900 0 128 0\n"))
    np.testing.assert_allclose(c.positions + c.origin, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(c.attributes["intensity"], [-1200, -900])
    np.testing.assert_array_equal(c.colors[:, :3], [[255, 0, 10], [0, 128, 0]])
    assert len(read_points(_write(tmp_path / "b.pts", "# scan 1\n1\n1 2 3\n"))) == 1
    c = read_points(_write(tmp_path / "c.xyzn", "1 2 3 0 0.6 0.8\n4 5 6 1 0 0\n"))
    assert c.colors is None and list(c.attributes) == ["nx", "ny", "nz"]
    np.testing.assert_allclose(c.attributes["ny"], [0.6, 0])
    c = read_points(_write(tmp_path / "d.xyzrgb", "1 2 3 1 0.5 0\n4 5 6 0 0 0.2\n"))
    np.testing.assert_array_equal(c.colors[:, :3], [[255, 128, 0], [0, 0, 51]])
    c = read_points(_write(tmp_path / "e.xyzrgb", "1 2 3 255 128 0\n"))
    np.testing.assert_array_equal(c.colors[:, :3], [[255, 128, 0]])
    # pure colours, as Open3D writes them (paint_uniform_color([1, 0, 0])): red, not near black
    c = read_points(_write(tmp_path / "f.xyzrgb", "1 2 3 1.0000000000 0.0000000000 0.0000000000\n"))
    np.testing.assert_array_equal(c.colors[:, :3], [[255, 0, 0]])


def _pcd_header(fields, sizes, types, n, data, counts=None):
    counts = counts or ["1"] * len(fields)
    return (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {' '.join(fields)}\nSIZE {' '.join(sizes)}\nTYPE {' '.join(types)}\n"
        f"COUNT {' '.join(counts)}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    ).encode()


def test_pcd_binary_rgb(tmp_path):
    rec = np.zeros(3, [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<f4"), ("intensity", "<f4")])
    rec["x"], rec["y"], rec["z"] = [1, 2, 3], [4, 5, 6], [7, 8, np.nan]
    packed = np.array([0xFF0000, 0x00FF00, 0x0000FF], np.uint32)
    rec["rgb"] = packed.view(np.float32)
    rec["intensity"] = [0.1, 0.2, 0.3]
    path = tmp_path / "a.pcd"
    path.write_bytes(
        _pcd_header(["x", "y", "z", "rgb", "intensity"], ["4"] * 5, ["F"] * 5, 3, "binary") + rec.tobytes()
    )
    c = read_points(path)
    np.testing.assert_array_equal(c.positions[:2], [[1, 4, 7], [2, 5, 8]])
    assert np.isnan(c.positions[2, 2])  # an organized cloud's hole, kept
    np.testing.assert_array_equal(c.colors[:, :3], [[255, 0, 0], [0, 255, 0], [0, 0, 255]])
    np.testing.assert_allclose(c.attributes["intensity"], [0.1, 0.2, 0.3])
    # truncated
    path.write_bytes(path.read_bytes()[:-4])
    with pytest.raises(DataError, match="truncated PCD file"):
        read_points(path)


def test_pcd_ascii(tmp_path):
    rgb = np.array([0x102030], np.uint32).view(np.float32)[0]
    body = f"1 2 3 {float(rgb):.9g} 0.5 0.25 1\n4 5 6 {0x405060} 0 0 0\n"  # packed float, packed integer
    path = tmp_path / "b.pcd"
    path.write_bytes(
        _pcd_header(
            ["x", "y", "z", "rgb", "h"],
            ["4", "4", "4", "4", "4"],
            ["F"] * 5,
            2,
            "ascii",
            ["1", "1", "1", "1", "3"],
        )
        + body.encode()
    )
    c = read_points(path)
    np.testing.assert_array_equal(c.positions, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(c.colors[:, :3], [[0x10, 0x20, 0x30], [0x40, 0x50, 0x60]])
    assert "h" not in c.attributes  # a 3-count field: skipped


def test_pcd_binary_compressed_and_pcl_ascii_rgb(tmp_path):
    """LZF-compressed data (pypcd4 writes it as PCL does), read back equal;
    and PCL's ascii rgb: a float field written as its packed uint32, alpha
    0xFF (above float32's exact integers), unpacked to the exact colour; a
    COUNT 3 field and '_' padding skipped."""
    pypcd4 = pytest.importorskip("pypcd4", reason="pypcd4 is in the test extra (the pcd extra)")
    rng = np.random.default_rng(3)
    xyz = rng.integers(0, 4, size=(500, 3)).astype(np.float32)  # compressible (pypcd4 writes
    rgb = rng.integers(0, 4, 500).astype(np.uint32) * 0x405060 | np.uint32(0xFF000000)  # binary else)
    pc = pypcd4.PointCloud.from_points(
        [xyz[:, 0], xyz[:, 1], xyz[:, 2], rgb.view(np.float32), xyz[:, 0] * 2],
        ("x", "y", "z", "rgb", "intensity"),
        (np.float32,) * 5,
    )
    path = tmp_path / "c.pcd"
    pc.save(path, encoding=pypcd4.Encoding.BINARY_COMPRESSED)
    assert b"DATA binary_compressed" in path.read_bytes()[:400]
    c = read_points(path)
    np.testing.assert_array_equal(c.positions + np.asarray(c.origin, np.float32), xyz)
    np.testing.assert_array_equal(c.colors[:, 0], (rgb >> 16) & 255)
    np.testing.assert_array_equal(c.colors[:, 2], rgb & 255)
    np.testing.assert_allclose(c.attributes["intensity"], xyz[:, 0] * 2)
    body = f"1 2 3 {0xFF102031} 7 8 9 0\n"  # how pcd_io.cpp writes an opaque rgb
    path = tmp_path / "pcl.pcd"
    path.write_bytes(
        _pcd_header(
            ["x", "y", "z", "rgb", "h", "_"], ["4"] * 6, ["F"] * 6, 1, "ascii", ["1"] * 4 + ["3", "1"]
        )
        + body.encode()
    )
    c = read_points(path)
    np.testing.assert_array_equal(c.colors[0, :3], [0x10, 0x20, 0x31])
    assert "h" not in c.attributes and "_" not in c.attributes


def test_missing_pypcd4_names_the_extra(tmp_path, monkeypatch):
    path = tmp_path / "a.pcd"
    path.write_bytes(_pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, 1, "ascii") + b"1 2 3\n")
    monkeypatch.setitem(sys.modules, "pypcd4", None)
    with pytest.raises(ImportError, match=r'pip install "clvis\[pcd\]"'):
        read_points(path)


@pytest.mark.parametrize(
    "head, body, message",
    [
        (b"VERSION 0.7\nFIELDS x y z\n", b"", "no DATA line"),
        (b"HELLO\n", b"", "not a PCD file"),
        (
            _pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, 2, "binary_compressed"),
            b"\0" * 40,
            "unpack to 0 bytes; 2 points of 12 bytes need 24",
        ),
        (  # a few bytes declaring 12 GB of points: refused before pypcd4 allocates
            _pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, 10**9, "binary_compressed"),
            np.array([8, 12 * 10**9 % 2**32], "<u4").tobytes() + b"\0" * 8,
            "unpack to",
        ),
        (
            _pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, 1000, "binary_compressed"),
            np.array([8, 12000], "<u4").tobytes() + b"\0" * 8,
            "truncated or malformed compressed PCD data",
        ),
        (
            _pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, 1, "binary_compressed"),
            np.array([4, 12], "<u4").tobytes() + b"\xff" * 4,
            "malformed PCD data",
        ),
        (b"VERSION 0.7\nVERSION 0.7\nDATA ascii\n", b"", "VERSION twice"),
        (b"VERSION 0.7\nFIELDS x\xff\nDATA ascii\n", b"", "not ASCII"),
        (
            _pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, 1, "binary").replace(b"WIDTH 1\n", b""),
            b"\0" * 12,
            "no WIDTH",
        ),
        (_pcd_header(["x", "y", "z"], ["4"] * 3, ["Q"] * 3, 1, "binary"), b"\0" * 12, "unsupported TYPE"),
        (_pcd_header(["x", "y", "z"], ["4", "4"], ["F"] * 3, 1, "binary"), b"\0" * 12, "differ in length"),
        (_pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, 10**12, "binary"), b"\0" * 12, "truncated PCD"),
        (
            _pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, 10**12, "ascii"),
            b"1 2 3\n",
            "more than the file",
        ),
        (
            _pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, 2, "ascii"),
            b"1 2 3\n",
            "1 rows of data; the header declares 2",
        ),
        (_pcd_header(["x", "y", "z"], ["4"] * 3, ["F"] * 3, 1, "ascii"), b"1 2 x\n", "malformed PCD data"),
        (_pcd_header(["a", "b", "c"], ["4"] * 3, ["F"] * 3, 1, "binary"), b"\0" * 12, "no x, y, z column"),
    ],
)
def test_pcd_errors(tmp_path, head, body, message):
    """Each a DataError naming the file; the sizes are checked before pypcd4
    reads."""
    path = tmp_path / "bad.pcd"
    path.write_bytes(head + body)
    with pytest.raises(DataError, match=message) as e:
        read_points(path)
    assert str(path) in str(e.value)
