"""Point cloud files: :class:`PointCloud` and the readers and writers.

:func:`read_points` reads PLY (ASCII or binary, via plyfile), LAS and LAZ (via
laspy; LAZ needs its lazrs backend), NPY and NPZ, chosen by the file extension.
:func:`write_ply` and :func:`save_npz` write a cloud back so that it round-trips.

Positions are float32, what the kernels read. float32 keeps about 7 significant
digits, too few for georeferenced coordinates (UTM eastings of 10^5..10^6 m), so
the LAS/LAZ reader subtracts the minimum of the points' coordinates and keeps it,
in float64, as ``cloud.origin``: world position = origin + position. Other
formats take positions as stored (origin zero), except that files written by
clvis carry their origin along (an NPZ key, a PLY header comment).

A missing file raises FileNotFoundError; a file clvis cannot read (unknown
extension, malformed or truncated content, wrong shapes) raises
:class:`clvis.errors.DataError` naming the file and the problem.
"""

from __future__ import annotations

import ast
import errno
import math
import os
import struct
import tokenize
import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ._arrays import real_array
from .errors import DataError

__all__ = ["PointCloud", "read_points", "save_npz", "write_ply"]

# Named columns (PLY vertex properties, structured NPY fields) with a meaning.
_COLOR_NAMES = (("red", "green", "blue", "alpha"), ("r", "g", "b", "a"))
_VELOCITY_NAMES = (("vx", "vy", "vz"), ("velocity_x", "velocity_y", "velocity_z"))
_RESERVED_COLUMNS = frozenset({"x", "y", "z", "radius"}.union(*_COLOR_NAMES, *_VELOCITY_NAMES))
_NPZ_KEYS = ("positions", "colors", "velocity", "radius", "origin")
# The PLY header comment that carries a cloud's origin.
_ORIGIN_COMMENT = "clvis origin"


def _vectors(name: str, a, n: int | None) -> np.ndarray:
    a = real_array(name, a)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (N, 3), got {a.shape}")
    _check_length(name, len(a), n)
    return np.ascontiguousarray(a, dtype=np.float32)


def _check_length(name: str, length: int, n: int | None) -> None:
    if n is not None and length != n:
        raise ValueError(f"{name}: {length} rows, but positions has {n}")


def _colors(a, n: int) -> np.ndarray:
    a = real_array("colors", a)
    if a.ndim != 2 or a.shape[1] not in (3, 4):
        raise ValueError(f"colors: expected shape (N, 3) or (N, 4), got {a.shape}")
    _check_length("colors", len(a), n)
    if a.dtype == np.uint16:
        a = (a >> 8).astype(np.uint8)
    elif a.dtype.kind == "f":
        if not ((a >= 0) & (a <= 1)).all():  # NaN fails too
            raise ValueError("colors: float colors must lie in [0, 1]")
        a = np.rint(a.astype(np.float64) * 255).astype(np.uint8)
    elif a.dtype != np.uint8:
        if a.size and (a.min() < 0 or a.max() > 255):
            raise ValueError(
                f"colors: {a.dtype} colors must lie in 0..255 "
                "(uint16 colors are scaled down; pass them as uint16)"
            )
        a = a.astype(np.uint8)
    if a.shape[1] == 3:
        a = np.concatenate([a, np.full((len(a), 1), 255, np.uint8)], axis=1)
    return np.ascontiguousarray(a)


