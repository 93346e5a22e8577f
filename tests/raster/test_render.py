"""clvis.raster against clvis.reference.raster: visibility exactly, G-buffers
exactly (the velocity angle within atan2's few ulp), on every device and both
work shapes, through the 64-bit path and the two-pass fallback."""

import warnings
from pathlib import Path

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest
from hypothesis import given
from hypothesis import strategies as st

import clvis
from clvis import raster, runtime
from clvis._arrays import to_host
from clvis.camera import CAMERA_DTYPE, Camera, camera_buffer
from clvis.reference import raster as ref

W, H = 64, 48


def _scene(n, seed=0, spread=1.0):
    rng = np.random.default_rng(seed)
    return (rng.normal(size=(n, 3)) * spread).astype(np.float32)


def _cam(aspect=W / H, **kw):
    kw.setdefault("near", 0.5)
    kw.setdefault("far", 20.0)
    return Camera.look_at((0.3, -6.0, 1.2), (0.0, 0.0, 0.0), (0, 0, 1), fov_y=50.0, aspect=aspect, **kw)


def _vis(queue, pos, cam, w=W, h=H, morton=False, batch_size=raster.BATCH_SIZE):
    r = clvis.Rasterizer(pos, morton=morton, batch_size=batch_size, queue=queue)
    vis, _ = r.visibility(cam, w, h)
    return vis.get()


def _assert_gbuffers(got, want):
    np.testing.assert_array_equal(got.index, want.index)
    np.testing.assert_array_equal(got.depth, want.depth)
    np.testing.assert_array_equal(got.rgba, want.rgba)
    assert got.attributes.keys() == want.attributes.keys()
    for k in want.attributes:
        assert got.attributes[k].dtype == want.attributes[k].dtype
        np.testing.assert_array_equal(got.attributes[k], want.attributes[k])
    for k in ("vel2d", "vel_speed", "radius_px"):
        a, b = getattr(got, k), getattr(want, k)
        assert (a is None) == (b is None), k
        if a is not None:
            np.testing.assert_array_equal(a, b)
    if want.vel_angle is not None:
        # OpenCL's atan2 is specified to 6 ulp (OpenCL C 1.2, 7.4), not correctly rounded:
        # Intel's runtime differs from numpy's by up to 2 ulp near +-pi
        ulp = np.spacing(np.abs(np.nan_to_num(want.vel_angle)).astype(np.float32))
        err = np.abs(np.nan_to_num(got.vel_angle) - np.nan_to_num(want.vel_angle))
        assert (err <= 6 * ulp).all(), (
            f"vel_angle off by {float((err / ulp).max()):.1f} ulp (OpenCL allows 6)"
        )
        np.testing.assert_array_equal(np.isnan(got.vel_angle), np.isnan(want.vel_angle))


