"""Mutation operators: generic ones (bit flips, random bytes, extreme integers,
length fields, truncation, appends, splices) and field-aware edits of the
LAS/LAZ header, VLRs and laszip items, NIfTI-1/2 headers and extensions, ZIP
(NPZ) records, NPY headers, VDB descriptors and E57 files (numbers of the XML,
the binary header, with the page checksums made right again). Each takes (rng, data, seed)
and returns the mutant's bytes; :func:`mutate` picks one (or two) at random.
"""

from __future__ import annotations

import gzip
import re
import struct

import numpy as np

EXTREMES = [
    0,
    1,
    2,
    7,
    8,
    0x7F,
    0x80,
    0xFF,
    0x100,
    0x7FFF,
    0x8000,
    0xFFFF,
    0x10000,
    0x7FFFFFF0,
    0x7FFFFFFF,
    0x80000000,
    0xFFFFFFFF,
    0xFFFF0001,
    1 << 32,
    1 << 40,
    (1 << 63) - 1,
    1 << 63,
    (1 << 64) - 1,
]


def _extreme(rng, width: int, old: int | None = None) -> int:
    vals = list(EXTREMES)
    if old is not None:
        vals += [old + 1, old - 1, old * 2, old * 16, old // 2, old + 1000, -old]
    return int(vals[rng.integers(0, len(vals))]) & ((1 << 8 * width) - 1)


def _put(b: bytearray, at: int, width: int, value: int) -> None:
    if 0 <= at and at + width <= len(b):
        b[at : at + width] = (value & ((1 << 8 * width) - 1)).to_bytes(width, "little")


def _get(b, at: int, width: int) -> int:
    return int.from_bytes(b[at : at + width], "little")


# ---------------------------------------------------------------- generic


def bit_flips(rng, data: bytes, seed) -> bytes:
    b = bytearray(data)
    for _ in range(int(rng.integers(1, 9))):
        i = int(rng.integers(0, len(b)))
        b[i] ^= 1 << int(rng.integers(0, 8))
    return bytes(b)


def random_bytes(rng, data: bytes, seed) -> bytes:
    b = bytearray(data)
    head = min(len(b), int(rng.choice([64, 512, 4096, len(b)])))
    for _ in range(int(rng.integers(1, 6))):
        b[int(rng.integers(0, head))] = int(rng.integers(0, 256))
    return bytes(b)


def extreme_int(rng, data: bytes, seed) -> bytes:
    b = bytearray(data)
    width = int(rng.choice([1, 2, 4, 8]))
    head = min(len(b), int(rng.choice([128, 400, 1024, len(b)])))
    at = int(rng.integers(0, max(1, head - width)))
    _put(b, at, width, _extreme(rng, width, _get(b, at, width)))
    return bytes(b)


def length_field(rng, data: bytes, seed) -> bytes:
    """An aligned 2/4/8-byte field whose value could be a length, count or offset
    into the file (0 < v <= size) set to an extreme or a near miss."""
    b = bytearray(data)
    width = int(rng.choice([2, 4, 8]))
    n = len(b)
    picks = [
        at for at in range(0, min(n, 8192) - width + 1, 2 if width == 2 else 4) if 0 < _get(b, at, width) <= n
    ]
    if not picks:
        return extreme_int(rng, data, seed)
    at = picks[int(rng.integers(0, len(picks)))]
    _put(b, at, width, _extreme(rng, width, _get(b, at, width)))
    return bytes(b)


def truncate(rng, data: bytes, seed) -> bytes:
    n = len(data)
    cut = int(
        rng.choice([rng.integers(0, n), n - rng.integers(1, min(n, 64) + 1), rng.integers(0, min(n, 600))])
    )
    return data[: max(cut, 0)]


def append(rng, data: bytes, seed) -> bytes:
    kind = int(rng.integers(0, 3))
    k = int(rng.choice([1, 7, 64, 4096, 65536]))
    tail = (
        bytes(k)
        if kind == 0
        else bytes(rng.integers(0, 256, k, dtype=np.uint8))
        if kind == 1
        else data[-min(k, len(data)) :]
    )
    return data + tail


def splice(rng, data: bytes, seed, others=()) -> bytes:
    """A run of bytes from another seed of the format (or this one) written over,
    or inserted into, this one."""
    donors = [o for o in others if o] or [data]
    donor = donors[int(rng.integers(0, len(donors)))]
    if not data or not donor:
        return data
    k = int(rng.integers(1, min(len(donor), 512) + 1))
    src = int(rng.integers(0, len(donor) - k + 1))
    at = int(rng.integers(0, len(data)))
    piece = donor[src : src + k]
    if rng.integers(0, 2):
        return data[:at] + piece + data[at + k :]
    return data[:at] + piece + data[at:]


# ---------------------------------------------------------------- LAS / LAZ


# public header fields: (offset, width)
_LAS_FIELDS = [
    (24, 1), (25, 1), (94, 2), (96, 4), (100, 4), (104, 1), (105, 2), (107, 4), (111, 4),
    (131, 8), (155, 8), (179, 8), (187, 8), (227, 8), (235, 8), (243, 4), (247, 8), (255, 8),
]  # fmt: skip


def _las_vlrs(b) -> list[tuple[int, bytes, int, int]]:
    """[(header position, user id, record id, length)] of the VLRs."""
    out = []
    if len(b) < 104 or b[:4] != b"LASF":
        return out
    header_size, _, n = struct.unpack_from("<HII", b, 94)
    pos = header_size
    for _ in range(min(n, 64)):
        if pos + 54 > len(b):
            break
        uid = bytes(b[pos + 2 : pos + 18]).rstrip(b"\0")
        rid, length = struct.unpack_from("<HH", b, pos + 18)
        out.append((pos, uid, rid, length))
        pos += 54 + length
    return out


def las_fields(rng, data: bytes, seed) -> bytes:
    b = bytearray(data)
    vlrs = _las_vlrs(b)
    choice = int(rng.integers(0, 5))
    if choice == 0 or not vlrs:  # a public header field
        at, width = _LAS_FIELDS[int(rng.integers(0, len(_LAS_FIELDS)))]
        if width == 8 and at in (131, 155, 179, 187) and rng.integers(0, 2):  # a double
            v = float(rng.choice([0.0, -1.0, 1e-300, 1e300, np.inf, np.nan, 1e-9]))
            if at + 8 <= len(b):  # a first operator may have truncated the header
                struct.pack_into("<d", b, at, v)
        else:
            _put(b, at, width, _extreme(rng, width, _get(b, at, width)))
        return bytes(b)
    pos, uid, rid, length = vlrs[int(rng.integers(0, len(vlrs)))]
    laszip = next((v for v in vlrs if (v[1], v[2]) == (b"laszip encoded", 22204)), None)
    extra = next((v for v in vlrs if (v[1], v[2]) == (b"LASF_Spec", 4)), None)
    if choice == 1:  # a VLR's length or record id
        at, width = (pos + 20, 2) if rng.integers(0, 2) else (pos + 18, 2)
        _put(b, at, width, _extreme(rng, width, _get(b, at, width)))
    elif choice == 2 and laszip is not None:  # the laszip VLR: compressor, chunk size, items
        d = laszip[0] + 54
        n_items = _get(b, d + 32, 2)
        fields = [(d, 2), (d + 2, 2), (d + 12, 4), (d + 16, 8), (d + 24, 8), (d + 32, 2)]
        fields += [(d + 34 + 6 * i + k, 2) for i in range(min(n_items, 8)) for k in (0, 2, 4)]
        at, width = fields[int(rng.integers(0, len(fields)))]
        old = _get(b, at, width)
        if at >= d + 34 and rng.integers(0, 2):  # another item type, size or version: small values
            _put(
                b,
                at,
                width,
                int(rng.integers(0, 16)) if (at - d - 34) % 6 != 2 else old + int(rng.integers(-3, 4)),
            )
        else:
            _put(b, at, width, _extreme(rng, width, old))
    elif choice == 3 and extra is not None:  # an extra bytes descriptor
        d = extra[0] + 54 + 192 * int(rng.integers(0, max(1, extra[3] // 192)))
        at = d + int(rng.choice([2, 3, 2, 3, 64, 72, 80]))
        _put(b, at, 1, int(rng.integers(0, 256)))
    else:  # the chunk table (LAZ): its offset, or an entry
        data_offset = _get(b, 96, 4)
        if data_offset + 8 <= len(b):
            if rng.integers(0, 2):
                _put(b, data_offset, 8, _extreme(rng, 8, _get(b, data_offset, 8)))
            else:
                table = _get(b, data_offset, 8)
                if table == (1 << 64) - 1 and len(b) >= 8:
                    table = _get(b, len(b) - 8, 8)
                at = table + int(rng.integers(0, 24)) if table < len(b) else len(b) - 8
                _put(b, at, 4, _extreme(rng, 4, _get(b, at, 4)))
    return bytes(b)


# ---------------------------------------------------------------- NIfTI

_NII1 = [
    (0, 4),
    (40, 2),
    (42, 2),
    (44, 2),
    (46, 2),
    (48, 2),
    (68, 2),
    (70, 2),
    (72, 2),
    (108, 4),
    (348, 1),
    (352, 4),
]
_NII2 = [
    (0, 4),
    (12, 2),
    (14, 2),
    (16, 8),
    (24, 8),
    (32, 8),
    (40, 8),
    (48, 8),
    (168, 8),
    (504, 4),
    (540, 1),
    (544, 4),
]
_NII_FLOATS = {108: "<f", 112: "<f", 116: "<f", 80: "<f", 84: "<f", 88: "<f"}


def nifti_fields(rng, data: bytes, seed) -> bytes:
    gz = data[:2] == b"\x1f\x8b"
    try:
        raw = bytearray(gzip.decompress(data)) if gz else bytearray(data)
    except Exception:  # noqa: BLE001 - already mutated: leave it
        return data
    two = _get(raw, 0, 4) == 540
    fields = _NII2 if two else _NII1
    if not two and rng.integers(0, 4) == 0:  # a float field
        at = int(rng.choice(list(_NII_FLOATS)))
        v = float(rng.choice([0.0, -1.0, np.nan, np.inf, 1e30, 3.4e38, 352.0, 1e9]))
        if at + 4 <= len(raw):
            struct.pack_into("<f", raw, at, v)
    elif rng.integers(0, 4) == 0:  # a large extension
        ext = 540 if two else 348
        if ext + 12 <= len(raw):
            raw[ext] = 1
            _put(raw, ext + 4, 4, _extreme(rng, 4, _get(raw, ext + 4, 4)))
    else:
        at, width = fields[int(rng.integers(0, len(fields)))]
        _put(raw, at, width, _extreme(rng, width, _get(raw, at, width)))
    return gzip.compress(bytes(raw)) if gz else bytes(raw)


# ---------------------------------------------------------------- ZIP (NPZ)

_ZIP_RECORDS = {
    b"PK\x03\x04": [(8, 2), (14, 4), (18, 4), (22, 4), (26, 2), (28, 2)],
    b"PK\x01\x02": [(10, 2), (20, 4), (24, 4), (28, 2), (30, 2), (32, 2), (42, 4)],
    b"PK\x05\x06": [(8, 2), (10, 2), (12, 4), (16, 4), (20, 2)],
    b"PK\x06\x06": [(24, 8), (32, 8), (40, 8), (48, 8)],
    b"PK\x06\x07": [(8, 8), (16, 4)],
}


def zip_fields(rng, data: bytes, seed) -> bytes:
    b = bytearray(data)
    spots = [(m.start(), sig) for sig in _ZIP_RECORDS for m in re.finditer(re.escape(sig), data)]
    # zip64 extra fields (id 1): their 8-byte sizes and offsets
    zip64 = [m.start() for m in re.finditer(b"\x01\x00(\x08|\x10|\x18)\x00", data)]
    if zip64 and rng.integers(0, 3) == 0:
        at = zip64[int(rng.integers(0, len(zip64)))] + 4 + 8 * int(rng.integers(0, 2))
        _put(b, at, 8, _extreme(rng, 8, _get(b, at, 8)))
        return bytes(b)
    if not spots:
        return extreme_int(rng, data, seed)
    pos, sig = spots[int(rng.integers(0, len(spots)))]
    off, width = _ZIP_RECORDS[sig][int(rng.integers(0, len(_ZIP_RECORDS[sig])))]
    _put(b, pos + off, width, _extreme(rng, width, _get(b, pos + off, width)))
    return bytes(b)


# ---------------------------------------------------------------- NPY

_DESCRS = [
    "'<f8'",
    "'|V0'",
    "'<U1000000'",
    "'>i4'",
    "'|O'",
    "[('a', '<f4', (1000000,))]",
    "'<f4'",
    "'|b1'",
    "'<c16'",
]
_SHAPES = [
    "(2147483648, 3)",
    "(0, 3)",
    "(-1, 3)",
    "(3,)",
    "(10**9, 10**9)",
    "(4, 5, 6)",
    "(1 << 62, 3)",
    "()",
]


def npy_header(rng, data: bytes, seed) -> bytes:
    """Edits of the header dict (its length field kept), or of the length field."""
    if data[:6] != b"\x93NUMPY" or len(data) < 10:
        return extreme_int(rng, data, seed)
    width = 2 if data[6] == 1 else 4
    n = _get(data, 8, width)
    head = data[8 + width : 8 + width + n].decode("latin1")
    kind = int(rng.integers(0, 4))
    if kind == 0:
        head = re.sub(
            r"'descr': [^,]*(\[.*?\])?",
            "'descr': " + _DESCRS[int(rng.integers(0, len(_DESCRS)))],
            head,
            count=1,
        )
    elif kind == 1:
        head = re.sub(r"'shape': \([^)]*\)", "'shape': " + _SHAPES[int(rng.integers(0, len(_SHAPES)))], head)
    elif kind == 2:
        head = head.replace("False", "True") if "False" in head else head.replace("True", "False")
    else:
        b = bytearray(data)
        _put(b, 8, width, _extreme(rng, width, n))
        return bytes(b)
    body = head.rstrip(" \n")
    pad = (-(8 + width + len(body) + 1)) % 64
    head = body + " " * pad + "\n"
    return data[:8] + len(head).to_bytes(width, "little") + head.encode("latin1") + data[8 + width + n :]


# ---------------------------------------------------------------- VDB


def vdb_fields(rng, data: bytes, seed) -> bytes:
    """The header (version, grid count), then a string length, grid offset or
    node count (4- and 8-byte fields after the header)."""
    b = bytearray(data)
    if rng.integers(0, 3) == 0:
        at, width = [(8, 4), (12, 4), (16, 4), (20, 1), (57, 4), (61, 4)][int(rng.integers(0, 6))]
        _put(b, at, width, _extreme(rng, width, _get(b, at, width)))
        return bytes(b)
    return length_field(rng, data, seed)


def _crc32c_table() -> list[int]:
    table = []
    for n in range(256):
        c = n
        for _ in range(8):
            c = (c >> 1) ^ (0x82F63B78 if c & 1 else 0)
        table.append(c)
    return table


_CRC32C = _crc32c_table()
E57_PAGE = 1024  # E57 physical pages: 1020 bytes of data and their CRC-32C, big-endian


def _crc32c(data: bytes) -> int:
    crc = 0xFFFFFFFF
    for byte in data:
        crc = (crc >> 8) ^ _CRC32C[(crc ^ byte) & 0xFF]
    return crc ^ 0xFFFFFFFF


def _e57_checksums(b: bytearray) -> None:
    """Every whole page's checksum made right again, so that libE57Format's
    parser (not its page check) meets the edit."""
    for at in range(0, len(b) - E57_PAGE + 1, E57_PAGE):
        b[at + 1020 : at + 1024] = _crc32c(bytes(b[at : at + 1020])).to_bytes(4, "big")


def e57_fields(rng, data: bytes, seed) -> bytes:
    """An E57 file past its page checksums: a number of the XML section (a
    recordCount, fileOffset, length, or bound) overwritten by digits of the same
    length, a field of the binary header (file length, XML offset and length,
    page size) set to an extreme, or random bytes in a page; then every page's
    CRC-32C recomputed."""
    b = bytearray(data)
    numbers = [m.span(1) for m in re.finditer(rb'(?:="|>)(-?\d+)(?:"|<)', bytes(b))]
    pick = int(rng.integers(0, 3))
    if pick == 0 and numbers:
        lo, hi = numbers[int(rng.integers(0, len(numbers)))]
        digits = (
            "9" * (hi - lo)
            if rng.integers(0, 2)
            else "".join(str(int(d)) for d in rng.integers(0, 10, hi - lo))
        )
        b[lo:hi] = digits.encode()
    elif pick == 1 and len(b) >= 48:
        at = [16, 24, 32, 40][int(rng.integers(0, 4))]
        _put(b, at, 8, _extreme(rng, 8, _get(b, at, 8)))
    else:
        for _ in range(int(rng.integers(1, 9))):
            if b:
                b[int(rng.integers(0, len(b)))] = int(rng.integers(0, 256))
    _e57_checksums(b)
    return bytes(b)


FIELD_AWARE = {
    "e57": e57_fields,
    "las": las_fields,
    "laz": las_fields,
    "nii": nifti_fields,
    "nii.gz": nifti_fields,
    "hdr": nifti_fields,  # an Analyze 7.5 header: the layout NIfTI-1 extends (348 bytes)
    "npz": zip_fields,
    "npy": npy_header,
    "vdb": vdb_fields,
}
GENERIC = [bit_flips, random_bytes, extreme_int, length_field, truncate, append, splice]


def operators(fmt: str) -> list:
    ops = list(GENERIC)
    if fmt in FIELD_AWARE:
        ops += [FIELD_AWARE[fmt]] * 4  # field-aware edits: about half the mutants
    return ops


def mutate(rng, data: bytes, fmt: str, others=()) -> tuple[bytes, str]:
    """(mutant, the operators' names)."""
    ops = operators(fmt)
    names = []
    for _ in range(1 if rng.random() < 0.8 else 2):
        if not data:  # a truncation left nothing: the empty file is the case
            break
        op = ops[int(rng.integers(0, len(ops)))]
        if fmt == "nii.gz" and op is not nifti_fields and rng.integers(0, 2):
            # mostly mutate the decompressed header, then compress again
            try:
                data = gzip.compress(op(rng, gzip.decompress(data), None))
            except Exception:  # noqa: BLE001
                data = op(rng, data, None)
        else:
            data = op(rng, data, None, others) if op is splice else op(rng, data, None)
        names.append(op.__name__)
    return data, "+".join(names)