def _attribute(key, a, n: int) -> np.ndarray:
    if not isinstance(key, str) or not key:
        raise TypeError(f"attributes: names must be non-empty strings, got {key!r}")
    name = f"attributes[{key!r}]"
    if isinstance(a, (str, bytes)) or a is None:
        raise TypeError(f"{name}: expected an array, got {type(a).__name__}")
    a = np.asarray(a)
    if a.ndim != 1:
        raise ValueError(f"{name}: expected shape (N,), got {a.shape}")
    _check_length(name, len(a), n)
    if a.dtype == np.bool_:
        return a.astype(np.uint8)
    if a.dtype.kind not in "iuf":
        raise TypeError(f"{name}: expected real numbers or bools, got dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype=np.uint8 if a.dtype == np.uint8 else np.float32)


class PointCloud:
    """Points with optional colors, velocities, radii and per-point attributes.

    The constructor checks and converts its arguments (TypeError / ValueError
    naming the argument).

    Parameters
    ----------
    positions : (N, 3) real array
        Stored as float32, C-contiguous.
    colors : (N, 3) or (N, 4) array, optional
        uint8 as is; uint16 scaled down (>> 8); float in [0, 1] scaled by 255 and
        rounded; other integers in 0..255 as is. Stored as (N, 4) uint8 RGBA
        (alpha 255 when not given).
    attributes : dict of str -> (N,) array, optional
        float32 and uint8 kept, bool stored as uint8, other reals as float32.
    velocity : (N, 3) real array, optional
        Stored as float32.
    radius : (N,) real array, optional
        Stored as float32.
    origin : (3,) real, optional
        World position of the local coordinate origin (float64, default zeros).
    """

    def __init__(
        self,
        positions: npt.ArrayLike,
        colors: npt.ArrayLike | None = None,
        attributes: Mapping[str, Any] | None = None,
        velocity: npt.ArrayLike | None = None,
        radius: npt.ArrayLike | None = None,
        origin: npt.ArrayLike | None = None,
    ) -> None:
        self.positions = _vectors("positions", positions, None)
        n = len(self.positions)
        self.colors = None if colors is None else _colors(colors, n)
        self.velocity = None if velocity is None else _vectors("velocity", velocity, n)
        if radius is None:
            self.radius = None
        else:
            r = real_array("radius", radius)
            if r.ndim != 1:
                raise ValueError(f"radius: expected shape (N,), got {r.shape}")
            _check_length("radius", len(r), n)
            self.radius = np.ascontiguousarray(r, dtype=np.float32)
        if attributes is None:
            attributes = {}
        if not isinstance(attributes, dict):
            raise TypeError(f"attributes: expected a dict, got {type(attributes).__name__}")
        self.attributes = {k: _attribute(k, v, n) for k, v in attributes.items()}
        o = np.zeros(3) if origin is None else np.asarray(real_array("origin", origin), dtype=np.float64)
        if o.shape != (3,) or not np.isfinite(o).all():
            raise ValueError(f"origin: expected 3 finite numbers, got {o.tolist()}")
        self.origin = o

    def __len__(self) -> int:
        return len(self.positions)

    def __repr__(self) -> str:
        parts = [f"{len(self)} points"]
        parts += [name for name in ("colors", "velocity", "radius") if getattr(self, name) is not None]
        if self.attributes:
            parts.append(f"attributes={list(self.attributes)}")
        if self.origin.any():
            parts.append(f"origin={self.origin.tolist()}")
        return f"PointCloud({', '.join(parts)})"

    @property
    def attribute_names(self) -> tuple[str, ...]:
        """The attribute names, in insertion order."""
        return tuple(self.attributes)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max), two (3,) float64 arrays over the points whose x, y, z are all
        finite, in local coordinates (add ``origin`` for world coordinates)."""
        finite = np.isfinite(self.positions).all(axis=1)
        if not finite.any():
            raise ValueError("bounds: the cloud has no finite points")
        p = self.positions[finite]
        return p.min(axis=0).astype(np.float64), p.max(axis=0).astype(np.float64)

    def subset(self, index: npt.ArrayLike | slice) -> PointCloud:
        """A new cloud with the points selected by `index`: a boolean mask of length
        N, an array of indices, or a slice. An index out of range raises
        DataError."""
        if not isinstance(index, slice):
            index = np.asarray(index)
            if index.dtype == np.bool_:
                if index.shape != (len(self),):
                    raise ValueError(f"index: a mask must have shape ({len(self)},), got {index.shape}")
            elif index.dtype.kind not in "iu" or index.ndim != 1:
                raise TypeError(
                    f"index: expected a boolean mask, 1-D integer indices or a slice, "
                    f"got {index.dtype} with shape {index.shape}"
                )

            elif index.size and not (-len(self) <= index.min() and index.max() < len(self)):
                raise DataError(
                    f"index: indices must lie in [-{len(self)}, {len(self)}), got "
                    f"{int(index.min())}..{int(index.max())}"
                )

        def pick(a):
            return None if a is None else a[index]

        return PointCloud(
            self.positions[index],
            pick(self.colors),
            {k: v[index] for k, v in self.attributes.items()},
            pick(self.velocity),
            pick(self.radius),
            self.origin,
        )


# ---------------------------------------------------------------- reading


def read_points(path: str | os.PathLike[str]) -> PointCloud:
    """Read a point cloud; the format comes from the extension (case-insensitive).

    - ``.ply``: the ``vertex`` element. x, y, z are required; red, green, blue
      [, alpha] (or r, g, b [, a]) become colors; vx, vy, vz (or velocity_x, ...)
      the velocity; radius the radius; every other scalar property an attribute.
    - ``.las``, ``.laz``: positions relative to ``origin`` = the minimum of the
      points' coordinates; red/green/blue become 8-bit (>> 8 when any value
      exceeds 255, else as is); every other dimension (intensity, classification,
      return_number, ...) an attribute. gps_time is stored as seconds since the
      earliest point, which float32 resolves where absolute GPS time would not.
    - ``.npy``: an (N, 3) array, or a structured array with fields x, y, z and
      others named as for PLY.
    - ``.npz``: key ``positions`` (N, 3) required; ``colors``, ``velocity``,
      ``radius``, ``origin`` optional; every other key an (N,) attribute.
    """
    path = Path(path)
    readers = {".ply": _read_ply, ".las": _read_las, ".laz": _read_las, ".npy": _read_npy, ".npz": _read_npz}
    if not path.exists():
        raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), str(path))
    reader = readers.get(path.suffix.lower())
    if reader is None:
        raise DataError(
            f"{path}: unknown point cloud format {path.suffix!r}; expected one of {', '.join(readers)}"
        )
    return reader(path)


def _cloud(path: Path, **fields) -> PointCloud:
    """PointCloud(**fields), its complaints turned into DataErrors naming the file."""
    try:
        return PointCloud(**fields)
    except (TypeError, ValueError) as e:
        raise DataError(f"{path}: {e}") from e


def _from_columns(path: Path, columns: dict[str, np.ndarray], origin=None) -> PointCloud:
    """A cloud from named 1-D columns (PLY properties, structured NPY fields)."""
    missing = [c for c in "xyz" if c not in columns]
    if missing:
        raise DataError(f"{path}: no {', '.join(missing)} column (found {', '.join(columns) or 'none'})")
    columns = dict(columns)

    def take(names):
        return np.stack([columns.pop(c) for c in names], axis=1)

    fields = {"positions": take("xyz"), "origin": origin}
    for names in _COLOR_NAMES:
        if all(c in columns for c in names[:3]):
            fields["colors"] = take([c for c in names if c in columns])
            break
    for names in _VELOCITY_NAMES:
        if all(c in columns for c in names):
            fields["velocity"] = take(names)
            break
    if "radius" in columns:
        fields["radius"] = columns.pop("radius")
    fields["attributes"] = columns
    return _cloud(path, **fields)


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
    fmt, elements = None, []
    for line in head[:end].decode("ascii", "replace").splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "format" and len(words) > 1:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3:
            try:
                elements.append([words[1], int(words[2]), 0, 0])  # name, count, min bytes, properties
            except ValueError:
                return
        elif words[0] == "property" and elements:
            el = elements[-1]
            el[3] += 1
            if len(words) >= 5 and words[1] == "list":
                el[2] += _PLY_SIZES.get(words[2], 1)
            elif len(words) >= 3:
                el[2] += _PLY_SIZES.get(words[1], 1)
    need = 0
    for _, count, row, props in elements:
        if count < 0:
            raise DataError(f"{path}: malformed PLY header: a negative element count {count}")
        need += count * max(1, row if fmt != "ascii" else 2 * props - 1)
    have = size - data_start
    if need > have:
        declared = ", ".join(f"{count} {name}" for name, count, _, _ in elements)
        raise DataError(
            f"{path}: truncated or malformed PLY file: the header declares {declared} "
            f"rows, at least {_size(need)}, but the file holds {have} bytes after the header"
        )


def _read_ply(path: Path) -> PointCloud:
    import plyfile

    _check_ply_header(path)
    try:
        ply = plyfile.PlyData.read(str(path), mmap=False)
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
    columns = {k: data[k] for k in data.dtype.names if data.dtype[k].kind in "iufb"}  # lists skipped
    origin = None
    for c in ply.comments:
        if c.startswith(_ORIGIN_COMMENT + " "):
            try:
                origin = [float(v) for v in c[len(_ORIGIN_COMMENT) :].split()]
            except ValueError as e:
                raise DataError(f"{path}: malformed origin comment {c!r}") from e
    return _from_columns(path, columns, origin)


# A LAZ file's point data cannot decompress to more points than this per byte.
# LASzip codes each point with an adaptive arithmetic coder and stores the first
# point of every chunk raw; a million identical points compress to about 140
# points per byte (point format 0, the most compressible), so 1000 is seven
# times what the best case reaches, while a header that lies by a factor of
# 10^4 (50 M points in 1.5 kB) is refused before anything is decompressed.
_LAZ_MAX_POINTS_PER_BYTE = 1000
# Points decompressed at a time (laspy's chunk iterator): 256 Ki points of at
# most 67 bytes (point format 10), ~17 MB per chunk.
_LAS_READ_CHUNK = 1 << 18
_LASZIP_VLR = (b"laszip encoded", 22204)


def _check_las_header(path: Path) -> tuple[int, int]:
    """Reject header counts the file cannot hold before laspy sees them: laspy loops
    over a corrupt VLR count (up to 2^32) reading empty records, for hours; laspy
    allocates the declared points; lazrs aborts the process (an uncatchable
    allocation failure) on a corrupt chunk count. Returns (point count, record
    length)."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(375)
        if len(head) < 227 or head[:4] != b"LASF":
            raise DataError(f"{path}: not a LAS/LAZ file (no LASF signature, or shorter than a header)")
        # public header fields from byte 94: header size, offset to point data, number of VLRs,
        # point data format, record length, legacy point count
        header_size, data_offset, n_vlr, point_format, record_len, count = struct.unpack_from(
            "<HIIBHI", head, 94
        )
        if header_size < 227 or header_size + 54 * n_vlr > data_offset:
            raise DataError(
                f"{path}: malformed LAS/LAZ header: header size {header_size} and {n_vlr} VLRs "
                f"do not fit before the point data at byte {data_offset}"
            )
        if data_offset > size:
            raise DataError(
                f"{path}: truncated LAS/LAZ file: the point data should start at byte "
                f"{data_offset}, the file has {size} bytes"
            )
        evlr_start = n_evlr = 0
        if (head[24], head[25]) >= (1, 4) and header_size >= 375:
            evlr_start, n_evlr, count64 = struct.unpack_from("<QIQ", head, 235)
            count = count64 or count
            if n_evlr and evlr_start + 60 * n_evlr > size:
                raise DataError(
                    f"{path}: malformed LAS/LAZ header: {n_evlr} extended VLRs from byte "
                    f"{evlr_start} of {size}"
                )
        vlrs = _las_records(f, path, header_size, n_vlr, data_offset, 54, "<H", "VLR")
        if n_evlr:
            _las_records(f, path, evlr_start, n_evlr, size, 60, "<Q", "extended VLR")
        compressed = point_format & 0xC0
        if not compressed:
            if data_offset + count * record_len > size:
                raise DataError(
                    f"{path}: truncated LAS file: the header declares {count} points of "
                    f"{record_len} bytes from byte {data_offset}, the file has {size} bytes"
                )
            return count, record_len
        laszip = vlrs.get(_LASZIP_VLR)
        if laszip is None:
            raise DataError(f"{path}: malformed LAZ file: no laszip VLR (the compression parameters)")
        _check_laz(f, path, size, data_offset, count, record_len, laszip)
    return count, record_len


