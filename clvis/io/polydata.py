"""VTK point sets as point clouds, read by VTK's own readers (the ``vtk``
extra): XML ``.vtp`` (PolyData), ``.vtu`` (UnstructuredGrid) and ``.vts``
(StructuredGrid) (vtkXMLPolyDataReader, vtkXMLUnstructuredGridReader,
vtkXMLStructuredGridReader: ascii, inline binary, raw or base64 appended
data, zlib- or LZ4-compressed or not, one piece or several: a .vts's pieces,
which share their boundary points, as one grid; a .vtp's or .vtu's
appended, as VTK appends them) and legacy ``.vtk`` whose DATASET is
POLYDATA, UNSTRUCTURED_GRID or STRUCTURED_GRID (ASCII or BINARY, file
versions before 5 and from 5 on). A legacy STRUCTURED_POINTS or
RECTILINEAR_GRID file is a volume (:func:`clvis.io.read_volume`).

The cloud is the points (a mesh's vertices; its cells are not kept): float32
positions, or, stored as doubles too far from zero for float32, relative to
their minimum kept as ``origin`` (as the other readers do). The point data
arrays: the first unsigned-char array of 3 or 4 components becomes the
colours (RGB or RGBA; legacy COLOR_SCALARS read as VTK reads them); a
3-component array named velocity (or vel, Velocity, velocities) the
velocity; a 1-component ``radius`` the radius; every other array
attributes: one of one component by its name, one of several as one
attribute a component (``Normals_x``, ``Normals_y``, ``Normals_z`` for 3,
``name_0``, ``name_1``, ... otherwise). Arrays of strings are skipped.

Bounded as the volume readers (:mod:`clvis.io.vtk`): before VTK reads, the
header is checked against the file: .vtp, .vtu: every piece's
NumberOfPoints and cell counts (.vts: its Extent, inside the WholeExtent,
the pieces covering it), each DataArray's byte count or compressed-block
header against its count and the bytes the file holds, no DTD or entities; legacy: every
section's count (POINTS, the cells, CELL_TYPES, POINT_DATA, CELL_DATA,
FIELD, SCALARS, LOOKUP_TABLE, ...) against the bytes after it, exact for
BINARY. VTK's error messages become a DataError naming the file; nothing
reaches stderr. VTK reads the bytes clvis checked, from memory (not the file
again, which may have changed since): a .vtp, .vtu or .vts without its
cells and cell data (VTK trusts cell offsets; each reader of its own kind,
not the XML rewritten as PolyData: a .vts's reader puts the pieces' shared
points in one grid); a legacy file whole, its cell lists checked to add up.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .cloud import PointCloud, _cloud, component_columns, relative_positions
from .vtk import (
    _VTI_TYPES,
    POINT_DATASETS,
    VOLUME_DATASETS,
    _attrs,
    _cells,
    _check_array,
    _check_legacy,
    _components,
    _count,
    _elements,
    _legacy_head,
    _numbers,
    _observe,
    _opened,
    _quiet,
    _section,
    _vtk,
    _why,
    _xml_head,
    _xml_part,
)

SUFFIXES = (".vtp", ".vtu", ".vts", ".vtk")
_XML_KINDS = {".vtp": "PolyData", ".vtu": "UnstructuredGrid", ".vts": "StructuredGrid"}
_CELL_KINDS = ("Verts", "Lines", "Strips", "Polys")
_VELOCITY = ("velocity", "velocities", "vel")


def _number(path: Path, attrs: dict[str, str], key: str, default: str | None = None) -> int:
    """The count `key` of an element's `attrs`; `default` where the attribute is
    absent or blank, as VTK's XML readers take it (meshio writes its cell arrays
    with NumberOfComponents="")."""
    text = attrs.get(key, "").strip() or default
    if text is None or not re.fullmatch("[0-9]+", text):  # isdigit() takes '²'; int() does not
        raise DataError(f"{path}: malformed or missing {key} {text!r}")
    return int(text)


def _check_xml(path: Path, raw: bytes, kind: str) -> int:
    """Check a .vtp, .vtu or .vts (`kind`: PolyData, UnstructuredGrid,
    StructuredGrid) against the file before VTK reads it: every piece's
    counts (a .vts piece's Extent, inside the WholeExtent, the pieces
    covering it), and each DataArray's size against its count and the bytes
    the file holds; the points it holds. A DataError naming the file for
    what is not read or lies about its size."""
    at, xml = _xml_part(path, raw)
    fa, da = _xml_head(path, xml, kind)
    found, opened = _elements(xml, "Piece")
    pieces = [(tag, body) for _, _, tag, body in found]
    if len(pieces) != opened:
        raise DataError(f"{path}: malformed {kind}: a <Piece> without its </Piece>")

    def check(arrays: list[tuple[dict[str, str], bytes]], tuples: int | None, what: str) -> None:
        for a, text in arrays:
            t = _VTI_TYPES.get(a.get("type", ""))
            if t is None and a.get("type") != "String":
                raise DataError(f"{path}: {what}: unsupported DataArray type {a.get('type')!r}")
            comps = _number(path, a, "NumberOfComponents", "1")
            if comps < 1:
                raise DataError(f"{path}: {what}: an array of {comps} components")
            if tuples is None and "NumberOfTuples" in a:  # field data: the array says how many
                count: int | None = _number(path, a, "NumberOfTuples") * comps
            else:
                count = None if tuples is None else tuples * comps
            nbytes = None if count is None or t is None else count * np.dtype(t).itemsize
            _check_array(path, raw, at, a, text, fa, nbytes, None if t is None else count)

    def section(body: bytes, tag: str) -> list[tuple[dict[str, str], bytes]]:
        found = _section(body, tag)  # the volume reader's: its arrays, or none
        return found[1] if found else []

    def offsets(arrays: list[tuple[dict[str, str], bytes]], count: int, what: str) -> None:
        offsets = [x for x in arrays if x[0].get("Name") == "offsets"]
        if count and len(offsets) != 1:
            raise DataError(f"{path}: {count} {what} and no offsets array for them")
        try:  # VTK writes a count of offsets (and, some versions, a leading 0 more)
            check(offsets, count, f"{what} offsets")
        except DataError:
            check(offsets, count + 1, f"{what} offsets")

    whole = (
        _numbers(path, "WholeExtent", da.get("WholeExtent", ""), 6, int) if kind == "StructuredGrid" else []
    )
    exts: list[list[int]] = []
    head = xml[: xml.find(b"<Piece")] if pieces else xml
    check(section(head, "FieldData"), None, "FieldData")
    total = 0
    for tag, body in pieces:
        pa = _attrs(tag)
        if whole:  # a .vts piece: its Extent's points and cells
            ext = _numbers(path, "Piece Extent", pa.get("Extent", ""), 6, int)
            if any(ext[k] < whole[k] for k in (0, 2, 4)) or any(ext[k] > whole[k] for k in (1, 3, 5)):
                raise DataError(f"{path}: Piece Extent {ext} outside WholeExtent {whole}")
            n, cells = _count(path, "Piece Extent", ext), {"": _count(path, "Piece Extent", _cells(ext))}
        else:
            n = _number(path, pa, "NumberOfPoints", "0")
            kinds = _CELL_KINDS if kind == "PolyData" else ("Cells",)
            cells = {k: _number(path, pa, f"NumberOf{k}", "0") for k in kinds}
        points = section(body, "Points")
        if n and (len(points) != 1 or _components(points[0][0]) != "3"):
            raise DataError(f"{path}: a Piece of {n} points has no <Points> array of 3 components")
        check(points, n, "Points")
        check(section(body, "PointData"), n, "PointData")
        check(section(body, "CellData"), sum(cells.values()), "CellData")
        for k, count in cells.items() if not whole else ():
            arrays = section(body, k)
            offsets(arrays, count, k)
            types = [x for x in arrays if x[0].get("Name") == "types"]  # a .vtu's: one a cell
            if kind == "UnstructuredGrid" and count and len(types) != 1:
                raise DataError(f"{path}: {count} Cells and no types array for them")
            check(types, count, "Cells types")
            check([x for x in arrays if x[0].get("Name") not in ("offsets", "types")], None, k)
        if whole:
            exts.append(ext)
        total += n
    if whole:  # the pieces (their points checked against the file's bytes) cover the WholeExtent
        n = _count(path, "WholeExtent", whole)
        if total < n:
            raise DataError(f"{path}: the pieces hold {total} points, the WholeExtent {whole} needs {n}")
        covered = np.zeros([whole[k + 1] - whole[k] + 1 for k in (4, 2, 0)], bool)
        for ext in exts:
            covered[tuple(slice(ext[k] - whole[k], ext[k + 1] - whole[k] + 1) for k in (4, 2, 0))] = True
        if not covered.all():
            raise DataError(f"{path}: the pieces do not cover the WholeExtent {whole}")
        return n
    return total


def _without_cells(path: Path, raw: bytes) -> bytes:
    """The .vtp, .vtu or .vts `raw` with its pieces' cells and cell data
    taken out of its XML (the appended data, addressed from its own start,
    as it is): what VTK reads. VTK's reader trusts a cell array's offsets (a
    last offset of 2^63 made it allocate that: std::bad_alloc, an abort,
    ./dev.sh fuzz), and the cells are not kept (a .vts's are implicit: its
    cell data goes)."""
    at, xml = _xml_part(path, raw)
    tags = (*_CELL_KINDS, "Cells", "CellData")
    spans = sorted(e[:2] for tag in tags for e in _elements(xml, tag)[0])
    kept, start = [], 0
    for a, b in spans:
        if a >= start:  # (an element inside one taken out already is gone with it)
            kept.append(xml[start:a])
            start = b
    xml = b"".join(kept) + xml[start:]
    xml = re.sub(rb'\bNumberOf(Verts|Lines|Strips|Polys|Cells)\s*=\s*"[^"]*"', rb'NumberOf\1="0"', xml)
    return xml + (raw[at:] if at >= 0 else b"")


def _read_xml(path: Path, kind: str) -> PointCloud:
    raw = path.read_bytes()
    n = _check_xml(path, raw, kind)
    core, _, xmlio, ns = _vtk()
    with _quiet(core) as messages:
        r = getattr(xmlio, f"vtkXML{kind}Reader")()
        if _opened(core, r, path, messages, _without_cells(path, raw)):
            r.Update()
        return _points(path, r, messages, n, ns)


def _read_legacy_points(path: Path) -> PointCloud:
    raw = path.read_bytes()
    dataset, binary, new_cells, _ = _legacy_head(path, raw)
    if dataset not in POINT_DATASETS:
        if dataset in VOLUME_DATASETS:
            raise DataError(
                f"{path}: legacy VTK {dataset} is a volume, not a point cloud; "
                "read_volume, clvis iso, clvis gauss and clvis view read it"
            )
        raise DataError(
            f"{path}: legacy VTK {dataset} is not read as points "
            "(POLYDATA, UNSTRUCTURED_GRID, STRUCTURED_GRID)"
        )
    n = _check_legacy(path, raw, binary, new_cells)
    core, legacy, _, ns = _vtk()
    reader = {
        "POLYDATA": "vtkPolyDataReader",
        "UNSTRUCTURED_GRID": "vtkUnstructuredGridReader",
        "STRUCTURED_GRID": "vtkStructuredGridReader",
    }[dataset]
    with _quiet(core) as messages:
        r = getattr(legacy, reader)()
        _observe(core, r, messages)
        r.ReadFromInputStringOn()  # the bytes checked, not the file again (it may have changed since)
        r.SetInputString(raw, len(raw))
        for what in ("Scalars", "Vectors", "Normals", "TCoords", "ColorScalars", "Fields", "Tensors"):
            getattr(r, f"ReadAll{what}On")()
        r.Update()
        return _points(path, r, messages, max(n, 0), ns)


def _points(path: Path, reader: Any, messages: list[str], n: int, ns: Any) -> PointCloud:
    """The cloud of `reader`'s output: its points and point data arrays."""
    data = reader.GetOutput()
    if messages or reader.GetErrorCode() or data is None:
        raise DataError(f"{path}: VTK could not read it: {_why(messages)}")
    if data.GetNumberOfPoints() != n or (n and data.GetPoints() is None):
        raise DataError(f"{path}: VTK read {data.GetNumberOfPoints()} points, the file declares {n}")
    return cloud_of(data, path, ns)


