"""Point cloud files: :class:`PointCloud` and the readers and writers.

:func:`read_points` reads PLY (ASCII or binary, via plyfile), LAS and LAZ (via
laspy; LAZ needs its lazrs backend), NPY and NPZ, chosen by the file extension.
:func:`write_ply` and :func:`save_npz` write a cloud back so that it round-trips.

Positions are float32, what the kernels read. float32 keeps about 7 significant
digits, too few for georeferenced coordinates (UTM eastings of 10^5..10^6 m), so
the LAS/LAZ reader subtracts the minimum of the points' coordinates and keeps it,
in float64, as ``cloud.origin``: world position = origin + position. Other
formats take positions as stored (origin zero), except that files written by
clvis carry their origin along (an NPZ key, a PLY header comment).

A missing file raises FileNotFoundError; a file clvis cannot read (unknown
extension, malformed or truncated content, wrong shapes) raises
:class:`clvis.errors.DataError` naming the file and the problem.
"""

from __future__ import annotations

import errno
import os
import struct
import tokenize
import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ._arrays import real_array
from .errors import DataError

__all__ = ["PointCloud", "read_points", "save_npz", "write_ply"]

# Named columns (PLY vertex properties, structured NPY fields) with a meaning.
_COLOR_NAMES = (("red", "green", "blue", "alpha"), ("r", "g", "b", "a"))
_VELOCITY_NAMES = (("vx", "vy", "vz"), ("velocity_x", "velocity_y", "velocity_z"))
_RESERVED_COLUMNS = frozenset({"x", "y", "z", "radius"}.union(*_COLOR_NAMES, *_VELOCITY_NAMES))
_NPZ_KEYS = ("positions", "colors", "velocity", "radius", "origin")
# What np.load raises on a malformed file (the header is parsed as a Python literal).
_NPY_ERRORS = (ValueError, EOFError, SyntaxError, tokenize.TokenError)
# ... and on a malformed zip archive (NotImplementedError: unknown compression;
# RuntimeError: a member marked encrypted).
_NPZ_ERRORS = (*_NPY_ERRORS, zipfile.BadZipFile, zlib.error, NotImplementedError, RuntimeError)
# The PLY header comment that carries a cloud's origin.
_ORIGIN_COMMENT = "clvis origin"


def _vectors(name: str, a, n: int | None) -> np.ndarray:
    a = real_array(name, a)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (N, 3), got {a.shape}")
    _check_length(name, len(a), n)
    return np.ascontiguousarray(a, dtype=np.float32)


def _check_length(name: str, length: int, n: int | None) -> None:
    if n is not None and length != n:
        raise ValueError(f"{name}: {length} rows, but positions has {n}")


def _colors(a, n: int) -> np.ndarray:
    a = real_array("colors", a)
    if a.ndim != 2 or a.shape[1] not in (3, 4):
        raise ValueError(f"colors: expected shape (N, 3) or (N, 4), got {a.shape}")
    _check_length("colors", len(a), n)
    if a.dtype == np.uint16:
        a = (a >> 8).astype(np.uint8)
    elif a.dtype.kind == "f":
        if not ((a >= 0) & (a <= 1)).all():         # NaN fails too
            raise ValueError("colors: float colors must lie in [0, 1]")
        a = np.rint(a.astype(np.float64) * 255).astype(np.uint8)
    elif a.dtype != np.uint8:
        if a.size and (a.min() < 0 or a.max() > 255):
            raise ValueError(f"colors: {a.dtype} colors must lie in 0..255 "
                             "(uint16 colors are scaled down; pass them as uint16)")
        a = a.astype(np.uint8)
    if a.shape[1] == 3:
        a = np.concatenate([a, np.full((len(a), 1), 255, np.uint8)], axis=1)
    return np.ascontiguousarray(a)


