"""clvis.post.pack against clvis.reference.post.pack, out= arrays (a host-backed
ALLOC_HOST_PTR buffer mapped to numpy included) and bad input.

Tolerance: exact everywhere. Packing copies values; the depth normalisation
is one float32 subtraction and one correctly rounded division on both sides
(FP_CONTRACT OFF), so the kernels give the reference's bits."""

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest
from hypothesis import given
from hypothesis import strategies as st

import clvis
from clvis.errors import ClvisError, DataError
from clvis.post import pack as pack_module
from clvis.post.pack import pack_iso, pack_rgbda, padded_shape, unpack_rgba8
from clvis.reference.post import pack as ref

SHAPES = [(1, 1), (1, 9), (9, 1), (3, 5), (17, 33), (37, 53)]
STRIDES = [1, 8, 16]


def iso_inputs(shape, seed):
    rng = np.random.default_rng(seed)
    rgba = rng.uniform(-0.5, 1.5, shape + (4,)).astype(np.float32)
    hit = rng.random(shape) < 0.6
    active = rng.random(shape) < 0.2
    rgba[~hit] = np.nan  # colours of pixels not hit are never read
    return rgba, hit, active


def rgbda_inputs(shape, seed, kept=0.6):
    rng = np.random.default_rng(seed)
    x = np.zeros(shape + (5,), np.float32)
    keep = rng.random(shape) < kept
    x[..., :3] = np.where(keep[..., None], rng.random(shape + (3,)), 0)
    x[..., 3] = np.where(keep, rng.uniform(0.5, 80.0, shape), np.inf)
    x[..., 4] = keep
    return x


def mirrored(t, h, w):
    """The padding (rows >= h, columns >= w) is the image reflected about its
    last row and column, again and again (period 2n): numpy.pad's
    "symmetric", written out here."""

    def m(i, n):
        j = i % (2 * n)
        return j if j < n else 2 * n - 1 - j

    rows = [m(i, h) for i in range(t.shape[-2])]
    cols = [m(i, w) for i in range(t.shape[-1])]
    np.testing.assert_array_equal(t, t[..., rows, :][..., cols])


def same(got, want):
    assert isinstance(got, np.ndarray) and got.dtype == want.dtype and got.shape == want.shape
    np.testing.assert_array_equal(got, want)
    assert got.tobytes() == want.tobytes()  # signs of zeros too


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("stride", STRIDES)
def test_pack_iso(queue, shape, stride):
    rgba, hit, active = iso_inputs(shape, seed=hash((shape, stride)) % 2**32)
    got = pack_iso(rgba, hit, active, stride=stride, queue=queue)
    want = ref.pack_iso(rgba, hit, active, stride=stride)
    same(got, want)
    hp, wp = padded_shape(*shape, stride)
    assert got.shape == (1, 5, hp, wp) and hp % stride == 0 and wp % stride == 0
    # in-fill: padding as finished rays that missed (the W-Net measured best so)
    assert not got[:, :, shape[0] :].any() and not got[:, :, :, shape[1] :].any()
    same(pack_iso(rgba, hit.astype(np.uint8) * 3, active.astype(np.uint8), stride=stride, queue=queue), want)


@pytest.mark.parametrize("shape", [(1, 1), (17, 33), (37, 53)])
@pytest.mark.parametrize("stride", [1, 16])
def test_pack_iso_candidates(queue, shape, stride):
    """The sixth channel: min(candidates, 8) / 8 where active, else 0 (every
    count 0..255, on running and finished pixels), the first five as without
    it; numpy, device and out= inputs."""
    rgba, hit, active = iso_inputs(shape, seed=hash((shape, stride, 6)) % 2**32)
    cand = np.random.default_rng(5).integers(0, 256, shape).astype(np.uint8)
    cand.ravel()[: min(cand.size, 12)] = np.arange(min(cand.size, 12))  # 0..11 around the cap
    got = pack_iso(rgba, hit, active, candidates=cand, stride=stride, queue=queue)
    want = ref.pack_iso(rgba, hit, active, candidates=cand, stride=stride)
    same(got, want)
    hp, wp = padded_shape(*shape, stride)
    assert got.shape == (1, 6, hp, wp)
    assert pack_module.CANDIDATES_CAP == ref.CANDIDATES_CAP == clvis.iso.CANDIDATES
    same(got[:, :5], ref.pack_iso(rgba, hit, active, stride=stride))
    c = got[0, 5, : shape[0], : shape[1]]
    want_c = np.where(active, np.minimum(cand, 8) / np.float32(8), 0).astype(np.float32)
    np.testing.assert_array_equal(c, want_c)
    assert not got[0, 5, shape[0] :].any() and not got[0, 5, :, shape[1] :].any()
    out = cla.empty(queue, want.shape, np.float32)
    dev = pack_iso(rgba, hit, active, candidates=cla.to_device(queue, cand), stride=stride, out=out)
    assert dev is out
    same(out.get(), want)
    with pytest.raises(TypeError, match="candidates: dtype"):
        pack_iso(rgba, hit, active, candidates=cand.astype(np.int32), queue=queue)
    with pytest.raises(ValueError, match="candidates: shape"):
        pack_iso(rgba, hit, active, candidates=cand[:, :0], queue=queue)


