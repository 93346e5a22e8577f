"""VTK point sets (.vtp PolyData, legacy .vtk POLYDATA / UNSTRUCTURED_GRID /
STRUCTURED_GRID) through read_points: files VTK's own writers make in each
mode, their points, colours, velocity and attributes; a DataError naming the
file, before VTK reads, for headers that lie about their sizes; and the
routing between read_points and read_volume by a .vtk's DATASET."""

import base64
import re

import numpy as np
import pytest

import clvis.io.polydata as polydata
from clvis.errors import DataError
from clvis.io import read_points, read_volume

vtk = pytest.importorskip("vtk", reason="vtk is in the test extra")
from vtk.util import numpy_support  # noqa: E402

N = 30
RNG = np.random.default_rng(37)
XYZ = RNG.normal(0, 10, (N, 3)) + [6.4e6, -3.2e6, 100.0]  # UTM-like: far from zero for float32
RGB = RNG.integers(0, 256, (N, 3)).astype(np.uint8)
TEMP = RNG.random(N).astype(np.float32)
VEL = RNG.normal(size=(N, 3)).astype(np.float32)
NORMALS = RNG.normal(size=(N, 3)).astype(np.float32)
IDS = np.arange(N, dtype=np.int32) * 3


def _array(values, name):
    a = numpy_support.numpy_to_vtk(np.ascontiguousarray(values), deep=True)
    a.SetName(name)
    return a


def _polydata():
    """N points far from zero, verts and two triangles, point arrays of each
    kind and a cell array (not read)."""
    pts = vtk.vtkPoints()
    pts.SetData(numpy_support.numpy_to_vtk(XYZ, deep=True))
    pd = vtk.vtkPolyData()
    pd.SetPoints(pts)
    verts = vtk.vtkCellArray()
    for i in range(N):
        verts.InsertNextCell(1, [i])
    polys = vtk.vtkCellArray()
    polys.InsertNextCell(3, [0, 1, 2])
    polys.InsertNextCell(3, [3, 4, 5])
    pd.SetVerts(verts)
    pd.SetPolys(polys)
    point_data = pd.GetPointData()
    point_data.SetScalars(_array(RGB, "RGB"))
    point_data.AddArray(_array(TEMP, "temperature"))
    point_data.AddArray(_array(VEL, "velocity"))
    point_data.SetNormals(_array(NORMALS, "Normals"))
    point_data.AddArray(_array(IDS, "id"))
    pd.GetCellData().AddArray(_array(np.arange(N + 2, dtype=np.float64), "cell"))
    return pd


def _check(cloud, legacy=False):
    assert len(cloud) == N
    np.testing.assert_allclose(cloud.origin, XYZ.min(axis=0))  # float64 kept
    np.testing.assert_allclose(cloud.origin + cloud.positions, XYZ, atol=1e-5)
    assert cloud.positions.dtype == np.float32
    np.testing.assert_array_equal(cloud.colors[:, :3], RGB)
    assert (cloud.colors[:, 3] == 255).all()
    np.testing.assert_array_equal(cloud.velocity, VEL)
    np.testing.assert_array_equal(cloud.attributes["temperature"], TEMP)
    np.testing.assert_array_equal(cloud.attributes["id"], IDS)
    for j, axis in enumerate("xyz"):
        np.testing.assert_array_equal(cloud.attributes[f"Normals_{axis}"], NORMALS[:, j])
    assert "cell" not in cloud.attributes and not any(k.startswith("RGB") for k in cloud.attributes)


@pytest.mark.parametrize(
    "mode, compressor, encode, header",
    [("Ascii", None, False, 32), ("Binary", None, False, 32), ("Binary", "ZLib", False, 64),
     ("Appended", None, False, 32), ("Appended", "ZLib", False, 32), ("Appended", "LZ4", True, 64),
     ("Appended", None, True, 64)],
)  # fmt: skip
def test_vtp_every_mode_vtks_writer_makes(tmp_path, mode, compressor, encode, header):
    path, text = _vtp(tmp_path, mode, compressor, encode, header)
    assert (b"compressor=" in text) == (compressor is not None)
    assert (b'<AppendedData encoding="base64"' in text) == (mode == "Appended" and encode)
    _check(read_points(path))


