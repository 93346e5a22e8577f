"""VTK image data volumes (.vti, legacy .vtk STRUCTURED_POINTS and evenly
spaced RECTILINEAR_GRID) through
read_volume: pyvista's own file, the encodings VTK writes, and a DataError
naming the file for what is not read. VTK's readers read the files (the vtk
extra); the header checks before them keep hostile sizes from allocating."""

import base64
import re
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from clvis.errors import DataError
from clvis.io import read_volume

DATA = Path(__file__).parent / "data"


def test_pyvista_uniform_vtk():
    """Legacy binary, big-endian doubles, with cell data and a field before the
    point scalars (x*y*z on a 10^3 grid)."""
    v = read_volume(DATA / "pyvista_uniform.vtk")
    assert v.shape == (10, 10, 10) and v.data.dtype == np.float64 and v.data.dtype.isnative
    z, y, x = np.mgrid[:10, :10, :10]
    np.testing.assert_array_equal(v.data, x * y * z)
    assert v.spacing == (1.0, 1.0, 1.0) and v.origin == (0.0, 0.0, 0.0)


def _vti(data, encoding, spacing="1 2 3", header="UInt32", big=False):
    """A .vti of (Z, Y, X) `data` as VTK writes it."""
    nz, ny, nx = data.shape
    order = ">" if big else "<"
    raw = data.astype(data.dtype.newbyteorder(order)).tobytes()
    hdt = order + ("u8" if header == "UInt64" else "u4")
    comp = ""
    if encoding == "ascii":
        body = " ".join(str(v) for v in data.ravel())
    elif encoding == "binary":
        body = base64.b64encode(np.array([len(raw)], hdt).tobytes() + raw).decode()
    else:  # zlib blocks of 64 bytes, header and data encoded separately (VTK's layout)
        comp = ' compressor="vtkZLibDataCompressor"'
        blocks = [raw[i : i + 64] for i in range(0, len(raw), 64)]
        zs = [zlib.compress(b) for b in blocks]
        head = np.array([len(blocks), 64, len(blocks[-1]) % 64, *map(len, zs)], hdt).tobytes()
        body = base64.b64encode(head).decode() + base64.b64encode(b"".join(zs)).decode()
        encoding = "binary"
    t = {"uint8": "UInt8", "int16": "Int16", "float32": "Float32", "float64": "Float64"}[data.dtype.name]
    return (
        f'<?xml version="1.0"?>\n<VTKFile type="ImageData" version="0.1" '
        f'byte_order="{"BigEndian" if big else "LittleEndian"}" header_type="{header}"{comp}>\n'
        f'<ImageData WholeExtent="0 {nx - 1} 0 {ny - 1} 0 {nz - 1}" Origin="5 6 7" Spacing="{spacing}">\n'
        f'<Piece Extent="0 {nx - 1} 0 {ny - 1} 0 {nz - 1}"><PointData Scalars="v">\n'
        f'<DataArray type="Float32" Name="other" format="ascii">{" ".join(["0"] * data.size)}</DataArray>\n'
        f'<DataArray type="{t}" Name="v" format="{encoding}">\n{body}\n</DataArray>\n'
        "</PointData><CellData></CellData></Piece></ImageData></VTKFile>\n"
    ).encode()


@pytest.mark.parametrize("encoding", ["ascii", "binary", "zlib"])
@pytest.mark.parametrize("dtype", ["uint8", "int16", "float32", "float64"])
def test_vti_encodings(tmp_path, encoding, dtype):
    data = (np.arange(5 * 6 * 7).reshape(5, 6, 7) % 100).astype(dtype)
    for header, big in (("UInt32", False), ("UInt64", True)):
        path = tmp_path / f"v{header}.vti"
        path.write_bytes(_vti(data, encoding, header=header, big=big))
        v = read_volume(path)
        np.testing.assert_array_equal(v.data, data)  # the Scalars array, not the first
        assert v.data.dtype == np.dtype(dtype) and v.data.dtype.isnative
        assert v.spacing == (3.0, 2.0, 1.0) and v.origin == (5.0, 6.0, 7.0)


def test_vti_errors(tmp_path):
    data = np.zeros((2, 3, 4), np.float32)
    good = _vti(data, "zlib")

    def bad(content, message):
        p = tmp_path / "bad.vti"
        p.write_bytes(content)
        with pytest.raises(DataError, match=message) as e:
            read_volume(p)
        assert str(p) in str(e.value) and str(e.value).count(str(p)) == 1  # named once

    bad(b"hello", "not a VTK ImageData file")
    bad(b'<!DOCTYPE x [<!ENTITY a "b">]>' + good, "DTD or entities")
    app = good.replace(b'format="binary">', b'format="appended" offset="0">')
    bad(
        app.replace(b"</VTKFile>", b'<AppendedData encoding="base64">_AAAA</AppendedData></VTKFile>'),
        "truncated or malformed compressed array",
    )
    bad(
        app.replace(b"</VTKFile>", b'<AppendedData encoding="uu">_AAAA</AppendedData></VTKFile>'),
        "encoding 'uu' is not read",
    )
    bad(
        app.replace(b"</VTKFile>", b'<AppendedData encoding="raw">_\0\0</AppendedData></VTKFile>'),
        "truncated",
    )
    bad(
        app.replace(b'offset="0"', b'offset="99999"') + b'<AppendedData encoding="raw">_\0\0\0\0\0', "outside"
    )
    bad(app.replace(b'offset="0"', b'offset="-3"') + b'<AppendedData encoding="raw">_\0\0\0\0\0', "outside")
    bad(app.replace(b"</VTKFile>", b'<AppendedData encoding="raw"></AppendedData></VTKFile>'), "no '_'")
    bad(app.replace(b'offset="0"', b'offset="x"') + b'<AppendedData encoding="raw">_\0\0\0\0\0', "offset")
    bad(app, "format 'appended' is not read")  # no <AppendedData> at all
    bad(good.replace(b'WholeExtent="0 3', b'WholeExtent="0 30'), "the pieces hold 24 samples")
    bad(good.replace(b'Extent="0 3', b'Extent="0 30'), "the extent needs")
    bad(good.replace(b'Float32" Name="v"', b'Float16" Name="v"'), "unsupported DataArray type")
    bad(good.replace(b'Name="v"', b'Name="v" NumberOfComponents="3"'), "several components")
    bad(good.replace(b"vtkZLibDataCompressor", b"vtkLZMADataCompressor"), "zlib or LZ4")
    bad(good.replace(b"vtkZLibDataCompressor", b"vtkLZ4DataCompressor"), "VTK could not read it")
    bad(good.replace(b'<Piece Extent="0 3', b'<Piece Extent="0 4'), "outside WholeExtent")
    bad(good.replace(b'<Piece Extent="0 3', b'<Piece Extent="1 3'), "holds 96 bytes, the extent needs 72")
    z = _vti(data, "zlib").split(b"\n")
    z[6] = z[6][:-8]  # the array cut short
    bad(b"\n".join(z), "truncated or malformed|malformed binary")
    bad(_vti(data, "binary").replace(b'format="binary">\n', b'format="binary">\n!!'), "VTK could not read it")
    # the point array relabelled as cells: 24 points' values where 6 cells' are due
    as_cells = good.replace(b"<PointData", b"<CellData").replace(b"</PointData>", b"</CellData>")
    bad(as_cells, "the extent needs 24")
    empty = re.sub(rb"<DataArray\b.*?</DataArray>", b"", good, flags=re.S)
    assert b"<DataArray" not in empty
    bad(empty, "no point or cell data array")


