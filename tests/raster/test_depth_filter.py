"""clvis.raster.depth_filter against clvis.reference.raster.depth_filter (exact), plus the
filter's meaning on a synthetic scene and its bad-input errors."""

import inspect

import numpy as np
import pyopencl.array as cla
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import clvis
from clvis.raster.depth_filter import depth_filter_mask, level_shapes, rgbda
from clvis.reference.raster import depth_filter as ref

# the module: clvis.raster's depth_filter attribute is the function of that name

INF = np.float32(np.inf)


def layered(shape, density, seed, layers=(2.0, 5.0, 20.0), noise=0.01):
    """Sparse depth: each pixel on one of a few noisy layers, present with
    probability `density` (+inf elsewhere)."""
    rng = np.random.default_rng(seed)
    base = np.asarray(layers, np.float32)[rng.integers(0, len(layers), shape)]
    d = base * (1 + noise * rng.standard_normal(shape)).astype(np.float32)
    return np.where(rng.random(shape) < density, d, INF).astype(np.float32)


def scene(h, w, hole_fraction, seed, noise=0.002):
    """A near plane (depth 5, a rectangle with random holes) over a far plane
    (depth 10, dense). Returns depth, the rectangle (y0, y1, x0, x1), holes."""
    rng = np.random.default_rng(seed)
    far = 10 * (1 + noise * rng.standard_normal((h, w)))
    near = 5 * (1 + noise * rng.standard_normal((h, w)))
    y0, y1, x0, x1 = h // 4, 3 * h // 4, w // 4, 3 * w // 4
    yy, xx = np.mgrid[:h, :w]
    inside = (yy >= y0) & (yy < y1) & (xx >= x0) & (xx < x1)
    holes = rng.random((h, w)) < hole_fraction
    depth = np.where(inside & ~holes, near, far).astype(np.float32)
    return depth, (y0, y1, x0, x1), holes


def check(depth, queue, *args, **kw):
    got = depth_filter_mask(depth, *args, queue=queue, **kw)
    want = ref.depth_filter_mask(depth, *args, **kw)
    assert got.dtype == np.bool_ and got.shape == depth.shape
    np.testing.assert_array_equal(got, want)
    assert not (got & ~np.isfinite(depth)).any()  # only present points are kept
    return got


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (7, 1), (2, 2), (3, 5), (33, 17), (64, 65), (255, 257)])
def test_parity_random(queue, shape):
    for i, density in enumerate((0.2, 0.6, 1.0)):
        d = layered(shape, density, seed=hash((shape, i)) % 2**32)
        for levels in (0, 1, 2, 3, 4, 6, 9, 16):
            check(d, queue, levels)
        for strength, edge in ((1.0, 0.0), (1.01, 0.01), (1.3, 0.0), (1.025, 0.5), (3.0, 0.01)):
            check(d, queue, 4, strength, edge_threshold=edge)


def test_parity_large(queue):
    d = layered((1081, 1921), 0.5, seed=7)
    kept = check(d, queue)
    assert 0 < kept.sum() < np.isfinite(d).sum()


def test_parity_continuous(queue):
    """Uniformly random depths (ties and near-ties of s * ref everywhere)."""
    rng = np.random.default_rng(3)
    d = rng.uniform(0, 1e3, (97, 131)).astype(np.float32)
    d[rng.random(d.shape) < 0.3] = INF
    d[5, :] = 0.0
    for levels in (1, 4, 8):
        for strength in (1.0, 1.0001, 1.025, 2.0):
            check(d, queue, levels, strength)


