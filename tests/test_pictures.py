"""One image convention (clvis.images.Picture): every rendered image type has
to_uint8(background=None) -> (H, W, 4) uint8 RGBA, straight alpha, transparent
where empty (or over an RGB background, alpha 255) and save_png(path)."""

import numpy as np
import pytest
from PIL import Image

from clvis import Camera, datasets, images
from clvis.gauss import GaussianImage, GaussianRenderer, Gaussians
from clvis.iso import IsoImage, IsoRenderer
from clvis.raster import FilteredImage, GBuffers, Rasterizer, depth_filter

W, H = 48, 32
CAM = Camera.look_at((0.5, -2.5, 1.2), (0.5, 0.5, 0.5), (0, 0, 1), 40, W / H, near=0.1, far=10)


def _pictures(queue):
    rng = np.random.default_rng(0)
    p = rng.random((4000, 3)).astype(np.float32)
    colors = (rng.random((4000, 4)) * 255).astype(np.uint8)
    colors[:, 3] = 255
    g = Rasterizer(p, colors=colors, queue=queue).render(CAM, W, H)
    d = datasets.marschner_lobb(16)
    iso = IsoRenderer(d["volume"], spacing=(1 / 15,) * 3, queue=queue).render(CAM, W, H, 0.5)
    gs = Gaussians(p[:300], np.full((300, 3), 0.03), values=rng.random(300))
    gi = GaussianRenderer(gs, queue=queue).render(CAM, W, H)
    return {"gbuffers": g, "filtered": depth_filter(g, 2, queue=queue), "iso": iso, "gauss": gi}


def test_every_image_type_is_a_picture():
    for t in (GBuffers, FilteredImage, IsoImage, GaussianImage):
        assert issubclass(t, images.Picture)
        assert t.to_uint8 is not images.Picture.to_uint8, t


def test_to_uint8_and_save_png(queue, tmp_path):
    for name, img in _pictures(queue).items():
        a = img.to_uint8()
        assert a.dtype == np.uint8 and a.shape == (H, W, 4), name
        empty = a[..., 3] == 0
        assert empty.any() and (~empty).any(), name  # something drawn, something not
        assert (a[empty] == 0).all(), name  # empty pixels transparent black
        b = img.to_uint8(images.BACKGROUND)
        assert (b[..., 3] == 255).all(), name
        assert (b[empty][:, :3] == images.BACKGROUND).all(), name
        full = a[..., 3] == 255
        # alpha 255 after rounding (a Gaussian image's 0.999): colours within one level
        assert np.abs(b[full][:, :3].astype(int) - a[full][:, :3]).max() <= 1, name
        path = img.save_png(tmp_path / name / "x.png")
        with Image.open(path) as im:
            np.testing.assert_array_equal(np.asarray(im), a)
        with Image.open(img.save_png(tmp_path / f"{name}-bg.png", (255, 255, 255))) as im:
            assert np.asarray(im)[empty][:, :3].min() == 255


def test_the_conventions_agree():
    """The iso image's shading straight from rgba; the Gaussian image's
    premultiplied colour divided by alpha; the G-buffers' rgba copied."""
    rgba = np.zeros((2, 2, 4), np.float32)
    rgba[0, 0] = (0.25, 0.5, 1.0, 1.0)
    iso = IsoImage(
        rgba, np.zeros((2, 2)), np.eye(2, dtype=bool), np.zeros((2, 2)), np.zeros((2, 2), bool), 1, {}
    )
    a = iso.to_uint8()
    assert tuple(a[0, 0]) == (64, 128, 255, 255) and tuple(a[0, 1]) == (0, 0, 0, 0)
    assert tuple(a[1, 1]) == (0, 0, 0, 255)  # a hit shaded black stays a (black) hit
    g = GaussianImage(np.array([[[0.25, 0.0, 0.5, 0.5]]], np.float32), np.zeros((1, 1)), None, None)
    assert tuple(g.to_uint8()[0, 0]) == (128, 0, 255, 128)
    assert tuple(g.to_uint8((0, 0, 0))[0, 0]) == (64, 0, 128, 255)
    with pytest.raises(ValueError, match="background"):
        g.to_uint8((0, 0, 300))


