"""Benchmarks of clvis.primitives with their peers in the same session.

Each op has: clvis on device arrays (role "clvis"), clvis from numpy to numpy
(role "clvis-host", transfers included, for reference), the peers a user
would otherwise call (numpy; pyopencl's own algorithms), and a device copy
kernel over the op's main array (role "copy"), the bandwidth limit.
extra_info carries the bytes model of DESIGN.md, so the report can give
throughput, % of copy bandwidth and the ratio to each peer:

    clvis bench primitives        (runs this file and prints the table)
"""

import numpy as np
import pyopencl.array as cla
import pytest
from benchutil import run, run_copy, scaled, threads

import clvis
from clvis import primitives as P

# --------------------------------------------------------------------------
# scan: bytes model 2 n w

SCAN_N = scaled(1 << 24)


_scan_cache = {}


def scan_data(queue, dtype):
    """(x, x on the device, an output buffer), made once per dtype."""
    if dtype not in _scan_cache:
        x = np.random.default_rng(0).integers(0, 100, SCAN_N).astype(dtype)
        xd = cla.to_device(queue, x)
        _scan_cache[dtype] = (x, xd, cla.empty_like(xd))
    return _scan_cache[dtype]


SCAN_IMPLS = ["clvis", "clvis-host", "numpy", "numpy-same-dtype", "pyopencl", "copy"]
# np.cumsum(x) already keeps float32: the same-dtype peer exists for int32 only
SCAN_CASES = [
    (d, i)
    for d in ("int32", "float32")
    for i in SCAN_IMPLS
    if not (d == "float32" and i == "numpy-same-dtype")
]


@pytest.mark.parametrize("dtype,impl", SCAN_CASES)
def test_scan(benchmark, queue, dtype, impl):
    dt = np.dtype(dtype)
    x, xd, out = scan_data(queue, dt)
    n = x.size
    op = f"scan[{dt.name}]"
    model = 2 * n * dt.itemsize
    if impl == "clvis":
        run(
            benchmark,
            lambda: clvis.scan(xd, out=out),
            op=op,
            impl=impl,
            role="clvis",
            n=n,
            nbytes=model,
            queue=queue,
        )
    elif impl == "clvis-host":
        run(benchmark, lambda: clvis.scan(x), op=op, impl=impl, role="clvis-host", n=n, nbytes=model)
    elif impl == "numpy":
        # as users call it: int32 sums in int64
        run(benchmark, lambda: np.cumsum(x), op=op, impl="numpy.cumsum(x)", role="peer", n=n, nbytes=model)
    elif impl == "numpy-same-dtype":
        # the same output as clvis's (sums wrapping in 32 bits)
        run(
            benchmark,
            lambda: np.cumsum(x, dtype=dt),
            op=op,
            impl="numpy.cumsum(x, dtype=x.dtype)",
            role="peer",
            n=n,
            nbytes=model,
        )
    elif impl == "pyopencl":
        from pyopencl.scan import ExclusiveScanKernel

        knl = ExclusiveScanKernel(queue.context, dt, "a+b", "0")
        run(
            benchmark,
            lambda: knl(xd, out),
            op=op,
            impl="pyopencl.ExclusiveScanKernel",
            role="peer",
            n=n,
            nbytes=model,
            queue=queue,
        )
    else:
        run_copy(benchmark, queue, op, xd, n, out=out)


# --------------------------------------------------------------------------
# compaction, half kept: bytes model n w + k w

COMPACT_N = scaled(1 << 24)


@pytest.fixture(scope="module")
def compact_data(queue):
    rng = np.random.default_rng(1)
    x = rng.integers(0, 1 << 30, COMPACT_N).astype(np.int32)
    mask = rng.random(COMPACT_N) < 0.5
    return x, mask, cla.to_device(queue, x), cla.to_device(queue, mask.view(np.uint8))


@pytest.mark.parametrize("impl", ["clvis", "clvis-host", "numpy", "pyopencl", "copy"])
def test_compact(benchmark, queue, compact_data, impl):
    x, mask, xd, fd = compact_data
    n, k = x.size, int(mask.sum())
    op = "compact[int32, half kept]"
    model = (n + k) * x.itemsize
    if impl == "clvis":
        run(
            benchmark,
            lambda: clvis.compact(xd, fd),
            op=op,
            impl=impl,
            role="clvis",
            n=n,
            nbytes=model,
            queue=queue,
        )
    elif impl == "clvis-host":
        run(benchmark, lambda: clvis.compact(x, mask), op=op, impl=impl, role="clvis-host", n=n, nbytes=model)
    elif impl == "numpy":
        run(benchmark, lambda: x[mask], op=op, impl="numpy boolean mask", role="peer", n=n, nbytes=model)
    elif impl == "pyopencl":
        from pyopencl.algorithm import copy_if

        run(
            benchmark,
            lambda: copy_if(xd, "flags[i] != 0", extra_args=[("flags", fd)]),
            op=op,
            impl="pyopencl.algorithm.copy_if",
            role="peer",
            n=n,
            nbytes=model,
            queue=queue,
            rounds=3,
        )
    else:
        run_copy(benchmark, queue, op, xd, n)


# --------------------------------------------------------------------------
# radix sort, uint32 keys with uint32 values: bytes model P n (3K + 2V)

SORT_N = scaled(1 << 22)


@pytest.fixture(scope="module")
def sort_data(queue):
    rng = np.random.default_rng(2)
    keys = rng.integers(0, 1 << 32, SORT_N, dtype=np.uint64).astype(np.uint32)
    vals = np.arange(SORT_N, dtype=np.uint32)
    return keys, vals, cla.to_device(queue, keys), cla.to_device(queue, vals)


