"""Point Cloud Library files (``.pcd``) through pypcd4 (the ``pcd`` extra):
``ascii``, ``binary`` and ``binary_compressed`` (LZF) data.

Bounded: before pypcd4 reads, the header (FIELDS, SIZE, TYPE, COUNT, WIDTH,
HEIGHT, POINTS, DATA, each once, in PCL's spelling, within the first 64 kB)
is checked, and the points it declares against the file's length: binary
data must hold POINTS records, compressed data's sizes must match them and
the bytes the file holds (LZF expands at most ~90x), ascii data needs a byte
a point; so a hostile header cannot make the library allocate gigabytes.

x, y, z become positions; ``rgb`` (a float32 or uint32 packing 0x00RRGGBB,
PCL's convention) or ``rgba`` the colours; normal_x.. and every other
single-count field attributes (fields with COUNT > 1, such as feature
histograms, and ``_`` padding are skipped). NaN points (the holes of an
organized cloud) are kept; the renderers skip them.
"""

from __future__ import annotations

import io
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .cloud import PointCloud, _from_columns

_MAX_HEADER = 1 << 16
_MAX_LZF_RATIO = 90  # an LZF back-reference of 3 bytes copies at most 264: a header claiming more lies
_TYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4", ("I", 8): "<i8",
          ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4", ("U", 8): "<u8"}  # fmt: skip
_LINE = re.compile(
    r"[\w.+\-]+(?:\s+[\w.+\-]+)*"
)  # words and numbers: what pypcd4's header parser takes whole
_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")


def _pypcd4() -> Any:
    try:
        import pypcd4
    except ImportError:
        raise ImportError(
            'reading .pcd files needs pypcd4: pip install "clvis[pcd]" (".[pcd]" in a clvis checkout, '
            "or pip install pypcd4)"
        ) from None
    return pypcd4


def _header(path: Path) -> tuple[dict, int]:
    """(the header's entries, the byte offset of the data)."""
    with open(path, "rb") as f:
        head = f.read(_MAX_HEADER)
    entries: dict[str, list[str]] = {}
    pos = 0
    while True:
        end = head.find(b"\n", pos)
        if end < 0:
            raise DataError(f"{path}: not a PCD file, or a truncated one (no DATA line in its first 64 kB)")
        try:
            line = head[pos:end].decode("ascii").strip()
        except UnicodeDecodeError:
            raise DataError(f"{path}: not a PCD file (a header line that is not ASCII)") from None
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        if key not in _KEYS or not _LINE.fullmatch(line):
            raise DataError(f"{path}: not a PCD file (header line {line[:60]!r})")
        if key in entries:
            raise DataError(f"{path}: malformed PCD header: {key} twice")
        entries[key] = values
        if key == "DATA":
            return entries, pos


def _check(path: Path) -> tuple[dict, list[int], int, str]:
    """The header checked against the file: (entries, COUNTs, POINTS, DATA)."""
    h, offset = _header(path)
    for key in ("FIELDS", "SIZE", "TYPE", "WIDTH", "POINTS", "DATA"):
        if key not in h:
            raise DataError(f"{path}: malformed PCD header: no {key} line")
    fields = h["FIELDS"]
    n = len(fields)
    counts = h.get("COUNT", ["1"] * n)
    if not (len(h["SIZE"]) == len(h["TYPE"]) == len(counts) == n):
        raise DataError(f"{path}: malformed PCD header: FIELDS, SIZE, TYPE and COUNT differ in length")
    try:
        sizes, counts_i, points = [int(s) for s in h["SIZE"]], [int(c) for c in counts], int(h["POINTS"][0])
    except (ValueError, IndexError):
        raise DataError(f"{path}: malformed PCD header: SIZE, COUNT and POINTS must be integers") from None
    if points < 0 or any(c < 1 for c in counts_i):
        raise DataError(f"{path}: malformed PCD header: POINTS {points}, COUNT {counts}")
    dtypes = []
    for name, size, typ, count in zip(fields, sizes, h["TYPE"], counts_i, strict=True):
        t = _TYPES.get((typ, size))
        if t is None:
            raise DataError(f"{path}: PCD field {name!r}: unsupported TYPE {typ} SIZE {size}")
        dtypes.append((name, t) if count == 1 else (name, t, (count,)))
    try:
        itemsize = np.dtype(dtypes).itemsize
    except (ValueError, TypeError) as e:
        raise DataError(f"{path}: malformed PCD fields: {e}") from None
    kind = h["DATA"][0] if len(h["DATA"]) == 1 else ""
    file_size = path.stat().st_size
    if kind == "binary":
        need = offset + points * itemsize
        if need > file_size:
            raise DataError(
                f"{path}: truncated PCD file: {points} points of {itemsize} bytes need {need} bytes, "
                f"the file has {file_size}"
            )
    elif kind == "binary_compressed":
        if points:
            with open(path, "rb") as f:
                f.seek(offset)
                sizes8 = f.read(8)
            if len(sizes8) < 8:
                raise DataError(f"{path}: truncated PCD file: no compressed-data sizes after the header")
            packed, unpacked = (int(v) for v in np.frombuffer(sizes8, "<u4"))
            if unpacked != points * itemsize:
                raise DataError(
                    f"{path}: the compressed data unpack to {unpacked} bytes; {points} points of "
                    f"{itemsize} bytes need {points * itemsize}"
                )
            if offset + 8 + packed > file_size or unpacked > _MAX_LZF_RATIO * packed + 64:
                raise DataError(
                    f"{path}: truncated or malformed compressed PCD data ({packed} bytes declared, "
                    f"{file_size - offset - 8} in the file)"
                )
    elif kind == "ascii":
        if points > file_size:  # each point takes at least one byte of text
            raise DataError(
                f"{path}: the header declares {points} points, more than the file's {file_size} bytes"
            )
    else:
        raise DataError(f"{path}: malformed PCD header: DATA {' '.join(h['DATA'])!r}")
    return h, counts_i, points, kind