def test_legacy_ascii_and_errors(tmp_path):
    head = "# vtk DataFile Version 3.0\nx\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 3 2\n"
    head += "SPACING 1 2 3\nORIGIN 0 0 0\nPOINT_DATA 12\nSCALARS s float 1\nLOOKUP_TABLE default\n"
    p = tmp_path / "a.vtk"
    p.write_text(head + " ".join(str(k) for k in range(12)) + "\n")
    v = read_volume(p)
    np.testing.assert_array_equal(v.data, np.arange(12, dtype=np.float32).reshape(2, 3, 2))
    assert v.spacing == (3.0, 2.0, 1.0)
    for text, message in (
        (head + "1 2 3\n", "truncated or malformed: SCALARS s float 1 declares 12 values"),
        (head + "1 2 3 4 5 6 7 8 9 10 11\n", "VTK (could not read it|read no 12-sample)"),
        (head.replace("POINT_DATA", "FIELD f 1\na 3 900000000 float\nPOINT_DATA") + "0 " * 12, "field array"),
        (
            head.replace("POINT_DATA", "CELL_DATA 99999\nPOINT_DATA") + "0 " * 12,
            r"CELL_DATA 99999 does not match DIMENSIONS 2 3 2 \(2 cells\)",
        ),
        (head.replace("POINT_DATA 12", "POINT_DATA 11") + "0 " * 12, "does not match DIMENSIONS"),
        (head.replace("float 1", "float 3") + "0 " * 36, "one component"),
        (head.replace("STRUCTURED_POINTS", "POLYDATA"), "only DATASET STRUCTURED_POINTS or RECTILINEAR_GRID"),
        (head.replace("ASCII", "BINARY") + "\0" * 8, "truncated"),
        ("hello\n", "not a legacy VTK file"),
        (head.replace("SCALARS s float 1\nLOOKUP_TABLE default\n", ""), "no point or cell data array"),
    ):
        p.write_text(text)
        with pytest.raises(DataError, match=message):
            read_volume(p)


def test_legacy_header_with_blank_lines_reads_as_vtk_reads_it(tmp_path):
    """VTK passes over blank lines after a legacy file's title (it reads the
    header word by word): blank lines before ASCII, before DATASET and between
    DIMENSIONS, SPACING and ORIGIN were a malformed header, or "no
    DIMENSIONS". The title itself may be blank."""
    from vtkmodules.vtkIOLegacy import vtkStructuredPointsReader

    from clvis.io.vtk import legacy_dataset

    p = tmp_path / "blank.vtk"
    p.write_text(
        "# vtk DataFile Version 3.0\n\n\nASCII\n\n \nDATASET STRUCTURED_POINTS\n\nDIMENSIONS 2 3 2\n\n"
        "SPACING 1 2 3\n\nORIGIN 4 5 6\nPOINT_DATA 12\nSCALARS s float 1\nLOOKUP_TABLE default\n"
        + " ".join(str(k) for k in range(12))
        + "\n"
    )
    r = vtkStructuredPointsReader()  # VTK itself reads it
    r.SetFileName(str(p))
    r.Update()
    assert r.GetOutput().GetDimensions() == (2, 3, 2)
    assert legacy_dataset(p) == "STRUCTURED_POINTS"
    v = read_volume(p)
    np.testing.assert_array_equal(v.data, np.arange(12, dtype=np.float32).reshape(2, 3, 2))
    assert v.spacing == (3.0, 2.0, 1.0) and v.origin == (4.0, 5.0, 6.0)
    p.write_text("# vtk DataFile Version 3.0\nx\n\nASCII\n\n")  # still too short
    with pytest.raises(DataError, match="malformed legacy VTK header"):
        read_volume(p)


def _world_image(dims, spacing, origin, direction=None):
    """vtkImageData whose point scalar "w" is x + 10 y + 100 z of the point
    (VTK's own placing: origin + Direction @ (i * spacing))."""
    from vtkmodules.util import numpy_support as ns
    from vtkmodules.vtkCommonDataModel import vtkImageData

    img = vtkImageData()
    img.SetDimensions(*dims)
    img.SetSpacing(*spacing)
    img.SetOrigin(*origin)
    if direction is not None:
        img.SetDirectionMatrix(*np.ravel(direction))
    pts = np.array([img.GetPoint(i) for i in range(img.GetNumberOfPoints())])
    a = ns.numpy_to_vtk(pts @ np.array([1.0, 10.0, 100.0]), deep=True)
    a.SetName("w")
    img.GetPointData().SetScalars(a)
    return img


