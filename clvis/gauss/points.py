"""Gaussians from point clouds (NARVis's Gaussian renderer).

Per point, either an anisotropic Gaussian elongated along the point's velocity,
Sigma = R diag(stretch, 1, 1)^2 R^T * scale^2 with R's first axis along the
velocity, or an isotropic one whose sigma is the mean distance to the k
nearest neighbours (hole filling for terrain scans; scipy's cKDTree), clamped
to the KNN_CLAMP_PERCENTILE-th percentile of those distances: the bulk of a
scan's points lie on its sampled surfaces, where the kNN distance is the
sampling spacing the Gaussians should fill; the sparsest few percent are
outliers and stray returns whose kNN distance is their gap to the scene, and
a Gaussian that wide would cover the picture in a blurred cloud.

Colour: a cloud with rgb gives its Gaussians those colours (Gaussians.colors,
composited as they are; the values then hold the elevation z for the
transfer function's opacity); otherwise the values come from an attribute
chosen by name, the speed with a velocity, or the elevation z, so that a
transfer function always has something to show.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import numpy.typing as npt

from .._arrays import positive_int, real_array
from ..errors import DataError
from ..io import PointCloud
from ..io.cloud import check_finite
from .gaussians import Gaussians

__all__ = [
    "KNN_CLAMP_PERCENTILE",
    "STRETCH",
    "MAX_KNN",
    "frames_along",
    "gaussians_from_points",
    "knn_mean_distance",
    "knn_sigma",
]

KNN_CLAMP_PERCENTILE = 95.0  # isotropic kNN sigmas are clamped to this percentile of them
MAX_KNN = 64  # neighbours per point at most (the query holds N x k distances)
#: how many times longer than across a velocity-elongated Gaussian is along
#: the velocity by default: NARVis's (clvis.training.data.NARVIS_STRETCH)
STRETCH = 4.0


def _k(k) -> int:
    k = positive_int("k", k)
    if k > MAX_KNN:
        raise ValueError(f"k: expected 1..{MAX_KNN} neighbours, got {k}")
    return k


def _lone_sigma(positions: np.ndarray) -> float:
    """The sigma of a cloud of one distinct point (copies of it), which has
    no spacing to size its Gaussian by (it was 0: a Gaussian of no width,
    a blank picture): the smallest extent a camera frames around it
    (clvis.camera.min_extent), so that the view fitted to it shows a dot."""
    from ..camera import min_extent

    return min_extent(np.asarray(positions[0], np.float64))


def knn_mean_distance(positions: npt.ArrayLike, k: int = 4) -> np.ndarray:
    """(N,) float32: each point's mean distance to its k nearest other points
    (scipy.spatial.cKDTree), copies of a point counted as one point. Fewer
    than k + 1 distinct points: the mean over those there are; a single one:
    0. k in 1..MAX_KNN. positions: (N, 3) finite real coordinates
    (DataError naming the first point with a NaN or infinite one, or when a
    distance does not fit in float32)."""
    return _knn_mean(_finite_positions(positions), _k(k), True)


def _knn_mean(p: np.ndarray, k: int, merge: bool) -> np.ndarray:
    """knn_mean_distance of checked float64 positions; `merge`: copies of a
    point (found where a distance is 0) are merged once, then not again (two
    points 1e-200 apart are distance 0 but not copies)."""
    from scipy.spatial import cKDTree

    n = len(p)
    if n < 2:
        return np.zeros(n, np.float32)
    kk = min(k, n - 1)
    tree = _interruptible(cKDTree, p)
    # queried in the tree's own leaf order, so neighbouring queries walk the
    # same nodes (a scan's file order or a random order missed the caches:
    # 3x the CPU time at 10^6 points); the distances do not depend on the order
    order = tree.indices
    # (the query's workers are Python threads that this one joins: Ctrl-C lands at once)
    dist, _ = tree.query(p[order], k=kk + 1, workers=-1)
    if merge and not dist[:, 1].all():
        # copies of a point (merged scans, mesh vertices) are one point: at
        # distance 0 from each other, k copies made a Gaussian of no width
        # (np.unique only here: it costs about what the query does)
        unique, inverse = np.unique(p, axis=0, return_inverse=True)
        return _knn_mean(unique, k, False)[inverse.ravel()]
    with np.errstate(over="ignore"):  # the check below reports it
        mean = dist[:, 1:].mean(axis=1).astype(np.float32)
    if not np.isfinite(mean).all():
        raise DataError(
            "positions: the distances between points overflow float32 "
            f"(coordinates up to {np.abs(p).max():.3g}); recentre or rescale the cloud"
        )
    out = np.empty(n, np.float32)
    out[order] = mean
    return out


def _interruptible(fn: Any, *args: Any) -> Any:
    """fn(*args) (a call that releases the GIL and runs long in C, as
    cKDTree's build: ~2 s at 2M points) in a thread of its own, this thread
    waiting in an interruptible join: a Ctrl-C (or the CLI's SIGTERM) is
    raised here at once rather than when fn returns; fn then ends in the
    background and its result is dropped."""
    import threading

    out: list[Any] = []

    def run() -> None:
        try:
            out.append((True, fn(*args)))
        except BaseException as e:  # noqa: BLE001 - raised in the caller's thread below
            out.append((False, e))

    worker = threading.Thread(target=run, name="clvis-knn-build", daemon=True)
    worker.start()
    worker.join()
    ok, value = out[0]
    if not ok:
        raise value
    return value


def _finite_positions(positions) -> np.ndarray:
    """positions as (N, 3) float64, every coordinate finite (ValueError,
    TypeError or DataError naming what is wrong)."""
    p = real_array("positions", positions)
    if p.ndim != 2 or p.shape[1:] != (3,):
        raise ValueError(f"positions: expected shape (N, 3), got {p.shape}")
    p = p.astype(np.float64)
    finite = np.isfinite(p).all(axis=1)
    if not finite.all():
        bad = int(np.flatnonzero(~finite)[0])
        raise DataError(
            f"positions: point {bad} has a NaN or infinite coordinate "
            f"({int((~finite).sum()):,} of {len(p):,} points)"
        )
    return p


def knn_sigma(positions: npt.ArrayLike, k: int = 4) -> np.ndarray:
    """(N,) float32: the standard deviation of each point's isotropic Gaussian
    in :func:`gaussians_from_points` without a velocity or scale: its mean
    distance to its k nearest neighbours, clamped to the
    KNN_CLAMP_PERCENTILE-th percentile of those (the splat radius plane of
    narvis-scan: ``Rasterizer(..., radius=knn_sigma(positions))``)."""
    sigma = knn_mean_distance(positions, k).astype(np.float64)
    if len(sigma):
        sigma = np.minimum(sigma, np.percentile(sigma, KNN_CLAMP_PERCENTILE))
    return sigma.astype(np.float32)


def frames_along(directions: npt.ArrayLike) -> np.ndarray:
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


def gaussians_from_points(
    cloud: PointCloud | Any,
    *,
    velocity: Any = None,
    stretch: float = STRETCH,
    scale: Any = None,
    k: int = 4,
    values: Any = None,
    opacity: Any = 1.0,
    color_by: str | None = None,
) -> Gaussians:
    """Gaussians for the points of `cloud` (a clvis.PointCloud or (N, 3) positions).

    velocity : (N, 3), ``"cloud"`` (the cloud's own velocity) or None.
        Given: anisotropic Gaussians, scales = scale * (stretch, 1, 1) along
        (velocity, two normals); a point with zero velocity gets scale * (1, 1, 1).
        None: isotropic, sigma = scale, or (scale None) the mean distance to
        the k nearest neighbours (1..MAX_KNN), clamped to the
        KNN_CLAMP_PERCENTILE-th percentile of those distances (see the module doc);
        a cloud of one distinct point: clvis.camera.min_extent around it.
    scale : float or (N,) base sigma. For anisotropic Gaussians it defaults to
        the median k-nearest-neighbour distance: across the flow a Gaussian
        is as wide as the points are apart (NARVis's GR), `stretch` times
        that along it.
    values : (N,) or an attribute name of the cloud; default (see color_by) the
        speed |velocity| with a velocity, else the elevation z.
    opacity : float or (N,) in [0, 1].
    color_by : None, "rgb", "z" or an attribute name of the cloud.
        "rgb": the Gaussians carry the cloud's colours (ValueError without);
        "z": values = elevation; a name: values = that attribute. None: "rgb"
        when the cloud has colours and `values` is not given, else `values`
        or their default.

    A NaN or infinite coordinate, velocity component or value of the attribute
    the Gaussians are coloured by raises DataError naming it and the first
    such point.
    """
    if isinstance(cloud, PointCloud):
        positions = cloud.positions
    else:
        if isinstance(cloud, (str, os.PathLike)):
            raise TypeError(
                f"cloud: expected a PointCloud or (N, 3) positions, got a path ({cloud!r}): "
                "clvis.read_points reads it"
            )
        from ..io.objects import refuse_foreign

        refuse_foreign(cloud, "PointCloud", "cloud: expected a PointCloud or (N, 3) positions")
        positions = real_array("cloud", cloud)  # complex, bool, object and strings refused
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
    k = _k(k)
    cloud_colors = cloud.colors if isinstance(cloud, PointCloud) else None
    colors = None
    if color_by is not None:
        if not isinstance(color_by, str):
            raise TypeError(
                f"color_by: expected None, 'rgb', 'z' or an attribute name, got {type(color_by).__name__}"
            )
        if values is not None:
            raise ValueError("color_by and values: give one of them")
        if color_by == "rgb":
            if cloud_colors is None:
                raise ValueError("color_by='rgb': the cloud has no colours")
            colors = cloud_colors
        elif color_by == "z":
            values = positions[:, 2]
        else:
            attrs = cloud.attributes if isinstance(cloud, PointCloud) else {}
            if color_by not in attrs:
                have = ", ".join(["rgb"] * (cloud_colors is not None) + ["z", *attrs])
                raise ValueError(f"color_by: the cloud has no attribute {color_by!r} (it has {have})")
            values = attrs[color_by]
            check_finite(f"attribute {color_by!r}", values)
    elif values is None and cloud_colors is not None:
        colors = cloud_colors
    if isinstance(values, str):
        if not isinstance(cloud, PointCloud) or values not in cloud.attributes:
            raise ValueError(f"values: the cloud has no attribute {values!r}")
        name, values = values, cloud.attributes[values]
        check_finite(f"attribute {name!r}", values)
    if colors is not None and values is None:
        values = positions[:, 2]  # the transfer function's opacity reads something real

    if velocity is not None:
        vel = np.asarray(velocity, np.float64)
        if vel.shape != (n, 3):
            raise ValueError(f"velocity: expected shape ({n}, 3), got {vel.shape}")
        check_finite("velocity", vel)
        if scale is None:
            # the cross-section keeps the point spacing (it was the spacing /
            # stretch: needles 1/250 of the spacing thick, a blank picture)
            base = np.float64(np.median(knn_mean_distance(positions, k))) if n else 0.0
            base = np.full(n, base if base > 0 or not n else _lone_sigma(positions))
        else:
            base = _per_point("scale", scale, n)
        moving = np.linalg.norm(vel, axis=1) > 0
        scales = np.stack([base * np.where(moving, stretch, 1.0), base, base], axis=1)
        rotations = frames_along(vel)
        if values is None:
            values = np.linalg.norm(vel, axis=1)
    else:
        if scale is None:
            sigma = knn_mean_distance(positions, k).astype(np.float64)
            if n:  # knn_sigma's clamp, in float64
                sigma = np.minimum(sigma, np.percentile(sigma, KNN_CLAMP_PERCENTILE))
            if n and not sigma.any():  # one distinct point: no spacing to take
                sigma = np.full(n, _lone_sigma(positions))
        else:
            sigma = _per_point("scale", scale, n)
        scales = np.repeat(np.asarray(sigma, np.float64)[:, None], 3, axis=1)
        rotations = None
        if values is None:
            values = positions[:, 2]
    values = np.asarray(values)
    if values.shape != (n,):
        raise ValueError(f"values: expected shape ({n},), got {values.shape}")
    opacities = _per_point("opacity", opacity, n)
    return Gaussians(
        positions,
        scales,
        rotations,
        values.astype(np.float32),
        opacities,
        None if colors is None else colors[:, :3],
    )


def _per_point(name, v, n) -> np.ndarray:
    a = np.asarray(v, np.float64)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.shape != (n,):
        raise ValueError(f"{name}: expected a number or shape ({n},), got {a.shape}")
    if not np.isfinite(a).all() or (a < 0).any():
        raise ValueError(f"{name}: values must be finite and >= 0")
    return a
