"""clvis.iso.macrocell_grids (kernels_cl/iso/macrocell.cl) against
clvis.reference.iso.block_ranges / coarse_ranges of the decoded volume:
exactly, on every device and both work shapes."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import clvis
from clvis import datasets, iso, zfp
from clvis.reference import iso as ref


def _expected(zv):
    dec = zfp.decode(zv)
    lo, hi = ref.block_ranges(dec)
    clo, chi = ref.coarse_ranges((lo, hi))
    return np.stack([lo, hi], axis=-1), np.stack([clo, chi], axis=-1)


def _volumes():
    rng = np.random.default_rng(0)
    z, y, x = np.mgrid[0:21, 0:18, 0:35] / 7.0
    yield "random", rng.normal(size=(13, 17, 9)).astype(np.float32), 8
    yield "smooth", (np.sin(x) * np.cos(y) + np.sin(z)).astype(np.float32), 12
    yield "explosion", datasets.explosion((40, 36, 33))["volume"], 6
    yield "n-1 multiple of 4", rng.uniform(size=(9, 5, 13)).astype(np.float32), 16
    yield "tiny", rng.uniform(size=(2, 2, 2)).astype(np.float32), 32
    yield "constant", np.full((8, 8, 8), 3.5, np.float32), 4
    yield "zeros", np.zeros((6, 7, 8), np.float32), 1


@pytest.mark.parametrize("name,volume,rate", list(_volumes()), ids=[v[0] for v in _volumes()])
def test_grids_match_reference(queue, name, volume, rate):
    zv = zfp.compress(volume, rate)
    g = iso.macrocell_grids(zv, queue=queue)
    fine, coarse = _expected(zv)
    assert g.fine.shape == fine.shape and g.coarse.shape == coarse.shape
    np.testing.assert_array_equal(g.fine, fine)
    np.testing.assert_array_equal(g.coarse, coarse)


def test_empty_last_blocks(queue):
    """n - 1 a multiple of 4: the last block holds no cell and gets (+inf, -inf)."""
    zv = zfp.compress(np.random.default_rng(1).uniform(size=(9, 9, 9)).astype(np.float32), 8)
    g = iso.macrocell_grids(zv, queue=queue)
    assert g.fine.shape == (3, 3, 3, 2)
    assert np.isposinf(g.fine[2, :, :, 0]).all() and np.isneginf(g.fine[:, :, 2, 1]).all()
    assert np.isfinite(g.fine[:2, :2, :2]).all()


def test_active_and_device_output(queue):
    v = datasets.explosion((32, 32, 32))["volume"]
    zv = zfp.compress(v, 8)
    g = iso.macrocell_grids(zv, queue=queue, host=False)
    fine, coarse = _expected(zv)
    np.testing.assert_array_equal(g.fine.get(), fine)
    fa, ca = g.active(0.5)
    assert fa.any() and not fa.all()
    # a coarse cell is active exactly when one of its blocks is
    np.testing.assert_array_equal(ca, ((coarse[..., 0] <= 0.5) & (0.5 <= coarse[..., 1])))


@given(
    shape=st.tuples(st.integers(2, 14), st.integers(2, 14), st.integers(2, 14)),
    rate=st.integers(1, 32),
    seed=st.integers(0, 2**31),
)
def test_property(shape, rate, seed):
    v = np.random.default_rng(seed).normal(size=shape).astype(np.float32)
    zv = zfp.compress(v, rate)
    g = iso.macrocell_grids(zv, queue=clvis.default_queue())
    fine, coarse = _expected(zv)
    np.testing.assert_array_equal(g.fine, fine)
    np.testing.assert_array_equal(g.coarse, coarse)


def test_bad_input():
    with pytest.raises(TypeError, match="volume"):
        iso.macrocell_grids(np.zeros((4, 4, 4), np.float32))
    with pytest.raises(ValueError, match="2 samples"):
        iso.macrocell_grids(zfp.compress(np.zeros((1, 4, 4), np.float32), 8))