@pytest.mark.parametrize("shape", [(1, 1), (17, 33), (37, 53)])
@pytest.mark.parametrize("rate", [0.0, 0.2, 1 / 3, 0.5, 0.97, 1.0])
@pytest.mark.parametrize("stride", [1, 16])
def test_pack_iso_prior(queue, shape, rate, stride):
    """The seventh channel: 1 - (1 - rate)^min(candidates, 8) where active
    (the power as k float32 products in order), else 0, bit for bit; the
    first six as without it; numpy, device and out= inputs."""
    rgba, hit, active = iso_inputs(shape, seed=hash((shape, rate, 7)) % 2**32)
    cand = np.random.default_rng(7).integers(0, 256, shape).astype(np.uint8)
    cand.ravel()[: min(cand.size, 12)] = np.arange(min(cand.size, 12))  # 0..11 around the cap
    got = pack_iso(rgba, hit, active, candidates=cand, crossing_rate=rate, stride=stride, queue=queue)
    want = ref.pack_iso(rgba, hit, active, candidates=cand, crossing_rate=rate, stride=stride)
    same(got, want)
    assert got.shape[1] == 7
    same(got[:, :6], ref.pack_iso(rgba, hit, active, candidates=cand, stride=stride))
    prior = got[0, 6, : shape[0], : shape[1]]
    k = np.minimum(cand, 8).astype(np.float64)
    np.testing.assert_allclose(prior, np.where(active, 1 - (1 - rate) ** k, 0), atol=2e-7)
    assert (prior[~active] == 0).all()
    assert not got[0, 6, shape[0] :].any() and not got[0, 6, :, shape[1] :].any()
    if rate in (0.0, 1.0):  # no chance to cross: 0; certain: 1 wherever a block is left
        np.testing.assert_array_equal(prior, np.where(active & (cand > 0), np.float32(rate), 0))
    out = cla.empty(queue, want.shape, np.float32)
    dev = pack_iso(
        cla.to_device(queue, rgba),
        hit,
        active,
        candidates=cla.to_device(queue, cand),
        crossing_rate=np.float32(rate),
        stride=stride,
        out=out,
    )
    assert dev is out
    same(out.get(), want)


@pytest.mark.parametrize("shape", [(1, 1), (3, 5), (17, 33), (37, 53)])
@pytest.mark.parametrize("stride", [1, 16])
@pytest.mark.parametrize("kind", ["mixed", "none", "one value"])
def test_pack_iso_depth(queue, shape, stride, kind):
    """The seventh and eighth channels: the finished hits' t and the running
    rays' next_t on one [0, 1] scale over the frame's finite values of both
    (a reduction on the device), 0 elsewhere; no finite value or a single
    one: 0 everywhere. Bit for bit; the first six as without them; numpy,
    device and out= inputs."""
    rgba, hit, active = iso_inputs(shape, seed=hash((shape, stride, 8)) % 2**32)
    rng = np.random.default_rng(8)
    cand = rng.integers(0, 12, shape).astype(np.uint8)
    t = rng.uniform(-3.0, 40.0, shape).astype(np.float32)
    nxt = rng.uniform(0.5, 60.0, shape).astype(np.float32)
    flat = t.ravel(), nxt.ravel()
    for a in flat:  # a few non-finite values, never in the range
        a[::7] = np.inf
        a[3::11] = np.nan
    if kind == "none":
        t[:], nxt[:] = np.inf, np.nan
    elif kind == "one value":
        t[:], nxt[:] = np.float32(2.5), np.float32(2.5)
    got = pack_iso(rgba, hit, active, candidates=cand, depth=(t, nxt), stride=stride, queue=queue)
    want = ref.pack_iso(rgba, hit, active, candidates=cand, depth=(t, nxt), stride=stride)
    same(got, want)
    assert got.shape[1] == 8
    same(got[:, :6], ref.pack_iso(rgba, hit, active, candidates=cand, stride=stride))
    d, n = got[0, 6, : shape[0], : shape[1]], got[0, 7, : shape[0], : shape[1]]
    done, run = hit & ~active & np.isfinite(t), active & np.isfinite(nxt)
    assert not d[~done].any() and not n[~run].any()
    assert not got[0, 6:, shape[0] :].any() and not got[0, 6:, :, shape[1] :].any()
    vals = np.concatenate([t[done], nxt[run]]).astype(np.float64)
    if kind == "mixed" and vals.size > 1 and np.ptp(vals) > 0:
        np.testing.assert_allclose(d[done], (t[done] - vals.min()) / np.ptp(vals), atol=1e-6)
        np.testing.assert_allclose(n[run], (nxt[run] - vals.min()) / np.ptp(vals), atol=1e-6)
        assert min(d[done].min(initial=1), n[run].min(initial=1)) == 0
        assert max(d[done].max(initial=0), n[run].max(initial=0)) == 1
    else:
        assert not got[0, 6:].any()
    out = cla.empty(queue, want.shape, np.float32)
    dev = pack_iso(
        cla.to_device(queue, rgba),
        hit,
        active,
        candidates=cand,
        depth=(cla.to_device(queue, t), nxt),
        stride=stride,
        out=out,
    )
    assert dev is out
    same(out.get(), want)


