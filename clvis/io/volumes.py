"""Volume files: :func:`read_volume` and the :class:`Volume` it returns.

Formats, chosen by the file name (case-insensitive):

- ``.raw``: headerless samples, little-endian, x fastest on disk (then y,
  then z), named like the Open SciVis datasets
  ``<name>_<X>x<Y>x<Z>_<type>.raw`` (e.g. ``bonsai_256x256x256_uint8.raw``),
  type one of uint8, int8, uint16, int16, uint32, int32, float32, float64.
  The keywords ``shape`` (numpy order ``(Z, Y, X)``, *not* the X x Y x Z of
  the name) and ``dtype`` give or override what the name says. The file size
  must be exactly Z * Y * X * itemsize bytes.
- ``.npy``: a 3-D array of real numbers, taken as [z, y, x].
- ``.nii``, ``.nii.gz``: NIfTI-1/2 through nibabel (an optional dependency:
  ``pip install ".[nifti]"`` from a clvis checkout, or ``pip install nibabel``).
  NIfTI's data array is indexed [i, j, k] with i the fastest on disk; it is
  transposed to [k, j, i] = [z, y, x]. Trailing axes of size 1 (a 3-D image
  stored as 4-D) are dropped. A 4-D image (a time series) needs ``volume_index``
  to pick one volume; only that volume is read. The header's scale (scl_slope,
  scl_inter) is applied when set, as nibabel does.
- ``.mgz``, ``.mgh``: FreeSurfer's MGH format (brain.mgz, aseg.mgz) through
  nibabel, read as NIfTI is (the same axes, ``volume_index`` for a 4-D one;
  ``.mgz`` is gzip-compressed).
- ``.hdr`` / ``.img`` (or ``.hdr.gz`` / ``.img.gz``, both compressed): an
  Analyze 7.5 (or NIfTI-1 pair) header and its data file beside it, through
  nibabel, read as NIfTI is; either name may be given. The other file is
  nibabel's name for it (``scan.HDR`` pairs with ``scan.IMG``, ``scan.hdr``
  with ``scan.img``), else the one file of that name in another case
  (``scan.Hdr`` with ``SCAN.IMG``, which nibabel alone does not pair); its
  absence is a DataError naming it.
- ``.vti`` (VTK XML ImageData), ``.vtr`` (VTK XML RectilinearGrid) and
  ``.vtk`` (legacy STRUCTURED_POINTS or RECTILINEAR_GRID), a rectilinear
  grid only where its coordinates are evenly spaced:
  through VTK's own readers (the ``vtk`` extra: ``pip install "clvis[vtk]"``),
  after clvis's checks of the header against the file (:mod:`clvis.io.vtk`);
  the point scalars (a legacy file's first SCALARS, else its first FIELD
  array of one component), with the file's spacing and origin (a .vti's
  Direction that permutes and flips the axes applied, a rotating one an
  error; an axis of negative spacing, which runs backward in VTK, flipped,
  its origin at its last sample; a flat axis of spacing 0, as 2-D images are written, a step
  of 1; a zero step along an axis of several samples an error); a file
  without point arrays gives its cell data (one sample a cell, the origin
  at the first cell's centre).

The samples are returned as stored (uint8 stays uint8: volumes can be large;
convert where needed, e.g. ``volume.data.astype(np.float32)``), in native
byte order and C order, with the library's conventions: ``data`` [z, y, x];
``spacing`` (dz, dy, dx): 1 for raw and NPY files, for NIfTI the header's
zooms (pixdim, (dx, dy, dz)) reversed, as nibabel reads them (0 as 1, a
negative size as its absolute value; NaN or inf is an error); ``origin``
(x, y, z) = 0 for every format but VTK's, which state theirs (sample [k, j, i] at world (i dx, j dy, k dz)).
NIfTI, MGH and Analyze volumes come in the closest RAS+ orientation of their
voxel-to-world affine (x toward the subject's right, y anterior, z superior:
the voxel axes permuted and flipped as nibabel's ``as_closest_canonical``
does, never resampled), so that a scan stored left-to-right (LAS, Analyze's
default) is not drawn as its mirror image; ``affine`` is the voxel-to-world
map of the axes as returned (a rotation beyond their order and signs stays
in it, unused), and ``spacing`` follows the axes.

A missing file raises FileNotFoundError (as :func:`clvis.read_points` does);
a file clvis cannot read (an unknown extension, a raw name without shape or
type, a file size that does not match, a malformed NPY or NIfTI file, data
that is not 3-D or not real numbers, an unreadable path) raises
:class:`clvis.errors.DataError` naming the file and the problem.
"""

from __future__ import annotations

import math
import operator
import os
import re
import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import DataError
from .files import mesh_hint, regular_file
from .npy import load_npy

