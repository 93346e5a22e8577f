"""ASTM E57 point clouds (``.e57``) through pye57 (libE57Format), the ``e57``
extra.

Every scan (``data3d`` entry) of the file is read, in the file's own
coordinates (each scan's pose applied and spherical coordinates converted,
as pye57's ``read_scan`` does), and the scans joined into one cloud.
colorRed/Green/Blue become the colours (8 bits), intensity an attribute, when
every scan has them. Points flagged invalid are left out. As for
LAS, positions are kept relative to their minimum (``cloud.origin``), which
float32 resolves where georeferenced coordinates would not.

Memory stays bounded by the file: the header's point counts are checked
against the file's size (at most ``MAX_POINTS_PER_BYTE`` points a byte) before
anything is read, so a few bytes cannot declare billions of points.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .cloud import PointCloud, _cloud, bulk_origin

MAX_POINTS_PER_BYTE = 64
_XYZ = ("cartesianX", "cartesianY", "cartesianZ")
_RGB = ("colorRed", "colorGreen", "colorBlue")
_SPHERICAL = ("sphericalRange", "sphericalAzimuth", "sphericalElevation")


def _pye57() -> Any:
    try:
        import pye57
    except ImportError:
        raise ImportError(
            'reading .e57 files needs pye57 (libE57Format): pip install ".[e57]" in a clvis checkout '
            "(or pip install pye57)"
        ) from None
    return pye57


def _read_e57(path: Path) -> PointCloud:
    pye57 = _pye57()
    try:
        f = pye57.E57(os.fspath(path))
    except Exception as e:  # libE57Format's E57Exception and friends: not an E57 file
        raise DataError(f"{path}: not a readable E57 file ({_why(e)})") from None
    try:
        return _scans(path, f)
    finally:
        try:
            f.close()
        except Exception:  # noqa: S110  a failed close of a file read to the end changes nothing
            pass


def _why(e: BaseException) -> str:
    text = " ".join(str(e).split())[:200]
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def _scans(path: Path, f: Any) -> PointCloud:
    try:
        count = int(f.scan_count)
        headers = [f.get_header(i) for i in range(count)]
        sizes = [int(h.point_count) for h in headers]
        fields = [list(h.point_fields) for h in headers]
    except Exception as e:
        raise DataError(f"{path}: malformed E57 file ({_why(e)})") from None
    if count == 0:
        raise DataError(f"{path}: the E57 file holds no scan (no data3d entry)")
    total = sum(sizes)
    size = path.stat().st_size
    if any(n < 0 for n in sizes) or total > MAX_POINTS_PER_BYTE * size:
        raise DataError(
            f"{path}: the E57 header declares {total:,} points in a file of {size:,} bytes "
            f"(at most {MAX_POINTS_PER_BYTE} points a byte)"
        )
    for i, names in enumerate(fields):
        if not (all(k in names for k in _XYZ) or all(k in names for k in _SPHERICAL)):
            raise DataError(
                f"{path}: scan {i} has neither cartesianX/Y/Z nor sphericalRange/Azimuth/Elevation "
                f"(fields: {', '.join(names) or 'none'})"
            )
    intensity = all("intensity" in names for names in fields)
    colours = all(all(k in names for k in _RGB) for names in fields)
    positions, rgb, values = [], [], []
    for i in range(count):
        if sizes[i] == 0:
            continue
        try:  # the scan's pose applied, invalid points (cartesianInvalidState != 0) left out
            scan = f.read_scan(i, intensity=intensity, colors=colours, ignore_missing_fields=True)
        except Exception as e:
            raise DataError(f"{path}: scan {i} cannot be read ({_why(e)})") from None
        xyz = np.stack([np.asarray(scan[k], np.float64) for k in _XYZ], axis=1)
        if len(xyz) > sizes[i]:
            raise DataError(f"{path}: scan {i} holds {len(xyz):,} points, its header says {sizes[i]:,}")
        positions.append(xyz)
        if colours:
            rgb.append(np.stack([np.asarray(scan[k]) for k in _RGB], axis=1))
        if intensity:
            values.append(np.asarray(scan["intensity"], np.float32))
    if not positions or not sum(len(p) for p in positions):
        raise DataError(f"{path}: the E57 file's scans hold no valid points")
    p = np.concatenate(positions)
    origin = bulk_origin(p)  # the finite minimum (of the bulk, where stray points lie far away)
    out: dict[str, Any] = {"positions": p - origin, "origin": origin}
    if colours:
        c = np.concatenate(rgb)
        if c.dtype != np.uint8:  # wider colours (the file's colorLimits): 8 bits, as for LAS
            wide = np.asarray(c, np.float64)
            top = float(wide.max()) if wide.size else 0.0
            c = np.clip(np.rint(wide * (255.0 / top if top > 255 else 1.0)), 0, 255).astype(np.uint8)
        out["colors"] = c
    out["attributes"] = {"intensity": np.concatenate(values)} if intensity else {}
    return _cloud(path, **out)
