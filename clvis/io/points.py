"""Point cloud files: :class:`PointCloud` and the readers and writers.

:func:`read_points` reads PLY (ASCII or binary, via plyfile), LAS and LAZ (via
laspy; LAZ needs its lazrs backend), NPY and NPZ, PCD, E57, .xyz/.txt/.csv/.pts/.xyzn/.xyzrgb text and
VTK point sets (.vtp, .vtu, .vts, legacy .vtk), chosen by the file extension.
:func:`write_ply` and :func:`save_npz` write a cloud back so that it round-trips.

Positions are float32, what the kernels read. float32 keeps about 7 significant
digits, too few for georeferenced coordinates (UTM eastings of 10^5..10^6 m), so
the LAS/LAZ reader subtracts the minimum of the points' coordinates and keeps it,
in float64, as ``cloud.origin``: world position = origin + position; so do
the E57 and ASCII readers, and the PLY, NPY and NPZ readers for double x, y, z
too far from zero for float32 (more than ~170 times the cloud's extent). Where
a few stray points lie far from the rest (records at (0, 0, 0) in a
georeferenced scan), the minimum and the extent are the bulk's
(:func:`clvis.io.cloud.bulk_origin`): relative to the strays the scan itself
kept only 0.5 m at 6e6 m. Other
formats take positions as stored (origin zero), except that files written by
clvis carry their origin along (an NPZ key, a PLY header comment).

A missing file raises FileNotFoundError; a file clvis cannot read (unknown
extension, malformed or truncated content, wrong shapes) raises
:class:`clvis.errors.DataError` naming the file and the problem.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..errors import DataError
from .ascii import SUFFIXES as _ASCII_SUFFIXES
from .ascii import _read_ascii
from .cloud import (
    _NPZ_KEYS,
    PointCloud,
    _check_cloud,
    _cloud,
    _from_columns,
    _write_or_remove,
    relative_positions,
)
from .e57 import _read_e57
from .files import mesh_hint, regular_file
from .las import _read_las
from .npy import load_npy, load_npz
from .pcd import _read_pcd
from .ply import _read_ply, write_ply
from .polydata import SUFFIXES as _VTK_SUFFIXES
from .polydata import read_vtk_points

__all__ = ["PointCloud", "read_points", "save_npz", "write_ply"]

#: the file name endings read_points reads (the commands pick points or a volume by them)
#: (.npy: an (N, 3) array or a volume; .vtk: a point set, or a volume where its DATASET
#: is STRUCTURED_POINTS or RECTILINEAR_GRID)
POINT_SUFFIXES = (".ply", ".las", ".laz", ".npy", ".npz", ".pcd", ".e57", *_ASCII_SUFFIXES, *_VTK_SUFFIXES)


# ---------------------------------------------------------------- reading


def _readers() -> dict[str, Any]:
    """{suffix: reader}, one for each of POINT_SUFFIXES."""
    readers = {".ply": _read_ply, ".las": _read_las, ".laz": _read_las, ".npy": _read_npy, ".npz": _read_npz}
    readers.update({".pcd": _read_pcd, ".e57": _read_e57, **dict.fromkeys(_ASCII_SUFFIXES, _read_ascii)})
    readers.update(dict.fromkeys(_VTK_SUFFIXES, read_vtk_points))
    return readers


def read_points(path: str | os.PathLike[str]) -> PointCloud:
    """Read a point cloud; the format comes from the extension (case-insensitive).

    - ``.ply``: the ``vertex`` element. x, y, z are required; red, green, blue
      [, alpha] (or r, g, b [, a], or diffuse_red, ...) become colors; vx, vy, vz
      (or velocity_x, ...) the velocity; radius the radius (these names in any
      case where the file has no lower-case one: X, Y, Z); every other scalar
      property an attribute.
      Double x, y, z too far from zero for float32 (more than ~170 times the
      cloud's extent): positions relative to ``origin`` = their finite minimum
      (unless the file carries clvis's origin comment), as for NPY and NPZ.
    - ``.las``, ``.laz``: positions relative to ``origin`` = the minimum of the
      points' coordinates (of their bulk, where a few lie far away);
      red/green/blue become 8-bit (>> 8 when any value exceeds 255, else as
      is); every other dimension (intensity, classification, return_number,
      ...) an attribute. gps_time is stored as seconds since the
      earliest point, which float32 resolves where absolute GPS time would not.
    - ``.npy``: an (N, 3) array, or a structured array with fields x, y, z and
      others named as for PLY; float64 (or int64) positions as for PLY.
    - ``.npz``: key ``positions`` (N, 3) required; ``colors``, ``velocity``,
      ``radius``, ``origin`` optional; every other key an (N,) attribute;
      float64 positions without an ``origin`` as for PLY. An archive of one
      array under any other name (``np.savez(path, xyz)``: ``arr_0``) is
      read as a ``.npy`` of it.
    - ``.pcd``: the Point Cloud Library's format, ascii, binary or
      binary_compressed, through pypcd4 (the ``pcd`` extra; :mod:`clvis.io.pcd`).
    - ``.xyz``, ``.txt``, ``.csv``: one point a line, columns named by a header
      or by their count, positions relative to their minimum as for LAS
      (:mod:`clvis.io.ascii`); so are Leica's ``.pts`` (its point count
      first) and Open3D's ``.xyzn`` (normals) and ``.xyzrgb`` (colours).
    - ``.e57``: ASTM E57 scans through pye57 (the ``e57`` extra), joined,
      positions relative to their minimum as for LAS (:mod:`clvis.io.e57`).
    - ``.vtp``, ``.vtu``, ``.vts``, ``.vtk``: VTK PolyData, UnstructuredGrid
      and StructuredGrid (XML) and legacy POLYDATA, UNSTRUCTURED_GRID or
      STRUCTURED_GRID through VTK's readers (the ``vtk`` extra): the points
      (a mesh's vertices; its cells not kept), unsigned-char RGB(A) point
      data the colours, the other point arrays attributes; double positions
      as for PLY (:mod:`clvis.io.polydata`). A legacy STRUCTURED_POINTS
      or RECTILINEAR_GRID .vtk is a volume (:func:`clvis.io.read_volume`).
    """
    readers = _readers()
    # a FIFO would block the read, /dev/zero never end, a directory fail in the parser
    path = regular_file(path)
    reader = readers.get(path.suffix.lower())
    if reader is None:
        raise DataError(
            f"{path}: unknown point cloud format {path.suffix!r}; expected one of {', '.join(readers)}"
            f"{mesh_hint(path)}"
        )
    return reader(path)


def _read_npy(path: Path) -> PointCloud:
    return _from_array(path, load_npy(path))


def _from_array(path: Path, a: np.ndarray) -> PointCloud:
    """The cloud of one array: (N, 3) positions, or a structured array's
    x, y, z (and other) fields."""
    if a.dtype.names:
        if a.ndim != 1:
            raise DataError(f"{path}: expected a 1-D structured array, got shape {a.shape}")
        return _from_columns(path, {k: a[k] for k in a.dtype.names if a.dtype[k].ndim == 0})
    if a.ndim != 2 or a.shape[1] != 3:
        raise DataError(
            f"{path}: expected an (N, 3) array or a structured array with x, y, z fields, got shape {a.shape}"
        )
    positions, origin = relative_positions(a)
    return _cloud(path, positions=positions, origin=origin)


def _read_npz(path: Path) -> PointCloud:
    arrays = load_npz(path)
    if "positions" not in arrays:
        if len(arrays) == 1:  # np.savez(path, xyz) or one array of any name: read as a .npy is
            return _from_array(path, next(iter(arrays.values())))
        raise DataError(
            f"{path}: no 'positions' array (keys: {', '.join(arrays) or 'none'}); name the (N, 3) "
            "array positions, the others colors, velocity, radius or an attribute's name: "
            "np.savez(path, positions=xyz, colors=rgb, intensity=i)"
        )
    fields: dict[str, object] = {k: arrays.pop(k) for k in _NPZ_KEYS if k in arrays}
    fields["positions"], fields["origin"] = relative_positions(fields["positions"], fields.get("origin"))
    fields["attributes"] = arrays
    return _cloud(path, **fields)


def save_npz(path: str | os.PathLike[str], cloud: PointCloud) -> None:
    """Write `cloud` as an uncompressed NPZ file with the keys :func:`read_points`
    reads: positions, origin, colors / velocity / radius when present, and one
    key per attribute."""
    _check_cloud(cloud)
    clash = [k for k in cloud.attributes if k in _NPZ_KEYS]
    if clash:
        raise ValueError(f"cloud: attribute names {clash} clash with the NPZ keys {list(_NPZ_KEYS)}")
    arrays = {"positions": cloud.positions, "origin": cloud.origin}
    arrays.update(
        {k: getattr(cloud, k) for k in ("colors", "velocity", "radius") if getattr(cloud, k) is not None}
    )
    arrays.update(cloud.attributes)

    def write(f: IO[Any]) -> None:
        # np.savez's own keywords (file, allow_pickle) would clash with attribute names
        with zipfile.ZipFile(f, "w") as archive:
            for k, v in arrays.items():
                with archive.open(f"{k}.npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, np.asarray(v), allow_pickle=False)

    _write_or_remove(path, write)