def _attribute(key, a, n: int) -> np.ndarray:
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
        uint8 as is; uint16 scaled down (>> 8); float in [0, 1] scaled by 255 and
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

    def __init__(self, positions: npt.ArrayLike, colors: npt.ArrayLike | None = None,
                 attributes: Mapping[str, Any] | None = None, velocity: npt.ArrayLike | None = None,
                 radius: npt.ArrayLike | None = None, origin: npt.ArrayLike | None = None) -> None:
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
        N, an array of indices, or a slice."""
        if not isinstance(index, slice):
            index = np.asarray(index)
            if index.dtype == np.bool_:
                if index.shape != (len(self),):
                    raise ValueError(f"index: a mask must have shape ({len(self)},), got {index.shape}")
            elif index.dtype.kind not in "iu" or index.ndim != 1:
                raise TypeError(f"index: expected a boolean mask, 1-D integer indices or a slice, "
                                f"got {index.dtype} with shape {index.shape}")

        def pick(a):
            return None if a is None else a[index]

        return PointCloud(self.positions[index], pick(self.colors),
                          {k: v[index] for k, v in self.attributes.items()},
                          pick(self.velocity), pick(self.radius), self.origin)


# ---------------------------------------------------------------- reading

def read_points(path: str | os.PathLike[str]) -> PointCloud:
    """Read a point cloud; the format comes from the extension (case-insensitive).

    - ``.ply``: the ``vertex`` element. x, y, z are required; red, green, blue
      [, alpha] (or r, g, b [, a]) become colors; vx, vy, vz (or velocity_x, ...)
      the velocity; radius the radius; every other scalar property an attribute.
    - ``.las``, ``.laz``: positions relative to ``origin`` = the minimum of the
      points' coordinates; red/green/blue become 8-bit (>> 8 when any value
      exceeds 255, else as is); every other dimension (intensity, classification,
      return_number, ...) an attribute. gps_time is stored as seconds since the
      earliest point, which float32 resolves where absolute GPS time would not.
    - ``.npy``: an (N, 3) array, or a structured array with fields x, y, z and
      others named as for PLY.
    - ``.npz``: key ``positions`` (N, 3) required; ``colors``, ``velocity``,
      ``radius``, ``origin`` optional; every other key an (N,) attribute.
    """
    path = Path(path)
    readers = {".ply": _read_ply, ".las": _read_las, ".laz": _read_las, ".npy": _read_npy,
               ".npz": _read_npz}
    if not path.exists():
        raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), str(path))
    reader = readers.get(path.suffix.lower())
    if reader is None:
        raise DataError(f"{path}: unknown point cloud format {path.suffix!r}; "
                        f"expected one of {', '.join(readers)}")
    return reader(path)


def _cloud(path: Path, **fields) -> PointCloud:
    """PointCloud(**fields), its complaints turned into DataErrors naming the file."""
    try:
        return PointCloud(**fields)
    except (TypeError, ValueError) as e:
        raise DataError(f"{path}: {e}") from e


def _from_columns(path: Path, columns: dict[str, np.ndarray], origin=None) -> PointCloud:
    """A cloud from named 1-D columns (PLY properties, structured NPY fields)."""
    missing = [c for c in "xyz" if c not in columns]
    if missing:
        raise DataError(f"{path}: no {', '.join(missing)} column (found {', '.join(columns) or 'none'})")
    columns = dict(columns)

    def take(names):
        return np.stack([columns.pop(c) for c in names], axis=1)

    fields = {"positions": take("xyz"), "origin": origin}
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


def _read_ply(path: Path) -> PointCloud:
    import plyfile

    try:
        ply = plyfile.PlyData.read(str(path), mmap=False)
    except (plyfile.PlyParseError, ValueError, OverflowError, EOFError, struct.error) as e:
        raise DataError(f"{path}: malformed PLY file: {e}") from e
    except MemoryError as e:
        raise DataError(f"{path}: the PLY header declares more data than fits in memory") from e
    names = [el.name for el in ply.elements]
    if "vertex" not in names:
        raise DataError(f"{path}: the PLY file has no vertex element "
                        f"(elements: {', '.join(names) or 'none'})")
    data = ply["vertex"].data           # plyfile raises on fewer rows than the header declares
    columns = {k: data[k] for k in data.dtype.names if data.dtype[k].kind in "iufb"}   # lists skipped
    origin = None
    for c in ply.comments:
        if c.startswith(_ORIGIN_COMMENT + " "):
            try:
                origin = [float(v) for v in c[len(_ORIGIN_COMMENT):].split()]
            except ValueError as e:
                raise DataError(f"{path}: malformed origin comment {c!r}") from e
    return _from_columns(path, columns, origin)


def _check_las_header(path: Path) -> None:
    """Reject header counts the file cannot hold before laspy sees them: laspy loops
    over a corrupt VLR count (up to 2^32) reading empty records, for hours."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(375)
    if len(head) < 227 or head[:4] != b"LASF":
        raise DataError(f"{path}: not a LAS/LAZ file (no LASF signature, or shorter than a header)")
    # public header fields from byte 94: header size, offset to point data, number of VLRs,
    # point data format, record length, legacy point count
    header_size, data_offset, n_vlr, point_format, record_len, count = struct.unpack_from(
        "<HIIBHI", head, 94)
    if header_size < 227 or header_size + 54 * n_vlr > data_offset:
        raise DataError(f"{path}: malformed LAS/LAZ header: header size {header_size} and {n_vlr} VLRs "
                        f"do not fit before the point data at byte {data_offset}")
    if data_offset > size:
        raise DataError(f"{path}: truncated LAS/LAZ file: the point data should start at byte {data_offset}, "
                        f"the file has {size} bytes")
    if (head[24], head[25]) >= (1, 4) and header_size >= 375:
        evlr_start, n_evlr, count64 = struct.unpack_from("<QIQ", head, 235)
        count = count64 or count
        if n_evlr and evlr_start + 60 * n_evlr > size:
            raise DataError(f"{path}: malformed LAS/LAZ header: {n_evlr} extended VLRs from byte "
                            f"{evlr_start} of {size}")
    compressed = point_format & 0xC0
    if not compressed and data_offset + count * record_len > size:
        raise DataError(f"{path}: truncated LAS file: the header declares {count} points of {record_len} "
                        f"bytes from byte {data_offset}, the file has {size} bytes")