def _las_records(f, path, start: int, n: int, end: int, head_len: int, len_fmt: str, what: str) -> dict:
    """Walk n (E)VLRs from `start`: each must end by `end`. {(user id, record id): (data start, length)}."""
    found = {}
    pos = start
    for i in range(n):
        f.seek(pos)
        h = f.read(head_len)
        if len(h) < head_len:
            raise DataError(f"{path}: truncated LAS/LAZ file: {what} {i} of {n} at byte {pos}")
        (length,) = struct.unpack_from(len_fmt, h, 20)
        if pos + head_len + length > end:
            raise DataError(
                f"{path}: malformed LAS/LAZ file: {what} {i} at byte {pos} declares "
                f"{length} bytes, past byte {end}"
            )
        key = (h[2:18].rstrip(b"\0"), struct.unpack_from("<H", h, 18)[0])
        found.setdefault(key, (pos + head_len, length))
        pos += head_len + length
    return found


def _check_laz(f, path, size: int, data_offset: int, count: int, record_len: int, laszip) -> None:
    """The laszip VLR, the chunk table and the declared point count against the file."""
    vlr_start, vlr_len = laszip
    f.seek(vlr_start)
    vlr = f.read(vlr_len)
    if len(vlr) < 34:
        raise DataError(f"{path}: malformed LAZ file: a laszip VLR of {len(vlr)} bytes")
    chunk_size = struct.unpack_from("<I", vlr, 12)[0]
    (n_items,) = struct.unpack_from("<H", vlr, 32)
    if 34 + 6 * n_items > len(vlr):
        raise DataError(
            f"{path}: malformed LAZ file: the laszip VLR lists {n_items} items in {len(vlr)} bytes"
        )
    item_bytes = sum(struct.unpack_from("<H", vlr, 34 + 6 * i + 2)[0] for i in range(n_items))
    if item_bytes != record_len:
        raise DataError(
            f"{path}: malformed LAZ file: the laszip items take {item_bytes} bytes per point, "
            f"the header says {record_len}"
        )
    data_bytes = size - data_offset
    if count > _LAZ_MAX_POINTS_PER_BYTE * data_bytes:
        raise DataError(
            f"{path}: the header declares {count} points of {record_len} bytes = "
            f"{_size(count * record_len)} but the file holds {data_bytes} bytes of compressed "
            f"point data (at most {_LAZ_MAX_POINTS_PER_BYTE} points per byte)"
        )
    if count == 0:
        return
    # the chunk table: its offset (int64) starts the point data; -1 means "at the end,
    # the offset in the last 8 bytes"; then version (uint32), number of chunks (uint32)
    f.seek(data_offset)
    raw = f.read(8)
    if len(raw) < 8:
        raise DataError(f"{path}: truncated LAZ file: no chunk table offset at byte {data_offset}")
    (table,) = struct.unpack("<q", raw)
    if table == -1 and size >= 8:
        f.seek(size - 8)
        (table,) = struct.unpack("<q", f.read(8))
    if not data_offset + 8 <= table <= size - 8:
        raise DataError(
            f"{path}: malformed LAZ file: the chunk table offset {table} lies outside the "
            f"point data (bytes {data_offset + 8}..{size - 8})"
        )
    f.seek(table)
    version, n_chunks = struct.unpack("<II", f.read(8))
    # every chunk stores its first point raw: a chunk takes at least record_len bytes
    room = (table - data_offset - 8) // max(record_len, 1)
    if n_chunks > room:
        raise DataError(
            f"{path}: malformed LAZ file: the chunk table declares {n_chunks} chunks, "
            f"the {table - data_offset - 8} bytes of point data hold at most {room}"
        )
    if chunk_size != 0xFFFFFFFF and count > n_chunks * chunk_size:
        raise DataError(
            f"{path}: malformed LAZ file: {count} points do not fit in {n_chunks} chunks of {chunk_size}"
        )
    _check_laz_chunks(f, path, data_offset, table, count, record_len, vlr, chunk_size, n_chunks)