def test_pack_iso_depth_bad_input(queue):
    rgba, hit, active = iso_inputs((4, 5), seed=3)
    cand = np.ones((4, 5), np.uint8)
    t = np.ones((4, 5), np.float32)
    with pytest.raises(ValueError, match="depth: the depth planes come after the candidates plane"):
        pack_iso(rgba, hit, active, depth=(t, t), queue=queue)
    with pytest.raises(ValueError, match="depth: the depth planes come after the candidates plane"):
        pack_iso(rgba, hit, active, candidates=cand, crossing_rate=0.5, depth=(t, t), queue=queue)
    with pytest.raises(TypeError, match="depth: expected a pair"):
        pack_iso(rgba, hit, active, candidates=cand, depth=t, queue=queue)
    with pytest.raises(TypeError, match=r"depth\[1\] \(next_t\): dtype"):
        pack_iso(rgba, hit, active, candidates=cand, depth=(t, t.astype(np.float64)), queue=queue)
    with pytest.raises(ValueError, match=r"depth\[0\] \(t\): shape"):
        pack_iso(rgba, hit, active, candidates=cand, depth=(t[:3], t), queue=queue)


def test_pack_iso_prior_bad_input(queue):
    rgba, hit, active = iso_inputs((5, 7), seed=3)
    cand = np.ones((5, 7), np.uint8)
    for bad in (-0.01, 1.01, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="crossing_rate: expected a number in"):
            pack_iso(rgba, hit, active, candidates=cand, crossing_rate=bad, queue=queue)
    for bad in (True, "0.5", [0.5]):
        with pytest.raises(TypeError, match="crossing_rate: expected a number"):
            pack_iso(rgba, hit, active, candidates=cand, crossing_rate=bad, queue=queue)
    with pytest.raises(ValueError, match="needs candidates"):
        pack_iso(rgba, hit, active, crossing_rate=0.5, queue=queue)
    with pytest.raises(ValueError, match="needs candidates"):
        ref.pack_iso(rgba, hit, active, crossing_rate=0.5)


def test_crossing_rate(queue):
    """Finished hits per candidate block tested, at most 1, 0 with none
    tested; host and device masks; bad counts and shapes named."""
    hit = np.array([[1, 1, 0, 1], [0, 1, 1, 0]], bool)
    active = np.array([[0, 1, 0, 0], [0, 0, 1, 1]], bool)  # finished hits: 3
    assert pack_module.crossing_rate(hit, active, 12) == 0.25
    assert pack_module.crossing_rate(hit.astype(np.uint8) * 7, active.astype(np.uint8), 12) == 0.25
    assert pack_module.crossing_rate(cla.to_device(queue, hit.view(np.uint8)), active, 6) == 0.5
    assert pack_module.crossing_rate(hit, active, 2) == 1.0  # more hits than tests counted: clipped
    assert pack_module.crossing_rate(hit, active, 0) == 0.0
    with pytest.raises(ValueError, match="tested: expected a count >= 0"):
        pack_module.crossing_rate(hit, active, -1)
    for bad in (2.5, True, None, "4"):
        with pytest.raises(TypeError, match="tested: expected an integer"):
            pack_module.crossing_rate(hit, active, bad)
    with pytest.raises(ValueError, match="active: shape"):
        pack_module.crossing_rate(hit, active[:, :3], 4)
    with pytest.raises(TypeError, match="hit: dtype"):
        pack_module.crossing_rate(np.where(hit, 1.0, np.nan), active, 4)  # NaN would count as a hit
    with pytest.raises(ValueError, match="active"):
        pack_module.crossing_rate(hit, active[None], 4)


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("stride", STRIDES)
def test_pack_rgbda(queue, shape, stride):
    x = rgbda_inputs(shape, seed=hash((shape, stride)) % 2**32)
    got = pack_rgbda(x, stride=stride, queue=queue)
    want = ref.pack_rgbda(x, stride=stride)
    same(got, want)
    kept = x[..., 4] > 0
    d = got[0, 4, : shape[0], : shape[1]]
    if kept.sum() > 1:
        assert d[kept].min() == 0 and d[kept].max() == 1
    assert (d[~kept] == -1).all()
    mirrored(got, *shape)


