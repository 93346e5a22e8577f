"""The copy kernel (the benchmarks' bandwidth yardstick) against its reference."""

import numpy as np
import pyopencl.array as cla
import pytest

from clvis import primitives
from clvis.reference import primitives as ref


@pytest.mark.parametrize("nbytes", [0, 1, 15, 16, 17, 4096, 1_000_003])
def test_parity(device, nbytes):
    q = primitives.runtime.queue_for(device)
    x = np.random.default_rng(nbytes).integers(0, 256, nbytes, dtype=np.uint8)
    np.testing.assert_array_equal(primitives.copy(x, queue=q), ref.copy(x))


def test_shapes_and_device_arrays(device):
    q = primitives.runtime.queue_for(device)
    x = np.arange(3 * 1001, dtype=np.float64).reshape(1001, 3)
    got = primitives.copy(cla.to_device(q, x))
    assert isinstance(got, cla.Array) and got.shape == x.shape and got.dtype == x.dtype
    np.testing.assert_array_equal(got.get(), x)


def test_into_out(device):
    q = primitives.runtime.queue_for(device)
    x = cla.to_device(q, np.arange(1000, dtype=np.int32))
    out = cla.zeros(q, 1000, np.int32)
    assert primitives.copy(x, out=out) is out
    np.testing.assert_array_equal(out.get(), np.arange(1000))
    with pytest.raises(ValueError, match="out: expected shape"):
        primitives.copy(x, out=cla.zeros(q, 999, np.int32))
