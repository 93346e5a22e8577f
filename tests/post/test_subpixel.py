"""clvis.post.subpixel (kernels_cl/post/subpixel.cl) against
clvis.reference.post.subpixel on every device and tuning profile, with and
without the volume score, its limits (weight 1: the input's colours
exactly; weight 0, a full volume score and empty windows: the network's
output exactly), the in-place device call PostNetwork makes, the shipped
narvis network with the rule off and on, and bad input.

Tolerance: 1e-5 absolute on [0, 1] colours (the kernel's fixed-point window
sums and float32 ratios against float64)."""

import numpy as np
import pyopencl.array as cla
import pytest

from clvis import post
from clvis.post.subpixel import subpixel_blend
from clvis.reference.post.subpixel import colour_noise, subpixel_weight
from clvis.reference.post.subpixel import subpixel_blend as ref_blend

ATOL = 1e-5
RC = 5  # the radius plane's channel in these tests' planes
DC = 4  # the depth plane's
#: a volume score that these inputs' windows span: colour noise 0.2..0.5
#: (3 channels of uniform colours: ~1 between any two pixels, less where
#: the depth layers keep few neighbours), coverage fraction 0.3..0.8
VOL = (0.005, 0.2, 0.5, 0.3, 0.8)


def inputs(shape, seed, covered=0.5, rmax=1.0):
    rng = np.random.default_rng(seed)
    h, w = shape
    x = rng.random((1, 6, h, w), dtype=np.float32)
    # coverage and colour noise ramp down the image, so windows span the volume score
    cov = rng.random((h, w)) < covered * (0.5 + np.linspace(0, 1, h)[:, None])
    x[0, 3] = cov
    x[0, :3] *= cov * np.linspace(0.2, 1.0, h)[:, None].astype(np.float32)
    # a ramp across the image (so every window's mean spans lo..hi) with noise
    ramp = np.linspace(0.0, rmax, w)[None, :] + 0.2 * rng.random((h, w))
    x[0, RC] = (ramp * cov).astype(np.float32)
    # depth layers: neighbours at one depth (0), 0.1 % apart (within tau = 0.5 %) or 10 % (not)
    x[0, DC] = ((10 + rng.choice([0.0, 0.01, 1.0], (h, w))) * cov).astype(np.float32)
    img = rng.random((1, 3, h, w), dtype=np.float32)
    return x, img


@pytest.mark.parametrize("volume", [None, VOL], ids=["sigma", "volume"])
@pytest.mark.parametrize("reach", [0, 3, 8])
@pytest.mark.parametrize("shape", [(16, 16), (37, 53), (64, 24), (5, 90)], ids=str)
def test_kernel_equals_reference(queue, shape, reach, volume):
    x, img = inputs(shape, seed=sum(shape) + reach)
    got = subpixel_blend(
        x, img, radius_channel=RC, lo=0.2, hi=0.6, reach=reach, depth_channel=DC, volume=volume, queue=queue
    )
    want = ref_blend(x, img, RC, 0.2, 0.6, reach, DC, volume)
    assert isinstance(got, np.ndarray) and got.dtype == np.float32 and got.shape == (1, 3) + shape
    np.testing.assert_allclose(got, want, atol=ATOL, rtol=0)
    w = subpixel_weight(x, RC, 0.2, 0.6, reach, DC, volume)
    assert 0 < (w > 0).mean() < 1 and ((w > 0) & (w < 1)).any()  # the ramp is exercised
    if volume is not None and 0 < reach and 2 * reach + 1 < min(shape):
        # the volume score is exercised: it lowers some weights, not all
        ws = subpixel_weight(x, RC, 0.2, 0.6, reach)
        held = w < ws - 1e-3
        assert held.any() and ((w > 1e-3) & held).any() and (~held & (ws > 0)).any()


