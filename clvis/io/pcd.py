"""Point Cloud Library files (``.pcd``): ASCII and binary data, the header's
FIELDS, SIZE, TYPE, COUNT, WIDTH, HEIGHT and POINTS checked against the
file's length before anything is allocated.

x, y, z become positions; ``rgb`` (a float32 or uint32 packing 0x00RRGGBB,
PCL's convention) or ``rgba`` the colours; normal_x.. and every other
single-count field attributes (fields with COUNT > 1, such as feature
histograms, are skipped). NaN points (the holes of an organized cloud) are
kept; the renderers skip them. ``binary_compressed`` (LZF) is refused with
the command that converts it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import DataError
from .cloud import PointCloud, _from_columns

_MAX_HEADER = 1 << 16
_TYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4", ("I", 8): "<i8",
          ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4", ("U", 8): "<u8"}  # fmt: skip
_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")


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
        line = head[pos:end].decode("ascii", "replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        if key.upper() not in _KEYS:
            raise DataError(f"{path}: not a PCD file (header line {line[:60]!r})")
        entries[key.upper()] = values
        if key.upper() == "DATA":
            return entries, pos


def _read_pcd(path: Path) -> PointCloud:
    h, offset = _header(path)
    for key in ("FIELDS", "SIZE", "TYPE", "POINTS", "DATA"):
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
        t = _TYPES.get((typ.upper(), size))
        if t is None:
            raise DataError(f"{path}: PCD field {name!r}: unsupported TYPE {typ} SIZE {size}")
        dtypes.append((name, t) if count == 1 else (name, t, (count,)))
    try:
        dtype = np.dtype(dtypes)
    except (ValueError, TypeError) as e:
        raise DataError(f"{path}: malformed PCD fields: {e}") from None
    kind = h["DATA"][0].lower() if h["DATA"] else ""
    file_size = path.stat().st_size
    if kind == "binary":
        need = offset + points * dtype.itemsize
        if need > file_size:
            raise DataError(
                f"{path}: truncated PCD file: {points} points of {dtype.itemsize} bytes need {need} bytes, "
                f"the file has {file_size}"
            )
        data = np.fromfile(path, dtype=dtype, count=points, offset=offset)
    elif kind == "ascii":
        if points > file_size:  # each point takes at least one byte of text
            raise DataError(
                f"{path}: the header declares {points} points, more than the file's {file_size} bytes"
            )
        flat = []
        for name, count in zip(fields, counts_i, strict=True):
            flat += [name] if count == 1 else [f"{name}_{k}" for k in range(count)]
        try:
            with open(path, "rb") as f:
                f.seek(offset)
                rows = np.loadtxt(f, dtype=np.float64, ndmin=2, max_rows=points)
        except ValueError as e:
            raise DataError(f"{path}: malformed PCD data: {e}") from None
        if rows.shape[0] != points or (points and rows.shape[1] != len(flat)):
            raise DataError(
                f"{path}: {rows.shape[0]} rows of {rows.shape[1]} values; "
                f"the header declares {points} of {len(flat)}"
            )
        data = np.zeros(points, dtype)
        col = 0
        for name, t, *shape in dtypes:
            k = shape[0][0] if shape else 1
            vals = rows[:, col : col + k]
            if name.lower() in ("rgb", "rgba") and np.dtype(t).itemsize == 4:
                v = vals[:, 0]
                # a packed float (PCL's) or the packed integer (some writers)
                whole = np.isfinite(v) & (v >= 1) & (v == np.round(v)) & (v < 2**32)
                bits = np.where(whole, 0, v).astype(np.float32).view(np.uint32)
                data[name] = np.where(whole, v, bits).astype(np.uint32).view(np.dtype(t))
            elif k == 1:
                data[name] = vals[:, 0]
            else:
                data[name] = vals
            col += k
    elif kind == "binary_compressed":
        raise DataError(
            f"{path}: binary_compressed PCD (LZF) is not read; convert it with "
            "pcl_convert_pcd_ascii_binary FILE OUT.pcd 1 (binary)"
        )
    else:
        raise DataError(f"{path}: malformed PCD header: DATA {' '.join(h['DATA'])!r}")
    columns = {}
    for name in data.dtype.names or ():
        if data.dtype[name].shape:
            continue  # multi-count fields (histograms, ...)
        low = name.lower()
        if low in ("rgb", "rgba"):
            packed = (
                np.ascontiguousarray(data[name]).view(np.uint32) if data.dtype[name].itemsize == 4 else None
            )
            if packed is None:
                raise DataError(f"{path}: PCD field {name!r} must be 4 bytes (packed 0xAARRGGBB)")
            columns["red"] = ((packed >> 16) & 255).astype(np.uint8)
            columns["green"] = ((packed >> 8) & 255).astype(np.uint8)
            columns["blue"] = (packed & 255).astype(np.uint8)
        else:
            columns[low] = data[name]
    return _from_columns(path, columns)
