"""Memory: a pool per queue, checks before large allocations (one buffer
against the device's max allocation, a total against device and host memory),
and pooled, checked device arrays."""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import functools
import inspect
import math
import os
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import pyopencl as cl
import pyopencl.array as cla
import pyopencl.tools

from ..errors import DeviceError
from .device import _contexts, _lock, _state, capabilities, describe
from .dispatch import fill


def allocator(queue: cl.CommandQueue) -> cl.tools.MemoryPool:
    """A memory pool for the queue: repeated calls reuse device buffers."""
    state = _state(queue.context)
    with _lock:
        pool = state.pools.get(queue.int_ptr)
        if pool is None:
            pool = state.pools[queue.int_ptr] = cl.tools.MemoryPool(cl.tools.ImmediateAllocator(queue))
        return pool


def free_pools() -> None:
    """Give every pooled buffer back to the drivers."""
    with _lock:
        for s in _contexts.values():
            for pool in s.pools.values():
                pool.free_held()


def free_held(queue: cl.CommandQueue) -> None:
    """Give the buffers the queue's pool holds for reuse (freed, not in use)
    back to the driver; arrays in use stay. Call it when a job whose buffer
    sizes differ from the next one's is done (a scene of other sizes): the
    pool keeps a freed block of every size it has seen, so a series of
    scenes of different sizes would otherwise grow it by each scene's
    buffers (on a CPU device, host memory). The C heap is trimmed after
    (trim_heap): the freed buffers' pages go back to the system."""
    with _lock:
        pool = _state(queue.context).pools.get(queue.int_ptr)
    if pool is not None:
        pool.free_held()
        trim_heap()


@functools.cache
def _malloc_trim():
    """glibc's malloc_trim, None elsewhere (musl, macOS, Windows)."""
    name = ctypes.util.find_library("c")
    try:
        trim = ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):
        return None
    if trim is not None:
        trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return trim


def trim_heap() -> bool:
    """Give the C heap's free pages back to the system (glibc's
    malloc_trim(0); False where there is none). A CPU device's buffers are
    host memory: freed, glibc keeps them in the heap (its mmap threshold
    grows with every large block freed, so later buffers of a few MB come
    from the heap, not from mmap), and a viewer whose window went through 35
    sizes grew by 3.6 MB a size; with the trim, new sizes within one range
    keep its memory level (bench/results/README.md).
    It changes no setting: the heap is as after many frees."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True


def check_alloc(queue: cl.CommandQueue, nbytes: int, what: str) -> None:
    """DeviceError if one buffer of `nbytes` exceeds the device's max single allocation."""
    limit = capabilities(queue).max_alloc_bytes
    if nbytes > limit:
        raise DeviceError(
            f"{what}: needs one buffer of {nbytes} bytes, more than the max single allocation "
            f"of {limit} bytes on {describe(queue.device)}"
        )


def host_available_bytes() -> int | None:
    """Memory this process can still take on the host: the kernel's estimate of
    available memory (MemAvailable), lowered to the address-space limit
    (RLIMIT_AS) minus what the process already maps; None where neither is
    known."""
    avail = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        pass
    if avail is None:
        with contextlib.suppress(ValueError, OSError, AttributeError):
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            with open("/proc/self/statm") as f:
                mapped = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
            left = max(0, soft - mapped)
            avail = left if avail is None else min(avail, left)
    except (ImportError, OSError, ValueError, IndexError):
        pass
    return avail


def check_memory(queue: cl.CommandQueue, what: str, *, device_bytes: int = 0, host_bytes: int = 0) -> None:
    """DeviceError naming both figures when `device_bytes` more on the device or
    `host_bytes` more on the host would not fit: call it before a large
    allocation (a big image, a tile plan), so the caller gets a clear error
    instead of a driver failure, a swap storm or the OOM killer. On a CPU
    device, device memory is host memory: both count against the host."""
    caps = capabilities(queue)
    if device_bytes > caps.global_mem_bytes:
        raise DeviceError(
            f"{what}: needs {device_bytes / 1e9:.2f} GB on the device and "
            f"{host_bytes / 1e9:.2f} GB on the host; {describe(queue.device)} has "
            f"{caps.global_mem_bytes / 1e9:.2f} GB"
        )
    host_need = host_bytes + (device_bytes if caps.device_type == "CPU" else 0)
    avail = host_available_bytes()
    if avail is not None and host_need > avail:
        raise DeviceError(
            f"{what}: needs {device_bytes / 1e9:.2f} GB on the device and "
            f"{host_bytes / 1e9:.2f} GB on the host ({host_need / 1e9:.2f} GB of host memory "
            f"with a CPU device), but only {avail / 1e9:.2f} GB is available"
        )


# pyopencl.array.Array's constructor from shape, strides and size as given
# (what pyopencl's own views use): cla.empty checks the shape with ~10 NumPy
# calls, ~35 us of CPU an array, and a render pass makes ~60 of them
_FAST_ARRAY = "_fast" in inspect.signature(cla.Array.__init__).parameters


def _dims(shape: tuple) -> tuple[int, ...] | None:
    """`shape` as Python ints where it is non-negative integers (not bools), else None."""
    if all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) and s >= 0 for s in shape):
        return tuple(int(s) for s in shape)
    return None


def empty(queue: cl.CommandQueue, shape: int | Sequence[int], dtype: npt.DTypeLike, what: str) -> cla.Array:
    """A device array from the pool, after check_alloc; DeviceError if the driver refuses.
    The array is cla.empty's (C strides, no offset); a shape of non-negative
    integers takes pyopencl's fast constructor, any other goes to cla.empty and
    its errors."""
    shape = (int(shape),) if isinstance(shape, (int, np.integer)) else tuple(shape)
    dtype = np.dtype(dtype)
    dims = _dims(shape)
    nbytes = (math.prod(dims) if dims is not None else int(np.prod(shape, dtype=np.int64))) * dtype.itemsize
    check_alloc(queue, nbytes, what)
    pool = allocator(queue)
    try:
        if dims is not None and _FAST_ARRAY:
            strides = [dtype.itemsize] if dims else []
            for s in dims[:0:-1]:
                strides.append(strides[-1] * max(1, s))
            return cla.Array(
                None,
                dims,
                dtype,
                allocator=pool,
                strides=tuple(strides[::-1]),
                _fast=True,
                _size=math.prod(dims),
                _context=queue.context,
                _queue=queue,
            )
        return cla.empty(queue, shape, dtype, allocator=pool)
    except (cl.MemoryError, cl.Error) as e:
        raise DeviceError(f"{what}: allocating {nbytes} bytes on {describe(queue.device)} failed: {e}") from e


def fill_zero(queue: cl.CommandQueue, a: cla.Array) -> cla.Array:
    """Zero a device array's bytes: :func:`fill` with 0."""
    return fill(queue, a, 0)


def zeros(queue: cl.CommandQueue, shape: int | Sequence[int], dtype: npt.DTypeLike, what: str) -> cla.Array:
    """empty(), zeroed."""
    return fill_zero(queue, empty(queue, shape, dtype, what))
