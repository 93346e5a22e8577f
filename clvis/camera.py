"""Cameras: view and projection matrices, the pixel convention, viewpoint samplers.

Conventions (DESIGN.md): right-handed world, OpenGL clip space, column vectors::

    clip = projection @ view @ [x, y, z, 1]

The view looks down its −z axis; ``projection`` is the standard gluPerspective or
glOrtho matrix. A point's depth is its view-space distance along the view axis,
``depth_row · [x, y, z, 1]``, positive in front of the camera (it equals clip w
for a perspective camera; for an orthographic one clip w is 1).

:meth:`Camera.project` is the pixel convention, written in float32 exactly as the
OpenCL kernels compute it; kernel tests compare against it bit for bit.

The samplers :func:`grid_cameras` and :func:`hemisphere_cameras` produce the
NARVis training viewpoints (z is up); :func:`fit_camera` and
:func:`axis_camera` frame a scene as the commands' default views do.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import os
import sys
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from types import FrameType

import numpy as np
import numpy.typing as npt

from ._arrays import positive_int, real_array
from .errors import AspectWarning, DataError

__all__ = [
    "ASPECT_TOLERANCE",
    "AXIS_VIEWS",
    "CAMERA_DTYPE",
    "Camera",
    "Projected",
    "aspect_checked",
    "axis_camera",
    "box_corners",
    "camera_buffer",
    "check_aspect",
    "fit_camera",
    "grid_cameras",
    "hemisphere_cameras",
    "min_extent",
    "point_spacing",
    "ray_buffer",
    "robust_bounds",
    "robust_fences",
    "same_camera",
    "singular",
]

# Camera.fit frames the bounding sphere enlarged by this factor, so rounding never
# pushes a box corner out of the image.
FIT_MARGIN = 1.05
# The renderers warn (AspectWarning) when a camera's aspect and the image's
# width / height differ by more than this fraction (the larger over the
# smaller, less 1): a picture stretched by 1 % is hard to see, by 2 % a
# circle is visibly an ellipse. Rounding a size to whole pixels stays far below.
ASPECT_TOLERANCE = 0.01
# A box smaller than this fraction of its coordinates' magnitude (the largest
# |x|, |y|, |z| of its corners) is treated as a sphere of that radius, so a single
# point still gets a camera whose float32 matrices resolve it; relative, so a
# volume of micrometre voxels given in metres (a box 1e-5 wide at the origin)
# fills the frame as it does in micrometres (an absolute 1e-4 below magnitude 1
# drew it as a dot). A box with no magnitude at all (one point at the origin)
# gets _MIN_RADIUS itself.
_MIN_RADIUS = 1e-4


def _vec3(name: str, v) -> np.ndarray:
    try:
        a = np.array(v, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise TypeError(f"{name}: expected 3 real numbers, got {v!r}") from e
    if a.shape != (3,):
        raise ValueError(f"{name}: expected 3 numbers, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: must be finite, got {a.tolist()}")
    return a


def _real(name: str, v) -> float:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}: expected a real number, got {type(v).__name__}")
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"{name}: must be finite, got {v}")
    return v


def _positive(name: str, v) -> float:
    v = _real(name, v)
    if v <= 0:
        raise ValueError(f"{name}: must be > 0, got {v}")
    return v


def _fov(fov_y) -> float:
    fov_y = _real("fov_y", fov_y)
    if not 0 < fov_y < 180:
        raise ValueError(f"fov_y: must be in (0, 180) degrees, got {fov_y}")
    return fov_y


def _near_far(near, far, perspective: bool) -> tuple[float, float]:
    near, far = _real("near", near), _real("far", far)
    if perspective and near <= 0:
        raise ValueError(f"near: must be > 0 for a perspective camera, got {near}")
    if far <= near:
        raise ValueError(f"far: must be > near ({near}), got {far}")
    return near, far


def _image_size(name: str, v) -> int:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{name}: expected an int, got {type(v).__name__}")
    if not 0 < v <= 2**24:
        raise ValueError(f"{name}: must be in 1..2^24 (exact in float32), got {v}")
    return int(v)


def singular(
    projection: np.ndarray, view: np.ndarray | None = None, depth_row: np.ndarray | None = None
) -> str | None:
    """Why projection @ view has no usable inverse (rays and the depth key come
    from it), or None. Checked apart, and scale-free: the projection by its
    condition number (world coordinates do not enter it), the view's rotation
    by its normalised determinant (a view far from the origin, as with UTM
    coordinates, is fine), and the depth row (not zero)."""
    p = np.asarray(projection, np.float64)
    with np.errstate(all="ignore"):
        cond = float(np.linalg.cond(p)) if p.shape == (4, 4) and p.any() else math.inf
    if not (math.isfinite(cond) and cond < 1e12):
        return f"the projection is singular (condition number {cond:.3g}): a zero-size view volume"
    if view is not None:
        r = np.asarray(view, np.float64)[:3, :3]
        norms = np.linalg.norm(r, axis=1)
        if not norms.all() or abs(np.linalg.det(r)) / norms.prod() < 1e-9:
            return "the view matrix is singular (eye, target and up do not span a frame)"
    if depth_row is not None and not np.asarray(depth_row)[:3].any():
        return "its depth row is zero"
    return None


def _bounds(bounds_min, bounds_max) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = _vec3("bounds_min", bounds_min), _vec3("bounds_max", bounds_max)
    if (hi < lo).any():
        raise ValueError(
            f"bounds_max: must be >= bounds_min component-wise, got {hi.tolist()} < {lo.tolist()}"
        )
    return lo, hi


def _sphere(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of the box's bounding sphere (radius at least min_extent(lo, hi))."""
    centre = 0.5 * (lo + hi)
    return centre, max(0.5 * float(np.linalg.norm(hi - lo)), min_extent(lo, hi))