__all__ = ["FORMATS", "RAW_TYPES", "Volume", "otsu_level", "raw_layout", "read_volume", "volume_parts"]

RAW_TYPES = {
    name: np.dtype(name)
    for name in ("uint8", "int8", "uint16", "int16", "uint32", "int32", "float32", "float64")
}
_RAW_NAME = re.compile(
    r"^(?P<name>.*)_(?P<x>\d+)x(?P<y>\d+)x(?P<z>\d+)_(?P<type>[A-Za-z0-9]+)\.raw$", re.IGNORECASE
)


@dataclass(frozen=True, eq=False)
class Volume:
    """A volume read from a file.

    Attributes
    ----------
    data : (Z, Y, X) array, as stored (native byte order, C order).
    spacing : (dz, dy, dx) floats.
    origin : (x, y, z) floats, (0, 0, 0).
    path : the file it came from.
    affine : (4, 4) float64 voxel [i, j, k, 1] -> world of a NIfTI, MGH or
        Analyze file (of its axes as returned: closest RAS+), else None.
    array : the name of the data array read from a VTK file, else None.
    """

    data: np.ndarray
    spacing: tuple = (1.0, 1.0, 1.0)
    origin: tuple = (0.0, 0.0, 0.0)
    path: str | None = None
    affine: np.ndarray | None = None
    array: str | None = None

    @property
    def shape(self) -> tuple:
        """(Z, Y, X)."""
        return self.data.shape

    def __repr__(self) -> str:
        return (
            f"Volume({self.path!r}, shape={self.data.shape}, dtype={self.data.dtype}, spacing={self.spacing})"
        )


def volume_parts(
    volume: object, spacing: Sequence[float] | None, origin: Sequence[float] | None
) -> tuple[object, Sequence[float], Sequence[float]]:
    """(samples, spacing, origin) of what a renderer was given: a
    :class:`Volume` (read_volume's) gives its data, and its spacing and origin
    where they are not given (None); anything else is the samples, with
    (1, 1, 1) and (0, 0, 0) for what is not given. A path is refused, naming
    read_volume."""
    if isinstance(volume, Volume):
        return (
            volume.data,
            volume.spacing if spacing is None else spacing,
            volume.origin if origin is None else origin,
        )
    if isinstance(volume, (str, os.PathLike)):
        raise TypeError(
            f"volume: expected an array or a clvis.Volume, got a path ({volume!r}): "
            "clvis.read_volume reads it"
        )
    from .objects import refuse_foreign

    refuse_foreign(volume, "Volume", "volume: expected an array or a clvis.Volume")
    return (
        volume,
        (1.0, 1.0, 1.0) if spacing is None else spacing,
        (0.0, 0.0, 0.0) if origin is None else origin,
    )


#: Analyze (and NIfTI-1 pair) header and data files: nibabel pairs a .hdr with a
#: .img, a .hdr.gz with a .img.gz
_PAIR_FORMATS = (".hdr", ".img", ".hdr.gz", ".img.gz")
#: the volume files read through nibabel (NIfTI, MGH, Analyze header/data pairs)
NIBABEL_FORMATS = (".nii", ".nii.gz", ".mgz", ".mgh", *_PAIR_FORMATS)
FORMATS = (".raw", ".npy", *NIBABEL_FORMATS, ".vti", ".vtr", ".vtk")


def read_volume(
    path: str | os.PathLike[str],
    *,
    shape: Sequence[int] | None = None,
    dtype: npt.DTypeLike | None = None,
    volume_index: int | None = None,
    array: str | None = None,
) -> Volume:
    """Read a volume file (``.raw``, ``.npy``, ``.nii``, ``.nii.gz``, ``.mgz``,
    ``.mgh``, ``.hdr``/``.img``, ``.hdr.gz``/``.img.gz``, ``.vti``, ``.vtr``,
    ``.vtk``, in any case; see the module docstring).

    `shape` (Z, Y, X) and `dtype` apply to ``.raw`` files only: they give the
    shape and the sample type when the file name does not, and override the
    name when it does. `volume_index` picks one volume of a 4-D NIfTI, MGH or
    Analyze file. `array` picks a VTK file's data array by name (a point
    array, else a cell array; a legacy .vtk's SCALARS and FIELD arrays; by
    default the point scalars, see the module docstring); the one read is
    ``Volume.array``."""
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path: expected a str or path, got {type(path).__name__}")
    path = regular_file(path)  # FileNotFoundError; DataError for a directory, FIFO or device
    name = path.name.lower()
    if name.endswith(".raw"):
        return _read_raw(path, shape, dtype)
    if shape is not None or dtype is not None:
        raise ValueError(f"shape, dtype: only for .raw files, not {path.name}")
    vtk = name.endswith((".vti", ".vtr", ".vtk"))
    if array is not None and (not isinstance(array, str) or not vtk):
        raise ValueError(
            f"array: a data array's name (a str) for .vti, .vtr and .vtk files, got {array!r} for {path.name}"
        )
    if name.endswith(NIBABEL_FORMATS):
        return _read_nifti(path, volume_index)
    if volume_index is not None:
        raise ValueError(f"volume_index: only for 4-D NIfTI, MGH or Analyze files, not {path.name}")
    if name.endswith(".npy"):
        return _read_npy(path)
    if vtk:
        from .vtk import read_legacy, read_vti, read_vtr

        reader = {".vti": read_vti, ".vtr": read_vtr}.get(name[-4:], read_legacy)
        data, spacing, origin, chosen = reader(path, array)
        return Volume(
            data, tuple(float(s) for s in spacing), tuple(float(o) for o in origin), str(path), array=chosen
        )
    from .points import POINT_SUFFIXES

    if name.endswith(POINT_SUFFIXES):  # .vtp, .ply, ...: the user is told where it goes
        raise DataError(
            f"{path}: a point cloud file ({path.suffix}), not a volume; "
            "read_points, clvis render, clvis gauss and clvis view read it"
        )
    raise DataError(f"{path}: unknown volume format (expected {', '.join(FORMATS)}){mesh_hint(path)}")