def test_pack_rgbda_adversarial(queue):
    x = rgbda_inputs((23, 31), seed=3)
    # negative depths, zeros of both signs, extremes, alpha > 0 with +inf depth (empty)
    x[0, 0, 3:] = (-5.0, 1.0)
    x[0, 1, 3:] = (-0.0, 1.0)
    x[0, 2, 3:] = (0.0, 1.0)
    x[0, 3, 3:] = (np.inf, 1.0)
    x[0, 4, 3:] = (3e38, 0.5)
    x[0, 5, 3:] = (7.0, 0.0)  # alpha 0: empty whatever the depth
    x[1, 0, 3:] = (-np.inf, 0.0)
    same(pack_rgbda(x, queue=queue), ref.pack_rgbda(x))
    # one kept pixel; every kept depth equal: D = 0
    for depth in (4.0, -0.0):
        y = np.zeros((9, 11, 5), np.float32)
        y[..., 3] = np.inf
        y[2:5, 3, 3:] = (depth, 1.0)
        got = pack_rgbda(y, stride=8, queue=queue)
        same(got, ref.pack_rgbda(y, stride=8))
        assert (got[0, 4, 2:5, 3] == 0).all() and (got[0, 3, 2:5, 3] == 1).all()
    # no kept pixel at all: every pixel empty, not an error
    y[..., 4] = 0
    got = pack_rgbda(y, stride=16, queue=queue)
    same(got, ref.pack_rgbda(y, stride=16))
    assert not got[0, :4].any() and (got[0, 4] == -1).all()


def test_pack_large(queue):
    x = rgbda_inputs((720, 1280), seed=5)
    same(pack_rgbda(x, stride=16, queue=queue), ref.pack_rgbda(x, stride=16))
    rgba, hit, active = iso_inputs((721, 1279), seed=6)
    same(pack_iso(rgba, hit, active, stride=16, queue=queue), ref.pack_iso(rgba, hit, active, stride=16))
    # unpack's work-items are row segments of ITEMS pixels: a width that is
    # not a multiple of them, many rows
    t = np.random.default_rng(7).uniform(-0.25, 1.25, (1, 4, 736, 1280)).astype(np.float32)
    same(unpack_rgba8(t, 721, 1279, queue=queue), ref.unpack_rgba8(t, 721, 1279))


@pytest.mark.parametrize("channels", [3, 4])
@pytest.mark.parametrize("shape", [(1, 1), (5, 3), (37, 53)])
def test_unpack(queue, channels, shape):
    rng = np.random.default_rng(hash((channels, shape)) % 2**32)
    hp, wp = padded_shape(*shape, 16)
    t = rng.uniform(-0.25, 1.25, (1, channels, hp, wp)).astype(np.float32)
    flat = t.reshape(-1)
    specials = [np.nan, -np.nan, np.inf, -np.inf, 0.5, 0.5 / 255, 1.5 / 255, 2.5 / 255, -0.0, 1.0]
    flat[: len(specials)] = specials
    t[0, :, 0, : min(4, shape[1])] = np.float32(127.5 / 255)
    got = unpack_rgba8(t, *shape, queue=queue)
    want = ref.unpack_rgba8(t, *shape)
    same(got, want)
    assert got.shape == shape + (4,)
    if channels == 3:
        assert (got[..., 3] == 255).all()
    same(unpack_rgba8(t, 1, 1, queue=queue), ref.unpack_rgba8(t, 1, 1))


def test_unpack_rounds_half_to_even(queue):
    # (k + 0.5) / 255 in float32 times 255 gives k + 0.5 exactly for these k
    t = np.zeros((1, 3, 1, 4), np.float32)
    t[0, 0, 0] = np.array([0.5, 1.5, 2.5, 127.5], np.float32) / np.float32(255)
    got = unpack_rgba8(t, 1, 4, queue=queue)
    want = ref.unpack_rgba8(t, 1, 4)
    same(got, want)


