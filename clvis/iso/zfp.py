"""ZFP fixed-rate compression of 3-D volumes, decoded on the device.

:func:`compress` goes through zfpy (``zfpy.compress_numpy(v, rate=r,
write_header=False)``) after converting the volume to float32; the result is
a :class:`ZfpVolume` (the headerless stream, shape, rate). :func:`decode`
turns a stream back into the float32 volume with the OpenCL kernel of
``kernels_cl/iso/zfp.cl`` (the block decoder lives in
``kernels_cl/include/clvis/zfp.h`` for other kernels to reuse), bit for bit
what zfpy's own decompression gives. :func:`decode_blocks` decodes a list of
blocks into 64-float bricks on the device, for block caches.

The format: rate r (an integer, 1..32) gives every 4x4x4 block exactly
64 r bits (r little-endian 64-bit words), blocks x fastest over zfp's
nx = X, ny = Y, nz = Z of a [Z, Y, X] volume, partial blocks at the edges
padded by zfp on encode. Inside a brick, value i is voxel (x, y, z) of the
block with i = x + 4 y + 16 z. The steps are spelled out in
``clvis.reference.iso.zfp``.

Validation: a stream's length is fixed by its shape and rate
(:func:`expected_nbytes`); a shorter or longer one raises
:class:`~clvis.DataError` naming both lengths (a stream with a zfp header is
recognised by its magic and named as such). The contents are not checked:
in fixed-rate mode any bits decode to *some* values, so a corrupt stream of
the right length decodes to garbage (finite or infinite, never NaN) without
error, and the kernels never read outside the stream whatever it holds.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime
from .._arrays import is_device, nonnegative_int, resolve_queue, result
from ..errors import DataError
from ..io.volumes import Volume

__all__ = [
    "BRICK_VALUES",
    "MAX_RATE",
    "MIN_RATE",
    "PROFILES",
    "ZfpVolume",
    "compress",
    "decode",
    "decode_blocks",
    "expected_nbytes",
]

MIN_RATE, MAX_RATE = 1, 32
BRICK_VALUES = 64  # floats per decoded block, index x + 4 y + 16 z
_SRC = "iso/zfp.cl"
_MAX_SIDE = 1 << 31  # nx, ny, nz are uint in the kernels (plus 3 for rounding up)
_MAX_BLOCKS = (1 << 32) - 1  # block ids are uint
_ZFP_MAGIC = b"zfp"  # a stream written with a header starts with it
# the fixed local size of the one-work-item-per-block kernels (a driver-chosen
# one would make PoCL compile a work-group function per launch size)
PROFILES = {"cpu": {"wg": 64}, "gpu": {"wg": 64}}


def _as_bytes(stream) -> bytes:
    """A host stream (bytes, a numpy array, anything with the buffer protocol) as bytes."""
    if isinstance(stream, np.ndarray):
        return np.ascontiguousarray(stream).tobytes()
    if isinstance(stream, bytes):
        return stream
    try:
        return bytes(memoryview(stream))
    except TypeError:
        raise TypeError(f"stream: expected bytes or an array, got {type(stream).__name__}") from None


def _check_rate(rate) -> int:
    if isinstance(rate, bool) or not isinstance(rate, (int, float, np.integer, np.floating)):
        raise TypeError(f"rate: expected an integer, got {type(rate).__name__}")
    r = float(rate)
    if not (math.isfinite(r) and r == int(r)):
        raise ValueError(f"rate: only integer rates (bits per value) are supported, got {rate!r}")
    r = int(r)
    if not MIN_RATE <= r <= MAX_RATE:
        raise ValueError(f"rate: expected an integer in [{MIN_RATE}, {MAX_RATE}], got {r}")
    return r


def _check_shape(shape) -> tuple[int, int, int]:
    try:
        dims = tuple(shape)
    except TypeError:
        raise TypeError(f"shape: expected three integers (Z, Y, X), got {shape!r}") from None
    if len(dims) != 3:
        raise ValueError(f"shape: expected three sizes (Z, Y, X), got {dims!r}")
    out = []
    for d in dims:
        d = nonnegative_int("shape", d)
        if not d < _MAX_SIDE:
            raise ValueError(f"shape: each size must be in [0, 2^31), got {dims!r}")
        out.append(int(d))
    nblocks = math.prod(-(-d // 4) for d in out)
    if nblocks > _MAX_BLOCKS:
        raise ValueError(f"shape: {tuple(out)} has {nblocks} blocks of 4^3; at most 2^32 - 1")
    return out[0], out[1], out[2]


def _grid(shape) -> tuple[int, int, int]:
    return tuple(-(-d // 4) for d in shape)


def expected_nbytes(shape: Sequence[int], rate: int) -> int:
    """The exact byte length of a headerless fixed-rate stream of a float32
    volume of `shape` ([Z, Y, X]) at `rate`: 8 rate bytes per 4^3 block."""
    shape, rate = _check_shape(shape), _check_rate(rate)
    return math.prod(_grid(shape)) * rate * 8


def _length_error(nbytes: int, shape, rate, head: bytes | None = None) -> DataError:
    want = expected_nbytes(shape, rate)
    nblocks = math.prod(_grid(shape))
    what = (
        f"stream: {nbytes} bytes, but a fixed-rate stream of shape {shape} at rate {rate} "
        f"is exactly {want} bytes ({nblocks} blocks of {8 * rate})"
    )
    if nbytes < want:
        return DataError(f"{what}: it is {want - nbytes} bytes short (truncated?)")
    hint = ""
    if head is not None and head[:3] == _ZFP_MAGIC:
        hint = "; it starts with a zfp header: compress with write_header=False"
    return DataError(f"{what}: it has {nbytes - want} bytes too many{hint}")


@dataclasses.dataclass(frozen=True)
class ZfpVolume:
    """A float32 volume compressed by zfp at a fixed rate.

    stream: the headerless stream (bytes); shape: (Z, Y, X) of the volume;
    rate: bits per value, an integer in 1..32. Construction checks that the
    stream has exactly :func:`expected_nbytes` bytes (DataError if not).
    """

    stream: bytes
    shape: tuple
    rate: int

    def __post_init__(self):
        stream = self.stream
        if is_device(stream):
            raise TypeError(
                "stream: a ZfpVolume keeps its stream on the host; pass bytes "
                "(decode() takes device streams directly)"
            )
        stream = _as_bytes(stream)
        shape, rate = _check_shape(self.shape), _check_rate(self.rate)
        if len(stream) != expected_nbytes(shape, rate):
            raise _length_error(len(stream), shape, rate, stream[:3])
        object.__setattr__(self, "stream", stream)
        object.__setattr__(self, "shape", shape)
        object.__setattr__(self, "rate", rate)

    @property
    def blocks(self) -> tuple[int, int, int]:
        """The block grid (nbz, nby, nbx): ceil of each side / 4."""
        return _grid(self.shape)

    @property
    def nblocks(self) -> int:
        return math.prod(self.blocks)

    @property
    def nbytes(self) -> int:
        """Bytes of the compressed stream."""
        return len(self.stream)

    @property
    def compression_ratio(self) -> float:
        """float32 bytes of the volume / compressed bytes (inf for an empty volume)."""
        return 4 * math.prod(self.shape) / self.nbytes if self.nbytes else math.inf

    def block_id(self, bz: int, by: int, bx: int) -> int:
        """The stream index of block (bz, by, bx): x fastest."""
        nbz, nby, nbx = self.blocks
        if not (0 <= bz < nbz and 0 <= by < nby and 0 <= bx < nbx):
            raise ValueError(f"block ({bz}, {by}, {bx}) is outside the grid {self.blocks}")
        return (bz * nby + by) * nbx + bx

    def block_origin(self, block_id: int) -> tuple[int, int, int]:
        """The voxel (z, y, x) of block `block_id`'s first value."""
        _, nby, nbx = self.blocks
        if not 0 <= block_id < self.nblocks:
            raise ValueError(f"block_id: {block_id} is outside [0, {self.nblocks})")
        return (4 * (block_id // (nbx * nby)), 4 * (block_id // nbx % nby), 4 * (block_id % nbx))

    def to_device(self, queue: cl.CommandQueue | None = None) -> cla.Array:
        """The stream on the device: a uint64 ``pyopencl.array.Array`` of its
        words, which :func:`decode` and :func:`decode_blocks` take in place of
        the bytes."""
        q = resolve_queue(queue)
        return _upload(q, self.stream)

    def decode(self, *, queue: cl.CommandQueue | None = None, host: bool = True) -> np.ndarray | cla.Array:
        """:func:`decode` of this volume."""
        return decode(self, queue=queue, host=host)

    def __repr__(self) -> str:
        return f"ZfpVolume(shape={self.shape}, rate={self.rate}, nbytes={self.nbytes})"


def compress(volume: Any, rate: int) -> ZfpVolume:
    """Compress a 3-D volume ([Z, Y, X]; or a clvis.Volume's data) with zfp at a fixed integer `rate`
    (bits per value, 1..32). float32 is compressed as it is; float64, float16
    and integer volumes are converted to float32 first. A non-finite value
    (after the conversion: float64 beyond float32's range too) raises
    DataError naming how many and the first. Needs zfpy."""
    rate = _check_rate(rate)
    v = volume.get() if is_device(volume) else volume
    if isinstance(v, Volume):  # clvis.read_volume's: its samples
        v = v.data
    if isinstance(v, (str, bytes)) or v is None:
        raise TypeError(f"volume: expected an array, got {type(v).__name__}")
    from ..io.objects import refuse_foreign

    refuse_foreign(v, "Volume", "volume: expected an array or a clvis.Volume")
    v = np.asarray(v)
    if v.dtype.kind not in "iuf":
        raise TypeError(f"volume: dtype {v.dtype} is not supported; expected floats or integers")
    if v.ndim != 3:
        raise ValueError(f"volume: expected a 3-D array [Z, Y, X], got shape {v.shape}")
    shape = _check_shape(v.shape)
    converted = v.dtype != np.float32
    if converted:
        with np.errstate(over="ignore", invalid="ignore"):
            v = v.astype(np.float32)
    v = np.ascontiguousarray(v)
    bad = ~np.isfinite(v)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        note = " after conversion to float32" if converted else ""
        raise DataError(
            f"volume: {int(bad.sum())} non-finite values{note} (zfp's fixed-rate mode "
            f"cannot keep NaN or Inf); the first at [z, y, x] = {first}: {v[first]}"
        )
    if v.size == 0:
        return ZfpVolume(b"", shape, rate)
    try:
        import zfpy
    except ImportError as e:
        raise ImportError("clvis.zfp.compress needs zfpy (pip install zfpy)") from e
    stream = zfpy.compress_numpy(v, rate=float(rate), write_header=False)
    return ZfpVolume(bytes(stream), shape, rate)


# --------------------------------------------------------------------------
# decoding


def _stream_args(stream_or_zfpvolume, shape, rate):
    """(stream, shape, rate) checked; stream as bytes or a device array."""
    if isinstance(stream_or_zfpvolume, ZfpVolume):
        zv = stream_or_zfpvolume
        if shape is not None and _check_shape(shape) != zv.shape:
            raise ValueError(f"shape: {tuple(shape)} differs from the ZfpVolume's {zv.shape}")
        if rate is not None and _check_rate(rate) != zv.rate:
            raise ValueError(f"rate: {rate} differs from the ZfpVolume's {zv.rate}")
        return zv.stream, zv.shape, zv.rate
    if shape is None or rate is None:
        raise TypeError("shape and rate are needed with a bare stream (a ZfpVolume has them)")
    shape, rate = _check_shape(shape), _check_rate(rate)
    stream = stream_or_zfpvolume
    if is_device(stream):
        if not stream.flags.c_contiguous:
            raise ValueError("stream: the device array is not contiguous")
        nbytes = int(stream.nbytes)
        head = None
    else:
        stream = _as_bytes(stream)
        nbytes, head = len(stream), stream[:3]
    if nbytes != expected_nbytes(shape, rate):
        raise _length_error(nbytes, shape, rate, head)
    return stream, shape, rate


def _upload(queue, stream: bytes):
    words = np.frombuffer(stream, dtype="<u8")
    d = runtime.empty(queue, max(len(words), 1), np.uint64, "zfp stream")
    if len(words):
        d.set(words, queue=queue)
    return d


def _stream_buffer(queue, stream):
    """The cl.Buffer of the stream's words on the queue's device."""
    if is_device(stream):
        if stream.context.int_ptr != queue.context.int_ptr:
            raise ValueError("stream: the device array belongs to another OpenCL context than the queue")
        if stream.offset:
            stream = stream.copy()  # the kernels take a whole buffer of aligned words
        return stream.base_data
    return _upload(queue, stream).base_data


def decode(
    stream_or_zfpvolume: ZfpVolume | Any,
    shape: Sequence[int] | None = None,
    rate: int | None = None,
    *,
    queue: cl.CommandQueue | None = None,
    host: bool = True,
) -> np.ndarray | cla.Array:
    """The float32 volume of `shape` ([Z, Y, X]) in a headerless zfp
    fixed-rate stream, decoded on the device bit for bit as zfp does.

    stream_or_zfpvolume: a :class:`ZfpVolume`, or the stream (bytes, a
    numpy array of its bytes or words, or a device array: uint8 or uint64,
    e.g. :meth:`ZfpVolume.to_device`) with `shape` and `rate`. host=True
    returns numpy, host=False a ``pyopencl.array.Array`` on the queue.
    DataError if the stream's length is not the one of `shape` and `rate`.
    """
    stream, shape, rate = _stream_args(stream_or_zfpvolume, shape, rate)
    q = resolve_queue(queue, stream=stream)
    out = runtime.empty(q, shape, np.float32, "decoded volume")
    nblocks = math.prod(_grid(shape))
    if nblocks:
        wg = PROFILES[runtime.tuning_profile(q)]["wg"]
        k = runtime.get_kernel(q, _SRC, "decode_volume", {})
        runtime.launch(
            q,
            k,
            *runtime.items(q, nblocks, wg),
            _stream_buffer(q, stream),
            np.uint32(rate),
            np.uint32(shape[2]),
            np.uint32(shape[1]),
            np.uint32(shape[0]),
            out.base_data,
        )
    return result(out, host)


def decode_blocks(
    stream_or_zfpvolume: ZfpVolume | Any,
    ids: Any,
    shape: Sequence[int] | None = None,
    rate: int | None = None,
    *,
    queue: cl.CommandQueue | None = None,
    host: bool = False,
) -> np.ndarray | cla.Array:
    """Blocks `ids` of a stream as bricks: a (len(ids), 64) float32 array,
    row j block ids[j] (x-fastest block order, :meth:`ZfpVolume.block_id`),
    value i of a row voxel (x, y, z) of the block with i = x + 4 y + 16 z
    (edge blocks whole, padding included). A device array by default
    (host=False): the block-cache entry point.

    ids: integers (numpy: each must be a block of the volume, else
    DataError), or a uint32 device array (not checked on the host: the
    kernel gives an out-of-range id a brick of NaN without reading).
    Stream, shape, rate as for :func:`decode`.
    """
    stream, shape, rate = _stream_args(stream_or_zfpvolume, shape, rate)
    nblocks = math.prod(_grid(shape))
    q = resolve_queue(queue, stream=stream, ids=ids)
    if is_device(ids):
        if ids.dtype != np.uint32 or ids.ndim != 1:
            raise TypeError(f"ids: a device array of ids must be 1-D uint32, got {ids.ndim}-D {ids.dtype}")
        ids_d = ids if not ids.offset else ids.copy()
        count = int(ids.size)
    else:
        ids_h = np.asarray(ids)
        if ids_h.ndim != 1 or (ids_h.size and ids_h.dtype.kind not in "iu"):
            raise TypeError(f"ids: expected a 1-D array of integers, got {ids_h.ndim}-D {ids_h.dtype}")
        ids_h = ids_h.astype(np.int64)
        bad = (ids_h < 0) | (ids_h >= nblocks)
        if bad.any():
            j = int(np.argmax(bad))
            raise DataError(
                f"ids: ids[{j}] = {int(ids_h[j])} is not a block of the volume "
                f"(shape {shape}: {nblocks} blocks)"
            )
        count = int(ids_h.size)
        ids_d = None
        if count:
            ids_d = runtime.empty(q, count, np.uint32, "block ids")
            ids_d.set(ids_h.astype(np.uint32), queue=q)
    out = runtime.empty(q, (count, BRICK_VALUES), np.float32, "decoded bricks")
    if count:
        wg = PROFILES[runtime.tuning_profile(q)]["wg"]
        k = runtime.get_kernel(q, _SRC, "decode_blocks", {})
        runtime.launch(
            q,
            k,
            *runtime.items(q, count, wg),
            _stream_buffer(q, stream),
            np.uint32(rate),
            np.uint32(nblocks),
            ids_d.base_data,
            np.uint32(count),
            out.base_data,
        )
    return result(out, host)