# Layers per item of LASzip's layered compression (point formats 6-10): the
# point (10) has 9, RGB (11) 1, RGB+NIR (12) 2, the wave packet (13) 1, the
# extra bytes (14) one per byte.
_LAZ_LAYERS = {
    10: lambda size: 9,
    11: lambda size: 1,
    12: lambda size: 2,
    13: lambda size: 1,
    14: lambda size: size,
}


def _check_laz_chunks(f, path, data_offset, table, count, record_len, vlr, chunk_size, n_chunks):
    """The chunk table's entries (decoded by lazrs, whose table of n_chunks entries
    is now small) and, for layered compression, each chunk's layer sizes: lazrs
    allocates what these declare, and a failed allocation aborts the process."""
    import lazrs

    f.seek(data_offset)
    try:
        entries = lazrs.read_chunk_table(f, lazrs.LazVlr(vlr))
    except (RuntimeError, ValueError, OSError, OverflowError) as e:
        raise DataError(f"{path}: malformed LAZ file: unreadable chunk table: {e}") from None
    room = table - data_offset - 8
    if len(entries) != n_chunks or sum(b for _, b in entries) > room:
        raise DataError(
            f"{path}: malformed LAZ file: the chunk table's {len(entries)} chunks take "
            f"{sum(b for _, b in entries)} bytes, the point data has {room}"
        )
    if chunk_size == 0xFFFFFFFF:  # variable-size chunks: each says its count
        if sum(p for p, _ in entries) < count or any(p > _LAZ_MAX_POINTS_PER_BYTE * b for p, b in entries):
            raise DataError(
                f"{path}: malformed LAZ file: the chunk table's point counts do not match "
                f"the header's {count} points or their bytes"
            )
    elif not 0 < chunk_size <= _LAZ_MAX_POINTS_PER_BYTE * max((b for _, b in entries), default=0):
        # lazrs sizes its buffers by the chunk size
        raise DataError(
            f"{path}: malformed LAZ file: a chunk size of {chunk_size} points, for chunks of "
            f"at most {max((b for _, b in entries), default=0)} bytes"
        )
    compressor = struct.unpack_from("<H", vlr, 0)[0]
    items = [struct.unpack_from("<HH", vlr, 34 + 6 * i) for i in range(struct.unpack_from("<H", vlr, 32)[0])]
    if compressor != 3 or not all(t in _LAZ_LAYERS for t, _ in items):
        return
    n_layers = sum(_LAZ_LAYERS[t](size) for t, size in items)
    pos = data_offset + 8
    left = count
    for i, (points, nbytes) in enumerate(entries):
        points = points if chunk_size == 0xFFFFFFFF else chunk_size
        # a layered chunk: the first point raw, the number of points (uint32), then the
        # byte count of every layer (uint32 each), then the layers
        f.seek(pos + record_len)
        raw = f.read(4 + 4 * n_layers)
        if len(raw) < 4 + 4 * n_layers:
            raise DataError(f"{path}: truncated LAZ file: chunk {i} at byte {pos}")
        in_chunk, *layers = struct.unpack(f"<{1 + n_layers}I", raw)
        if in_chunk > min(points, left) or sum(layers) > nbytes:
            raise DataError(
                f"{path}: malformed LAZ file: chunk {i} at byte {pos} declares {in_chunk} "
                f"points in layers of {sum(layers)} bytes; the chunk table gives it "
                f"{min(points, left)} points in {nbytes} bytes"
            )
        left -= in_chunk
        pos += nbytes