def test_vtp_of_several_pieces(tmp_path):
    path = tmp_path / "pieces.vtp"
    w = vtk.vtkXMLPolyDataWriter()
    w.SetFileName(str(path))
    w.SetInputData(_polydata())
    w.SetNumberOfPieces(3)
    w.SetDataModeToBinary()
    assert w.Write() == 1
    assert path.read_bytes().count(b"<Piece") == 3
    cloud = read_points(path)
    assert len(cloud) >= N  # VTK's pieces may repeat the points their cells share
    np.testing.assert_allclose(
        np.unique(np.round(cloud.origin + cloud.positions.astype(np.float64), 3), axis=0),
        np.unique(np.round(XYZ, 3), axis=0),
    )


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
@pytest.mark.parametrize("version", [42, 51])
def test_legacy_polydata_each_mode(tmp_path, binary, version):
    """VTK's legacy writer: ASCII and BINARY, file version 4.2 (cells as
    counts and ids) and 5.1 (OFFSETS and CONNECTIVITY); colours as
    COLOR_SCALARS, the other arrays as NORMALS and FIELD arrays."""
    path = tmp_path / f"p{version}.vtk"
    w = vtk.vtkPolyDataWriter()
    w.SetFileName(str(path))
    w.SetInputData(_polydata())
    w.SetFileVersion(version)
    w.SetFileTypeToBinary() if binary else w.SetFileTypeToASCII()
    assert w.Write() == 1
    text = path.read_bytes()
    assert (b"OFFSETS" in text) == (version == 51) and b"COLOR_SCALARS" in text
    if binary:
        _check(read_points(path))
    else:  # ASCII: six significant digits (positions relative to the minimum: to 1e-5 of 6.4e6)
        cloud = read_points(path)
        np.testing.assert_allclose(cloud.origin + cloud.positions, XYZ, rtol=1e-5)
        np.testing.assert_allclose(cloud.attributes["temperature"], TEMP, rtol=1e-5)
        np.testing.assert_array_equal(cloud.colors[:, :3], RGB)


@pytest.mark.parametrize("kind", ["UnstructuredGrid", "StructuredGrid"])
def test_legacy_grids_read_their_points(tmp_path, kind):
    if kind == "UnstructuredGrid":
        grid = vtk.vtkUnstructuredGrid()
        grid.Allocate(N)
        for i in range(0, N - 3, 4):
            grid.InsertNextCell(vtk.VTK_TETRA, 4, [i, i + 1, i + 2, i + 3])
    else:
        grid = vtk.vtkStructuredGrid()
        grid.SetDimensions(5, 3, 2)
    pts = vtk.vtkPoints()
    near = (XYZ - XYZ.min(axis=0)).astype(np.float32)  # ASCII keeps 6 digits
    pts.SetData(numpy_support.numpy_to_vtk(near, deep=True))
    grid.SetPoints(pts)
    grid.GetPointData().SetScalars(_array(TEMP, "temperature"))
    for binary in (False, True):
        path = tmp_path / f"{kind}{binary}.vtk"
        w = getattr(vtk, f"vtk{kind}Writer")()
        w.SetFileName(str(path))
        w.SetInputData(grid)
        w.SetFileTypeToBinary() if binary else w.SetFileTypeToASCII()
        assert w.Write() == 1
        cloud = read_points(path)
        assert len(cloud) == N and not cloud.origin.any()  # float32 positions: as stored
        np.testing.assert_allclose(cloud.positions, near, rtol=1e-5, atol=1e-4)
        np.testing.assert_allclose(cloud.attributes["temperature"], TEMP, rtol=1e-5)


def test_a_globe_as_pyvista_ships_it(tmp_path):
    """pyvista's globe.vtk's layout (legacy 4.2 BINARY POLYDATA, double
    points, POLYGONS, TEXTURE_COORDINATES of 2 components), made here: the
    sphere's vertices, its texture coordinates two attributes."""
    sphere = vtk.vtkTexturedSphereSource()
    sphere.SetRadius(6.371e9)
    sphere.SetThetaResolution(36)
    sphere.SetPhiResolution(15)
    sphere.Update()
    pd = sphere.GetOutput()
    pd.GetPointData().GetTCoords().SetName("Texture Coordinates")
    pts = vtk.vtkPoints()
    pts.SetDataTypeToDouble()
    pts.DeepCopy(pd.GetPoints())
    pd.SetPoints(pts)
    path = tmp_path / "globe.vtk"
    w = vtk.vtkPolyDataWriter()
    w.SetFileName(str(path))
    w.SetInputData(pd)
    w.SetFileVersion(42)
    w.SetFileTypeToBinary()
    assert w.Write() == 1
    head = path.read_bytes()[:200]
    assert b"DATASET POLYDATA\nPOINTS" in head and b" double" in head
    cloud = read_points(path)
    assert len(cloud) == pd.GetNumberOfPoints() > 500
    radii = np.linalg.norm(cloud.positions.astype(np.float64), axis=1)
    np.testing.assert_allclose(radii, 6.371e9, rtol=1e-6)  # within float32's reach: no origin
    assert {"Texture Coordinates_0", "Texture Coordinates_1"} <= set(cloud.attributes)
    with pytest.raises(
        DataError,
        match=r"POLYDATA: only DATASET STRUCTURED_POINTS or RECTILINEAR_GRID is a volume; .*clvis render",
    ):
        read_volume(path)