def _check_world(v):
    """Each sample of Volume `v` at origin + index * spacing holds its x + 10 y + 100 z."""
    assert min(v.spacing) > 0
    z, y, x = (np.arange(n) * s for n, s in zip(v.data.shape, v.spacing, strict=True))
    ox, oy, oz = v.origin
    want = (ox + x)[None, None, :] + 10 * (oy + y)[None, :, None] + 100 * (oz + z)[:, None, None]
    np.testing.assert_allclose(v.data, want, atol=1e-9)


@pytest.mark.parametrize("suffix", [".vti", ".vtk"])
def test_image_data_of_negative_or_flat_spacing_reads_with_forward_steps(tmp_path, suffix):
    """VTK puts sample i at origin + i * spacing: an axis of negative spacing
    runs backward, and a 2-D image is often written with spacing 0 along its
    flat axis (meshio's test image 00_image.vtk: SPACING 0.5 0.5 0.0).
    read_volume handed those spacings on and every renderer refused them
    (clvis gauss 00_image.vtk: "spacing: (0.0, 0.5, 0.5) must be > 0 on every
    axis", naming no file). Now a backward axis is flipped, its origin at its
    last sample (every sample where VTK puts it), a flat axis gets a step of
    1, and a zero step along an axis of several samples is a DataError
    naming the file."""
    from vtkmodules.vtkIOLegacy import vtkStructuredPointsWriter
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

    def write(img, name):
        path = tmp_path / (name + suffix)
        w = vtkXMLImageDataWriter() if suffix == ".vti" else vtkStructuredPointsWriter()
        w.SetFileName(str(path))
        w.SetInputData(img)
        assert w.Write() == 1
        return path

    v = read_volume(write(_world_image((4, 3, 5), (-0.5, 2.0, -3.0), (1.0, 2.0, 3.0)), "backward"))
    assert v.shape == (5, 3, 4) and v.spacing == (3.0, 2.0, 0.5) and v.origin == (-0.5, 2.0, -9.0)
    _check_world(v)
    flat = read_volume(write(_world_image((6, 4, 1), (0.5, 0.5, 0.0), (0.0, 1.0, 2.0)), "flat"))
    assert flat.shape == (1, 4, 6) and flat.spacing == (1.0, 0.5, 0.5) and flat.origin == (0.0, 1.0, 2.0)
    _check_world(flat)
    import clvis

    clvis.gaussians_from_volume(flat)  # a renderer takes it
    path = write(_world_image((6, 4, 3), (0.5, 0.0, 1.0), (0.0, 0.0, 0.0)), "zero")
    with pytest.raises(DataError, match=rf"zero{suffix}: spacing 0 along y: its 4 samples at one place"):
        read_volume(path)


def test_a_vti_direction_that_flips_or_permutes_axes_is_applied(tmp_path):
    """A .vti's Direction (VTK 9 writes it; a scan converted from DICOM's LPS
    order has x and y flipped) was ignored: the volume came out mirrored or
    turned. A Direction that permutes and flips axes is applied (each sample
    where VTK puts it, no resampling); a rotation is a DataError naming the
    file, as from_vtk says of such an image."""
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

    def write(img, name):
        path = tmp_path / name
        w = vtkXMLImageDataWriter()
        w.SetFileName(str(path))
        w.SetInputData(img)
        assert w.Write() == 1
        return path

    lps = np.diag([-1.0, -1.0, 1.0])
    v = read_volume(write(_world_image((4, 3, 5), (0.5, 2.0, 3.0), (1.0, 2.0, 3.0), lps), "lps.vti"))
    assert v.shape == (5, 3, 4) and v.spacing == (3.0, 2.0, 0.5) and v.origin == (-0.5, -2.0, 3.0)
    _check_world(v)
    turned = [[0, -1, 0], [0, 0, 1], [1, 0, 0]]  # i along +z, j along -x, k along +y
    v = read_volume(write(_world_image((4, 3, 5), (0.5, 2.0, 3.0), (1.0, 2.0, 3.0), turned), "t.vti"))
    assert v.shape == (4, 5, 3) and v.spacing == (0.5, 3.0, 2.0)
    _check_world(v)
    c, s = np.cos(0.5), np.sin(0.5)
    path = write(_world_image((4, 3, 5), (1, 1, 1), (0, 0, 0), [[c, -s, 0], [s, c, 0], [0, 0, 1]]), "r.vti")
    with pytest.raises(DataError, match=r"r.vti: its axes are rotated \(Direction 0.877583 -0.479426"):
        read_volume(path)


def _grid(x, y, z, values, cells=False):
    """A vtkRectilinearGrid of those coordinates, `values` its point (or
    `cells`: cell) array "v"."""
    from vtkmodules.util import numpy_support as ns
    from vtkmodules.vtkCommonDataModel import vtkRectilinearGrid

    g = vtkRectilinearGrid()
    g.SetDimensions(len(x), len(y), len(z))
    g.SetXCoordinates(ns.numpy_to_vtk(np.asarray(x, np.float64), deep=True))
    g.SetYCoordinates(ns.numpy_to_vtk(np.asarray(y, np.float64), deep=True))
    g.SetZCoordinates(ns.numpy_to_vtk(np.asarray(z, np.float64), deep=True))
    a = ns.numpy_to_vtk(values, deep=True)
    a.SetName("v")
    (g.GetCellData() if cells else g.GetPointData()).SetScalars(a)
    return g


def _rectilinear(path, x, y, z, values, binary, cells=False):
    """A legacy RECTILINEAR_GRID as VTK's own writer makes it (what
    pyvista's RectilinearGrid.save writes); `cells`: `values` its cell data."""
    from vtkmodules.vtkIOLegacy import vtkRectilinearGridWriter

    w = vtkRectilinearGridWriter()
    w.SetFileName(str(path))
    w.SetInputData(_grid(x, y, z, values, cells))
    w.SetFileTypeToBinary() if binary else w.SetFileTypeToASCII()
    assert w.Write() == 1