def test_colour_noise_reference():
    """The reference's colour noise on a 3 x 3 patch worked by hand: the
    centre's neighbours within tau of its depth, the mean of their
    colour distances; a pixel with none has v = 0."""
    x = np.zeros((1, 6, 3, 3), np.float32)
    x[0, 3] = 1
    x[0, 3, 0, 0] = 0  # uncovered: not a neighbour
    x[0, DC] = 10.0
    x[0, DC, 2, 2] = 12.0  # 20 % deeper: not a neighbour of anyone
    x[0, 0] = [[0.0, 0.3, 0.0], [0.1, 0.5, 0.0], [0.0, 0.0, 0.9]]
    q, v = colour_noise(x, DC, 0.005)
    # centre (R = 0.5, G = B = 0): neighbours (0,1) (0,2) (1,0) (1,2) (2,0) (2,1):
    # |0.5 - 0.3| + |0.5 - 0.1| + 4 x 0.5 = 2.6 over 6
    assert q[1, 1] == pytest.approx(2.6 / 6)
    assert v[2, 2] == 0 and q[2, 2] == 0 and v[0, 0] == 0
    assert v[1, 1] == 1 and v[0, 1] == 1


def test_limits(queue):
    """Every sigma <= lo: the input's colours exactly (uncovered pixels
    black); every sigma >= hi, or no coverage: the network's output exactly."""
    x, img = inputs((24, 40), seed=1)
    small = x.copy()
    small[0, RC] = 0.1 * small[0, 3]
    got = subpixel_blend(small, img, radius_channel=RC, lo=0.2, hi=0.6, queue=queue)
    # every window with a covered pixel takes the raster; an empty window keeps the network
    n = subpixel_weight(small, RC, 0.2, 0.6, 8)
    assert (n == 1).mean() > 0.99
    np.testing.assert_array_equal(got[0][:, n == 1], x[0, :3][:, n == 1])
    big = x.copy()
    big[0, RC] = 0.6 * big[0, 3] + 2.0
    np.testing.assert_array_equal(
        subpixel_blend(big, img, radius_channel=RC, lo=0.2, hi=0.6, queue=queue), img
    )
    empty = x.copy()
    empty[0, 3] = 0
    np.testing.assert_array_equal(
        subpixel_blend(empty, img, radius_channel=RC, lo=0.2, hi=0.6, queue=queue), img
    )


def test_volume_limits(queue):
    """Every window a volume (full coverage, one depth, colours that differ
    by far more than c_hi): the network's output exactly, however small the
    sigma; a volume score that never starts (c_lo above any colour noise):
    the sigma rule exactly."""
    x, img = inputs((24, 40), seed=4)
    x[0, 3] = 1
    x[0, :3] = np.random.default_rng(4).random((3, 24, 40))
    x[0, DC] = 10.0
    x[0, RC] = 0.1
    kw = dict(radius_channel=RC, lo=0.2, hi=0.6, depth_channel=DC, queue=queue)
    np.testing.assert_array_equal(subpixel_blend(x, img, volume=(0.005, 0.1, 0.2, 0.5, 0.9), **kw), img)
    np.testing.assert_array_equal(subpixel_blend(x, img, volume=(0.005, 3.0, 3.5, 0.5, 0.9), **kw), x[:, :3])
    yy, xx = np.mgrid[:24, :40]
    x[0, DC] = 10 * (1 + 0.1 * (xx % 3 + 3 * (yy % 3)))  # every neighbour 5 % or more apart: V = 0, C = 0
    np.testing.assert_array_equal(subpixel_blend(x, img, volume=(0.005, 0.1, 0.2, 0.5, 0.9), **kw), x[:, :3])


def test_device_in_place(queue):
    """PostNetwork's call: device planes, the output blended where it lies."""
    x, img = inputs((32, 48), seed=2)
    want = ref_blend(x, img, RC, 0.2, 0.6, 8, DC, VOL)
    d_x, d_img = cla.to_device(queue, x), cla.to_device(queue, img)
    got = subpixel_blend(
        d_x, d_img, radius_channel=RC, lo=0.2, hi=0.6, depth_channel=DC, volume=VOL, out=d_img, queue=queue
    )
    assert got is d_img
    np.testing.assert_allclose(d_img.get(), want, atol=ATOL, rtol=0)
    d_img2 = cla.to_device(queue, img)
    got2 = subpixel_blend(
        d_x, d_img2, radius_channel=RC, lo=0.2, hi=0.6, depth_channel=DC, volume=VOL, queue=queue
    )
    assert isinstance(got2, cla.Array)
    np.testing.assert_allclose(got2.get(), want, atol=ATOL, rtol=0)
    np.testing.assert_array_equal(d_img2.get(), img)  # the input left as it was


