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