def _view_matrix(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """gluLookAt: rows s, u, −f (right, up, backward) and the translation to the eye."""
    f = target - eye
    dist = np.linalg.norm(f)
    if dist == 0:
        raise ValueError(f"target: must differ from eye, both are {eye.tolist()}")
    f = f / dist
    up_len = np.linalg.norm(up)
    if up_len == 0:
        raise ValueError("up: must be a non-zero vector")
    s = np.cross(f, up / up_len)
    s_len = np.linalg.norm(s)
    if s_len < 1e-6:
        raise ValueError(f"up: {up.tolist()} is parallel to the view direction {f.tolist()}")
    s = s / s_len
    u = np.cross(s, f)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = s, u, -f
    view[:3, 3] = -view[:3, :3] @ eye
    return view


def _perspective(fov_y: float, aspect: float, near: float, far: float) -> np.ndarray:
    """gluPerspective."""
    f = 1.0 / math.tan(math.radians(fov_y) / 2)
    p = np.zeros((4, 4))
    p[0, 0], p[1, 1] = f / aspect, f
    p[2, 2], p[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
    p[3, 2] = -1.0
    return p


def _ortho(height: float, aspect: float, near: float, far: float) -> np.ndarray:
    """glOrtho(−w/2, w/2, −h/2, h/2, near, far) with w = height · aspect."""
    p = np.eye(4)
    p[0, 0], p[1, 1] = 2 / (height * aspect), 2 / height
    p[2, 2], p[2, 3] = -2 / (far - near), -(far + near) / (far - near)
    return p


def _projection_aspect(projection) -> float | None:
    """width / height of the view volume `projection` maps onto clip space
    (|P[1, 1] / P[0, 0]|: gluPerspective's and glOrtho's `aspect`), or None
    where it has none: x and y mixed (P[0, 1], P[1, 0], or w depending on x
    or y), a zero scale, a ratio not finite."""
    try:
        p = np.asarray(projection, np.float64)
    except (TypeError, ValueError):
        return None
    if p.shape != (4, 4) or not np.isfinite(p).all():
        return None
    sx, sy = abs(float(p[0, 0])), abs(float(p[1, 1]))
    mixed = max(abs(float(p[0, 1])), abs(float(p[1, 0])))
    if sx == 0 or sy == 0 or mixed > 1e-9 * max(sx, sy):
        return None
    if max(abs(float(p[3, 0])), abs(float(p[3, 1]))) > 1e-9 * max(abs(float(p[3, 2])), abs(float(p[3, 3]))):
        return None
    with np.errstate(all="ignore"):
        ratio = sy / sx
    return ratio if math.isfinite(ratio) and ratio > 0 else None


# clvis's own renders of a camera already checked (a distributed frame's
# workers and their windows, a throwaway warm-up frame): no second warning.
# A context variable, so it holds for the thread (or task) that set it only.
_ASPECT_CHECKED: contextvars.ContextVar[bool] = contextvars.ContextVar("clvis_aspect_checked", default=False)


@contextlib.contextmanager
def aspect_checked() -> Iterator[None]:
    """Within it, :func:`check_aspect` does not warn (in this thread or task
    only): for clvis's renders of a camera already checked."""
    token = _ASPECT_CHECKED.set(True)
    try:
        yield
    finally:
        _ASPECT_CHECKED.reset(token)


_PACKAGE = os.path.dirname(os.path.abspath(__file__)) + os.sep


def _caller_stacklevel() -> int:
    """The stacklevel, as warnings.warn in check_aspect counts it, of the
    first frame outside the clvis package: the user's call."""
    frame: FrameType | None = sys._getframe(2)  # check_aspect's caller
    level = 2
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(_PACKAGE):
        frame = frame.f_back
        level += 1
    return level


def check_aspect(camera: Camera, width: int, height: int) -> None:
    """Warn (:class:`clvis.AspectWarning`) when `camera`'s aspect
    (:attr:`Camera.aspect`) and ``width / height`` differ by more than
    ASPECT_TOLERANCE: the picture would come out stretched. A projection
    without an aspect (x and y mixed on purpose) is not checked. The
    public renderers call it once per render."""
    if _ASPECT_CHECKED.get():
        return
    have = _projection_aspect(getattr(camera, "projection", None))
    if have is None:
        return
    want = int(width) / int(height)
    if max(have, want) / min(have, want) - 1 <= ASPECT_TOLERANCE + 1e-12:  # 101 x 100: 1 %, not more
        return
    warnings.warn(
        f"camera: its aspect (width / height) is {have:.4g} but the image is {int(width)} x "
        f"{int(height)} (aspect {want:.4g}): the picture is stretched "
        f"{'horizontally' if want > have else 'vertically'}. Render with "
        f"camera.with_aspect({int(width)} / {int(height)}), or build the camera with "
        f"aspect={int(width)} / {int(height)}; for a projection made so on purpose, "
        "warnings.filterwarnings('ignore', category=clvis.AspectWarning)",
        AspectWarning,
        stacklevel=_caller_stacklevel(),
    )


def same_camera(a: Camera, b: Camera) -> bool:
    """Whether two cameras give the same rays: the same kind and view and
    projection matrices equal within 1e-9 of each matrix's largest entry
    (float64 rounding, far below what float32 rays resolve)."""
    if a is b:
        return True
    if a.orthographic != b.orthographic:
        return False
    for x, y in ((a.view, b.view), (a.projection, b.projection)):
        scale = max(1.0, float(np.abs(x).max()), float(np.abs(y).max()))
        if float(np.abs(x - y).max()) > 1e-9 * scale:
            return False
    return True


@dataclass(frozen=True)
class Projected:
    """Points in pixels, as :meth:`Camera.project` defines them; arrays of length N.

    ``sx``, ``sy`` (float32): continuous pixel coordinates, (0, 0) the top-left corner
    of the image; ``px``, ``py`` (int32): the pixel, ``floor(sx)``, ``floor(sy)``
    where visible and −1 elsewhere; ``depth`` (float32): the view-axis distance;
    ``visible`` (bool): the point lands in the image and within [near, far].
    """

    sx: np.ndarray
    sy: np.ndarray
    px: np.ndarray
    py: np.ndarray
    depth: np.ndarray
    visible: np.ndarray


@dataclass(frozen=True, eq=False, repr=False)
class Camera:
    """A pinhole or orthographic camera.

    Build one with :meth:`look_at`, :meth:`ortho` or :meth:`fit`. The arrays are
    read-only float64 copies.

    A camera is made for one image shape: its ``aspect`` (width / height,
    default 1) is part of the projection. Render it at that width / height;
    for another size, ``camera.with_aspect(width / height)`` is the same
    camera (eye, target, up, vertical field of view or height, near, far)
    for it. The renderers warn (:class:`clvis.AspectWarning`) when the two
    differ by more than 1 %: the picture would be stretched.

    Attributes
    ----------
    view, projection : (4, 4) float64
        clip = projection @ view @ [x, y, z, 1].
    near, far : float
        The depth range drawn (view-axis distances).
    orthographic : bool
        True for a glOrtho projection.
    eye : (3,) float64
        The camera position in world space.
    """

    view: np.ndarray
    projection: np.ndarray
    near: float
    far: float
    orthographic: bool
    eye: np.ndarray

    def __post_init__(self):
        for name in ("view", "projection"):
            m = np.array(getattr(self, name), dtype=np.float64)
            if m.shape != (4, 4):
                raise ValueError(f"{name}: expected a 4x4 matrix, got shape {m.shape}")
            if not np.isfinite(m).all():
                raise ValueError(f"{name}: must be finite")
            m.setflags(write=False)
            object.__setattr__(self, name, m)
        if not isinstance(self.orthographic, (bool, np.bool_)):
            raise TypeError(f"orthographic: expected a bool, got {type(self.orthographic).__name__}")
        near, far = _near_far(self.near, self.far, not self.orthographic)
        why = singular(self.projection, self.view)
        if why is not None:
            raise DataError(
                f"camera: {why}; make cameras with Camera.look_at, Camera.ortho or Camera.fit, "
                "whose arguments are checked (fov_y, aspect, near < far, eye != target, up not "
                "along the view)"
            )
        eye = _vec3("eye", self.eye)
        eye.setflags(write=False)
        object.__setattr__(self, "near", near)
        object.__setattr__(self, "far", far)
        object.__setattr__(self, "orthographic", bool(self.orthographic))
        object.__setattr__(self, "eye", eye)

    def __repr__(self) -> str:
        kind = "orthographic" if self.orthographic else "perspective"
        return (
            f"Camera({kind}, eye={self.eye.tolist()}, forward={self.forward.tolist()}, "
            f"near={self.near:g}, far={self.far:g})"
        )

    @classmethod
    def look_at(
        cls,
        eye: npt.ArrayLike,
        target: npt.ArrayLike,
        up: npt.ArrayLike = (0, 0, 1),
        fov_y: float = 60.0,
        aspect: float = 1.0,
        near: float = 0.1,
        far: float = 1000.0,
    ) -> Camera:
        """A perspective camera at `eye` looking at `target`.

        `fov_y` is the vertical field of view in degrees, `aspect` = width / height.
        """
        eye, target, up = _vec3("eye", eye), _vec3("target", target), _vec3("up", up)
        fov_y, aspect = _fov(fov_y), _positive("aspect", aspect)
        near, far = _near_far(near, far, perspective=True)
        cam = cls(
            _view_matrix(eye, target, up), _perspective(fov_y, aspect, near, far), near, far, False, eye
        )
        # what with_aspect builds again (exactly look_at's matrices for the new aspect)
        object.__setattr__(cam, "_made", ("look_at", eye, target, up, fov_y, near, far))
        return cam

    @classmethod
    def ortho(
        cls,
        eye: npt.ArrayLike,
        target: npt.ArrayLike,
        up: npt.ArrayLike = (0, 0, 1),
        height: float = 2.0,
        aspect: float = 1.0,
        near: float = 0.1,
        far: float = 1000.0,
    ) -> Camera:
        """An orthographic camera at `eye` looking at `target`.

        `height` is the world-space height of the view volume (its width is
        ``height * aspect``); `near` may be zero or negative (behind the eye).
        """
        eye, target, up = _vec3("eye", eye), _vec3("target", target), _vec3("up", up)
        height, aspect = _positive("height", height), _positive("aspect", aspect)
        near, far = _near_far(near, far, perspective=False)
        cam = cls(_view_matrix(eye, target, up), _ortho(height, aspect, near, far), near, far, True, eye)
        object.__setattr__(cam, "_made", ("ortho", eye, target, up, height, near, far))
        return cam

    @classmethod
    def fit(
        cls,
        bounds_min: npt.ArrayLike,
        bounds_max: npt.ArrayLike,
        direction: npt.ArrayLike = (-1, -1, -0.6),
        up: npt.ArrayLike = (0, 0, 1),
        fov_y: float = 60.0,
        aspect: float = 1.0,
    ) -> Camera:
        """A perspective camera that frames the whole box.

        It looks at the box centre along `direction` (the view direction, from the
        eye towards the centre: the default looks down from the +x, +y, +z side),
        from the distance at which the box's bounding sphere fits the narrower of
        the two fields of view. near and far enclose the sphere with margin. A
        long box (a strip of scan, a tall volume) then fills part of the frame:
        ``clvis.camera.fit_camera(corners, lo, hi)`` with the box's 8 corners
        (or the points themselves) frames it tightly from the same direction.
        """
        lo, hi = _bounds(bounds_min, bounds_max)
        direction, up = _vec3("direction", direction), _vec3("up", up)
        fov_y, aspect = _fov(fov_y), _positive("aspect", aspect)
        length = np.linalg.norm(direction)
        if length == 0:
            raise ValueError("direction: must be a non-zero vector")
        centre, radius = _sphere(lo, hi)
        half_y = math.radians(fov_y) / 2
        half = min(half_y, math.atan(aspect * math.tan(half_y)))
        dist = FIT_MARGIN * radius / math.sin(half)
        eye = centre - dist * direction / length
        return cls.look_at(eye, centre, up, fov_y, aspect, *_sphere_depths(dist, radius))

    @property
    def matrix(self) -> np.ndarray:
        """projection @ view, (4, 4) float64."""
        return self.projection @ self.view

    @property
    def aspect(self) -> float | None:
        """The width / height the projection is made for (look_at's, ortho's
        and fit's `aspect`): ``|projection[1, 1] / projection[0, 0]|``. None
        for a projection that has none (one given as a matrix that mixes x
        and y). Render at a width / height equal to it, or see
        :meth:`with_aspect`."""
        return _projection_aspect(self.projection)

    def with_aspect(self, aspect: float) -> Camera:
        """The same camera for an image of another width / height `aspect`
        (e.g. ``camera.with_aspect(640 / 360)``): the same eye, view
        direction, up, near and far, and the same vertical extent (field of
        view, or an orthographic camera's height); the horizontal extent
        follows the new aspect. A camera from look_at, ortho or fit comes
        out exactly as made with that aspect (fit's distance is not
        recomputed: call fit again to frame the box for the new shape).
        One made from matrices has its projection's x row scaled
        (``aspect`` must not be None)."""
        aspect = _positive("aspect", aspect)
        made = self.__dict__.get("_made")
        if made is not None:
            kind, eye, target, up, size, near, far = made
            build = Camera.look_at if kind == "look_at" else Camera.ortho
            return build(eye, target, up, size, aspect, near, far)
        have = self.aspect
        if have is None:
            raise ValueError(
                "camera: its projection has no aspect to change (it mixes x and y, or a scale is "
                "zero); build it with Camera.look_at / Camera.ortho and the aspect you need"
            )
        p = np.array(self.projection)
        p[0, :] *= have / aspect
        return Camera(self.view, p, self.near, self.far, self.orthographic, self.eye)

    @property
    def depth_row(self) -> np.ndarray:
        """(4,) float64 row with depth = depth_row · [x, y, z, 1] (= −view[2, :])."""
        return -self.view[2, :]

    @property
    def forward(self) -> np.ndarray:
        """The unit view direction in world space, (3,) float64."""
        return -self.view[2, :3]

    def focal_px(self, height: int) -> float:
        """Pixels per world unit at depth 1 (perspective) or anywhere (orthographic),
        for an image `height` pixels tall."""
        return 0.5 * height * float(self.projection[1, 1])

    def project(self, points: npt.ArrayLike, width: int, height: int) -> Projected:
        """Project (N, 3) points to a `width` x `height` image, in float32 as the kernels do.

        With M = float32(matrix), D = float32(depth_row) and (x, y, z) the float32
        point, each product and sum rounded to float32 separately (no fma), in order::

            clip_i = ((M[i,0]*x + M[i,1]*y) + M[i,2]*z) + M[i,3]      i = 0, 1, 3
            depth  = ((D[0]*x + D[1]*y) + D[2]*z) + D[3]
            r = 1 / clip_3                                           (one division)
            sx = ((clip_0 * r) * 0.5 + 0.5) * W,  sy = (0.5 - (clip_1 * r) * 0.5) * H

        (correctly rounded division). A point is visible when x, y, z are finite,
        near <= depth <= far (near, far rounded to float32), clip_3 > 0,
        0 <= sx < W and 0 <= sy < H; then px = floor(sx), py = floor(sy).
        """
        w, h = np.float32(_image_size("width", width)), np.float32(_image_size("height", height))
        p = _points_f32(points)
        m = self.matrix.astype(np.float32)
        d = self.depth_row.astype(np.float32)
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        half = np.float32(0.5)
        with np.errstate(all="ignore"):
            clip_x, clip_y, clip_w = (
                ((m[i, 0] * x + m[i, 1] * y) + m[i, 2] * z) + m[i, 3] for i in (0, 1, 3)
            )
            depth = ((d[0] * x + d[1] * y) + d[2] * z) + d[3]
            r = np.float32(1) / clip_w
            sx = ((clip_x * r) * half + half) * w
            sy = (half - (clip_y * r) * half) * h
            visible = (
                np.isfinite(p).all(axis=1)
                & (depth >= np.float32(self.near))
                & (depth <= np.float32(self.far))
                & (clip_w > 0)
                & (sx >= 0)
                & (sx < w)
                & (sy >= 0)
                & (sy < h)
            )
        px = np.where(visible, np.floor(sx), -1).astype(np.int32)
        py = np.where(visible, np.floor(sy), -1).astype(np.int32)
        return Projected(sx, sy, px, py, depth, visible)


def _points_f32(points) -> np.ndarray:
    a = real_array("points", points)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"points: expected shape (N, 3), got {a.shape}")
    return np.ascontiguousarray(a, dtype=np.float32)


def _sphere_depths(dist: float, radius: float) -> tuple[float, float]:
    """near, far for a camera `dist` from the centre of a sphere of `radius` (dist > radius):
    the sphere's depth range [dist − radius, dist + radius] with margin on both sides."""
    return 0.5 * (dist - radius), 1.5 * (dist + radius)


def grid_cameras(
    bounds_min: npt.ArrayLike,
    bounds_max: npt.ArrayLike,
    count: int | Sequence[int] = 4,
    spacing: float | None = None,
    height: float | None = None,
    fov_y: float = 60.0,
    aspect: float = 1.0,
    near: float | None = None,
    far: float | None = None,
) -> Iterator[Camera]:
    """NARVis grid viewpoints: 24 cameras at each position of a grid over the box.

    Positions are the centres of an nx x ny grid of cells covering the box's x–y
    extent, at z = box top + `height` (default: a tenth of the box diagonal; may
    be negative). nx, ny come from `count` (an int, or (nx, ny)) or, when given,
    from `spacing`: ceil(extent / spacing) cells along each axis. An axis with no
    extent gets one position.

    At each position the camera yaws through 0°, 45°, ..., 315° (from +x towards
    +y) and for each yaw pitches 1°, 30° and 60° below the horizon: 8 x 3 = 24
    cameras per position, ordered position (x fastest), yaw, pitch. The up vector
    is +z. near defaults to 1e-3 of the scene scale; far to the distance from the
    farthest camera to the farthest box corner, with margin, so every part of the
    box a camera faces is within [near, far].
    """
    lo, hi = _bounds(bounds_min, bounds_max)
    fov_y, aspect = _fov(fov_y), _positive("aspect", aspect)
    _, radius = _sphere(lo, hi)
    height = 0.2 * radius if height is None else _real("height", height)
    xs, ys = (_grid_axis(lo[i], hi[i], n) for i, n in enumerate(_grid_counts(lo, hi, count, spacing)))
    z = hi[2] + height
    eyes = [np.array([x, y, z]) for y in ys for x in xs]
    corners = np.array(
        [[cx, cy, cz] for cx in (lo[0], hi[0]) for cy in (lo[1], hi[1]) for cz in (lo[2], hi[2])]
    )
    reach = max(np.linalg.norm(corners - e, axis=1).max() for e in eyes)
    scale = max(2 * radius, abs(height))
    near = 1e-3 * scale if near is None else near
    far = 1.01 * reach + 1e-3 * scale if far is None else far
    near, far = _near_far(near, far, perspective=True)
    return _grid(eyes, fov_y, aspect, near, far)


def _grid_counts(lo, hi, count, spacing) -> tuple[int, ...]:
    extent = hi[:2] - lo[:2]
    if spacing is not None:
        spacing = _positive("spacing", spacing)
        return tuple(max(1, math.ceil(e / spacing)) for e in extent)
    counts = (count, count) if isinstance(count, (int, np.integer)) else tuple(count)
    if len(counts) != 2 or not all(
        isinstance(c, (int, np.integer)) and not isinstance(c, bool) and c > 0 for c in counts
    ):
        raise ValueError(f"count: expected a positive int or two positive ints, got {count!r}")
    return tuple(int(c) if e > 0 else 1 for c, e in zip(counts, extent, strict=True))


def _grid_axis(lo: float, hi: float, n: int) -> np.ndarray:
    return lo + (np.arange(n) + 0.5) * ((hi - lo) / n)


def _grid(eyes, fov_y, aspect, near, far) -> Iterator[Camera]:
    for eye in eyes:
        for yaw in range(0, 360, 45):
            for pitch in (1, 30, 60):
                y, p = math.radians(yaw), math.radians(pitch)
                forward = np.array([math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), -math.sin(p)])
                yield Camera.look_at(eye, eye + forward, (0, 0, 1), fov_y, aspect, near, far)


