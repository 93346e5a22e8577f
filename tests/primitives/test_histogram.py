"""clvis.histogram against clvis.reference.primitives.histogram."""

import numpy as np
import pyopencl.array as cla
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import clvis
from clvis.reference import primitives as ref


@pytest.mark.parametrize("nbins", [1, 7, 256, 4096, 4097, 65536, 65537, 1 << 20])
def test_parity(queue, nbins):
    rng = np.random.default_rng(nbins)
    for n in (0, 1, 1000, 200_003):
        keys = rng.integers(0, nbins, n).astype(np.int32)
        got = clvis.histogram(keys, nbins, queue=queue)
        assert got.dtype == np.uint32 and got.shape == (nbins,)
        np.testing.assert_array_equal(got, ref.histogram(keys, nbins))


@pytest.mark.parametrize("dtype", [np.int32, np.uint32], ids=lambda d: np.dtype(d).name)
def test_contention(queue, dtype):
    """Every key in one bin, and two bins alternating."""
    keys = np.full(300_000, 5, dtype)
    np.testing.assert_array_equal(clvis.histogram(keys, 6, queue=queue), ref.histogram(keys, 6))
    keys = (np.arange(1 << 20) % 2).astype(dtype)
    np.testing.assert_array_equal(clvis.histogram(keys, 1 << 16, queue=queue), ref.histogram(keys, 1 << 16))


def test_out_of_range(queue):
    keys = np.array([0, 3, -1, 4, 2, 2**31 - 1, 3], np.int32)
    with pytest.raises(clvis.DataError, match=r"3 keys lie outside \[0, 4\)"):
        clvis.histogram(keys, 4, queue=queue)
    np.testing.assert_array_equal(clvis.histogram(keys, 4, check=False, queue=queue), ref.histogram(keys, 4))
    ukeys = np.array([1, 0xFFFFFFFF], np.uint32)
    with pytest.raises(clvis.DataError, match="1 keys"):
        clvis.histogram(ukeys, 10, queue=queue)


def test_device_arrays(queue):
    keys = np.arange(100000, dtype=np.uint32) % 77
    got = clvis.histogram(cla.to_device(queue, keys), 77, check=False)
    assert isinstance(got, cla.Array)
    np.testing.assert_array_equal(got.get(), ref.histogram(keys, 77))


@given(
    keys=hnp.arrays(np.int32, st.integers(0, 4000), elements=st.integers(-3, 300)), nbins=st.integers(1, 400)
)
def test_property(device, keys, nbins):
    q = clvis.runtime.queue_for(device)
    got = clvis.histogram(keys, nbins, check=False, queue=q)
    np.testing.assert_array_equal(got, ref.histogram(keys, nbins))
    inside = int(((keys >= 0) & (keys < nbins)).sum())
    assert int(got.sum()) == inside


def test_bad_input():
    with pytest.raises(TypeError, match="keys: dtype float32"):
        clvis.histogram(np.zeros(4, np.float32), 4)
    with pytest.raises(ValueError, match="nbins: expected 1..2\\^32-1, got 0"):
        clvis.histogram(np.zeros(4, np.int32), 0)
    with pytest.raises(TypeError, match="nbins: expected an int"):
        clvis.histogram(np.zeros(4, np.int32), 4.5)
    with pytest.raises(ValueError, match="keys: expected a 1-D array"):
        clvis.histogram(np.zeros((2, 2), np.int32), 4)