def test_round_trip(queue):
    """unpack_rgba8 of a packed image's colour planes gives the colours back."""
    rgba8 = np.random.default_rng(2).integers(0, 256, (19, 23, 4)).astype(np.uint8)
    rgba = (rgba8.astype(np.float32) / np.float32(255)).astype(np.float32)
    hit = np.ones((19, 23), bool)
    packed = pack_iso(rgba, hit, np.zeros_like(hit), stride=8, queue=queue)
    back = unpack_rgba8(packed[:, :3].copy(), 19, 23, queue=queue)
    np.testing.assert_array_equal(back[..., :3], rgba8[..., :3])


def test_device_arrays(queue):
    rgba, hit, active = iso_inputs((21, 13), seed=7)
    got = pack_iso(cla.to_device(queue, rgba), hit, active, stride=8)
    assert isinstance(got, cla.Array) and got.queue is queue
    same(got.get(), ref.pack_iso(rgba, hit, active, stride=8))
    x = rgbda_inputs((21, 13), seed=8)
    got = pack_rgbda(cla.to_device(queue, x), stride=8)
    assert isinstance(got, cla.Array)
    same(got.get(), ref.pack_rgbda(x, stride=8))
    t = got.get()[:, :4].copy()  # R, G, B, A
    back = unpack_rgba8(cla.to_device(queue, t), 21, 13)
    assert isinstance(back, cla.Array) and back.dtype == np.uint8
    same(back.get(), ref.unpack_rgba8(t, 21, 13))


def test_out(queue):
    x = rgbda_inputs((21, 13), seed=9)
    want = ref.pack_rgbda(x, stride=16)
    out = cla.empty(queue, want.shape, np.float32)
    assert pack_rgbda(x, stride=16, out=out, queue=queue) is out
    same(out.get(), want)
    rgba, hit, active = iso_inputs((21, 13), seed=9)
    assert pack_iso(rgba, hit, active, stride=16, out=out, queue=queue) is out
    same(out.get(), ref.pack_iso(rgba, hit, active, stride=16))
    img = cla.empty(queue, (21, 13, 4), np.uint8)
    assert unpack_rgba8(out.get()[:, :3].copy(), 21, 13, out=img) is img
    same(img.get(), ref.unpack_rgba8(out.get()[:, :3], 21, 13))


def test_out_host_mapped(queue):
    """A host-backed buffer (ALLOC_HOST_PTR), as handed to onnxruntime's IO
    binding: after queue.finish() its mapped view holds the result."""
    x = rgbda_inputs((37, 53), seed=10)
    want = ref.pack_rgbda(x, stride=8)
    mf = cl.mem_flags
    b = cl.Buffer(queue.context, mf.READ_WRITE | mf.ALLOC_HOST_PTR, want.nbytes)
    out = cla.Array(queue, want.shape, np.float32, data=b)
    assert pack_rgbda(x, stride=8, out=out, queue=queue) is out
    queue.finish()
    view, _ = cl.enqueue_map_buffer(queue, b, cl.map_flags.READ, 0, want.shape, np.float32)
    try:
        np.testing.assert_array_equal(view, want)
    finally:
        view.base.release(queue)
    queue.finish()
    img = cl.Buffer(queue.context, mf.READ_WRITE | mf.ALLOC_HOST_PTR, 37 * 53 * 4)
    packed = ref.pack_iso(*iso_inputs((37, 53), seed=11), stride=8)
    unpack_rgba8(
        packed[:, :3].copy(), 37, 53, out=cla.Array(queue, (37, 53, 4), np.uint8, data=img), queue=queue
    )
    queue.finish()
    view, _ = cl.enqueue_map_buffer(queue, img, cl.map_flags.READ, 0, (37, 53, 4), np.uint8)
    try:
        np.testing.assert_array_equal(view, ref.unpack_rgba8(packed[:, :3], 37, 53))
    finally:
        view.base.release(queue)


@given(
    h=st.integers(1, 40),
    w=st.integers(1, 40),
    stride=st.sampled_from([1, 2, 8, 16, 32]),
    seed=st.integers(0, 2**16),
    kept=st.sampled_from([0.0, 0.01, 0.5, 1.0]),
)
def test_property(device, h, w, stride, seed, kept):
    q = clvis.runtime.queue_for(device)
    x = rgbda_inputs((h, w), seed, kept)
    got = pack_rgbda(x, stride=stride, queue=q)
    same(got, ref.pack_rgbda(x, stride=stride))
    d = got[0, 4]
    assert ((d == -1) | ((d >= 0) & (d <= 1))).all()
    rgba, hit, active = iso_inputs((h, w), seed)
    same(pack_iso(rgba, hit, active, stride=stride, queue=q), ref.pack_iso(rgba, hit, active, stride=stride))


def test_limits():
    assert pack_module.MAX_SIDE == ref.MAX_SIDE and pack_module.MAX_PIXELS == ref.MAX_PIXELS
    assert padded_shape(1, 1, 16) == (16, 16) and padded_shape(720, 1280, 16) == (720, 1280)
    assert padded_shape(721, 1281, 8) == (728, 1288)


