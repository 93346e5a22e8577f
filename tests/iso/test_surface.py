"""clvis.iso.surface: a second field at the hits (sample_hits, surface.cl)
against clvis.reference.iso.surface on every device, what it means (the
volume itself sampled at its hits gives the isovalue; a linear field gives
the hit's world coordinate), surface colours and several isovalues composited
by depth, and the bad-input errors.

Tolerance: the kernel works in float32 and the reference in float64 from the
same float32 rays, t and field: VALUE_TOLERANCE of the field's range plus its
change over POSITION_TOLERANCE index units; NaN exactly where the reference's
is, save hits within float32 rounding of the field box's edge (none here: the
fields below cover the volume box with room to spare or exactly)."""

import dataclasses

import numpy as np
import pyopencl.array as cla
import pytest

from clvis import Camera, datasets, iso, zfp
from clvis.reference.iso import surface as ref

W, H = 48, 40
_ML = datasets.marschner_lobb(33)


def _cam(eye=(2.2, -2.6, 1.8)):
    return Camera.look_at(eye, (0, 0, 0), (0, 0, 1), fov_y=40, aspect=W / H, near=0.05, far=20)


@pytest.fixture(scope="module")
def rendered():
    """(volume decoded, renderer inputs, {isovalue: host image}) on the default queue."""
    d = _ML
    zv = zfp.compress(d["volume"], 16)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"])
    imgs = {v: r.render(_cam(), W, H, v) for v in (0.3, 0.5, 0.7)}
    return zfp.decode(zv), d, imgs


def _field(shape, seed):
    rng = np.random.default_rng(seed)
    z, y, x = np.meshgrid(*(np.linspace(0, 1, n) for n in shape), indexing="ij")
    return (np.sin(3 * x + 1) * np.cos(2 * y) + z**2 + 0.01 * rng.standard_normal(shape)).astype(np.float32)


def _check(image, cam, field, spacing, origin, queue):
    got = iso.sample_hits(image, cam, field, spacing, origin, queue=queue)
    want = ref.sample_hits(field, cam, W, H, image.hit, image.t, spacing, origin)
    assert got.dtype == np.float32 and got.shape == (H, W)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    f = np.asarray(field, np.float64)
    span = float(f.max() - f.min()) or 1.0
    slope = max(float(np.abs(np.diff(f, axis=a)).max()) for a in range(3))
    tol = ref.VALUE_TOLERANCE * span + slope * ref.POSITION_TOLERANCE
    ok = ~np.isnan(want)
    np.testing.assert_allclose(got[ok], want[ok], rtol=0, atol=tol)
    return got


@pytest.mark.parametrize("shape", [(2, 2, 2), (9, 13, 7), (33, 33, 33)])
def test_parity_on_the_volume_box(queue, rendered, shape):
    """A field of any grid stretched over the volume box."""
    _, d, imgs = rendered
    lo = np.asarray(d["origin"], np.float64)
    extent = (np.array(_ML["volume"].shape[::-1]) - 1) * np.asarray(d["spacing"])[::-1]
    spacing = tuple((extent / (np.array(shape[::-1]) - 1))[::-1])
    for v, img in imgs.items():
        got = _check(img, _cam(), _field(shape, int(v * 10)), spacing, tuple(lo), queue)
        assert (~np.isnan(got) == img.hit).all()  # every hit lies in the box


def test_parity_partly_outside(queue):
    """Synthetic planes: random hits and t, a field covering part of the
    view: NaN outside it, values inside."""
    rng = np.random.default_rng(5)
    hit = rng.random((H, W)) < 0.7
    t = np.where(hit, rng.uniform(1.0, 6.0, (H, W)), np.inf).astype(np.float32)
    t[0, :3] = np.nan  # a hit with a non-finite t: NaN
    planes = dict(
        rgba=np.zeros((H, W, 4), np.float32),
        depth=t.copy(),
        hit=hit,
        t=t,
        active=np.zeros((H, W), bool),
        completion=1.0,
        stats={},
    )
    img = iso.IsoImage(**planes)
    field = _field((11, 12, 13), 1)
    got = _check(img, _cam(), field, (0.1, 0.12, 0.09), (-0.8, -0.5, -0.6), queue)
    assert np.isnan(got).any() and (~np.isnan(got)).any()
    assert np.isnan(got[~hit]).all()
    # planes that are views (Fortran order, a float64 t): the same values
    views = dict(planes, hit=np.asfortranarray(hit), t=t.astype(np.float64))
    again = iso.sample_hits(
        iso.IsoImage(**views), _cam(), field, (0.1, 0.12, 0.09), (-0.8, -0.5, -0.6), queue=queue
    )
    np.testing.assert_array_equal(again, got)


