"""PLY point clouds (via plyfile): the header checked against the file size
before plyfile allocates, the reader and the writer."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from ..errors import DataError
from .cloud import (
    _COLOR_NAMES,
    _ORIGIN_COMMENT,
    _RESERVED_COLUMNS,
    _VELOCITY_NAMES,
    PointCloud,
    _check_cloud,
    _from_columns,
    _write_or_remove,
)
from .npy import _size

# PLY property types and their sizes in bytes
_PLY_SIZES = {
    "char": 1,
    "uchar": 1,
    "int8": 1,
    "uint8": 1,
    "short": 2,
    "ushort": 2,
    "int16": 2,
    "uint16": 2,
    "int": 4,
    "uint": 4,
    "int32": 4,
    "uint32": 4,
    "float": 4,
    "float32": 4,
    "double": 8,
    "float64": 8,
}


def _check_ply_header(path: Path) -> None:
    """Compare the rows the PLY header declares with the bytes after it: plyfile
    allocates every element's rows before reading them (and loops over them one by
    one), so a header declaring 10^12 vertices must be refused first. A binary row
    takes at least its scalar properties plus its list lengths; an ASCII row at
    least two bytes per property (a digit and a separator). What the check cannot
    follow (unknown types, no end_header) is left to plyfile to refuse."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return
    nl = head.find(b"\n", end)
    data_start = size if nl < 0 else nl + 1
    fmt = None
    elements: list[tuple[str, list[int]]] = []  # (name, [count, min bytes a row, properties])
    for line in head[:end].decode("ascii", "replace").splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "format" and len(words) > 1:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3:
            try:
                elements.append((words[1], [int(words[2]), 0, 0]))
            except ValueError:
                return
        elif words[0] == "property" and elements:
            el = elements[-1][1]
            el[2] += 1
            if len(words) >= 5 and words[1] == "list":
                el[1] += _PLY_SIZES.get(words[2], 1)
            elif len(words) >= 3:
                el[1] += _PLY_SIZES.get(words[1], 1)
    need = 0
    for _, (count, row, props) in elements:
        if count < 0:
            raise DataError(f"{path}: malformed PLY header: a negative element count {count}")
        need += count * max(1, row if fmt != "ascii" else 2 * props - 1)
    have = size - data_start
    if need > have:
        declared = ", ".join(f"{count} {name}" for name, (count, _, _) in elements)
        raise DataError(
            f"{path}: truncated or malformed PLY file: the header declares {declared} "
            f"rows, at least {_size(need)}, but the file holds {have} bytes after the header"
        )


def _read_ply(path: Path) -> PointCloud:
    import plyfile

    _check_ply_header(path)
    try:
        # binary data memory-mapped (plyfile reads ASCII, and elements with
        # lists, row by row either way): a 2 M-vertex file loads in
        # milliseconds instead of a minute; the columns are copied out below
        ply = plyfile.PlyData.read(str(path), mmap="r")
    except (
        plyfile.PlyParseError,
        ValueError,
        OverflowError,
        EOFError,
        struct.error,
        TypeError,
        IndexError,
        KeyError,
        UnicodeDecodeError,
    ) as e:
        raise DataError(f"{path}: malformed PLY file: {type(e).__name__}: {e}") from e
    names = [el.name for el in ply.elements]
    if "vertex" not in names:
        raise DataError(
            f"{path}: the PLY file has no vertex element (elements: {', '.join(names) or 'none'})"
        )
    data = ply["vertex"].data  # plyfile raises on fewer rows than the header declares
    # lists skipped; each column copied out of the mapping (native byte order),
    # so the file is not held open
    columns = {
        k: np.array(data[k], dtype=data.dtype[k].newbyteorder("="))
        for k in data.dtype.names
        if data.dtype[k].kind in "iufb"
    }
    origin = None
    for c in ply.comments:
        if c.startswith(_ORIGIN_COMMENT + " "):
            try:
                origin = [float(v) for v in c[len(_ORIGIN_COMMENT) :].split()]
            except ValueError as e:
                raise DataError(f"{path}: malformed origin comment {c!r}") from e
    # double x, y, z far from zero: relative to their minimum (cloud.relative_positions)
    return _from_columns(path, columns, origin)


# A LAZ file's point data cannot decompress to more points than this per byte.
# LASzip codes each point with an adaptive arithmetic coder and stores the first
# point of every chunk raw; a million identical points compress to about 140
# points per byte (point format 0, the most compressible), so 1000 is seven
# times what the best case reaches, while a header that lies by a factor of


def write_ply(path: str | os.PathLike[str], cloud: PointCloud, text: bool = False) -> None:
    """Write `cloud` as a PLY file (binary little-endian, or ASCII with `text`).

    Vertex properties: x, y, z (float); red, green, blue, alpha (uchar); vx, vy, vz
    and radius (float); one property per attribute (float or uchar). A nonzero
    origin goes into a header comment that :func:`read_points` reads back.
    """
    import plyfile

    _check_cloud(cloud)
    for k in cloud.attributes:
        if k in _RESERVED_COLUMNS or not k.isidentifier():
            raise ValueError(
                f"cloud: attribute {k!r} cannot be a PLY property (a reserved name or not an identifier)"
            )
    columns = [(c, cloud.positions[:, i]) for i, c in enumerate("xyz")]
    if cloud.colors is not None:
        columns += [(c, cloud.colors[:, i]) for i, c in enumerate(_COLOR_NAMES[0])]
    if cloud.velocity is not None:
        columns += [(c, cloud.velocity[:, i]) for i, c in enumerate(_VELOCITY_NAMES[0])]
    if cloud.radius is not None:
        columns.append(("radius", cloud.radius))
    columns += list(cloud.attributes.items())
    vertex = np.empty(len(cloud), dtype=[(k, v.dtype) for k, v in columns])
    for k, v in columns:
        vertex[k] = v
    comments = []
    if cloud.origin.any():
        comments.append(f"{_ORIGIN_COMMENT} {' '.join(repr(float(v)) for v in cloud.origin)}")
    ply = plyfile.PlyData(
        [plyfile.PlyElement.describe(vertex, "vertex")], text=text, byte_order="<", comments=comments
    )
    _write_or_remove(path, ply.write)
