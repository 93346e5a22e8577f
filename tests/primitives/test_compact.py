"""clvis.compact and clvis.compact_indices against the NumPy reference."""

import numpy as np
import pyopencl.array as cla
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import clvis
from clvis.reference import primitives as ref

SIZES = [0, 1, 2, 3, 15, 16, 17, 1023, 1024, 1025, 4097, 65537, 1 << 20]
DENSITIES = [0.0, 0.001, 0.5, 0.999, 1.0]


def flags_for(n, density, rng, dtype=np.bool_):
    f = rng.random(n) < density
    if np.dtype(dtype) == np.bool_:
        return f
    # non-zero values of all sizes, not just 1
    return np.where(f, rng.integers(1, 100, n), 0).astype(dtype)


@pytest.mark.parametrize("density", DENSITIES)
def test_parity_sizes(queue, density):
    rng = np.random.default_rng(11)
    for n in SIZES:
        x = rng.integers(-(2**31), 2**31, n).astype(np.int32)
        f = flags_for(n, density, rng)
        got = clvis.compact(x, f, queue=queue)
        np.testing.assert_array_equal(got, ref.compact(x, f))
        assert got.dtype == x.dtype
        np.testing.assert_array_equal(clvis.compact_indices(f, queue=queue), ref.compact_indices(f))


@pytest.mark.parametrize(
    "fdtype",
    [np.bool_, np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32, np.uint64, np.int64],
    ids=lambda d: np.dtype(d).name,
)
def test_flag_dtypes(queue, fdtype):
    rng = np.random.default_rng(5)
    n = 30011
    x = np.arange(n, dtype=np.float32)
    f = flags_for(n, 0.3, rng, fdtype)
    if np.dtype(fdtype).kind == "i":
        f = -f  # negative flags are non-zero too
    np.testing.assert_array_equal(clvis.compact(x, f, queue=queue), ref.compact(x, f))
    np.testing.assert_array_equal(clvis.compact_indices(f, queue=queue), ref.compact_indices(f))


@pytest.mark.parametrize(
    "dtype,row",
    [
        (np.uint8, ()),
        (np.int16, ()),
        (np.float64, ()),
        (np.complex128, ()),
        (np.float32, (3,)),
        (np.uint8, (4,)),
        (np.uint8, (3,)),
        (np.int16, (2, 3)),
        (np.dtype([("a", np.float32), ("b", np.uint8)]), ()),
    ],
    ids=str,
)
def test_row_types(queue, dtype, row):
    """Rows of any width are kept whole (copied as 8/4/2/1-byte words)."""
    rng = np.random.default_rng(9)
    n = 20003
    raw = rng.integers(0, 256, n * np.dtype(dtype).itemsize * int(np.prod(row)), dtype=np.uint8)
    x = raw.view(dtype).reshape((n,) + row)
    f = flags_for(n, 0.5, rng)
    got = clvis.compact(x, f, queue=queue)
    want = ref.compact(x, f)
    assert got.shape == want.shape and got.dtype == want.dtype
    assert got.tobytes() == want.tobytes()


def test_device_pipeline_count_on_device(queue, monkeypatch):
    """With `count`, nothing is read back, the count stays on the device and
    nothing past the kept rows is written."""
    rng = np.random.default_rng(2)
    n = 100_000
    x = rng.integers(0, 1000, n).astype(np.uint32)
    f = flags_for(n, 0.25, rng)
    xd, fd = cla.to_device(queue, x), cla.to_device(queue, f)
    sentinel = np.uint32(0xDEADBEEF)
    out = cla.to_device(queue, np.full(n, sentinel, np.uint32))
    count = cla.zeros(queue, 1, np.uint32)
    monkeypatch.setattr(cla.Array, "get", lambda *a, **k: pytest.fail("host read in a device pipeline"))
    r_out, r_count = clvis.compact(xd, fd, out=out, count=count)
    r2_out, r2_count = clvis.compact_indices(
        fd, out=cla.empty(queue, n, np.uint32), count=cla.zeros(queue, 1, np.uint32)
    )
    monkeypatch.undo()
    assert r_out is out and r_count is count
    k = int(count.get()[0])
    assert k == int(f.sum())
    got = out.get()
    np.testing.assert_array_equal(got[:k], x[f])
    assert np.all(got[k:] == sentinel)
    np.testing.assert_array_equal(r2_out.get()[: int(r2_count.get()[0])], np.flatnonzero(f))


def test_device_result_is_sized(queue):
    x = cla.to_device(queue, np.arange(1000, dtype=np.int64))
    f = cla.to_device(queue, (np.arange(1000) % 7 == 0))
    got = clvis.compact(x, f)
    assert isinstance(got, cla.Array) and got.shape == (143,)
    np.testing.assert_array_equal(got.get(), np.arange(0, 1000, 7))
    empty = clvis.compact(x, cla.zeros(queue, 1000, np.uint8))
    assert empty.shape == (0,)


@given(f=hnp.arrays(np.uint8, st.integers(0, 5000), elements=st.integers(0, 3)))
def test_property_indices(device, f):
    q = clvis.runtime.queue_for(device)
    idx = clvis.compact_indices(f, queue=q)
    assert idx.dtype == np.uint32
    np.testing.assert_array_equal(idx, np.flatnonzero(f))
    x = np.arange(f.size, dtype=np.int64) * 3
    np.testing.assert_array_equal(clvis.compact(x, f, queue=q), x[f != 0])


def test_bad_input():
    with pytest.raises(ValueError, match="flags: length 3 differs from x's 4"):
        clvis.compact(np.zeros(4), np.ones(3, bool))
    with pytest.raises(TypeError, match="flags: dtype float32"):
        clvis.compact(np.zeros(4), np.ones(4, np.float32))
    with pytest.raises(ValueError, match="flags: expected a 1-D array"):
        clvis.compact_indices(np.ones((2, 2), bool))
    with pytest.raises(ValueError, match="x: expected at least 1-D"):
        clvis.compact(np.float32(3), np.ones(1, bool))
    q = clvis.default_queue()
    xd = cla.to_device(q, np.zeros(8, np.int32))
    fd = cla.to_device(q, np.ones(8, np.uint8))
    with pytest.raises(ValueError, match="out: expected shape"):
        clvis.compact(xd, fd, out=cla.empty(q, 4, np.int32), count=cla.zeros(q, 1, np.uint32))
    with pytest.raises(TypeError, match="count: dtype int32"):
        clvis.compact(xd, fd, count=cla.zeros(q, 1, np.int32))