def raw_layout(
    path: str | os.PathLike[str], shape: Sequence[int] | None = None, dtype: npt.DTypeLike | None = None
) -> tuple[tuple[int, ...], np.dtype]:
    """(shape (Z, Y, X), little-endian dtype) of the .raw file `path`, from
    its name (``<name>_<X>x<Y>x<Z>_<type>.raw``) and the keywords, as
    :func:`read_volume` takes them, without reading the file; DataError
    naming the file when neither gives them."""
    path = Path(path)
    m = _RAW_NAME.match(path.name)
    if shape is None:
        if m is None:
            raise DataError(
                f"{path}: the name does not give the shape; expected "
                f"<name>_<X>x<Y>x<Z>_<type>.raw (e.g. bonsai_256x256x256_uint8.raw), "
                "or give the shape: shape=(Z, Y, X) in Python, --shape XxYxZ --dtype TYPE in the "
                "clvis commands"
            )
        shape = (int(m["z"]), int(m["y"]), int(m["x"]))
    else:
        try:
            shape = tuple(_index(s) for s in shape)
        except TypeError:
            raise TypeError(f"shape: expected three ints (Z, Y, X), got {shape!r}") from None
        if len(shape) != 3:
            raise ValueError(f"shape: expected three ints (Z, Y, X), got {shape!r}")
    if min(shape) < 1:
        raise DataError(f"{path}: the shape (Z, Y, X) = {shape} has an empty axis")
    if dtype is None:
        if m is None:
            raise DataError(
                f"{path}: the name does not give the sample type; expected "
                f"<name>_<X>x<Y>x<Z>_<type>.raw with type one of {', '.join(RAW_TYPES)}, "
                f"or pass dtype="
            )
        kind = m["type"].lower()
        if kind not in RAW_TYPES:
            raise DataError(
                f"{path}: unknown sample type {m['type']!r} in the name; expected one of "
                f"{', '.join(RAW_TYPES)}"
            )
        dt = RAW_TYPES[kind]
    else:
        try:
            dt = np.dtype(dtype)
        except TypeError:
            raise TypeError(f"dtype: not a numpy dtype: {dtype!r}") from None
        if dt.newbyteorder("=") not in RAW_TYPES.values():
            raise ValueError(f"dtype: expected one of {', '.join(RAW_TYPES)}, got {dt}")
    return shape, dt.newbyteorder("<")


def _index(v) -> int:
    """v as an int, for ints and numpy integers only."""
    if isinstance(v, bool):
        raise TypeError("bool")
    return operator.index(v)


def _read_raw(path: Path, shape, dtype) -> Volume:
    shape, dt = raw_layout(path, shape, dtype)
    count = shape[0] * shape[1] * shape[2]
    need = count * dt.itemsize
    try:
        size = path.stat().st_size
        if size != need:
            what = "short" if size < need else "long"
            raise DataError(
                f"{path}: {size} bytes, but {shape[2]}x{shape[1]}x{shape[0]} {dt.newbyteorder('=')} "
                f"samples need {need} (the file is {what} by {abs(size - need)} bytes)"
            )
        data = np.fromfile(path, dtype=dt, count=count)
    except OSError as e:
        raise DataError(f"{path}: cannot read: {e.strerror or e}") from e
    if data.size != count:  # the file shrank while we read it
        raise DataError(f"{path}: expected {count} samples, read {data.size}")
    data = data.reshape(shape).astype(dt.newbyteorder("="), copy=False)
    return Volume(data, (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), str(path))