def _read_las(path: Path) -> PointCloud:
    import laspy

    count, _ = _check_las_header(path)
    try:
        with laspy.open(str(path)) as reader:
            header = reader.header
            if header.point_count != count:
                raise DataError(
                    f"{path}: malformed LAS/LAZ header: laspy reads {header.point_count} "
                    f"points, the header fields say {count}"
                )
            parts = [chunk.array for chunk in reader.chunk_iterator(_LAS_READ_CHUNK)]
        point_format = header.point_format
        array = np.concatenate(parts) if parts else np.zeros(0, point_format.dtype())
        las = laspy.ScaleAwarePointRecord(array, point_format, header.scales, header.offsets)
        n, declared = len(las), header.point_count
    except DataError:
        raise
    except (
        laspy.errors.LaspyException,
        ValueError,
        RuntimeError,
        OverflowError,
        EOFError,
        struct.error,
        OSError,
        KeyError,
        IndexError,
        TypeError,
    ) as e:
        # RuntimeError / lazrs.LazrsError: lazrs's decompression errors
        raise DataError(f"{path}: malformed LAS/LAZ file: {type(e).__name__}: {e}") from e
    if n != declared:
        raise DataError(
            f"{path}: truncated LAS/LAZ file: the header declares {declared} points, {n} were read"
        )
    xyz = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    origin = xyz.min(axis=0) if n else np.zeros(3)
    dims = list(las.point_format.dimension_names)
    fields = {"positions": (xyz - origin).astype(np.float32), "origin": origin}
    if all(c in dims for c in ("red", "green", "blue")):
        rgb = np.stack([np.asarray(las[c]) for c in ("red", "green", "blue")], axis=1)
        fields["colors"] = (rgb >> 8 if n and rgb.max() > 255 else rgb).astype(np.uint8)
    attributes = {}
    for name in dims:
        if name in ("X", "Y", "Z", "red", "green", "blue"):
            continue
        a = np.asarray(las[name])
        if a.ndim != 1:  # array-valued extra bytes
            continue
        if name == "gps_time" and n:
            a = a - a.min()
        attributes[name] = a
    fields["attributes"] = attributes
    return _cloud(path, **fields)