@pytest.mark.parametrize("hole_fraction", [0.1, 0.3, 0.5])
def test_scene(queue, hole_fraction):
    """Far points seen through the holes of a near plane go; the near plane and
    the far plane around it stay."""
    levels = 4
    d, (y0, y1, x0, x1), holes = scene(128, 192, hole_fraction, seed=11)
    keep = check(d, queue, levels)
    yy, xx = np.mgrid[: d.shape[0], : d.shape[1]]
    inside = (yy >= y0) & (yy < y1) & (xx >= x0) & (xx < x1)
    into = np.minimum(np.minimum(yy - y0, y1 - 1 - yy), np.minimum(xx - x0, x1 - 1 - xx))
    assert keep[inside & ~holes].all()  # near plane kept
    assert keep[~inside].all()  # far plane around it kept
    through = inside & holes
    # see-through points removed, but for a band along the silhouette (the
    # near side of an edge compares with the far plane beside it)
    assert not keep[through & (into >= 8)].any()
    assert keep[through & (into >= 2)].mean() < 0.1
    # no pyramid: nothing removed; a tolerance beyond the depth ratio: nothing removed
    assert check(d, queue, 0).all()
    assert check(d, queue, levels, 2.5).all()


def test_uniform_and_empty(queue):
    for shape in [(0, 0), (0, 5), (4, 0)]:
        got = depth_filter_mask(np.zeros(shape, np.float32), queue=queue)
        assert got.shape == shape and got.dtype == np.bool_
    for shape in [(1, 1), (1, 9), (17, 33), (128, 128)]:
        for levels in (0, 1, 4, 16):
            assert not check(np.full(shape, INF), queue, levels).any()
            for value in (0.0, 1.0, 7.5, 3e38):
                assert check(np.full(shape, value, np.float32), queue, levels).all()


def test_single_point_and_steps(queue):
    """One point alone, and two planes side by side: nothing occludes anything."""
    d = np.full((40, 50), INF)
    d[17, 23] = 3.0
    assert check(d, queue, 5).sum() == 1
    step = np.full((40, 50), 4.0, np.float32)
    step[:, 25:] = 9.0
    assert check(step, queue, 4).all()
    step[:17, :] = 1.0  # three planes, T-junction
    assert check(step, queue, 4).all()


def test_device_arrays(queue):
    d = layered((70, 90), 0.6, seed=5)
    got = depth_filter_mask(cla.to_device(queue, d), 3)
    assert isinstance(got, cla.Array) and got.dtype == np.uint8 and got.shape == d.shape
    np.testing.assert_array_equal(got.get(), ref.depth_filter_mask(d, 3).astype(np.uint8))
    empty = depth_filter_mask(cla.to_device(queue, np.zeros((0, 3), np.float32)))
    assert isinstance(empty, cla.Array) and empty.shape == (0, 3)


def test_rgbda(queue):
    rng = np.random.default_rng(9)
    d = layered((45, 61), 0.7, seed=9)
    keep = ref.depth_filter_mask(d)
    for channels in (3, 4):
        rgba = rng.integers(0, 256, (45, 61, channels), dtype=np.uint8)
        rgba[0, 0, :3] = (0, 128, 255)
        for k in (keep, keep.astype(np.uint8)):
            got = rgbda(rgba, d, k, queue=queue)
            want = ref.rgbda(rgba, d, k)
            assert got.dtype == np.float32 and got.shape == (45, 61, 5)
            np.testing.assert_array_equal(got, want)
    assert got[keep, 4].min() == 1 and got[~keep, 4].max() == 0
    assert np.isinf(got[~keep, 3]).all() and (got[keep, 3] == d[keep]).all()
    assert (got[~keep, :3] == 0).all()
    if keep[0, 0]:
        assert got[0, 0, 0] == 0 and got[0, 0, 2] == 1.0
    dev = rgbda(cla.to_device(queue, rgba), d, depth_filter_mask(cla.to_device(queue, d)))
    assert isinstance(dev, cla.Array)
    np.testing.assert_array_equal(dev.get(), want)
    assert rgbda(
        np.zeros((0, 4, 4), np.uint8), np.zeros((0, 4), np.float32), np.zeros((0, 4), bool), queue=queue
    ).shape == (0, 4, 5)