def test_the_volume_at_its_hits_is_the_isovalue(queue, rendered):
    """The decoded volume sampled where its own isosurface was hit gives the
    isovalue (within the root finder's and float32's error)."""
    vol, d, imgs = rendered
    for v, img in imgs.items():
        got = iso.sample_hits(img, _cam(), vol, d["spacing"], d["origin"], queue=queue)
        assert img.hit.sum() > 50
        np.testing.assert_allclose(got[img.hit], v, atol=2e-3)


def test_linear_field_gives_world_coordinates(queue, rendered):
    """A field equal to the world x (trilinear interpolation is exact on it)
    gives each hit's world x: o + t d."""
    _, d, imgs = rendered
    img = imgs[0.5]
    x = np.linspace(-1.5, 1.5, 7, dtype=np.float32)
    field = np.broadcast_to(x[None, None, :], (5, 6, 7)).copy()
    got = iso.sample_hits(img, _cam(), field, (0.75, 0.6, 0.5), (-1.5, -1.5, -1.5), queue=queue)
    from clvis.camera import ray_buffer
    from clvis.reference.camera import camera_rays

    o, dirs = camera_rays(ray_buffer(_cam(), W, H), W, H)
    hx = (o[:, 0] + np.where(img.hit.ravel(), img.t.ravel(), 0) * dirs[:, 0]).reshape(H, W)
    np.testing.assert_allclose(got[img.hit], hx[img.hit], atol=1e-5)


def test_device_image_in_device_array_out(queue):
    d = _ML
    r = iso.IsoRenderer(d["volume"], rate=16, spacing=d["spacing"], origin=d["origin"], queue=queue)
    dev = r.render(_cam(), W, H, 0.5, host=False)
    field = _field((8, 8, 8), 2)
    got = iso.sample_hits(dev, _cam(), cla.to_device(queue, field), d["spacing"], d["origin"])
    assert isinstance(got, cla.Array) and got.shape == (H, W)
    host = dataclasses.replace(dev, hit=dev.hit.get(), t=dev.t.get())
    np.testing.assert_array_equal(
        got.get(), iso.sample_hits(host, _cam(), field, d["spacing"], d["origin"], queue=queue)
    )


