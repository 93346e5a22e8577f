"""VTK image data volumes, read by VTK's own readers (the ``vtk`` extra):
XML ``.vti`` (ImageData; vtkXMLImageDataReader: ascii, inline binary,
raw or base64 appended data, zlib- or LZ4-compressed or not, one piece or
several), XML ``.vtr`` (RectilinearGrid, vtkXMLRectilinearGridReader, the
same encodings) and legacy ``.vtk`` STRUCTURED_POINTS
(vtkStructuredPointsReader, ASCII or BINARY) or RECTILINEAR_GRID
(vtkRectilinearGridReader); a rectilinear grid only where its coordinates
are evenly spaced along each axis (pyvista writes a RectilinearGrid so;
uneven ones are refused, naming the axis: clvis volumes are uniform grids).
The volume is the point data's ``Scalars`` array (.vti, .vtr: the one
``<PointData Scalars=...>`` names, else the first point array; .vtk: the
first POINT_DATA SCALARS, else the first one-component FIELD array of the
point data: VTK writes every array but the scalars as a FIELD), one
component. A file with no point array (a simulation's cell-centred field,
e.g. pyvista's ``channels.vti``) gives its cell data the same way: one
sample a cell, the origin moved to the first cell's centre. ``array=NAME``
picks a point array, else a cell array, by name (a legacy file's SCALARS
or FIELD arrays); a name the file lacks is a DataError listing its arrays.

Bounded: before VTK reads, the header is checked against the file (the
hardening of the other readers): the extents, the array's type and
components, and for every piece the byte count or compressed-block header of
the array (and of a .vtr's coordinate arrays) against its extent and the
bytes the file holds, so that a few
hostile bytes cannot make VTK allocate gigabytes; a DTD or entity declaration
is refused (no entity expansion). VTK reads only the chosen array. VTK's
error messages become a DataError naming the file; nothing reaches stderr.
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import re
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..errors import DataError

_VTI_TYPES = {
    "Int8": "i1", "UInt8": "u1", "Int16": "i2", "UInt16": "u2", "Int32": "i4", "UInt32": "u4",
    "Int64": "i8", "UInt64": "u8", "Float32": "f4", "Float64": "f8",
}  # fmt: skip
_LEGACY_TYPES = {
    "unsigned_char": "u1", "char": "i1", "unsigned_short": "u2", "short": "i2", "unsigned_int": "u4",
    "int": "i4", "unsigned_long": "u8", "long": "i8", "float": "f4", "double": "f8",
}  # fmt: skip
# the most a compressed block can expand (zlib ~1032x, LZ4 ~255x): a header claiming more lies
_MAX_RATIO = {"vtkZLibDataCompressor": 1100, "vtkLZ4DataCompressor": 260}


def _vtk() -> Any:
    """VTK's modules clvis uses (imported only here: the ``vtk`` extra)."""
    try:
        from vtkmodules import vtkCommonCore, vtkIOLegacy, vtkIOXML
        from vtkmodules.util import numpy_support
    except ImportError:
        raise ImportError(
            'reading .vti/.vtk volumes needs VTK: pip install "clvis[vtk]" (".[vtk]" in a clvis checkout, '
            "or pip install vtk)"
        ) from None
    return vtkCommonCore, vtkIOLegacy, vtkIOXML, numpy_support


# _quiet's hold on VTK's three globals: the reads in flight (any thread) and what
# the globals were before the first of them
_QUIET_LOCK = threading.Lock()
_quiet_held: list[Any] = []  # [(warning display, logger cutoff, output window)] while reads are in flight
_quiet_count = 0


@contextlib.contextmanager
def _quiet(core: Any) -> Iterator[list[str]]:
    """VTK's messages kept off stderr for the duration: VTK's output window
    a string window (what no observer takes goes there, unread) and its
    logger's stderr output off, its global warning display on (VTK's error
    macros invoke the ErrorEvent only while it is on: with it off a reader's
    errors were lost, and a legacy file whose cells VTK could not read gave
    its points without their data, no error), all put back as they were
    when the last read in flight ends (counted under a lock, so reads in
    several threads cannot restore each other's settings or leave them
    changed; other VTK code in the process is quiet while a read runs); the
    readers' own errors reach the list yielded through an ErrorEvent
    observer (:func:`_observe`)."""
    global _quiet_count
    with _QUIET_LOCK:
        if _quiet_count == 0:
            # the logger's cutoff is its stderr verbosity where no callback is added (VTK's Python has none)
            _quiet_held[:] = [
                (
                    core.vtkObject.GetGlobalWarningDisplay(),
                    core.vtkLogger.GetCurrentVerbosityCutoff(),
                    core.vtkOutputWindow.GetInstance(),
                )
            ]
            core.vtkOutputWindow.SetInstance(core.vtkStringOutputWindow())
            core.vtkObject.GlobalWarningDisplayOn()
            core.vtkLogger.SetStderrVerbosity(core.vtkLogger.VERBOSITY_OFF)
        _quiet_count += 1
    try:
        yield []
    finally:
        with _QUIET_LOCK:
            _quiet_count -= 1
            if _quiet_count == 0:
                shown, logged, window = _quiet_held.pop()
                core.vtkLogger.SetStderrVerbosity(logged)
                core.vtkObject.SetGlobalWarningDisplay(shown)
                core.vtkOutputWindow.SetInstance(window)


def _observe(core: Any, obj: Any, messages: list[str]) -> None:
    def seen(_obj: Any, _event: str, data: Any = None) -> None:
        messages.append(str(data) if data is not None else "error")

    seen.CallDataType = core.VTK_STRING  # type: ignore[attr-defined]  # the message as the call data
    obj.AddObserver("ErrorEvent", seen)


def _why(messages: list[str]) -> str:
    text = " ".join(" ".join(messages).split())
    text = re.sub(r"(ERROR|Warning): In [^,]*, line \d+\s*", "", text)
    return text[:300] or "its reader failed (data that do not decode, or fewer values than declared)"


def _attrs(tag: bytes) -> dict[str, str]:
    # latin-1: any byte decodes (VTK writes ASCII; a stray byte fails later, on its value)
    return {k.decode("latin-1"): v.decode("latin-1") for k, v in re.findall(rb'(\w+)\s*=\s*"([^"]*)"', tag)}


def _numbers(path: Path, what: str, text: str, n: int, kind: type = float) -> list:
    try:
        v = [kind(t) for t in text.split()]
    except ValueError:
        v = []
    if len(v) != n:
        raise DataError(f"{path}: malformed {what} {text!r} (expected {n} numbers)")
    return v