def _gbuffers(depth, rgba):
    """G-buffers of the planes depth_filter reads (index: any point)."""
    index = np.where(np.isfinite(depth), 0, 0xFFFFFFFF).astype(np.uint32)
    return clvis.GBuffers(index=index, depth=depth, rgba=rgba, attributes={})


def _device_gbuffers(q, g):
    return clvis.GBuffers(
        index=cla.to_device(q, g.index),
        depth=cla.to_device(q, g.depth),
        rgba=cla.to_device(q, g.rgba),
        attributes={},
    )


def _check_filtered(f, depth, rgba, levels, device):
    """Every plane of a FilteredImage against the reference, on the side it should be."""
    keep = ref.depth_filter_mask(depth, levels)
    want_depth, want_rgba = ref.kept(depth, keep, rgba)
    want_rgbda = ref.rgbda(rgba if rgba is not None else np.zeros(depth.shape + (4,), np.uint8), depth, keep)
    kind = cla.Array if device else np.ndarray
    planes = {"keep": (f.keep, keep), "depth": (f.depth, want_depth), "rgbda": (f.rgbda, want_rgbda)}
    if rgba is None:
        assert f.rgba is None
    else:
        planes["rgba"] = (f.rgba, want_rgba)
    for name, (got, want) in planes.items():
        assert isinstance(got, kind), f"{name}: {type(got).__name__}"
        assert got.dtype == want.dtype and tuple(got.shape) == want.shape, name
        np.testing.assert_array_equal(got.get() if device else got, want, err_msg=name)


@pytest.mark.parametrize("shape", [(1, 1), (3, 5), (64, 65)])
def test_depth_filter_host_and_device(queue, shape):
    """depth_filter: numpy G-buffers (or depth) in, numpy planes out; device
    planes in, device planes out, every plane equal to the reference."""
    rng = np.random.default_rng(hash(shape) % 2**32)
    d = layered(shape, 0.6, seed=11)
    rgba = rng.integers(0, 256, shape + (4,), dtype=np.uint8)
    g = _gbuffers(d, rgba)
    for levels in (0, 1, 4):
        _check_filtered(clvis.depth_filter(g, levels, queue=queue), d, rgba, levels, device=False)
        _check_filtered(clvis.depth_filter(_device_gbuffers(queue, g), levels), d, rgba, levels, device=True)
        _check_filtered(clvis.depth_filter(d, levels, queue=queue), d, None, levels, device=False)
        _check_filtered(clvis.depth_filter(cla.to_device(queue, d), levels), d, None, levels, device=True)
    # one plane on the device is enough for device planes out
    mixed = clvis.GBuffers(index=g.index, depth=cla.to_device(queue, d), rgba=rgba, attributes={})
    _check_filtered(clvis.depth_filter(mixed, 2), d, rgba, 2, device=True)


def test_depth_filter_empty_and_bad(queue):
    for host in (True, False):
        d = np.zeros((0, 3), np.float32)
        f = clvis.depth_filter(d if host else cla.to_device(queue, d), queue=queue)
        assert isinstance(f.rgbda, np.ndarray if host else cla.Array)
        assert f.keep.shape == f.depth.shape == (0, 3) and f.rgbda.shape == (0, 3, 5) and f.rgba is None
    d = layered((4, 5), 0.5, seed=1)
    with pytest.raises(ValueError, match="rgba: expected shape"):
        clvis.depth_filter(_gbuffers(d, np.zeros((4, 6, 4), np.uint8)), queue=queue)
    with pytest.raises(TypeError, match="rgba: dtype float32"):
        clvis.depth_filter(_gbuffers(d, np.zeros((4, 5, 4), np.float32)), queue=queue)
    x = d.copy()
    x[1, 1] = np.nan
    with pytest.raises(clvis.DataError, match="1 NaN"):
        clvis.depth_filter(_device_gbuffers(queue, _gbuffers(x, np.zeros((4, 5, 4), np.uint8))))