def hemisphere_cameras(
    bounds_min: npt.ArrayLike,
    bounds_max: npt.ArrayLike,
    fov_y: float = 60.0,
    aspect: float = 1.0,
    near: float | None = None,
    far: float | None = None,
) -> Iterator[Camera]:
    """NARVis hemisphere viewpoints: 128 cameras looking at the box centre.

    The eyes lie on the upper hemisphere around the centre with radius 0.75 x the
    box diagonal, at polar angles θ = π/8, π/4, 3π/8, π/2 from +z (the pole θ = 0,
    where +z is parallel to the view, is left out) and azimuths φ = kπ/16,
    k = 0..31, from +x towards +y: 4 x 32 = 128 cameras, ordered θ then φ. Up is
    +z. near and far default to the box's bounding-sphere depth range with
    margin, so the whole box lies within [near, far].
    """
    lo, hi = _bounds(bounds_min, bounds_max)
    fov_y, aspect = _fov(fov_y), _positive("aspect", aspect)
    centre, radius = _sphere(lo, hi)
    dist = 1.5 * radius  # 0.75 x diagonal
    default_near, default_far = _sphere_depths(dist, radius)
    near, far = _near_far(
        default_near if near is None else near, default_far if far is None else far, perspective=True
    )
    return _hemisphere(centre, dist, fov_y, aspect, near, far)