@pytest.mark.parametrize("mode", ["legacy-ascii", "legacy-binary", "Ascii", "Binary", "Appended"])
def test_rectilinear_grid_of_even_coordinates_is_a_volume(tmp_path, mode):
    """A legacy RECTILINEAR_GRID or an XML RectilinearGrid (.vtr, in each of
    VTK's data modes; pyvista's RectilinearGrid.save writes either):
    evenly spaced coordinates give the spacing and origin; uneven or
    decreasing ones are refused naming the axis; a .vtr's cell array (no
    point array) is one sample a cell at the cells' centres; a hostile
    coordinate count is refused before VTK reads."""
    legacy = mode.startswith("legacy")
    p = tmp_path / ("grid.vtk" if legacy else "grid.vtr")

    def write(x, y, z, values, cells=False):
        if legacy:
            _rectilinear(p, x, y, z, values, mode == "legacy-binary")
        else:
            _vtr(p, x, y, z, values, mode, cells)

    x, y, z = np.arange(4) * 0.5 + 1, np.arange(3) * 2.0 - 3, np.linspace(0, 1, 5)
    values = np.arange(4 * 3 * 5, dtype=np.float32) * 3 % 17
    write(x, y, z, values)
    v = read_volume(p)
    np.testing.assert_array_equal(v.data, values.reshape(5, 3, 4))
    assert v.data.dtype == np.float32
    assert v.spacing == pytest.approx((0.25, 2.0, 0.5)) and v.origin == pytest.approx((1.0, -3.0, 0.0))
    uneven, decreasing = (
        (r"grid\.vtk: RECTILINEAR_GRID with uneven Y_COORDINATES", "X_COORDINATES must increase")
        if legacy
        else (r"grid\.vtr: a RectilinearGrid with uneven Y coordinates", "the X coordinates must increase")
    )
    write(x, [0.0, 1.0, 3.0], z, values)
    with pytest.raises(DataError, match=uneven):
        read_volume(p)
    write(x[::-1], y, z, values)
    with pytest.raises(DataError, match=decreasing):
        read_volume(p)
    if not legacy:
        cells = np.arange(3 * 2 * 4, dtype=np.int16)
        write(x, y, z, cells, cells=True)
        v = read_volume(p)
        np.testing.assert_array_equal(v.data, cells.reshape(4, 2, 3))
        assert v.spacing == pytest.approx((0.25, 2.0, 0.5))
        assert v.origin == pytest.approx((1.25, -2.0, 0.125))
    if mode == "legacy-ascii":
        write(x, y, z, values)
        p.write_text(p.read_text().replace("X_COORDINATES 4", "X_COORDINATES 999999999", 1))
        with pytest.raises(DataError, match="X_COORDINATES declares 999999999 values"):
            read_volume(p)


@pytest.mark.parametrize(
    "mode, compressed, header",
    [("Appended", True, 32), ("Appended", False, 32), ("Appended", True, 64), ("Appended", False, 64),
     ("Binary", True, 32), ("Binary", False, 64), ("Ascii", False, 32)],
)  # fmt: skip
def test_files_vtks_writer_makes(tmp_path, mode, compressed, header):
    """pyvista's uniform.vtk as VTK's own reader sees it (point scalars x*y*z
    after a cell array: the scalars at a non-zero appended offset), written
    by VTK's XML writer in each data mode; ParaView and VTK write raw
    appended data by default. clvis reads the values VTK reads back."""
    vtk = pytest.importorskip("vtk", reason="vtk is in the test extra")
    from vtk.util import numpy_support

    r = vtk.vtkStructuredPointsReader()
    r.SetFileName(str(DATA / "pyvista_uniform.vtk"))
    r.ReadAllScalarsOn()
    r.Update()
    img = r.GetOutput()
    assert img.GetCellData().GetNumberOfArrays() >= 1  # written before the point data
    w = vtk.vtkXMLImageDataWriter()
    path = tmp_path / f"{mode}.vti"
    w.SetFileName(str(path))
    w.SetInputData(img)
    getattr(w, f"SetDataModeTo{mode}")()
    w.SetEncodeAppendedData(False)
    if not compressed:
        w.SetCompressorTypeToNone()
    if header == 64:
        w.SetHeaderTypeToUInt64()
    assert w.Write() == 1
    text = path.read_bytes()
    assert (b'format="appended"' in text) == (mode == "Appended")
    back = vtk.vtkXMLImageDataReader()
    back.SetFileName(str(path))
    back.Update()
    scalars = back.GetOutput().GetPointData().GetScalars()
    want = numpy_support.vtk_to_numpy(scalars).reshape(back.GetOutput().GetDimensions()[::-1])
    v = read_volume(path)
    np.testing.assert_array_equal(v.data, want)
    z, y, x = np.mgrid[:10, :10, :10]
    np.testing.assert_array_equal(v.data, x * y * z)


@pytest.mark.parametrize("attr", [b'Origin="5 6 7"', b'Spacing="1 2 3"', b'format="binary"'])
def test_vti_attribute_not_utf8_is_a_data_error(tmp_path, attr):
    # a byte that is not UTF-8 in an attribute's value: UnicodeDecodeError escaped
    # (./dev.sh fuzz with .vti seeds: 35 of 483 mutants)
    data = _vti(np.arange(24, dtype=np.float32).reshape(2, 3, 4), "binary")
    assert attr in data
    path = tmp_path / "bad.vti"
    path.write_bytes(data.replace(attr, attr[:-2] + b"\xe9" + attr[-2:]))
    with pytest.raises(DataError) as e:
        read_volume(path)
    assert str(path) in str(e.value)


def _uniform():
    import vtk

    r = vtk.vtkStructuredPointsReader()
    r.SetFileName(str(DATA / "pyvista_uniform.vtk"))
    r.ReadAllScalarsOn()
    r.Update()
    return r.GetOutput()


@pytest.mark.parametrize("compressed", [True, False])
def test_base64_appended_data_reads(tmp_path, compressed):
    """VTK's writer with EncodeAppendedData on (base64 appended), which the
    hand-written reader refused."""
    vtk = pytest.importorskip("vtk", reason="vtk is in the test extra")
    w = vtk.vtkXMLImageDataWriter()
    path = tmp_path / "b64.vti"
    w.SetFileName(str(path))
    w.SetInputData(_uniform())
    w.SetDataModeToAppended()
    w.SetEncodeAppendedData(True)
    if not compressed:
        w.SetCompressorTypeToNone()
    assert w.Write() == 1
    assert b'<AppendedData encoding="base64">' in path.read_bytes()
    z, y, x = np.mgrid[:10, :10, :10]
    np.testing.assert_array_equal(read_volume(path).data, x * y * z)