def _full_gbuffers(depth, seed):
    """G-buffers with every plane kind: index, depth, rgba, a float and a
    uint8 attribute, the velocity planes and the radius (empty pixels as the
    renderer leaves them)."""
    rng = np.random.default_rng(seed)
    h, w = depth.shape
    cov = np.isfinite(depth)

    def f32(*shape):
        return np.where(
            cov.reshape(cov.shape + (1,) * len(shape)), rng.random((h, w, *shape)), np.nan
        ).astype(np.float32)

    vel = f32(2)
    return clvis.GBuffers(
        index=np.where(cov, rng.integers(0, 1000, (h, w)), 0xFFFFFFFF).astype(np.uint32),
        depth=depth,
        rgba=np.where(cov[..., None], rng.integers(1, 256, (h, w, 4)), 0).astype(np.uint8),
        attributes={"t": f32(), "class": np.where(cov, rng.integers(1, 9, (h, w)), 0).astype(np.uint8)},
        vel2d=vel,
        vel_angle=np.arctan2(vel[..., 1], vel[..., 0]),
        vel_speed=np.hypot(vel[..., 0], vel[..., 1]),
        radius_px=f32(),
        stats={"points": 1000},
    )


@pytest.mark.parametrize("levels,strength", [(0, 1.025), (2, 1.025), (4, 1.4)])
def test_filter_gbuffers(queue, levels, strength):
    """filter_gbuffers empties, in every plane, the pixels the mask removes
    (as the renderer leaves a pixel no point reached) and keeps the rest bit
    for bit; device planes in, host planes out."""
    d = layered((37, 29), 0.7, seed=5)
    g = _full_gbuffers(d, 3)
    keep = ref.depth_filter_mask(d, levels, strength)
    removed = np.isfinite(d) & ~keep
    assert removed.any() or levels == 0
    on_device = clvis.GBuffers(
        index=cla.to_device(queue, g.index),
        depth=cla.to_device(queue, g.depth),
        rgba=cla.to_device(queue, g.rgba),
        attributes={k: cla.to_device(queue, v) for k, v in g.attributes.items()},
        vel2d=cla.to_device(queue, g.vel2d),
        vel_angle=cla.to_device(queue, g.vel_angle),
        vel_speed=cla.to_device(queue, g.vel_speed),
        radius_px=cla.to_device(queue, g.radius_px),
        stats=g.stats,
    )
    for src in (g, on_device):
        f = clvis.raster.filter_gbuffers(src, levels, strength, queue=queue)
        assert isinstance(f.index, np.ndarray) and f.stats == {
            **src.stats,
            "depth_filter_removed": removed.sum(),
        }
        np.testing.assert_array_equal(f.covered, np.isfinite(d) & keep)
        np.testing.assert_array_equal(f.index, np.where(keep, g.index, 0xFFFFFFFF))
        np.testing.assert_array_equal(f.depth, np.where(keep, d, INF))
        np.testing.assert_array_equal(f.rgba, np.where(keep[..., None], g.rgba, 0))
        for name, a, b in [
            ("t", f.attributes["t"], g.attributes["t"]),
            ("radius", f.radius_px, g.radius_px),
            ("vel2d", f.vel2d, g.vel2d),
            ("angle", f.vel_angle, g.vel_angle),
            ("speed", f.vel_speed, g.vel_speed),
        ]:
            m = keep.reshape(keep.shape + (1,) * (a.ndim - 2))
            np.testing.assert_array_equal(a, np.where(m, b, np.nan), err_msg=name)
        np.testing.assert_array_equal(f.attributes["class"], np.where(keep, g.attributes["class"], 0))


def test_filter_gbuffers_bad_input(queue):
    d = layered((6, 5), 0.5, seed=1)
    with pytest.raises(TypeError, match="gbuffers: expected GBuffers"):
        clvis.raster.filter_gbuffers(d, queue=queue)
    g = _full_gbuffers(d, 1)
    with pytest.raises(ValueError, match="filter_strength"):
        clvis.raster.filter_gbuffers(g, 4, 0.5, queue=queue)
    bad = _full_gbuffers(d.copy(), 1)
    bad.depth[2, 2] = np.nan
    with pytest.raises(clvis.DataError, match="1 NaN"):
        clvis.raster.filter_gbuffers(bad, queue=queue)
    short = clvis.GBuffers(index=g.index[:5], depth=d, rgba=g.rgba, attributes={})
    with pytest.raises(ValueError, match="index: shape"):
        clvis.raster.filter_gbuffers(short, queue=queue)