def _read_pcd(path: Path) -> PointCloud:
    h, counts, points, kind = _check(path)
    pypcd4 = _pypcd4()
    colour = [k for k, f in enumerate(h["FIELDS"]) if f.lower() in ("rgb", "rgba") and h["TYPE"][k] == "F"]
    try:
        if kind == "ascii" and colour:
            # PCL writes a float-typed rgb in ascii as its packed uint32 (pcd_io.cpp), which
            # float32 cannot hold (0xFF alpha): read as float64 and unpacked below
            raw = path.read_bytes()
            at = raw.index(b"\nSIZE ") + 1
            end = raw.index(b"\n", at)
            sizes = h["SIZE"][:]
            for k in colour:
                sizes[k] = "8"
            raw = raw[:at] + ("SIZE " + " ".join(sizes)).encode() + raw[end:]
            pc = pypcd4.PointCloud.from_fileobj(io.BufferedReader(io.BytesIO(raw)))
        else:
            pc = pypcd4.PointCloud.from_path(path)
        data = np.atleast_1d(pc.pc_data)
    except MemoryError:
        raise
    except Exception as e:  # pydantic's ValidationError, numpy's ValueError, lzf's, ...: not a readable PCD
        why = " ".join(str(e).split())[:200]
        raise DataError(f"{path}: malformed PCD data: {type(e).__name__}: {why}") from None
    names = tuple("_" if f.startswith("#$%&~~") else f for f in pc.metadata.fields)  # pypcd4's padding
    if names != tuple(h["FIELDS"]) or tuple(pc.metadata.count) != tuple(counts):
        raise DataError(f"{path}: malformed PCD header (pypcd4 reads the fields {names})")
    if data.shape[0] != points:
        raise DataError(f"{path}: {data.shape[0]} rows of data; the header declares {points} points")
    columns = {}
    for name, count in zip(h["FIELDS"], counts, strict=True):
        if count != 1 or name == "_":
            continue  # multi-count fields (histograms, ...) and padding
        low = name.lower()
        column = data[name]
        if low in ("rgb", "rgba"):
            if column.dtype == np.float64 and kind == "ascii":  # a packed float, or the packed integer
                v = column
                whole = np.isfinite(v) & (v >= 1) & (v == np.round(v)) & (v < 2**32)
                bits = np.where(whole, 0, v).astype(np.float32).view(np.uint32)
                column = np.where(whole, v, bits).astype(np.uint32)
            if column.dtype.itemsize != 4:
                raise DataError(f"{path}: PCD field {name!r} must be 4 bytes (packed 0xAARRGGBB)")
            packed = np.ascontiguousarray(column).view(np.uint32)
            columns["red"] = ((packed >> 16) & 255).astype(np.uint8)
            columns["green"] = ((packed >> 8) & 255).astype(np.uint8)
            columns["blue"] = (packed & 255).astype(np.uint8)
        else:
            columns[low] = np.ascontiguousarray(column)
    return _from_columns(path, columns)