def test_several_pieces_read(tmp_path):
    """A .vti of two pieces (z 0-1 ascii, z 2-4 zlib-compressed binary): VTK
    joins them; a WholeExtent the pieces do not cover is refused."""
    data = np.arange(5 * 6 * 7, dtype=np.float32).reshape(5, 6, 7)
    one = _vti(data[:2], "ascii")
    two = _vti(data[2:], "zlib")
    piece_one = one[one.index(b"<Piece") : one.index(b"</Piece>") + 8]
    piece_two = two[two.index(b"<Piece") : two.index(b"</Piece>") + 8].replace(b"0 1 0 5 0 2", b"0 6 0 5 2 4")
    piece_two = piece_two.replace(b'Extent="0 6 0 5 0 2"', b'Extent="0 6 0 5 2 4"')
    text = two.replace(two[two.index(b"<Piece") : two.index(b"</Piece>") + 8], piece_one + b"\n" + piece_two)
    text = text.replace(b'WholeExtent="0 6 0 5 0 2"', b'WholeExtent="0 6 0 5 0 4"')
    path = tmp_path / "pieces.vti"
    path.write_bytes(text)
    assert text.count(b"<Piece") == 2
    v = read_volume(path)
    np.testing.assert_array_equal(v.data, data)
    path.write_bytes(text.replace(b'WholeExtent="0 6 0 5 0 4"', b'WholeExtent="0 6 0 5 0 5"'))
    with pytest.raises(DataError, match="the pieces hold 210 samples"):
        read_volume(path)


def test_vtk_errors_become_data_errors_and_stay_off_stderr(tmp_path, capfd):
    """A file whose header is sound and whose compressed bytes are not: VTK's
    own error becomes the DataError; VTK prints nothing; VTK's global
    warning display is on again after."""
    vtk = pytest.importorskip("vtk", reason="vtk is in the test extra")
    data = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)
    good = _vti(data, "zlib")
    lines = good.split(b"\n")
    head = base64.b64encode(np.array([1, 96, 0, 20], "<u4").tobytes())
    lines[6] = head + base64.b64encode(b"\x78\x9c" + b"\xff" * 18)  # not a zlib stream
    path = tmp_path / "garbled.vti"
    path.write_bytes(b"\n".join(lines))
    before = vtk.vtkObject.GetGlobalWarningDisplay()
    with pytest.raises(DataError, match="VTK could not read it") as e:
        read_volume(path)
    assert str(e.value).count(str(path)) == 1
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    assert vtk.vtkObject.GetGlobalWarningDisplay() == before == 1  # VTK's setting put back
    cutoff = vtk.vtkLogger.GetCurrentVerbosityCutoff()
    # a legacy file whose second SCALARS VTK's logger complains about (the fuzzer's find: it
    # printed to stderr past the global warning display)
    legacy = tmp_path / "second.vtk"
    legacy.write_text(
        "# vtk DataFile Version 3.0\nx\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 1 1\n"
        "POINT_DATA 2\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2\nSCALARS t float zz\n"
        "LOOKUP_TABLE default\n3 4\n"
    )
    try:
        np.testing.assert_array_equal(read_volume(legacy).data, [[[1, 2]]])
    except DataError:
        pass  # either way: nothing on stderr
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    assert vtk.vtkLogger.GetCurrentVerbosityCutoff() == cutoff


def test_vtk_reads_in_threads_put_vtks_settings_back(tmp_path):
    """Reads in several threads at once (a Dask worker's threads): VTK's
    global warning display and logger cutoff are what they were after the
    last one ends, whatever the interleaving (each read saving and restoring
    the globals itself could leave them off)."""
    import threading

    vtk = pytest.importorskip("vtk", reason="vtk is in the test extra")
    data = np.arange(4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6)
    paths = []
    for i, enc in enumerate(("ascii", "zlib", "binary", "zlib")):
        paths.append(tmp_path / f"{i}.vti")
        paths[-1].write_bytes(_vti(data, enc))
    before = (vtk.vtkObject.GetGlobalWarningDisplay(), vtk.vtkLogger.GetCurrentVerbosityCutoff())
    errors: list[BaseException] = []

    def reads(p):
        try:
            for _ in range(15):
                np.testing.assert_array_equal(read_volume(p).data, data)
        except BaseException as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=reads, args=(p,)) for p in paths]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert not errors, errors
    assert (vtk.vtkObject.GetGlobalWarningDisplay(), vtk.vtkLogger.GetCurrentVerbosityCutoff()) == before


def test_missing_vtk_names_the_extra(tmp_path, monkeypatch):
    path = tmp_path / "a.vti"
    path.write_bytes(_vti(np.zeros((2, 2, 2), np.float32), "ascii"))
    monkeypatch.setitem(sys.modules, "vtkmodules", None)
    with pytest.raises(ImportError, match=r'pip install "clvis\[vtk\]"'):
        read_volume(path)


def test_lz4_reads_lzma_is_refused(tmp_path):
    """VTK's LZ4 compressor reads (its ratio bounds the header's sizes);
    LZMA, whose ratio does not bound memory, is refused before VTK reads."""
    vtk = pytest.importorskip("vtk", reason="vtk is in the test extra")
    z, y, x = np.mgrid[:10, :10, :10]
    for compressor in ("LZ4", "LZMA"):
        w = vtk.vtkXMLImageDataWriter()
        path = tmp_path / f"{compressor}.vti"
        w.SetFileName(str(path))
        w.SetInputData(_uniform())
        getattr(w, f"SetCompressorTypeTo{compressor}")()
        assert w.Write() == 1
        if compressor == "LZ4":
            np.testing.assert_array_equal(read_volume(path).data, x * y * z)
        else:
            with pytest.raises(DataError, match="vtkLZMADataCompressor is not read"):
                read_volume(path)