def _read_npy(path: Path) -> PointCloud:
    a = load_npy(path)
    if a.dtype.names:
        if a.ndim != 1:
            raise DataError(f"{path}: expected a 1-D structured array, got shape {a.shape}")
        return _from_columns(path, {k: a[k] for k in a.dtype.names if a.dtype[k].ndim == 0})
    if a.ndim != 2 or a.shape[1] != 3:
        raise DataError(
            f"{path}: expected an (N, 3) array or a structured array with x, y, z fields, got shape {a.shape}"
        )
    return _cloud(path, positions=a)


def _read_npz(path: Path) -> PointCloud:
    arrays = load_npz(path)
    if "positions" not in arrays:
        raise DataError(f"{path}: no 'positions' array (keys: {', '.join(arrays) or 'none'})")
    fields = {k: arrays.pop(k) for k in _NPZ_KEYS if k in arrays}
    fields["attributes"] = arrays
    return _cloud(path, **fields)


# ---------------------------------------------------------------- NPY / NPZ
#
# np.load trusts the header: it allocates what the shape declares (MemoryError,
# or an OverflowError for a shape whose product overflows) before it finds the
# file too short, and its header parser leaks TypeError / TokenError on odd
# headers. These readers parse the header themselves, check the declared size
# against the bytes present, and only then read.

