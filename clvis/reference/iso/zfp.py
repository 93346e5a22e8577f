"""ZFP fixed-rate decoding of 3-D float32 volumes, step by step in Python.

The definition of what ``kernels_cl/iso/zfp.cl`` computes (mirrors
``clvis.zfp``: :func:`decode`, :func:`decode_blocks`). Written to be read, not
to be fast: a few milliseconds a block, for small volumes in the tests.

The stream (zfp's fixed-rate mode, ``zfpy.compress_numpy(v, rate=r,
write_header=False)``): a volume [Z, Y, X] is zfp's field nx = X, ny = Y,
nz = Z, cut into 4x4x4 blocks that run x fastest, then y, then z. Every block
takes exactly ``maxbits = 64 * rate`` bits, so block b is words
``[b * rate, (b + 1) * rate)`` of the stream read as little-endian 64-bit
words, bits least significant first. Inside a block:

1. 1 bit: 0 means the block is all zeros (the rest of its bits are padding).
2. 8 bits: the common exponent, emax = field - 127.
3. ``maxbits - 9`` bits at most of embedded bit-plane coding (:func:`decode_ints`):
   64 unsigned 32-bit coefficients, bit plane 31 first, each plane a verbatim
   run for the coefficients already significant and a group test for the
   others; decoding stops when the bit budget runs out. (Fixed-rate mode sets
   zfp's maxprec = 64 and minexp = -1074, so all 32 planes are allowed and the
   budget is the only limit.)
4. Negabinary to two's complement: ``(u ^ 0xaaaaaaaa) - 0xaaaaaaaa``.
5. Coefficient i goes to block position :data:`PERM_3` [i] (sequency order).
6. The inverse decorrelating transform: :func:`inv_lift` along z, then y,
   then x, in wrapping 32-bit integer arithmetic.
7. value = float32(i) * float32(2^(emax - 30)), both rounded to float32 as zfp
   does (``ldexpf(1, emax - 30)`` is 0 below 2^-149; the product may round to a
   subnormal).

A block at the edge of the volume is decoded whole; only its in-range values
are kept (zfp padded it on encode).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__all__ = [
    "EBIAS",
    "NBMASK",
    "PERM_3",
    "block_words",
    "decode",
    "decode_block",
    "decode_blocks",
    "decode_ints",
    "dequantize",
    "expected_nbytes",
    "grid",
    "inv_lift",
    "inv_xform",
]

EBIAS = 127
NBMASK = 0xAAAAAAAA


def _ix(x, y, z):
    return x + 4 * y + 16 * z


# zfp's coefficient order for 3-D blocks: (x, y, z) by x + y + z, then by
# x^2 + y^2 + z^2 (ties in zfp's own order: this table is part of the format)
PERM_3 = (
    _ix(0, 0, 0),
    _ix(1, 0, 0),
    _ix(0, 1, 0),
    _ix(0, 0, 1),
    _ix(0, 1, 1),
    _ix(1, 0, 1),
    _ix(1, 1, 0),
    _ix(2, 0, 0),
    _ix(0, 2, 0),
    _ix(0, 0, 2),
    _ix(1, 1, 1),
    _ix(2, 1, 0),
    _ix(2, 0, 1),
    _ix(0, 2, 1),
    _ix(1, 2, 0),
    _ix(1, 0, 2),
    _ix(0, 1, 2),
    _ix(3, 0, 0),
    _ix(0, 3, 0),
    _ix(0, 0, 3),
    _ix(2, 1, 1),
    _ix(1, 2, 1),
    _ix(1, 1, 2),
    _ix(0, 2, 2),
    _ix(2, 0, 2),
    _ix(2, 2, 0),
    _ix(3, 1, 0),
    _ix(3, 0, 1),
    _ix(0, 3, 1),
    _ix(1, 3, 0),
    _ix(1, 0, 3),
    _ix(0, 1, 3),
    _ix(1, 2, 2),
    _ix(2, 1, 2),
    _ix(2, 2, 1),
    _ix(3, 1, 1),
    _ix(1, 3, 1),
    _ix(1, 1, 3),
    _ix(3, 2, 0),
    _ix(3, 0, 2),
    _ix(0, 3, 2),
    _ix(2, 3, 0),
    _ix(2, 0, 3),
    _ix(0, 2, 3),
    _ix(2, 2, 2),
    _ix(3, 2, 1),
    _ix(3, 1, 2),
    _ix(1, 3, 2),
    _ix(2, 3, 1),
    _ix(2, 1, 3),
    _ix(1, 2, 3),
    _ix(0, 3, 3),
    _ix(3, 0, 3),
    _ix(3, 3, 0),
    _ix(3, 2, 2),
    _ix(2, 3, 2),
    _ix(2, 2, 3),
    _ix(1, 3, 3),
    _ix(3, 1, 3),
    _ix(3, 3, 1),
    _ix(2, 3, 3),
    _ix(3, 2, 3),
    _ix(3, 3, 2),
    _ix(3, 3, 3),
)


def grid(shape: Sequence[int]) -> tuple[int, int, int]:
    """Blocks along (z, y, x) of a [Z, Y, X] volume."""
    z, y, x = (-(-int(s) // 4) for s in shape)
    return z, y, x


def expected_nbytes(shape: Sequence[int], rate: int) -> int:
    """Bytes of the fixed-rate stream: rate 64-bit words per block."""
    nbz, nby, nbx = grid(shape)
    return nbz * nby * nbx * rate * 8


def block_words(stream: bytes | np.ndarray, b: int, rate: int) -> np.ndarray:
    """The `rate` little-endian 64-bit words of block b."""
    words = np.frombuffer(bytes(stream), dtype="<u8")
    return words[b * rate : (b + 1) * rate]


class _Bits:
    """Reads one block's bits, least significant bit of word 0 first; never
    beyond the block (an AssertionError if the decoder tried)."""

    def __init__(self, words: np.ndarray):
        self.value = int.from_bytes(np.asarray(words, "<u8").tobytes(), "little")
        self.size = 64 * len(words)
        self.pos = 0

    def read(self, n: int) -> int:
        assert self.pos + n <= self.size, "read past the block"
        v = (self.value >> self.pos) & ((1 << n) - 1)
        self.pos += n
        return v


def decode_ints(bits: _Bits, budget: int) -> list[int]:
    """zfp's embedded decoding of 64 unsigned 32-bit coefficients with at
    most `budget` bits (the rate-constrained path of decode_few_ints)."""
    data = [0] * 64
    n = 0  # coefficients significant so far
    for k in range(31, -1, -1):  # bit plane k, most significant first
        if budget == 0:
            break
        # the first n bits of the plane, verbatim
        m = min(n, budget)
        budget -= m
        x = bits.read(m)
        # the rest: group tests, each followed by a unary run to the next one-bit
        while budget and n < 64:
            budget -= 1
            if not bits.read(1):
                break  # no more one-bits in this plane
            while budget and n < 63:
                budget -= 1
                if bits.read(1):
                    break
                n += 1
            x |= 1 << n  # set even when the budget ran out (as zfp does)
            n += 1
        for i in range(64):
            if (x >> i) & 1:
                data[i] |= 1 << k
    return data


def inv_lift(v: np.ndarray, axis: int) -> None:
    """zfp's inverse lifting of the 4-vectors along `axis` of the int32 block v, in place."""
    a = np.moveaxis(v, axis, 0)  # a view: assignments write into v
    x, y, z, w = (a[i].copy() for i in range(4))
    y += w >> 1
    w -= y >> 1
    y += w
    w -= y - w
    z += x
    x -= z - x
    y += z
    z -= y - z
    w += x
    x -= w - x
    a[0], a[1], a[2], a[3] = x, y, z, w


