"""A point cloud (:class:`PointCloud`), what it checks and converts, and the
helpers every point reader and writer shares."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np
import numpy.typing as npt

from .._arrays import real_array
from ..errors import DataError
from .files import write_replacing

# Named columns (PLY vertex properties, structured NPY fields) with a meaning.
_COLOR_NAMES: tuple[tuple[str, ...], ...] = (
    ("red", "green", "blue", "alpha"),
    ("r", "g", "b", "a"),
    ("diffuse_red", "diffuse_green", "diffuse_blue", "diffuse_alpha"),  # the PLY spec's material colours
)
_VELOCITY_NAMES: tuple[tuple[str, ...], ...] = (
    ("vx", "vy", "vz"),
    ("velocity_x", "velocity_y", "velocity_z"),
)
_RESERVED_COLUMNS = frozenset({"x", "y", "z", "radius"}.union(*_COLOR_NAMES, *_VELOCITY_NAMES))
_NPZ_KEYS = ("positions", "colors", "velocity", "radius", "origin")
# The PLY header comment that carries a cloud's origin.
_ORIGIN_COMMENT = "clvis origin"


def _vectors(name: str, a: npt.ArrayLike, n: int | None) -> np.ndarray:
    a = real_array(name, a)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (N, 3), got {a.shape}")
    _check_length(name, len(a), n)
    return np.ascontiguousarray(a, dtype=np.float32)


def _check_length(name: str, length: int, n: int | None) -> None:
    if n is not None and length != n:
        raise ValueError(f"{name}: {length} rows, but positions has {n}")


def _colors(a: npt.ArrayLike, n: int) -> np.ndarray:
    a = real_array("colors", a)
    if a.ndim != 2 or a.shape[1] not in (3, 4):
        raise ValueError(f"colors: expected shape (N, 3) or (N, 4), got {a.shape}")
    _check_length("colors", len(a), n)
    if not a.dtype.isnative:  # a big-endian uint16 is uint16
        a = a.astype(a.dtype.newbyteorder("="))
    if a.dtype == np.uint16:
        # as read_points reads a LAS file: many (laspy's simple.las, autzen)
        # keep 8-bit colours in their 16-bit fields, which >> 8 would make black
        a = (a >> 8 if a.size and a.max() > 255 else a).astype(np.uint8)
    elif a.dtype.kind == "f":
        if not ((a >= 0) & (a <= 1)).all():  # NaN fails too
            raise ValueError("colors: float colors must lie in [0, 1]")
        a = np.rint(a.astype(np.float64) * 255).astype(np.uint8)
    elif a.dtype != np.uint8:
        if a.size and (a.min() < 0 or a.max() > 255):
            raise ValueError(
                f"colors: {a.dtype} colors must lie in 0..255 "
                "(16-bit colors are scaled down; pass them as uint16)"
            )
        a = a.astype(np.uint8)
    if a.shape[1] == 3:
        a = np.concatenate([a, np.full((len(a), 1), 255, np.uint8)], axis=1)
    return np.ascontiguousarray(a)


def _attribute(key: object, a: npt.ArrayLike, n: int) -> np.ndarray:
    if not isinstance(key, str) or not key:
        raise TypeError(f"attributes: names must be non-empty strings, got {key!r}")
    name = f"attributes[{key!r}]"
    if isinstance(a, (str, bytes)) or a is None:
        raise TypeError(f"{name}: expected an array, got {type(a).__name__}")
    a = np.asarray(a)
    if a.ndim != 1:
        raise ValueError(f"{name}: expected shape (N,), got {a.shape}")
    _check_length(name, len(a), n)
    if a.dtype == np.bool_:
        return a.astype(np.uint8)
    if a.dtype.kind not in "iuf":
        raise TypeError(f"{name}: expected real numbers or bools, got dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype=np.uint8 if a.dtype == np.uint8 else np.float32)


class PointCloud:
    """Points with optional colors, velocities, radii and per-point attributes.

    The constructor checks and converts its arguments (TypeError / ValueError
    naming the argument).

    Parameters
    ----------
    positions : (N, 3) real array
        Stored as float32, C-contiguous.
    colors : (N, 3) or (N, 4) array, optional
        uint8 as is; uint16 scaled down (>> 8) unless none is above 255 (8-bit
        colours in 16-bit fields, as LAS files often have them: as is, as
        read_points reads them); float in [0, 1] scaled by 255 and
        rounded; other integers in 0..255 as is. Stored as (N, 4) uint8 RGBA
        (alpha 255 when not given).
    attributes : dict of str -> (N,) array, optional
        float32 and uint8 kept, bool stored as uint8, other reals as float32.
    velocity : (N, 3) real array, optional
        Stored as float32.
    radius : (N,) real array, optional
        Stored as float32.
    origin : (3,) real, optional
        World position of the local coordinate origin (float64, default zeros).
    """

    def __init__(
        self,
        positions: npt.ArrayLike,
        colors: npt.ArrayLike | None = None,
        attributes: Mapping[str, Any] | None = None,
        velocity: npt.ArrayLike | None = None,
        radius: npt.ArrayLike | None = None,
        origin: npt.ArrayLike | None = None,
    ) -> None:
        self.positions = _vectors("positions", positions, None)
        n = len(self.positions)
        self.colors = None if colors is None else _colors(colors, n)
        self.velocity = None if velocity is None else _vectors("velocity", velocity, n)
        if radius is None:
            self.radius = None
        else:
            r = real_array("radius", radius)
            if r.ndim != 1:
                raise ValueError(f"radius: expected shape (N,), got {r.shape}")
            _check_length("radius", len(r), n)
            self.radius = np.ascontiguousarray(r, dtype=np.float32)
        if attributes is None:
            attributes = {}
        if not isinstance(attributes, dict):
            raise TypeError(f"attributes: expected a dict, got {type(attributes).__name__}")
        self.attributes = {k: _attribute(k, v, n) for k, v in attributes.items()}
        o = np.zeros(3) if origin is None else np.asarray(real_array("origin", origin), dtype=np.float64)
        if o.shape != (3,) or not np.isfinite(o).all():
            raise ValueError(f"origin: expected 3 finite numbers, got {o.tolist()}")
        self.origin = o

    def __len__(self) -> int:
        return len(self.positions)

    def __repr__(self) -> str:
        parts = [f"{len(self)} points"]
        parts += [name for name in ("colors", "velocity", "radius") if getattr(self, name) is not None]
        if self.attributes:
            parts.append(f"attributes={list(self.attributes)}")
        if self.origin.any():
            parts.append(f"origin={self.origin.tolist()}")
        return f"PointCloud({', '.join(parts)})"

    @property
    def attribute_names(self) -> tuple[str, ...]:
        """The attribute names, in insertion order."""
        return tuple(self.attributes)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max), two (3,) float64 arrays over the points whose x, y, z are all
        finite, in local coordinates (add ``origin`` for world coordinates)."""
        finite = np.isfinite(self.positions).all(axis=1)
        if not finite.any():
            raise ValueError("bounds: the cloud has no finite points")
        p = self.positions[finite]
        return p.min(axis=0).astype(np.float64), p.max(axis=0).astype(np.float64)

    def subset(self, index: npt.ArrayLike | slice) -> PointCloud:
        """A new cloud with the points selected by `index`: a boolean mask of length
        N, an array of indices, or a slice. An index out of range raises
        DataError."""
        if not isinstance(index, slice):
            index = np.asarray(index)
            if index.dtype == np.bool_:
                if index.shape != (len(self),):
                    raise ValueError(f"index: a mask must have shape ({len(self)},), got {index.shape}")
            elif index.dtype.kind not in "iu" or index.ndim != 1:
                raise TypeError(
                    f"index: expected a boolean mask, 1-D integer indices or a slice, "
                    f"got {index.dtype} with shape {index.shape}"
                )

            elif index.size and not (-len(self) <= index.min() and index.max() < len(self)):
                raise DataError(
                    f"index: indices must lie in [-{len(self)}, {len(self)}), got "
                    f"{int(index.min())}..{int(index.max())}"
                )

        def pick(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[index]

        return PointCloud(
            self.positions[index],
            pick(self.colors),
            {k: v[index] for k, v in self.attributes.items()},
            pick(self.velocity),
            pick(self.radius),
            self.origin,
        )


def _cloud(path: Path, **fields: Any) -> PointCloud:
    """PointCloud(**fields), its complaints turned into DataErrors naming the file."""
    try:
        return PointCloud(**fields)
    except (TypeError, ValueError) as e:
        raise DataError(f"{path}: {e}") from e


def check_finite(name: str, a: Any) -> None:
    """DataError when a per-point array (velocity (N, 3), an attribute (N,))
    holds a NaN or infinite value: its message names `name` (the caller puts
    the file and the attribute in it), the first such point, its value and
    how many points have one."""
    a = np.asarray(a)
    if a.dtype.kind not in "fc" or not a.size:
        return
    bad = ~np.isfinite(a.reshape(len(a), -1)).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        values = [f"{v:.6g}" for v in np.ravel(a[i]).tolist()]
        value = values[0] if a.ndim == 1 else f"[{', '.join(values)}]"
        raise DataError(f"{name}: point {i} is {value}, not finite ({int(bad.sum()):,} of {len(a):,} points)")


#: positions farther from zero than this many times the cloud's extent are
#: read relative to their minimum: float32's spacing there (|x| 2^-24) is then
#: over 1e-5 of the extent
FAR_FROM_ZERO = 2**24 * 1e-5


def bulk_origin(xyz: np.ndarray) -> np.ndarray:
    """(3,) float64: the origin a file's wide (float64) positions `xyz`
    ((N, 3)) are kept relative to, in float32: the minimum of the finite
    points; where some lie far outside the bulk (a few stray records at (0, 0,
    0) in a georeferenced scan, which clvis render leaves out of the view),
    the minimum of the bulk (the points within :func:`clvis.camera.robust_fences`
    of a sample, as clvis render finds it). Relative to the strays' minimum,
    float32 quantised the bulk, 6e6 m from it, to 0.5 m: a scan drawn as rows
    of points. Zeros for no finite point."""
    return _bulk_box(xyz)[0]


def _bulk_box(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the finite points of `xyz`, or of their bulk where some
    lie outside it (bulk_origin); zeros for no finite point. Points all
    finite (a file's usual case): one isfinite pass and a min and max a
    column (an (N, 3) array's min over axis 0 walks it strided, and a
    reduction with where= more slowly still: 20 M points took 1.9 s, now
    about 0.2 s)."""
    from ..camera import robust_fences, robust_sample_step

    p = np.asarray(xyz, np.float64)
    finite: np.ndarray
    if np.isfinite(p).all():
        finite = np.ones(len(p), bool)
        lowest = np.array([p[:, k].min() for k in range(3)]) if len(p) else np.zeros(3)
        highest = np.array([p[:, k].max() for k in range(3)]) if len(p) else np.zeros(3)
        if not len(p):
            return lowest, highest
    elif not (finite := np.asarray(np.isfinite(p).all(axis=1))).any():
        return np.zeros(3), np.zeros(3)
    else:
        lowest = np.min(p, axis=0, where=finite[:, None], initial=np.inf)
        highest = np.max(p, axis=0, where=finite[:, None], initial=-np.inf)
    try:
        fence_lo, fence_hi = robust_fences(p[:: robust_sample_step(len(p))])
    except ValueError:  # the sample holds no finite row (the finite points are few): no bulk to take
        return lowest, highest
    if (lowest >= fence_lo).all() and (highest <= fence_hi).all():
        return lowest, highest  # no stray point (cheap: no pass over the points but these)
    with np.errstate(invalid="ignore"):
        bulk = np.asarray(finite & ((p >= fence_lo) & (p <= fence_hi)).all(axis=1))
    if not bulk.any():
        return lowest, highest
    return (
        np.min(p, axis=0, where=bulk[:, None], initial=np.inf),
        np.max(p, axis=0, where=bulk[:, None], initial=-np.inf),
    )


def component_columns(name: str, a: np.ndarray) -> dict[str, np.ndarray]:
    """The attributes of an (N, C) per-point array of several components (a
    VTK array, a LAS extra-bytes field, an Open3D tensor attribute): one a
    component, named NAME_x, NAME_y, NAME_z for three, else NAME_0, NAME_1..."""
    suffixes = "xyz" if a.shape[1] == 3 else [str(j) for j in range(a.shape[1])]
    return {f"{name}_{s}": np.ascontiguousarray(a[:, j]) for j, s in enumerate(suffixes)}


def relative_positions(xyz: Any, origin: Any = None) -> tuple[Any, Any]:
    """(positions, origin) of a file's (N, 3) positions: stored wider than
    float32 (float64, int64), with no origin of their own and too far from
    zero for float32 (FAR_FROM_ZERO), float32 relative to their finite
    minimum and that minimum as the origin (world = origin + position), as
    LAS, E57 and ASCII files are read (float32 of x = 1e9 + [0, 1) is 1e9 for
    every point: the cloud fell onto one); any other as given."""
    a = np.asarray(xyz)
    if (
        origin is not None
        or a.ndim != 2
        or a.shape[1] != 3
        or a.dtype.kind not in "iuf"
        or a.dtype.itemsize <= 4
    ):
        return xyz, origin
    d = a.astype(np.float64)
    finite = np.isfinite(d).all(axis=1)
    if not finite.any():
        return xyz, origin
    # the bulk's box: a few stray points far away (records at (0, 0, 0)) neither widen the extent
    # float32 must resolve nor move the origin away from the points that are drawn
    lowest, highest = _bulk_box(d)
    reach = float(np.maximum(np.abs(lowest), np.abs(highest)).max())
    if reach <= FAR_FROM_ZERO * float((highest - lowest).max()):
        return xyz, origin
    return (d - lowest).astype(np.float32), lowest.tolist()


def _from_columns(path: Path, columns: dict[str, np.ndarray], origin: Any = None) -> PointCloud:
    """A cloud from named 1-D columns (PLY properties, structured NPY fields).
    The names clvis reads (x, y, z, the colours, the velocity, radius) are
    found in any case (X, Y, Z: a pandas DataFrame's records, some PLY
    writers) where the file has no column of that name in lower case and
    one only in another case."""
    columns = _lower_reserved(columns)
    missing = [c for c in "xyz" if c not in columns]
    if missing:
        raise DataError(f"{path}: no {', '.join(missing)} column (found {', '.join(columns) or 'none'})")
    columns = dict(columns)

    def take(names: Iterable[str]) -> np.ndarray:
        return np.stack([columns.pop(c) for c in names], axis=1)

    positions, origin = relative_positions(take("xyz"), origin)
    fields: dict[str, Any] = {"positions": positions, "origin": origin}
    for names in _COLOR_NAMES:
        if all(c in columns for c in names[:3]):
            fields["colors"] = take([c for c in names if c in columns])
            break
    for names in _VELOCITY_NAMES:
        if all(c in columns for c in names):
            fields["velocity"] = take(names)
            break
    if "radius" in columns:
        fields["radius"] = columns.pop("radius")
    fields["attributes"] = columns
    return _cloud(path, **fields)


def _lower_reserved(columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """`columns` with each group of names clvis reads (x, y, z; a colour
    group, its alpha with it; a velocity group) that the file holds whole in
    another case only (X, Y, Z: one column each) renamed to it, in the same
    order. A lone name is left as it is: an attribute "R" or "A" (an
    amplitude) is no colour channel, "Radius" no radius unless so named."""
    by_lower: dict[str, list[str]] = {}
    for k in columns:
        by_lower.setdefault(k.lower(), []).append(k)

    def other_case(c: str) -> bool:  # held in another case only, once
        return c not in columns and len(by_lower.get(c, ())) == 1

    rename: dict[str, str] = {}
    for group in (("x", "y", "z"), *_COLOR_NAMES, *_VELOCITY_NAMES):
        if all(other_case(c) for c in group[:3]):  # a colour's alpha goes with its red, green and blue
            rename.update({by_lower[c][0]: c for c in group if other_case(c)})
    return {rename.get(k, k): v for k, v in columns.items()} if rename else columns


def _write_or_remove(path: str | os.PathLike[str], write: Callable[[IO[Any]], object]) -> None:
    """write(file) into a file that then replaces `path` atomically: on any
    failure `path` keeps what it held (see :mod:`clvis.io.files`)."""
    write_replacing(path, write)


def _check_cloud(cloud: object) -> None:
    if not isinstance(cloud, PointCloud):
        raise TypeError(f"cloud: expected a PointCloud, got {type(cloud).__name__}")