def _real_volume(path: Path, a: np.ndarray) -> np.ndarray:
    if a.dtype == np.bool_:
        # a mask (np.save("mask.npy", seg > t)): 0 and 1, its surface at the default 0.5
        a = a.view(np.uint8)
    if a.dtype.kind not in "iuf":
        raise DataError(f"{path}: expected real numbers, got dtype {a.dtype}")
    if a.ndim != 3:
        raise DataError(f"{path}: expected a 3-D volume, got shape {a.shape}")
    if min(a.shape) < 1:
        raise DataError(f"{path}: the volume is empty, shape {a.shape}")
    return np.ascontiguousarray(a.astype(a.dtype.newbyteorder("="), copy=False))


def _read_npy(path: Path) -> Volume:
    a = load_npy(path)
    return Volume(_real_volume(path, a), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), str(path))


# gzip (deflate) expands at most 1032:1, so a .nii.gz cannot decompress to more
# than this many bytes per byte of the file.
_DEFLATE_MAX_RATIO = 1032


def _gzipped(path: Path) -> bool:
    """Whether a NIfTI or MGH file is gzip-compressed (.nii.gz, .mgz)."""
    return path.name.lower().endswith((".gz", ".mgz"))


def _kind(path: Path) -> str:
    name = path.name.lower()
    if name.endswith((".mgz", ".mgh")):
        return "MGH"
    return "Analyze" if name.endswith(_PAIR_FORMATS) else "NIfTI"


def nibabel_errors() -> tuple[type[BaseException], ...]:
    """What nibabel raises on malformed headers and data (OverflowError: an
    infinite vox_offset; HeaderDataError: an unknown datatype code; MGHError:
    an MGH header's zero dimension): each becomes a DataError naming the file."""
    from nibabel.filebasedimages import ImageFileError
    from nibabel.freesurfer.mghformat import MGHError
    from nibabel.spatialimages import HeaderDataError

    return (
        ImageFileError,
        MGHError,
        HeaderDataError,
        OSError,
        EOFError,
        ValueError,
        zlib.error,
        KeyError,
        OverflowError,
        TypeError,
        IndexError,
        struct.error,
    )


def _nibabel_name(name: str) -> tuple[str, str, str]:
    """(stem, suffix, trailing) of a file name nibabel reads, in the name's
    own case: "scan.Hdr.gz" -> ("scan", ".Hdr", ".gz"); the suffix "" where
    it is none of NIBABEL_FORMATS'."""
    low = name.lower()
    trail = ".gz" if low.endswith(".gz") and not low.endswith(".mgz") else ""
    base = name[: len(name) - len(trail)]
    for suffix in (".nii", ".hdr", ".img", ".mgz", ".mgh"):
        if base.lower().endswith(suffix):
            return base[: -len(suffix)], base[-len(suffix) :], name[len(base) :]
    return name, "", ""


def _nibabel_rule(path: Path, suffix: str) -> Path:
    """The file beside `path` that nibabel names with `suffix` (".hdr",
    ".img", ".nii"): the suffix in upper case where `path`'s is, else in
    lower case (a mixed-case one too), the trailing .gz as it is."""
    stem, ext, trail = _nibabel_name(path.name)
    return path.with_name(stem + (suffix.upper() if ext.isupper() else suffix) + trail)


def _beside(want: Path) -> list[Path]:
    """The files in `want`'s folder named as `want` is but for case."""
    key = want.name.lower()
    try:
        return sorted(p for p in want.parent.iterdir() if p.name.lower() == key and p.is_file())
    except OSError:
        return []


def analyze_pair(path: Path) -> tuple[Path, Path]:
    """(header, data) files of an Analyze or NIfTI-1 pair (.hdr/.img, or
    .hdr.gz/.img.gz: nibabel pairs compressed with compressed) named by
    either: the other is nibabel's name for it (its suffix in upper case
    where the given one is, else in lower case), else the one file in the
    folder of that name in another case (scan.Hdr and SCAN.IMG; nibabel
    reads only the first kind); a DataError when the other is missing or
    several files could be it (nibabel said FileNotFoundError of a name the
    user never gave)."""
    import gzip

    stem, ext, trail = _nibabel_name(path.name)
    header = ext.lower() == ".hdr"
    if header:
        try:
            with gzip.open(path, "rb") if trail else open(path, "rb") as f:
                magic = f.read(348)[344:348]
        except (OSError, EOFError, zlib.error) as e:
            raise DataError(f"{path}: cannot read: {getattr(e, 'strerror', None) or e}") from e
        if magic in (b"n+1\0", b"n+2\0"):  # a single-file NIfTI named .hdr
            raise DataError(
                f"{path}: a single-file NIfTI (magic {magic[:3].decode()}), not a pair: name it .nii{trail}"
            )
    want = _nibabel_rule(path, ".img" if header else ".hdr")
    found = [want] if want.is_file() else _beside(want)
    what = "data" if header else "header"
    if len(found) > 1:
        raise DataError(
            f"{path}: an Analyze {'header' if header else 'data file'}; several files could be its "
            f"{what} file ({', '.join(p.name for p in found)}): keep one"
        )
    if not found:
        # the pair's other half compressed where this one is not, or the reverse
        other = want.with_name(want.name[: -len(trail)] if trail else want.name + ".gz")
        near = _beside(other)
        hint = (
            f"; {near[0].name} is there, but nibabel pairs a .hdr.gz with a .img.gz and a .hdr with "
            "a .img: compress both or neither"
            if near
            else " (the pair is read from the same folder)"
        )
        raise DataError(
            f"{path}: an Analyze {'header' if header else 'data file'}; its {what} file "
            f"{want.name} is missing{hint}"
        )
    return (path, found[0]) if header else (found[0], path)