def test_color_surface(rendered):
    _, _, imgs = rendered
    img = imgs[0.5]
    h = img.hit
    own = iso.color_surface(img)
    # the default colour is the renderer's: its own image back
    np.testing.assert_allclose(own[h], img.rgba[h], atol=1e-5)
    assert (own[~h] == 0).all() and (own[..., 3][h] == 1).all()
    red = iso.color_surface(img, (1.0, 0.0, 0.0))
    assert red[..., 0][h].max() > 0.5 and (red[..., 1] == red[..., 2]).all()  # the highlight stays white
    assert (red[..., 1][h] < red[..., 0][h]).all()
    # values: one colour per value through the colormap, NaN hits in nan_color
    vals = np.where(np.arange(W)[None, :] < W // 2, 0.0, 1.0) * np.ones((H, 1))
    vals[:5] = np.nan
    c = iso.color_surface(img, values=vals, colormap_name="gray", value_range=(0, 1), nan_color=(0, 0, 1))
    left, right = h.copy(), h.copy()
    left[:, W // 2 :] = right[:, : W // 2] = False
    left[:5] = right[:5] = False
    white, black = iso.color_surface(img, (1, 1, 1)), iso.color_surface(img, (0, 0, 0))
    assert left.any() and right.any()
    np.testing.assert_allclose(c[left], black[left], atol=1e-6)
    np.testing.assert_allclose(c[right], white[right], atol=1e-6)
    np.testing.assert_allclose(c[:5][h[:5]], iso.color_surface(img, (0, 0, 1))[:5][h[:5]], atol=1e-6)
    with pytest.raises(ValueError, match="color"):
        iso.color_surface(img, (2, 0, 0))
    with pytest.raises(ValueError, match="values"):
        iso.color_surface(img, values=np.zeros((3, 3)))


def test_composite_takes_the_nearest_hit(rendered):
    _, _, imgs = rendered
    a, b = imgs[0.3], imgs[0.7]
    both = iso.composite([a, b], colors=[(1, 0, 0), (0, 0, 1)])
    np.testing.assert_array_equal(both.hit, a.hit | b.hit)
    da, db = np.where(a.hit, a.depth, np.inf), np.where(b.hit, b.depth, np.inf)
    np.testing.assert_array_equal(both.depth, np.minimum(da, db))
    first = a.hit & (da <= db)
    second = b.hit & (db < da)
    assert first.any() and second.any()  # nested surfaces: each is in front somewhere
    red, blue = iso.color_surface(a, (1, 0, 0)), iso.color_surface(b, (0, 0, 1))
    np.testing.assert_array_equal(both.rgba[first], red[first])
    np.testing.assert_array_equal(both.rgba[second], blue[second])
    default = iso.composite([a, b])
    np.testing.assert_allclose(default.rgba[first], iso.color_surface(a)[first])
    planes = [np.full((H, W, 4), 0.25, np.float32), np.full((H, W, 4), 0.75, np.float32)]
    p = iso.composite([a, b], planes=planes)
    assert (p.rgba[first] == 0.25).all() and (p.rgba[second] == 0.75).all()
    assert iso.surface_colors(12)[0] == iso.SURFACE_COLOR and len(set(iso.surface_colors(10))) == 10
    # the candidate blocks left: summed over the isovalues, capped at CANDIDATES; None if one has none
    ca = np.arange(H * W).reshape(H, W).astype(np.uint8) % 7
    left = iso.composite([dataclasses.replace(a, candidates=ca), dataclasses.replace(b, candidates=ca)])
    np.testing.assert_array_equal(left.candidates, np.minimum(2 * ca, iso.CANDIDATES))
    assert iso.composite([a, dataclasses.replace(b, candidates=None)]).candidates is None
    # where the next candidate block begins: the nearest over the isovalues; None if one has none
    ta = np.linspace(1, 2, H * W, dtype=np.float32).reshape(H, W)
    tb = ta[::-1, ::-1].copy()
    tb[0, 0] = np.inf
    near = iso.composite([dataclasses.replace(a, next_t=ta), dataclasses.replace(b, next_t=tb)])
    np.testing.assert_array_equal(near.next_t, np.minimum(ta, tb))
    assert (
        iso.composite([dataclasses.replace(a, next_t=ta), dataclasses.replace(b, next_t=None)]).next_t is None
    )


def test_bad_arguments(rendered):
    vol, d, imgs = rendered
    img = imgs[0.5]
    with pytest.raises(TypeError, match="image"):
        iso.sample_hits(img.rgba, _cam(), vol)
    with pytest.raises(TypeError, match="camera"):
        iso.sample_hits(img, "cam", vol)
    with pytest.raises(ValueError, match="field"):
        iso.sample_hits(img, _cam(), vol[0])
    with pytest.raises(ValueError, match="field"):
        iso.sample_hits(img, _cam(), vol[:1])
    with pytest.raises(TypeError, match="field"):
        iso.sample_hits(img, _cam(), np.zeros((2, 2, 2), complex))
    with pytest.raises(ValueError, match="hit and t planes"):
        iso.sample_hits(dataclasses.replace(img, t=img.t[:3]), _cam(), vol)
    with pytest.raises(ValueError, match="spacing"):
        iso.sample_hits(img, _cam(), vol, (0, 1, 1))
    with pytest.raises(ValueError, match="images"):
        iso.composite(
            [img, iso.IsoImage(*(p[:2] for p in (img.rgba, img.depth, img.hit, img.t, img.active)), 1.0, {})]
        )
    with pytest.raises(ValueError, match="colors"):
        iso.composite([img, img], colors=[(1, 0, 0)])
    with pytest.raises(TypeError, match="images"):
        iso.composite([])


def test_the_image_records_its_camera(queue):
    """The renderer records the camera in every image it makes (render,
    passes, host=False, composite); sample_hits takes it when no camera is
    given, and the same values as with the camera passed."""
    d = _ML
    r = iso.IsoRenderer(d["volume"], rate=16, spacing=d["spacing"], origin=d["origin"], queue=queue)
    cam = _cam()
    img = r.render(cam, W, H, 0.5, tile_pixels=W * 8)
    assert img.camera is cam
    assert all(p.camera is cam for p in r.passes(cam, W, H, 0.5, tile_pixels=W * 8))
    dev = r.render(cam, W, H, 0.5, host=False)
    assert dev.camera is cam
    field = d["volume"][::-1].copy()  # a second field on the volume's grid
    want = iso.sample_hits(img, cam, field, d["spacing"], d["origin"], queue=queue)
    for got in (
        iso.sample_hits(img, None, field, d["spacing"], d["origin"], queue=queue),
        iso.sample_hits(img, field=field, spacing=d["spacing"], origin=d["origin"], queue=queue),
        iso.sample_hits(img, _cam(), field, d["spacing"], d["origin"], queue=queue),  # an equal camera
        iso.sample_hits(dev, field=field, spacing=d["spacing"], origin=d["origin"]).get(),
    ):
        np.testing.assert_array_equal(got, want)
    assert np.isfinite(want).any()
    assert iso.composite([img, r.render(cam, W, H, 0.3)]).camera is cam
    # a hand-made image records none: the composite neither
    bare = dataclasses.replace(img, camera=None)
    assert iso.composite([img, bare]).camera is None


def test_sample_hits_refuses_another_camera(rendered):
    """The Python-API trial's case: a camera made square (look_at's default
    aspect) for an image rendered at W x H, or another view, gave values at
    the wrong points, silently; now a ValueError naming the camera. A
    hand-made image without a camera needs one."""
    vol, d, imgs = rendered
    img = imgs[0.5]
    square = Camera.look_at((2.2, -2.6, 1.8), (0, 0, 0), (0, 0, 1), fov_y=40, near=0.05, far=20)  # aspect 1
    with pytest.raises(ValueError, match="not the camera the image was rendered with"):
        iso.sample_hits(img, square, vol, d["spacing"], d["origin"])
    others = (
        _cam().with_aspect(1.0),
        _cam(eye=(2.2, -2.6, 1.9)),
        Camera.look_at((2.2, -2.6, 1.8), (0, 0, 0), (0, 0, 1), fov_y=41, aspect=W / H, near=0.05, far=20),
    )
    for other in others:
        with pytest.raises(ValueError, match="not the camera the image was rendered with"):
            iso.sample_hits(img, other, vol, d["spacing"], d["origin"])
    bare = dataclasses.replace(img, camera=None)
    with pytest.raises(ValueError, match="records no camera"):
        iso.sample_hits(bare, None, vol, d["spacing"], d["origin"])
    with pytest.raises(ValueError, match="records no camera"):
        iso.sample_hits(bare, field=vol)
    # with its camera given, a hand-made image works as before
    np.testing.assert_array_equal(
        iso.sample_hits(bare, _cam(), vol, d["spacing"], d["origin"]),
        iso.sample_hits(img, field=vol, spacing=d["spacing"], origin=d["origin"]),
    )
    with pytest.raises(TypeError, match="field"):
        iso.sample_hits(img)
    with pytest.raises(TypeError, match="field goes third"):
        iso.sample_hits(img, vol)
    with pytest.raises(ValueError, match="different cameras"):
        iso.composite([img, dataclasses.replace(imgs[0.3], camera=others[1])])
