"""clvis.post.splat (the splat_gather kernel) against clvis.reference.post.splat,
the splat's meaning (a lone point, nothing covered) and its bad-input errors.

Tolerance: 2e-5 absolute. The kernel sums in float32 what the reference sums
in float64 (up to (2 radius + 1)^2 = 169 terms of exp and log1p per pixel,
colours in [0, 1]); the reference's result is rounded to float32 too."""

import numpy as np
import pytest

from clvis.errors import DataError
from clvis.post.splat import splat
from clvis.reference.post import splat as ref

H, W = 48, 64
ATOL = 2e-5


def frame(pattern, seed):
    rng = np.random.default_rng(seed)
    rgb = rng.random((H, W, 3)).astype(np.float32)
    if pattern == "none":
        cov = np.zeros((H, W), bool)
    elif pattern == "all":
        cov = np.ones((H, W), bool)
    elif pattern == "corner":
        cov = np.zeros((H, W), bool)
        cov[H - 1, 0] = True
    else:
        cov = rng.random((H, W)) < 0.25
    rgb[~cov] = np.nan  # never read
    return rgb, cov


def check(queue, rgb, cov, vel=None, **kw):
    got = splat(rgb, cov, vel, queue=queue, **kw)
    want = ref.splat(np.nan_to_num(rgb), cov, vel, **kw)
    assert isinstance(got, np.ndarray) and got.dtype == np.float32 and got.shape == (H, W, 3)
    np.testing.assert_allclose(got, want, rtol=0, atol=ATOL)
    return got


@pytest.mark.parametrize("pattern", ["none", "all", "corner", "sparse"])
def test_parity(queue, pattern):
    rgb, cov = frame(pattern, seed=len(pattern))
    rng = np.random.default_rng(7)
    vel = rng.normal(0, 3, (H, W, 2)).astype(np.float32)
    vel[: H // 3] = 0  # zero speed: round
    sigma = rng.uniform(0.2, 3.0, (H, W)).astype(np.float32)
    sigma[::5, ::3] = np.nan  # the reference's 0.5
    outs = [
        check(queue, rgb, cov),
        check(queue, rgb, cov, vel, stretch=3.0, opacity=0.8),
        check(queue, rgb, cov, None, sigma=sigma, radius=4),
        check(queue, rgb, cov, vel, sigma=sigma.astype(np.float64), radius=2, opacity=1.0),
    ]
    if pattern == "none":
        assert all(not o.any() for o in outs)
    else:
        assert all(o.any() for o in outs)


def test_lone_point(queue):
    """A lone covered pixel: a round Gaussian of sigma 2.4 (the 9 x 9
    coverage 1/81 gives 4.5, clipped to radius / 2.5 = 6 / 2.5), alpha = opacity x
    weight, the colour exact where the weight is."""
    rgb, cov = frame("corner", 0)
    cov[:] = False
    cov[20, 30] = True
    rgb[20, 30] = (1.0, 0.5, 0.25)
    out = check(queue, rgb, cov, opacity=0.5)
    d = np.array([0, 1, 3])
    wt = np.exp(-0.5 * (d / 2.4) ** 2)
    np.testing.assert_allclose(out[20, 30 + d, 0], 0.5 * wt, atol=1e-6)
    np.testing.assert_allclose(out[20 + d, 30, 1], 0.25 * wt, atol=1e-6)
    assert not out[:14].any() and not out[:, 37:].any()  # past the radius


def test_uint8_covered_and_device_arrays(queue):
    import pyopencl.array as cla

    rgb, cov = frame("sparse", 3)
    rgb = np.nan_to_num(rgb)
    want = splat(rgb, cov, queue=queue)
    np.testing.assert_array_equal(splat(rgb, cov.astype(np.uint8) * 9, queue=queue), want)
    got = splat(cla.to_device(queue, rgb), cla.to_device(queue, cov.view(np.uint8)), queue=queue)
    assert isinstance(got, cla.Array)
    np.testing.assert_array_equal(got.get(), want)


def test_bad_input(queue):
    rgb, cov = frame("sparse", 5)
    rgb = np.nan_to_num(rgb)
    vel = np.zeros((H, W, 2), np.float32)
    with pytest.raises(TypeError, match="rgb: dtype"):
        splat(rgb.astype(np.int32), cov, queue=queue)
    with pytest.raises(TypeError, match="covered: dtype"):
        splat(rgb, cov.astype(np.float32), queue=queue)
    with pytest.raises(ValueError, match="rgb: shape"):
        splat(rgb[..., :2], cov, queue=queue)
    with pytest.raises(ValueError, match="rgb: shape"):
        splat(rgb[1:], cov, queue=queue)
    with pytest.raises(ValueError, match="vel: shape"):
        splat(rgb, cov, vel[..., :1], queue=queue)
    with pytest.raises(ValueError, match="sigma: shape"):
        splat(rgb, cov, sigma=np.ones((H, W + 1), np.float32), queue=queue)
    for r in (0, 33, -1):
        with pytest.raises(ValueError, match="radius: expected 1..32"):
            splat(rgb, cov, radius=r, queue=queue)
    with pytest.raises(TypeError, match="radius"):
        splat(rgb, cov, radius=2.5, queue=queue)
    with pytest.raises(ValueError, match="stretch"):
        splat(rgb, cov, stretch=0.5, queue=queue)
    with pytest.raises(ValueError, match="opacity"):
        splat(rgb, cov, opacity=1.5, queue=queue)
    bad = rgb.copy()
    bad[np.argwhere(cov)[0][0], np.argwhere(cov)[0][1], 1] = np.inf
    with pytest.raises(DataError, match="rgb: NaN or infinite"):
        splat(bad, cov, queue=queue)
    bad[~cov] = np.nan  # uncovered: never read
    bad[cov] = 0.5
    splat(bad, cov, queue=queue)
    vel[cov] = np.nan
    with pytest.raises(DataError, match="vel: NaN or infinite"):
        splat(rgb, cov, vel, queue=queue)
    with pytest.raises(DataError, match="empty"):
        splat(rgb[:0], cov[:0], queue=queue)
