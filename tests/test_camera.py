"""Camera matrices, the float32 pixel convention, the viewpoint samplers, bad input."""

import math
import warnings

import numpy as np
import pytest

import clvis
from clvis.camera import (
    Camera,
    _projection_aspect,
    aspect_checked,
    axis_camera,
    check_aspect,
    grid_cameras,
    hemisphere_cameras,
)
from clvis.errors import AspectWarning


def _h(m, p):
    """m @ [p, 1] in float64."""
    return m @ np.append(np.asarray(p, dtype=np.float64), 1.0)


# ---------------------------------------------------------------- matrices


def test_look_at_basis_and_translation():
    cam = Camera.look_at((1, 2, 3), (1, 7, 3), up=(0, 0, 1))
    # looking along +y with z up: right is +x
    np.testing.assert_allclose(cam.view[:3, :3], [[1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=1e-15)
    np.testing.assert_allclose(_h(cam.view, (1, 2, 3)), [0, 0, 0, 1], atol=1e-15)  # eye -> origin
    np.testing.assert_allclose(_h(cam.view, (1, 6, 3))[:3], [0, 0, -4], atol=1e-15)  # ahead -> -z
    np.testing.assert_allclose(cam.forward, [0, 1, 0], atol=1e-15)
    np.testing.assert_array_equal(cam.eye, [1, 2, 3])
    assert not cam.orthographic


def test_view_is_rigid():
    cam = Camera.look_at((3, -2, 5), (-1, 4, 0.5), up=(0.1, 0.2, 1))
    r = cam.view[:3, :3]
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(r) == pytest.approx(1.0)  # right-handed
    np.testing.assert_array_equal(cam.view[3], [0, 0, 0, 1])


@pytest.mark.parametrize("d", [0.1, 0.5, 3.0, 99.0, 100.0])
def test_perspective_depth_is_clip_w(d):
    near, far = 0.1, 100.0
    cam = Camera.look_at((2, 1, 1), (2, 1, -5), up=(0, 1, 0), fov_y=45, aspect=1.5, near=near, far=far)
    p = (2, 1, 1 - d)  # on the view axis, d in front
    clip = _h(cam.matrix, p)
    assert clip[3] == pytest.approx(d)
    assert cam.depth_row @ np.append(p, 1) == pytest.approx(d)
    np.testing.assert_allclose(clip[:2], 0, atol=1e-12)
    ndc_z = clip[2] / clip[3]
    if d == near:
        assert ndc_z == pytest.approx(-1)
    elif d == far:
        assert ndc_z == pytest.approx(1)
    else:
        assert -1 < ndc_z < 1


def test_perspective_field_of_view():
    fov, aspect = 50.0, 2.0
    cam = Camera.look_at((0, 0, 0), (0, 0, -1), up=(0, 1, 0), fov_y=fov, aspect=aspect)
    t = math.tan(math.radians(fov / 2))
    top = _h(cam.matrix, (0, 3 * t, -3))  # on the top edge at depth 3
    right = _h(cam.matrix, (3 * t * aspect, 0, -3))  # on the right edge
    assert top[1] / top[3] == pytest.approx(1)
    assert right[0] / right[3] == pytest.approx(1)
    assert cam.focal_px(480) == pytest.approx(240 / t)


def test_orthographic():
    cam = Camera.ortho((0, 0, 10), (0, 0, 0), up=(0, 1, 0), height=4.0, aspect=2.0, near=-1, far=20)
    assert cam.orthographic
    for p in [(0, 0, 0), (4, 2, 5), (-4, -2, -9)]:
        clip = _h(cam.matrix, p)
        assert clip[3] == 1.0
        assert cam.depth_row @ np.append(p, 1) == pytest.approx(10 - p[2])
    np.testing.assert_allclose(_h(cam.matrix, (4, 2, 0))[:2], [1, 1])  # width 8, height 4
    np.testing.assert_allclose(_h(cam.matrix, (0, 0, 11))[2], -1)  # depth -1 = near
    np.testing.assert_allclose(_h(cam.matrix, (0, 0, -10))[2], 1)  # depth 20 = far
    assert cam.focal_px(100) == pytest.approx(25)  # 100 px for 4 units


def test_camera_is_immutable():
    cam = Camera.look_at((1, 0, 0), (0, 0, 0))
    with pytest.raises(AttributeError):
        cam.near = 1.0
    with pytest.raises(ValueError):
        cam.view[0, 0] = 2.0
    assert cam.matrix.dtype == np.float64 and cam.depth_row.shape == (4,)


# ---------------------------------------------------------------- pixel convention


def test_pixel_convention():
    cam = Camera.look_at((0, 0, 5), (0, 0, 0), up=(0, 1, 0), fov_y=90)
    w, h = 64, 48
    r = cam.project(np.array([[0, 0, 0], [0, 1, 0], [0, -1, 0], [1, 0, 0], [-1, 0, 0]]), w, h)
    assert (r.sx[0], r.sy[0]) == (w / 2, h / 2)
    assert (r.px[0], r.py[0]) == (w // 2, h // 2)
    assert r.py[1] < h / 2 < r.py[2]  # above the axis: a row near the top
    assert r.px[4] < w / 2 < r.px[3]  # right of the axis: a column on the right
    assert r.visible.all()
    np.testing.assert_array_equal(r.depth, 5)
    assert r.sx.dtype == r.sy.dtype == r.depth.dtype == np.float32
    assert r.px.dtype == r.py.dtype == np.int32


def test_pixel_edges_half_open():
    cam = Camera.ortho((0, 0, 1), (0, 0, 0), up=(0, 1, 0), height=2.0, near=0, far=2)
    # ndc -1 and +1 exactly: the left/top edges are in, the right/bottom edges out
    r = cam.project(np.array([[-1, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0]]), 8, 8)
    np.testing.assert_array_equal(r.sx, [0, 8, 4, 4])
    np.testing.assert_array_equal(r.sy, [4, 4, 0, 8])
    np.testing.assert_array_equal(r.visible, [True, False, True, False])
    np.testing.assert_array_equal(r.px, [0, -1, 4, -1])


def _f32(v):
    """A Python float rounded to float32 (double rounding from a double result is
    exact for +, -, *, / of float32 operands)."""
    return float(np.float32(v))


def _div(a, b):
    if b == 0:
        if a == 0 or math.isnan(a):
            return math.nan
        return math.copysign(math.inf, a) * math.copysign(1.0, b)
    return a / b


def _project_scalar(cam, p, w, h):
    """The spec of Camera.project, one point at a time in Python floats."""
    m = [[_f32(v) for v in row] for row in cam.matrix]
    d = [_f32(v) for v in cam.depth_row]
    x, y, z = (_f32(v) for v in p)

    def dot(r):
        return _f32(_f32(_f32(_f32(r[0] * x) + _f32(r[1] * y)) + _f32(r[2] * z)) + r[3])

    cx, cy, cw, depth = dot(m[0]), dot(m[1]), dot(m[3]), dot(d)
    r = _f32(_div(1.0, cw))
    sx = _f32(_f32(_f32(_f32(cx * r) * 0.5) + 0.5) * w)
    sy = _f32(_f32(0.5 - _f32(_f32(cy * r) * 0.5)) * h)
    vis = (
        all(math.isfinite(v) for v in (x, y, z))
        and _f32(cam.near) <= depth <= _f32(cam.far)
        and cw > 0
        and 0 <= sx < w
        and 0 <= sy < h
    )
    return sx, sy, (math.floor(sx) if vis else -1), (math.floor(sy) if vis else -1), depth, vis


def _same_f32(a, b):
    a, b = np.float32(a), np.float32(b)
    return (np.isnan(a) and np.isnan(b)) or a.view(np.uint32) == b.view(np.uint32)


def _adversarial_points(cam, w, h, rng):
    fwd, eye = cam.forward, cam.eye
    right, up = cam.view[0, :3], cam.view[1, :3]
    pts = [
        eye + fwd * rng.uniform(cam.near, cam.far, 1)[0] + right * rng.normal(0, 20) + up * rng.normal(0, 20)
        for _ in range(200)
    ]
    pts += [
        eye + fwd * cam.near,
        eye + fwd * cam.far,  # near/far planes
        eye + fwd * np.nextafter(cam.near, 0),
        eye + fwd * np.nextafter(cam.far, np.inf),
        eye,
        eye - fwd * 3,
        eye - fwd * 3 + right,
        eye + right,  # behind, at the eye plane
        [np.nan, 0, 0],
        [0, np.inf, 0],
        [0, 0, -np.inf],
        [1e38, 1e38, 1e38],
        [-3e38, 0, 0],
    ]
    # points aimed at pixel edges: ndc = 2 k / W - 1 exactly, at a few depths
    inv = np.linalg.inv(cam.matrix)
    for k in [0, 1, w // 2, w - 1, w]:
        for j in [0, 1, h // 3, h - 1, h]:
            for depth in [cam.near, 1.0, 0.5 * (cam.near + cam.far), cam.far]:
                ndc = np.array([2 * k / w - 1, 1 - 2 * j / h])
                q = inv @ np.array([ndc[0] * depth, ndc[1] * depth, 0, depth])
                q = q[:3] / q[3]
                q = eye + (q - eye) * depth / (fwd @ (q - eye))
                pts.append(q)
    return np.array(pts, dtype=np.float64)


@pytest.mark.parametrize("kind", ["perspective", "orthographic"])
def test_project_bit_exact(kind):
    rng = np.random.default_rng(7)
    w, h = 640, 361
    if kind == "perspective":
        cam = Camera.look_at(
            (3.3, -7.1, 2.9), (0.2, 0.4, -0.3), up=(0, 0, 1), fov_y=55, aspect=w / h, near=0.7, far=90.0
        )
    else:
        cam = Camera.ortho(
            (3.3, -7.1, 2.9), (0.2, 0.4, -0.3), up=(0, 0, 1), height=31.0, aspect=w / h, near=0.7, far=90.0
        )
    pts = _adversarial_points(cam, w, h, rng)
    r = cam.project(pts, w, h)
    assert 0 < r.visible.sum() < len(pts)
    assert r.px[r.visible].max() <= w - 1 and r.py[r.visible].max() <= h - 1
    with np.errstate(all="ignore"):
        for i, p in enumerate(pts):
            sx, sy, px, py, depth, vis = _project_scalar(cam, p, w, h)
            assert _same_f32(r.sx[i], sx), (i, p, r.sx[i], sx)
            assert _same_f32(r.sy[i], sy), (i, p, r.sy[i], sy)
            assert _same_f32(r.depth[i], depth), (i, p)
            assert (bool(r.visible[i]), int(r.px[i]), int(r.py[i])) == (vis, px, py), (i, p)


def test_project_empty_and_dtypes():
    cam = Camera.look_at((5, 0, 0), (0, 0, 0))
    r = cam.project(np.zeros((0, 3)), 4, 4)
    assert r.sx.shape == r.px.shape == r.visible.shape == (0,)
    r64 = cam.project(np.array([[0.1, 0.2, 0.3]]), 4, 4)
    r32 = cam.project(np.array([[0.1, 0.2, 0.3]], dtype=np.float32), 4, 4)
    assert r64.sx[0] == r32.sx[0]
    assert cam.project([[1, 2, 3]], 4, 4).sx.dtype == np.float32


# ---------------------------------------------------------------- fit and samplers


@pytest.mark.parametrize(
    "lo,hi", [((0, 0, 0), (10, 5, 2)), ((-1e3, 2e3, 7), (-1e3 + 1, 2e3 + 4, 7)), ((1, 1, 1), (1, 1, 1))]
)
@pytest.mark.parametrize("aspect", [0.5, 1.0, 2.5])
@pytest.mark.parametrize("fov", [20.0, 60.0, 150.0])
def test_fit_frames_the_box(lo, hi, aspect, fov):
    cam = Camera.fit(lo, hi, fov_y=fov, aspect=aspect)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    centre = 0.5 * (np.array(lo) + np.array(hi))
    r = cam.project(np.vstack([corners, centre]), 100, 100)
    assert r.visible.all()
    np.testing.assert_allclose(cam.forward, -np.array([1, 1, 0.6]) / np.linalg.norm([1, 1, 0.6]))
    assert cam.forward @ (centre - cam.eye) > 0  # direction points from the eye to the centre


def _corners(lo, hi):
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


@pytest.mark.parametrize("lo,hi", [((0, 0, 0), (8, 4, 2)), ((-3, 5, 1), (3, 5, 1))])
def test_hemisphere_cameras(lo, hi):
    cams = list(hemisphere_cameras(lo, hi, fov_y=40, aspect=1.5))
    assert len(cams) == 4 * 32
    lo, hi = np.array(lo, float), np.array(hi, float)
    centre = 0.5 * (lo + hi)
    radius = 0.75 * np.linalg.norm(hi - lo)
    thetas, phis = set(), set()
    for cam in cams:
        assert np.linalg.norm(cam.eye - centre) == pytest.approx(radius)
        off = cam.eye - centre
        thetas.add(round(math.degrees(math.acos(off[2] / radius)), 6))
        phis.add(round(math.degrees(math.atan2(off[1], off[0])) % 360, 6))
        r = cam.project(centre[None], 300, 200)
        assert r.visible[0]
        assert (r.sx[0], r.sy[0]) == pytest.approx((150, 100), abs=1e-3)
        depth = _corners(lo, hi) @ cam.forward - cam.eye @ cam.forward
        assert (depth > cam.near).all() and (depth < cam.far).all()
    assert thetas == {22.5, 45.0, 67.5, 90.0}
    assert phis == {round(k * 11.25, 6) for k in range(32)}


def test_grid_cameras():
    lo, hi = np.array([0.0, 0, 0]), np.array([8.0, 4, 2])
    cams = list(grid_cameras(lo, hi, count=(4, 2), height=1.5))
    assert len(cams) == 4 * 2 * 8 * 3
    eyes = np.array([c.eye for c in cams])
    np.testing.assert_allclose(eyes[:, 2], 3.5)
    np.testing.assert_allclose(sorted(set(eyes[:, 0])), [1, 3, 5, 7])
    np.testing.assert_allclose(sorted(set(eyes[:, 1])), [1, 3])
    for i, cam in enumerate(cams[:24]):  # one position: yaw outer, pitch inner
        yaw, pitch = math.radians(45 * (i // 3)), math.radians((1, 30, 60)[i % 3])
        np.testing.assert_allclose(
            cam.forward,
            [math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw), -math.sin(pitch)],
            atol=1e-12,
        )
    for cam in cams:
        assert cam.view[1, 2] > 0  # z up stays up in the image
        far_corner = np.linalg.norm(_corners(lo, hi) - cam.eye, axis=1).max()
        assert cam.far >= far_corner
        on_axis = cam.eye + cam.forward * 0.5 * (cam.near + cam.far)
        r = cam.project(on_axis[None], 100, 100)
        assert r.visible[0] and (r.sx[0], r.sy[0]) == pytest.approx((50, 50), abs=1e-3)
    # every box corner and the centre are seen by some camera
    pts = np.vstack([_corners(lo, hi), 0.5 * (lo + hi)])
    seen = np.zeros(len(pts), bool)
    for cam in cams:
        seen |= cam.project(pts, 100, 100).visible
    assert seen.all()


def test_grid_spacing_and_flat_box():
    cams = list(grid_cameras((0, 0, 0), (10, 0, 0), spacing=3.0))  # flat in y and z
    assert len(cams) == 4 * 1 * 24
    assert len(list(grid_cameras((0, 0, 0), (0, 0, 0)))) == 24
    assert len(list(grid_cameras((0, 0, 0), (1, 1, 1)))) == 16 * 24


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "kwargs,name",
    [
        ({"eye": (1, 2, 3), "target": (1, 2, 3)}, "target"),
        ({"eye": (0, 0, 1), "target": (0, 0, 0)}, "up"),
        ({"eye": (0, 0, 1), "target": (0, 0, 0), "up": (0, 0, 0)}, "up"),
        ({"eye": (1, 0, 0), "target": (0, 0, 0), "fov_y": 0}, "fov_y"),
        ({"eye": (1, 0, 0), "target": (0, 0, 0), "fov_y": 180}, "fov_y"),
        ({"eye": (1, 0, 0), "target": (0, 0, 0), "aspect": 0}, "aspect"),
        ({"eye": (1, 0, 0), "target": (0, 0, 0), "aspect": np.inf}, "aspect"),
        ({"eye": (1, 0, 0), "target": (0, 0, 0), "near": 0}, "near"),
        ({"eye": (1, 0, 0), "target": (0, 0, 0), "near": -1}, "near"),
        ({"eye": (1, 0, 0), "target": (0, 0, 0), "near": 2, "far": 2}, "far"),
        ({"eye": (1, 0, 0), "target": (0, 0, 0), "far": np.nan}, "far"),
        ({"eye": (np.nan, 0, 0), "target": (0, 0, 0)}, "eye"),
        ({"eye": (1, 0), "target": (0, 0, 0)}, "eye"),
        ({"eye": (1, 0, 0), "target": (0, np.inf, 0)}, "target"),
    ],
)
def test_look_at_bad_input(kwargs, name):
    with pytest.raises(ValueError, match=name):
        Camera.look_at(**kwargs)


def test_ortho_bad_input():
    Camera.ortho((1, 0, 0), (0, 0, 0), near=-5, far=5)  # near may be <= 0
    with pytest.raises(ValueError, match="far"):
        Camera.ortho((1, 0, 0), (0, 0, 0), near=1, far=-1)
    with pytest.raises(ValueError, match="height"):
        Camera.ortho((1, 0, 0), (0, 0, 0), height=0)
    with pytest.raises(TypeError, match="height"):
        Camera.ortho((1, 0, 0), (0, 0, 0), height="2")


def test_project_bad_input():
    cam = Camera.look_at((1, 0, 0), (0, 0, 0))
    with pytest.raises(ValueError, match="points"):
        cam.project(np.zeros((5, 2)), 4, 4)
    with pytest.raises(TypeError, match="points"):
        cam.project(np.array([["a", "b", "c"]]), 4, 4)
    with pytest.raises(ValueError, match="width"):
        cam.project(np.zeros((1, 3)), 0, 4)
    with pytest.raises(TypeError, match="height"):
        cam.project(np.zeros((1, 3)), 4, 4.0)


@pytest.mark.parametrize("sampler", [grid_cameras, hemisphere_cameras, Camera.fit])
def test_sampler_bad_bounds(sampler):
    with pytest.raises(ValueError, match="bounds_max"):
        sampler((0, 0, 0), (1, -1, 1))  # raised on the call, before iterating
    with pytest.raises(ValueError, match="bounds_min"):
        sampler((0, np.nan, 0), (1, 1, 1))
    with pytest.raises(ValueError, match="bounds_max"):
        sampler((0, 0, 0), (1, 1))


def test_sampler_bad_options():
    with pytest.raises(ValueError, match="count"):
        grid_cameras((0, 0, 0), (1, 1, 1), count=0)
    with pytest.raises(ValueError, match="spacing"):
        grid_cameras((0, 0, 0), (1, 1, 1), spacing=-1.0)
    with pytest.raises(ValueError, match="far"):
        hemisphere_cameras((0, 0, 0), (1, 1, 1), near=5.0, far=1.0)
    with pytest.raises(ValueError, match="direction"):
        Camera.fit((0, 0, 0), (1, 1, 1), direction=(0, 0, 0))
    with pytest.raises(ValueError, match="up"):
        Camera.fit((0, 0, 0), (1, 1, 1), direction=(0, 0, -1))


def test_singular_cameras_are_refused():
    """A camera whose matrix cannot be inverted (its rays come from the
    inverse) is a clvis error naming the camera where it is made; ray_buffer
    refuses rays that are not finite in float32."""
    from clvis.camera import ray_buffer
    from clvis.errors import ClvisError

    good = Camera.look_at((3, 0, 0), (0, 0, 0))
    eye = np.zeros(3)
    for view, proj in [
        (np.zeros((4, 4)), good.projection),  # no view at all
        (good.view, np.diag([1.0, 1.0, 0.0, 0.0])),  # flattened projection
        (good.view, good.projection[[0, 0, 2, 3]]),
    ]:  # two rows alike
        with pytest.raises(ClvisError, match="camera: .*singular"):
            Camera(view, proj, 0.1, 10.0, False, eye)
        with pytest.raises(ValueError, match="camera"):
            Camera(view, proj, 0.1, 10.0, False, eye)
    with pytest.raises(ValueError, match="view"):
        Camera(np.full((4, 4), np.nan), good.projection, 0.1, 10.0, False, eye)
    with pytest.raises(ValueError, match="far"):
        Camera(good.view, good.projection, 10.0, 10.0, False, eye)
    for kwargs, name in [({"fov_y": 0}, "fov_y"), ({"aspect": 0}, "aspect"), ({"near": 1, "far": 1}, "far")]:
        with pytest.raises(ValueError, match=name):
            Camera.look_at((3, 0, 0), (0, 0, 0), **kwargs)
    with pytest.raises(ValueError, match="target"):
        Camera.look_at((1, 2, 3), (1, 2, 3))
    with pytest.raises(ValueError, match="parallel"):
        Camera.look_at((0, 0, 3), (0, 0, 0), up=(0, 0, 1))
    # a depth range of 2e39: ill-conditioned, refused where it is made
    with pytest.raises(ClvisError, match="camera: the projection is singular"):
        Camera.ortho((1e39, 0, 0), (0, 0, 0), near=-1e39, far=1e39)
    # an eye beyond float32's range (a well-formed camera, scale-free checks): its
    # rays overflow float32, or its matrix cannot even be inverted -- a clvis error
    with pytest.raises(ClvisError, match="camera: its (rays|matrix projection @ view cannot be inverted)"):
        ray_buffer(Camera.look_at((1e39, 0, 0), (0, 0, 0), near=1, far=10), 4, 4)
    assert np.isfinite(ray_buffer(good, 4, 4)).all()


# --------------------------------------------------------------------------
# framing a scene (the commands' default views)


def test_axis_camera_frames_the_box():
    from clvis.camera import AXIS_VIEWS, axis_camera, box_corners

    lo, hi = np.array([-3.0, 1.0, 0.5]), np.array([5.0, 2.0, 4.0])
    corners = box_corners(lo, hi)
    assert corners.shape == (8, 3) and (corners.min(axis=0) == lo).all() and (corners.max(axis=0) == hi).all()
    for kind in AXIS_VIEWS:
        for aspect in (0.5, 1.0, 16 / 9):
            cam = axis_camera(kind, lo, hi, aspect)
            assert cam.orthographic
            assert cam.project(corners, 160, int(160 / aspect)).visible.all(), (kind, aspect)
    with pytest.raises(ValueError, match="kind: expected one of top, front, side"):
        axis_camera("bottom", lo, hi)


def test_fit_camera_frames_the_points():
    from clvis.camera import fit_camera

    rng = np.random.default_rng(3)
    p = rng.normal(size=(5000, 3)) * [10.0, 10.0, 0.5]  # a flat cloud: Camera.fit leaves it small
    lo, hi = p.min(axis=0), p.max(axis=0)
    tight = fit_camera(p, lo, hi, direction=(1, 1, -0.5), fov_y=40, aspect=1.5)
    loose = Camera.fit(lo, hi, direction=(1, 1, -0.5), fov_y=40, aspect=1.5)
    pt, pl = tight.project(p, 300, 200), loose.project(p, 300, 200)
    assert pt.visible.all() and pl.visible.all()
    assert np.ptp(pt.sx) > 1.2 * np.ptp(pl.sx)  # fills more of the frame
    # one point (or none finite): Camera.fit's own framing
    one = np.array([[1.0, 2.0, 3.0]])
    got, want = fit_camera(one, one[0], one[0]), Camera.fit(one[0], one[0])
    np.testing.assert_array_equal(got.matrix, want.matrix)


@pytest.mark.parametrize("scale", [1e-6, 1e-9])
@pytest.mark.parametrize("offset", [0.0, -0.5])  # from the origin, and centred on it
def test_framing_is_the_same_at_any_scale(scale, offset):
    """A box of micrometre voxels given in metres (1e-5 wide) fills the frame
    as the same box in micrometres does: the floor on the framed radius is
    relative to the coordinates' magnitude. An absolute 1e-4 below magnitude
    1 drew it as a dot (Camera.fit, fit_camera and the axis views)."""
    from clvis.camera import axis_camera, fit_camera

    lo, hi = np.array([0.0, 0.0, 0.0]) + offset, np.array([10.0, 6.0, 4.0]) + offset

    def screens(s):
        corners = _corners(lo * s, hi * s)
        cams = [
            Camera.fit(lo * s, hi * s, aspect=1.5),
            fit_camera(corners, lo * s, hi * s, aspect=1.5),
            axis_camera("front", lo * s, hi * s, aspect=1.5),
        ]
        out = []
        for cam in cams:
            r = cam.project(corners, 300, 200)
            assert r.visible.all()
            out.append(np.c_[r.sx, r.sy])
        return out

    for unit, tiny in zip(screens(1.0), screens(scale), strict=True):
        np.testing.assert_allclose(tiny, unit, atol=1e-3)


@pytest.mark.parametrize(
    "point",
    [(0, 0, 0), (1e-6, 0, 0), (1e-12, 1e-12, 1e-12), (1e-300, 0, 0), (1e7, 1e7, 1e7), (-3e5, 4e6, 10)],
)
def test_one_point_gets_a_camera_at_any_scale(point):
    """One point (a box of no size) at the origin, at micro scale, below
    float32's range, or far from the origin: a finite camera that sees it
    in the middle of the picture, and finite float32 rays. (The top view of
    a point 4e6 from the origin framed 1e-3 of Camera.fit's floor, finer
    than float32 resolves there, and drew it off the picture.)"""
    from clvis.camera import axis_camera, fit_camera, ray_buffer

    p = np.array(point, np.float64)
    for cam in (Camera.fit(p, p), fit_camera(p[None], p, p), axis_camera("top", p, p)):
        assert np.isfinite(ray_buffer(cam, 8, 8)).all()
        r = cam.project(p[None], 100, 100)
        assert r.visible.all() and abs(r.sx[0] - 50) < 1 and abs(r.sy[0] - 50) < 1


def test_robust_bounds_leaves_out_stray_points():
    from clvis.camera import robust_bounds

    rng = np.random.default_rng(0)
    bulk = rng.uniform((698000, 6259000, 10), (699000, 6260000, 260), (20000, 3))
    p = np.concatenate([bulk, np.zeros((2, 3)), [[np.nan, 0, 0]]])
    rb = robust_bounds(p)
    assert rb.total == 20002 and rb.kept == 20000 and not rb.inside[-3:].any()
    np.testing.assert_array_equal(rb.lo, bulk.min(axis=0))
    np.testing.assert_array_equal(rb.hi, bulk.max(axis=0))
    # a uniform or Gaussian cloud keeps every point: its bounds are its min and max
    for cloud in (bulk, rng.standard_normal((50000, 3))):
        rb = robust_bounds(cloud)
        assert rb.kept == rb.total == len(cloud)
        np.testing.assert_array_equal(rb.hi, cloud.max(axis=0))
    # a flat cloud (z all one value) keeps its points
    flat = bulk.copy()
    flat[:, 2] = 5.0
    assert robust_bounds(flat).kept == len(flat)
    with pytest.raises(ValueError, match="no finite points"):
        robust_bounds(np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match="shape"):
        robust_bounds(np.zeros((3, 2)))


def test_point_spacing():
    from clvis.camera import point_spacing

    # a 100 x 100 grid seen from straight above, filling 1000 x 1000 pixels: 10 pixels apart
    g = np.stack(np.meshgrid(np.arange(100) + 0.5, np.arange(100) + 0.5), -1).reshape(-1, 2)
    p = np.concatenate([g, np.zeros((len(g), 1))], axis=1).astype(np.float32)
    cam = Camera.ortho((50, 50, 10), (50, 50, 0), (0, 1, 0), height=100, aspect=1.0, near=1, far=20)
    assert point_spacing(cam, p, 1000, 1000) == pytest.approx(10, rel=0.05)
    assert point_spacing(cam, p, 100, 100) == pytest.approx(1, rel=0.05)
    # nothing in view: 0
    away = Camera.ortho((500, 500, 10), (500, 500, 0), (0, 1, 0), height=10, aspect=1.0, near=1, far=20)
    assert point_spacing(away, p, 100, 100) == 0.0


# ---------------------------------------------------------------- aspect: one camera, one image shape

_EYE, _TARGET = (2.2, -2.6, 1.8), (0.0, 0.0, 0.0)


def test_aspect_is_the_projections():
    assert Camera.look_at(_EYE, _TARGET).aspect == 1.0  # the default
    assert Camera.look_at(_EYE, _TARGET, aspect=16 / 9).aspect == pytest.approx(16 / 9, rel=1e-15)
    assert Camera.ortho(_EYE, _TARGET, height=3, aspect=0.5).aspect == pytest.approx(0.5, rel=1e-15)
    assert Camera.fit((0, 0, 0), (1, 2, 3), aspect=2.5).aspect == pytest.approx(2.5, rel=1e-15)
    assert axis_camera("top", (0, 0, 0), (4, 1, 1), aspect=3.0).aspect == pytest.approx(3.0, rel=1e-15)
    # a projection that mixes x and y (an image rotated on screen, a projective x) has none
    c = Camera.look_at(_EYE, _TARGET)
    for i, j in ((0, 1), (1, 0), (3, 0)):
        p = np.array(c.projection)
        p[i, j] = 0.3
        assert Camera(c.view, p, c.near, c.far, False, c.eye).aspect is None
    # a mirrored projection keeps its ratio
    p = np.array(c.projection)
    p[0] *= -2.0
    assert Camera(c.view, p, c.near, c.far, False, c.eye).aspect == pytest.approx(0.5)
    # odd matrices: None, never inf or NaN (nor an exception)
    huge = np.diag([1e-320, 1e300, 1.0, 1.0])
    for m in (huge, np.diag([0.0, 1, 1, 1]), np.full((4, 4), np.nan), np.eye(3), "x", None):
        assert _projection_aspect(m) is None


@pytest.mark.parametrize(
    "make",
    [
        lambda a: Camera.look_at(_EYE, _TARGET, (0, 0, 1), 40, a, 0.05, 20),
        lambda a: Camera.ortho(_EYE, _TARGET, (0, 0, 1), 3.0, a, -1.0, 20),
        lambda a: Camera.fit((-1, -1, -1), (1, 1, 1), aspect=a),
    ],
    ids=["look_at", "ortho", "fit"],
)
def test_with_aspect_is_the_camera_made_for_that_aspect(make):
    """look_at / ortho / fit (aspect >= 1: the vertical extent decides the
    distance) made square, then given 640 / 360, are the cameras made for
    640 / 360, bit for bit: the same pictures."""
    square, wide = make(1.0), make(640 / 360)
    got = square.with_aspect(640 / 360)
    assert got.aspect == pytest.approx(640 / 360, rel=1e-15)
    np.testing.assert_array_equal(got.view, wide.view)
    np.testing.assert_array_equal(got.projection, wide.projection)
    np.testing.assert_array_equal(got.eye, square.eye)
    assert (got.near, got.far, got.orthographic) == (square.near, square.far, square.orthographic)
    assert got.focal_px(360) == square.focal_px(360)  # the vertical extent is kept
    back = got.with_aspect(1.0)
    np.testing.assert_array_equal(back.projection, square.projection)


def test_with_aspect_of_a_matrix_camera():
    """A camera made from matrices: the projection's x row scaled, the
    rest (view, y, depth) kept; one without an aspect cannot change it."""
    c = Camera.look_at(_EYE, _TARGET, fov_y=50, aspect=1.25, near=0.1, far=30)
    raw = Camera(c.view, c.projection, c.near, c.far, False, c.eye)
    got = raw.with_aspect(2.0)
    assert got.aspect == pytest.approx(2.0)
    np.testing.assert_allclose(
        got.projection,
        Camera.look_at(_EYE, _TARGET, fov_y=50, aspect=2.0, near=0.1, far=30).projection,
        rtol=1e-14,
    )
    np.testing.assert_array_equal(got.projection[1:], raw.projection[1:])
    np.testing.assert_array_equal(got.view, raw.view)
    p = np.array(c.projection)
    p[0, 1] = 0.3
    with pytest.raises(ValueError, match="no aspect"):
        Camera(c.view, p, c.near, c.far, False, c.eye).with_aspect(2.0)
    for bad in (0, -1.5, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="aspect"):
            c.with_aspect(bad)
    with pytest.raises(TypeError, match="aspect"):
        c.with_aspect("16/9")


def test_check_aspect_warns_beyond_one_percent():
    square = Camera.look_at(_EYE, _TARGET)  # aspect 1
    with pytest.warns(AspectWarning) as caught:
        check_aspect(square, 640, 360)
    assert len(caught) == 1
    text = str(caught[0].message)
    assert "1.778" in text and " 1 " in text and "640 x 360" in text
    assert "camera.with_aspect(640 / 360)" in text and "filterwarnings" in text
    assert caught[0].filename == __file__  # the caller's line, not clvis's
    assert issubclass(AspectWarning, UserWarning) and clvis.AspectWarning is AspectWarning
    with warnings.catch_warnings():
        warnings.simplefilter("error", AspectWarning)
        check_aspect(square, 360, 360)
        check_aspect(square, 101, 100)  # within 1 %
        check_aspect(square.with_aspect(640 / 360), 640, 360)
        check_aspect(Camera.look_at(_EYE, _TARGET, aspect=1.77), 640, 360)  # 0.4 %: rounding a size
        p = np.array(square.projection)
        p[0, 1] = 0.3  # no aspect: a projection made so on purpose is not checked
        check_aspect(Camera(square.view, p, square.near, square.far, False, square.eye), 640, 360)
        with aspect_checked():  # clvis's own renders of a camera already checked
            check_aspect(square, 640, 360)
    with pytest.warns(AspectWarning):
        check_aspect(square, 360, 640)  # and back on after it


def test_renderers_warn_once_per_render_of_a_stretched_camera():
    """Every public renderer given a camera of another aspect than the
    image's warns, once a call (not per tile or pass), at the caller's
    line; with the camera's with_aspect nothing is said; the warning can
    be filtered."""
    from clvis import datasets
    from clvis.gauss.points import gaussians_from_points

    W, H = 40, 22
    square = Camera.look_at(_EYE, _TARGET, (0, 0, 1), 40, 1.0, 0.05, 20)
    pos = np.random.default_rng(3).uniform(-1, 1, (200, 3)).astype(np.float32)
    ml = datasets.marschner_lobb(9)
    r = clvis.Rasterizer(pos)
    ir = clvis.IsoRenderer(ml["volume"], rate=16, spacing=ml["spacing"], origin=ml["origin"])
    gr = clvis.GaussianRenderer(gaussians_from_points(pos))
    renders = {
        "rasterize": lambda cam: clvis.rasterize(pos, cam, W, H),
        "Rasterizer.render": lambda cam: r.render(cam, W, H),
        "Rasterizer.visibility": lambda cam: r.visibility(cam, W, H),
        "IsoRenderer.render": lambda cam: ir.render(cam, W, H, 0.5, tile_pixels=W * 4),
        "IsoRenderer.passes": lambda cam: list(ir.passes(cam, W, H, 0.5, tile_pixels=W * 4)),
        "GaussianRenderer.render": lambda cam: gr.render(cam, W, H, tile_rows=8),
        "render_gaussians": lambda cam: clvis.render_gaussians(gaussians_from_points(pos), cam, W, H),
    }
    for name, render in renders.items():
        with pytest.warns(AspectWarning, match=r"camera\.with_aspect\(40 / 22\)") as caught:
            render(square)
        assert len(caught) == 1, name  # once, whatever the tiles and passes
        assert caught[0].filename == __file__, (name, caught[0].filename)
        with warnings.catch_warnings():
            warnings.simplefilter("error", AspectWarning)
            render(square.with_aspect(W / H))
            warnings.filterwarnings("ignore", category=AspectWarning)  # the docstring's way out
            render(square)
