"""Gaussians from point clouds (NARVis's Gaussian renderer).

Per point, either an anisotropic Gaussian elongated along the point's velocity,
Sigma = R diag(stretch, 1, 1)^2 R^T * scale^2 with R's first axis along the
velocity, or an isotropic one whose sigma is the mean distance to the k
nearest neighbours (hole filling for terrain scans; scipy's cKDTree).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import DataError
from ..io import PointCloud
from .gaussians import Gaussians

__all__ = ["frames_along", "gaussians_from_points", "knn_mean_distance"]


def knn_mean_distance(positions, k: int = 4) -> np.ndarray:
    """(N,) float32: each point's mean distance to its k nearest other points
    (scipy.spatial.cKDTree). Fewer than k + 1 points: the mean over those there are;
    a single point: 0."""
    from scipy.spatial import cKDTree

    p = np.asarray(positions, np.float64)
    n = len(p)
    if n < 2:
        return np.zeros(n, np.float32)
    kk = min(k, n - 1)
    dist, _ = cKDTree(p).query(p, k=kk + 1)
    return dist[:, 1:].mean(axis=1).astype(np.float32)


def frames_along(directions) -> np.ndarray:
    """(N, 3, 3) float32 rotations whose first column is the unit direction
    (the x axis where the direction is zero), completed to a right-handed
    orthonormal frame."""
    v = np.asarray(directions, np.float64)
    length = np.linalg.norm(v, axis=1)
    a = np.where(length[:, None] > 0, v / np.where(length > 0, length, 1)[:, None], [1.0, 0.0, 0.0])
    # a helper axis not parallel to a
    helper = np.where((np.abs(a[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    b = np.cross(a, helper)
    b /= np.linalg.norm(b, axis=1)[:, None]
    c = np.cross(a, b)
    return np.stack([a, b, c], axis=2).astype(np.float32)


def gaussians_from_points(cloud: PointCloud | Any, *, velocity: Any = None, stretch: float = 250.0,
                          scale: Any = None, k: int = 4, values: Any = None,
                          opacity: Any = 1.0) -> Gaussians:
    """Gaussians for the points of `cloud` (a clvis.PointCloud or (N, 3) positions).

    velocity : (N, 3), ``"cloud"`` (the cloud's own velocity) or None.
        Given: anisotropic Gaussians, scales = scale * (stretch, 1, 1) along
        (velocity, two normals); a point with zero velocity gets scale * (1, 1, 1).
        None: isotropic, sigma = scale, or (scale None) the mean distance to
        the k nearest neighbours.
    scale : float or (N,) base sigma. For anisotropic Gaussians it defaults to
        the median k-nearest-neighbour distance / stretch.
    values : (N,) or an attribute name of the cloud; default the speed |velocity|
        with a velocity, else zeros.
    opacity : float or (N,) in [0, 1].
    """
    if isinstance(cloud, PointCloud):
        positions = cloud.positions
    else:
        positions = np.asarray(cloud)
        if positions.ndim != 2 or positions.shape[1:] != (3,):
            raise ValueError(f"cloud: expected a PointCloud or (N, 3) positions, got shape {positions.shape}")
        positions = positions.astype(np.float32)
    n = len(positions)
    if n and not np.isfinite(positions).all():
        bad = int(np.flatnonzero(~np.isfinite(positions).all(axis=1))[0])
        raise DataError(f"cloud: point {bad} has a NaN or infinite coordinate")
    if isinstance(velocity, str):
        if velocity != "cloud":
            raise ValueError(f"velocity: expected an array, 'cloud' or None, got {velocity!r}")
        if not isinstance(cloud, PointCloud) or cloud.velocity is None:
            raise ValueError("velocity='cloud': the cloud has no velocity")
        velocity = cloud.velocity
    stretch = float(stretch)
    if not (np.isfinite(stretch) and stretch > 0):
        raise ValueError(f"stretch: expected a positive number, got {stretch!r}")
    if isinstance(values, str):
        if not isinstance(cloud, PointCloud) or values not in cloud.attributes:
            raise ValueError(f"values: the cloud has no attribute {values!r}")
        values = cloud.attributes[values]

    if velocity is not None:
        vel = np.asarray(velocity, np.float64)
        if vel.shape != (n, 3):
            raise ValueError(f"velocity: expected shape ({n}, 3), got {vel.shape}")
        if not np.isfinite(vel).all():
            raise DataError("velocity: NaN or infinite components")
        if scale is None:
            base = np.float64(np.median(knn_mean_distance(positions, k))) / stretch if n else 0.0
            base = np.full(n, base)
        else:
            base = _per_point("scale", scale, n)
        moving = np.linalg.norm(vel, axis=1) > 0
        scales = np.stack([base * np.where(moving, stretch, 1.0), base, base], axis=1)
        rotations = frames_along(vel)
        if values is None:
            values = np.linalg.norm(vel, axis=1)
    else:
        sigma = knn_mean_distance(positions, k) if scale is None else _per_point("scale", scale, n)
        scales = np.repeat(np.asarray(sigma, np.float64)[:, None], 3, axis=1)
        rotations = None
        if values is None:
            values = np.zeros(n)
    values = np.asarray(values)
    if values.shape != (n,):
        raise ValueError(f"values: expected shape ({n},), got {values.shape}")
    opacities = _per_point("opacity", opacity, n)
    return Gaussians(positions, scales, rotations, values.astype(np.float32), opacities)


def _per_point(name, v, n) -> np.ndarray:
    a = np.asarray(v, np.float64)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.shape != (n,):
        raise ValueError(f"{name}: expected a number or shape ({n},), got {a.shape}")
    if not np.isfinite(a).all() or (a < 0).any():
        raise ValueError(f"{name}: values must be finite and >= 0")
    return a