@given(
    d=hnp.arrays(
        np.float32,
        st.tuples(st.integers(1, 24), st.integers(1, 24)),
        elements=st.sampled_from([0.0, 1.0, 1.02, 1.03, 2.0, 2.05, 10.0, np.inf]),
    ),
    levels=st.integers(0, 6),
    strength=st.sampled_from([1.0, 1.025, 1.5]),
    edge=st.sampled_from([0.0, 0.01, 1.0]),
)
def test_property(device, d, levels, strength, edge):
    q = clvis.runtime.queue_for(device)
    got = check(d, q, levels, strength, edge_threshold=edge)
    if levels == 0:
        np.testing.assert_array_equal(got, np.isfinite(d))


def test_defaults_match_reference():
    a = inspect.signature(depth_filter_mask).parameters
    b = inspect.signature(ref.depth_filter_mask).parameters
    for name in ("levels", "filter_strength", "edge_threshold"):
        assert a[name].default == b[name].default
    assert level_shapes((1081, 1921), 3) == [(1081, 1921), (541, 961), (271, 481), (136, 241)]


def test_bad_input(device):
    q = clvis.runtime.queue_for(device)
    d = np.ones((4, 5), np.float32)
    with pytest.raises(TypeError, match="depth: dtype float64"):
        depth_filter_mask(d.astype(np.float64), queue=q)
    with pytest.raises(ValueError, match="depth: expected a 2-D array"):
        depth_filter_mask(np.ones(5, np.float32), queue=q)
    with pytest.raises(TypeError, match="depth: expected an array"):
        depth_filter_mask(None, queue=q)
    for levels, exc in ((-1, ValueError), (17, ValueError), (2.0, TypeError), (True, TypeError)):
        with pytest.raises(exc, match="levels"):
            depth_filter_mask(d, levels, queue=q)
    for s in (0.99, 0.0, -1.0, float("nan"), float("inf"), 1e39):
        with pytest.raises(ValueError, match="filter_strength"):
            depth_filter_mask(d, 4, s, queue=q)
    with pytest.raises(TypeError, match="filter_strength"):
        depth_filter_mask(d, 4, "1.1", queue=q)
    for t in (-0.01, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="edge_threshold"):
            depth_filter_mask(d, edge_threshold=t, queue=q)
    for bad, what in (
        (np.nan, "1 NaN and 0 negative"),
        (-1.0, "0 NaN and 1 negative"),
        (-np.inf, "0 NaN and 1 negative"),
    ):
        x = d.copy()
        x[2, 3] = bad
        for levels in (0, 4):
            with pytest.raises(clvis.DataError, match=what):
                depth_filter_mask(x, levels, queue=q)
        with pytest.raises(clvis.DataError, match="depth"):
            depth_filter_mask(cla.to_device(q, x))
    rgba = np.zeros((4, 5, 4), np.uint8)
    with pytest.raises(TypeError, match="rgba: dtype float32"):
        rgbda(rgba.astype(np.float32), d, d > 0, queue=q)
    with pytest.raises(ValueError, match="rgba: expected 3 or 4 channels"):
        rgbda(np.zeros((4, 5, 2), np.uint8), d, d > 0, queue=q)
    with pytest.raises(ValueError, match="depth: shape"):
        rgbda(rgba, d[:3], d > 0, queue=q)
    with pytest.raises(ValueError, match="keep: shape"):
        rgbda(rgba, d, (d > 0)[:, :4], queue=q)
    with pytest.raises(TypeError, match="keep: dtype"):
        rgbda(rgba, d, d, queue=q)
