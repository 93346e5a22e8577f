"""clvis.scan against clvis.reference.primitives.scan.

Integers are compared exactly (sums wrap in the input's width, as the
reference's). float32 is compared exactly too wherever the data are integers
whose partial sums stay below 2^24 -- every summation order is then exact, so
a dropped or doubled element shows -- and within a stated rounding bound on
real-valued data.
"""

import os

import numpy as np
import pyopencl.array as cla
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import clvis
from clvis.reference import primitives as ref

DTYPES = [np.int32, np.uint32, np.int64, np.uint64, np.float32]
SIZES = [0, 1, 2, 3, 15, 16, 17, 255, 256, 257, 2047, 2048, 2049, 4095, 4096, 4097, 65535, 65536, 65537]


def data(n, dtype, rng, kind="random"):
    dtype = np.dtype(dtype)
    if kind == "random":
        if dtype.kind == "f":  # integers: exact in float32 while sums < 2^24
            hi = max(2, min(100, (1 << 24) // max(n, 1)))
            return rng.integers(0, hi, n).astype(dtype)
        info = np.iinfo(dtype)
        return rng.integers(info.min, info.max, n, dtype=dtype, endpoint=True)
    if kind == "zeros":
        return np.zeros(n, dtype)
    if kind == "extremes":  # min/max of the type: sums wrap around
        info = np.iinfo(dtype) if dtype.kind in "iu" else np.finfo(dtype)
        return np.where(np.arange(n) % 3 == 0, info.max, info.min).astype(dtype)
    raise ValueError(kind)


def check(x, exclusive, queue):
    out, total = clvis.scan(x, exclusive, return_total=True, queue=queue)
    want, want_total = ref.scan(x, exclusive, return_total=True)
    assert out.dtype == x.dtype and out.shape == x.shape
    # np.array_equal first: the same verdict at 2^27 elements in a fraction of
    # assert_array_equal's time, which then runs only to explain a mismatch
    # (and to accept NaNs in the same places)
    if not np.array_equal(out, want):
        np.testing.assert_array_equal(out, want)
    assert total == want_total and np.asarray(total).dtype == x.dtype


@pytest.mark.parametrize("exclusive", [True, False], ids=["exclusive", "inclusive"])
@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: np.dtype(d).name)
def test_parity_sizes(queue, dtype, exclusive):
    rng = np.random.default_rng(7)
    for n in SIZES:
        check(data(n, dtype, rng), exclusive, queue)


@pytest.mark.parametrize("kind", ["zeros", "extremes"])
@pytest.mark.parametrize("dtype", [np.int32, np.uint32, np.int64, np.uint64], ids=lambda d: np.dtype(d).name)
def test_adversarial_integers(queue, dtype, kind):
    for n in (1, 1000, 100003):
        check(data(n, dtype, np.random.default_rng(1), kind), True, queue)
        check(data(n, dtype, np.random.default_rng(1), kind), False, queue)


@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: np.dtype(d).name)
@pytest.mark.parametrize("n", [(1 << 20) - 1, 1 << 20, (1 << 20) + 1])
def test_parity_mega(queue, dtype, n):
    check(data(n, dtype, np.random.default_rng(n)), True, queue)


@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: np.dtype(d).name)
def test_parity_2_24(device, dtype):
    """2^24 elements (float32: 0/1 values, so every sum below 2^24 is exact)."""
    queue = clvis.runtime.queue_for(device)
    rng = np.random.default_rng(24)
    n = 1 << 24
    x = rng.integers(0, 2, n).astype(dtype) if dtype == np.float32 else data(n, dtype, rng)
    check(x, False, queue)


@pytest.mark.large
@pytest.mark.skipif(os.environ.get("CLVIS_LARGE") != "1", reason="set CLVIS_LARGE=1 (2^27 elements)")
@pytest.mark.parametrize("dtype", [np.int32, np.uint64], ids=lambda d: np.dtype(d).name)
def test_2_27(device, dtype):
    queue = clvis.runtime.queue_for(device)
    x = np.random.default_rng(27).integers(0, 1 << 20, 1 << 27, dtype=dtype)  # drawn in dtype: no int64 copy
    check(x, True, queue)


def test_float_rounding_bound(queue):
    """Real-valued float32: |out - exact| <= d * eps * sum(|x[j]|, j <= i),
    the classic bound for a sum whose terms pass through at most d dependent
    additions. In every work shape a range holds at most n / 16 tiles (one
    carried addition each), a tile at most 2048 elements, and the work-group
    scan and the ranges before it add fewer than 2048 more. Exactness of the
    algorithm itself is checked by the integer-valued tests above."""
    rng = np.random.default_rng(3)
    n = 200_003
    x = (rng.standard_normal(n) * 10).astype(np.float32)
    exact = np.cumsum(x.astype(np.float64))
    mag = np.cumsum(np.abs(x).astype(np.float64))
    out = clvis.scan(x, False, queue=queue)
    depth = n // 16 + 2 * 2048
    eps = np.finfo(np.float32).eps
    err = np.abs(out.astype(np.float64) - exact)
    assert np.all(err <= depth * eps * mag)


def test_float_nan_inf(queue):
    x = np.ones(5000, np.float32)
    x[1000] = np.inf
    x[2000] = -np.inf  # inf - inf: NaN from here on
    out = clvis.scan(x, False, queue=queue)
    with np.errstate(invalid="ignore"):  # inf + -inf, as the kernel computes too
        want = ref.scan(x, False)
    np.testing.assert_array_equal(np.isnan(out), np.isnan(want))
    np.testing.assert_array_equal(np.isinf(out), np.isinf(want))
    np.testing.assert_array_equal(out[:1000], want[:1000])
    x = np.zeros(3000, np.float32)
    x[1234] = np.nan
    out = clvis.scan(x, True, queue=queue)
    assert not np.isnan(out[:1235]).any() and np.isnan(out[1235:]).all()