def nibabel_image(path: Path) -> tuple[Any, Path]:
    """(nibabel's image of the NIfTI, MGH or Analyze file `path` (either file
    of a pair), its data not read; the file the data is in), after the checks
    of its header against the file (:func:`_check_nifti_head`). nibabel.load
    where it finds the files by `path`'s name; where it would not (a suffix in
    mixed case, "brain.Nii.gz", for which nibabel looks for "brain.nii.gz";
    a pair found in another case, see :func:`analyze_pair`), nibabel's own
    choice of image class (the first whose header the file may hold, in
    nibabel's order) reads the files clvis found. ImportError without
    nibabel; nibabel's errors (:func:`nibabel_errors`) pass through."""
    import nibabel

    stem, ext, trail = _nibabel_name(path.name)
    pair = ext.lower() in (".hdr", ".img")
    head, data = analyze_pair(path) if pair else (path, path)
    _check_nifti_head(head)
    own = ext.lower() if ext.lower() in (".hdr", ".img", ".nii") else None
    if own is None or (
        _nibabel_rule(path, own) == path
        and (not pair or (_nibabel_rule(path, ".hdr"), _nibabel_rule(path, ".img")) == (head, data))
    ):
        return nibabel.load(path), data
    return _load_mapped(path, head, data), data


def _load_mapped(path: Path, head: Path, data: Path) -> Any:
    """nibabel.load's image of `head` and `data`, named as nibabel would not
    name them: the first of nibabel's image classes that reads `path`'s
    suffix and may hold the header `head` holds (nibabel.load's test),
    reading these files (an SPM Analyze image's .mat: nibabel's name beside
    the header)."""
    from nibabel.filebasedimages import ImageFileError
    from nibabel.filename_parser import splitext_addext
    from nibabel.imageclasses import all_image_classes
    from nibabel.openers import ImageOpener

    sniff = b""
    for klass in all_image_classes:
        if splitext_addext(path.name, klass._compressed_suffixes)[1].lower() not in klass.valid_exts:
            continue
        if hasattr(klass.header_class, "may_contain_header"):
            need = klass._meta_sniff_len
            if len(sniff) < need:
                with ImageOpener(str(head), "rb") as f:
                    sniff = f.read(max(need, 1024))
            if len(sniff) < need or not klass.header_class.may_contain_header(sniff):
                continue
        types = dict(klass.files_types)
        files = {"image": str(data), "header": str(head), "mat": str(_nibabel_rule(head, ".mat"))}
        return klass.from_file_map(klass.make_file_map({k: v for k, v in files.items() if k in types}))
    raise ImageFileError(f'Cannot work out file type of "{path}"')


