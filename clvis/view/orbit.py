"""The viewer's camera: an orbit around a target, z up, driven by the mouse.

Dragging turns the view (azimuth, elevation), a right or shift drag pans the
target, the wheel moves the eye towards it. ``camera(aspect)`` is the
clvis.Camera of the current state; ``state()`` is what the page shows,
including the ``--eye/--target/--up/--fov`` options that render the same
view with the other commands.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from ..camera import Camera

__all__ = ["Orbit"]

_UP = np.array([0.0, 0.0, 1.0])
_MAX_ELEVATION = 89.0
_DEGREES_PER_HEIGHT = 180.0  # a drag across the whole view height turns the view this much


class Orbit:
    """Orbit state around the bounding box [lo, hi]."""

    def __init__(
        self,
        lo: npt.ArrayLike,
        hi: npt.ArrayLike,
        azimuth: float = -115.0,
        elevation: float = 35.0,
        fov_y: float = 45.0,
        points: Any = None,
    ) -> None:
        self.lo = np.asarray(lo, np.float64)
        self.hi = np.asarray(hi, np.float64)
        if self.lo.shape != (3,) or self.hi.shape != (3,) or not np.isfinite([self.lo, self.hi]).all():
            raise ValueError(f"orbit bounds: expected two finite 3-vectors, got {lo!r}, {hi!r}")
        # one point (or all in one place) has no size to frame: a unit sphere
        # around it, so the view stands off and the wheel zooms (1e-6 did neither).
        # "No size" is relative below 1: a box 1e-7 wide at the origin (micrometre
        # data in metres) is framed as itself (a unit sphere drew it as a dot)
        extent = float(np.linalg.norm(self.hi - self.lo)) / 2
        magnitude = float(np.abs([self.lo, self.hi]).max())
        self.radius = extent if extent > 1e-6 * min(1.0, magnitude) else 1.0
        self.fov_y = float(fov_y)
        self._home = (float(azimuth), float(elevation))
        # what fit() frames: a sample of the points where given (a round cloud
        # fills more of the view than its box's corners would let it), else the corners
        b0, b1 = self.lo, self.hi
        corners = np.array(
            [[x, y, z] for x in (b0[0], b1[0]) for y in (b0[1], b1[1]) for z in (b0[2], b1[2])]
        )
        self._frame = corners if points is None else np.asarray(points, np.float64).reshape(-1, 3)
        self.fit()

    def fit(self, aspect: float = 16 / 9) -> None:
        """Back to the start: the box centre, its 8 corners (or the points
        given) inside a view of `aspect` (width / height) with a 5 % margin."""
        self.target = (self.lo + self.hi) / 2
        self.azimuth, self.elevation = self._home
        tan_y = math.tan(math.radians(self.fov_y) / 2) / 1.05
        tan_x = tan_y * float(aspect)
        self.distance = 1.0
        eye = self.eye
        fwd = self.target - eye
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, _UP)
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        rel = self._frame - self.target  # the eye sits at -distance along fwd from the target
        f, r, u = rel @ fwd, np.abs(rel @ right), np.abs(rel @ up)
        # a point is inside when |r| <= (distance + f) tan_x and |u| <= (distance + f) tan_y
        need = np.maximum(r / tan_x, u / tan_y) - f
        # nothing to frame (one point): the unit sphere around it fills the view
        self.distance = max(float(need.max()), self.radius * 1e-3) if need.max() > 0 else self.radius / tan_y

    @property
    def eye(self) -> np.ndarray:
        a, e = math.radians(self.azimuth), math.radians(self.elevation)
        d = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
        return self.target + self.distance * d

    def camera(self, aspect: float) -> Camera:
        # near and far enclose the bounding sphere around the target's box
        centre = (self.lo + self.hi) / 2
        to_centre = float(np.linalg.norm(self.eye - centre))
        far = to_centre + 1.2 * self.radius
        near = max(to_centre - 1.2 * self.radius, far * 1e-4)
        return Camera.look_at(self.eye, self.target, _UP, self.fov_y, aspect, near, far)

    def _apply(self, what: str, **state: Any) -> None:
        """Set the attributes `state` (target, distance, azimuth, elevation,
        fov_y) only if the camera they make is finite; else ValueError naming
        `what`, and the orbit stays as it was (a pan of 1e300 pixels made
        every later frame fail with "near: must be finite")."""
        old = {k: getattr(self, k) for k in state}
        for k, v in state.items():
            setattr(self, k, v)
        try:
            with np.errstate(all="ignore"):
                ok = bool(np.isfinite(self.eye).all() and np.isfinite(self.target).all())
                if ok:
                    self.camera(1.0)
        except (ValueError, ArithmeticError):
            ok = False
        if not ok:
            for k, v in old.items():
                setattr(self, k, v)
            raise ValueError(f"{what}: the camera would not be finite; the view is unchanged")

    def orbit(self, dx: float, dy: float, height: int) -> None:
        """Turn by a drag of (dx, dy) pixels in a view `height` pixels high."""
        k = _DEGREES_PER_HEIGHT / max(int(height), 1)
        self._apply(
            "orbit",
            azimuth=(self.azimuth - dx * k + 180.0) % 360.0 - 180.0,
            elevation=min(_MAX_ELEVATION, max(-_MAX_ELEVATION, self.elevation + dy * k)),
        )

    def pan(self, dx: float, dy: float, height: int) -> None:
        """Move the target with the pointer: (dx, dy) pixels."""
        per_px = 2 * self.distance * math.tan(math.radians(self.fov_y) / 2) / max(int(height), 1)
        fwd = self.target - self.eye
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, _UP)
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        with np.errstate(all="ignore"):  # a move too far for a float: refused by _apply
            target = self.target - per_px * (dx * right - dy * up)
        self._apply("pan", target=target)

    def zoom(self, factor: float) -> None:
        """Distance times `factor` (< 1: closer)."""
        f = float(factor)
        if not (math.isfinite(f) and f > 0):
            raise ValueError(f"zoom factor: expected a positive number, got {factor!r}")
        self._apply("zoom", distance=min(max(self.distance * f, self.radius * 1e-3), self.radius * 1e3))

    def set(self, eye: npt.ArrayLike, target: npt.ArrayLike, fov_y: float | None = None) -> None:
        """A typed camera: the orbit that looks from `eye` at `target` (z up).
        Everything is checked before anything changes: a refused camera
        (ValueError) leaves the view as it was."""
        eye_a, target_a = np.asarray(eye, np.float64), np.asarray(target, np.float64)
        if eye_a.shape != (3,) or target_a.shape != (3,) or not np.isfinite([eye_a, target_a]).all():
            raise ValueError("camera: eye and target must be finite 3-vectors")
        d = eye_a - target_a
        dist = float(np.linalg.norm(d))
        if dist == 0:
            raise ValueError("camera: eye and target are the same point")
        fov = self.fov_y
        if fov_y is not None:
            try:
                fov = float(fov_y)
            except (TypeError, ValueError, OverflowError):
                fov = math.nan
            if not 1.0 <= fov <= 170.0:
                raise ValueError(f"camera: fov must be in 1..170 degrees, got {fov_y!r}")
        el = math.degrees(math.asin(max(-1.0, min(1.0, d[2] / dist))))
        self._apply(
            "camera",
            target=target_a,
            distance=dist,
            azimuth=math.degrees(math.atan2(d[1], d[0])),
            elevation=min(_MAX_ELEVATION, max(-_MAX_ELEVATION, el)),
            fov_y=fov,
        )

    def state(self, origin: npt.ArrayLike | None = None) -> dict:
        """JSON-ready: eye, target, up, fov, and the same view as command-line
        options. `origin`: where the orbit's coordinates start in the data's own
        (a point cloud's origin: its positions are kept relative to it, the
        commands' --eye/--target are in the file's coordinates); eye and target
        are given in those."""
        shift = np.zeros(3) if origin is None else np.asarray(origin, np.float64).reshape(3)
        # written to a millionth of the data's size: enough digits for
        # coordinates far from 0 (UTM eastings: 6 significant digits drop the
        # decimals), rounding noise (1e-14 where a coordinate is 0) written as 0
        quantum = 10.0 ** math.floor(math.log10(self.radius * 1e-6))

        def v(a) -> str:
            return ",".join(f"{round(x / quantum) * quantum + 0.0:.15g}" for x in a)

        eye, target = self.eye + shift, self.target + shift
        return {
            "eye": [float(x) for x in eye],
            "target": [float(x) for x in target],
            "up": [0.0, 0.0, 1.0],
            "fov": self.fov_y,
            "azimuth": self.azimuth,
            "elevation": self.elevation,
            "cli": f"--eye {v(eye)} --target {v(target)} --up 0,0,1 --fov {self.fov_y:g}",
        }