def test_float_deterministic(queue):
    """Same input, same device and work shape: the same bits, run after run."""
    x = np.random.default_rng(4).standard_normal(300_001).astype(np.float32)
    first = clvis.scan(x, False, queue=queue)
    for _ in range(3):
        assert clvis.scan(x, False, queue=queue).tobytes() == first.tobytes()


def test_negative_zero(queue):
    x = np.array([-0.0, -0.0, 1.0, -1.0], np.float32)
    np.testing.assert_array_equal(clvis.scan(x, False, queue=queue), [0.0, 0.0, 1.0, 0.0])


CHAIN_SIZES = [1, 15, 16, 17, 4095, 4096, 4097, 65537, 1_000_003]


@pytest.mark.parametrize("dtype", [np.int32, np.uint32], ids=lambda d: np.dtype(d).name)
def test_chained_scan_used_and_matches_fallback_build(device, dtype, monkeypatch):
    """32-bit integers on the CPU shape take the single-pass chained scan when
    the device has 64-bit atomics; built without them (forced) they take
    reduce-then-scan. Both equal the reference."""
    q = clvis.runtime.queue_for(device)
    used = []
    real = clvis.runtime.get_kernel
    monkeypatch.setattr(
        clvis.runtime,
        "get_kernel",
        lambda queue, path, name, defines: used.append(name) or real(queue, path, name, defines),
    )
    rng = np.random.default_rng(5)
    with clvis.runtime.configure(tuning="cpu"):
        for n in CHAIN_SIZES:
            check(data(n, dtype, rng), True, q)
        assert ("scan_chained" in used) == clvis.runtime.capabilities(q).int64_atomics
        used.clear()
        with clvis.runtime.configure(int64_atomics=False):
            for n in CHAIN_SIZES:
                check(data(n, dtype, rng), False, q)
        assert "scan_chained" not in used and "scan_downsweep" in used


def test_chained_scan_fallback_path(device, monkeypatch):
    """Every look-back summing its predecessors' ranges itself (what happens
    when a predecessor has not published) gives the same result."""
    q = clvis.runtime.queue_for(device)
    if not clvis.runtime.capabilities(q).int64_atomics:
        pytest.skip("no 64-bit atomics: scan_chained is not built on this device")
    monkeypatch.setattr(clvis.primitives, "_SCAN_TEST_FALLBACK", True)
    rng = np.random.default_rng(6)
    with clvis.runtime.configure(tuning="cpu"):
        for n in CHAIN_SIZES:
            check(data(n, np.int32, rng), True, q)
            check(data(n, np.uint32, rng), False, q)


def test_device_arrays_stay_on_device(queue, monkeypatch):
    x = np.arange(10000, dtype=np.int64)
    xd = cla.to_device(queue, x)
    monkeypatch.setattr(cla.Array, "get", lambda *a, **k: pytest.fail("host read in a device pipeline"))
    out, total = clvis.scan(xd, False, return_total=True)
    assert isinstance(out, cla.Array) and out.queue is queue and isinstance(total, cla.Array)
    monkeypatch.undo()
    np.testing.assert_array_equal(out.get(), np.cumsum(x))
    assert total.get()[0] == x.sum()


def test_in_place(queue):
    x = np.arange(1, 70001, dtype=np.uint32)
    xd = cla.to_device(queue, x)
    r = clvis.scan(xd, True, out=xd)
    assert r is xd
    np.testing.assert_array_equal(xd.get(), ref.scan(x, True))


def test_empty_total(queue):
    out, total = clvis.scan(np.zeros(0, np.float32), return_total=True, queue=queue)
    assert out.shape == (0,) and total == 0


@given(
    x=hnp.arrays(st.sampled_from([np.int32, np.uint32, np.int64, np.uint64]), st.integers(0, 5000)),
    exclusive=st.booleans(),
)
def test_property_integers(device, x, exclusive):
    check(x, exclusive, clvis.runtime.queue_for(device))


@given(x=hnp.arrays(np.int64, st.integers(1, 3000), elements=st.integers(-(2**40), 2**40)))
def test_property_exclusive_is_inclusive_minus_x(device, x):
    q = clvis.runtime.queue_for(device)
    inc, total = clvis.scan(x, False, return_total=True, queue=q)
    exc = clvis.scan(x, True, queue=q)
    np.testing.assert_array_equal(inc - x, exc)
    assert total == inc[-1]


def test_bad_input():
    with pytest.raises(TypeError, match="x: dtype float64"):
        clvis.scan(np.zeros(4))
    with pytest.raises(TypeError, match="x: dtype int16"):
        clvis.scan(np.zeros(4, np.int16))
    with pytest.raises(ValueError, match="x: expected a 1-D array"):
        clvis.scan(np.zeros((2, 2), np.int32))
    with pytest.raises(TypeError, match="x: expected an array"):
        clvis.scan("1234")
    q = clvis.default_queue()
    xd = cla.to_device(q, np.zeros(8, np.int32))
    with pytest.raises(TypeError, match="out: dtype"):
        clvis.scan(xd, out=cla.empty(q, 8, np.int64))
    with pytest.raises(ValueError, match="out: size 7"):
        clvis.scan(xd, out=cla.empty(q, 7, np.int32))
    with pytest.raises(ValueError, match="x: the device array is not C-contiguous"):
        clvis.scan(cla.to_device(q, np.zeros(16, np.int32))[::2])
