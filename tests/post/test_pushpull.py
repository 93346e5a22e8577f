"""clvis.post.pushpull against clvis.reference.post.pushpull, the fill's meaning
(identity, constant fill, quality on a smooth image) and its bad-input errors.

Tolerance: exact. The kernels repeat the reference's float32 operations in the
same order (FP_CONTRACT OFF, correctly rounded division), so every device that
keeps float32 denormals gives the reference's bits."""

import importlib

import numpy as np
import pyopencl.array as cla
import pytest
from hypothesis import given
from hypothesis import strategies as st
from skimage.metrics import peak_signal_noise_ratio

import clvis
from clvis.errors import ClvisError, DataError
from clvis.post.pushpull import default_levels, pushpull
from clvis.reference.post import pushpull as ref

# the module: clvis.post's pushpull attribute is the function of that name
pp_module = importlib.import_module("clvis.post.pushpull")


def holed(shape, channels, fraction, seed, nan_holes=True):
    rng = np.random.default_rng(seed)
    img = rng.uniform(-2, 3, shape + (channels,)).astype(np.float32)
    valid = rng.random(shape) >= fraction
    if nan_holes:
        img[~valid] = np.nan  # never read
    return img, valid


def check(img, valid, queue, **kw):
    got = pushpull(img, valid, queue=queue, **kw)
    want = ref.pushpull(img, valid, **kw)
    assert isinstance(got, np.ndarray) and got.dtype == np.float32 and got.shape == img.shape
    np.testing.assert_array_equal(got, want)
    v = np.asarray(valid) != 0
    np.testing.assert_array_equal(got[v], img[v])  # known pixels bit for bit
    return got


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (2, 2), (3, 5), (17, 33), (37, 53), (64, 65)])
@pytest.mark.parametrize("channels", [1, 3, 4, 5])
def test_parity(queue, shape, channels):
    for i, fraction in enumerate((0.0, 0.15, 0.6, 0.97)):
        img, valid = holed(shape, channels, fraction, seed=hash((shape, channels, i)) % 2**32)
        out = check(img, valid, queue)
        assert np.isfinite(out).all()
    for levels in (0, 1, 2, 3, 16):
        check(img, valid.astype(np.uint8) * 7, queue, levels=levels)


def test_parity_large(queue):
    img, valid = holed((720, 1280), 3, 0.3, seed=4)
    check(img, valid, queue)


def test_levels():
    assert [default_levels(*s) for s in [(1, 1), (1, 2), (2, 2), (3, 1), (37, 53), (720, 1280)]] == [
        0,
        1,
        1,
        2,
        6,
        11,
    ]
    assert ref.default_levels(720, 1280) == 11 and ref.MAX_LEVELS == pp_module.MAX_LEVELS


def test_all_valid_is_identity(queue):
    img, _ = holed((37, 53), 4, 0.0, seed=2)
    img[0, 0] = -0.0
    out = check(img, np.ones((37, 53), bool), queue)
    assert out.tobytes() == img.tobytes()


@pytest.mark.parametrize("shape", [(1, 1), (1, 40), (37, 53)])
def test_single_valid_pixel_fills_constant(queue, shape):
    img = np.full(shape + (3,), np.nan, np.float32)
    valid = np.zeros(shape, bool)
    y, x = shape[0] // 3, shape[1] // 2
    img[y, x] = (0.25, -1.5, 7.0)
    valid[y, x] = True
    out = check(img, valid, queue)
    np.testing.assert_array_equal(out, np.broadcast_to(img[y, x], out.shape))


def test_nothing_valid_gives_zeros(queue):
    img = np.full((13, 7, 2), np.nan, np.float32)
    for levels in (None, 0, 5):
        out = check(img, np.zeros((13, 7), np.uint8), queue, levels=levels)
        assert not out.any()