def test_bad_input(device, monkeypatch):
    q = clvis.runtime.queue_for(device)
    rgba, hit, active = iso_inputs((6, 7), seed=1)
    x = rgbda_inputs((6, 7), seed=1)
    with pytest.raises(TypeError, match="rgba: dtype float64"):
        pack_iso(rgba.astype(np.float64), hit, active, queue=q)
    with pytest.raises(ValueError, match="rgba: expected 4 channels"):
        pack_iso(rgba[..., :3], hit, active, queue=q)
    with pytest.raises(ValueError, match="hit: shape"):
        pack_iso(rgba, hit[:5], active, queue=q)
    with pytest.raises(TypeError, match="active: dtype int32"):
        pack_iso(rgba, hit, active.astype(np.int32), queue=q)
    bad = rgba.copy()
    bad[hit.nonzero()[0][0], hit.nonzero()[1][0], 2] = np.inf
    with pytest.raises(DataError, match="rgba: 1 hit pixels with a NaN or infinite"):
        pack_iso(bad, hit, active, queue=q)
    with pytest.raises(DataError):
        ref.pack_iso(bad, hit, active)
    for stride, exc in ((0, ValueError), (-8, ValueError), (1.5, TypeError), (True, TypeError)):
        with pytest.raises(exc, match="stride"):
            pack_rgbda(x, stride=stride, queue=q)
    with pytest.raises(ValueError, match="rgbda: expected 5 channels"):
        pack_rgbda(x[..., :4], queue=q)
    for name, (pix, ch, value) in {
        "nan colour": ((1, 1), 0, np.nan),
        "nan alpha": ((2, 2), 4, np.nan),
        "nan depth": ((0, 0), 3, np.nan),
    }.items():
        y = x.copy()
        y[pix][ch] = value
        with pytest.raises(DataError, match="rgbda: 1 NaN values and 0 pixels") as e:
            pack_rgbda(y, queue=q)
        assert isinstance(e.value, ClvisError), name
        with pytest.raises(DataError):
            ref.pack_rgbda(y)
    y = x.copy()
    y[3, 3, 3:] = (-np.inf, 1.0)
    with pytest.raises(DataError, match="0 NaN values and 1 pixels with alpha > 0 and depth -inf"):
        pack_rgbda(cla.to_device(q, y))
    for shape in [(0, 4), (4, 0)]:
        with pytest.raises(DataError, match="rgbda: empty"):
            pack_rgbda(np.zeros(shape + (5,), np.float32), queue=q)
        with pytest.raises(DataError, match="rgba: empty"):
            pack_iso(
                np.zeros(shape + (4,), np.float32), np.zeros(shape, bool), np.zeros(shape, bool), queue=q
            )
    # the size limits (checked before anything is allocated on the device)
    wide = np.broadcast_to(np.zeros(5, np.float32), (1, 32769, 5))
    with pytest.raises(DataError, match="at most 32768 per side"):
        pack_rgbda(wide, queue=q)
    with monkeypatch.context() as m:
        m.setattr(pack_module, "MAX_PIXELS", 6 * 8 - 1)
        with pytest.raises(DataError, match="\\(6 x 8 padded\\)"):
            pack_rgbda(x, stride=2, queue=q)
        pack_rgbda(x, queue=q)
    with pytest.raises(DataError, match="at most 32768 per side"):
        pack_iso(
            np.broadcast_to(np.zeros(4, np.float32), (1, 32767, 4)),
            np.zeros((1, 32767), bool),
            np.zeros((1, 32767), bool),
            stride=3,  # 32767 padded to 32769
            queue=q,
        )
    # out
    want_shape = (1, 5, 6, 7)
    for out, exc, msg in (
        (np.zeros(want_shape, np.float32), TypeError, "out: expected a pyopencl.array.Array"),
        (cla.empty(q, (1, 5, 6, 8), np.float32), ValueError, "out: expected shape"),
        (cla.empty(q, want_shape, np.float64), ValueError, "out: expected shape"),
        (
            cla.empty(q, (2, 5, 6, 7), np.float32)[1:],
            ValueError,
            "out: expected a C-contiguous array without",
        ),
    ):
        with pytest.raises(exc, match=msg):
            pack_rgbda(x, out=out, queue=q)
    # unpack
    t = np.zeros((1, 4, 8, 8), np.float32)
    with pytest.raises(ValueError, match="nchw: expected shape"):
        unpack_rgba8(np.zeros((2, 4, 8, 8), np.float32), 8, 8, queue=q)
    with pytest.raises(ValueError, match="nchw: expected shape"):
        unpack_rgba8(np.zeros((1, 5, 8, 8), np.float32), 8, 8, queue=q)
    with pytest.raises(ValueError, match="nchw: expected a 4-D array"):
        unpack_rgba8(t[0], 8, 8, queue=q)
    with pytest.raises(TypeError, match="nchw: dtype float16"):
        unpack_rgba8(t.astype(np.float16), 8, 8, queue=q)
    with pytest.raises(ValueError, match="height: 9 is more"):
        unpack_rgba8(t, 9, 8, queue=q)
    with pytest.raises(ValueError, match="width: 9 is more"):
        unpack_rgba8(t, 8, 9, queue=q)
    for v, exc in ((0, ValueError), (2.0, TypeError)):
        with pytest.raises(exc, match="height"):
            unpack_rgba8(t, v, 8, queue=q)
    with pytest.raises(ValueError, match="out: expected shape"):
        unpack_rgba8(t, 8, 8, out=cla.empty(q, (8, 8, 3), np.uint8), queue=q)