_NPY_MAGIC = b"\x93NUMPY"
_NPY_MAX_HEADER = 10000  # numpy's own limit on the header's length
_ZIP_MAGIC = b"PK\x03\x04"
# zlib's deflate expands at most 1032:1 (a run of one byte), so a deflated NPZ
# member cannot hold more than this many bytes per compressed byte.
_DEFLATE_MAX_RATIO = 1032


def _npy_header(f, name: str, available: int):
    """Parse an NPY header from `f` (at the magic): (dtype, shape, fortran_order,
    nbytes). `available` is the number of bytes from the magic to the end."""
    magic = f.read(8)
    if magic[:6] != _NPY_MAGIC:
        if magic[:4] == _ZIP_MAGIC:
            raise DataError(f"{name}: expected an NPY array, found an NPZ archive")
        raise DataError(f"{name}: not a NumPy file (no NPY magic)")
    if len(magic) < 8 or magic[6] not in (1, 2, 3) or magic[7] != 0:
        raise DataError(f"{name}: malformed NPY file: unknown format version {tuple(magic[6:8])}")
    width = 2 if magic[6] == 1 else 4
    raw = f.read(width)
    if len(raw) < width:
        raise DataError(f"{name}: malformed NPY file: truncated header")
    length = int.from_bytes(raw, "little")
    if length > _NPY_MAX_HEADER:
        raise DataError(f"{name}: malformed NPY file: a header of {length} bytes (at most {_NPY_MAX_HEADER})")
    text = f.read(length)
    if len(text) < length:
        raise DataError(f"{name}: malformed NPY file: truncated header")
    try:
        header = ast.literal_eval(text.decode("utf8" if magic[6] == 3 else "latin1"))
    except (
        ValueError,
        SyntaxError,
        TypeError,
        MemoryError,
        RecursionError,
        UnicodeDecodeError,
        tokenize.TokenError,
    ) as e:
        raise DataError(f"{name}: malformed NPY file: unreadable header ({type(e).__name__})") from None
    if (
        not isinstance(header, dict)
        or set(header) != {"descr", "fortran_order", "shape"}
        or not isinstance(header["fortran_order"], bool)
        or not isinstance(header["shape"], tuple)
        or not all(type(s) is int and s >= 0 for s in header["shape"])
    ):
        raise DataError(
            f"{name}: malformed NPY file: the header is not a dict of descr, fortran_order "
            f"and a shape of non-negative ints: {text[:200]!r}"
        )
    try:
        dtype = np.lib.format.descr_to_dtype(header["descr"])
    except Exception as e:  # numpy's dtype parser raises anything on hostile descr
        raise DataError(
            f"{name}: malformed NPY file: bad dtype {header['descr']!r:.100}: {type(e).__name__}"
        ) from None
    if dtype.hasobject:
        raise DataError(
            f"{name}: the NPY array holds Python objects (dtype {dtype}), which would "
            "need pickle; clvis reads numeric arrays only"
        )
    shape = header["shape"]
    count = math.prod(shape)
    nbytes = count * dtype.itemsize
    have = available - 8 - width - length
    if count * max(dtype.itemsize, 1) > have:
        raise DataError(
            f"{name}: truncated or malformed NPY file: the header declares shape {shape} "
            f"of {dtype} = {_size(nbytes)} but the file holds {max(have, 0)} bytes of data"
        )
    return dtype, shape, header["fortran_order"], nbytes


def _read_npy_stream(f, name: str, available: int) -> np.ndarray:
    """The array of the NPY stream `f` holding `available` bytes (checked first)."""
    dtype, shape, fortran, nbytes = _npy_header(f, name, available)
    buf = bytearray(nbytes)
    got = f.readinto(buf) if nbytes else 0
    if got != nbytes:
        raise DataError(f"{name}: truncated NPY file: {got} of {nbytes} bytes of data")
    if dtype.itemsize == 0:  # e.g. void0 / empty structs: nothing to read
        return np.zeros(shape, dtype, order="F" if fortran else "C")
    a = np.frombuffer(buf, dtype=dtype, count=math.prod(shape))
    return a.reshape(shape, order="F" if fortran else "C")


