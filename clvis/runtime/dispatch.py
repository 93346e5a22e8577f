"""The launch layer: every family sizes (:func:`local_size`, :func:`items`),
fills (:func:`fill`), passes (:func:`arg`) and enqueues (:func:`launch`) its
kernels with these."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .device import _as_device, _lock, _native_capabilities


def launch(
    queue: cl.CommandQueue,
    kernel: cl.Kernel,
    global_size: int,
    local_size: int | None,
    *args: Any,
    wait_for: Sequence[cl.Event] | None = None,
) -> cl.Event:
    """Set `args` and enqueue a 1-D launch (serialised: kernels hold their args).

    The scalar arguments are NumPy scalars (np.uint32, np.float32, ...): the
    first launch of a kernel with a given pattern of scalar and buffer
    arguments gives it pyopencl's typed setter for that pattern
    (Kernel.set_scalar_arg_dtypes: each scalar packed by its dtype, the same
    bytes). pyopencl's untyped set_args tries every argument as a memory
    object, a local-memory size, a sampler... before it takes a scalar's
    bytes, each failed try a C++ exception (this VM: 48 us for a 5-argument
    call with 3 scalars, 1.8 us typed; an iso frame makes ~110 launches)."""
    sig = tuple(a.dtype if isinstance(a, np.generic) else None for a in args)
    with _lock:
        if getattr(kernel, "_clvis_arg_dtypes", None) != sig:
            kernel.set_scalar_arg_dtypes(sig)
            setattr(kernel, "_clvis_arg_dtypes", sig)  # noqa: B010  (a pyopencl Kernel takes attributes; mypy does not know it)
        kernel.set_args(*args)
        return cl.enqueue_nd_range_kernel(
            queue,
            kernel,
            (int(global_size),),
            None if local_size is None else (int(local_size),),
            wait_for=wait_for,
        )


# Every family sizes, fills and times its launches with these, and every
# renderer runs under the options it captured (see LaunchConfig).

# the compiler flags of the kernels whose float32 results the references
# repeat exactly (each such kernel's ABI comment says so)
EXACT_FP = ("-cl-fp32-correctly-rounded-divide-sqrt",)


def local_size(queue: cl.CommandQueue, wanted: int) -> int:
    """`wanted` work-items per group, halved until the queue's device allows
    it (at least 1). Halving keeps a power of two a power of two: the work
    shapes of the PROFILES tables are, and tiles (64 pixels of march.cl) are
    multiples of them."""
    wg = max(1, int(wanted))
    limit = _native_capabilities(_as_device(queue)).max_work_group_size
    while wg > 1 and wg > limit:
        wg //= 2
    return wg


def items(queue: cl.CommandQueue, n: int, wg: int) -> tuple[int, int]:
    """(global, local) sizes of a 1-D launch with one work-item per element
    of `n`: local = local_size(queue, wg), global the next multiple of it.
    n == 0 gives one group, not zero: an empty launch is invalid before
    OpenCL 2.1, and every such kernel returns for items past its count."""
    local = local_size(queue, wg)
    return max(1, -(-int(n) // local)) * local, local


def fill(
    queue: cl.CommandQueue,
    a: cla.Array,
    value: Any = 0,
    *,
    start: int = 0,
    wait_for: Sequence[cl.Event] | None = None,
) -> cla.Array:
    """Set the elements of device array `a` from element `start` on to
    `value` (converted to a's dtype: np.float32(np.inf), -1, 0xFFFFFFFF, ...)
    with clEnqueueFillBuffer (pyopencl's Array.fill would build a kernel of
    its own). A pattern whose bytes are all equal (0, all ones) is sent as
    one byte. Returns `a`."""
    dtype = np.dtype(a.dtype)
    off = int(start) * dtype.itemsize
    nbytes = a.nbytes - off
    if nbytes <= 0:
        return a
    if value == 0:
        pattern = np.zeros(1, np.uint8)
    else:
        pattern = np.full(1, value, dtype).view(np.uint8)
        if (pattern == pattern[0]).all():
            pattern = pattern[:1].copy()
    cl.enqueue_fill_buffer(
        queue,
        a.base_data,  # type: ignore[arg-type]  # a Buffer: nbytes > 0
        pattern,
        a.offset + off,
        nbytes,
        wait_for=wait_for,
    )
    return a


def arg(a: cla.Array | cl.MemoryObjectHolder | None) -> cl.MemoryObjectHolder | cl.SVMPointer | None:
    """A buffer argument that may be absent: None (a NULL pointer) for None
    or an empty array, else the array's cl.Buffer. A cl.Buffer passes as is."""
    if a is None or isinstance(a, cl.MemoryObjectHolder):
        return a
    return a.base_data if a.size else None


def nbytes(*arrays: Any) -> int:
    """Device bytes of `arrays` (None counts 0): what a renderer's stats report
    as allocated, from the arrays it holds rather than from a formula."""
    return int(sum(a.nbytes for a in arrays if a is not None))
