"""NPY and NPZ files read safely (points and volumes both use these).

np.load trusts the header: it allocates what the shape declares (MemoryError,
or an OverflowError for a shape whose product overflows) before it finds the
file too short, and its header parser leaks TypeError / TokenError on odd
headers. These readers parse the header themselves, check the declared size
against the bytes present, and only then read.
"""

from __future__ import annotations

import ast
import math
import os
import struct
import tokenize
import zipfile
import zlib

import numpy as np

from ..errors import DataError
from .files import regular_file

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
    path = regular_file(path)
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
    path = regular_file(path)
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
    path = regular_file(path)
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