def test_quality(queue):
    """A smooth image with 15% random holes: the fill is far closer to the full
    image than the holed input (holes black)."""
    h, w = 96, 128
    yy, xx = np.mgrid[:h, :w].astype(np.float32)
    full = np.stack(
        [
            0.5 + 0.4 * np.sin(xx / 13.0) * np.cos(yy / 17.0),
            0.5 + 0.4 * np.cos((xx + yy) / 23.0),
            (xx + yy) / (h + w),
        ],
        axis=-1,
    ).astype(np.float32)
    valid = np.random.default_rng(6).random((h, w)) >= 0.15
    holes = np.where(valid[..., None], full, 0).astype(np.float32)
    filled = check(holes, valid, queue)
    before = peak_signal_noise_ratio(full, holes, data_range=1.0)
    after = peak_signal_noise_ratio(full, filled, data_range=1.0)
    assert after > before + 25 and after > 40


def test_device_arrays(queue):
    img, valid = holed((29, 31), 3, 0.4, seed=8)
    want = ref.pushpull(img, valid)
    for v in (valid, valid.astype(np.uint8)):
        got = pushpull(cla.to_device(queue, img), cla.to_device(queue, v))
        assert isinstance(got, cla.Array) and got.queue is queue and got.shape == img.shape
        np.testing.assert_array_equal(got.get(), want)
    mixed = pushpull(img, cla.to_device(queue, valid))
    assert isinstance(mixed, cla.Array)
    np.testing.assert_array_equal(mixed.get(), want)


@given(
    h=st.integers(1, 20),
    w=st.integers(1, 20),
    channels=st.integers(1, 8),
    fraction=st.sampled_from([0.0, 0.5, 0.9, 1.0]),
    seed=st.integers(0, 2**16),
    levels=st.one_of(st.none(), st.integers(0, 7)),
)
def test_property(device, h, w, channels, fraction, seed, levels):
    img, valid = holed((h, w), channels, fraction, seed)
    out = check(img, valid, clvis.runtime.queue_for(device), levels=levels)
    if valid.any() and (levels is None or levels >= default_levels(h, w)):
        # a convex combination of known values, channel by channel (with fewer
        # levels a coarsest pixel that sees no known pixel stays 0)
        if True:
            lo, hi = img[valid].min(axis=0), img[valid].max(axis=0)
            span = np.maximum(np.abs(lo), np.abs(hi)) * 1e-6
            assert (out >= lo - span).all() and (out <= hi + span).all()


def test_bad_input(device):
    q = clvis.runtime.queue_for(device)
    img, valid = holed((4, 5), 3, 0.3, seed=1)
    with pytest.raises(TypeError, match="image: dtype float64"):
        pushpull(img.astype(np.float64), valid, queue=q)
    with pytest.raises(ValueError, match="image: expected a 3-D array"):
        pushpull(img[..., 0], valid, queue=q)
    for c in (0, 9):
        with pytest.raises(ValueError, match="image: expected 1..8 channels"):
            pushpull(np.zeros((4, 5, c), np.float32), valid, queue=q)
    with pytest.raises(TypeError, match="valid: dtype float32"):
        pushpull(img, valid.astype(np.float32), queue=q)
    with pytest.raises(ValueError, match="valid: shape"):
        pushpull(img, valid[:3], queue=q)
    with pytest.raises(TypeError, match="image: expected an array"):
        pushpull(None, valid, queue=q)
    for shape in [(0, 5), (4, 0), (0, 0)]:
        with pytest.raises(DataError, match="image: empty"):
            pushpull(np.zeros(shape + (3,), np.float32), np.zeros(shape, bool), queue=q)
    for levels, exc in ((-1, ValueError), (17, ValueError), (2.0, TypeError), (True, TypeError)):
        with pytest.raises(exc, match="levels"):
            pushpull(img, valid, levels=levels, queue=q)
    for value in (np.nan, np.inf, -np.inf):
        bad = img.copy()
        bad[valid.nonzero()[0][0], valid.nonzero()[1][0], 1] = value
        with pytest.raises(DataError, match="image: 1 NaN or infinite values at valid pixels") as e:
            pushpull(bad, valid, queue=q)
        assert isinstance(e.value, ClvisError)
        with pytest.raises(DataError, match="image: 1 NaN or infinite"):
            pushpull(cla.to_device(q, bad), cla.to_device(q, valid))
        with pytest.raises(DataError):
            ref.pushpull(bad, valid)
    with pytest.raises(TypeError, match="queue"):
        pushpull(img, valid, queue="gpu")