def _components(attrs: dict[str, str]) -> str:
    """A DataArray's NumberOfComponents as written, "1" where it is absent or
    blank: VTK's XML readers keep one component where the attribute holds no
    number (meshio writes NumberOfComponents="")."""
    return attrs.get("NumberOfComponents", "").strip() or "1"


def _count(path: Path, what: str, ext: list[int]) -> int:
    dims = (ext[1] - ext[0] + 1, ext[3] - ext[2] + 1, ext[5] - ext[4] + 1)
    if min(dims) < 1:
        raise DataError(f"{path}: empty {what} {ext}")
    return dims[0] * dims[1] * dims[2]


def _elements(xml: bytes, tag: str) -> tuple[list[tuple[int, int, bytes, bytes]], int]:
    """([(start, end, attributes, body)] of each <tag ...>body</tag> or
    <tag .../> in `xml`, in order, and how many tags open one): one pass
    over the tags and one over the closing tags, paired in order (VTK's
    elements of one kind do not nest). Regular expressions that search for
    each tag's end took time quadratic in the tags a hostile file leaves
    unclosed (8,000 in 140 kB: 11 s); an unclosed one here has no body and
    is not listed."""
    name = tag.encode()
    closes = [(m.start(), m.end()) for m in re.finditer(rb"</" + name + rb"\s*>", xml)]
    found, opened, j = [], 0, 0
    for m in re.finditer(rb"<" + name + rb"\b([^<>]*)>", xml):  # no '<' or '>' inside a tag: linear
        opened += 1
        if m.group(1).endswith(b"/"):
            found.append((m.start(), m.end(), m.group(1)[:-1], b""))
            continue
        while j < len(closes) and closes[j][0] < m.end():
            j += 1
        if j < len(closes):
            found.append((m.start(), closes[j][1], m.group(1), xml[m.end() : closes[j][0]]))
            j += 1
    return found, opened


def _arrays(section: bytes) -> list[tuple[dict[str, str], bytes]]:
    """The (attributes, body) of each <DataArray .../> (an appended array, as
    VTK writes it) or <DataArray ...>text</DataArray> in `section`; a body
    ends where VTK's range after some arrays' values begins (<InformationKey
    name="L2_NORM_RANGE" ...>)."""
    return [
        (_attrs(a), b.split(b"<InformationKey", 1)[0]) for _, _, a, b in _elements(section, "DataArray")[0]
    ]


def _xml_part(path: Path, raw: bytes) -> tuple[int, bytes]:
    """(where <AppendedData> starts or -1, the XML before it) of a VTK XML
    file; a DataError for a DTD or entity declaration (no entity expansion)."""
    if b"<!DOCTYPE" in raw[:4096] or b"<!ENTITY" in raw[:4096]:
        raise DataError(f"{path}: a VTK file with a DTD or entities is not read")
    at = raw.find(b"<AppendedData")
    return at, raw if at < 0 else raw[:at]  # the appended bytes are not XML: never searched as such


def _xml_head(path: Path, xml: bytes, kind: str) -> tuple[dict[str, str], dict[str, str]]:
    """(the <VTKFile> attributes, the <`kind`> attributes) of a VTK XML file
    of that type; a DataError for any other file, comments or CDATA, or a
    compressor that is not read."""
    head = re.findall(rb"<VTKFile\b[^<>]*>", xml)
    data = re.findall(rb"<" + kind.encode() + rb"\b[^<>]*>", xml)
    if len(head) != 1 or len(data) != 1 or _attrs(head[0]).get("type", kind) != kind:
        raise DataError(f'{path}: not a VTK {kind} file (no <VTKFile type="{kind}"> and <{kind}>)')
    if b"<!--" in xml or b"<![CDATA[" in xml:
        raise DataError(f"{path}: XML comments or CDATA in a VTK file are not read")
    fa = _attrs(head[0])
    compressor = fa.get("compressor")
    if compressor is not None and compressor not in _MAX_RATIO:
        raise DataError(f"{path}: compressor {compressor} is not read (zlib or LZ4)")
    return fa, _attrs(data[0])


def _check_grid(
    path: Path, raw: bytes, kind: str = "ImageData", array: str | None = None
) -> tuple[str, int, str]:
    """Check a .vti's (`kind` "ImageData") or .vtr's ("RectilinearGrid")
    header against the file before VTK reads it: (the name of the array
    that is the volume, its samples, "cell" where it is cell data else "");
    a DataError naming the file for what is not read or lies about its
    size. `array`: that point (else cell) array, by name; by default the
    point data's Scalars, else its first array, else the cell data's. A
    .vtr's pieces hold their coordinates too: three one-component arrays of
    their extent's points along X, Y and Z, checked the same way."""
    at, xml = _xml_part(path, raw)
    fa, ia = _xml_head(path, xml, kind)
    whole = _numbers(path, "WholeExtent", ia.get("WholeExtent", ""), 6, int)
    n = _count(path, "WholeExtent", whole)
    if kind == "ImageData":
        _numbers(path, "Spacing", ia.get("Spacing", "1 1 1"), 3)
        _numbers(path, "Origin", ia.get("Origin", "0 0 0"), 3)
    elements, opened = _elements(xml, "Piece")
    pieces = [(tag, body) for _, _, tag, body in elements]
    if not pieces or len(pieces) != opened:
        raise DataError(f"{path}: malformed {kind}: no <Piece>...</Piece>")
    name, covered, where = None, 0, ""
    if array is not None:  # the named array, among the first piece's point arrays, else its cell arrays
        names = {
            tag: [a.get("Name") for a, _ in (_section(pieces[0][1], tag) or (b"", []))[1]]
            for tag in ("PointData", "CellData")
        }
        if array in names["PointData"]:
            name = array
        elif array in names["CellData"]:
            name, where = array, "cell"
            n = _count(path, "WholeExtent", _cells(whole))
        else:
            listed = "; ".join(
                f"{t[:-4].lower()} arrays: {', '.join(map(str, v))}" for t, v in names.items() if v
            )
            raise DataError(f"{path}: no array {array!r} ({listed or 'no arrays'})")
    elif not any(_section(body, "PointData") for _, body in pieces):
        if not any(_section(body, "CellData") for _, body in pieces):
            raise DataError(f"{path}: no point or cell data array")
        where = "cell"  # no point array in any piece: the cell data is the volume
        n = _count(path, "WholeExtent", _cells(whole))
    for tag, body in pieces:
        ext = _numbers(path, "Piece Extent", _attrs(tag).get("Extent", ""), 6, int)
        if any(ext[k] < whole[k] for k in (0, 2, 4)) or any(ext[k] > whole[k] for k in (1, 3, 5)):
            raise DataError(f"{path}: Piece Extent {ext} outside WholeExtent {whole}")
        pn = _count(path, "Piece Extent", _cells(ext) if where else ext)
        if kind == "RectilinearGrid":
            _check_coordinates(path, raw, at, fa, body, ext)
        found = _section(body, "CellData" if where else "PointData")
        if found is None:
            raise DataError(f"{path}: a Piece has no {where or 'point'} data array")
        section, arrays = found
        if name is None:  # the first piece's Scalars, or its first array
            want = _attrs(b"<x " + section + b">").get("Scalars")
            first = next((a for a, _ in arrays if want and a.get("Name") == want), arrays[0][0])
            name = first.get("Name")
            if not name:
                raise DataError(f"{path}: the {where or 'point'} data array has no Name")
        a, text = next(((a, t) for a, t in arrays if a.get("Name") == name), ({}, b""))
        if not a:
            raise DataError(f"{path}: a Piece has no {where or 'point'} array {name!r}")
        t = _VTI_TYPES.get(a.get("type", ""))
        if t is None:
            raise DataError(f"{path}: unsupported DataArray type {a.get('type')!r}")
        if _components(a) != "1":
            raise DataError(f"{path}: array {name!r} has several components; a volume has one")
        _check_array(path, raw, at, a, text, fa, pn * np.dtype(t).itemsize, pn)
        covered += pn
    if covered < n:
        raise DataError(f"{path}: the pieces hold {covered} samples, the WholeExtent {whole} needs {n}")
    return str(name), n, where