def _read_nifti(path: Path, volume_index: int | None = None) -> Volume:
    """A NIfTI or (the same reading, nibabel's MGHImage) an MGH file, or an
    Analyze (NIfTI-1 pair) header and data file, named by either."""
    kind = _kind(path)
    try:
        import nibabel
    except ImportError:
        raise ImportError(
            f'reading {path.name} ({kind}) needs nibabel: pip install ".[nifti]" in a clvis checkout '
            "(or pip install nibabel)"
        ) from None
    errors = nibabel_errors()
    try:
        img, data_file = nibabel_image(path)  # the header only; the data is read below
        if isinstance(img, nibabel.cifti2.Cifti2Image):
            raise DataError(f"{path}: a CIFTI-2 file (a matrix over brain grayordinates), not a volume")
        header = img.header
        shape = tuple(int(s) for s in header.get_data_shape())
        dtype = np.dtype(header.get_data_dtype())
        # where nibabel reads the data from (a single file's vox_offset 0 means
        # "after the header and its extensions": the proxy knows the byte)
        offset = int(getattr(img.dataobj, "offset", header.get_data_offset()))
        zooms = tuple(float(z) for z in header.get_zooms())
        affine = np.array(img.affine, dtype=np.float64)
    except DataError:
        raise
    except errors as e:
        if isinstance(e, EOFError):  # nibabel reads an MGH file's footer, after its data
            raise DataError(f"{path}: truncated {kind} file ({e})") from e
        raise DataError(f"{path}: not a readable {kind} file: {type(e).__name__}: {e}") from e
    series = len(shape) == 4 and shape[3] > 1
    if volume_index is not None:
        t = _index(volume_index) if not isinstance(volume_index, bool) else -1
        count = shape[3] if len(shape) > 3 else 1
        if not 0 <= t < count:
            raise ValueError(
                f"volume_index: {volume_index!r} is outside 0..{count - 1} ({path.name} holds "
                f"{count} volume{'s' if count != 1 else ''}; clvis iso/gauss/view: --volume-index T)"
            )
    elif series:
        # a truncated file is said first: asked for an index, a user would
        # pick one only to be told then that the file is cut short
        _check_nifti_series_whole(path, shape, dtype, offset, data_file)
        raise DataError(
            f"{path}: a 4-D {kind} image of {shape[3]} volumes {shape[:3]} (i, j, k); "
            "choose one: --volume-index T (clvis iso, gauss and view), volume_index=T in Python"
        )
    # a series' volume t needs the file up to its end only (volumes are
    # contiguous in a 4-D file; a 5-D one interleaves the fifth axis)
    stored = shape[:3] + (t + 1,) if series and len(shape) == 4 else shape
    _check_nifti_layout(path, shape[:3] + shape[4:] if series else shape, dtype, offset, stored, data_file)
    try:
        if series:
            data = np.asanyarray(img.dataobj[:, :, :, t])
        else:
            data = np.asanyarray(img.dataobj)
    except errors as e:
        if series:  # a .gz cut before volume t: say so (the layout check cannot see into gzip)
            _check_nifti_series_whole(path, shape, dtype, offset, data_file)
        if isinstance(e, EOFError):
            raise DataError(f"{path}: truncated {kind} file ({e})") from e
        raise DataError(f"{path}: not a readable {kind} file: {type(e).__name__}: {e}") from e
    if data.ndim > 3 and all(s == 1 for s in data.shape[3:]):
        data = data.reshape(data.shape[:3])
    if data.ndim != 3:
        raise DataError(f"{path}: expected a 3-D volume, got shape {data.shape} (i, j, k, ...)")
    spacing = zooms[:3]
    if len(spacing) != 3 or not all(np.isfinite(z) and z > 0 for z in spacing):
        raise DataError(f"{path}: the voxel size (pixdim) must be three positive numbers, got {zooms[:3]}")
    data, spacing, affine = _canonical(data, spacing, affine)
    data = _real_volume(path, data.transpose(2, 1, 0))
    return Volume(data, spacing[::-1], (0.0, 0.0, 0.0), str(path), affine)


def ras_orientation(affine: np.ndarray) -> np.ndarray | None:
    """nibabel's orientation array (per stored voxel axis: the RAS+ axis it
    goes to, and +1 or -1) that turns a volume of this voxel-to-world
    `affine` into its closest RAS+ order (i toward the right, j anterior, k
    superior: nibabel's io_orientation, as as_closest_canonical uses it);
    None where it is the stored order already, or the affine is not finite
    or leaves an axis undetermined (the stored order is kept)."""
    from nibabel import orientations

    affine = np.asarray(affine, np.float64)
    if affine.shape != (4, 4) or not np.isfinite(affine).all():
        return None
    try:
        ornt = orientations.io_orientation(affine)
    except (ValueError, np.linalg.LinAlgError):
        return None
    if ornt.shape != (3, 2) or not np.isfinite(ornt).all() or (ornt == [[0, 1], [1, 1], [2, 1]]).all():
        return None
    return ornt


def _canonical(data: np.ndarray, zooms: tuple, affine: np.ndarray) -> tuple[np.ndarray, tuple, np.ndarray]:
    """(data, zooms, affine) of a stored (i, j, k) volume in its closest
    RAS+ order (:func:`ras_orientation`): the voxel axes permuted and
    flipped, never resampled (a rotation beyond the axes' order and signs
    stays in the affine), the affine that of the new voxel axes. Stored
    order (a LAS scan, Analyze's default) drew a mirror image of the
    subject."""
    from nibabel import orientations

    ornt = ras_orientation(affine)
    if ornt is None:
        return data, zooms, affine
    out = orientations.apply_orientation(data, ornt)
    new_zooms = [0.0, 0.0, 0.0]
    for axis, (to, _) in enumerate(ornt):
        new_zooms[int(to)] = zooms[axis]
    return out, tuple(new_zooms), affine @ orientations.inv_ornt_aff(ornt, data.shape)