def _size(n: int) -> str:
    """n bytes, readably."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit} ({n} bytes)"
    return f"{n} bytes"


def load_npy(path: str | os.PathLike[str]) -> np.ndarray:
    """The array of a .npy file; DataError naming the file when it is malformed,
    truncated, declares more data than it holds, holds objects (no pickles) or
    is an .npz archive."""
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            return _read_npy_stream(f, str(path), size)
    except OSError as e:
        if isinstance(e, FileNotFoundError):
            raise
        raise DataError(f"{path}: cannot read: {e.strerror or e}") from e


def npy_shape(path: str | os.PathLike[str]) -> tuple[int, ...]:
    """The shape a .npy file declares, read from its header alone (checked as
    :func:`load_npy` checks it), to tell a volume from a point array."""
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            return tuple(_npy_header(f, str(path), size)[1])
    except OSError as e:
        if isinstance(e, FileNotFoundError):
            raise
        raise DataError(f"{path}: cannot read: {e.strerror or e}") from e


def load_npz(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """The arrays of an .npz archive by key (the member name without .npy);
    DataError naming the file when it is malformed, truncated, an NPY array, or
    declares more data than it holds."""
    name = str(path)
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if f.read(6) == _NPY_MAGIC:
                raise DataError(f"{name}: expected an NPZ archive, found an NPY array")
            f.seek(0)
            with zipfile.ZipFile(f) as z:
                arrays = {}
                for info in z.infolist():
                    arrays[_npz_key(info.filename)] = _npz_member(z, info, name, size)
                return arrays
    except DataError:
        raise
    except FileNotFoundError:
        raise
    except (
        zipfile.BadZipFile,
        zlib.error,
        NotImplementedError,
        RuntimeError,
        EOFError,
        OSError,
        ValueError,
        struct.error,
        OverflowError,
        UnicodeDecodeError,
        KeyError,
    ) as e:
        # NotImplementedError: an unknown compression; RuntimeError: an encrypted member
        raise DataError(f"{name}: malformed NPZ file: {type(e).__name__}: {e}") from None


def _npz_key(member: str) -> str:
    return member[:-4] if member.endswith(".npy") else member


def _npz_member(z: zipfile.ZipFile, info: zipfile.ZipInfo, name: str, size: int) -> np.ndarray:
    where = f"{name} (member {info.filename!r})"
    if info.compress_size > size:
        raise DataError(f"{where}: {info.compress_size} compressed bytes in a file of {size}")
    if info.compress_type == zipfile.ZIP_STORED:
        limit = info.compress_size
    elif info.compress_type == zipfile.ZIP_DEFLATED:
        limit = info.compress_size * _DEFLATE_MAX_RATIO
    else:
        raise DataError(f"{where}: unsupported zip compression {info.compress_type}")
    if info.file_size > limit:
        raise DataError(
            f"{where}: declares {_size(info.file_size)} uncompressed from "
            f"{info.compress_size} compressed bytes"
        )
    with z.open(info) as member:
        return _read_npy_stream(member, where, info.file_size)


# ---------------------------------------------------------------- writing


def _write_or_remove(path, write) -> None:
    """write(file) into `path`; on any failure the partial file is removed."""
    path = Path(path)
    with open(path, "wb") as f:
        try:
            write(f)
        except BaseException:
            f.close()
            path.unlink()
            raise


def _check_cloud(cloud) -> None:
    if not isinstance(cloud, PointCloud):
        raise TypeError(f"cloud: expected a PointCloud, got {type(cloud).__name__}")


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


def save_npz(path: str | os.PathLike[str], cloud: PointCloud) -> None:
    """Write `cloud` as an uncompressed NPZ file with the keys :func:`read_points`
    reads: positions, origin, colors / velocity / radius when present, and one
    key per attribute."""
    _check_cloud(cloud)
    clash = [k for k in cloud.attributes if k in _NPZ_KEYS]
    if clash:
        raise ValueError(f"cloud: attribute names {clash} clash with the NPZ keys {list(_NPZ_KEYS)}")
    arrays = {"positions": cloud.positions, "origin": cloud.origin}
    arrays.update(
        {k: getattr(cloud, k) for k in ("colors", "velocity", "radius") if getattr(cloud, k) is not None}
    )
    arrays.update(cloud.attributes)

    def write(f):
        # np.savez's own keywords (file, allow_pickle) would clash with attribute names
        with zipfile.ZipFile(f, "w") as archive:
            for k, v in arrays.items():
                with archive.open(f"{k}.npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, np.asarray(v), allow_pickle=False)

    _write_or_remove(path, write)
