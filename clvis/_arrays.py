"""Turning the caller's arrays into device arrays and back.

Every op takes numpy arrays (and returns numpy) or ``pyopencl.array.Array``
(and returns device arrays on the same queue, with no host round trip).
"""

from __future__ import annotations

import operator
import typing
from collections.abc import Iterable
from typing import Any

import numpy as np
import numpy.typing as npt
import pyopencl as cl
import pyopencl.array as cla

from . import runtime


def is_device(x: object) -> bool:
    return isinstance(x, cla.Array)


def resolve_queue(queue: cl.CommandQueue | None, **arrays: Any) -> cl.CommandQueue:
    """The queue to run on: `queue`, else the first device array's, else the default.
    Every device array must live in that queue's context."""
    dev = [(k, a) for k, a in arrays.items() if is_device(a)]
    if queue is None:
        queue = dev[0][1].queue if dev else runtime.default_queue()
        if queue is None:
            raise ValueError(f"{dev[0][0]}: the device array has no queue; pass queue=")
    elif not isinstance(queue, cl.CommandQueue):
        raise TypeError(f"queue: expected a pyopencl.CommandQueue, got {type(queue).__name__}")
    for name, a in dev:
        if a.context.int_ptr != queue.context.int_ptr:
            raise ValueError(f"{name}: the device array belongs to another OpenCL context than the queue")
    return queue


def _dtype_names(dtypes) -> str:
    return ", ".join(np.dtype(d).name for d in dtypes)


# The longest first axis a host array may have: kernels index items with 32-bit
# unsigned ints. Checked before the array is copied, so that a huge broadcast
# view fails with this message rather than a MemoryError.
MAX_LENGTH = 2**32 - 1


def check_array(
    name: str,
    x: Any,
    dtypes: Iterable[Any] | None = None,
    ndim: int | None = None,
    min_ndim: int | None = None,
) -> Any:
    """Check dtype and rank; returns x (a device array) or a C-contiguous numpy array.

    Object arrays raise a TypeError naming the argument; host arrays in the
    other byte order (big-endian) are converted to native order (the kernels
    read native values); a first axis longer than MAX_LENGTH raises a
    ValueError before anything is copied."""
    if not is_device(x):
        if isinstance(x, (str, bytes)) or x is None:
            raise TypeError(f"{name}: expected an array, got {type(x).__name__}")
        x = np.asarray(x)
        if x.dtype.hasobject:
            raise TypeError(f"{name}: expected numbers, got an object array (dtype {x.dtype})")
        if x.ndim and x.shape[0] > MAX_LENGTH:
            raise ValueError(f"{name}: {x.shape[0]} items; at most 2^32 - 1 per array")
        if not (x.flags.c_contiguous and x.dtype.isnative):
            _check_copy(name, x)
        if not x.dtype.isnative:
            x = x.astype(x.dtype.newbyteorder("="))
    if dtypes is not None and np.dtype(x.dtype) not in [np.dtype(d) for d in dtypes]:
        raise TypeError(
            f"{name}: dtype {np.dtype(x.dtype).name} is not supported; expected one of {_dtype_names(dtypes)}"
        )
    if ndim is not None and x.ndim != ndim:
        raise ValueError(f"{name}: expected a {ndim}-D array, got shape {tuple(x.shape)}")
    if min_ndim is not None and x.ndim < min_ndim:
        raise ValueError(f"{name}: expected at least {min_ndim}-D, got shape {tuple(x.shape)}")
    if is_device(x):
        if not x.flags.c_contiguous:
            raise ValueError(f"{name}: the device array is not C-contiguous")
    else:
        x = np.ascontiguousarray(x)
    return x


def _check_copy(name: str, x: np.ndarray) -> None:
    """The contiguous copy of a view (a broadcast or zero-stride view may claim
    billions of elements over a few bytes) must fit in host memory: DeviceError
    naming the bytes instead of numpy's MemoryError."""
    need = int(x.size) * x.dtype.itemsize
    if need < 1 << 26:
        return
    avail = runtime.host_available_bytes()
    if avail is not None and need > avail:
        from .errors import DeviceError

        raise DeviceError(
            f"{name}: a view of shape {x.shape} ({x.dtype}) needs a contiguous copy of "
            f"{need / 1e9:.2f} GB, and only {avail / 1e9:.2f} GB of host memory is available"
        )