def _no_vtk(monkeypatch):
    """VTK's readers out of reach: a DataError then comes from clvis's checks."""

    def never():
        raise AssertionError("VTK was asked to read a file the checks should refuse")

    monkeypatch.setattr(polydata, "_vtk", never)


LEGACY = (
    "# vtk DataFile Version 5.1\nvtk output\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n"
    "0 0 0 1 0 0 0 1 0 0 0 1\nVERTICES 5 4\nOFFSETS vtktypeint64\n0 1 2 3 4\n"
    "CONNECTIVITY vtktypeint64\n0 1 2 3\nPOINT_DATA 4\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2 3 4\n"
)


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("POINTS 4 float", "POINTS 400000000000 float", "POINTS declares 1200000000000 values"),
        ("VERTICES 5 4", "VERTICES 5 900000000000", "VERTICES declares"),
        ("POINT_DATA 4", "POINT_DATA 5", "POINT_DATA 5 does not match POINTS 4"),
        (
            "LOOKUP_TABLE default\n",
            "LOOKUP_TABLE default\n1 2 3 4\nLOOKUP_TABLE t 99999999999\n",
            "t 99999999999",
        ),
        ("POINT_DATA 4\n", "POINT_DATA 4\nFIELD f 1\na 3 900000000 float\n", "field array 'a'"),
        ("POINT_DATA 4\n", "POINT_DATA 4\nFIELD f 99999999999\n", "FIELD of 99999999999 arrays"),
        ("POINT_DATA 4\n", "CELL_TYPES 88888888888\nPOINT_DATA 4\n", "CELL_TYPES declares"),
        ("s float 1", "s float 9", "SCALARS of 9 components"),
        ("s float 1", "s float16 1", "values of type 'float16' are not read"),
        ("POINTS 4 float", "POINTS -4 float", "malformed POINTS count"),
        ("DATASET POLYDATA", "DATASET RECTILINEAR_GRID", "RECTILINEAR_GRID is a volume, not a point cloud"),
        ("ASCII", "TEXT", "malformed legacy VTK header"),
        # VTK reads a version it cannot parse as 0, its cells in the layout before 5: ./dev.sh fuzz's SIGSEGV
        ("Version 5.1", "Version 5\xfc1", "malformed legacy VTK version line"),
    ],
)
def test_hostile_legacy_headers_are_refused_before_vtk_reads(tmp_path, monkeypatch, old, new, message):
    path = tmp_path / "hostile.vtk"
    path.write_text(LEGACY)
    assert len(read_points(path)) == 4  # the file as written reads
    _no_vtk(monkeypatch)
    assert old in LEGACY
    path.write_text(LEGACY.replace(old, new, 1))
    with pytest.raises(DataError, match=re.escape(message)) as e:
        read_points(path)
    assert str(e.value).count(str(path)) == 1


def _binary_legacy(tmp_path, version=51):
    path = tmp_path / "b.vtk"
    w = vtk.vtkPolyDataWriter()
    w.SetFileName(str(path))
    w.SetInputData(_polydata())
    w.SetFileVersion(version)
    w.SetFileTypeToBinary()
    assert w.Write() == 1
    return path, path.read_bytes()