def _hemisphere(centre, dist, fov_y, aspect, near, far) -> Iterator[Camera]:
    for i in range(1, 5):
        theta = i * math.pi / 8
        for k in range(32):
            phi = k * math.pi / 16
            offset = dist * np.array(
                [math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)]
            )
            yield Camera.look_at(centre + offset, centre, (0, 0, 1), fov_y, aspect, near, far)


# --------------------------------------------------------------------------
# framing a scene: the commands' default views (--view fit, top/front/side)

# the axis views: (view direction, up)
AXIS_VIEWS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "top": ((0, 0, -1), (0, 1, 0)),
    "front": ((0, 1, 0), (0, 0, 1)),
    "side": ((-1, 0, 0), (0, 0, 1)),
}


def box_corners(bounds_min: npt.ArrayLike, bounds_max: npt.ArrayLike) -> np.ndarray:
    """The 8 corners of the box [bounds_min, bounds_max], (8, 3) float64."""
    lo, hi = np.asarray(bounds_min, np.float64), np.asarray(bounds_max, np.float64)
    return np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], np.float64
    )


def min_extent(bounds_min: npt.ArrayLike, bounds_max: npt.ArrayLike | None = None) -> float:
    """An extent too small to frame on its own in the box [bounds_min,
    bounds_max] (or around the point `bounds_min`): _MIN_RADIUS times the
    largest magnitude of its coordinates, below which float32 cameras no
    longer resolve the points (Camera.fit's floor); relative, so data of
    any scale (micrometres in metres) is framed alike; _MIN_RADIUS itself
    for the origin alone (no scale to take)."""
    lo = np.asarray(bounds_min, np.float64)
    hi = lo if bounds_max is None else np.asarray(bounds_max, np.float64)
    magnitude = float(max(np.abs(lo).max(), np.abs(hi).max()))
    # a magnitude under 1e-6 counts as 1e-6: a camera framing less than 1e-10
    # has a projection too ill-conditioned to invert (singular(): its condition
    # number grows as 1 / near), so data of sub-angstrom extent in metres is
    # framed small, and a point at 1e-300 still gets a camera
    return _MIN_RADIUS * max(magnitude, 1e-6) if magnitude > 0 else _MIN_RADIUS


