"""VTK image data volumes: XML ``.vti`` (ImageData, one piece; the first
point-data array, or the one its ``Scalars`` names; inline ``binary``
(base64, zlib-compressed or not) or ``ascii`` arrays) and legacy ``.vtk``
STRUCTURED_POINTS (ASCII or BINARY; the first SCALARS).

Bounded: the header's extents and sizes are checked against the data the
file holds before anything is decompressed or allocated; a DTD or entity
declaration is refused (no entity expansion); appended data and several
pieces, which VTK's own writers use for large files, raise a DataError
saying so.
"""

from __future__ import annotations

import base64
import binascii
import re
import zlib
from pathlib import Path

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
_MAX_RATIO = 1100  # zlib expands at most ~1032x: a header claiming more lies


def _attrs(tag: bytes) -> dict[str, str]:
    """A tag's attributes; a value that is not UTF-8 keeps U+FFFD for its bad
    bytes (then an unknown type or a malformed number, refused by name, not a
    UnicodeDecodeError)."""
    return {k.decode(): v.decode("utf-8", "replace") for k, v in re.findall(rb'(\w+)\s*=\s*"([^"]*)"', tag)}


def _numbers(path, what, text, n, kind=float):
    try:
        v = [kind(t) for t in text.split()]
    except ValueError:
        v = []
    if len(v) != n:
        raise DataError(f"{path}: malformed {what} {text!r} (expected {n} numbers)")
    return v


def read_vti(path: Path) -> tuple[np.ndarray, tuple, list]:
    """(data (Z, Y, X), spacing (dz, dy, dx), origin (x, y, z))."""
    raw = path.read_bytes()
    if b"<!DOCTYPE" in raw[:4096] or b"<!ENTITY" in raw[:4096]:
        raise DataError(f"{path}: a VTK file with a DTD or entities is not read")
    head = re.search(rb"<VTKFile\b[^>]*>", raw)
    image = re.search(rb"<ImageData\b[^>]*>", raw)
    if head is None or image is None:
        raise DataError(f'{path}: not a VTK ImageData file (no <VTKFile type="ImageData"> and <ImageData>)')
    fa, ia = _attrs(head.group(0)), _attrs(image.group(0))
    if b"<AppendedData" in raw:
        raise DataError(
            f"{path}: VTK appended data is not read; save the file with inline data (binary or ascii)"
        )
    if len(re.findall(rb"<Piece\b", raw)) != 1:
        raise DataError(f"{path}: one Piece expected (a VTK image of several pieces is not read)")
    ext = _numbers(path, "WholeExtent", ia.get("WholeExtent", ""), 6, int)
    nx, ny, nz = (ext[1] - ext[0] + 1, ext[3] - ext[2] + 1, ext[5] - ext[4] + 1)
    if min(nx, ny, nz) < 1:
        raise DataError(f"{path}: empty WholeExtent {ext}")
    spacing = _numbers(path, "Spacing", ia.get("Spacing", "1 1 1"), 3)
    origin = _numbers(path, "Origin", ia.get("Origin", "0 0 0"), 3)
    pd = re.search(rb"<PointData\b([^>]*)>(.*?)</PointData>", raw, re.S)
    arrays = re.findall(rb"(<DataArray\b[^>]*>)(.*?)</DataArray>", pd.group(2), re.S) if pd else []
    if pd is None or not arrays:
        raise DataError(f"{path}: no point data array (cell data is not read)")
    want = _attrs(b"<x " + pd.group(1) + b">").get("Scalars")
    tag, body = next(((t, b) for t, b in arrays if want and _attrs(t).get("Name") == want), arrays[0])
    a = _attrs(tag)
    t = _VTI_TYPES.get(a.get("type", ""))
    if t is None:
        raise DataError(f"{path}: unsupported DataArray type {a.get('type')!r}")
    if int(a.get("NumberOfComponents", "1")) != 1:
        raise DataError(f"{path}: array {a.get('Name')!r} has several components; a volume has one")
    n = nx * ny * nz
    order = ">" if fa.get("byte_order") == "BigEndian" else "<"
    dtype = np.dtype(order + t)
    fmt = a.get("format", "ascii")
    if fmt == "ascii":
        if n > len(body):
            raise DataError(f"{path}: {n} samples declared, the array holds {len(body)} bytes of text")
        try:
            data = np.array(body.split(), dtype=np.float64).astype(dtype)
        except ValueError as e:
            raise DataError(f"{path}: malformed ascii array: {e}") from None
    elif fmt == "binary":
        data = _inline_binary(path, body, fa, dtype, n)
    else:
        raise DataError(f"{path}: DataArray format {fmt!r} is not read (binary or ascii)")
    if data.size != n:
        raise DataError(f"{path}: the array holds {data.size} samples, the extent {nx}x{ny}x{nz} needs {n}")
    return (
        data.astype(dtype.newbyteorder("=")).reshape(nz, ny, nx),
        (spacing[2], spacing[1], spacing[0]),
        origin,
    )