# ---------------------------------------------------------------------------
# pack_gbuffers: rasterizer G-buffers for the NARVis U-Net


def gbuffers(shape, seed, covered=0.5, attributes=("temperature",)):
    """Synthetic G-buffers as Rasterizer.render gives them: NaN / +inf /
    EMPTY at empty pixels, finite values at covered ones."""
    from clvis.raster import EMPTY, GBuffers

    rng = np.random.default_rng(seed)
    cov = rng.random(shape) < covered
    index = np.where(cov, rng.integers(0, 1000, shape), EMPTY).astype(np.uint32)
    rgba = np.where(cov[..., None], rng.integers(0, 256, shape + (4,)), 0).astype(np.uint8)
    nan = np.float32(np.nan)
    depth = np.where(cov, rng.uniform(1, 500, shape), np.inf).astype(np.float32)
    vel = np.where(cov[..., None], rng.normal(0, 30, shape + (2,)), nan).astype(np.float32)
    angle = np.where(cov, np.arctan2(vel[..., 1], vel[..., 0]), nan).astype(np.float32)
    speed = np.where(cov, np.hypot(vel[..., 0], vel[..., 1]), nan).astype(np.float32)
    attrs = {a: np.where(cov, rng.uniform(200, 300, shape), nan).astype(np.float32) for a in attributes}
    attrs["class"] = np.where(cov, rng.integers(1, 9, shape), 0).astype(np.uint8)
    radius = np.where(cov, rng.uniform(0.2, 12, shape), nan).astype(np.float32)
    return GBuffers(index, depth, rgba, attrs, vel, angle, speed, radius)


GBUFFER_SELECTIONS = [
    ("rgb",),
    ("rgb", "depth", "vel2d"),
    ("rgb", "vel2d", "temperature", "class", "depth"),
    ("rgb", "depth", "radius"),  # narvis-scan's
    ("rgb", "class", "radius", "vel2d"),
]


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("stride", STRIDES)
@pytest.mark.parametrize("planes", GBUFFER_SELECTIONS, ids=["-".join(p) for p in GBUFFER_SELECTIONS])
def test_pack_gbuffers(queue, shape, stride, planes):
    from clvis.post import pack_gbuffers
    from clvis.post.names import gbuffer_channels

    g = gbuffers(shape, seed=hash((shape, stride, planes)) % 2**32)
    got = pack_gbuffers(g, planes, stride=stride, queue=queue)
    want = ref.pack_gbuffers(g, planes, stride=stride)
    same(got, want)
    hp, wp = padded_shape(*shape, stride)
    assert got.shape == (1, len(gbuffer_channels(planes)), hp, wp)
    cov = g.index != 0xFFFFFFFF
    np.testing.assert_array_equal(got[0, 3, : shape[0], : shape[1]], cov)
    assert not got[0, :, : shape[0], : shape[1]][:, ~cov].any()  # empty pixels are 0 in every channel
    mirrored(got, *shape)  # the padding: the image reflected past its edge
    if "vel2d" in planes:
        c = gbuffer_channels(planes).index("vel_speed")
        np.testing.assert_array_equal(got[0, c, : shape[0], : shape[1]][cov], g.vel_speed[cov])
    if "radius" in planes:  # after the velocity, before the attributes, whatever the order given
        layout = gbuffer_channels(planes)
        c = layout.index("radius_px")
        assert layout[: c + 1][-1] == "radius_px" and not {"class", "temperature"} & set(layout[:c])
        np.testing.assert_array_equal(got[0, c, : shape[0], : shape[1]][cov], g.radius_px[cov])