def _finite_sample(positions: npt.ArrayLike, limit: int = 200_000) -> np.ndarray:
    """Up to `limit` of the points with finite x, y, z (an even stride), float64."""
    positions = np.asarray(positions)
    step = max(1, len(positions) // limit)
    p = positions[::step].astype(np.float64)
    return p[np.isfinite(p).all(axis=1)]


# Robust framing: the box of the points that lie within ROBUST_FENCE box
# widths of the ROBUST_PERCENTILE..(100 - ROBUST_PERCENTILE) percentile box,
# per axis. A Gaussian cloud keeps every point out to 7 sigma, a uniform one
# all of them; a few stray points (a (0, 0, 0) record in a georeferenced
# scan) far outside the bulk are left out of the frame.
ROBUST_PERCENTILE = 1.0
ROBUST_FENCE = 1.0


@dataclass(frozen=True, eq=False)
class RobustBounds:
    """What :func:`robust_bounds` finds. lo, hi: (3,) float64, the box of the
    points kept; inside: (N,) bool, the points within the fences (finite
    ones only); kept, total: how many of the finite points are inside, of
    how many."""

    lo: np.ndarray
    hi: np.ndarray
    inside: np.ndarray
    kept: int
    total: int


ROBUST_SAMPLE = 1_000_000  # the points robust_fences' percentiles are taken of, at most


def robust_sample_step(n: int) -> int:
    """The stride of the sample :func:`robust_bounds` takes its percentiles
    of, for a cloud of `n` points: every k-th point, up to ROBUST_SAMPLE."""
    return max(1, int(n) // ROBUST_SAMPLE)


def robust_fences(
    sample: npt.ArrayLike, percentile: float = ROBUST_PERCENTILE, fence: float = ROBUST_FENCE
) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi): the fences :func:`robust_bounds` keeps points within, from
    `sample` ((m, 3), every :func:`robust_sample_step`-th point of the cloud;
    non-finite rows are left out): per axis, the `percentile` and 100 -
    `percentile` percentiles widened by `fence` times their distance. (A
    cloud split over workers computes them from the same rows.)"""
    s = np.asarray(sample).astype(np.float64)
    s = s[np.isfinite(s).all(axis=1)]
    if len(s) == 0:
        raise ValueError("bounds: the cloud has no finite points")
    a, b = np.percentile(s, [percentile, 100 - percentile], axis=0)
    return a - fence * (b - a), b + fence * (b - a)


def robust_bounds(
    positions: npt.ArrayLike, percentile: float = ROBUST_PERCENTILE, fence: float = ROBUST_FENCE
) -> RobustBounds:
    """The bounds of the bulk of a cloud: per axis, the `percentile` and
    100 - `percentile` percentiles (of a sample of up to 10^6 points) widened
    by `fence` times their distance on each side; the points inside all three
    fences are kept and their min and max are the bounds. ValueError when no
    point is finite."""
    p = np.asarray(positions)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"positions: expected shape (N, 3), got {p.shape}")
    if not (0 <= percentile < 50 and fence >= 0):
        raise ValueError(f"percentile {percentile!r} must lie in [0, 50) and fence {fence!r} be >= 0")
    finite = np.isfinite(p).all(axis=1)
    total = int(finite.sum())
    if total == 0:
        raise ValueError("bounds: the cloud has no finite points")
    lo_f, hi_f = robust_fences(p[:: robust_sample_step(len(p))], percentile, fence)
    with np.errstate(invalid="ignore"):
        inside = finite & ((p >= lo_f) & (p <= hi_f)).all(axis=1)
    kept = int(inside.sum())
    q = p[inside] if kept < total else p[finite]
    return RobustBounds(
        q.min(axis=0).astype(np.float64), q.max(axis=0).astype(np.float64), inside, kept, total
    )


def point_spacing(camera: Camera, positions: npt.ArrayLike, width: int, height: int) -> float:
    """The typical distance in pixels between neighbouring points on screen:
    sqrt(footprint / visible points), the footprint measured as the cells
    of that spacing's size that hold a point (computed twice: first from the
    points' screen bounding box). 0 when no point is visible."""
    p = _finite_sample(positions, 1_000_000)
    scale = len(np.asarray(positions)) / max(len(p), 1)
    pr = camera.project(p, width, height)
    sx, sy = pr.sx[pr.visible].astype(np.float64), pr.sy[pr.visible].astype(np.float64)
    n = len(sx) * scale
    if len(sx) == 0:
        return 0.0
    area = max((np.ptp(sx) + 1) * (np.ptp(sy) + 1), 1.0)
    spacing = math.sqrt(area / n)
    for _ in range(2):
        cell = max(spacing, 1.0)
        cells = np.unique(
            np.floor(sx / cell).astype(np.int64) * (2**31) + np.floor(sy / cell).astype(np.int64)
        )
        spacing = math.sqrt(len(cells) * cell * cell / n)
    return spacing


def fit_camera(
    positions: npt.ArrayLike,
    bounds_min: npt.ArrayLike,
    bounds_max: npt.ArrayLike,
    *,
    direction: npt.ArrayLike = (-1, -1, -0.6),
    fov_y: float = 60.0,
    aspect: float = 1.0,
) -> Camera:
    """A perspective camera framing the points `positions` ((N, 3)) tightly:
    :meth:`Camera.fit` on the bounds, then moved sideways until the points (a
    sample of them) are centred on screen and along its view axis until they
    just fill the frame; the direction is kept (z up). Camera.fit frames the
    bounding sphere, which leaves a flat cloud (a storm, a terrain) small."""
    cam = Camera.fit(bounds_min, bounds_max, direction=direction, aspect=aspect, fov_y=fov_y)
    p = _finite_sample(positions)
    lo, hi = np.asarray(bounds_min, np.float64), np.asarray(bounds_max, np.float64)
    centre = 0.5 * (lo + hi)
    if len(p) == 0 or np.ptp(p, axis=0).max() <= min_extent(lo, hi):
        return cam  # (about) one point: Camera.fit's own framing
    right, up, forward = cam.view[0, :3], cam.view[1, :3], cam.forward
    o = p - centre
    c = o @ forward
    tan_y = 1.0 / cam.projection[1, 1]
    tan_x = aspect * tan_y
    # with the eye at distance D from the centre, shifted sideways by (sx, sy),
    # a point is in frame when |a - sx| <= tan_x (D + c) and |b - sy| <=
    # tan_y (D + c), and in front when D + c > 0
    a, b = o @ right, o @ up
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), min_extent(lo, hi))
    shift = np.zeros(2)

    def distance() -> float:
        return max(
            float(
                np.max(
                    FIT_MARGIN * np.maximum(np.abs(a - shift[0]) / tan_x, np.abs(b - shift[1]) / tan_y) - c
                )
            ),
            float(np.max(-c)) + 1e-3 * radius,
        )

    dist = distance()
    # perspective puts the near side of an oblique cloud lower and wider on
    # screen: shift the eye sideways until the points' extents are centred in
    # the frame, then move it in again (a few rounds converge)
    step = max(1, len(c) // 20_000)  # the centre from a sample; the distance from all
    for _ in range(3):
        depth = dist + c[::step]
        for k, s in enumerate((a[::step], b[::step])):
            lo_s, hi_s = float(s.min()), float(s.max())
            for _ in range(40):  # bisect: the mid of the extents, decreasing in the shift
                mid = 0.5 * (lo_s + hi_s)
                x = (s - mid) / depth
                lo_s, hi_s = (mid, hi_s) if x.max() + x.min() > 0 else (lo_s, mid)
            shift[k] = 0.5 * (lo_s + hi_s)
        dist = distance()
    nearest, farthest = dist + float(c.min()), dist + float(c.max())
    fov = math.degrees(2 * math.atan(tan_y))
    target = centre + shift[0] * right + shift[1] * up
    return Camera.look_at(
        target - dist * forward, target, (0, 0, 1), fov, aspect, near=0.5 * nearest, far=1.5 * farthest
    )


def axis_camera(
    kind: str,
    bounds_min: npt.ArrayLike,
    bounds_max: npt.ArrayLike,
    aspect: float = 1.0,
    anatomical: bool = False,
) -> Camera:
    """An orthographic camera along an axis (`kind`, a key of AXIS_VIEWS)
    framing the box: top looks down (north, +y, up), front looks along +y,
    side along -x. `anatomical` (a scan in RAS+ order, +y anterior): front
    looks along -y, at the face (along +y it saw the back of the head)."""
    if kind not in AXIS_VIEWS:
        raise ValueError(f"kind: expected one of {', '.join(AXIS_VIEWS)}, got {kind!r}")
    lo, hi = np.asarray(bounds_min, np.float64), np.asarray(bounds_max, np.float64)
    direction, up = (np.asarray(v, np.float64) for v in AXIS_VIEWS[kind])
    if anatomical and kind == "front":
        direction = -direction
    right = np.cross(direction, up)
    ext = hi - lo
    width, height, depth = (float(np.abs(v) @ ext) for v in (right, up, direction))
    centre = 0.5 * (lo + hi)
    floor = min_extent(lo, hi)
    scale = max(width, height, depth, floor)
    # a box with no width across the view (one point) gets Camera.fit's floor:
    # 1e-3 of it was finer than float32 resolves there (the point drawn off
    # the picture at 4e6 from the origin)
    frame = FIT_MARGIN * max(height, width / aspect, 1e-3 * scale, 2 * floor)
    back = 0.5 * depth + 0.1 * scale  # the eye sits outside the box
    return Camera.ortho(
        centre - back * direction,
        centre,
        up,
        height=frame,
        aspect=aspect,
        near=0.05 * scale,
        far=back + 0.5 * depth + 0.1 * scale,
    )


# --------------------------------------------------------------------------
# the camera as kernels read it (kernels_cl/include/clvis/camera.h)

CAMERA_DTYPE = np.dtype([("m", "<f4", (4, 4)), ("d", "<f4", (4,))])


def camera_buffer(camera: Camera) -> np.ndarray:
    """The 20 float32 of clvis/camera.h: M = projection @ view, then the depth row."""
    m = np.asarray(camera.matrix, np.float64)
    d = np.asarray(camera.depth_row, np.float64)
    if m.shape != (4, 4) or d.shape != (4,) or not (np.isfinite(m).all() and np.isfinite(d).all()):
        raise ValueError("camera: its matrix must be a finite 4x4 array and its depth row finite")
    out = np.zeros(1, CAMERA_DTYPE)
    out["m"][0] = m
    out["d"][0] = d
    return out.view(np.float32)


def ray_buffer(camera: Camera, width: int, height: int) -> np.ndarray:
    """The 22 float32 camera-ray coefficients of clvis/camera.h for a
    `width` x `height` image: pixel centre (u, v) = (px + 0.5, py + 0.5) has its
    ray origin on the near plane, o = o0 + u ou + v ov, and direction
    dd = d0 + u du + v dv towards the far plane (computed in float64 from the
    inverse of projection @ view, then rounded), plus the depth row."""
    if not isinstance(camera, Camera):
        raise TypeError(f"camera: expected a clvis.Camera, got {type(camera).__name__}")
    w, h = positive_int("width", width), positive_int("height", height)
    try:
        inv = np.linalg.inv(camera.matrix)
    except np.linalg.LinAlgError:
        raise DataError(
            "camera: its matrix projection @ view cannot be inverted in float64 (coordinates "
            "too large for the rays to be computed)"
        ) from None

    def point(u, v, zn):
        p = inv @ np.array([u / w * 2 - 1, 1 - v / h * 2, zn, 1.0])
        return p[:3] / p[3]

    with np.errstate(all="ignore"):  # a point at infinity is caught below
        near = [point(0, 0, -1), point(1, 0, -1), point(0, 1, -1)]
        far = [point(0, 0, 1), point(1, 0, 1), point(0, 1, 1)]
        o0, ou, ov = near[0], near[1] - near[0], near[2] - near[0]
        f0, fu, fv = far[0], far[1] - far[0], far[2] - far[0]
        buf = np.concatenate([o0, ou, ov, f0 - o0, fu - ou, fv - ov, camera.depth_row])
        out = buf.astype(np.float32)
    if not np.isfinite(out).all():
        raise DataError(
            f"camera: its rays for a {w} x {h} image are not finite in float32 (a near or far "
            f"plane at infinity, or a degenerate matrix): {camera!r}"
        )
    return out