@pytest.mark.parametrize("n", [0, 1, 1000, 1_000_000])
@pytest.mark.parametrize("morton", [False, True], ids=["input-order", "morton"])
def test_visibility_parity(queue, n, morton):
    pos = _scene(n, seed=n)
    cam = _cam()
    got = _vis(queue, pos, cam, morton=morton)
    want = ref.visibility(pos, cam, W, H)
    np.testing.assert_array_equal(got, want)
    if n >= 1000:
        assert (want != np.iinfo(np.uint64).max).sum() > min(n // 3, W * H // 4)  # a real picture


def test_many_points_per_pixel_and_ties(queue):
    """200k points on a 4x3 image; many share a position, so ties in depth go
    to the lowest index (also after the Morton reordering)."""
    rng = np.random.default_rng(5)
    base = _scene(2000, seed=1, spread=0.3)
    pos = base[rng.integers(0, 2000, 200_000)]
    cam = _cam(aspect=4 / 3)
    want = ref.visibility(pos, cam, 4, 3)
    for morton in (False, True):
        got = _vis(queue, pos, cam, 4, 3, morton=morton, batch_size=777)
        np.testing.assert_array_equal(got, want)
    ids = (want & np.uint64(0xFFFFFFFF)).astype(np.int64)
    # the winner is the first occurrence of its position
    first = {tuple(p): i for i, p in reversed(list(enumerate(map(tuple, pos[:5000]))))}
    for i in ids.ravel():
        if i < 5000:
            assert first[tuple(pos[i])] == i


def test_near_far_behind_and_edges(queue):
    """An orthographic camera with dyadic pixel edges: points exactly on the
    near and far planes and on pixel edges, just outside them, and behind."""
    cam = Camera.ortho((0, 0, 0), (0, 0, -1), (0, 1, 0), height=2.0, aspect=1.0, near=1.0, far=8.0)
    depth = cam.depth_row
    assert np.array_equal(depth, [0, 0, -1, 0])  # depth = -z, exactly
    e = np.float32(np.spacing(np.float32(1.0)))
    xs = np.array([-1.0, -0.75, -0.5, 0.0, 0.25, 0.5, 1.0 - e, 1.0, -1.0 - e], np.float32)
    zs = np.array([-1.0, -8.0, -1.0 + e, -8.0 - 8 * e, -4.0, 3.0, 0.0], np.float32)
    pts = np.array([(x, y, z) for x in xs for y in xs[::-1] for z in zs], np.float32)
    pr = cam.project(pts, 8, 8)
    drawn = pts[pr.visible]
    assert ((drawn[:, 2] == -1.0) | (drawn[:, 2] == -8.0) | (drawn[:, 2] == -4.0)).all()
    assert (pts[pr.visible][:, 0] >= -1).all() and (pts[pr.visible][:, 0] < 1).all()
    assert pr.visible[(pts[:, 0] == -1) & (pts[:, 1] == 0) & (pts[:, 2] == -1)].all()
    assert not pr.visible[pts[:, 0] == 1].any()
    for morton in (False, True):
        np.testing.assert_array_equal(
            _vis(queue, pts, cam, 8, 8, morton=morton), ref.visibility(pts, cam, 8, 8)
        )


@pytest.mark.parametrize("spread", [1.0, 0.3])
def test_nan_inf_never_drawn(queue, spread):
    pos = _scene(50_000, seed=3, spread=spread)
    rng = np.random.default_rng(3)
    bad = rng.random(pos.shape) < 0.05
    pos[bad] = rng.choice(np.array([np.nan, np.inf, -np.inf], np.float32), int(bad.sum()))
    pos[:20_000] = np.nan  # whole batches with no finite point
    # perspective: render.cl's float8 loop takes clip w as the depth; the
    # orthographic camera's depth row is its own (clvis_project8's w_depth).
    # spread 0.3: every batch box lies inside the view (clvis_box_inside), so
    # the float8 loop tests only the depth range, which must reject them too
    ortho = Camera.ortho((0.3, -6.0, 1.2), (0, 0, 0), (0, 0, 1), height=6.0, aspect=W / H, near=0.5, far=20)
    for cam in (_cam(), ortho):
        want = ref.visibility(pos, cam, W, H)
        ids = want[want != np.iinfo(np.uint64).max] & np.uint64(0xFFFFFFFF)
        assert len(ids) > 200 and np.isfinite(pos[ids.astype(np.int64)]).all()
        for morton in (False, True):
            np.testing.assert_array_equal(_vis(queue, pos, cam, morton=morton, batch_size=4096), want)


def test_fallback_without_int64_atomics(device):
    """The two-pass path gives the same buffer bit for bit, forced off on a
    device that has the extension."""
    pos = _scene(300_000, seed=9)
    rng = np.random.default_rng(9)
    pos = np.concatenate([pos, pos[rng.integers(0, len(pos), 100_000)]])  # exact ties
    cam = _cam()
    q = runtime.queue_for(device)
    fast = _vis(q, pos, cam)
    with runtime.configure(int64_atomics=False):
        assert not runtime.capabilities(q).int64_atomics
        for profile in ("cpu", "gpu"):
            with runtime.configure(tuning=profile):
                slow = _vis(q, pos, cam, morton=profile == "gpu")
                np.testing.assert_array_equal(slow, fast)
                got = clvis.rasterize(pos, cam, W, H, queue=q, soft_z=True)
                _assert_gbuffers(got, ref.rasterize(pos, cam, W, H, soft_z=True))
    np.testing.assert_array_equal(fast, ref.visibility(pos, cam, W, H))


def _full_cloud(n, seed=0):
    rng = np.random.default_rng(seed)
    pos = _scene(n, seed)
    colors = rng.integers(0, 256, (n, 4), dtype=np.uint8)
    attrs = {
        "temperature": rng.normal(300, 20, n).astype(np.float32),
        "pressure": rng.random(n).astype(np.float64),  # converted to float32
        "label": rng.integers(0, 7, n).astype(np.uint8),
        "flag": rng.random(n) < 0.5,
    }
    attrs["temperature"][::97] = np.nan
    vel = rng.normal(size=(n, 3)).astype(np.float32)
    radius = rng.random(n).astype(np.float32) * 0.05
    return pos, colors, attrs, vel, radius


@pytest.mark.parametrize("morton", [False, True], ids=["input-order", "morton"])
def test_gbuffers_parity(queue, morton):
    pos, colors, attrs, vel, radius = _full_cloud(60_000)
    cam = _cam()
    kw = {"colors": colors, "attributes": attrs, "velocity": vel, "radius": radius}
    got = clvis.rasterize(pos, cam, W, H, morton=morton, queue=queue, **kw)
    want = ref.rasterize(pos, cam, W, H, **kw)
    _assert_gbuffers(got, want)
    assert got.attributes["pressure"].dtype == np.float32
    assert got.attributes["flag"].dtype == np.uint8
    assert got.covered.sum() > W * H // 4
    empty = ~got.covered
    assert np.isinf(got.depth[empty]).all() and (got.rgba[empty] == 0).all()
    assert np.isnan(got.vel2d[empty]).all() and np.isnan(got.radius_px[empty]).all()
    # velocity planes are consistent with each other
    c = got.covered
    np.testing.assert_allclose(got.vel_speed[c], np.hypot(got.vel2d[c, 0], got.vel2d[c, 1]), rtol=1e-6)


def test_radius_plane_of_an_orthographic_camera(queue):
    """An orthographic camera draws a world unit as focal_px pixels at every
    depth: radius_px is radius x focal_px, not divided by the depth (as a
    perspective camera's is); the kernel matches the reference."""
    pos, colors, attrs, vel, radius = _full_cloud(20_000, seed=4)
    cam = Camera.ortho((0.3, -6.0, 1.2), (0.0, 0.0, 0.0), (0, 0, 1), 3.0, W / H, 0.1, 20.0)
    got = clvis.rasterize(pos, cam, W, H, radius=radius, queue=queue)
    want = ref.rasterize(pos, cam, W, H, radius=radius)
    _assert_gbuffers(got, want)
    c = got.covered
    assert c.sum() > W * H // 8
    np.testing.assert_allclose(
        got.radius_px[c], radius[got.index[c]] * np.float32(cam.focal_px(H)), rtol=1e-6
    )


def test_screen_velocity_is_the_pixel_motion(device):
    """vel2d is the derivative of the pixel position: compare with a finite
    difference of the projection."""
    q = runtime.queue_for(device)
    pos, _, _, vel, _ = _full_cloud(5000, seed=2)
    cam = _cam()
    g = clvis.rasterize(pos, cam, W, H, velocity=vel, queue=q)
    idx = g.index[g.covered].astype(np.int64)
    h = 1e-3
    p0 = cam.project(pos[idx].astype(np.float64), W, H)
    p1 = cam.project((pos[idx] + h * vel[idx]).astype(np.float64), W, H)
    fd = np.stack([(p1.sx - p0.sx) / h, (p1.sy - p0.sy) / h], axis=1)
    got = g.vel2d[g.covered]
    np.testing.assert_allclose(got, fd, rtol=0.05, atol=0.05 * np.abs(fd).max())


@pytest.mark.parametrize("color_by", ["temperature", "label"])
def test_transfer_function(queue, color_by):
    pos, _, attrs, _, _ = _full_cloud(40_000, seed=4)
    cam = _cam()
    for cmap, vr in (("viridis", None), ("magma", (290.0, 310.0)), ("jet", (3.0, 3.0))):
        got = clvis.rasterize(
            pos, cam, W, H, attributes=attrs, color_by=color_by, colormap=cmap, value_range=vr, queue=queue
        )
        want = ref.rasterize(
            pos, cam, W, H, attributes=attrs, color_by=color_by, colormap=cmap, value_range=vr
        )
        _assert_gbuffers(got, want)
        colors = len(np.unique(got.rgba[got.covered & ~np.isnan(got.attributes[color_by])], axis=0))
        if vr is None:
            assert colors >= 5  # the data's own range spreads over the colormap
        elif vr[0] == vr[1]:
            assert colors == 1


@pytest.mark.parametrize("soft_z", [True, 1.0, 1.2])
def test_soft_z(queue, soft_z):
    pos, colors, attrs, _, _ = _full_cloud(80_000, seed=6)
    cam = _cam()
    got = clvis.rasterize(pos, cam, W, H, colors=colors, soft_z=soft_z, queue=queue, morton=True)
    want = ref.rasterize(pos, cam, W, H, colors=colors, soft_z=soft_z)
    _assert_gbuffers(got, want)
    hard = ref.rasterize(pos, cam, W, H, colors=colors)
    if soft_z == 1.2:  # averaging many colours differs from the nearest point's
        assert (got.rgba != hard.rgba).any()
    got = clvis.rasterize(
        pos, cam, W, H, attributes=attrs, color_by="temperature", soft_z=soft_z, queue=queue
    )
    _assert_gbuffers(
        got, ref.rasterize(pos, cam, W, H, attributes=attrs, color_by="temperature", soft_z=soft_z)
    )


def test_batch_culling(queue):
    """A Morton-ordered cloud seen in part: culled batches read no point, and
    the image is still exact."""
    rng = np.random.default_rng(8)
    pos = (rng.random((400_000, 3)) * [100, 100, 2]).astype(np.float32)
    cam = Camera.look_at((10, 10, 8), (12, 12, 0), (0, 1, 0), fov_y=40, aspect=W / H, near=0.1, far=50)
    r = clvis.Rasterizer(pos, morton=True, batch_size=2048, queue=queue)
    g = r.render(cam, W, H)
    s = g.stats
    assert s["batches"] == -(-400_000 // 2048)
    assert s["batches_drawn"] < s["batches"] // 4
    assert s["points_read"] < 400_000 // 4
    np.testing.assert_array_equal(g.index, ref.rasterize(pos, cam, W, H).index)
    assert g.covered.sum() > W * H // 3


@pytest.mark.parametrize("morton", [True, False], ids=["morton", "shuffled"])
@pytest.mark.parametrize("int64", [True, False], ids=["int64", "no-int64"])
def test_walk_directions(queue, int64, morton):
    """A cloud (ties, a partial last batch, batches of a size that is no
    multiple of 8, culled batches when Morton-ordered) seen from opposite sides: one view walks
    the batches and their points forwards, the other backwards (render.cl's
    walk: its reverse bit; its coherent bit, the 8-point early-z, for the
    Morton-ordered cloud only), and both give the reference's image."""
    rng = np.random.default_rng(9)
    pos = (rng.random((5000, 3)) * [8, 8, 2]).astype(np.float32)
    pos = np.concatenate([pos, pos[rng.integers(0, 5000, 1500)]])
    with runtime.configure(int64_atomics=int64):
        r = clvis.Rasterizer(pos, morton=morton, batch_size=333, queue=queue)
    assert r.coherent == morton
    walks = set()
    for eye, target in (((2, 3, 5), (2, 3, 1)), ((6, 5, -3), (6, 5, 1))):
        cam = Camera.look_at(eye, target, (0, 1, 0), fov_y=40, aspect=W / H, near=0.1, far=50)
        f = camera_buffer(cam)[16:19].astype(np.float64)
        walks.add(bool(f[0] + 2 * f[1] + 4 * f[2] < 0))
        vis, drawn = r.visibility(cam, W, H)
        np.testing.assert_array_equal(vis.get(), ref.visibility(pos, cam, W, H))
        if morton:  # spatially coherent batches: some fall outside the view
            assert 0 < drawn.get().sum() < r.nbatches
    assert walks == {False, True}


def test_coherent_judged_from_the_batch_boxes(queue):
    """Points the caller sorted along the Morton curve count as coherent
    without morton=True (render.cl's 8-point early-z); the same shuffled do
    not; a cloud whose coordinates are all NaN is not (no batch box)."""
    rng = np.random.default_rng(3)
    pos = (rng.random((20000, 3)) * [50, 30, 4]).astype(np.float32)
    order = clvis.morton_order(pos, queue=queue)
    assert clvis.Rasterizer(pos[order], morton=False, batch_size=256, queue=queue).coherent
    assert not clvis.Rasterizer(pos, morton=False, batch_size=256, queue=queue).coherent
    assert clvis.Rasterizer(pos, batch_size=256, queue=queue).coherent
    nan = np.full((600, 3), np.nan, np.float32)
    assert not clvis.Rasterizer(nan, morton=False, batch_size=256, queue=queue).coherent


@given(seed=st.integers(0, 2**32 - 1), ortho=st.booleans(), batch=st.sampled_from([1, 7, 256, 10240]))
def test_property_random_cameras(device, seed, ortho, batch):
    """Random clouds, random cameras (inside the cloud too), every batch size:
    culling never drops a point that the projection draws."""
    rng = np.random.default_rng(seed)
    pos = (rng.normal(size=(3000, 3)) * rng.uniform(0.1, 10)).astype(np.float32)
    eye = rng.normal(size=3) * rng.uniform(0.1, 20)
    target = eye + rng.normal(size=3)
    kw = {
        "aspect": float(rng.uniform(0.5, 2)),
        "near": float(rng.uniform(0.01, 1)),
        "far": float(rng.uniform(2, 40)),
    }
    cam = (
        Camera.ortho(eye, target, (0, 0, 1), height=float(rng.uniform(0.5, 20)), **kw)
        if ortho
        else Camera.look_at(eye, target, (0, 0, 1), fov_y=float(rng.uniform(10, 120)), **kw)
    )
    w, h = int(rng.integers(1, 40)), int(rng.integers(1, 40))
    q = runtime.queue_for(device)
    with warnings.catch_warnings():  # any projection at any size: stretched on purpose
        warnings.simplefilter("ignore", clvis.AspectWarning)
        got = _vis(q, pos, cam, w, h, morton=bool(seed % 2), batch_size=batch)
    np.testing.assert_array_equal(got, ref.visibility(pos, cam, w, h))


def test_device_arrays(queue):
    pos, colors, *_ = _full_cloud(20_000, seed=12)
    cam = _cam()
    g = clvis.rasterize(
        cla.to_device(queue, pos), cam, W, H, colors=cla.to_device(queue, colors), morton=True
    )
    _assert_gbuffers(g, ref.rasterize(pos, cam, W, H, colors=colors))


def test_point_cloud_input(queue):
    pos, colors, attrs, vel, radius = _full_cloud(10_000, seed=13)
    cloud = clvis.PointCloud(pos, colors=colors, attributes=attrs, velocity=vel, radius=radius)
    cam = _cam()
    g = clvis.rasterize(cloud, cam, W, H, color_by="label", queue=queue)
    _assert_gbuffers(
        g,
        ref.rasterize(
            pos,
            cam,
            W,
            H,
            colors=colors,
            attributes=cloud.attributes,
            velocity=vel,
            radius=radius,
            color_by="label",
        ),
    )


def test_layouts(device):
    """The host's dtypes match the kernels' layouts: the camera buffer as
    clvis/camera.h loads it, and the visibility word as two uints."""
    q = runtime.queue_for(device)
    cam = _cam()
    buf = camera_buffer(cam)
    assert CAMERA_DTYPE.itemsize == 80 and buf.dtype == np.float32 and buf.size == 20
    rec = buf.view(CAMERA_DTYPE)[0]
    np.testing.assert_array_equal(rec["m"], cam.matrix.astype(np.float32))
    np.testing.assert_array_equal(rec["d"], cam.depth_row.astype(np.float32))
    src = """
    #include "clvis/camera.h"
    kernel void probe(global const float *cam, global float *out) {
        clvis_camera c = clvis_load_camera(cam);
        vstore4(c.r0, 0, out); vstore4(c.r1, 1, out); vstore4(c.r2, 2, out);
        vstore4(c.r3, 3, out); vstore4(c.d, 4, out);
    }"""
    with warnings.catch_warnings():  # drivers may log remarks on success
        warnings.simplefilter("ignore", cl.CompilerWarning)
        prg = cl.Program(q.context, src).build(["-I", str(runtime.INCLUDE_DIR)])
    d_cam = cla.to_device(q, buf)
    out = cla.empty(q, 20, np.float32)
    prg.probe(q, (1,), (1,), d_cam.data, out.data)
    np.testing.assert_array_equal(out.get(), buf)
    pos = _scene(5000)
    vis = _vis(q, pos, cam)
    words = vis.view(raster.VIS_DTYPE)
    g = ref.rasterize(pos, cam, W, H)
    np.testing.assert_array_equal(words["id"], g.index)
    covered = g.covered
    np.testing.assert_array_equal(ref.key_depth(words["dkey"][covered]), g.depth[covered])


def test_depth_filter(queue):
    """clvis.depth_filter on G-buffers: a near wall with holes over a far wall;
    the far points seen through the holes are removed."""
    rng = np.random.default_rng(14)
    n = 4000  # about one point per pixel of the near wall: it has holes
    near = np.column_stack([rng.uniform(-1, 1, n), np.full(n, -2.0), rng.uniform(-1, 1, n)])
    m = 300_000
    far = np.column_stack([rng.uniform(-6, 6, m), np.full(m, 6.0), rng.uniform(-6, 6, m)])
    pos = np.concatenate([near, far]).astype(np.float32)
    cam = Camera.look_at((0, -6, 0), (0, 0, 0), (0, 0, 1), fov_y=40, aspect=1.0, near=0.5, far=20)
    g = clvis.rasterize(pos, cam, 96, 96, queue=queue)
    f = clvis.depth_filter(g, levels=4, queue=queue)
    from clvis.reference.raster import depth_filter as ref_df

    np.testing.assert_array_equal(f.keep, ref_df.depth_filter_mask(g.depth, 4))
    from_near = g.covered & (g.index < n)
    from_far = g.covered & (g.index >= n)
    pr = cam.project(np.array([[-0.8, -2, -0.8], [0.8, -2, 0.8]], np.float32), 96, 96)
    inner = np.zeros_like(from_far)
    inner[pr.py[1] + 3 : pr.py[0] - 3, pr.px[0] + 3 : pr.px[1] - 3] = True
    assert from_far[inner].sum() > 50  # see-through points exist
    assert f.keep[from_far & inner].mean() < 0.1  # and are removed
    assert f.keep[from_near].mean() > 0.95
    assert f.rgbda.shape == (96, 96, 5)
    np.testing.assert_array_equal(f.rgbda[..., 4], f.keep.astype(np.float32))
    assert np.isinf(f.depth[~f.keep]).all() and (f.rgba[~f.keep] == 0).all()
    f2 = clvis.depth_filter(g.depth, levels=4, queue=queue)
    np.testing.assert_array_equal(f2.keep, f.keep)
    assert f2.rgba is None


def test_a_misspelt_colormap_is_refused_without_color_by(queue):
    """colormap="nope" with no color_by (the cloud's colours or white) drew
    without a word: a typo went unnoticed until color_by was added."""
    pos, cam = _scene(10), _cam()
    with pytest.raises(ValueError, match="unknown colormap 'viridi'"):
        clvis.rasterize(pos, cam, W, H, colormap="viridi", queue=queue)
    with pytest.raises(TypeError, match="colormap name"):
        clvis.Rasterizer(pos, queue=queue).render(cam, W, H, colormap=None)  # type: ignore[arg-type]
    assert clvis.rasterize(pos, cam, W, H, colormap="magma", queue=queue).rgba.shape == (H, W, 4)


def test_bad_input(queue):
    cam = _cam()
    pos = _scene(10)
    with pytest.raises(TypeError, match="positions"):
        clvis.rasterize(pos.astype(bool), cam, W, H, queue=queue)
    with pytest.raises(TypeError, match="positions"):
        clvis.rasterize(pos.astype(np.complex64), cam, W, H, queue=queue)
    with pytest.raises(TypeError, match="read_points"):
        clvis.rasterize(Path("scan.las"), cam, W, H, queue=queue)
    # other real coordinates are float32's, as PointCloud takes them (big-endian float64 too)
    want = clvis.rasterize(np.round(pos).astype(np.float32), cam, W, H, queue=queue).index
    for other in (
        np.round(pos).astype(np.int32),
        np.round(pos).astype(">f8"),
        np.round(pos).astype(np.float16),
    ):
        np.testing.assert_array_equal(clvis.rasterize(other, cam, W, H, queue=queue).index, want)
    with pytest.raises(ValueError, match="positions"):
        clvis.rasterize(pos[:, :2], cam, W, H, queue=queue)
    with pytest.raises(ValueError, match="colors"):
        clvis.rasterize(pos, cam, W, H, colors=np.zeros((9, 4), np.uint8), queue=queue)
    with pytest.raises(TypeError, match="colors"):
        clvis.rasterize(pos, cam, W, H, colors=np.zeros((10, 4), np.float32), queue=queue)
    with pytest.raises(ValueError, match="velocity"):
        clvis.rasterize(pos, cam, W, H, velocity=np.zeros((10, 2), np.float32), queue=queue)
    with pytest.raises(ValueError, match="radius"):
        clvis.rasterize(pos, cam, W, H, radius=np.zeros(11, np.float32), queue=queue)
    with pytest.raises(ValueError, match="at most 8"):
        clvis.rasterize(pos, cam, W, H, attributes={str(i): np.zeros(10) for i in range(9)}, queue=queue)
    with pytest.raises(ValueError, match=r"attributes\['a'\]"):
        clvis.rasterize(pos, cam, W, H, attributes={"a": np.zeros(3)}, queue=queue)
    with pytest.raises(TypeError, match=r"attributes\['a'\]"):
        clvis.rasterize(pos, cam, W, H, attributes={"a": np.array(["x"] * 10)}, queue=queue)
    for w in (0, raster.MAX_IMAGE_SIDE + 1):
        with pytest.raises(ValueError, match="width"):
            clvis.rasterize(pos, cam, w, H, queue=queue)
    with pytest.raises(TypeError, match="height"):
        clvis.rasterize(pos, cam, W, 4.5, queue=queue)
    with pytest.raises(TypeError, match="camera"):
        clvis.rasterize(pos, np.eye(4), W, H, queue=queue)
    for bad in (0.5, float("nan"), "x"):
        with pytest.raises((TypeError, ValueError), match="soft_z"):
            clvis.rasterize(pos, cam, W, H, soft_z=bad, queue=queue)
    with pytest.raises(ValueError, match="color_by"):
        clvis.rasterize(pos, cam, W, H, color_by="nope", queue=queue)
    with pytest.raises(ValueError, match="value_range"):
        clvis.rasterize(
            pos, cam, W, H, attributes={"a": np.zeros(10)}, color_by="a", value_range=(1.0, 0.0), queue=queue
        )
    with pytest.raises(ValueError, match="value_range"):
        clvis.rasterize(
            pos, cam, W, H, attributes={"a": np.zeros(10)}, color_by="a", value_range=(0.0, 1e39), queue=queue
        )
    with pytest.raises(ValueError, match="viridi"):
        clvis.rasterize(
            pos, cam, W, H, attributes={"a": np.zeros(10)}, color_by="a", colormap="viridi", queue=queue
        )
    with pytest.raises(ValueError, match="batch_size"):
        clvis.Rasterizer(pos, batch_size=0, queue=queue)
    ortho = Camera.ortho((0, 0, 5), (0, 0, 0), (0, 1, 0), near=-1.0, far=10.0)
    with pytest.raises(ValueError, match="near > 0"):
        clvis.rasterize(pos, ortho, W, H, soft_z=True, queue=queue)
    with (
        runtime.configure(max_alloc_bytes=1 << 20),
        pytest.raises(clvis.DeviceError, match="visibility buffer"),
    ):
        clvis.rasterize(pos, cam.with_aspect(1.0), 1024, 1024, queue=queue)


def _other(queue, int64):
    """Options unlike those in force: the other atomics path and work shape."""
    return {"int64_atomics": not int64, "tuning": "gpu" if runtime.tuning_profile(queue) == "cpu" else "cpu"}


def _options_scene(queue):
    pos = _scene(4000, seed=5)
    rng = np.random.default_rng(5)
    colors = rng.integers(0, 256, (len(pos), 4), dtype=np.uint8)
    return pos, colors, {"v": rng.normal(size=len(pos)).astype(np.float32)}


@pytest.mark.parametrize("int64", [True, False], ids=["int64", "no-int64"])
def test_options_captured_at_construction(queue, int64):
    """A Rasterizer keeps the options it was made with; configure() applies to
    the next one, with the same result."""
    pos, colors, attrs = _options_scene(queue)
    with runtime.configure(int64_atomics=int64):
        r = clvis.Rasterizer(pos, colors=colors, attributes=attrs, batch_size=256, queue=queue)
    want = r.render(_cam(), W, H, soft_z=True)
    want_vis = r.visibility(_cam(), W, H)[0].get()
    with runtime.configure(**_other(queue, int64)) as o:
        _assert_gbuffers(r.render(_cam(), W, H, soft_z=True), want)
        np.testing.assert_array_equal(r.visibility(_cam(), W, H)[0].get(), want_vis)
        r2 = clvis.Rasterizer(pos, colors=colors, attributes=attrs, batch_size=256, queue=queue)
        assert r2.config.tuning == o.tuning != r.config.tuning
        _assert_gbuffers(r2.render(_cam(), W, H, soft_z=True), want)


def test_configure_from_another_thread(queue, options_flipping):
    """configure() from another thread during renders: the same G-buffers, no crash."""
    pos, colors, attrs = _options_scene(queue)
    r = clvis.Rasterizer(pos, colors=colors, attributes=attrs, batch_size=256, queue=queue)
    want = r.render(_cam(), W, H, soft_z=True)
    with options_flipping() as flips:
        for _ in range(20):
            _assert_gbuffers(r.render(_cam(), W, H, soft_z=True), want)
    assert flips[0] > 2


# ---------------------------------------------------------------------------
# clouds with more attributes than planes (a LAS file), and planes=

LAZ = __import__("pathlib").Path(__file__).parents[1] / "data" / "laspy_simple.laz"


def _laz():
    cloud = clvis.read_points(LAZ)
    assert len(cloud.attributes) > raster.MAX_ATTRIBUTES
    cam = Camera.fit(*cloud.bounds(), aspect=W / H)
    return cloud, cam


def test_las_file_color_by(queue):
    """A LAS file's 13+ attributes: coloring by one needs no planes, and by
    default none is resolved (more than 8)."""
    cloud, cam = _laz()
    g = clvis.rasterize(cloud, cam, W, H, color_by="intensity", queue=queue)
    want = ref.rasterize(
        cloud.positions, cam, W, H, colors=cloud.colors, attributes=cloud.attributes, color_by="intensity"
    )
    _assert_gbuffers(g, want)
    assert g.attributes == {} and g.covered.sum() > 100
    assert len(np.unique(g.rgba[g.covered], axis=0)) > 5


def test_las_file_planes(queue):
    cloud, cam = _laz()
    r = clvis.Rasterizer(cloud, queue=queue)
    assert r.attribute_names == list(cloud.attributes)
    for planes in (
        ["classification", "intensity", "gps_time"],
        ["intensity"],
        [],
        "user_data",
        list(cloud.attributes)[-8:],
    ):
        g = r.render(cam, W, H, planes=planes, color_by="gps_time")
        names = [planes] if isinstance(planes, str) else planes
        assert list(g.attributes) == names  # in the order asked for
        _assert_gbuffers(
            g,
            ref.rasterize(
                cloud.positions,
                cam,
                W,
                H,
                colors=cloud.colors,
                attributes=cloud.attributes,
                planes=names,
                color_by="gps_time",
            ),
        )
    assert g.attributes["user_data"].dtype == np.uint8 or "user_data" not in g.attributes
    with pytest.raises(ValueError, match="at most 8"):
        r.render(cam, W, H, planes=list(cloud.attributes)[:9])
    with pytest.raises(ValueError, match="planes: no attribute 'nope'"):
        r.render(cam, W, H, planes=["nope"])
    with pytest.raises(ValueError, match="twice"):
        r.render(cam, W, H, planes=["intensity", "intensity"])
    with pytest.raises(ValueError, match="attributes: 13 given; at most 8"):
        clvis.Rasterizer(cloud.positions, attributes=cloud.attributes, queue=queue)


def test_planes_default_and_bit_identical(queue):
    """At most 8 attributes: all of them by default, as before planes=."""
    pos, colors, attrs, vel, radius = _full_cloud(20_000, seed=21)
    cam = _cam()
    r = clvis.Rasterizer(pos, colors=colors, attributes=attrs, velocity=vel, queue=queue)
    full = r.render(cam, W, H, color_by="label")
    _assert_gbuffers(
        full, ref.rasterize(pos, cam, W, H, colors=colors, attributes=attrs, velocity=vel, color_by="label")
    )
    part = r.render(cam, W, H, color_by="label", planes=["flag", "temperature"])
    assert list(part.attributes) == ["flag", "temperature"]
    for k in part.attributes:
        np.testing.assert_array_equal(part.attributes[k], full.attributes[k])
    np.testing.assert_array_equal(part.rgba, full.rgba)
    dev = r.render(cam, W, H, planes=["pressure"], host=False)
    np.testing.assert_array_equal(dev.attributes["pressure"].get(), full.attributes["pressure"])
    # without the screen velocity: those planes are None, every other is the same
    for host in (True, False):
        g = r.render(cam, W, H, color_by="label", screen_velocity=False, host=host)
        assert g.vel2d is None and g.vel_angle is None and g.vel_speed is None
        for name in ("index", "depth", "rgba"):
            np.testing.assert_array_equal(to_host(getattr(g, name)), getattr(full, name))
        for k in full.attributes:
            np.testing.assert_array_equal(to_host(g.attributes[k]), full.attributes[k])


# ---------------------------------------------------------------------------
# point size


def _splat_scene(n=3000, seed=30):
    """Points near the image's edges and corners as well as inside, and exact
    ties (repeated positions)."""
    rng = np.random.default_rng(seed)
    cam = Camera.ortho((0, 0, 5), (0, 0, 0), (0, 1, 0), height=2.0, aspect=W / H, near=0.5, far=10)
    half_w = W / H
    xy = rng.uniform([-half_w, -1], [half_w, 1], (n, 2))
    edge = rng.uniform(0, 1, (n // 4, 2)) * [2 * half_w, 2] - [half_w, 1]
    edge[: n // 16, 0] = np.where(rng.random(n // 16) < 0.5, -half_w, half_w * (1 - 1e-6))
    edge[n // 16 : n // 8, 1] = np.where(rng.random(n // 8 - n // 16) < 0.5, -1 + 1e-6, 1 - 1e-6)
    xy = np.concatenate([xy, edge])
    z = rng.uniform(-3, 3, len(xy))
    pos = np.column_stack([xy, z]).astype(np.float32)
    pos = np.concatenate([pos, pos[rng.integers(0, len(pos), n // 3)]])  # ties
    return pos, cam


@pytest.mark.parametrize("int64", [True, False], ids=["int64", "no-int64"])
@pytest.mark.parametrize("point_size", [1, 2, 3, 5])
def test_point_size_parity(queue, int64, point_size):
    pos, cam = _splat_scene()
    rng = np.random.default_rng(point_size)
    colors = rng.integers(0, 256, (len(pos), 4), dtype=np.uint8)
    want_vis = ref.visibility(pos, cam, W, H, point_size)
    with runtime.configure(int64_atomics=int64):
        r = clvis.Rasterizer(pos, colors=colors, morton=point_size % 2 == 1, batch_size=1000, queue=queue)
    np.testing.assert_array_equal(r.visibility(cam, W, H, point_size=point_size)[0].get(), want_vis)
    for soft_z in (None, 1.2):
        got = r.render(cam, W, H, point_size=point_size, soft_z=soft_z)
        _assert_gbuffers(
            got, ref.rasterize(pos, cam, W, H, colors=colors, soft_z=soft_z, point_size=point_size)
        )
    if point_size == 1:
        np.testing.assert_array_equal(want_vis, ref.visibility(pos, cam, W, H))
    else:
        assert got.covered.sum() > r.render(cam, W, H).covered.sum()
        assert got.covered[0].any() and got.covered[-1].any()  # edges reached, clipped
        assert got.covered[:, 0].any() and got.covered[:, -1].any()


def test_point_size_square(device):
    """One point: its square, with the documented offset for even sizes, and
    clipped at the image's corner."""
    q = runtime.queue_for(device)
    cam = Camera.ortho((0, 0, 5), (0, 0, 0), (0, 1, 0), height=2.0, aspect=1.0, near=0.5, far=10)
    centre = np.array([[0.01, -0.01, 0]], np.float32)  # pixel (8, 8) of 16 x 16
    corner = np.array([[-0.99, 0.99, 0]], np.float32)  # pixel (0, 0)
    for n, (lo, hi) in {1: (8, 8), 2: (8, 9), 3: (7, 9), 4: (7, 10), 5: (6, 10)}.items():
        g = clvis.rasterize(centre, cam, 16, 16, point_size=n, queue=q)
        ys, xs = np.nonzero(g.covered)
        assert (ys.min(), ys.max(), xs.min(), xs.max()) == (lo, hi, lo, hi), n
        g = clvis.rasterize(corner, cam, 16, 16, point_size=n, queue=q)
        assert g.covered.sum() == (n // 2 + 1) ** 2, n


def test_point_size_bad(queue):
    pos = _scene(10)
    for bad in (0, 65, -1):
        with pytest.raises(ValueError, match=r"point_size: .* outside \[1, 64\]"):
            clvis.rasterize(pos, _cam(), W, H, point_size=bad, queue=queue)
    for bad in (2.0, True, "3"):
        with pytest.raises(TypeError, match="point_size"):
            clvis.rasterize(pos, _cam(), W, H, point_size=bad, queue=queue)


# ---------------------------------------------------------------------------
# non-finite points, image bounds, singular cameras


def test_nonfinite_counted(queue):
    pos = _scene(30_000, seed=31)
    pos[::7, 1] = np.nan
    pos[5::11, 2] = np.inf
    pos[:5000] = -np.inf  # whole batches
    want = ref.nonfinite(pos)
    assert want > 5000
    for morton in (False, True):
        r = clvis.Rasterizer(pos, morton=morton, batch_size=1024, queue=queue)
        assert r.render(_cam(), W, H).stats["points_nonfinite"] == want == r.nonfinite
    assert clvis.rasterize(_scene(100), _cam(), W, H, queue=queue).stats["points_nonfinite"] == 0
    empty = clvis.rasterize(np.zeros((0, 3), np.float32), _cam(), W, H, queue=queue)
    assert empty.stats["points_nonfinite"] == 0


def test_image_pixels_bounded(monkeypatch, queue):
    """W x H must stay below 2^31 (32-bit pixel indices), whatever the side limit."""
    from clvis.limits import RASTER, ImageLimits
    from clvis.raster import inputs

    monkeypatch.setattr(inputs, "LIMITS", ImageLimits(1 << 20, RASTER.max_pixels, RASTER.why))
    with pytest.raises(ValueError, match=r"width x height: 65536x32768 = 2147483648 pixels"):
        clvis.rasterize(_scene(10), _cam(), 65536, 32768, queue=queue)


def test_singular_camera(queue):
    import dataclasses

    pos = _scene(100)
    cam = _cam()
    flat = np.array(cam.projection)
    flat[1, 1] = 0.0  # zero height
    bad_view = np.array(cam.view)
    bad_view[2, :3] = bad_view[0, :3]  # two equal axes
    huge = np.array(cam.projection)
    huge[0, 0] = 1e39  # overflows float32
    # a clvis.Camera refuses a singular projection @ view where it is made; the
    # rasterizer checks what reaches it (duck-typed cameras too)
    cases = [
        (lambda: dataclasses.replace(cam, projection=np.zeros((4, 4))), "projection is singular"),
        (lambda: dataclasses.replace(cam, projection=flat), "projection is singular"),
        (lambda: dataclasses.replace(cam, view=bad_view), "view matrix is singular"),
        # 1e39: refused where it is made (ill-conditioned), else as beyond float32
        (lambda: dataclasses.replace(cam, projection=huge), "(projection is singular|overflows float32)"),
    ]

    class NaNCamera:
        matrix = np.full((4, 4), np.nan)
        depth_row = np.zeros(4)
        projection = np.eye(4)
        near, far = 0.1, 10.0

    class SingularCamera:  # not a clvis.Camera: checked by raster
        matrix = np.zeros((4, 4))
        depth_row = np.array([0.0, 0.0, -1.0, 0.0])
        projection = np.zeros((4, 4))
        near, far = 0.1, 10.0

    cases.append((NaNCamera, "must be finite"))
    cases.append((SingularCamera, "projection is singular"))
    for make, msg in cases:
        with pytest.raises(clvis.DataError, match=f"camera: .*{msg}"):
            clvis.rasterize(pos, make(), W, H, queue=queue)
    with pytest.raises(ValueError, match="target: must differ from eye"):
        Camera.look_at((1, 2, 3), (1, 2, 3))
    far_away = Camera.look_at((5e5, 5e6, 300), (5e5 + 100, 5e6 + 100, 0), aspect=W / H, near=1, far=1000)
    clvis.rasterize(pos + np.float32([5e5, 5e6, 0]), far_away, W, H, queue=queue)  # UTM-like: fine
