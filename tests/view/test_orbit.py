"""The viewer's orbit camera."""

import math

import numpy as np
import pytest

from clvis.view import Orbit


def test_fit_sees_the_whole_box():
    o = Orbit((-1, -2, 0), (1, 2, 3))
    cam = o.camera(16 / 9)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-2, 2) for z in (0, 3)], np.float64)
    p = cam.project(corners, 640, 360)
    assert p.visible.all()
    assert np.allclose(o.target, (0, 0, 1.5))


def test_orbit_turns_around_the_target_and_keeps_the_distance():
    o = Orbit((0, 0, 0), (1, 1, 1))
    eye0, d0 = o.eye.copy(), np.linalg.norm(o.eye - o.target)
    o.orbit(100, 0, 400)  # a quarter of the height: 45 degrees of azimuth
    assert math.isclose(np.linalg.norm(o.eye - o.target), d0)
    cosang = np.dot(eye0[:2] - o.target[:2], o.eye[:2] - o.target[:2])
    cosang /= np.linalg.norm(eye0[:2] - o.target[:2]) * np.linalg.norm(o.eye[:2] - o.target[:2])
    assert math.isclose(cosang, math.cos(math.radians(45)), rel_tol=1e-9)
    o.orbit(0, 10_000, 400)  # elevation clamps short of the pole
    assert o.elevation == 89.0
    o.camera(1.0)  # still a valid camera


def test_pan_moves_target_and_eye_together_and_zoom_keeps_the_target():
    o = Orbit((0, 0, 0), (1, 1, 1))
    off = o.eye - o.target
    o.pan(30, -20, 300)
    assert np.allclose(o.eye - o.target, off)
    t = o.target.copy()
    o.zoom(0.5)
    assert np.allclose(o.target, t) and math.isclose(
        np.linalg.norm(o.eye - o.target), np.linalg.norm(off) / 2
    )
    with pytest.raises(ValueError, match="zoom factor"):
        o.zoom(0)


def test_typed_camera_round_trips_and_its_cli_options():
    o = Orbit((0, 0, 0), (10, 10, 10))
    o.set((20, 5, 8), (5, 5, 5), 30)
    assert np.allclose(o.eye, (20, 5, 8)) and np.allclose(o.target, (5, 5, 5))
    s = o.state()
    assert s["cli"].startswith("--eye 20,5,8 --target 5,5,5 --up 0,0,1 --fov 30")
    with pytest.raises(ValueError, match="same point"):
        o.set((1, 1, 1), (1, 1, 1))


def test_one_point_is_framed_from_a_distance_and_zooms():
    """All points in one place: no size to frame; the view stands off (a unit
    sphere around the point) and the wheel changes the distance."""
    o = Orbit((5, 5, 5), (5, 5, 5), points=np.array([[5.0, 5.0, 5.0]]))
    assert o.radius == 1.0 and 1.0 < o.distance < 5.0
    d = o.distance
    o.zoom(0.5)
    assert math.isclose(o.distance, d / 2)
    cam = o.camera(16 / 9)
    p = cam.project(np.array([[5.0, 5.0, 5.0]]), 160, 90)
    assert p.visible.all() and abs(p.sx[0] - 80) < 1 and abs(p.sy[0] - 45) < 1


@pytest.mark.parametrize("scale", [1e-7, 1e-10])
def test_a_micro_scale_box_is_framed_as_at_unit_scale(scale):
    """A box 1e-7 wide (nanometre data in metres) fills the view as the same
    box 1 wide does: it was taken for one point (extent under an absolute
    1e-6), given a unit sphere and drawn as a dot."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-2, 2) for z in (0, 3)], np.float64)

    def screen(s):
        cam = Orbit((-s, -2 * s, 0), (s, 2 * s, 3 * s)).camera(16 / 9)
        p = cam.project(corners * s, 640, 360)
        assert p.visible.all()
        return np.c_[p.sx, p.sy]

    np.testing.assert_allclose(screen(scale), screen(1.0), atol=1e-2)