def test_pack_gbuffers_radius_plane_of_a_scan(queue):
    """narvis-scan's planes from a real render of a scan cloud whose radius is
    knn_sigma: the radius channel is the resolve's radius_px (the world
    radius x focal / depth), device planes as host ones."""
    from clvis.post import pack_gbuffers
    from clvis.post.names import SCAN_GBUFFER_PLANES, gbuffer_channels
    from clvis.training import data

    sc = data.scan_scene("town", 20_000, 3)
    cam = data.scan_cameras(sc, np.random.default_rng(0), 1, 75 / 41)[0]
    ras = sc.rasterizer(queue=queue)
    host = sc.gbuffers(ras, cam, 75, 41, SCAN_GBUFFER_PLANES)
    dev = sc.gbuffers(ras, cam, 75, 41, SCAN_GBUFFER_PLANES, host=False)
    cov = host.covered
    assert cov.mean() > 0.05
    want = ref.pack_gbuffers(host, SCAN_GBUFFER_PLANES, stride=16)
    same(pack_gbuffers(dev, SCAN_GBUFFER_PLANES, stride=16, queue=queue).get(), want)
    assert gbuffer_channels(SCAN_GBUFFER_PLANES) == ["r", "g", "b", "coverage", "depth", "radius_px"]
    # radius_px = knn_sigma of the winning point x the focal length in pixels / its depth
    focal = cam.focal_px(41)
    r = sc.cloud.radius[host.index[cov]] * focal / host.depth[cov]
    np.testing.assert_allclose(want[0, 5, :41, :75][cov], r, rtol=1e-4)


def test_pack_gbuffers_from_the_rasterizer_on_the_device(queue):
    """host=False G-buffers (device arrays) in, a device array out, the same
    values as the numpy ones; into a mapped ALLOC_HOST_PTR out= too."""
    from clvis.post import pack_gbuffers
    from clvis.training import data

    sc = data.narvis_scene("hurricane", 20_000, 1)
    ras = sc.rasterizer(queue=queue)
    cam = data.narvis_cameras(sc, "hemisphere", 75 / 41)[20]
    planes = ("rgb", "depth", "vel2d", "pressure")
    host = sc.gbuffers(ras, cam, 75, 41, planes)
    dev = sc.gbuffers(ras, cam, 75, 41, planes, host=False)
    want = ref.pack_gbuffers(host, planes, stride=16)
    assert host.covered.mean() > 0.05
    got = pack_gbuffers(dev, planes, stride=16, queue=queue)
    assert isinstance(got, cla.Array)
    same(got.get(), want)
    flags = cl.mem_flags.READ_WRITE | cl.mem_flags.ALLOC_HOST_PTR
    out = cla.Array(queue, want.shape, np.float32, data=cl.Buffer(queue.context, flags, want.nbytes))
    assert pack_gbuffers(host, planes, stride=16, out=out, queue=queue) is out
    same(out.get(), want)


def test_pack_gbuffers_bad_input(queue):
    from clvis.post import pack_gbuffers

    g = gbuffers((9, 13), 1)
    no_vel = gbuffers((9, 13), 1)
    no_vel.vel2d = no_vel.vel_angle = no_vel.vel_speed = None
    with pytest.raises(DataError, match="vel2d.*no velocity"):
        pack_gbuffers(no_vel, ("rgb", "vel2d"), queue=queue)
    no_radius = gbuffers((9, 13), 1)
    no_radius.radius_px = None
    with pytest.raises(DataError, match="'radius' plane.*no radius"):
        pack_gbuffers(no_radius, ("rgb", "depth", "radius"), queue=queue)
    with pytest.raises(DataError, match="no attribute plane 'pressure'.*temperature"):
        pack_gbuffers(g, ("rgb", "pressure"), queue=queue)
    with pytest.raises(ValueError, match="lacks 'rgb'"):
        pack_gbuffers(g, ("depth",), queue=queue)
    with pytest.raises(TypeError, match="GBuffers"):
        pack_gbuffers(np.zeros((9, 13, 5), np.float32), queue=queue)
    bad = gbuffers((9, 13), 1)
    cov = bad.index != 0xFFFFFFFF
    bad.depth[np.argwhere(cov)[0][0], np.argwhere(cov)[0][1]] = np.nan
    with pytest.raises(DataError, match="depth: 1 covered pixels with a NaN"):
        pack_gbuffers(bad, ("rgb", "depth"), queue=queue)
    short = gbuffers((9, 13), 1)
    short.depth = short.depth[:8]
    with pytest.raises(ValueError, match=r"depth: expected shape \(9, 13\)"):
        pack_gbuffers(short, ("rgb", "depth"), queue=queue)
    with pytest.raises(ClvisError):
        pack_gbuffers(gbuffers((0, 4), 1), queue=queue)