@pytest.mark.parametrize("mode", ["Appended", "Binary", "Ascii"])
def test_cell_data_is_the_volume_where_no_point_array_is(tmp_path, mode):
    """A .vti holding cell data only (a simulation's cell-centred field, as
    pyvista's channels.vti): one sample a cell, its origin at the first
    cell's centre; its byte count is checked against the cells, not the
    points (a count claiming the points' is refused)."""
    vtk = pytest.importorskip("vtk", reason="vtk is in the test extra")
    from vtk.util import numpy_support

    img = vtk.vtkImageData()
    img.SetDimensions(5, 4, 3)  # points; cells 4 x 3 x 2
    img.SetOrigin(1.0, 2.0, 3.0)
    img.SetSpacing(1.0, 2.0, 3.0)
    cells = (np.arange(24, dtype=np.int64) * 7 % 11).reshape(2, 3, 4)
    arr = numpy_support.numpy_to_vtk(cells.ravel(), deep=True)
    arr.SetName("facies")
    img.GetCellData().SetScalars(arr)
    w = vtk.vtkXMLImageDataWriter()
    path = tmp_path / "cells.vti"
    w.SetFileName(str(path))
    w.SetInputData(img)
    getattr(w, f"SetDataModeTo{mode}")()
    w.SetCompressorTypeToNone()
    assert w.Write() == 1
    assert b"<CellData" in path.read_bytes()
    v = read_volume(path)
    np.testing.assert_array_equal(v.data, cells)
    assert v.spacing == (3.0, 2.0, 1.0) and v.origin == (1.5, 3.0, 4.5)
    if mode == "Binary":  # the array's byte count as if it held a value a point
        text = path.read_bytes()
        body = text[text.index(b"<DataArray") :]
        start = body.index(b">") + 1
        blob = body[start : body.index(b"</DataArray>")].strip()
        raw = base64.b64decode(blob)[4:]  # after its 4-byte count
        forged = base64.b64encode(np.array([60 * 8], "<u4").tobytes() + raw + bytes(36 * 8))
        path.write_bytes(text.replace(blob, forged))
        with pytest.raises(DataError, match="byte count"):
            read_volume(path)


def _structured_points(path, point=(), cell=(), binary=False):
    """A legacy STRUCTURED_POINTS file of 4 x 3 x 2 points (3 x 2 x 1 cells)
    as VTK's writer makes it: `point` and `cell` [(name, values, scalars)],
    each array the section's SCALARS where `scalars`, else (as VTK writes
    every other array) a FIELD array."""
    from vtkmodules.util import numpy_support as ns
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkIOLegacy import vtkStructuredPointsWriter

    img = vtkImageData()
    img.SetDimensions(4, 3, 2)
    img.SetSpacing(1.0, 2.0, 3.0)
    img.SetOrigin(1.0, 2.0, 3.0)
    for data, arrays in ((img.GetPointData(), point), (img.GetCellData(), cell)):
        for name, values, scalars in arrays:
            a = ns.numpy_to_vtk(np.ascontiguousarray(values), deep=True)
            a.SetName(name)
            data.SetScalars(a) if scalars else data.AddArray(a)
    w = vtkStructuredPointsWriter()
    w.SetFileName(str(path))
    w.SetInputData(img)
    w.SetFileTypeToBinary() if binary else w.SetFileTypeToASCII()
    assert w.Write() == 1


@pytest.mark.parametrize("binary", [False, True])
def test_legacy_cell_data_and_field_arrays(tmp_path, binary):
    """A legacy .vtk whose point data has no SCALARS gives its first FIELD
    array of one component (VTK writes every array but the scalars as a
    FIELD); one without point arrays gives its cell data (one sample a
    cell, the origin at the first cell's centre), as a .vti does;
    array=NAME finds point, then cell, SCALARS and FIELD arrays, and a name
    the file lacks lists the arrays it has."""
    p = tmp_path / "v.vtk"
    pts, cells = np.arange(24, dtype=np.float32) * 3 % 7, np.arange(6, dtype=np.int16) - 3
    _structured_points(p, cell=[("c", cells, True)], binary=binary)
    v = read_volume(p)
    assert v.array == "c" and v.data.dtype == np.int16
    np.testing.assert_array_equal(v.data, cells.reshape(1, 2, 3))
    assert v.spacing == (3.0, 2.0, 1.0) and v.origin == (1.5, 3.0, 4.5)
    _structured_points(p, point=[("f", pts, False), ("g", -pts, False)], binary=binary)
    assert b"FIELD FieldData 2" in p.read_bytes() and b"SCALARS" not in p.read_bytes()
    v = read_volume(p)
    assert v.array == "f" and v.origin == (1.0, 2.0, 3.0)
    np.testing.assert_array_equal(v.data, pts.reshape(2, 3, 4))
    np.testing.assert_array_equal(read_volume(p, array="g").data, -pts.reshape(2, 3, 4))
    vectors = np.arange(72, dtype=np.float64).reshape(24, 3)
    _structured_points(
        p,
        point=[("s", pts, True), ("vec", vectors, False)],
        cell=[("cs", cells, True), ("cf", cells * 2, False)],
        binary=binary,
    )
    assert read_volume(p).array == "s"
    for name, want in (("cs", cells), ("cf", cells * 2)):
        v = read_volume(p, array=name)
        assert v.array == name and v.origin == (1.5, 3.0, 4.5)
        np.testing.assert_array_equal(v.data, want.reshape(1, 2, 3))
    with pytest.raises(
        DataError, match=r"v\.vtk: no array 'nope' \(point arrays: s, vec; cell arrays: cs, cf\)"
    ):
        read_volume(p, array="nope")
    with pytest.raises(DataError, match=r"point FIELD 'vec' \(3 components of type double\): one component"):
        read_volume(p, array="vec")
    # only arrays of several components: none is the default, the arrays listed
    _structured_points(p, point=[("vec", vectors, False)], binary=binary)
    with pytest.raises(
        DataError, match=r"no SCALARS or FIELD array of one component .*\(point arrays: vec\)"
    ):
        read_volume(p)
    # a RECTILINEAR_GRID's cell data alike
    x, y, z = np.arange(4) * 0.5 + 1, np.arange(3) * 2.0 - 3, np.linspace(0, 1, 5)
    grid_cells = np.arange(3 * 2 * 4, dtype=np.float32)
    _rectilinear(tmp_path / "g.vtk", x, y, z, grid_cells, binary, cells=True)
    v = read_volume(tmp_path / "g.vtk")
    np.testing.assert_array_equal(v.data, grid_cells.reshape(4, 2, 3))
    assert v.spacing == pytest.approx((0.25, 2.0, 0.5)) and v.origin == pytest.approx((1.25, -2.0, 0.125))