def _read_las(path: Path) -> PointCloud:
    import laspy

    _check_las_header(path)
    try:
        las = laspy.read(str(path))
        n, declared = len(las.points), las.header.point_count
    except (laspy.errors.LaspyException, ValueError, RuntimeError, OverflowError, EOFError,
            struct.error) as e:                     # RuntimeError: lazrs's decompression errors
        raise DataError(f"{path}: malformed LAS/LAZ file: {e}") from e
    except MemoryError as e:
        raise DataError(f"{path}: the file declares more points than fit in memory") from e
    if n != declared:
        raise DataError(f"{path}: truncated LAS/LAZ file: the header declares {declared} points, "
                        f"{n} were read")
    xyz = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    origin = xyz.min(axis=0) if n else np.zeros(3)
    dims = list(las.point_format.dimension_names)
    fields = {"positions": (xyz - origin).astype(np.float32), "origin": origin}
    if all(c in dims for c in ("red", "green", "blue")):
        rgb = np.stack([np.asarray(las[c]) for c in ("red", "green", "blue")], axis=1)
        fields["colors"] = (rgb >> 8 if n and rgb.max() > 255 else rgb).astype(np.uint8)
    attributes = {}
    for name in dims:
        if name in ("X", "Y", "Z", "red", "green", "blue"):
            continue
        a = np.asarray(las[name])
        if a.ndim != 1:              # array-valued extra bytes
            continue
        if name == "gps_time" and n:
            a = a - a.min()
        attributes[name] = a
    fields["attributes"] = attributes
    return _cloud(path, **fields)


def load_npy(path) -> np.ndarray:
    """The array of a .npy file; DataError naming the file when it is malformed
    or is an .npz archive (no pickles)."""
    with open(path, "rb") as f:                     # np.load leaks its own handle on bad files
        try:
            a = np.load(f, allow_pickle=False)
        except _NPY_ERRORS as e:
            raise DataError(f"{path}: malformed NPY file: {e}") from e
    if not isinstance(a, np.ndarray):
        raise DataError(f"{path}: expected an NPY array, found an NPZ archive")
    return a


def _read_npy(path: Path) -> PointCloud:
    a = load_npy(path)
    if a.dtype.names:
        if a.ndim != 1:
            raise DataError(f"{path}: expected a 1-D structured array, got shape {a.shape}")
        return _from_columns(path, {k: a[k] for k in a.dtype.names if a.dtype[k].ndim == 0})
    if a.ndim != 2 or a.shape[1] != 3:
        raise DataError(f"{path}: expected an (N, 3) array or a structured array with x, y, z fields, "
                        f"got shape {a.shape}")
    return _cloud(path, positions=a)