def test_shipped_narvis_rule_off_and_on():
    """A sub-pixel view (the storm's 30 k particles at 96 x 64 are not: its
    radius plane is scaled down to a quarter of a pixel here): with the rule
    on, the picture is the rule's blend of the network's own output."""
    from clvis.post.names import gbuffer_channels
    from clvis.training import data

    net = post.load("narvis")
    assert net.subpixel and not post.load("narvis-scan").subpixel
    sc = data.narvis_scene("storm", 30_000, 9)
    cam = data.narvis_cameras(sc, "hemisphere", 1.5)[45]
    sc.cloud.radius = sc.cloud.radius * np.float32(0.05)
    g = sc.gbuffers(sc.rasterizer(), cam, 96, 64, net.planes)
    net.subpixel = False
    raw = net.infer(g)
    net.subpixel = True
    on = net.infer(g)
    from clvis.reference.post import pack as ref

    x = ref.pack_gbuffers(g, net.planes, stride=net.stride)
    rc = gbuffer_channels(net.planes).index("radius_px")
    dc = gbuffer_channels(net.planes).index("depth")
    assert np.median(x[0, rc][x[0, 3] > 0]) < net.spec.subpixel[0]
    assert net.spec.subpixel_volume is not None
    want = ref_blend(x, raw, rc, *net.spec.subpixel, dc, net.spec.subpixel_volume)
    np.testing.assert_allclose(on, want, atol=ATOL, rtol=0)
    assert np.abs(on - raw).max() > 0.1


def test_bad_input():
    x, img = inputs((16, 16), seed=3)
    with pytest.raises(ValueError, match="radius_channel"):
        subpixel_blend(x, img, radius_channel=6, lo=0.2, hi=0.6)
    with pytest.raises(ValueError, match="radius_channel"):
        subpixel_blend(x, img, radius_channel=2, lo=0.2, hi=0.6)
    with pytest.raises(TypeError, match="radius_channel"):
        subpixel_blend(x, img, radius_channel=5.0, lo=0.2, hi=0.6)
    with pytest.raises(ValueError, match="lo, hi"):
        subpixel_blend(x, img, radius_channel=RC, lo=0.6, hi=0.6)
    with pytest.raises(ValueError, match="lo, hi"):
        subpixel_blend(x, img, radius_channel=RC, lo=float("nan"), hi=0.6)
    with pytest.raises(ValueError, match="reach"):
        subpixel_blend(x, img, radius_channel=RC, lo=0.2, hi=0.6, reach=-1)
    with pytest.raises(ValueError, match="image"):
        subpixel_blend(x, img[:, :, :8], radius_channel=RC, lo=0.2, hi=0.6)
    with pytest.raises(ValueError, match="planes"):
        subpixel_blend(x[:, :4], img, radius_channel=RC, lo=0.2, hi=0.6)
    with pytest.raises(TypeError, match="planes"):
        subpixel_blend(x.astype(np.float64), img, radius_channel=RC, lo=0.2, hi=0.6)
    with pytest.raises(ValueError, match="depth_channel"):
        subpixel_blend(x, img, radius_channel=RC, lo=0.2, hi=0.6, volume=VOL)
    with pytest.raises(ValueError, match="depth_channel"):
        subpixel_blend(x, img, radius_channel=RC, lo=0.2, hi=0.6, depth_channel=RC, volume=VOL)
    with pytest.raises(ValueError, match="depth_channel"):
        subpixel_blend(x, img, radius_channel=RC, lo=0.2, hi=0.6, depth_channel=6, volume=VOL)
    with pytest.raises(TypeError, match="depth_channel"):
        subpixel_blend(x, img, radius_channel=RC, lo=0.2, hi=0.6, depth_channel=4.0, volume=VOL)
    for bad in (
        (0.005, 0.2, 0.5, 0.3),
        (0.005, 0.5, 0.2, 0.3, 0.8),
        (-1, 0.2, 0.5, 0.3, 0.8),
        (0.005, 0.2, 0.5, 0.3, float("inf")),
        "abcde",
    ):
        with pytest.raises(ValueError, match="volume"):
            subpixel_blend(x, img, radius_channel=RC, lo=0.2, hi=0.6, depth_channel=DC, volume=bad)