def _inline_binary(path, body, fa, dtype, n):
    hs = 8 if fa.get("header_type") == "UInt64" else 4
    hdt = np.dtype(("<" if fa.get("byte_order") != "BigEndian" else ">") + ("u8" if hs == 8 else "u4"))
    text = re.sub(rb"\s+", b"", body)
    try:
        if fa.get("compressor") is None:
            blob = base64.b64decode(text, validate=True)
            size = int(np.frombuffer(blob[:hs], hdt)[0]) if len(blob) >= hs else -1
            if size != n * dtype.itemsize or len(blob) < hs + size:
                raise DataError(f"{path}: the array's byte count does not match its extent")
            return np.frombuffer(blob[hs : hs + size], dtype)
        if "ZLib" not in fa["compressor"]:
            raise DataError(f"{path}: compressor {fa['compressor']} is not read (zlib only)")
        first = base64.b64decode(text[: 4 * -(-hs // 3) + 4], validate=True)
        blocks = int(np.frombuffer(first[:hs], hdt)[0])
        hchars = 4 * -(-(3 + blocks) * hs // 3)
        header = np.frombuffer(
            base64.b64decode(text[:hchars], validate=True)[: (3 + blocks) * hs], hdt
        ).astype(np.int64)
        block, last, sizes = int(header[1]), int(header[2]), header[3:]
        total = block * (blocks - 1) + (last or block) if blocks else 0
        if total != n * dtype.itemsize:
            raise DataError(
                f"{path}: the compressed array holds {total} bytes, the extent needs {n * dtype.itemsize}"
            )
        comp = base64.b64decode(text[hchars:], validate=True)
        if int(sizes.sum()) > len(comp) or total > _MAX_RATIO * max(len(comp), 1):
            raise DataError(f"{path}: truncated or malformed compressed array")
        out, pos = bytearray(), 0
        for k, s in enumerate(sizes):
            want = last if (k == blocks - 1 and last) else block
            d = zlib.decompressobj()
            chunk = d.decompress(comp[pos : pos + int(s)], want)
            if len(chunk) != want:
                raise DataError(f"{path}: block {k} decompresses to {len(chunk)} bytes, not {want}")
            out += chunk
            pos += int(s)
        return np.frombuffer(bytes(out), dtype)
    except (binascii.Error, zlib.error, ValueError, IndexError) as e:
        raise DataError(f"{path}: malformed binary array: {e}") from None


def read_legacy(path: Path) -> tuple[np.ndarray, tuple, list]:
    """A legacy .vtk STRUCTURED_POINTS file: (data, spacing zyx, origin xyz);
    the point data's first SCALARS (CELL_DATA and FIELD sections before it are
    passed over)."""
    raw = path.read_bytes()
    lines = raw[:4096].split(b"\n")[:12]
    text = [t.decode("latin-1").strip() for t in lines]
    if not text or not text[0].startswith("# vtk DataFile"):
        raise DataError(f"{path}: not a legacy VTK file (no '# vtk DataFile' line)")
    up = [t.upper() for t in text]
    if len(up) < 4 or "STRUCTURED_POINTS" not in up[3]:
        kind = up[3] if len(up) > 3 else "?"
        raise DataError(f"{path}: legacy VTK {kind.title()!r}: only DATASET STRUCTURED_POINTS is a volume")
    binary = up[2] == "BINARY"
    f = {}
    for line in text[4:]:
        if not line or line.split()[0].upper() in ("POINT_DATA", "CELL_DATA"):
            break
        f[line.split()[0].upper()] = line.split()[1:]
    if "DIMENSIONS" not in f:
        raise DataError(f"{path}: malformed STRUCTURED_POINTS header: no DIMENSIONS")
    nx, ny, nz = _numbers(path, "DIMENSIONS", " ".join(f["DIMENSIONS"]), 3, int)
    spacing = _numbers(path, "SPACING", " ".join(f.get("SPACING", f.get("ASPECT_RATIO", ["1", "1", "1"]))), 3)
    origin = _numbers(path, "ORIGIN", " ".join(f.get("ORIGIN", ["0", "0", "0"])), 3)
    m = re.search(
        rb"(?:^|\n)POINT_DATA[ \t]+(\d+)[ \t\r]*\n+SCALARS[ \t]+(\S+)[ \t]+(\S+)(?:[ \t]+(\d+))?[ \t\r]*\n"
        rb"LOOKUP_TABLE[ \t]+\S+[ \t\r]*\n",
        raw,
    )
    if m is None:
        raise DataError(f"{path}: no POINT_DATA SCALARS with a LOOKUP_TABLE (cell data is not read)")
    t = _LEGACY_TYPES.get(m.group(3).decode("latin-1").lower())
    if t is None or (m.group(4) is not None and m.group(4) != b"1"):
        scalars = m.group(0).splitlines()[-2].decode("latin-1")
        raise DataError(f"{path}: {scalars!r}: one component of a numeric type expected")
    n = nx * ny * nz
    if min(nx, ny, nz) < 1 or int(m.group(1)) != n:
        raise DataError(f"{path}: POINT_DATA {int(m.group(1))} does not match DIMENSIONS {nx} {ny} {nz}")
    pos = m.end()
    dtype = np.dtype(">" + t)  # legacy binary is big-endian
    if binary:
        if pos + n * dtype.itemsize > len(raw):
            raise DataError(f"{path}: truncated: {n} samples of {dtype.itemsize} bytes after byte {pos}")
        data = np.frombuffer(raw, dtype, count=n, offset=pos)
    else:
        tokens = raw[pos:].split(maxsplit=n)[:n]
        if len(tokens) < n:
            raise DataError(f"{path}: {len(tokens)} samples, DIMENSIONS needs {n}")
        try:
            data = np.array(tokens, dtype=np.float64).astype(dtype)
        except ValueError as e:
            raise DataError(f"{path}: malformed ascii samples: {e}") from None
    return (
        data.astype(dtype.newbyteorder("=")).reshape(nz, ny, nx),
        (spacing[2], spacing[1], spacing[0]),
        origin,
    )
