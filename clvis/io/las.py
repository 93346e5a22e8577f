"""LAS and LAZ point clouds (via laspy; LAZ needs its lazrs backend), with
the header and chunk-table checks that keep a hostile file from allocating or
looping on counts it does not hold."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..errors import DataError
from .cloud import PointCloud, _cloud, bulk_origin, component_columns
from .npy import _size

# 10^4 (50 M points in 1.5 kB) is refused before anything is decompressed.
_LAZ_MAX_POINTS_PER_BYTE = 1000
# Points decompressed at a time (laspy's chunk iterator): 256 Ki points of at
# most 67 bytes (point format 10), ~17 MB per chunk.
_LAS_READ_CHUNK = 1 << 18
_LASZIP_VLR = (b"laszip encoded", 22204)
# LASzip's items (type, bytes) for each point data format, in order, and the
# extra bytes item that follows them: lazrs decodes whatever the VLR lists and
# sizes its buffers from it, so an item that does not belong to the point format
# decodes into re-interpreted points or makes lazrs abort on an allocation.
_POINT10, _GPSTIME11, _RGB12, _WAVE13 = (6, 20), (7, 8), (8, 6), (9, 29)
_POINT14, _RGB14, _RGBNIR14, _WAVE14 = (10, 30), (11, 6), (12, 8), (13, 29)
_LAZ_ITEMS = {
    0: (_POINT10,),
    1: (_POINT10, _GPSTIME11),
    2: (_POINT10, _RGB12),
    3: (_POINT10, _GPSTIME11, _RGB12),
    4: (_POINT10, _GPSTIME11, _WAVE13),
    5: (_POINT10, _GPSTIME11, _RGB12, _WAVE13),
    6: (_POINT14,),
    7: (_POINT14, _RGB14),
    8: (_POINT14, _RGBNIR14),
    9: (_POINT14, _WAVE14),
    10: (_POINT14, _RGBNIR14, _WAVE14),
}
# (extra bytes item type, item versions, compressors) for formats 0-5 and 6-10:
# pointwise (1) or pointwise chunked (2) items of version 1 or 2; layered
# chunked (3) items of version 3
_LAZ_LEGACY = (0, (1, 2), (1, 2))
_LAZ_LAYERED = (14, (3,), (3,))
# LASzip's default chunk: a chunk size up to this, or up to the point count,
# is accepted (lazrs allocates chunk size x record length up front)
_LAZ_DEFAULT_CHUNK = 50_000


def _is_panic(e: BaseException) -> bool:
    """Whether `e` is a Rust panic raised through pyo3 (pyo3_runtime.PanicException,
    which derives from BaseException, not Exception): lazrs panics on some corrupt
    data, e.g. an index out of bounds decoding a chunk table whose entries were
    overwritten."""
    return type(e).__name__ == "PanicException" and type(e).__module__ == "pyo3_runtime"


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
            if n_evlr and evlr_start >= size:
                raise DataError(
                    f"{path}: truncated LAS/LAZ file: its {n_evlr} extended VLRs should start at byte "
                    f"{evlr_start}, the file has {size} bytes"
                )
            if n_evlr and evlr_start + 60 * n_evlr > size:
                raise DataError(
                    f"{path}: truncated LAS/LAZ file, or a wrong header: {n_evlr} extended VLRs "
                    f"from byte {evlr_start} do not fit in its {size} bytes"
                )
        vlrs = _las_records(f, path, header_size, n_vlr, data_offset, 54, "<H", "VLR")
        if n_evlr:
            _las_records(f, path, evlr_start, n_evlr, size, 60, "<Q", "extended VLR")
        _check_extra_bytes(f, path, vlrs.get(_EXTRA_BYTES_VLR), point_format & 0x3F, record_len)
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
        _check_laz(f, path, size, data_offset, count, record_len, laszip, point_format & 0x3F)
    return count, record_len


# The extra bytes VLR: 192-byte descriptors; data_type (byte 2) 0 is "undocumented
# bytes", as many as options (byte 3) says; 1-10 scalars, 11-30 (LAS 1.3) arrays of them
_EXTRA_BYTES_VLR = (b"LASF_Spec", 4)
# a (E)VLR's key (user id, record id) and its data's place (start byte, length)
_RecordKey = tuple[bytes, int]
_Record = tuple[int, int]

_EXTRA_SIZES = (1, 1, 2, 2, 4, 4, 8, 8, 4, 8)
_BASE_RECORD = {0: 20, 1: 28, 2: 26, 3: 34, 4: 57, 5: 63, 6: 30, 7: 36, 8: 38, 9: 59, 10: 67}


def _check_extra_bytes(
    f: BinaryIO, path: Path, record: _Record | None, point_format: int, record_len: int
) -> None:
    """The extra bytes descriptors against the record: laspy divides by a
    descriptor's element size (0 for a data type 0 of no bytes) and lays the
    dimensions out in the record without checking that they fit."""
    if record is None:
        return
    start, length = record
    f.seek(start)
    raw = f.read(length)
    if length % 192 or len(raw) != length:
        raise DataError(
            f"{path}: malformed LAS/LAZ file: an extra bytes VLR of {length} bytes (192 per field)"
        )
    total = 0
    for i in range(length // 192):
        kind, options = raw[192 * i + 2], raw[192 * i + 3]
        if not raw[192 * i + 4 : 192 * i + 36].split(b"\0", 1)[0]:  # laspy lists it, then cannot give it
            raise DataError(f"{path}: malformed LAS/LAZ file: extra bytes field {i} has no name")
        if kind == 0:
            size = options
        elif kind <= 30:
            size = _EXTRA_SIZES[(kind - 1) % 10] * (1 + (kind - 1) // 10)
        else:
            size = 0
        if size == 0:
            raise DataError(
                f"{path}: malformed LAS/LAZ file: extra bytes field {i} has data type {kind} "
                f"of {size} bytes (types 0 with a byte count, 1-30)"
            )
        total += size
    room = record_len - _BASE_RECORD.get(point_format, 0)
    if total > room:
        raise DataError(
            f"{path}: malformed LAS/LAZ file: the extra bytes fields take {total} bytes, "
            f"the {record_len}-byte records of point format {point_format} have {room}"
        )


def _las_records(
    f: BinaryIO, path: Path, start: int, n: int, end: int, head_len: int, len_fmt: str, what: str
) -> dict[_RecordKey, _Record]:
    """Walk n (E)VLRs from `start`: each must end by `end`. {(user id, record id): (data start, length)}."""
    found: dict[_RecordKey, _Record] = {}
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


def _check_laz_items(path: Path, vlr: bytes, n_items: int, record_len: int, point_format: int) -> None:
    """The laszip VLR's compressor and items must be the canonical ones of the
    header's point format: (type, size, version) of each, then at most one
    extra bytes item of the bytes the record has beyond the format's own."""
    base = _LAZ_ITEMS.get(point_format)
    if base is None:
        raise DataError(f"{path}: malformed LAZ file: unknown point data format {point_format}")
    extra_type, versions, compressors = _LAZ_LAYERED if point_format >= 6 else _LAZ_LEGACY
    (compressor,) = struct.unpack_from("<H", vlr, 0)
    if compressor not in compressors:
        raise DataError(
            f"{path}: malformed LAZ file: compressor {compressor} for point format {point_format} "
            f"(expected {' or '.join(map(str, compressors))})"
        )
    items = [struct.unpack_from("<HHH", vlr, 34 + 6 * i) for i in range(n_items)]
    extra = record_len - sum(n for _, n in base)
    want = list(base) + ([(extra_type, extra)] if extra > 0 else [])
    if extra < 0 or [(t, n) for t, n, _ in items] != want or any(v not in versions for _, _, v in items):
        raise DataError(
            f"{path}: malformed LAZ file: the laszip VLR lists items (type, size, version) "
            f"{[tuple(i) for i in items]}; point format {point_format} with {record_len}-byte "
            f"records needs {[(t, n) for t, n in want]}, version {' or '.join(map(str, versions))}"
        )