@pytest.mark.parametrize("bg", [(1.0, 1.0, 1.0), (0.5, 0.5, 0.5), np.array([1.0, 1.0, 1.0]), (True, 0, 0)])
def test_a_float_background_is_refused_not_drawn_near_black(bg):
    """background=(1.0, 1.0, 1.0), white to a matplotlib or Open3D user, was
    taken as (1, 1, 1): a near-black background."""
    g = GaussianImage(np.array([[[0.25, 0.0, 0.5, 0.5]]], np.float32), np.zeros((1, 1)), None, None)
    with pytest.raises(ValueError, match="background"):
        g.to_uint8(bg)
    assert tuple(g.to_uint8(np.array([255, 255, 255]))[0, 0])[3] == 255  # integer arrays still do


def test_a_background_or_surface_colour_may_be_named():
    """background="white" and color="red", as PyVista and matplotlib take
    them: the background was refused as not three integers, and
    color_surface(img, "red") gave numpy's "could not convert string to
    float" without naming the argument."""
    from clvis.iso import color_surface

    g = GaussianImage(np.array([[[0.25, 0.0, 0.5, 0.5]]], np.float32), np.zeros((1, 1)), None, None)
    assert tuple(g.to_uint8("white")[0, 0]) == tuple(g.to_uint8((255, 255, 255))[0, 0])
    assert tuple(g.to_uint8("#1e1e1e")[0, 0]) == tuple(g.to_uint8((30, 30, 30))[0, 0])
    with pytest.raises(
        ValueError, match=r"background: 'whit' is not a colour name or #rrggbb; did you mean white"
    ):
        g.to_uint8("whit")
    rgba = np.zeros((1, 2, 4), np.float32)
    rgba[0, 0] = (0.0, 1.0, 0.0, 1.0)  # a hit facing the eye
    iso = IsoImage(
        rgba, np.zeros((1, 2)), np.array([[True, False]]), np.zeros((1, 2)), np.zeros((1, 2), bool), 1, {}
    )
    np.testing.assert_array_equal(color_surface(iso, "red"), color_surface(iso, (1.0, 0.0, 0.0)))
    with pytest.raises(ValueError, match="color: 'redd' is not a colour name"):
        color_surface(iso, "redd")
    with pytest.raises(ValueError, match=r"color: expected \(r, g, b\) in 0..1 or a colour name"):
        color_surface(iso, [1, "a", 2])


def test_an_images_repr_is_one_line_of_shapes_not_its_pixels():
    """repr(img) in a notebook printed every plane's numbers (the dataclass
    repr): dozens of lines for a 64x64 GBuffers."""
    g = GaussianImage(
        np.zeros((48, 64, 4), np.float32), np.zeros((48, 64), np.float32), None, None, {"k": 64}
    )
    assert repr(g) == (
        "GaussianImage(rgba=<48x64x4 float32>, depth=<48x64 float32>, "
        "hits=None, rounds=None, stats={'k': 64})"
    )
    stats = {f"key{i}": list(range(10)) for i in range(20)}
    iso = IsoImage(
        np.zeros((2, 3, 4)),
        np.zeros((2, 3)),
        np.zeros((2, 3), bool),
        np.zeros((2, 3)),
        np.zeros((2, 3), bool),
        1,
        stats,
    )
    r = repr(iso)
    assert "\n" not in r and "hit=<2x3 bool>" in r and "stats={20 entries: key0, key1" in r and len(r) < 400


def test_the_renderers_repr_says_what_they_hold():
    """repr(Rasterizer(...)) was '<clvis.raster.render.Rasterizer object at 0x...>'."""
    pos = np.random.default_rng(0).random((10, 3)).astype(np.float32)
    r = Rasterizer(pos, attributes={"h": pos[:, 2]})
    assert repr(r).startswith("Rasterizer(10 points, attributes=['h'], device=")
    iso = IsoRenderer(datasets.marschner_lobb(8)["volume"], spacing=(1.0, 2.0, 3.0))
    assert repr(iso).startswith("IsoRenderer(shape=(8, 8, 8), rate=8, spacing=(1.0, 2.0, 3.0), origin=(0.0,")
    g = GaussianRenderer(Gaussians(pos, np.full((10, 3), 0.1), values=pos[:, 0]))
    assert repr(g).startswith("GaussianRenderer(10 Gaussians, model='max_response'")