def _passes(queue):
    bits = P.PROFILES[clvis.runtime.tuning_profile(queue)]["radix"]["RADIX_BITS"]
    return -(-32 // bits)


NUMBA_THREADS = 2
_numba_sort = {}


def numba_lsd_sort():
    """A 2-thread LSD radix sort of uint32 pairs compiled by numba (8-bit
    digits, 4 passes; per pass: each thread counts its half, a prefix over
    (digit, thread), each thread scatters its half), the compiled peer."""
    if not _numba_sort:
        import numba

        @numba.njit(parallel=True, cache=False)
        def sort(keys, vals, nt):
            n = keys.shape[0]
            k0, v0 = keys.copy(), vals.copy()
            k1, v1 = np.empty_like(keys), np.empty_like(vals)
            per = (n + nt - 1) // nt
            hist = np.zeros((nt, 256), np.int64)
            for p in range(4):
                shift = np.uint32(8 * p)
                src_k, src_v = (k0, v0) if p % 2 == 0 else (k1, v1)
                dst_k, dst_v = (k1, v1) if p % 2 == 0 else (k0, v0)
                for t in numba.prange(nt):
                    h = hist[t]
                    h[:] = 0
                    for i in range(t * per, min(n, (t + 1) * per)):
                        h[(src_k[i] >> shift) & np.uint32(255)] += 1
                at = 0
                for d in range(256):
                    for t in range(nt):
                        c = hist[t, d]
                        hist[t, d] = at
                        at += c
                for t in numba.prange(nt):
                    nxt = hist[t]
                    for i in range(t * per, min(n, (t + 1) * per)):
                        d = (src_k[i] >> shift) & np.uint32(255)
                        q = nxt[d]
                        nxt[d] = q + 1
                        dst_k[q] = src_k[i]
                        dst_v[q] = src_v[i]
            return k0, v0

        _numba_sort["sort"] = sort
    return _numba_sort["sort"]


@pytest.mark.parametrize("impl", ["clvis", "clvis-host", "numpy", "numba", "pyopencl", "copy"])
def test_radix_sort(benchmark, queue, sort_data, impl):
    keys, vals, kd, vd = sort_data
    n = keys.size
    op = "radix_sort[uint32 keys + uint32 values]"
    passes = _passes(queue)
    model = passes * n * (3 * 4 + 2 * 4)
    if impl == "clvis":
        run(
            benchmark,
            lambda: clvis.radix_sort(kd, vd),
            op=op,
            impl=impl,
            role="clvis",
            n=n,
            nbytes=model,
            queue=queue,
            passes=passes,
        )
    elif impl == "clvis-host":
        run(
            benchmark,
            lambda: clvis.radix_sort(keys, vals),
            op=op,
            impl=impl,
            role="clvis-host",
            n=n,
            nbytes=model,
            passes=passes,
        )
    elif impl == "numpy":

        def np_sort():
            order = np.argsort(keys, kind="stable")
            return keys[order], vals[order]

        run(
            benchmark,
            np_sort,
            op=op,
            impl="numpy argsort(stable) + gather",
            role="peer",
            n=n,
            nbytes=model,
            rounds=3,
        )
    elif impl == "numba":
        with threads(numba=NUMBA_THREADS):  # numba's count given back after the case
            sort = numba_lsd_sort()
            gk, gv = sort(keys, vals, NUMBA_THREADS)  # compile, and check against numpy's stable sort
            order = np.argsort(keys, kind="stable")
            assert np.array_equal(gk, keys[order]) and np.array_equal(gv, vals[order])
            run(
                benchmark,
                lambda: sort(keys, vals, NUMBA_THREADS),
                op=op,
                impl=f"numba LSD ({NUMBA_THREADS} threads)",
                role="peer",
                n=n,
                nbytes=model,
                rounds=5,
            )
    elif impl == "pyopencl":
        from pyopencl.algorithm import RadixSort

        sorter = RadixSort(
            queue.context,
            "unsigned *keys, unsigned *vals",
            key_expr="keys[i]",
            sort_arg_names=["keys", "vals"],
            key_dtype=np.uint32,
        )
        run(
            benchmark,
            lambda: sorter(kd, vd, key_bits=32, queue=queue),
            op=op,
            impl="pyopencl.algorithm.RadixSort",
            role="peer",
            n=n,
            nbytes=model,
            queue=queue,
            rounds=2,
        )
    else:
        run_copy(benchmark, queue, op, kd, n)


# --------------------------------------------------------------------------
# histogram, 256 bins: bytes model n w

HIST_N = scaled(1 << 24)


@pytest.fixture(scope="module")
def hist_data(queue):
    rng = np.random.default_rng(3)
    keys = rng.integers(0, 256, HIST_N).astype(np.int32)
    return keys, cla.to_device(queue, keys)


@pytest.mark.parametrize("impl", ["clvis", "numpy", "copy"])
def test_histogram(benchmark, queue, hist_data, impl):
    keys, kd = hist_data
    n = keys.size
    op = "histogram[256 bins]"
    model = n * keys.itemsize
    if impl == "clvis":
        run(
            benchmark,
            lambda: clvis.histogram(kd, 256),
            op=op,
            impl=impl,
            role="clvis",
            n=n,
            nbytes=model,
            queue=queue,
        )
    elif impl == "numpy":
        run(
            benchmark,
            lambda: np.bincount(keys, minlength=256),
            op=op,
            impl="numpy.bincount",
            role="peer",
            n=n,
            nbytes=model,
        )
    else:
        run_copy(benchmark, queue, op, kd, n)