def test_pyvista_uniform_cell_field_array():
    """pyvista's uniform.vtk: its cell data is a FIELD array (Spatial Cell
    Data, before the point SCALARS), read by name as VTK reads it."""
    from vtkmodules.util import numpy_support as ns
    from vtkmodules.vtkIOLegacy import vtkStructuredPointsReader

    v = read_volume(DATA / "pyvista_uniform.vtk", array="Spatial Cell Data")
    r = vtkStructuredPointsReader()
    r.SetFileName(str(DATA / "pyvista_uniform.vtk"))
    r.Update()
    want = ns.vtk_to_numpy(r.GetOutput().GetCellData().GetArray("Spatial Cell Data"))
    assert v.shape == (9, 9, 9) and v.origin == (0.5, 0.5, 0.5) and v.array == "Spatial Cell Data"
    np.testing.assert_array_equal(v.data.ravel(), want)
    with pytest.raises(DataError, match="point arrays: Spatial Point Data; cell arrays: Spatial Cell Data"):
        read_volume(DATA / "pyvista_uniform.vtk", array="nope")


def test_legacy_field_header_lies_are_refused_before_vtk_reads(tmp_path):
    """A FIELD array's hostile counts (more tuples than the file holds, a
    negative count, a count that is not the section's) and data sections
    that are not the grid's are DataErrors naming what is wrong, before VTK
    reads or allocates."""
    head = "# vtk DataFile Version 3.0\nx\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 3 2\n"
    head += "SPACING 1 1 1\nORIGIN 0 0 0\n"
    values = " ".join(str(k) for k in range(12)) + "\n"
    good = head + "POINT_DATA 12\nFIELD FieldData 1\nf 1 12 float\n" + values
    p = tmp_path / "f.vtk"
    p.write_text(good)
    np.testing.assert_array_equal(read_volume(p).data.ravel(), np.arange(12))
    for text, message in (
        (good.replace("f 1 12 float", "f 1 2000000000 float"), "field array 'f' declares 2000000000 values"),
        (good.replace("f 1 12 float", "f 1 -12 float"), "malformed field array tuples count '-12'"),
        (good.replace("f 1 12 float", "f -1 12 float"), "malformed field array components count '-1'"),
        (
            good.replace("f 1 12 float", "f 1 6 float"),
            "point FIELD array 'f' holds 6 tuples, the point data 12",
        ),
        (
            good.replace("f 1 12 float\n" + values, "f 1 12 string\n" + "a\n" * 12),
            "one component of a numeric",
        ),
        (good.replace("FieldData 1", "FieldData 4000000000"), "FIELD of 4000000000 arrays"),
        (good.replace("POINT_DATA 12", "POINT_DATA 4000000000"), "POINT_DATA 4000000000 does not match"),
        (
            good.replace("POINT_DATA 12", "CELL_DATA 12"),
            r"CELL_DATA 12 does not match DIMENSIONS 2 3 2 \(2 cells\)",
        ),
        (good + "CELL_DATA 2\nFIELD c 1\nc 1 99999999 int\n0 0\n", "field array 'c' declares 99999999"),
    ):
        p.write_text(text)
        with pytest.raises(DataError, match=message):
            read_volume(p)
    binary = (
        head.replace("ASCII", "BINARY").encode()
        + b"CELL_DATA 2\nFIELD FieldData 1\nc 1 2 double\n"
        + np.array([5.0, -1.0], ">f8").tobytes()
        + b"\n"
    )
    p.write_bytes(binary)
    v = read_volume(p)
    np.testing.assert_array_equal(v.data, [[[5.0], [-1.0]]])  # cells (x, y, z) = (1, 2, 1)
    p.write_bytes(binary.replace(b"c 1 2 double", b"c 1 3 double"))
    with pytest.raises(DataError, match="truncated or malformed: field array 'c' declares 3 values"):
        read_volume(p)


@pytest.mark.parametrize(
    "line, after",
    [
        ("FIELD FieldS 2 float", "0 2\n"),  # ./dev.sh fuzz's mutant (a bit flip and a splice): SIGSEGV
        ("Y_COORDINATES 2", "float\n"),  # VTK reads the type from the next line
        ("POINT_DATA 12 13", ""),
    ],
)
def test_a_known_section_line_not_as_vtk_writes_it_is_refused(tmp_path, line, after):
    """VTK reads a legacy file's sections word by word across lines; the
    checks walk them line by line: an ASCII line of a section they know
    with other words than VTK writes (a FIELD line of four words, whose
    fourth VTK took for the first array's name and crashed on) is a
    DataError, read in a child process, before VTK reads."""
    from fuzz.harness import run_limited

    coords = "X_COORDINATES 3 float\n0 1 2\nY_COORDINATES 2 float\n0 2\nZ_COORDINATES 2 float\n0 0.5\n"
    text = (
        "# vtk DataFile Version 3.0\nclvis seed\nASCII\nDATASET RECTILINEAR_GRID\nDIMENSIONS 3 2 2\n"
        + coords
        + "POINT_DATA 12\nSCALARS v float 1\nLOOKUP_TABLE default\n0 1 2 3 4 5 6 7 8 9 10 11\n"
    )
    path = tmp_path / "grid.vtk"
    path.write_text(text)
    assert read_volume(path).shape == (2, 2, 3)
    if line.startswith("FIELD"):
        text = text.replace("Y_COORDINATES 2 float\n0 2\n", f"Y_COORDINATE5 -2\n{line}\n{after}")
    else:  # the section's line as VTK wrote it, replaced
        text = re.sub(rf"(?m)^{line.split()[0]} [^\n]*\n", lambda _: f"{line}\n{after}", text, count=1)
    path.write_text(text)
    r = run_limited(read_volume, str(path), name=str(path), limit_bytes=1 << 30)
    assert r.kind == "clvis" and "malformed or unknown legacy VTK section" in r.detail, r


