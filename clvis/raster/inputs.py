"""The raster family's input rules, public so that every caller applies the
same ones (the Rasterizer, and the distributed layer before it sends a view
to its workers): the cloud's normalisation (:class:`RasterInput`), the
camera (:func:`check_camera`), the image size (:func:`check_size`, the
limits of :data:`clvis.limits.RASTER`), the point size and the soft z
tolerance."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from .. import limits
from .._arrays import check_array, is_device
from ..camera import camera_buffer, singular
from ..errors import DataError, DeviceError
from ..limits import check_image_size

__all__ = [
    "LIMITS",
    "MAX_ATTRIBUTES",
    "MAX_IMAGE_SIDE",
    "MAX_PIXELS",
    "MAX_POINT_SIZE",
    "RasterInput",
    "check_camera",
    "check_point_size",
    "check_size",
    "soft_tolerance",
]

MAX_ATTRIBUTES = 8  # attribute planes a render resolves at most (render(planes=))
LIMITS = limits.RASTER  # image sizes (why: clvis.limits)
MAX_IMAGE_SIDE = LIMITS.max_side
MAX_PIXELS = LIMITS.max_pixels
MAX_POINT_SIZE = 64  # render.cl's POINT_SIZE: 1..64 pixels a side


def check_camera(camera: Any) -> tuple[np.ndarray, np.float32, np.float32]:
    """(camera buffer, near, far); a DataError naming the camera when the
    kernels could not use it: a matrix that is not finite (in float32 too), a
    singular projection @ view (a zero-size projection, a degenerate view),
    or a zero depth row."""
    for attr in ("matrix", "depth_row", "near", "far", "projection"):
        if not hasattr(camera, attr):
            raise TypeError(f"camera: expected a clvis.Camera, got {type(camera).__name__}")
    near, far = float(camera.near), float(camera.far)
    if not (math.isfinite(near) and math.isfinite(far) and near < far):
        raise ValueError(f"camera: needs finite near < far, got near={near}, far={far}")
    with np.errstate(over="ignore"):  # render.cl takes them as finite floats
        near_far32 = np.array([near, far], np.float32)
    if not np.isfinite(near_far32).all():
        raise ValueError(f"camera: near and far must be finite in float32, got near={near}, far={far}")
    try:
        m = np.array(camera.matrix, np.float64)
        d = np.array(camera.depth_row, np.float64)
    except (TypeError, ValueError):
        m = d = np.full(1, np.nan)
    if m.shape != (4, 4) or d.shape != (4,) or not (np.isfinite(m).all() and np.isfinite(d).all()):
        raise DataError(
            "camera: its matrix (projection @ view) and depth row must be finite, a 4x4 array and 4 numbers"
        )
    with np.errstate(all="ignore"):
        finite32 = np.isfinite(m.astype(np.float32)).all() and np.isfinite(d.astype(np.float32)).all()
    if not finite32:
        raise DataError("camera: its matrix overflows float32 (the kernels' precision)")
    why = singular(camera.projection, getattr(camera, "view", None), d)
    if why:
        raise DataError(f"camera: {why}; such a camera draws nothing")
    return camera_buffer(camera), np.float32(near), np.float32(far)


def check_size(width: Any, height: Any) -> tuple[int, int]:
    """(width, height) as ints within the raster limits (:data:`LIMITS`,
    :data:`clvis.limits.RASTER`): TypeError / ValueError naming the side."""
    return check_image_size(width, height, LIMITS)


def check_point_size(point_size: Any) -> int:
    """point_size as an int in 1..MAX_POINT_SIZE (render.cl's POINT_SIZE)."""
    if isinstance(point_size, bool) or not isinstance(point_size, (int, np.integer)):
        raise TypeError(f"point_size: expected an int, got {type(point_size).__name__}")
    if not 1 <= int(point_size) <= MAX_POINT_SIZE:
        raise ValueError(f"point_size: {int(point_size)} pixels is outside [1, {MAX_POINT_SIZE}]")
    return int(point_size)


def soft_tolerance(soft_z: Any, camera: Any) -> float | None:
    """The soft z-buffer's relative depth tolerance: None for off (None or
    False), 1.01 for True, else a finite factor >= 1; the camera needs near > 0."""
    if soft_z is None or soft_z is False:
        return None
    tol = 1.01 if soft_z is True else soft_z
    if isinstance(tol, bool) or not isinstance(tol, (int, float, np.floating, np.integer)):
        raise TypeError(f"soft_z: expected None, True or a tolerance factor, got {type(soft_z).__name__}")
    tol = float(tol)
    if not (math.isfinite(tol) and tol >= 1.0):
        raise ValueError(f"soft_z: the tolerance factor must be finite and >= 1, got {tol}")
    if not float(camera.near) > 0.0:
        raise ValueError("soft_z: needs a camera with near > 0 (a relative depth tolerance)")
    return tol


class RasterInput:
    """The caller's cloud, checked and normalised as the Rasterizer takes it
    (see :class:`~clvis.raster.Rasterizer`): ``positions`` float32 (N, 3),
    ``colors`` uint8 (N, 4) or None, ``velocity`` float32 (N, 3) or None,
    ``radius`` float32 (N,) or None (host or device arrays, as given), the
    attributes on the host by kind (``f32``, ``u8``: name -> (N,)) and
    ``names`` in the caller's order."""

    def __init__(
        self,
        cloud: Any,
        colors: Any = None,
        attributes: Mapping[str, Any] | None = None,
        velocity: Any = None,
        radius: Any = None,
    ) -> None:
        # the limit on planes applies to attributes given here, not to a
        # cloud's own (a LAS file has more; render(planes=) picks)
        if attributes is not None and len(attributes) > MAX_ATTRIBUTES:
            raise ValueError(
                f"attributes: {len(attributes)} given; at most {MAX_ATTRIBUTES} "
                "(a PointCloud's own attributes may be more: render(planes=) "
                "picks which to resolve)"
            )
        if hasattr(cloud, "positions"):
            positions = cloud.positions
            colors = colors if colors is not None else getattr(cloud, "colors", None)
            attributes = attributes if attributes is not None else getattr(cloud, "attributes", None)
            velocity = velocity if velocity is not None else getattr(cloud, "velocity", None)
            radius = radius if radius is not None else getattr(cloud, "radius", None)
        else:
            positions = cloud
        if isinstance(positions, (str, os.PathLike)):
            raise TypeError(
                f"cloud_or_positions: expected a PointCloud or an (N, 3) array, got a path ({positions!r}): "
                "clvis.read_points reads it"
            )
        from ..io.objects import refuse_foreign

        refuse_foreign(
            positions, "PointCloud", "cloud_or_positions: expected a PointCloud or an (N, 3) array"
        )
        if not is_device(positions) and not isinstance(positions, np.ndarray):
            positions = np.asarray(positions)
        if not is_device(positions) and positions.dtype.kind in "fiu" and positions.dtype != np.float32:
            # float64 (either byte order), float16 and integer coordinates: float32, as PointCloud takes them
            positions = positions.astype(np.float32)
        self.positions = check_array("positions", positions, dtypes=[np.float32], ndim=2)
        if self.positions.shape[1] != 3:
            raise ValueError(f"positions: expected shape (N, 3), got {tuple(self.positions.shape)}")
        n = self.n = int(self.positions.shape[0])
        if n >= 0xFFFFFFFF:
            raise DeviceError(f"positions: {n} points; at most 2^32 - 2 (0xFFFFFFFF marks empty pixels)")
        self.colors = None
        if colors is not None:
            c = check_array("colors", colors, dtypes=[np.uint8], ndim=2)
            if c.shape[0] != n or c.shape[1] not in (3, 4):
                raise ValueError(f"colors: expected shape ({n}, 4) or ({n}, 3), got {tuple(c.shape)}")
            if c.shape[1] == 3:
                c = c.get() if is_device(c) else c
                c = np.concatenate([c, np.full((n, 1), 255, np.uint8)], axis=1)
            self.colors = c
        self.velocity = None
        if velocity is not None:
            v = check_array("velocity", velocity, dtypes=[np.float32, np.float64], ndim=2)
            if v.shape != (n, 3):
                raise ValueError(f"velocity: expected shape ({n}, 3), got {tuple(v.shape)}")
            self.velocity = v.astype(np.float32) if v.dtype != np.float32 else v
        self.radius = None
        if radius is not None:
            r = check_array("radius", radius, dtypes=[np.float32, np.float64], ndim=1)
            if r.shape != (n,):
                raise ValueError(f"radius: expected shape ({n},), got {tuple(r.shape)}")
            self.radius = r.astype(np.float32) if r.dtype != np.float32 else r
        self.f32: dict[str, np.ndarray] = {}
        self.u8: dict[str, np.ndarray] = {}
        attributes = dict(attributes or {})
        self.names = list(attributes)
        for name, a in attributes.items():
            if not isinstance(name, str):
                raise TypeError(f"attributes: names must be strings, got {name!r}")
            a = a.get() if is_device(a) else np.asarray(a)
            if a.shape != (n,):
                raise ValueError(f"attributes[{name!r}]: expected shape ({n},), got {a.shape}")
            if a.dtype == np.uint8 or a.dtype == np.bool_:
                self.u8[name] = np.ascontiguousarray(a, np.uint8)
            elif a.dtype.kind in "iuf":
                self.f32[name] = np.ascontiguousarray(a, np.float32)
            else:
                raise TypeError(f"attributes[{name!r}]: dtype {a.dtype} is not numeric")