def _read_npz(path: Path) -> PointCloud:
    with open(path, "rb") as f:                     # np.load leaks its own handle on bad files
        try:
            z = np.load(f, allow_pickle=False)
            if isinstance(z, np.lib.npyio.NpzFile):
                with z:
                    arrays = {k: z[k] for k in z.files}
        except _NPZ_ERRORS as e:
            raise DataError(f"{path}: malformed NPZ file: {e}") from e
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise DataError(f"{path}: expected an NPZ archive, found an NPY array")
    if "positions" not in arrays:
        raise DataError(f"{path}: no 'positions' array (keys: {', '.join(arrays) or 'none'})")
    fields = {k: arrays.pop(k) for k in _NPZ_KEYS if k in arrays}
    fields["attributes"] = arrays
    return _cloud(path, **fields)


# ---------------------------------------------------------------- writing

def _write_or_remove(path, write) -> None:
    """write(file) into `path`; on any failure the partial file is removed."""
    path = Path(path)
    with open(path, "wb") as f:
        try:
            write(f)
        except BaseException:
            f.close()
            path.unlink()
            raise


def _check_cloud(cloud) -> None:
    if not isinstance(cloud, PointCloud):
        raise TypeError(f"cloud: expected a PointCloud, got {type(cloud).__name__}")


def write_ply(path, cloud: PointCloud, text: bool = False) -> None:
    """Write `cloud` as a PLY file (binary little-endian, or ASCII with `text`).

    Vertex properties: x, y, z (float); red, green, blue, alpha (uchar); vx, vy, vz
    and radius (float); one property per attribute (float or uchar). A nonzero
    origin goes into a header comment that :func:`read_points` reads back.
    """
    import plyfile

    _check_cloud(cloud)
    for k in cloud.attributes:
        if k in _RESERVED_COLUMNS or not k.isidentifier():
            raise ValueError(f"cloud: attribute {k!r} cannot be a PLY property "
                             "(a reserved name or not an identifier)")
    columns = [(c, cloud.positions[:, i]) for i, c in enumerate("xyz")]
    if cloud.colors is not None:
        columns += [(c, cloud.colors[:, i]) for i, c in enumerate(_COLOR_NAMES[0])]
    if cloud.velocity is not None:
        columns += [(c, cloud.velocity[:, i]) for i, c in enumerate(_VELOCITY_NAMES[0])]
    if cloud.radius is not None:
        columns.append(("radius", cloud.radius))
    columns += list(cloud.attributes.items())
    vertex = np.empty(len(cloud), dtype=[(k, v.dtype) for k, v in columns])
    for k, v in columns:
        vertex[k] = v
    comments = []
    if cloud.origin.any():
        comments.append(f"{_ORIGIN_COMMENT} {' '.join(repr(float(v)) for v in cloud.origin)}")
    ply = plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex")], text=text,
                          byte_order="<", comments=comments)
    _write_or_remove(path, ply.write)


def save_npz(path, cloud: PointCloud) -> None:
    """Write `cloud` as an uncompressed NPZ file with the keys :func:`read_points`
    reads: positions, origin, colors / velocity / radius when present, and one
    key per attribute."""
    _check_cloud(cloud)
    clash = [k for k in cloud.attributes if k in _NPZ_KEYS]
    if clash:
        raise ValueError(f"cloud: attribute names {clash} clash with the NPZ keys {list(_NPZ_KEYS)}")
    arrays = {"positions": cloud.positions, "origin": cloud.origin}
    arrays.update({k: getattr(cloud, k) for k in ("colors", "velocity", "radius")
                   if getattr(cloud, k) is not None})
    arrays.update(cloud.attributes)

    def write(f):
        # np.savez's own keywords (file, allow_pickle) would clash with attribute names
        with zipfile.ZipFile(f, "w") as archive:
            for k, v in arrays.items():
                with archive.open(f"{k}.npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, np.asarray(v), allow_pickle=False)

    _write_or_remove(path, write)