def _check_coordinates(
    path: Path, raw: bytes, at: int, fa: dict[str, str], body: bytes, ext: list[int]
) -> None:
    """A .vtr piece's <Coordinates>: three arrays of one component, of
    ext's point counts along X, Y and Z, each checked against the file."""
    found = _elements(body, "Coordinates")[0][:1]
    arrays = _arrays(found[0][3]) if found else []
    if len(arrays) != 3:
        raise DataError(f"{path}: a RectilinearGrid Piece without its three <Coordinates> arrays")
    for axis, (a, text), k in zip("XYZ", arrays, (0, 2, 4), strict=True):
        t = _VTI_TYPES.get(a.get("type", ""))
        if t is None or _components(a) != "1":
            raise DataError(f"{path}: the {axis} coordinates: one component of a numeric type expected")
        count = ext[k + 1] - ext[k] + 1
        _check_array(path, raw, at, a, text, fa, count * np.dtype(t).itemsize, count)


def _section(body: bytes, tag: str) -> tuple[bytes, list[tuple[dict[str, str], bytes]]] | None:
    """(the attributes, the arrays) of a piece's <PointData> or <CellData>
    section; None where it is missing or holds no array."""
    found = _elements(body, tag)[0][:1]
    arrays = _arrays(found[0][3]) if found else []
    return (found[0][2], arrays) if arrays else None


def _cells(ext: list[int]) -> list[int]:
    """The extent of the cells of a point extent (VTK: a flat axis keeps one)."""
    return [v for k in (0, 2, 4) for v in (ext[k], max(ext[k], ext[k + 1] - 1))]


