"""clvis.raster.edl (eye-dome lighting) against clvis.reference.raster.edl,
its meaning on a step in depth, and its bad-input errors.

Tolerance: one colour step. The kernel's log2 and exp are the device's
(OpenCL allows a few ulp), so c * shade may round to the other side of a
half where numpy's does not; everything else (which pixels change, alpha)
is exact."""

import sys

import numpy as np
import pyopencl.array as cla
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import clvis
from clvis.raster import edl
from clvis.reference.raster import edl as ref

INF = np.float32(np.inf)


def scene(shape, density, seed):
    rng = np.random.default_rng(seed)
    d = (rng.choice([2.0, 5.0, 20.0], shape) * (1 + 0.01 * rng.standard_normal(shape))).astype(np.float32)
    d = np.where(rng.random(shape) < density, d, INF).astype(np.float32)
    rgba = rng.integers(0, 256, shape + (4,), dtype=np.uint8)
    return d, rgba


def check(depth, rgba, queue, strength=1.0, radius=1):
    got = edl(depth, rgba, strength, radius, queue=queue)
    want = ref.edl(depth, rgba, strength, radius)
    assert got.dtype == np.uint8 and got.shape == rgba.shape
    diff = np.abs(got.astype(int) - want.astype(int))
    assert diff.max(initial=0) <= 1
    np.testing.assert_array_equal(got[..., 3], rgba[..., 3])
    holds = np.isfinite(depth) & (depth > 0)
    np.testing.assert_array_equal(got[~holds], rgba[~holds])  # empty pixels copied exactly
    return got


@pytest.mark.parametrize(
    "shape", [(0, 0), (0, 5), (1, 1), (1, 7), (7, 1), (2, 2), (3, 5), (33, 17), (64, 65)]
)
def test_parity(queue, shape):
    for i, density in enumerate((0.3, 1.0)):
        d, rgba = scene(shape, density, seed=i + 7 * shape[0] + shape[1])
        for strength, radius in ((1.0, 1), (0.3, 2), (5.0, 3), (0.0, 1), (1.0, 64)):
            check(d, rgba, queue, strength, radius)


def test_parity_large(queue):
    d, rgba = scene((1080, 1920), 0.5, seed=3)
    check(d, rgba, queue, 1.0, 2)


def test_adversarial_depths(queue):
    d = np.array([[0.0, -1.0, np.nan, 1e-38], [np.float32(3.4e38), 1.0, INF, -INF]], np.float32)
    rgba = np.full((2, 4, 4), 200, np.uint8)
    got = check(d, rgba, queue)
    # 0, negative, NaN and infinite depths hold no point: copied as they are
    np.testing.assert_array_equal(got[0, :3], rgba[0, :3])


def test_meaning_step(queue):
    """A far plane beside a near one: the far side of the step darkens, the
    near side and the flat interiors keep their colour."""
    d = np.full((8, 16), 10.0, np.float32)
    d[:, :8] = 5.0
    rgba = np.full((8, 16, 4), 200, np.uint8)
    got = edl(d, rgba, queue=queue)
    assert (got[:, 8, :3] < 100).all()  # the far column next to the step: log2(10/5) = 1 per neighbour
    np.testing.assert_array_equal(got[:, :8], rgba[:, :8])  # nearer than every neighbour
    np.testing.assert_array_equal(got[:, 10:], rgba[:, 10:])  # flat
    # strength 0 changes nothing
    np.testing.assert_array_equal(edl(d, rgba, 0.0, queue=queue), rgba)


def test_device_in_device_out(queue):
    d, rgba = scene((9, 11), 0.7, seed=1)
    got = edl(cla.to_device(queue, d), cla.to_device(queue, rgba), 2.0)
    assert isinstance(got, cla.Array)
    np.testing.assert_array_equal(got.get(), edl(d, rgba, 2.0, queue=queue))


@given(
    hnp.arrays(
        np.float32,
        st.tuples(st.integers(1, 9), st.integers(1, 9)),
        elements=st.floats(0.015625, 1048576.0, width=32) | st.just(float("inf")),
    ),
    st.floats(0, 20),
    st.integers(1, 4),
)
def test_property(device, depth, strength, radius):
    q = clvis.runtime.queue_for(device)
    rgba = np.full(depth.shape + (4,), 255, np.uint8)
    got = check(depth, rgba, q, strength, radius)
    assert (got[..., :3] <= 255).all()
    # a pixel nearer than (or level with) every neighbour is never darkened
    got_min = edl(np.full(depth.shape, 3.0, np.float32), rgba, strength, radius, queue=q)
    np.testing.assert_array_equal(got_min, rgba)


def test_defaults_match_reference():
    mod = sys.modules["clvis.raster.edl"]

    assert ref.EDL_SCALE == np.float32(300.0)  # the kernel's default -DEDL_SCALE
    assert mod.EDL_STRENGTH == 1.0 and mod.EDL_RADIUS == 1


def test_bad_input(queue):
    d, rgba = scene((4, 4), 1.0, seed=0)
    with pytest.raises(TypeError, match="depth: dtype float64"):
        edl(d.astype(np.float64), rgba, queue=queue)
    with pytest.raises(ValueError, match="rgba: expected 4 channels"):
        edl(d, rgba[..., :3], queue=queue)
    with pytest.raises(ValueError, match="depth: shape"):
        edl(d[:3], rgba, queue=queue)
    with pytest.raises(ValueError, match="strength: expected a finite number"):
        edl(d, rgba, -1.0, queue=queue)
    with pytest.raises(ValueError, match="strength"):
        edl(d, rgba, float("nan"), queue=queue)
    with pytest.raises(TypeError, match="strength: expected a number"):
        edl(d, rgba, "1", queue=queue)
    with pytest.raises(ValueError, match="radius: expected 1..64"):
        edl(d, rgba, 1.0, 0, queue=queue)
    with pytest.raises(TypeError, match="radius: expected an int"):
        edl(d, rgba, 1.0, 1.5, queue=queue)