def _vtr(path, x, y, z, values, mode, cells=False, compress=True):
    """A .vtr (XML RectilinearGrid) as VTK's writer makes it (what pyvista's
    RectilinearGrid.save("x.vtr") writes): `values` a point (or `cells`: a
    cell) array named "v", in `mode` (Ascii, Binary, Appended)."""
    from vtkmodules.vtkIOXML import vtkXMLRectilinearGridWriter

    w = vtkXMLRectilinearGridWriter()
    w.SetFileName(str(path))
    w.SetInputData(_grid(x, y, z, values, cells))
    getattr(w, f"SetDataModeTo{mode}")()
    if not compress:
        w.SetCompressorTypeToNone()
    assert w.Write() == 1


def test_vtr_header_lies_are_refused_before_vtk_reads(tmp_path):
    """A .vtr whose coordinate arrays do not match its extent (too few, a
    byte count of another size, a missing <Coordinates>) or whose extent
    claims more samples than the file holds is a DataError naming it."""
    x, y, z = np.arange(4.0), np.arange(3.0), np.arange(2.0)
    values = np.arange(24, dtype=np.float32)
    p = tmp_path / "lie.vtr"
    _vtr(p, x, y, z, values, "Binary", compress=False)
    good = p.read_bytes()
    assert read_volume(p).shape == (2, 3, 4)

    def bad(content, message):
        p.write_bytes(content)
        with pytest.raises(DataError, match=message):
            read_volume(p)

    big = good.replace(b'WholeExtent="0 3 0 2 0 1"', b'WholeExtent="0 3 0 2 0 99999"')
    bad(big.replace(b'Extent="0 3 0 2 0 1"', b'Extent="0 3 0 2 0 99999"'), "byte count")
    coords = good[good.index(b"<Coordinates>") : good.index(b"</Coordinates>") + len(b"</Coordinates>")]
    bad(good.replace(coords, b""), "three <Coordinates> arrays")
    first = coords.index(b"<DataArray")
    end = coords.index(b"</DataArray>") + len(b"</DataArray>")
    bad(good.replace(coords, coords[:first] + coords[end:]), "three <Coordinates> arrays")
    # the X coordinates' byte count claims 5 doubles where the extent has 4 points
    blob = coords[coords.index(b">", first) + 1 : coords.index(b"</DataArray>")].strip()
    raw = base64.b64decode(blob)
    forged = base64.b64encode(np.array([5 * 8], "<u4").tobytes() + raw[4:] + bytes(8))
    bad(good.replace(blob, forged), "byte count")
    bad(good.replace(b'type="RectilinearGrid"', b'type="ImageData"', 1), "not a VTK RectilinearGrid file")


def test_array_picks_a_vtk_files_data_array(tmp_path):
    """read_volume(array=NAME): a .vti's or .vtr's point array by name, else
    its cell array; a legacy .vtk's point SCALARS of that name (not the
    first); Volume.array names the array read (the default's too); a name
    the file lacks is a DataError listing what it has; other formats refuse
    the keyword."""
    from vtkmodules.util import numpy_support as ns
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

    img = vtkImageData()
    img.SetDimensions(4, 3, 2)
    values = {"a": np.arange(24, dtype=np.float32), "b": np.arange(24, dtype=np.float32) * -2}
    for k, v in values.items():
        arr = ns.numpy_to_vtk(v, deep=True)
        arr.SetName(k)
        img.GetPointData().AddArray(arr)
    img.GetPointData().SetActiveScalars("a")
    cells = ns.numpy_to_vtk(np.arange(6, dtype=np.int32) + 100, deep=True)
    cells.SetName("c")
    img.GetCellData().AddArray(cells)
    w = vtkXMLImageDataWriter()
    w.SetFileName(str(tmp_path / "v.vti"))
    w.SetInputData(img)
    assert w.Write() == 1
    p = tmp_path / "v.vti"
    assert read_volume(p).array == "a"
    v = read_volume(p, array="b")
    assert v.array == "b"
    np.testing.assert_array_equal(v.data, values["b"].reshape(2, 3, 4))
    c = read_volume(p, array="c")
    np.testing.assert_array_equal(c.data, (np.arange(6) + 100).reshape(1, 2, 3))
    with pytest.raises(DataError, match=r"v\.vti: no array 'nope' \(point arrays: a, b; cell arrays: c\)"):
        read_volume(p, array="nope")
    x, y, z = np.arange(4.0), np.arange(3.0), np.arange(2.0)
    _vtr(tmp_path / "g.vtr", x, y, z, values["a"], "Binary")
    assert read_volume(tmp_path / "g.vtr", array="v").array == "v"
    legacy = tmp_path / "two.vtk"
    text = " ".join(map(str, range(24)))
    legacy.write_text(
        "# vtk DataFile Version 3.0\ntwo\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 4 3 2\n"
        f"SPACING 1 1 1\nORIGIN 0 0 0\nPOINT_DATA 24\nSCALARS first float 1\nLOOKUP_TABLE default\n{text}\n"
        f"SCALARS second%20one int 1\nLOOKUP_TABLE default\n{' '.join(str(-i) for i in range(24))}\n"
    )
    assert read_volume(legacy).array == "first"
    v = read_volume(legacy, array="second one")  # legacy names encode a space as %20
    np.testing.assert_array_equal(v.data, -np.arange(24).reshape(2, 3, 4))
    assert v.array == "second one"
    with pytest.raises(DataError, match=r"two\.vtk: no array 'third' \(point arrays: first, second one\)"):
        read_volume(legacy, array="third")
    np.save(tmp_path / "v.npy", np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="array: a data array's name"):
        read_volume(tmp_path / "v.npy", array="a")