def _check_array(
    path: Path,
    raw: bytes,
    at: int,
    a: dict[str, str],
    text: bytes,
    fa: dict[str, str],
    nbytes: int | None,
    n: int | None,
) -> None:
    """One piece's array: its byte count (or compressed-block header)
    against its extent (`nbytes`, `n` values; None: any, a cell array's
    connectivity) and against what the file holds."""
    fmt = a.get("format", "ascii")
    hs = 8 if fa.get("header_type") == "UInt64" else 4
    hdt = np.dtype((">" if fa.get("byte_order") == "BigEndian" else "<") + ("u8" if hs == 8 else "u4"))
    compressor = fa.get("compressor")
    if fmt == "ascii":
        if n is not None and n > len(text):
            raise DataError(f"{path}: {n} samples declared, the array holds {len(text)} bytes of text")
        return
    if fmt == "binary":
        stream, base = re.sub(rb"\s+", b"", text), True
    elif fmt == "appended" and at >= 0:
        tag = re.match(rb"<AppendedData\b[^>]*>\s*_", raw[at:])
        if tag is None:
            raise DataError(f"{path}: malformed <AppendedData> (no '_' before its data)")
        encoding = _attrs(tag.group(0)).get("encoding", "raw")
        if encoding not in ("raw", "base64"):
            raise DataError(f"{path}: appended data encoding {encoding!r} is not read (raw or base64)")
        try:
            offset = int(a.get("offset", ""))
        except ValueError:
            raise DataError(f"{path}: malformed DataArray offset {a.get('offset')!r}") from None
        stream, base = raw[at + tag.end() :], encoding == "base64"
        if not 0 <= offset <= len(stream) - hs:
            raise DataError(f"{path}: the appended array's offset {offset} lies outside the file")
        stream = stream[offset:]
    else:
        raise DataError(
            f"{path}: DataArray format {a.get('format')!r} is not read (binary, ascii or appended)"
        )

    def take(start: int, count: int) -> bytes:  # `count` decoded bytes from decoded byte `start`
        if not base:
            return stream[start : start + count]
        chars = stream[4 * (start // 3) : 4 * -(-(start + count) // 3)]
        return base64.b64decode(chars.split(b"=")[0] + b"==")[start % 3 : start % 3 + count]

    size = len(stream) * 3 // 4 if base else len(stream)  # what the stream can hold
    try:
        if compressor is None:
            count = int(np.frombuffer(take(0, hs), hdt, 1)[0])
            if (nbytes is not None and count != nbytes) or hs + count > size:
                raise DataError(f"{path}: the array's byte count does not match its extent, or is truncated")
            return
        blocks = int(np.frombuffer(take(0, hs), hdt, 1)[0])
        if blocks > size // hs:
            raise DataError(f"{path}: truncated or malformed compressed array header")
        # VTK base64-encodes the block header on its own (padded), the blocks after it
        hbytes = (3 + blocks) * hs
        header = np.frombuffer(take(0, hbytes), hdt, 3 + blocks).astype(np.int64)
        block, last, sizes = int(header[1]), int(header[2]), header[3:]
        total = block * (blocks - 1) + (last or block) if blocks else 0
        if (nbytes is not None and total != nbytes) or (block < 1 and blocks):
            raise DataError(f"{path}: the compressed array holds {total} bytes, the extent needs {nbytes}")
        data = size - (4 * -(-hbytes // 3) * 3 // 4 if base else hbytes)
        if int(sizes.sum()) > data or (sizes < 0).any() or total > _MAX_RATIO[str(compressor)] * max(data, 1):
            raise DataError(f"{path}: truncated or malformed compressed array")
    except (binascii.Error, ValueError, IndexError) as e:
        if isinstance(e, DataError):
            raise
        raise DataError(f"{path}: malformed binary array: {e}") from None


def _scalars(
    path: Path, reader: Any, messages: list[str], name: str | None, n: int, ns: Any, cells: bool = False
) -> tuple[Any, np.ndarray]:
    """(the reader's output, its `n`-sample one-component array as (Z, Y, X)):
    the named one, else the scalars; of the cells with `cells`. A DataError
    for VTK's errors, or an array not of that size."""
    reader.Update()
    out = reader.GetOutput()
    if messages or reader.GetErrorCode() or out is None:
        raise DataError(f"{path}: VTK could not read it: {_why(messages)}")
    pd = out.GetCellData() if cells else out.GetPointData()
    arr = pd.GetScalars() if name is None else pd.GetArray(name)
    dims = out.GetDimensions()
    nx, ny, nz = (max(d - 1, 1) for d in dims) if cells else dims
    if arr is None or arr.GetNumberOfComponents() != 1 or arr.GetNumberOfTuples() != n or nx * ny * nz != n:
        raise DataError(f"{path}: VTK read no {n}-sample scalar array from it")
    return out, np.array(ns.vtk_to_numpy(arr), copy=True).reshape(nz, ny, nx)


def _image(
    path: Path, reader: Any, messages: list[str], name: str | None, n: int, ns: Any, cells: bool = False
) -> tuple:
    """(data (Z, Y, X), spacing zyx, origin xyz) of `reader`'s output; with
    `cells`, of its cell array: one sample a cell, at the cell's centre."""
    img, data = _scalars(path, reader, messages, name, n, ns, cells)
    return image_axes(path, img, data, cells)


def image_axes(what: Any, img: Any, data: np.ndarray, cells: bool) -> tuple[np.ndarray, tuple, list]:
    """(data (Z, Y, X), spacing (dz, dy, dx), origin (x, y, z)) of the
    samples `data` [k, j, i] of the vtkImageData `img` (`cells`: its cell
    data, one sample a cell, at the cell's centre) in the world's axes: VTK
    puts sample (i, j, k) at origin + Direction @ ((i, j, k) * spacing). A
    Direction that only permutes and flips the axes (a scan in LPS order, as
    DICOM converters write it) is applied: the samples transposed and
    flipped, never resampled (it was ignored: the volume came out mirrored);
    a rotated one is a DataError naming `what` (clvis volumes are
    axis-aligned); then forward_axes."""
    dims = img.GetDimensions()
    spacing = np.asarray(img.GetSpacing(), np.float64)
    origin = np.asarray(img.GetOrigin(), np.float64)
    m = img.GetDirectionMatrix() if hasattr(img, "GetDirectionMatrix") else None
    d = np.eye(3) if m is None else np.array([[m.GetElement(r, c) for c in range(3)] for r in range(3)])
    to = np.argmax(np.abs(d), axis=0)  # the world axis each index axis runs along
    if (
        not np.isfinite(d).all()
        or sorted(to.tolist()) != [0, 1, 2]
        or not np.allclose(np.abs(d), np.eye(3)[to].T, atol=1e-6)
    ):
        raise DataError(
            f"{what}: its axes are rotated (Direction {' '.join(f'{v:g}' for v in d.ravel())}); clvis "
            "volumes are axis-aligned: resample it onto an axis-aligned grid"
        )
    if cells:  # the cell centres: half a step in along each axis that has cells
        origin = origin + d @ np.array([s / 2 if n > 1 else 0.0 for s, n in zip(spacing, dims, strict=True)])
    sign = np.sign(d[to, [0, 1, 2]])
    world = np.empty(3)  # each world axis's step, signed: the index axis along it, and its sense
    order = [0, 0, 0]  # the data axis [k, j, i] that becomes each world axis's [z, y, x]
    for a in range(3):
        world[to[a]] = sign[a] * spacing[a]
        order[2 - to[a]] = 2 - a
    return forward_axes(what, np.transpose(data, order), world, origin)


def forward_axes(what: Any, data: np.ndarray, spacing: Any, origin: Any) -> tuple[np.ndarray, tuple, list]:
    """(data (Z, Y, X), spacing (dz, dy, dx), origin (x, y, z)) of image data
    whose `spacing` and `origin` (x, y, z) are VTK's, with every step > 0, as
    clvis's renderers take them: VTK puts sample i at origin + i * spacing, so
    an axis of negative spacing runs backward (it is flipped, the origin
    moved to its last sample: the same points in space); a flat axis (one
    sample) of spacing 0, as a 2-D image is often written, gets a step of 1
    (a rectilinear grid's lone coordinate does too). A DataError naming
    `what` for a spacing or origin that is not finite, or a zero step along
    an axis of several samples."""
    steps, start = [], []
    for k, (s, o) in enumerate(zip(spacing, origin, strict=True)):
        s, o, axis = float(s), float(o), 2 - k
        n = data.shape[axis]
        if not (np.isfinite(s) and np.isfinite(o)):
            raise DataError(f"{what}: spacing {s:g} and origin {o:g} along {'xyz'[k]}: not finite")
        if s == 0 and n > 1:
            raise DataError(f"{what}: spacing 0 along {'xyz'[k]}: its {n} samples at one place")
        if s < 0 and n > 1:
            data, o = np.flip(data, axis), o + s * (n - 1)
        steps.append(abs(s) if s else 1.0)
        start.append(o)
    return np.ascontiguousarray(data), (steps[2], steps[1], steps[0]), start


def _opened(core: Any, reader: Any, path: Path, messages: list[str], text: bytes | None = None) -> bool:
    """Whether VTK's XML `reader`, observed (:func:`_observe`), read the
    information of `path` (or of `text`, what it holds as clvis gives it to
    VTK) without an error: its arrays, to choose from."""
    _observe(core, reader, messages)
    if text is None:
        reader.SetFileName(str(path))
    else:
        reader.ReadFromInputStringOn()
        reader.SetInputString(text, len(text))
    reader.UpdateInformation()
    return not messages


def read_vti(path: Path, array: str | None = None) -> tuple[np.ndarray, tuple, list, str]:
    """(data (Z, Y, X), spacing (dz, dy, dx), origin (x, y, z), the array's
    name) of a .vti (`array`: that one, by name), read by
    vtkXMLImageDataReader after the header checks."""
    return _read_xml(path, "ImageData", array)


def read_vtr(path: Path, array: str | None = None) -> tuple[np.ndarray, tuple, list, str]:
    """(data (Z, Y, X), spacing (dz, dy, dx), origin (x, y, z), the array's name) of a .vtr
    (XML RectilinearGrid, as pyvista's RectilinearGrid.save writes it)
    whose coordinates are evenly spaced along each axis, read by
    vtkXMLRectilinearGridReader after the header checks; its cell data where
    it has no point array, as for a .vti."""
    return _read_xml(path, "RectilinearGrid", array)


def _read_xml(path: Path, kind: str, array: str | None) -> tuple[np.ndarray, tuple, list, str]:
    """A .vti (`kind` "ImageData") or .vtr ("RectilinearGrid") read by VTK's
    XML reader of that kind after _check_grid, only the chosen array enabled."""
    name, n, where = _check_grid(path, path.read_bytes(), kind, array)
    core, _, xmlio, ns = _vtk()
    with _quiet(core) as messages:
        r = getattr(xmlio, f"vtkXML{kind}Reader")()
        if _opened(core, r, path, messages):
            r.GetPointDataArraySelection().DisableAllArrays()
            r.GetCellDataArraySelection().DisableAllArrays()
            (r.GetCellDataArraySelection() if where else r.GetPointDataArraySelection()).EnableArray(name)
            if kind == "ImageData":
                return (*_image(path, r, messages, name, n, ns, cells=bool(where)), name)
            return (*_rectilinear(path, r, messages, n, ns, name, cells=bool(where)), name)
    raise DataError(f"{path}: VTK could not read it: {_why(messages)}")


#: the legacy DATASETs whose points read_points reads as a cloud
POINT_DATASETS = ("POLYDATA", "UNSTRUCTURED_GRID", "STRUCTURED_GRID")
#: the legacy DATASETs read_volume reads (a rectilinear grid whose coordinates are evenly spaced)
VOLUME_DATASETS = ("STRUCTURED_POINTS", "RECTILINEAR_GRID")
# how far a rectilinear grid's coordinate may lie from the even step (a share
# of the step): what float32 coordinates written by pyvista keep
_EVEN = 1e-4


def _legacy_lines(raw: bytes) -> tuple[list[str], int]:
    """The first lines of a legacy VTK file as VTK's reader takes them, up
    to 12 within its first 4096 bytes: the version line, the title (a whole
    line, which may be blank), then the lines that are not blank (VTK reads
    the words after the title one by one, passing over blank lines: a file
    with a blank line before its ASCII or DATASET line is read); and where
    the fourth of them (the DATASET line) ends, 0 where the file has fewer."""
    lines: list[str] = []
    end = pos = 0
    head = raw[:4096]
    while len(lines) < 12 and pos < len(head):
        nl = head.find(b"\n", pos)
        stop = len(head) if nl < 0 else nl
        text = head[pos:stop].decode("latin-1").strip()
        if text or len(lines) < 2:
            lines.append(text)
            if len(lines) == 4 and nl >= 0:
                end = nl + 1
        pos = stop + 1
    return lines, end


def legacy_dataset(path: str | Path) -> str:
    """The DATASET of a legacy .vtk file (``STRUCTURED_POINTS``,
    ``POLYDATA``, ...; upper case), "" where its header does not say (not a
    legacy VTK file, unreadable): what routes a .vtk to read_volume (a
    volume) or read_points (its points)."""
    try:
        with open(path, "rb") as f:
            text = _legacy_lines(f.read(4096))[0]
    except OSError:
        return ""
    if len(text) < 4 or not text[0].startswith("# vtk DataFile") or not text[3].upper().startswith("DATASET"):
        return ""
    words = text[3].upper().split()
    return words[1] if len(words) > 1 else ""


def _legacy_head(path: Path, raw: bytes) -> tuple[str, bool, bool, list[str]]:
    """(DATASET, binary, cells as OFFSETS/CONNECTIVITY (file version 5 on),
    the first lines) of a legacy VTK file; a DataError for any other file."""
    text = _legacy_lines(raw)[0]
    if not text or not text[0].startswith("# vtk DataFile"):
        raise DataError(f"{path}: not a legacy VTK file (no '# vtk DataFile' line)")
    up = [t.upper() for t in text]
    words = up[3].split() if len(up) > 3 else []
    if words[:1] != ["DATASET"] or len(words) != 2 or up[2] not in ("ASCII", "BINARY"):
        raise DataError(f"{path}: malformed legacy VTK header (ASCII or BINARY, then DATASET <type>)")
    # VTK reads cells as OFFSETS and CONNECTIVITY from version 5 on, and a version it cannot parse as 0:
    # a walk of the other layout than VTK's would let a lying cell list through (./dev.sh fuzz: SIGSEGV)
    version = re.fullmatch(r"# vtk DataFile Version (\d{1,3})\.(\d{1,3})", text[0])
    if version is None:
        raise DataError(f"{path}: malformed legacy VTK version line {text[0][:60]!r}")
    return words[1], up[2] == "BINARY", int(version.group(1)) >= 5, text


# bytes a value of each legacy type takes in a BINARY file (vtkIdType is written as int)
_LEGACY_SIZES = {
    **{k: np.dtype(v).itemsize for k, v in _LEGACY_TYPES.items()},
    "vtkidtype": 4, "vtktypeint64": 8, "vtktypeuint64": 8, "vtktypeint32": 4, "vtktypeuint32": 4,
    "vtktypeint8": 1, "vtktypeuint8": 1, "vtktypeint16": 2, "vtktypeuint16": 2,
    "vtktypefloat32": 4, "vtktypefloat64": 8,
}  # fmt: skip
_NOT_A_NUMBER = re.compile(r"[-+]?(NAN|INF)")
_CELL_SECTIONS = ("VERTICES", "LINES", "POLYGONS", "TRIANGLE_STRIPS", "CELLS")
# the attribute sections whose type is their third word: values a tuple
_ATTRIBUTES = {"VECTORS": 3, "NORMALS": 3, "TENSORS": 9, "TENSORS6": 6, "GLOBAL_IDS": 1, "PEDIGREE_IDS": 1}
# the sections _check_legacy walks: a line of one of these it does not read is malformed, ASCII too
_SECTION_KEYS = {
    "X_COORDINATES", "Y_COORDINATES", "Z_COORDINATES", "POINTS", *_CELL_SECTIONS, "CELL_TYPES",
    "POINT_DATA", "CELL_DATA", "SCALARS", "LOOKUP_TABLE", "COLOR_SCALARS", "TEXTURE_COORDINATES",
    *_ATTRIBUTES, "FIELD",
}  # fmt: skip
_ASCII_KEY = re.compile(rb"(?m)^[ \t]*([A-Za-z_][^\r\n]*)")
_BINARY_KEY = re.compile(rb"[ \t\r\n]*([^\r\n]*)")
_BLANK_LINE = re.compile(rb"\n\r?\n")
_TABLE_AFTER = re.compile(rb"[ \t\r\n]*LOOKUP_TABLE[ \t]+\S+[ \t\r]*\n", re.I)


def _check_cell_list(path: Path, key: str, raw: bytes, at: int, cells: int, total: int, binary: bool) -> None:
    """A cell list of a legacy file before version 5 (`cells` cells in
    `total` ints from byte `at`: each cell's point count, then its point
    ids): the counts must add up to `total` (VTK's reader trusts them and
    reads past its buffer where one lies: a segmentation fault)."""
    if binary:
        ids = np.frombuffer(raw, ">i4", total, at)
    else:
        # a value and its separator take two bytes, at most 21 (a 64-bit int) and some spaces: 24 bounds it
        text = raw[at : at + 24 * total + 64].decode("latin-1")
        try:
            ids = np.fromstring(text, dtype=np.int64, count=total, sep=" ")
        except ValueError:
            raise DataError(f"{path}: {key}: fewer than {total} integers or malformed ones") from None
    k = int(ids[0]) if total else 0
    if k >= 0 and total == cells * (k + 1) and (ids[:: k + 1] == k).all():  # one point count for every cell
        return
    i, n = 0, 0
    while i < total and n < cells:
        k = int(ids[i])
        if k < 0:
            break
        i, n = i + k + 1, n + 1
    if i != total or n != cells:
        raise DataError(f"{path}: {key} {cells} {total}: its cells' point counts do not add up to {total}")


class _LegacyArray(NamedTuple):
    """An array of a legacy file's POINT_DATA or CELL_DATA section, as its
    header line declares it."""

    where: str  # "point" or "cell"
    kind: str  # SCALARS, FIELD, VECTORS, ...
    name: str  # as VTK decodes it (%20: a space)
    type: str  # the legacy type word, lower case
    components: int
    tuples: int  # a FIELD array's own count; the section's for the others
    section: int  # the section's POINT_DATA or CELL_DATA count


def _check_legacy(
    path: Path, raw: bytes, binary: bool, new_cells: bool, arrays: list[_LegacyArray] | None = None
) -> int:
    """Every section of a legacy VTK file after its DATASET line, its count
    against the bytes the file holds, before VTK reads and allocates: BINARY
    walked section by section, each block's size exact (a count that lies
    is caught where it lies); ASCII each section's values bounded by the
    text after it (a value and its separator take two bytes). The points'
    count (-1: no POINTS); a DataError naming the file for what does not
    fit or is not read. `arrays`, where given, gets each array of the
    POINT_DATA and CELL_DATA sections (a dataset's own FIELD before them is
    none), in the file's order."""
    pos = _legacy_lines(raw)[1]  # after the version, title, ASCII/BINARY and DATASET lines
    if pos == 0:
        raise DataError(f"{path}: malformed legacy VTK header (fewer than 4 lines)")
    size, points, here, fields = len(raw), -1, 0, 0
    where, field_where = "", ""  # the data section we are in ("point", "cell"), the FIELD's

    def note(kind: str, name: str, type_word: str, components: int, tuples: int, data: str) -> None:
        """An array of the `data` section ("point", "cell"; "": none, not noted) into `arrays`."""
        if arrays is not None and data:
            arrays.append(
                _LegacyArray(
                    data,
                    kind,
                    _decoded(name.encode("latin-1")),
                    type_word.lower(),
                    components,
                    tuples,
                    here,
                )
            )

    def number(word: str, what: str) -> int:
        if not re.fullmatch("[0-9]+", word):  # isdigit() takes '²'; int() does not
            raise DataError(f"{path}: malformed {what} count {word!r}")
        return int(word)

    def values(count: int, kind: str, what: str, at: int) -> int:
        """Where `count` values of type `kind` from `at` end (BINARY; ASCII: `at`)."""
        kind = kind.lower()
        if kind == "bit":
            nbytes = -(-count // 8)
        elif kind in _LEGACY_SIZES:
            nbytes = count * _LEGACY_SIZES[kind]
        elif kind in ("string", "utf8_string") and not binary:
            nbytes = count
        else:
            raise DataError(f"{path}: {what}: values of type {kind!r} are not read")
        strings = kind in ("string", "utf8_string")
        need = nbytes if binary or strings else 2 * count - 1
        if need > size - at:
            raise DataError(
                f"{path}: truncated or malformed: {what} declares {count} values, "
                f"{'needs' if binary else 'at least'} {need} bytes, the file holds {size - at} after it"
            )
        if strings:  # ASCII strings: one a line (VTK writes a space as %20), any text: passed over
            for _ in range(count):
                at = raw.find(b"\n", at) + 1
                if at == 0:
                    raise DataError(f"{path}: truncated: {what} declares {count} strings, one a line")
            return at
        return at + nbytes if binary else at

    while True:
        # ASCII: the next line that starts with a word (values are numbers);
        # BINARY: the line where the last block ended
        m = _BINARY_KEY.match(raw, pos) if binary else _ASCII_KEY.search(raw, pos)
        if m is None or not m.group(1).strip():
            break
        words = [
            w.decode("latin-1") for w in m.group(1).split()
        ]  # ASCII whitespace (not latin-1's \x85, \xa0)
        key, pos = words[0].upper(), m.end() + (2 if raw[m.end() : m.end() + 2] == b"\r\n" else 1)
        what = " ".join(words)[:80]
        if not binary and _NOT_A_NUMBER.match(key):
            continue  # ASCII values: nan, inf
        if key == "METADATA":  # information keys and component names, up to a blank line
            end = _BLANK_LINE.search(raw, pos - 1)
            pos = size if end is None else end.end()
            continue
        if fields:  # a FIELD's array: name components tuples type
            fields -= 1
            if len(words) == 1 and key == "NULL_ARRAY":
                continue
            if len(words) != 4:
                raise DataError(f"{path}: malformed field array {what!r} (name components tuples type)")
            comps, tuples = number(words[1], "field array components"), number(words[2], "field array tuples")
            pos = values(comps * tuples, words[3], f"field array {words[0]!r}", pos)
            note("FIELD", words[0], words[3], comps, tuples, field_where)
        elif key in ("DIMENSIONS", "ORIGIN", "SPACING", "ASPECT_RATIO"):
            continue
        elif key in ("X_COORDINATES", "Y_COORDINATES", "Z_COORDINATES") and len(words) >= 3:
            # (VTK reads the count and type, whatever follows on the line)
            pos = values(number(words[1], key), words[2], key, pos)
        elif key == "POINTS" and len(words) >= 3:  # (VTK reads the count and type, not the rest)
            points = number(words[1], "POINTS")
            pos = values(3 * points, words[2], "POINTS", pos)
        elif key in _CELL_SECTIONS and len(words) == 3:
            cells, total = number(words[1], key), number(words[2], key)
            if not new_cells:
                after = values(total, "int", key, pos)
                _check_cell_list(path, key, raw, pos, cells, total, binary)
                pos = after
                continue
            if not binary:  # ASCII: OFFSETS and CONNECTIVITY bounded together
                pos = values(total + cells, "int", key, pos)
                continue
            for part, n in (("OFFSETS", cells), ("CONNECTIVITY", total)):  # file version 5's layout
                m = re.compile(rb"[ \t\r\n]*" + part.encode() + rb"[ \t]+(\S+)[^\n]*\n", re.I).match(raw, pos)
                if m is None:
                    raise DataError(f"{path}: {key}: no {part} line after it")
                pos = values(n, m.group(1).decode("latin-1"), f"{key} {part}", m.end())
        elif key == "CELL_TYPES" and len(words) == 2:
            pos = values(number(words[1], key), "int", key, pos)
        elif key in ("POINT_DATA", "CELL_DATA") and len(words) == 2:
            here, where = number(words[1], key), key.split("_")[0].lower()
            if key == "POINT_DATA" and points >= 0 and here != points:
                raise DataError(f"{path}: POINT_DATA {here} does not match POINTS {points}")
            if here > size:
                raise DataError(f"{path}: {key} {here}: more values than the file's bytes")
        elif key == "SCALARS" and len(words) in (3, 4):
            comps = number(words[3], "SCALARS components") if len(words) == 4 else 1
            if not 1 <= comps <= 4:
                raise DataError(f"{path}: SCALARS of {comps} components (VTK reads 1 to 4)")
            m = _TABLE_AFTER.match(raw, pos)
            pos = values(here * comps, words[2], what, m.end() if m else pos)
            note(key, words[1], words[2], comps, here, where)
        elif key == "LOOKUP_TABLE" and len(words) == 3:
            pos = values(4 * number(words[2], key), "unsigned_char" if binary else "float", what, pos)
        elif key == "COLOR_SCALARS" and len(words) == 3:
            comps = number(words[2], "COLOR_SCALARS components")
            pos = values(here * comps, "unsigned_char" if binary else "float", what, pos)
            note(key, words[1], "unsigned_char" if binary else "float", comps, here, where)
        elif key == "TEXTURE_COORDINATES" and len(words) == 4:
            comps = number(words[2], "TEXTURE_COORDINATES dimension")
            pos = values(here * comps, words[3], what, pos)
            note(key, words[1], words[3], comps, here, where)
        elif key in _ATTRIBUTES and len(words) == 3:
            pos = values(here * _ATTRIBUTES[key], words[2], what, pos)
            note(key, words[1], words[2], _ATTRIBUTES[key], here, where)
        elif key == "FIELD" and len(words) == 3:
            fields, field_where = number(words[2], "FIELD arrays"), where
            if fields > size:
                raise DataError(f"{path}: FIELD of {fields} arrays, more than the file's bytes")
        elif binary or key in _SECTION_KEYS:
            # ASCII: VTK refuses a word it does not know; a section it knows whose line is not as
            # VTK writes it, VTK reads word by word across lines, as the walk does not (a FIELD
            # line of four words: its fourth the first array's name to VTK, a SIGSEGV)
            raise DataError(f"{path}: malformed or unknown legacy VTK section {what!r}")
    return points


def read_legacy(path: Path, array: str | None = None) -> tuple[np.ndarray, tuple, list, str]:
    """A legacy .vtk STRUCTURED_POINTS or (evenly spaced) RECTILINEAR_GRID
    file: (data, spacing zyx, origin xyz, the array's name), read by
    vtkStructuredPointsReader or vtkRectilinearGridReader after the header
    checks. The array (one component of a numeric type): `array`, a point
    array of that name (SCALARS or a FIELD array: VTK writes the arrays that
    are not the scalars so), else a cell array; by default the point data's
    first SCALARS, else its first FIELD array of one component; a file without
    either in its point data gives its cell data's the same way (one sample
    a cell, the origin at the first cell's centre), as a .vti does."""
    raw = path.read_bytes()
    dataset, binary, new_cells, text = _legacy_head(path, raw)
    if dataset not in VOLUME_DATASETS:
        where = "read_points, clvis render, clvis gauss and clvis view read it"
        points = f"; its points are a point cloud: {where}" if dataset in POINT_DATASETS else ""
        raise DataError(
            f"{path}: legacy VTK {dataset}: only DATASET STRUCTURED_POINTS or RECTILINEAR_GRID is a "
            f"volume{points}"
        )
    f = {}
    for line in text[4:]:
        if not line or line.split()[0].upper() in ("POINT_DATA", "CELL_DATA"):
            break
        f[line.split()[0].upper()] = line.split()[1:]
    if "DIMENSIONS" not in f:
        raise DataError(f"{path}: malformed {dataset} header: no DIMENSIONS")
    nx, ny, nz = _numbers(path, "DIMENSIONS", " ".join(f["DIMENSIONS"]), 3, int)
    _numbers(path, "SPACING", " ".join(f.get("SPACING", f.get("ASPECT_RATIO", ["1", "1", "1"]))), 3)
    _numbers(path, "ORIGIN", " ".join(f.get("ORIGIN", ["0", "0", "0"])), 3)
    if min(nx, ny, nz) < 1:
        raise DataError(f"{path}: empty DIMENSIONS {nx} {ny} {nz}")
    n = nx * ny * nz
    counts = {"point": n, "cell": max(nx - 1, 1) * max(ny - 1, 1) * max(nz - 1, 1)}
    # every data section VTK reads holds a value a point or a cell (bounded by the file too, below)
    for key, k in re.findall(rb"(?im)^[ \t]*(POINT_DATA|CELL_DATA)[ \t]+(\d+)", raw):
        _check_section(path, key.decode("latin-1").upper(), int(k), counts, (nx, ny, nz))
    arrays: list[_LegacyArray] = []
    _check_legacy(path, raw, binary, new_cells, arrays)
    chosen = _legacy_array(path, arrays, array)
    _check_section(path, f"{chosen.where.upper()}_DATA", chosen.section, counts, (nx, ny, nz))
    if chosen.tuples != chosen.section:
        raise DataError(
            f"{path}: {chosen.where} {chosen.kind} array {chosen.name!r} holds {chosen.tuples} tuples, "
            f"the {chosen.where} data {chosen.section}"
        )
    cells = chosen.where == "cell"
    core, legacy, _, ns = _vtk()
    with _quiet(core) as messages:
        structured = dataset == "STRUCTURED_POINTS"
        r = legacy.vtkStructuredPointsReader() if structured else legacy.vtkRectilinearGridReader()
        _observe(core, r, messages)
        r.SetFileName(str(path))
        if chosen.kind == "SCALARS":  # VTK reads the first SCALARS of a section, else the one named
            r.SetScalarsName(chosen.name)
        count = counts[chosen.where]
        if structured:
            return (*_image(path, r, messages, chosen.name, count, ns, cells), chosen.name)
        return (*_rectilinear(path, r, messages, count, ns, chosen.name, cells, legacy=True), chosen.name)


def _check_section(path: Path, key: str, count: int, counts: dict[str, int], dims: tuple) -> None:
    """A DataError where a POINT_DATA or CELL_DATA `key`'s `count` is not the
    grid's (`counts`: its points and cells, of DIMENSIONS `dims`)."""
    what = key.split("_")[0].lower()
    if count != counts[what]:
        raise DataError(
            f"{path}: {key} {count} does not match DIMENSIONS {' '.join(map(str, dims))} "
            f"({counts[what]} {what}s)"
        )


def _readable(a: _LegacyArray) -> bool:
    """Whether a legacy array can be a volume: one component of a numeric type."""
    return a.components == 1 and a.type in _LEGACY_TYPES


def _legacy_array(path: Path, arrays: list[_LegacyArray], name: str | None) -> _LegacyArray:
    """The array read_legacy reads (see there); a DataError listing the
    file's arrays where there is none, or none by that name, or where the
    one chosen has several components or is not of a numeric type."""
    listed = "; ".join(
        f"{where} arrays: {', '.join(dict.fromkeys(a.name for a in arrays if a.where == where))}"
        for where in ("point", "cell")
        if any(a.where == where for a in arrays)
    )
    if name is not None:
        found = [a for where in ("point", "cell") for a in arrays if a.where == where and a.name == name]
        if not found:
            raise DataError(f"{path}: no array {name!r} ({listed or 'no arrays'})")
        chosen = found[0]
    else:
        candidates = [
            a
            for where in ("point", "cell")
            for kind in ("SCALARS", "FIELD")
            for a in arrays
            if a.where == where and a.kind == kind and (kind == "SCALARS" or _readable(a))
        ]
        if not candidates:
            if not arrays:
                raise DataError(f"{path}: no point or cell data array")
            raise DataError(
                f"{path}: no SCALARS or FIELD array of one component of a numeric type ({listed})"
            )
        chosen = candidates[0]
    if not _readable(chosen):
        raise DataError(
            f"{path}: {chosen.where} {chosen.kind} {chosen.name!r} ({chosen.components} components of "
            f"type {chosen.type}): one component of a numeric type expected ({listed})"
        )
    return chosen


def _decoded(name: bytes) -> str:
    """A legacy array name as VTK decodes it (%20 and the like: legacy names have no spaces)."""
    return re.sub(r"%([0-9A-Fa-f]{2})", lambda h: chr(int(h.group(1), 16)), name.decode("latin-1"))


def _rectilinear(
    path: Path,
    reader: Any,
    messages: list[str],
    n: int,
    ns: Any,
    name: str | None = None,
    cells: bool = False,
    legacy: bool = False,
) -> tuple:
    """(data (Z, Y, X), spacing zyx, origin xyz) of a legacy or XML
    rectilinear grid reader's output (the array `name`, else the scalars;
    with `cells`, of its cell array: one sample a cell, at the cell's
    centre), its coordinates evenly spaced along each axis (within _EVEN of
    a step), else a DataError naming the axis (`legacy`: as a legacy file
    names it, X_COORDINATES)."""
    grid, data = _scalars(path, reader, messages, name, n, ns, cells)
    nx, ny, nz = grid.GetDimensions()
    steps, origin = [], []
    for axis, count, coords in (
        ("X", nx, grid.GetXCoordinates()),
        ("Y", ny, grid.GetYCoordinates()),
        ("Z", nz, grid.GetZCoordinates()),
    ):
        what = f"{axis}_COORDINATES" if legacy else f"the {axis} coordinates"
        c = np.asarray(ns.vtk_to_numpy(coords), np.float64) if coords is not None else np.zeros(0)
        if len(c) != count:
            raise DataError(f"{path}: {what}: expected {count} values, got {len(c)}")
        if not np.isfinite(c).all():
            raise DataError(f"{path}: {what}: a NaN or infinite coordinate")
        step = (c[-1] - c[0]) / (count - 1) if count > 1 else 1.0
        if count > 1 and not step > 0:
            raise DataError(f"{path}: {what} must increase ({c[0]:g} .. {c[-1]:g})")
        off = float(np.abs(c - (c[0] + step * np.arange(count))).max()) if count > 1 else 0.0
        if off > _EVEN * step:
            uneven = (
                f"RECTILINEAR_GRID with uneven {what}"
                if legacy
                else f"a RectilinearGrid with uneven {axis} coordinates"
            )
            raise DataError(
                f"{path}: {uneven} (a sample {off:.3g} from an even "
                f"step of {step:.6g}); clvis volumes are uniform grids: resample it (e.g. pyvista's "
                "ImageData.sample)"
            )
        steps.append(float(step))
        # a cell array's samples lie at the cells' centres: half a step in along an axis with cells
        origin.append(float(c[0]) + (float(step) / 2 if cells and count > 1 else 0.0))
    return data, (steps[2], steps[1], steps[0]), origin