def inv_xform(block: np.ndarray) -> None:
    """The inverse transform of a [z, y, x] int32 block: along z, then y, then x."""
    for axis in (0, 1, 2):
        inv_lift(block, axis)


def dequantize(iblock: np.ndarray, emax: int) -> np.ndarray:
    """float32(i) * float32(2^(emax - 30)), each step rounded to float32."""
    with np.errstate(over="ignore", under="ignore"):
        s = np.ldexp(np.float32(1.0), np.int32(emax - 30)).astype(np.float32)
        return iblock.astype(np.float32) * s


def decode_block(words: np.ndarray, rate: int) -> np.ndarray:
    """The 64 float32 values of the block in `words` (its `rate` words), in
    zfp's in-block order: index x + 4 y + 16 z."""
    bits = _Bits(words)
    if not bits.read(1):
        return np.zeros(64, np.float32)
    emax = bits.read(8) - EBIAS
    u = np.array(decode_ints(bits, 64 * rate - 9), np.uint32)
    signed = ((u ^ np.uint32(NBMASK)) - np.uint32(NBMASK)).view(np.int32)
    flat = np.zeros(64, np.int32)
    flat[list(PERM_3)] = signed
    block = flat.reshape(4, 4, 4)  # [z, y, x]
    inv_xform(block)
    return dequantize(block.reshape(64), emax)


def _check(stream, shape, rate):
    shape = tuple(int(s) for s in shape)
    if len(bytes(stream)) != expected_nbytes(shape, rate):
        raise ValueError(f"stream: {len(bytes(stream))} bytes, expected {expected_nbytes(shape, rate)}")
    return shape


def decode(stream: bytes | np.ndarray, shape: Sequence[int], rate: int) -> np.ndarray:
    """The float32 volume of `shape` ([Z, Y, X]) in a headerless fixed-rate stream."""
    shape = _check(stream, shape, rate)
    nbz, nby, nbx = grid(shape)
    out = np.zeros(shape, np.float32)
    b = 0
    for bz in range(nbz):
        for by in range(nby):
            for bx in range(nbx):
                block = decode_block(block_words(stream, b, rate), rate).reshape(4, 4, 4)
                z, y, x = 4 * bz, 4 * by, 4 * bx
                part = out[z : z + 4, y : y + 4, x : x + 4]
                part[...] = block[: part.shape[0], : part.shape[1], : part.shape[2]]
                b += 1
    return out


def decode_blocks(
    stream: bytes | np.ndarray, ids: npt.ArrayLike, shape: Sequence[int], rate: int
) -> np.ndarray:
    """(len(ids), 64) float32: block ids[j] (x-fastest block order) in row j,
    in zfp's in-block order x + 4 y + 16 z."""
    shape = _check(stream, shape, rate)
    nbz, nby, nbx = grid(shape)
    ids = np.asarray(ids, np.int64).reshape(-1)
    out = np.zeros((len(ids), 64), np.float32)
    for j, b in enumerate(ids):
        if not 0 <= b < nbz * nby * nbx:
            raise ValueError(f"ids[{j}] = {b} is not a block of the volume")
        out[j] = decode_block(block_words(stream, int(b), rate), rate)
    return out
