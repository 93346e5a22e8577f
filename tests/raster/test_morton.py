"""clvis.raster.morton against clvis.reference.raster.morton on every device
and both work shapes: the permutation exactly, and the gather into it."""

import numpy as np
import pyopencl.array as cla

import clvis
from clvis.raster.morton import morton_gather
from clvis.reference import raster as ref


def _scene(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, 3)).astype(np.float32)


def test_morton_order(queue):
    pos = _scene(100_000, seed=11)
    pos[::1000] = np.nan
    perm = clvis.morton_order(pos, queue=queue)
    np.testing.assert_array_equal(perm, ref.morton_order(pos))
    assert np.array_equal(np.sort(perm), np.arange(len(pos)))
    assert np.isnan(pos[perm[-100:]]).any(axis=1).all()
    assert clvis.morton_order(np.zeros((0, 3), np.float32), queue=queue).shape == (0,)


def test_morton_order_keeps_device_arrays_on_the_device(queue):
    pos = _scene(5_000, seed=12)
    perm = clvis.morton_order(cla.to_device(queue, pos))
    assert isinstance(perm, cla.Array)
    np.testing.assert_array_equal(perm.get(), ref.morton_order(pos))


def test_morton_gather(queue):
    pos = _scene(30_000, seed=13)
    d = cla.to_device(queue, pos)
    perm = clvis.morton_order(d)
    out, inv = morton_gather(queue, d, perm)
    p = perm.get()
    np.testing.assert_array_equal(out.get(), pos[p])
    np.testing.assert_array_equal(inv.get()[p], np.arange(len(pos), dtype=np.uint32))