# NIFTI_INTENT_CONNECTIVITY_*: the intent codes of CIFTI-2 files (matrices over
# brain surfaces and voxels, not volumes)
_CIFTI_INTENTS = range(3000, 3100)
# sizeof_hdr -> (extension flag at, vox_offset format and offset, intent code format and offset)
_NIFTI_HEADERS = {348: (348, "f", 108, "h", 68), 540: (540, "q", 168, "i", 504)}


def _check_nifti_head(path: Path) -> None:
    """What nibabel trusts when it reads a header, checked against the file first:
    the extension chain after the header (nibabel reads each extension's declared
    size at once: 2 GB reserved for one field of a 400-byte file), and CIFTI-2's
    intent codes (nibabel gives a CIFTI image, without a volume's header)."""
    import gzip

    gz = _gzipped(path)
    size = path.stat().st_size
    # what the data after the header can be: the file, or what gzip expands it to
    available = size * _DEFLATE_MAX_RATIO if gz else size
    try:
        with gzip.open(path, "rb") if gz else open(path, "rb") as f:
            head = f.read(544)
            for order in "<>":
                if len(head) >= 4 and struct.unpack_from(order + "i", head)[0] in _NIFTI_HEADERS:
                    break
            else:
                return  # not NIfTI-1/2: nibabel says what it is
            ext_at, off_fmt, off_at, intent_fmt, intent_at = _NIFTI_HEADERS[
                struct.unpack_from(order + "i", head)[0]
            ]
            if len(head) < ext_at + 4 or head[ext_at] == 0:
                return  # no extensions (nibabel reports a short header itself)
            (intent,) = struct.unpack_from(order + intent_fmt, head, intent_at)
            if intent in _CIFTI_INTENTS:
                raise DataError(
                    f"{path}: a CIFTI-2 file (intent code {intent}: a matrix over brain "
                    "grayordinates), not a volume"
                )
            (vox_offset,) = struct.unpack_from(order + off_fmt, head, off_at)
            pos = ext_at + 4
            # nibabel reads extensions while vox_offset - position >= 16, or to
            # the end of the file when vox_offset lies before them
            if math.isnan(vox_offset) or 0 <= vox_offset - pos < 16:
                return
            end = available if vox_offset < pos or math.isinf(vox_offset) else min(available, int(vox_offset))
            while pos + (16 if end < available else 8) <= end:
                f.seek(pos)
                raw = f.read(8)
                if len(raw) < 8:
                    break
                esize, _ = struct.unpack(order + "ii", raw)
                if esize < 8 or pos + esize > end:
                    raise DataError(
                        f"{path}: malformed NIfTI header: an extension at byte {pos} declares "
                        f"{esize} bytes; the extensions end by byte {end}"
                    )
                pos += esize
    except DataError:
        raise
    except EOFError as e:
        raise DataError(f"{path}: truncated {_kind(path)} file ({e})") from e
    except (OSError, zlib.error, struct.error) as e:
        raise DataError(f"{path}: not a readable {_kind(path)} file: {type(e).__name__}: {e}") from e


def _gz_bytes(path: Path, need: int) -> int:
    """How many bytes the gzip file `path` decompresses to, counted up to
    `need` (a stream: compressed chunks in, at most 1 MiB out at a time,
    nothing kept); a cut or corrupt stream counts what came out before it.
    A whole single-member file whose trailer (ISIZE: the size mod 2^32) says
    `need` is not decompressed at all."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        if size >= 18:
            f.seek(size - 4)
            if struct.unpack("<I", f.read(4))[0] == need % 2**32:
                return need
            f.seek(0)
        have = 0
        d = zlib.decompressobj(wbits=31)
        while have < need:
            data = f.read(1 << 16)
            if not data:
                return have  # cut short: the stream never ended
            while data and have < need:
                try:
                    out = d.decompress(data, 1 << 20)
                except zlib.error:
                    return have
                have += len(out)
                data = d.unconsumed_tail
                if d.eof:  # another gzip member may follow
                    data, d = d.unused_data + data, zlib.decompressobj(wbits=31)
        return have


def _data_file(path: Path, data: Path | None) -> tuple[Path, str]:
    """(the file holding the data, how a message names it): `path` itself
    ("the file"), or a pair's data file beside it."""
    if data is None or data == path:
        return path, "the file"
    return data, f"the data file {data.name}"