def test_hostile_binary_legacy_is_refused_exactly(tmp_path, monkeypatch):
    """BINARY: each block's size is exact, so one point more than the bytes
    hold, a cut file or a count that lies in the middle is caught where it
    lies, and an unknown section (what follows it cannot be told) refused."""
    path, good = _binary_legacy(tmp_path)
    _no_vtk(monkeypatch)
    for old, new, message in (
        (b"POINTS 30 double", b"POINTS 31 double", "truncated or malformed|unknown legacy VTK section"),
        (b"VERTICES 31 30", b"VERTICES 31 31", "truncated or malformed|no CONNECTIVITY|unknown legacy VTK"),
        (b"POINT_DATA 30", b"POINT_DATA 30\nWHATEVER 3", "unknown legacy VTK section 'WHATEVER 3'"),
        # ./dev.sh fuzz: a line of latin-1's NEL alone split into no words (IndexError), '\xb2' (a
        # superscript 2) passed isdigit() and failed int() (ValueError)
        (b"POINT_DATA 30", b"\x85\nPOINT_DATA 30", "unknown legacy VTK section"),
        (b"POINT_DATA 30", b"POINT_DATA \xb230", "malformed POINT_DATA count"),
    ):
        assert old in good
        path.write_bytes(good.replace(old, new, 1))
        with pytest.raises(DataError, match=message) as e:
            read_points(path)
        assert str(path) in str(e.value)
    for cut in (len(good) // 3, len(good) - 20):
        path.write_bytes(good[:cut])
        with pytest.raises(DataError, match="truncated or malformed|unknown legacy VTK") as e:
            read_points(path)
        assert str(path) in str(e.value)


@pytest.mark.parametrize("binary", [True, False], ids=["binary", "ascii"])
def test_a_cell_list_whose_point_counts_lie_is_refused(tmp_path, monkeypatch, binary):
    """File version 4.2's cell lists (each cell's point count, then its
    ids): ./dev.sh fuzz's bit flips in a count made VTK's reader read past
    its buffer (SIGSEGV); the counts must add up to the list's size."""
    path = tmp_path / "cells42.vtk"
    w = vtk.vtkPolyDataWriter()
    w.SetFileName(str(path))
    w.SetInputData(_polydata())
    w.SetFileVersion(42)
    w.SetFileTypeToBinary() if binary else w.SetFileTypeToASCII()
    assert w.Write() == 1
    good = path.read_bytes()
    at = good.index(b"VERTICES 30 60\n") + len(b"VERTICES 30 60\n")
    _no_vtk(monkeypatch)
    if binary:  # cell 9's point count 1 -> 0x00800001 (the fuzzer's mutant)
        assert good[at + 72 : at + 76] == b"\0\0\0\1"
        bad = good[: at + 72] + b"\0\x80\0\1" + good[at + 76 :]
    else:
        assert good[at:].startswith(b"1 0 \n1 1 \n")
        bad = good[:at] + b"1 0 \n9 1 \n" + good[at + 10 :]
    path.write_bytes(bad)
    with pytest.raises(DataError, match="VERTICES 30 60: its cells' point counts do not add up to 60") as e:
        read_points(path)
    assert str(e.value).count(str(path)) == 1


def _vtp(tmp_path, mode="Binary", compressor=None, encode=False, header=32):
    """(path, bytes) of _polydata() as VTK's XML writer writes it in `mode`."""
    path = tmp_path / f"{mode}-{compressor}-{encode}-{header}.vtp"
    w = vtk.vtkXMLPolyDataWriter()
    w.SetFileName(str(path))
    w.SetInputData(_polydata())
    getattr(w, f"SetDataModeTo{mode}")()
    w.SetEncodeAppendedData(encode)
    w.SetCompressorTypeToNone() if compressor is None else getattr(w, f"SetCompressorTypeTo{compressor}")()
    if header == 64:
        w.SetHeaderTypeToUInt64()
    assert w.Write() == 1
    return path, path.read_bytes()


def test_hostile_vtp_headers_are_refused_before_vtk_reads(tmp_path, monkeypatch):
    path, good = _vtp(tmp_path)
    zlib_path, zipped = _vtp(tmp_path, compressor="ZLib")
    app_path, appended = _vtp(tmp_path, mode="Appended")
    _no_vtk(monkeypatch)
    cases = [
        (good, b'NumberOfPoints="30"', b'NumberOfPoints="3000000000"', "byte count does not match"),
        (good, b'NumberOfPolys="2"', b'NumberOfPolys="2000000000"', "byte count does not match"),
        (good, b'NumberOfLines="0"', b'NumberOfLines="x"', "malformed or missing"),
        (good, b'NumberOfPoints="30"', b'NumberOfPoints="\xb230"', "malformed or missing NumberOfPoints"),
        (good, b"<PolyData>", b'<!DOCTYPE x [<!ENTITY a "b">]><PolyData>', "DTD or entities"),
        (good, b'type="PolyData"', b'type="ImageData"', "not a VTK PolyData file"),
        (good, b'Name="Points" NumberOfComponents="3"', b'Name="Points" NumberOfComponents="2"', "<Points>"),
        (good, b'type="Float32" Name="temperature"', b'type="Float16" Name="temperature"', "Float16"),
        (zipped, b'NumberOfPoints="30"', b'NumberOfPoints="3000000000"', "compressed array holds"),
        (appended, b'NumberOfPoints="30"', b'NumberOfPoints="3000000000"', "byte count does not match"),
        (appended, b'offset="0"', b'offset="99999999"', "outside the file"),
    ]
    for text, old, new, message in cases:
        assert old in text, old
        p = path if text is good else zlib_path if text is zipped else app_path
        p.write_bytes(text.replace(old, new, 1))
        with pytest.raises(DataError, match=re.escape(message)) as e:
            read_points(p)
        assert str(e.value).count(str(p)) == 1
    path.write_bytes(good[: len(good) // 2])
    with pytest.raises(DataError) as e:
        read_points(path)
    assert str(path) in str(e.value)


@pytest.mark.parametrize("mode", ["Appended", "Binary"])
def test_a_vtp_whose_cell_offsets_lie_reads_its_points(tmp_path, mode):
    """VTK's XML reader trusts a cell array's offsets: a last offset of
    2^63 - 1 (./dev.sh fuzz's mutant) made it allocate that much, an abort
    (std::bad_alloc). VTK is given the file without its cells: the points
    read, in a child process under a memory limit."""
    from fuzz.harness import run_limited

    path, good = _vtp(tmp_path, mode, compressor=None, header=64)
    if mode == "Appended":  # the last 8 bytes of the appended data: the Polys' last offset, 6
        end = good.rindex(b"\n  </AppendedData>")
        assert good[end - 8 : end] == np.array([6], "<u8").tobytes()
        bad = good[: end - 8] + np.array([2**63 - 1], "<u8").tobytes() + good[end:]
    else:  # the Polys' offsets array, base64 of its byte count and values 3 6
        body = base64.b64encode(np.array([16, 3, 6], "<u8").tobytes())
        assert body in good
        bad = good.replace(body, base64.b64encode(np.array([16, 3, 2**63 - 1], "<u8").tobytes()))
    path.write_bytes(bad)
    r = run_limited(read_points, str(path), name=str(path), limit_bytes=1 << 30)
    assert r.kind == "ok", r
    cloud = read_points(path)
    assert len(cloud) == N and cloud.colors is not None


@pytest.mark.parametrize("tag", [b"DataArray", b"Piece", b"Verts"])
def test_unclosed_tags_take_linear_time(tmp_path, tag):
    """30,000 unclosed tags (500 kB): regular expressions that searched for
    each one's end took time quadratic in them (8,000 in 140 kB: 11 s of
    CPU; these: minutes); the checks pair tags and closing tags in one pass.
    The same helper reads .vti volumes' tags."""
    from fuzz.harness import run_limited

    path, good = _vtp(tmp_path, "Ascii")
    where = {b"DataArray": b"</Points>", b"Piece": b"</PolyData>", b"Verts": b"</Piece>"}[tag]
    path.write_bytes(good.replace(where, (b"<" + tag + b' a="1">') * 30000 + where, 1))
    r = run_limited(read_points, str(path), name=str(path), limit_bytes=1 << 30, timeout=20)
    assert r.kind in ("clvis", "ok"), r


def test_vtks_own_errors_are_data_errors_and_stay_off_stderr(tmp_path, capfd):
    """Sound counts over bytes VTK cannot read: VTK's error is the DataError
    (a legacy file whose cells VTK could not read gave its points without
    their data and no error while _quiet turned VTK's warning display off:
    VTK's error macros then invoke no ErrorEvent); nothing reaches stderr;
    VTK's warning display, logger cutoff and output window are put back."""
    before = (
        vtk.vtkObject.GetGlobalWarningDisplay(),
        vtk.vtkLogger.GetCurrentVerbosityCutoff(),
        vtk.vtkOutputWindow.GetInstance().__this__,
    )
    path, good = _vtp(tmp_path, compressor="ZLib")
    body = re.search(rb'Name="temperature"[^>]*>\s*(\S+)', good)
    head, blocks = body.group(1)[:16], body.group(1)[16:]  # the block header (one block, 4-byte sizes)
    path.write_bytes(good.replace(head + blocks, head + re.sub(rb"[A-Za-z0-9]", b"A", blocks)))
    with pytest.raises(DataError, match="VTK could not read it") as e:
        read_points(path)
    assert str(e.value).count(str(path)) == 1
    legacy = tmp_path / "x.vtk"
    legacy.write_text(LEGACY.replace("OFFSETS", "OFFSETZ", 1))  # left to VTK's reader in ASCII
    with pytest.raises(DataError, match="VTK could not read it: .*Error reading vertices"):
        read_points(legacy)
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    after = (
        vtk.vtkObject.GetGlobalWarningDisplay(),
        vtk.vtkLogger.GetCurrentVerbosityCutoff(),
        vtk.vtkOutputWindow.GetInstance().__this__,
    )
    assert after == before


def test_a_vtk_goes_where_its_dataset_says(tmp_path):
    """A STRUCTURED_POINTS .vtk is a volume: read_points says which read it;
    a .vtp is a cloud: read_volume says which read it."""
    sp = tmp_path / "v.vtk"
    sp.write_text(
        "# vtk DataFile Version 3.0\nx\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 1 1\n"
        "POINT_DATA 2\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2\n"
    )
    with pytest.raises(
        DataError, match="STRUCTURED_POINTS is a volume, not a point cloud; read_volume, clvis iso"
    ):
        read_points(sp)
    np.testing.assert_array_equal(read_volume(sp).data, [[[1, 2]]])
    path, _ = _vtp(tmp_path)
    with pytest.raises(
        DataError, match=r"a point cloud file \(.vtp\), not a volume; read_points, clvis render"
    ):
        read_volume(path)
    from clvis.io.vtk import legacy_dataset

    assert legacy_dataset(sp) == "STRUCTURED_POINTS" and legacy_dataset(path) == ""
    assert legacy_dataset(tmp_path / "missing.vtk") == ""


def test_an_empty_polydata_is_an_empty_cloud(tmp_path):
    path = tmp_path / "empty.vtp"
    w = vtk.vtkXMLPolyDataWriter()
    w.SetFileName(str(path))
    w.SetInputData(vtk.vtkPolyData())
    assert w.Write() == 1
    assert len(read_points(path)) == 0


def _grid(kind):
    """_polydata()'s points and point arrays as a vtkUnstructuredGrid (tetras,
    cell data not read) or a 5 x 3 x 2 vtkStructuredGrid (cells implicit)."""
    pd = _polydata()
    if kind == "UnstructuredGrid":
        grid = vtk.vtkUnstructuredGrid()
        grid.Allocate(N)
        for i in range(0, N - 3, 4):
            grid.InsertNextCell(vtk.VTK_TETRA, 4, [i, i + 1, i + 2, i + 3])
        cells = (N - 3 + 3) // 4
    else:
        grid = vtk.vtkStructuredGrid()
        grid.SetDimensions(5, 3, 2)
        cells = 4 * 2 * 1
    grid.SetPoints(pd.GetPoints())
    grid.GetPointData().ShallowCopy(pd.GetPointData())
    grid.GetCellData().AddArray(_array(np.arange(cells, dtype=np.float64), "cell"))
    return grid


def _xml_grid(tmp_path, kind, mode="Binary", compressor=None, encode=False, pieces=1):
    """(path, bytes) of _grid(kind) as VTK's XML writer writes it."""
    suffix = {"UnstructuredGrid": "vtu", "StructuredGrid": "vts"}[kind]
    path = tmp_path / f"{mode}-{compressor}-{encode}-{pieces}.{suffix}"
    w = getattr(vtk, f"vtkXML{kind}Writer")()
    w.SetFileName(str(path))
    w.SetInputData(_grid(kind))
    getattr(w, f"SetDataModeTo{mode}")()
    w.SetEncodeAppendedData(encode)
    w.SetCompressorTypeToNone() if compressor is None else getattr(w, f"SetCompressorTypeTo{compressor}")()
    w.SetNumberOfPieces(pieces)
    assert w.Write() == 1
    return path, path.read_bytes()


@pytest.mark.parametrize("kind", ["UnstructuredGrid", "StructuredGrid"])
def test_vtu_and_vts_every_mode_vtks_writers_make(tmp_path, kind):
    """A .vtu and a .vts (the files pyvista's mesh.save writes most often):
    ascii, inline binary, raw and base64 appended, each uncompressed, zlib
    and LZ4: their points and point arrays, the cells and cell data not."""
    for mode, encode in (("Ascii", False), ("Binary", False), ("Appended", False), ("Appended", True)):
        for compressor in (None, "ZLib", "LZ4"):
            path, text = _xml_grid(tmp_path, kind, mode, compressor, encode)
            assert (b"compressor=" in text) == (compressor is not None)
            assert (b"<Cells>" in text) == (kind == "UnstructuredGrid") and b"<CellData>" in text
            if mode == "Ascii":  # ASCII doubles keep 11 digits, Float32 arrays 8
                cloud = read_points(path)
                np.testing.assert_allclose(cloud.origin + cloud.positions, XYZ, atol=1e-5)
                np.testing.assert_allclose(cloud.attributes["temperature"], TEMP, rtol=1e-6)
                np.testing.assert_array_equal(cloud.colors[:, :3], RGB)
                np.testing.assert_array_equal(cloud.attributes["id"], IDS)
            else:
                _check(read_points(path))


@pytest.mark.parametrize("kind", ["UnstructuredGrid", "StructuredGrid"])
def test_vtu_and_vts_of_several_pieces(tmp_path, kind):
    """Three pieces: a .vts's share their boundary points and VTK's reader
    puts them in one grid (the points once); a .vtu's are appended, as VTK's
    own reader appends them."""
    path, text = _xml_grid(tmp_path, kind, pieces=3)
    assert text.count(b"<Piece") == 3
    cloud = read_points(path)
    if kind == "StructuredGrid":
        _check(cloud)
        return
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(str(path))
    r.Update()
    want = numpy_support.vtk_to_numpy(r.GetOutput().GetPoints().GetData())
    assert len(cloud) == len(want) >= N
    np.testing.assert_allclose(cloud.origin + cloud.positions, want, atol=1e-5)


def test_hostile_vtu_and_vts_headers_are_refused_before_vtk_reads(tmp_path, monkeypatch):
    vtu, u = _xml_grid(tmp_path, "UnstructuredGrid")
    uapp, ua = _xml_grid(tmp_path, "UnstructuredGrid", "Appended", "ZLib")
    vts, s = _xml_grid(tmp_path, "StructuredGrid")
    sapp, sa = _xml_grid(tmp_path, "StructuredGrid", "Appended", "LZ4", True)
    three, s3 = _xml_grid(tmp_path, "StructuredGrid", pieces=3)  # three pieces of the whole grid
    _no_vtk(monkeypatch)
    cases = [
        (vtu, u, b'NumberOfPoints="30"', b'NumberOfPoints="3000000000"', "byte count does not match"),
        (vtu, u, b'NumberOfCells="7"', b'NumberOfCells="7000000"', "byte count does not match"),
        (vtu, u, b'Name="offsets"', b'Name="offzets"', "7 Cells and no offsets array"),
        (vtu, u, b'Name="types"', b'Name="tipes"', "7 Cells and no types array"),
        (vtu, u, b'type="UnstructuredGrid"', b'type="PolyData"', "not a VTK UnstructuredGrid file"),
        (
            vtu,
            u,
            b'Name="id" format',
            b'Name="id" NumberOfComponents="2" format',
            "byte count does not match",
        ),
        (uapp, ua, b'NumberOfPoints="30"', b'NumberOfPoints="31"', "compressed array holds"),
        (vts, s, b'Piece Extent="0 4 0 2 0 1"', b'Piece Extent="0 4 0 2 0 2"', "outside WholeExtent"),
        (
            vts,
            s,
            b'WholeExtent="0 4 0 2 0 1"',
            b'WholeExtent="0 4 0 2 0 9"',
            "the WholeExtent [0, 4, 0, 2, 0, 9] needs 150",
        ),
        (vts, s, b'Piece Extent="0 4 0 2 0 1"', b'Piece Extent="0 4 0 2 0 x"', "malformed Piece Extent"),
        (
            three,
            s3,
            b'WholeExtent="0 4 0 2 0 1"',
            b'WholeExtent="0 4 0 2 0 2"',
            "do not cover the WholeExtent",
        ),
        (sapp, sa, b'type="StructuredGrid"', b'type="ImageData"', "not a VTK StructuredGrid file"),
        (sapp, sa, b'Piece Extent="0 4 0 2 0 1"', b'Piece Extent="0 4 0 2 0 0"', "compressed array holds"),
    ]
    for path, text, old, new, message in cases:
        assert old in text, old
        path.write_bytes(text.replace(old, new, 1))
        with pytest.raises(DataError, match=re.escape(message)) as e:
            read_points(path)
        assert str(e.value).count(str(path)) == 1


def test_a_vtu_whose_cell_offsets_lie_reads_its_points(tmp_path):
    """A .vtu's last cell offset 2^63 - 1 (VTK's reader trusts it, as a
    .vtp's: given the cells, it aborted, std::bad_alloc): VTK is given the
    file without its cells and cell data; the points read, in a child
    process under a memory limit."""
    from fuzz.harness import run_limited

    path, good = _xml_grid(tmp_path, "UnstructuredGrid", "Appended")
    # the offsets' byte count and values, raw after the connectivity
    offsets = np.array([56], "<u4").tobytes() + np.arange(4, 29, 4, dtype="<i8").tobytes()
    assert good.count(offsets) == 1
    path.write_bytes(good.replace(offsets, offsets[:-8] + np.array([2**63 - 1], "<i8").tobytes()))
    r = run_limited(read_points, str(path), name=str(path), limit_bytes=1 << 30)
    assert r.kind == "ok", r
    _check(read_points(path))


def test_legacy_string_field_arrays_are_passed_over(tmp_path):
    """A FIELD's string array, as vtkPolyDataWriter writes it in ASCII (one
    value a line): values that look like a section ('POINTS 9 float', a
    field array's 'name 1 2 float') were read as one and refused the file;
    a string array that declares more lines than the file holds is refused."""
    pd = vtk.vtkPolyData()
    pd.SetPoints(_polydata().GetPoints())
    notes = vtk.vtkStringArray()
    notes.SetName("notes")
    for text in ("POINTS 9 float", "a 1 2 float", "", "CELL_DATA 5"):
        notes.InsertNextValue(text)
    pd.GetFieldData().AddArray(notes)
    pd.GetFieldData().AddArray(_array(np.array([1.5], np.float32), "time"))
    pd.GetPointData().AddArray(_array(TEMP, "temperature"))
    path = tmp_path / "notes.vtk"
    w = vtk.vtkPolyDataWriter()
    w.SetFileName(str(path))
    w.SetInputData(pd)
    w.SetFileTypeToASCII()
    assert w.Write() == 1
    text = path.read_bytes()
    assert b"notes 1 4 string\nPOINTS%209%20float\n" in text
    cloud = read_points(path)
    assert len(cloud) == N
    np.testing.assert_allclose(cloud.attributes["temperature"], TEMP, rtol=1e-5)  # ASCII: 6 digits
    path.write_bytes(text[: text.index(b"a%201%202%20float\n") + 18])  # two of the four lines
    with pytest.raises(DataError, match="declares 4 strings, one a line") as e:
        read_points(path)
    assert str(e.value).count(str(path)) == 1


def test_blank_lines_in_a_legacy_header_are_read_as_vtk_reads_them(tmp_path):
    """VTK reads a legacy file's words after the title one by one, passing
    over blank lines: meshio's test mesh rbc_001.vtk (a red blood cell, "3D
    Unstructured Grid of Triangles") has a blank line between ASCII and
    DATASET, and was refused as a malformed header. ASCII and BINARY, points
    and routing (legacy_dataset, which clvis render and clvis view use)."""
    from clvis.io.vtk import legacy_dataset

    grid = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    near = (XYZ - XYZ.min(axis=0)).astype(np.float32)
    pts.SetData(numpy_support.numpy_to_vtk(near, deep=True))
    grid.SetPoints(pts)
    grid.Allocate(1)
    grid.InsertNextCell(vtk.VTK_TRIANGLE, 3, [0, 1, 2])
    grid.GetPointData().SetScalars(_array(TEMP, "temperature"))
    for binary in (False, True):
        path = tmp_path / f"blank{binary}.vtk"
        w = vtk.vtkUnstructuredGridWriter()
        w.SetFileName(str(path))
        w.SetInputData(grid)
        w.SetFileTypeToBinary() if binary else w.SetFileTypeToASCII()
        assert w.Write() == 1
        head = b"BINARY\n" if binary else b"ASCII\n"
        raw = path.read_bytes()
        path.write_bytes(raw.replace(head, head + b"\n", 1).replace(b"\nDATASET", b"\n \nDATASET", 1))
        r = vtk.vtkUnstructuredGridReader()  # VTK itself reads it
        r.SetFileName(str(path))
        r.Update()
        assert r.GetOutput().GetNumberOfPoints() == N
        assert legacy_dataset(path) == "UNSTRUCTURED_GRID"
        cloud = read_points(path)
        assert len(cloud) == N
        np.testing.assert_allclose(cloud.positions, near, rtol=1e-5, atol=1e-4)
        np.testing.assert_allclose(cloud.attributes["temperature"], TEMP, rtol=1e-5)


def test_a_blank_number_of_components_is_one_as_vtk_reads_it(tmp_path):
    """meshio writes a .vtu's cell arrays with NumberOfComponents="" (its
    test mesh 00_raw_binary.vtu); VTK's reader takes one component where the
    attribute holds no number, clvis refused the file ("malformed or missing
    NumberOfComponents ''"). Its points and point arrays are read; a blank
    NumberOfComponents of a point array is one component too."""
    path, raw = _xml_grid(tmp_path, "UnstructuredGrid", mode="Ascii")
    text = raw.decode()
    arrays = re.findall(r"<DataArray[^>]*>", text)
    blank = '<DataArray NumberOfComponents=""'
    for a in arrays:
        if re.search(r'Name="(offsets|types|connectivity|id)"', a):
            bare = re.sub(r'\s*NumberOfComponents="[^"]*"', "", a)
            text = text.replace(a, bare.replace("<DataArray", blank))
    assert text.count('NumberOfComponents=""') == 4
    path.write_text(text)
    r = vtk.vtkXMLUnstructuredGridReader()  # VTK itself reads it
    r.SetFileName(str(path))
    r.Update()
    assert r.GetOutput().GetNumberOfPoints() == N and r.GetOutput().GetNumberOfCells() > 0
    cloud = read_points(path)
    assert len(cloud) == N
    np.testing.assert_allclose(cloud.origin + cloud.positions, XYZ, rtol=1e-6)
    np.testing.assert_array_equal(cloud.attributes["id"], IDS)
    np.testing.assert_allclose(cloud.attributes["temperature"], TEMP, rtol=1e-6)
