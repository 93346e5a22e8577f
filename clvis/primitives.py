"""Parallel primitives: prefix sums, stream compaction, radix sort, histogram.

Each function takes numpy arrays (returns numpy) or ``pyopencl.array.Array``
(returns device arrays on the same queue, no host round trip). The kernels are
``kernels_cl/primitives/*.cl``; ``clvis.reference.primitives`` holds the NumPy
definition of each result.

All of them split the input into a few contiguous ranges, about
``groups_per_cu`` per compute unit, and never make one work-group wait for
another (reduce-then-scan), so they run on devices without forward-progress
guarantees between work-groups (PoCL, Apple, ARM).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from . import runtime
from ._arrays import buf, check_array, is_device, resolve_queue, result, to_device
from .errors import DataError, DeviceError

__all__ = ["compact", "compact_indices", "copy", "histogram", "radix_sort", "scan"]

# -D work shapes per tuning profile (runtime.tuning_profile). "cpu": one
# work-item per group walking a contiguous range (PoCL and other CPU drivers
# run work-items as loops, so this is what vectorises and streams); "gpu":
# wide groups staging tiles through local memory.
PROFILES: dict[str, dict[str, Any]] = {
    "cpu": {
        "groups_per_cu": 4,
        "scan": {"WG": 1, "ITEMS": 16},
        "compact": {"WG": 1, "ITEMS": 16},
        "radix": {"WG": 1, "ITEMS": 16, "RADIX_BITS": 8},
        "histogram": {"WG": 1, "LOCAL_BINS": 65536},
    },
    "gpu": {
        "groups_per_cu": 8,
        "scan": {"WG": 256, "ITEMS": 8},
        "compact": {"WG": 256, "ITEMS": 4},
        "radix": {"WG": 128, "ITEMS": 8, "RADIX_BITS": 4},
        "histogram": {"WG": 256, "LOCAL_BINS": 4096},
    },
}

_SCAN_T = {
    np.dtype(np.int32): "int",
    np.dtype(np.uint32): "uint",
    np.dtype(np.int64): "long",
    np.dtype(np.uint64): "ulong",
    np.dtype(np.float32): "float",
}
# key dtype -> (KEY_T, KEY_ORDER, bits)
_KEYS = {
    np.dtype(np.uint32): ("uint", 0, 32),
    np.dtype(np.int32): ("uint", 1, 32),
    np.dtype(np.float32): ("uint", 2, 32),
    np.dtype(np.uint64): ("ulong", 0, 64),
    np.dtype(np.int64): ("ulong", 1, 64),
    np.dtype(np.float64): ("ulong", 2, 64),
}
_WORD = {1: "uchar", 2: "ushort", 4: "uint", 8: "ulong"}
_FLAG_DTYPES = [np.bool_, np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32, np.uint64, np.int64]
_VALUE_DTYPES = [np.uint32, np.int32, np.float32]
_HIST_DTYPES = [np.int32, np.uint32]
_MAX_N = 2**32 - 1


def _shape(queue, family: str) -> tuple[dict, int]:
    """The family's -D work shape for this queue's device, clamped to what the
    device allows, and the number of groups to aim for."""
    prof = PROFILES[runtime.tuning_profile(queue)]
    caps = runtime.capabilities(queue)
    shape = dict(prof[family])
    shape["WG"] = runtime.local_size(queue, shape["WG"])
    return shape, max(1, prof["groups_per_cu"] * caps.compute_units)


def _partition(n: int, tile: int, groups: int) -> tuple[int, int]:
    """(per_group, G): ranges of a multiple of `tile` elements, about `groups` of them."""
    per = -(-n // groups)
    per = -(-per // tile) * tile
    return per, -(-n // per)


def _u64(v) -> np.uint64:
    return np.uint64(v)


def _check_size(n: int, what: str) -> None:
    if n > _MAX_N:
        raise DeviceError(f"{what}: {n} elements; clvis's primitives handle at most 2^32 - 1")


# --------------------------------------------------------------------------
# scan

# testing only: make scan_chained ignore what other groups publish, so every
# look-back takes the fallback path (scan.cl's SCAN_TEST_FALLBACK)
_SCAN_TEST_FALLBACK = False


def _scan_into(queue, src, dst, total, exclusive: bool) -> None:
    """Enqueue the scan of device array `src` (n > 0) into `dst`; total[0] = sum.

    32-bit integers on the CPU work shape take the single-pass chained scan
    when the device has 64-bit atomics (else, or in place, reduce-then-scan:
    the same result)."""
    n = src.size
    shape, groups = _shape(queue, "scan")
    wg, tile = shape["WG"], shape["WG"] * shape["ITEMS"]
    defines = {"T": _SCAN_T[src.dtype], "WG": wg, "ITEMS": shape["ITEMS"]}
    exclusive = np.uint32(1 if exclusive else 0)
    chained = (
        wg == 1
        and src.dtype.itemsize == 4
        and src.dtype.kind in "iu"
        and runtime.capabilities(queue).int64_atomics
        and src.base_data.int_ptr != dst.base_data.int_ptr
    )
    if chained:
        # ~4 ranges per group slot: each stays in cache between its two reads
        per, G = _partition(n, tile, 4 * groups)
        if _SCAN_TEST_FALLBACK:
            defines["SCAN_TEST_FALLBACK"] = 1
        status = runtime.zeros(queue, G + 1, np.uint64, "scan status")
        k = runtime.get_kernel(queue, "primitives/scan.cl", "scan_chained", defines)
        runtime.launch(
            queue, k, G, 1, buf(src), buf(dst), _u64(n), _u64(per), buf(status), exclusive, buf(total)
        )
        return
    per, G = _partition(n, tile, groups)
    partials = runtime.empty(queue, G, src.dtype, "scan partials")
    k_reduce = runtime.get_kernel(queue, "primitives/scan.cl", "scan_reduce", defines)
    k_down = runtime.get_kernel(queue, "primitives/scan.cl", "scan_downsweep", defines)
    runtime.launch(queue, k_reduce, G * wg, wg, buf(src), _u64(n), _u64(per), buf(partials))
    runtime.launch(
        queue,
        k_down,
        G * wg,
        wg,
        buf(src),
        buf(dst),
        _u64(n),
        _u64(per),
        buf(partials),
        exclusive,
        buf(total),
    )


def scan(
    x: Any,
    exclusive: bool = True,
    *,
    return_total: bool = False,
    out: cla.Array | None = None,
    queue: cl.CommandQueue | None = None,
) -> Any:
    """Prefix sums of a 1-D array of int32, uint32, int64, uint64 or float32.

    exclusive=True: out[i] = x[0] + ... + x[i-1] (out[0] = 0); False: up to x[i].
    The result has x's dtype: integer sums wrap modulo 2^bits (numpy's
    ``np.cumsum(x, dtype=x.dtype)``); float32 sums are rounded in an order
    fixed by the device's work shape, not sequentially.

    return_total=True returns (out, total), total being the sum of all of x:
    a numpy scalar for numpy input, a 1-element device array for device input.
    out: a device array (x's dtype and size) to write into; it may be x itself.
    """
    queue = resolve_queue(queue, x=x, out=out)
    host = not is_device(x)
    x = check_array("x", x, dtypes=_SCAN_T, ndim=1)
    _check_size(x.size, "scan")
    xd = to_device(queue, "x", x)
    n = xd.size
    if out is not None:
        if not is_device(out):
            raise TypeError("out: expected a pyopencl.array.Array")
        out = check_array("out", out, dtypes=[xd.dtype], ndim=1)
        if out.size != n:
            raise ValueError(f"out: size {out.size} differs from x's {n}")
        if out.offset:
            raise ValueError("out: a device array with an offset cannot be written in place")
        res = out
    else:
        res = runtime.empty(queue, n, xd.dtype, "scan output")
    if n == 0:
        total = runtime.zeros(queue, 1, xd.dtype, "scan total")
    else:
        total = runtime.empty(queue, 1, xd.dtype, "scan total")
        _scan_into(queue, xd, res, total, exclusive)
    out_res = result(res, host)
    if not return_total:
        return out_res
    return (out_res, total.get()[0]) if host else (out_res, total)


# --------------------------------------------------------------------------
# compaction


def _flags_input(queue, flags, n):
    f = check_array("flags", flags, dtypes=_FLAG_DTYPES, ndim=1)
    if f.shape[0] != n:
        raise ValueError(f"flags: length {f.shape[0]} differs from x's {n}")
    fd = to_device(queue, "flags", f)
    if fd.dtype == np.bool_:
        fd = fd.view(np.uint8)
    return fd


def _compact(queue, fd, xd, rowbytes: int, out, count):
    """Enqueue compaction of rows of xd (or of indices when xd is None) by fd."""
    n = fd.size
    shape, groups = _shape(queue, "compact")
    per, G = _partition(n, shape["WG"] * shape["ITEMS"], groups)
    defines = {"FLAG_T": _WORD[fd.dtype.itemsize], "WG": shape["WG"], "ITEMS": shape["ITEMS"]}
    if xd is not None:
        word = 8 if rowbytes % 8 == 0 else 4 if rowbytes % 4 == 0 else 2 if rowbytes % 2 == 0 else 1
        defines.update(ELEM_T=_WORD[word], ROW=rowbytes // word)
    counts = runtime.empty(queue, G, np.uint32, "compaction counts")
    wg = shape["WG"]
    k_count = runtime.get_kernel(queue, "primitives/compact.cl", "compact_count", defines)
    runtime.launch(queue, k_count, G * wg, wg, buf(fd), _u64(n), _u64(per), buf(counts))
    if xd is None:
        k = runtime.get_kernel(queue, "primitives/compact.cl", "compact_indices", defines)
        runtime.launch(queue, k, G * wg, wg, buf(fd), buf(out), _u64(n), _u64(per), buf(counts), buf(count))
    else:
        k = runtime.get_kernel(queue, "primitives/compact.cl", "compact_scatter", defines)
        runtime.launch(
            queue, k, G * wg, wg, buf(xd), buf(fd), buf(out), _u64(n), _u64(per), buf(counts), buf(count)
        )


def _compact_outputs(queue, n, row_shape, dtype, out, count, what):
    if count is not None:
        if not is_device(count):
            raise TypeError("count: expected a 1-element pyopencl.array.Array of uint32")
        count = check_array("count", count, dtypes=[np.uint32], ndim=1)
        if count.size != 1 or count.offset:
            raise ValueError("count: expected a 1-element uint32 device array without offset")
    else:
        count = runtime.empty(queue, 1, np.uint32, f"{what} count")
    if out is not None:
        if not is_device(out):
            raise TypeError("out: expected a pyopencl.array.Array")
        out = check_array("out", out, dtypes=[dtype])
        if tuple(out.shape[1:]) != tuple(row_shape) or out.shape[0] < n:
            raise ValueError(
                f"out: expected shape ({n}, ...{tuple(row_shape)}) or longer, got {tuple(out.shape)}"
            )
        if out.offset:
            raise ValueError("out: a device array with an offset cannot be written in place")
    else:
        out = runtime.empty(queue, (n,) + tuple(row_shape), dtype, f"{what} output")
    return out, count


def _finish_compact(out, count, host, sync):
    if host:
        k = int(count.get()[0])
        return out[:k].get() if k else np.empty((0,) + out.shape[1:], out.dtype)
    if not sync:
        return out, count
    k = int(count.get()[0])  # one 4-byte read to size the result
    return out[:k] if k else out[:0]


def compact(
    x: Any,
    flags: Any,
    *,
    out: cla.Array | None = None,
    count: cla.Array | None = None,
    queue: cl.CommandQueue | None = None,
) -> Any:
    """x[flags != 0], in input order. x: any dtype, shape (n, ...) (rows are
    kept whole); flags: 1-D of length n, bool or an integer type.

    numpy in: a numpy array out. Device in: a device array of the kept rows
    (the count is read with one 4-byte transfer). Device pipelines that must
    not wait pass ``count`` (a 1-element uint32 device array) and get
    ``(out, count)`` back at once: out has room for n rows, the first
    count[0] are the kept ones, and nothing past them is written.
    """
    queue = resolve_queue(queue, x=x, flags=flags, out=out, count=count)
    host = not is_device(x) and not is_device(flags)
    x = check_array("x", x, min_ndim=1)
    n = x.shape[0]
    _check_size(n, "compact")
    rowbytes = np.dtype(x.dtype).itemsize * math.prod(x.shape[1:])
    if rowbytes == 0:
        raise ValueError(f"x: rows of shape {tuple(x.shape[1:])} hold no data")
    fd = _flags_input(queue, flags, n)
    xd = to_device(queue, "x", x)
    out, count_d = _compact_outputs(queue, n, x.shape[1:], xd.dtype, out, count, "compaction")
    if n == 0:
        runtime.fill_zero(queue, count_d)
    else:
        _compact(queue, fd, xd, rowbytes, out, count_d)
    return _finish_compact(out, count_d, host, sync=count is None)


def compact_indices(
    flags: Any,
    *,
    out: cla.Array | None = None,
    count: cla.Array | None = None,
    queue: cl.CommandQueue | None = None,
) -> Any:
    """The indices i (uint32, ascending) where flags[i] != 0: ``np.flatnonzero``.
    Returns and ``out``/``count`` as :func:`compact`."""
    queue = resolve_queue(queue, flags=flags, out=out, count=count)
    host = not is_device(flags)
    flags = check_array("flags", flags, dtypes=_FLAG_DTYPES, ndim=1)
    n = flags.shape[0]
    _check_size(n, "compact_indices")
    fd = _flags_input(queue, flags, n)
    out, count_d = _compact_outputs(queue, n, (), np.dtype(np.uint32), out, count, "compact_indices")
    if n == 0:
        runtime.fill_zero(queue, count_d)
    else:
        _compact(queue, fd, None, 0, out, count_d)
    return _finish_compact(out, count_d, host, sync=count is None)


# --------------------------------------------------------------------------
# radix sort


# The CPU form (WG 1) sorts MSD first from this many keys: one pass on the
# top digit, then each bucket's remaining passes in cache (radix_sort.cl).
MSD_MIN_N = 1 << 20
# the widest top digit of the MSD-first form (2^12 private counters a
# work-item in its upsweep and scatter)
MSD_MAX_BITS = 12
# radix_bucket_lsd's digits (_bucket_digits): at most 12 bits (2^12
# counters a pass), 2^BUCKET_SLACK keys a counter or more, and the counters
# of all its passes at most BUCKET_COUNTERS (32 KiB of private memory)
BUCKET_MAX_BITS = 12
BUCKET_SLACK = 4
BUCKET_COUNTERS = 8192


def radix_sort(
    keys: Any,
    values: Any = None,
    *,
    key_bits: int | None = None,
    check: bool = True,
    queue: cl.CommandQueue | None = None,
) -> Any:
    """Stable LSD radix sort.

    keys: 1-D uint32, int32, float32, uint64, int64 or float64. Floats sort in
    total order: -inf < ... < -0.0 < +0.0 < ... < +inf < NaN (all NaNs last,
    in input order); the output keeps the input's exact bits.
    values: optional 1-D array of 32-bit values (uint32, int32 or float32) of
    the same length, moved with the keys.
    key_bits: sort on the low key_bits bits only, for integer keys known to
    lie in [0, 2**key_bits) (fewer passes). A key outside that range raises
    DataError after the sort (the input is never modified); for device keys
    that check costs one read-back, which check=False leaves out: the caller
    then guarantees the range (keys made by its own kernel), and a key outside
    it is not detected (the output is then some permutation of the pairs).

    Returns sorted keys, or (keys, values).
    """
    queue = resolve_queue(queue, keys=keys, values=values)
    host = not is_device(keys) and not is_device(values)
    keys = check_array("keys", keys, dtypes=_KEYS, ndim=1)
    key_t, order, bits = _KEYS[np.dtype(keys.dtype)]
    n = keys.shape[0]
    if values is not None:
        values = check_array("values", values, dtypes=_VALUE_DTYPES, ndim=1)
        if values.shape[0] != n:
            raise ValueError(f"values: length {values.shape[0]} differs from keys' {n}")
    if key_bits is not None:
        if isinstance(key_bits, bool) or not isinstance(key_bits, (int, np.integer)):
            raise TypeError(f"key_bits: expected an int, got {type(key_bits).__name__}")
        if order == 2:
            raise ValueError("key_bits: only integer keys can be limited to their low bits")
        if not 0 <= key_bits <= bits:
            raise ValueError(
                f"key_bits: expected 0..{bits} for {np.dtype(keys.dtype).name} keys, got {key_bits}"
            )
    sort_bits = bits if key_bits is None else int(key_bits)
    _check_size(n, "radix_sort")

    kd = to_device(queue, "keys", keys)
    vd = to_device(queue, "values", values) if values is not None else None
    shape, groups = _shape(queue, "radix")
    radix_bits = shape["RADIX_BITS"]
    radix = 1 << radix_bits
    # key_bits=0 still runs one pass: a stable sort all the same, and its
    # upsweep checks the keys on the device
    passes = max(1, -(-sort_bits // radix_bits))

    if n <= 1:
        ko = kd.copy() if not host else kd
        vo = (vd.copy() if not host else vd) if vd is not None else None
        if check and key_bits is not None and n and key_bits < bits:
            _check_key_bits(int(kd.get().view(f"u{kd.dtype.itemsize}")[0]), key_bits, keys.dtype)
        return _sorted_result(ko, vo, host)

    wg = shape["WG"]
    if wg > 1:
        # the tiled kernel's local memory: counters, the tile's keys and values
        def local_bytes(w):
            tile_bytes = w * shape["ITEMS"] * (kd.dtype.itemsize + (4 if vd is not None else 0))
            return 4 * radix * w + tile_bytes + 4 * (radix + w)

        while wg > 1 and local_bytes(wg) > runtime.capabilities(queue).local_mem_bytes:
            wg //= 2
    tile = wg * shape["ITEMS"]
    if wg == 1:
        per, G = _partition(n, tile, groups)
    else:  # the tiled kernel ranks one tile per group (radix_sort.cl)
        per, G = tile, -(-n // tile)
    defines = {
        "KEY_T": key_t,
        "KEY_ORDER": order,
        "HAS_VALUES": int(vd is not None),
        "RADIX_BITS": radix_bits,
        "WG": wg,
        "ITEMS": shape["ITEMS"],
    }
    k_up = runtime.get_kernel(queue, "primitives/radix_sort.cl", "radix_upsweep", defines)
    k_sc = runtime.get_kernel(queue, "primitives/radix_sort.cl", "radix_scatter", defines)

    hist = runtime.empty(queue, radix * G, np.uint32, "radix_sort histogram")
    offsets = runtime.empty(queue, radix * G, np.uint32, "radix_sort offsets")
    hist_total = runtime.empty(queue, 1, np.uint32, "radix_sort histogram total")
    orbits = runtime.empty(queue, G, kd.dtype, "radix_sort key check")
    kbuf = [runtime.empty(queue, n, kd.dtype, "radix_sort keys")]
    if passes > 1:
        kbuf.append(runtime.empty(queue, n, kd.dtype, "radix_sort keys"))
    vbuf: list[cla.Array | None] = [None, None]
    if vd is not None:
        vbuf = [
            runtime.empty(queue, n, vd.dtype, "radix_sort values"),
            runtime.empty(queue, n, vd.dtype, "radix_sort values") if passes > 1 else None,
        ]

    src_k, src_v = kd, vd
    if wg == 1 and passes >= 2 and n >= MSD_MIN_N:
        # MSD first: one pass on the top digit into kbuf[0], then every
        # bucket's remaining passes by one work-item, inside the cache. The
        # top digit is what the LSD digits leave, up to MSD_MAX_BITS wide:
        # more buckets, smaller ones (a 44-bit key: 12 + 4 x 8, not 8 bits
        # of which 4 vary + 5 x 8)
        lsd = max(1, -(-(sort_bits - MSD_MAX_BITS) // radix_bits))
        msd_bits = sort_bits - lsd * radix_bits
        shift = np.uint32(lsd * radix_bits)
        md = {**defines, "RADIX_BITS": msd_bits}
        k_up_m = runtime.get_kernel(queue, "primitives/radix_sort.cl", "radix_upsweep", md)
        # up to 8 top-digit bits, the scatter stages each digit's keys in a
        # private line written whole (non-temporal): 2^8 lines of keys and
        # values fill L1 (12 bits would be 512 KiB of lines); the lines'
        # vector stores need buffers aligned to 16 keys (and 16 values)
        word = max(kd.dtype.itemsize, vd.dtype.itemsize if vd is not None else 0)
        stage = msd_bits <= 8 and queue.device.mem_base_addr_align >= 8 * 16 * word
        k_sc_m = runtime.get_kernel(
            queue, "primitives/radix_sort.cl", "radix_scatter", {**md, "STAGE": int(stage)}
        )
        if msd_bits != radix_bits:
            hist = runtime.empty(queue, (1 << msd_bits) * G, np.uint32, "radix_sort histogram")
            offsets = runtime.empty(queue, (1 << msd_bits) * G, np.uint32, "radix_sort offsets")
        runtime.launch(queue, k_up_m, G, 1, buf(src_k), _u64(n), _u64(per), shift, buf(hist), buf(orbits))
        _scan_into(queue, hist, offsets, hist_total, exclusive=True)
        runtime.launch(
            queue,
            k_sc_m,
            G,
            1,
            buf(src_k),
            buf(kbuf[0]),
            buf(src_v) if src_v is not None else None,
            buf(vbuf[0]) if vbuf[0] is not None else None,
            _u64(n),
            _u64(per),
            shift,
            buf(offsets),
        )
        lsd, lsd_bits = _bucket_digits(int(shift), n >> msd_bits, radix_bits)
        k_lsd = runtime.get_kernel(
            queue,
            "primitives/radix_sort.cl",
            "radix_bucket_lsd",
            {**defines, "MSD_BITS": msd_bits, "RADIX_BITS": lsd_bits, "LSD_PASSES": lsd},
        )
        runtime.launch(
            queue,
            k_lsd,
            1 << msd_bits,
            1,
            buf(kbuf[0]),
            buf(kbuf[1]),
            buf(vbuf[0]) if vbuf[0] is not None else None,
            buf(vbuf[1]) if vbuf[1] is not None else None,
            _u64(n),
            np.uint32(G),
            buf(offsets),
        )
        src_k, src_v = kbuf[lsd % 2], vbuf[lsd % 2]
        passes = 0
    for p in range(passes):
        dst_k, dst_v = kbuf[p % 2], vbuf[p % 2]
        shift = np.uint32(p * radix_bits)
        runtime.launch(queue, k_up, G * wg, wg, buf(src_k), _u64(n), _u64(per), shift, buf(hist), buf(orbits))
        _scan_into(queue, hist, offsets, hist_total, exclusive=True)
        runtime.launch(
            queue,
            k_sc,
            G * wg,
            wg,
            buf(src_k),
            buf(dst_k),
            buf(src_v) if src_v is not None else None,
            buf(dst_v) if dst_v is not None else None,
            _u64(n),
            _u64(per),
            shift,
            buf(offsets),
        )
        src_k, src_v = dst_k, dst_v
    if check and key_bits is not None and key_bits < bits:
        _check_key_bits(int(np.bitwise_or.reduce(orbits.get())), key_bits, keys.dtype)
    return _sorted_result(src_k, src_v, host)


def _bucket_digits(bits: int, per_bucket: int, radix_bits: int) -> tuple[int, int]:
    """(passes, digit bits) of radix_bucket_lsd for the `bits` below the top
    digit: digits as wide as the buckets pay for (2^w counters a pass, zeroed
    and scanned, against ~per_bucket keys: 2^w <= per_bucket / 2^BUCKET_SLACK)
    and the counters fit (BUCKET_COUNTERS in all passes), from the LSD digit
    (8) up to BUCKET_MAX_BITS; the passes as few as that allows, their digits
    as even (24 bits of 2^16-key buckets: 2 x 12, not 3 x 8)."""
    widest = min(BUCKET_MAX_BITS, per_bucket.bit_length() - 1 - BUCKET_SLACK)
    while widest > radix_bits and -(-bits // widest) << widest > BUCKET_COUNTERS:
        widest -= 1
    passes = max(1, -(-bits // max(radix_bits, widest)))
    return passes, -(-bits // passes)


def _check_key_bits(ors: int, key_bits: int, dtype) -> None:
    if ors >> key_bits:
        raise DataError(
            f"keys: key_bits={key_bits} promises {np.dtype(dtype).name} keys in [0, 2**{key_bits}), "
            f"but some have higher bits set (bitwise OR of all keys: {ors:#x})"
        )


def _sorted_result(kd, vd, host):
    if vd is None:
        return result(kd, host)
    return result(kd, host), result(vd, host)


# --------------------------------------------------------------------------
# histogram


def histogram(
    keys: Any, nbins: int, *, check: bool = True, queue: cl.CommandQueue | None = None
) -> np.ndarray | cla.Array:
    """Counts per bin (uint32, length nbins) of int32/uint32 bin indices:
    ``np.bincount(keys, minlength=nbins)``.

    A key outside [0, nbins) raises DataError (check=True: for device input
    that costs one 4-byte read) or is left out of every bin (check=False).
    """
    queue = resolve_queue(queue, keys=keys)
    host = not is_device(keys)
    keys = check_array("keys", keys, dtypes=_HIST_DTYPES, ndim=1)
    if isinstance(nbins, bool) or not isinstance(nbins, (int, np.integer)):
        raise TypeError(f"nbins: expected an int, got {type(nbins).__name__}")
    if not 1 <= nbins <= _MAX_N:
        raise ValueError(f"nbins: expected 1..2^32-1, got {nbins}")
    nbins = int(nbins)
    _check_size(keys.shape[0], "histogram")
    # the counts (4 bytes a bin), and their copy when they are read back, before
    # anything is allocated: a failed host allocation of a CPU device's buffer
    # can bring the process down even when the MemoryError is caught
    runtime.check_memory(
        queue, f"histogram of {nbins} bins", device_bytes=4 * nbins, host_bytes=4 * nbins if host else 0
    )
    kd = to_device(queue, "keys", keys)
    n = kd.size
    counts = runtime.zeros(queue, nbins, np.uint32, "histogram counts")
    overflow = runtime.zeros(queue, 1, np.uint32, "histogram overflow")
    if n:
        shape, groups = _shape(queue, "histogram")
        wg = shape["WG"]
        # local counters for the bins needed (a power of two, so few variants),
        # if the profile and the device's local memory allow
        local_bins = max(256, 1 << (nbins - 1).bit_length())
        fits = (
            local_bins <= shape["LOCAL_BINS"]
            and 4 * (local_bins + 1) <= runtime.capabilities(queue).local_mem_bytes
        )
        defines = {"KEY_T": "int" if kd.dtype == np.int32 else "uint", "WG": wg, "LOCAL_BINS": local_bins}
        if fits and n >= nbins:
            per, G = _partition(n, wg, groups)
            k = runtime.get_kernel(queue, "primitives/histogram.cl", "histogram_local", defines)
            runtime.launch(
                queue,
                k,
                G * wg,
                wg,
                buf(kd),
                _u64(n),
                _u64(per),
                np.uint32(nbins),
                buf(counts),
                buf(overflow),
            )
        else:
            k = runtime.get_kernel(queue, "primitives/histogram.cl", "histogram_global", defines)
            G = min(groups * 64, -(-n // wg))
            runtime.launch(
                queue, k, G * wg, wg, buf(kd), _u64(n), np.uint32(nbins), buf(counts), buf(overflow)
            )
        if check:
            bad = int(overflow.get()[0])
            if bad:
                raise DataError(f"keys: {bad} keys lie outside [0, {nbins}) (nbins={nbins})")
    return result(counts, host)


# --------------------------------------------------------------------------
# copy


def copy(
    x: Any, *, out: cla.Array | None = None, queue: cl.CommandQueue | None = None
) -> np.ndarray | cla.Array:
    """A copy of x made by a device kernel: the benchmarks' bandwidth yardstick.
    out: a device array of x's dtype and shape to copy into (e.g. the very
    buffer an op under test writes, so both see the same memory placement)."""
    queue = resolve_queue(queue, x=x, out=out)
    host = not is_device(x)
    x = check_array("x", x)
    xd = to_device(queue, "x", x)
    if out is None:
        out = runtime.empty(queue, xd.shape, xd.dtype, "copy output")
    else:
        if not is_device(out):
            raise TypeError("out: expected a pyopencl.array.Array")
        out = check_array("out", out, dtypes=[xd.dtype])
        if out.shape != xd.shape or out.offset:
            raise ValueError(f"out: expected shape {xd.shape} without offset, got {out.shape}")
    nbytes = xd.nbytes
    if nbytes:
        k = runtime.get_kernel(queue, "primitives/copy.cl", "copy_bytes", {})
        chunks = max(1, nbytes // 16)
        runtime.launch(queue, k, chunks, None, buf(xd), buf(out), _u64(nbytes))
    return result(out, host)