def _check_nifti_series_whole(
    path: Path, shape: tuple, dtype: np.dtype, offset: int, data: Path | None = None
) -> None:
    """A 4-D NIfTI or MGH file's data against what its header declares: a
    DataError naming the volumes it holds whole when it is cut short (a .gz
    decompressed as a stream to count, see _gz_bytes); `data`: where the data
    is when not in `path` (an Analyze pair's .img)."""
    volume = math.prod(shape[:3]) * dtype.itemsize * math.prod(shape[4:])
    need = offset + volume * shape[3]
    if volume <= 0 or offset < 0:
        return  # the layout check that follows says what is wrong
    data, named = _data_file(path, data)
    gz = _gzipped(data)
    if gz and need > data.stat().st_size * _DEFLATE_MAX_RATIO:
        raise DataError(
            f"{path}: the header declares {shape[3]} volumes {shape[:3]} {dtype} = {need - offset} bytes "
            f"from byte {offset}, more than a gzip file of {data.stat().st_size} bytes can hold "
            f"(at most {_DEFLATE_MAX_RATIO}:1)"
        )
    try:
        have = _gz_bytes(data, need) if gz else data.stat().st_size
    except OSError as e:
        raise DataError(f"{path}: not a readable {_kind(path)} file: {type(e).__name__}: {e}") from e
    if have >= need:
        return
    whole = max(have - offset, 0) // volume
    held = (
        f"volumes 0..{whole - 1} are whole"
        if whole > 1
        else "volume 0 is whole"
        if whole
        else "no volume is whole"
    )
    raise DataError(
        f"{path}: truncated {_kind(path)} file: the header declares {shape[3]} volumes {shape[:3]} {dtype} "
        f"= {need - offset} bytes from byte {offset}, {named} holds {max(have - offset, 0)}"
        + (" (decompressed)" if gz else "")
        + f"; {held}"
        + (" (clvis iso, gauss and view: --volume-index T reads one)" if whole else "")
    )


def _check_nifti_layout(
    path: Path,
    shape: tuple,
    dtype: np.dtype,
    offset: int,
    stored: tuple | None = None,
    data: Path | None = None,
) -> None:
    """The header's shape, type and data offset against the file, before nibabel
    allocates the data (it allocates what the header declares, then reads).
    `shape` is what will be read, `stored` (default `shape`) what the file
    holds, `data` where when not in `path` (an Analyze pair's .img)."""
    if dtype == np.bool_ or dtype.kind not in "iuf":
        raise DataError(f"{path}: expected real numbers, got {_kind(path)} data type {dtype}")
    if len(shape) > 3 and any(s != 1 for s in shape[3:]) or len(shape) < 3:
        raise DataError(f"{path}: expected a 3-D volume, got shape {shape} (i, j, k, ...)")
    if min(shape) < 1:
        raise DataError(f"{path}: the volume is empty, shape {shape} (i, j, k, ...)")
    if offset < 0:
        raise DataError(f"{path}: malformed {_kind(path)} header: data offset {offset}")
    data, named = _data_file(path, data)
    size = data.stat().st_size
    nbytes = math.prod(stored or shape) * dtype.itemsize
    if _gzipped(data):
        if offset + nbytes > size * _DEFLATE_MAX_RATIO:
            raise DataError(
                f"{path}: the header declares {stored or shape} {dtype} samples = {nbytes} bytes from "
                f"byte {offset}, more than a gzip file of {size} bytes can hold "
                f"(at most {_DEFLATE_MAX_RATIO}:1)"
            )
    elif offset + nbytes > size:
        raise DataError(
            f"{path}: truncated {_kind(path)} file: the header declares {stored or shape} {dtype} samples = "
            f"{nbytes} bytes from byte {offset}, {named} has {size} bytes"
        )


#: otsu_level's samples at most (about: every k-th of the finite ones)
OTSU_SAMPLES = 2_000_000


def otsu_level(data: npt.ArrayLike) -> float:
    """Otsu's threshold of the finite samples (scikit-image), on at most ~2M of
    them: the isovalue that separates the two classes of a scan best, which
    shows a surface where the middle of the range often shows a few blobs.

    Moved to the middle of the gap between the samples on either side of it,
    which classifies them the same: scikit-image's value is a histogram bin's
    centre, and on a volume of few distinct values (a 0/1 mask, labels) the
    first bin of a tie, 1/512 of the range above the background, where the
    surface hugs the background samples and ZFP's error draws blobs around it;
    a mask's is now 0.5, between its two values."""
    from skimage.filters import threshold_otsu

    flat = np.asarray(data).ravel()
    step = max(1, flat.size // OTSU_SAMPLES)
    sample = flat[::step]
    sample = sample[np.isfinite(sample)]
    if not sample.size:
        raise ValueError("data: no finite sample")
    lo, hi = float(sample.min()), float(sample.max())
    if lo == hi:
        return lo
    t = float(threshold_otsu(sample.astype(np.float64)))
    below, above = sample[sample <= t], sample[sample > t]
    if not below.size or not above.size:
        return t
    return (float(below.max()) + float(above.min())) / 2