def to_device(queue: cl.CommandQueue, name: str, x: Any) -> cla.Array:
    """x (checked) on the device: device arrays as they are, numpy copied in."""
    if is_device(x):
        if x.offset:
            x = x.copy()  # kernels take whole buffers; a view with an offset is copied once
        return x
    d = runtime.empty(queue, x.shape, x.dtype, name)
    if x.size:
        d.set(x, queue=queue)
    return d


# the cl.Buffer behind a device array (None for an empty array)
buf = runtime.arg


def buffer_of(a: cla.Array) -> cl.Buffer:
    """The buffer behind the non-empty device array `a` (a cl.Buffer, or a
    pool's PooledBuffer, which enqueue_copy takes alike), for the calls whose
    types take no None."""
    b = a.base_data
    if not isinstance(b, cl.MemoryObjectHolder):
        raise TypeError(f"expected a device array with a buffer, got one of {a.nbytes} bytes")
    return typing.cast(cl.Buffer, b)


def result(a: cla.Array, host: bool) -> np.ndarray | cla.Array:
    return a.get() if host else a


def to_host(a: Any) -> np.ndarray:
    """`a` as a numpy array: a device array read back (one copy), anything
    else through np.asarray (the picture methods and other host-side readers
    of a result's planes, whichever side they are on)."""
    return a.get() if isinstance(a, cla.Array) else np.asarray(a)


def on_host(a: np.ndarray | cla.Array) -> np.ndarray:
    """`a`, a plane of a result made on the host (numpy in, or ``host=True``),
    typed as the numpy array it is; TypeError for a device array (the result
    was made with ``host=False``, or from device input): nothing is read back."""
    if not isinstance(a, np.ndarray):
        raise TypeError(
            f"expected a host (numpy) array, got {type(a).__name__}: read device planes back with .get()"
        )
    return a


def nonnegative_int(name: str, v: Any) -> int:
    """v as an int >= 0: TypeError for a non-integer (bool included), ValueError below 0."""
    if isinstance(v, bool):
        raise TypeError(f"{name}: expected an integer, got bool")
    try:
        v = operator.index(v)
    except TypeError:
        raise TypeError(f"{name}: expected an integer, got {type(v).__name__}") from None
    if v < 0:
        raise ValueError(f"{name}: expected >= 0, got {v}")
    return v


def positive_int(name: str, v: Any) -> int:
    """v as an int >= 1: TypeError for a non-integer (bool included), ValueError below 1."""
    v = nonnegative_int(name, v)
    if v < 1:
        raise ValueError(f"{name}: must be at least 1, got {v}")
    return v


def real_array(name: str, a: npt.ArrayLike) -> np.ndarray:
    """`a` as a numpy array of real numbers (integers or floats, not bool;
    object, complex and string arrays are refused): TypeError naming `name`
    otherwise. Nothing is copied: the byte order is kept (big-endian arrays are
    converted by the caller's astype / ascontiguousarray to its dtype)."""
    if isinstance(a, (str, bytes)) or a is None:
        raise TypeError(f"{name}: expected an array, got {type(a).__name__}")
    a = np.asarray(a)
    if a.dtype == np.bool_ or a.dtype.kind not in "iuf":
        raise TypeError(f"{name}: expected real numbers, got dtype {a.dtype}")
    return a


def triple(name: str, v, positive: bool) -> tuple[float, float, float]:
    """v as 3 floats, each finite as float32 (and > 0 with `positive`):
    TypeError naming `name` for a string or a non-sequence, ValueError for
    another length or a bad value."""
    if isinstance(v, (str, bytes)):
        raise TypeError(f"{name}: expected 3 numbers, got {type(v).__name__}")
    try:
        t = tuple(float(x) for x in v)
    except TypeError:
        raise TypeError(f"{name}: expected 3 numbers, got {type(v).__name__}") from None
    if len(t) != 3:
        raise ValueError(f"{name}: expected 3 numbers, got {len(t)}")
    with np.errstate(over="ignore"):  # overflow is what the check reports
        f32 = np.asarray(t, np.float32)
    if not np.isfinite(f32).all():
        raise ValueError(f"{name}: {t} is not finite as float32")
    if positive and not (f32 > 0).all():
        raise ValueError(f"{name}: {t} must be > 0 on every axis")
    return t
