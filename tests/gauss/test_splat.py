"""GaussianRenderer(model="splat") (splat.cl) against the float64 reference
clvis.reference.gauss.splat, on every device and both work shapes. Tolerance
1e-5 per channel: float32 projection and exp against float64."""

import numpy as np
import pytest

from clvis.camera import Camera
from clvis.colormap import TransferFunction
from clvis.gauss import render as gr
from clvis.gauss.gaussians import Gaussians
from clvis.gauss.points import gaussians_from_points
from clvis.gauss.tiles import projection_rows
from clvis.reference.gauss import splat as ref

from .test_render import _cam, _coloured, _random

W, H = 37, 29


def _check(queue, g, cam, w=W, h=H, tf=None, max_keys=None):
    tf = tf or TransferFunction("jet")
    img = gr.GaussianRenderer(g, tf, model="splat", queue=queue).render(cam, w, h, max_keys=max_keys)
    vmin, scale = tf.limits(g.values)
    rgba, depth, count = ref.render(
        g.means,
        g.scales,
        g.rotations,
        g.values,
        g.opacities,
        projection_rows(cam, w, h),
        cam.near,
        w,
        h,
        tf.table(),
        vmin,
        scale,
        colors=g.colors,
    )
    np.testing.assert_allclose(img.rgba, rgba, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(img.hits, count)
    fin = np.isfinite(depth)
    np.testing.assert_array_equal(np.isfinite(img.depth), fin)
    np.testing.assert_allclose(img.depth[fin], depth[fin], rtol=1e-6)
    return img, rgba


@pytest.mark.parametrize("colored", [False, True], ids=["tf", "own"])
def test_random_scene(queue, colored):
    g = _random(300, seed=1)
    if colored:
        g = _coloured(g, seed=3)
    img, rgba = _check(queue, g, _cam(w=W, h=H))
    assert (rgba[..., 3] > 0.1).mean() > 0.3 and img.stats["keys"] > 300
    assert img.stats["method"] == "tiles"


def test_opaque_stack_stops_at_1e4(queue):
    """Many opaque splats on one pixel: blending stops once T would drop below 1e-4."""
    n = 40
    g = Gaussians(
        np.column_stack([np.zeros(n), np.linspace(-2, 2, n), np.zeros(n)]),
        np.full((n, 3), 0.3),
        values=np.linspace(0, 1, n),
        opacities=np.full(n, 0.95),
    )
    img, rgba = _check(queue, g, _cam(eye=(0, -8, 0), w=16, h=16), w=16, h=16)
    assert 2 <= img.hits[8, 8] < n and rgba[8, 8, 3] > 1 - 1e-3


def test_near_plane_orthographic_bands(queue):
    """Means behind the near plane are culled (3DGS), orthographic cameras,
    and key bands give the same image."""
    g = _random(200, seed=5)
    _check(queue, g, _cam(eye=(0.0, -0.5, 0.0), target=(0, 1, 0), near=0.3, w=W, h=H))
    cam = Camera.ortho((0.2, -6, 0.5), (0, 0, 0), (0, 0, 1), height=5.0, aspect=W / H, near=0.5, far=20)
    _check(queue, g, cam)
    whole, _ = _check(queue, g, _cam(w=40, h=70), w=40, h=70)
    banded, _ = _check(queue, g, _cam(w=40, h=70), w=40, h=70, max_keys=60)
    assert banded.stats["key_bands"] > 1
    np.testing.assert_array_equal(banded.rgba, whole.rgba)


def test_point_clouds(queue):
    """NARVis's clouds: velocity-elongated and isotropic kNN Gaussians."""
    rng = np.random.default_rng(4)
    pts = rng.normal(size=(400, 3))
    vel = rng.normal(size=(400, 3))
    for g in (gaussians_from_points(pts, velocity=vel, stretch=4), gaussians_from_points(pts)):
        _check(queue, g, _cam(w=W, h=H))


def test_row_and_pixel_work_shapes_agree_bit_for_bit(queue):
    """splat_render8 (a row of 8 pixels a work-item, q in float8 lanes) gives
    splat_render's bits (a pixel a work-item), needles and bands included;
    the binning keeps only tiles the splat's ellipse meets."""
    from .test_tiles import _needles

    g = _needles(80, 7)
    cam = _cam(w=45, h=38)
    out = []
    for lanes in (1, 8):
        r = gr.GaussianRenderer(g, TransferFunction("jet"), model="splat", queue=queue)
        r.lanes = lanes
        out.append(r.render(cam, 45, 38, max_keys=200))
        assert out[-1].stats["lanes"] == lanes
    for a, b in ((out[0].rgba, out[1].rgba), (out[0].depth, out[1].depth), (out[0].hits, out[1].hits)):
        np.testing.assert_array_equal(a, b)
    img, rgba = _check(queue, g, cam, w=45, h=38)
    assert (rgba[..., 3] > 0.05).mean() > 0.1 and img.stats["keys"] > g.n


def test_binning_of_8_gaussians_a_work_item_agrees_bit_for_bit(queue):
    """splat_count8 / splat_keys8 (8 Gaussians a work-item in float8 lanes,
    taken with 8 lanes) give splat_count's and splat_keys's keys and ids,
    band by band: needles, Gaussians behind the near plane and counts that
    are not a multiple of 8 (the last work-item's idle lanes)."""
    from clvis.gauss.tiles import tile_lists

    from .test_tiles import _needles

    cams = (_cam(w=45, h=38), _cam(eye=(0.0, -0.5, 0.0), target=(0, 1, 0), near=0.3, w=45, h=38))
    for g in (_needles(83, 9), _random(301, seed=6), _random(5, seed=7)):
        for cam in cams:
            out = []
            for lanes in (1, 8):
                r = gr.GaussianRenderer(g, TransferFunction("jet"), model="splat", queue=queue)
                r.lanes = lanes
                out.append(tile_lists(r, cam, 45, 38, max_keys=150))
            assert sum(len(band[2]) for band in out[0]) > 0
            for one, eight in zip(*out, strict=True):
                assert one[:2] == eight[:2]
                for a, b in zip(one[2:], eight[2:], strict=True):
                    np.testing.assert_array_equal(a, b)


def test_bad_input(queue):
    g = _random(10)
    with pytest.raises(ValueError, match="needs method='tiles'"):
        gr.GaussianRenderer(g, model="splat", method="bvh", queue=queue)
    with pytest.raises(ValueError, match="max_response, absorption, splat"):
        gr.GaussianRenderer(g, model="gaussian", queue=queue)