def cloud_of(data: Any, what: Any, ns: Any) -> PointCloud:
    """The cloud of a VTK point set `data` (vtkPointSet: a file's, or one a
    program made, such as a pyvista mesh): its points and point data arrays
    as the module docstring says; `what` names it in a DataError; ns: VTK's
    numpy_support."""
    n = int(data.GetNumberOfPoints())
    pts = data.GetPoints()
    xyz = np.zeros((0, 3), np.float32) if not n else np.array(ns.vtk_to_numpy(pts.GetData()), copy=True)
    positions, origin = relative_positions(xyz.reshape(n, 3))
    fields: dict[str, Any] = {"positions": positions, "origin": origin, "attributes": {}}
    pd = data.GetPointData()
    for i in range(pd.GetNumberOfArrays()):
        arr = pd.GetArray(i)  # None for an array of strings
        if arr is None or arr.GetNumberOfTuples() != n:
            continue
        name = arr.GetName() or f"array{i}"
        comps = arr.GetNumberOfComponents()
        try:
            a = np.array(ns.vtk_to_numpy(arr), copy=True).reshape(n, comps)
        except (TypeError, ValueError, AssertionError, KeyError):  # a type numpy has not (bits)
            continue
        if "colors" not in fields and a.dtype == np.uint8 and comps in (3, 4):
            fields["colors"] = a
        elif "velocity" not in fields and comps == 3 and name.lower() in _VELOCITY:
            fields["velocity"] = a
        elif "radius" not in fields and comps == 1 and name == "radius":
            fields["radius"] = a[:, 0]
        elif comps == 1:
            fields["attributes"][name] = a[:, 0]
        else:
            fields["attributes"].update(component_columns(name, a))
    return _cloud(what, **fields)


def read_vtk_points(path: Path) -> PointCloud:
    """The cloud of a .vtp, .vtu, .vts or legacy .vtk point set (see the module docstring)."""
    kind = _XML_KINDS.get(path.suffix.lower())
    return _read_xml(path, kind) if kind else _read_legacy_points(path)