def _check_laz(
    f: BinaryIO,
    path: Path,
    size: int,
    data_offset: int,
    count: int,
    record_len: int,
    laszip: _Record,
    point_format: int,
) -> None:
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
    _check_laz_items(path, vlr, n_items, record_len, point_format)
    if chunk_size != 0xFFFFFFFF and chunk_size > max(count, _LAZ_DEFAULT_CHUNK):
        raise DataError(
            f"{path}: malformed LAZ file: a chunk size of {chunk_size} points for {count} points "
            f"(at most the point count, or {_LAZ_DEFAULT_CHUNK})"
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


def _check_laz_chunks(
    f: BinaryIO,
    path: Path,
    data_offset: int,
    table: int,
    count: int,
    record_len: int,
    vlr: bytes,
    chunk_size: int,
    n_chunks: int,
) -> None:
    """The chunk table's entries (decoded by lazrs, whose table of n_chunks entries
    is now small) and, for layered compression, each chunk's layer sizes: lazrs
    allocates what these declare, and a failed allocation aborts the process."""
    import lazrs

    f.seek(data_offset)
    try:
        entries = lazrs.read_chunk_table(f, lazrs.LazVlr(vlr))
    except (RuntimeError, ValueError, OSError, OverflowError) as e:
        raise DataError(f"{path}: malformed LAZ file: unreadable chunk table: {e}") from None
    except BaseException as e:
        if not _is_panic(e):
            raise
        raise DataError(f"{path}: malformed LAZ file: unreadable chunk table: lazrs: {e}") from None
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
        ZeroDivisionError,
    ) as e:
        # RuntimeError / lazrs.LazrsError: lazrs's decompression errors
        raise DataError(f"{path}: malformed LAS/LAZ file: {type(e).__name__}: {e}") from e
    except BaseException as e:  # a panic inside lazrs's decompression
        if not _is_panic(e):
            raise
        raise DataError(f"{path}: malformed LAZ file: lazrs: {e}") from None
    if n != declared:
        raise DataError(
            f"{path}: truncated LAS/LAZ file: the header declares {declared} points, {n} were read"
        )
    xyz = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    origin = bulk_origin(xyz)  # the minimum (of the bulk, where stray records lie far away)
    dims = list(las.point_format.dimension_names)
    fields: dict[str, object] = {"positions": (xyz - origin).astype(np.float32), "origin": origin}
    if all(c in dims for c in ("red", "green", "blue")):
        rgb = np.stack([np.asarray(las[c]) for c in ("red", "green", "blue")], axis=1)
        fields["colors"] = (rgb >> 8 if n and rgb.max() > 255 else rgb).astype(np.uint8)
    attributes: dict[str, np.ndarray] = {}
    for name in dims:
        if name in ("X", "Y", "Z", "red", "green", "blue"):
            continue
        a = np.asarray(las[name])
        if a.ndim == 2:  # an array-valued extra bytes field (3 colours, a normal): one attribute a value
            # (they were dropped without a word), named as a VTK array's components are
            attributes.update(component_columns(name, a))
            continue
        if a.ndim != 1:
            continue
        if name == "gps_time" and n:
            a = a - a.min()
        attributes[name] = a
    fields["attributes"] = attributes
    return _cloud(path, **fields)
