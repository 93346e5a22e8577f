"""clvis.iso.macrocell_grids (kernels_cl/iso/macrocell.cl) against
clvis.reference.iso.block_ranges / coarse_ranges of the decoded volume:
exactly, on every device and both work shapes."""

import numpy as np
import pyopencl.array as cla
import pytest
from hypothesis import given
from hypothesis import strategies as st

import clvis
from clvis import datasets, iso, zfp
from clvis.iso.macrocell import range_bits
from clvis.reference import iso as ref
from clvis.reference.iso.macrocell import range_bits as ref_range_bits


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


def _ranges(n, seed):
    """n float32 ranges (lo, hi) around 0.5, some empty (+inf, -inf), some NaN,
    some with an end exactly at 0.5."""
    rng = np.random.default_rng(seed)
    lo = rng.uniform(0, 1, n).astype(np.float32)
    hi = lo + rng.uniform(0, 0.5, n).astype(np.float32)
    r = np.stack([lo, hi], -1)
    k = rng.integers(0, 6, n)
    r[k == 0] = (np.inf, -np.inf)
    r[k == 1, 0] = np.nan
    r[k == 2, 1] = np.float32(0.5)
    r[k == 3, 0] = np.float32(0.5)
    return r


@pytest.mark.parametrize("n", [1, 5, 31, 32, 33, 64, 1000])
def test_range_bits_match_reference(queue, n):
    """range_bits (the grids as macro_traverse reads them) == the reference:
    every word, bits past n zero; one bit per range's test, in order."""
    r = _ranges(n, n).reshape(-1, 1, 2) if n % 5 else _ranges(n, n)
    for v in (0.5, 0.25, np.inf, np.nan):
        got = range_bits(cla.to_device(queue, np.ascontiguousarray(r)), v).get(queue=queue)
        want = ref_range_bits(r, v)
        assert got.dtype == np.uint32 and got.shape == (-(-n // 32),)
        np.testing.assert_array_equal(got, want)
        flat = r.reshape(-1, 2)
        on = (flat[:, 0] <= np.float32(v)) & (np.float32(v) <= flat[:, 1])
        bits = (want[np.arange(32 * want.size) // 32] >> (np.arange(32 * want.size) % 32)) & 1
        np.testing.assert_array_equal(bits[:n], on)
        assert not bits[n:].any()


def test_range_bits_of_the_grids(queue):
    zv = zfp.compress(datasets.explosion((40, 36, 33))["volume"], 8)
    g = iso.macrocell_grids(zv, queue=queue, host=False)
    for grid in (g.fine, g.coarse):
        np.testing.assert_array_equal(range_bits(grid, 0.5).get(queue=queue), ref_range_bits(grid.get(), 0.5))


def test_range_bits_bad_input(queue):
    with pytest.raises(TypeError, match="ranges"):
        range_bits(np.zeros((4, 2), np.float32), 0.5)
    with pytest.raises(TypeError, match="ranges"):
        range_bits(cla.to_device(queue, np.zeros((4, 3), np.float32)), 0.5)
    with pytest.raises(ValueError, match="ranges"):
        ref_range_bits(np.zeros((4, 2), np.float64), 0.5)
