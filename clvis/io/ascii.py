"""ASCII point clouds: ``.xyz``, ``.txt``, ``.csv`` (and CloudCompare's,
PDAL's and most scanners' text exports), Leica's ``.pts`` and Open3D's
``.xyzn`` and ``.xyzrgb``, one point a line.

The columns: a header line of names (``x,y,z,red,green,blue``, ``//X Y Z R G
B`` as CloudCompare writes it, ``X Y Z Intensity``, ``"X","Y","Z"`` as R's
write.csv quotes them) names them, mapped as
for PLY (x, y, z; red/green/blue or r/g/b the colours; vx, vy, vz the
velocity; the rest attributes). Without one, the count decides: 3 x y z;
4 x y z intensity; 6 x y z r g b when the last three are whole numbers in
0..255; 7 x y z intensity r g b likewise (Leica PTS); other counts x y z and
attributes named ``column_4`` on. Separators: commas, semicolons, tabs or
spaces. Lines starting with ``#``, ``//`` or ``%`` are comments. Positions
are parsed in float64 and kept relative to their minimum (``cloud.origin``),
as for LAS: text files usually hold georeferenced coordinates.

The suffix names what a header cannot: ``.xyzn`` is x y z nx ny nz (the
normals as the attributes nx, ny, nz, as a PLY's); ``.xyzrgb`` is x y z r g b,
colours in 0..1 (Open3D's) or 0..255; a ``.pts`` file starts with its point
count on a line of its own (checked against the points read; a file of
several scans, each after its own count, is refused naming the line), then
x y z [intensity] [r g b] as above.

Bounded: numpy's own text parser, no Python loop per line; a row with a
different count or a value that is not a number raises DataError naming
the line (a row of another count: its line in the file, found again only
then).
"""

from __future__ import annotations

import codecs
import os
import re
from pathlib import Path

import numpy as np

from ..errors import DataError
from .cloud import PointCloud, _from_columns, bulk_origin

SUFFIXES = (".xyz", ".txt", ".csv", ".pts", ".xyzn", ".xyzrgb")
# Open3D's text formats: the columns their suffix names
_SUFFIX_NAMES = {
    ".xyzn": ["x", "y", "z", "nx", "ny", "nz"],
    ".xyzrgb": ["x", "y", "z", "red", "green", "blue"],
}
_COMMENT = ("#", "//", "%")
_HEAD_BYTES = 1 << 16  # the header and the first data line lie in this


def _split(line: str, sep: str | None) -> list[str]:
    return [t for t in (line.split(sep) if sep else line.split()) if t.strip() != ""]


def _number(t: str) -> bool:
    try:
        float(t)
        return True
    except ValueError:
        return False


def _line_of_row(path: Path, first: int, row: int) -> int:
    """The line number (1 first) of the `row`-th row of values (1 first)
    that np.loadtxt read from line `first` (0 first) on: a line whose text
    before a comment mark is not blank."""
    mark = re.compile("|".join(re.escape(c) for c in _COMMENT))
    seen = 0
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        for k, line in enumerate(f):
            if k >= first and mark.split(line, 1)[0].strip():
                seen += 1
                if seen == row:
                    return k + 1
    return first + row


def _unquoted(t: str) -> str:
    """A header name without the double or single quotes around it."""
    return t[1:-1].strip() if len(t) >= 2 and t[0] == t[-1] and t[0] in "\"'" else t


def _read_ascii(path: Path) -> PointCloud:
    with open(path, "rb") as f:
        head = f.read(_HEAD_BYTES)
    try:
        text, encoding = head.decode("utf-8-sig"), "utf-8"
    except UnicodeDecodeError:
        text, encoding = head.decode("latin-1"), "latin-1"
    if "\0" in text:
        raise DataError(f"{path}: not a text point cloud (it holds binary data)")
    lines = text.splitlines()
    if len(head) == _HEAD_BYTES and lines:
        lines = lines[:-1]  # the last one may be cut
    names: list[str] | None = None
    skip = 0
    first = None
    suffix = path.suffix.lower()
    count: int | None = None  # a .pts file's declared point count
    for i, raw in enumerate(lines):
        s = raw.strip()
        if not s:
            continue
        comment = s.startswith(_COMMENT)
        body = re.sub(r"^(#|//|%)\s*", "", s) if comment else s
        sep = "," if "," in body else ";" if ";" in body else None
        tokens = [t.strip() for t in _split(body, sep)]
        bare = [_unquoted(t) for t in tokens]  # R's write.csv and spreadsheets quote the names
        if (
            tokens
            and not all(_number(t) for t in tokens)
            and all(re.fullmatch(r"[A-Za-z_][\w.]*", t) for t in bare)
        ):
            names, skip = [t.lower() for t in bare], i + 1  # a header (commented or not)
            continue
        if comment:
            skip = i + 1
            continue
        if suffix == ".pts" and count is None and len(tokens) == 1 and re.fullmatch(r"\d+", tokens[0]):
            count, skip = int(tokens[0]), i + 1  # Leica PTS: the point count first
            continue
        first, skip = (i, sep, tokens), skip
        break
    if first is None:
        raise DataError(f"{path}: no point in the file (no line of numbers)")
    line_no, sep, tokens = first
    if not all(_number(t) for t in tokens):
        raise DataError(f"{path}: line {line_no + 1}: expected numbers, got {lines[line_no].strip()[:80]!r}")
    ncol = len(tokens)
    if names is not None and len(names) != ncol:
        raise DataError(f"{path}: the header names {len(names)} columns, line {line_no + 1} holds {ncol}")
    # the bytes before the first line of numbers (a header, comments, a count)
    start = len("".join(text.splitlines(keepends=True)[:line_no]).encode(encoding))
    start += len(codecs.BOM_UTF8) if head.startswith(codecs.BOM_UTF8) else 0
    try:
        data = np.loadtxt(
            path,
            delimiter=sep,
            comments=_comments(path, start),
            skiprows=line_no,
            ndmin=2,
            dtype=np.float64,
            encoding="utf-8-sig",
        )
    except ValueError as e:
        changed = re.search(r"changed from (\d+) to (\d+) at row (\d+)", str(e))
        value = re.search(r"could not convert string (.*) to float64 at row (\d+), column (\d+)", str(e))
        if value is not None:  # numpy's row (0 first here) counts rows of values: the file's line said
            at = _line_of_row(path, line_no, int(value.group(2)) + 1)
            raise DataError(
                f"{path}: line {at}, column {value.group(3)}: expected a number, got {value.group(1)[:40]}"
            ) from None
        if changed is None:
            raise DataError(f"{path}: malformed text point cloud: {e}") from None
        # numpy's words ("use `usecols` to select a subset", a keyword of its own) and its row,
        # which counts rows of values (not comments, not blank lines): the file's line said
        was, now, row = (int(v) for v in changed.groups())
        at = _line_of_row(path, line_no, row)
        if suffix == ".pts" and now == 1:  # a count line further on: another scan's
            raise DataError(
                f"{path}: line {at} holds one value: a PTS file of several "
                "scans (each after its point count) is not read; split it into one file a scan"
            ) from None
        count_first = ncol == 1 and re.fullmatch(r"\d+", tokens[0]) and now >= 3
        hint = " (a point count first, as a Leica .pts file holds: name it .pts)" if count_first else ""
        raise DataError(
            f"{path}: line {at} holds {now} values, line {line_no + 1} {was}: every point "
            f"needs the same columns{hint}"
        ) from None
    if data.shape[1] != ncol:
        raise DataError(f"{path}: {data.shape[1]} columns, the first line holds {ncol}")
    if count is not None and count != len(data):
        raise DataError(f"{path}: its first line declares {count:,} points; the file holds {len(data):,}")
    if names is None and suffix in _SUFFIX_NAMES:
        names = _SUFFIX_NAMES[suffix]
        if ncol != len(names):
            raise DataError(f"{path}: {ncol} columns; a {suffix} file holds {' '.join(names)}")
    if names is None:
        names = _default_names(data)
    if ncol < 3:
        raise DataError(f"{path}: {ncol} columns; a point needs x, y, z")
    if len(set(names)) != len(names):
        raise DataError(f"{path}: the header names a column twice: {', '.join(names)}")
    # Open3D writes a .xyzrgb's colours as fractions, pure ones too (1 0 0: red)
    return _with_origin(path, {n: data[:, k] for k, n in enumerate(names)}, fractions=suffix == ".xyzrgb")


def _comments(path: Path, start: int) -> str | list[str]:
    """loadtxt's comment markers for the data from byte `start` on: '#' alone
    where no '//' or '%' follows (numpy parses a single marker in C; a list
    of them sends every line through a Python function: 2.1 of 3.4 s of a
    2 M-point .xyz), else all of _COMMENT."""
    import mmap

    with open(path, "rb") as f:
        if os.fstat(f.fileno()).st_size <= start:
            return list(_COMMENT)
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as m:  # memchr-fast finds, no copy
            if m.find(b"//", start) < 0 and m.find(b"%", start) < 0:
                return "#"
    return list(_COMMENT)


def _default_names(data: np.ndarray) -> list[str]:
    n = data.shape[1]

    def rgb(cols) -> bool:
        c = data[:, cols]
        return bool(np.isfinite(c).all() and (c >= 0).all() and (c <= 255).all() and (c == np.round(c)).all())

    if n == 3:
        return ["x", "y", "z"]
    if n == 4:
        return ["x", "y", "z", "intensity"]
    if n == 6 and rgb([3, 4, 5]):
        return ["x", "y", "z", "red", "green", "blue"]
    if n == 7 and rgb([4, 5, 6]):
        return ["x", "y", "z", "intensity", "red", "green", "blue"]
    return ["x", "y", "z", *(f"column_{k + 1}" for k in range(3, n))]


def _with_origin(path: Path, columns: dict, fractions: bool = False) -> PointCloud:
    """A cloud from float64 columns: x, y, z relative to their finite minimum
    (the origin), colours as 8-bit, the rest float32 attributes. Colours of
    at most 1 are fractions where one is not a whole number, or where
    `fractions` says so (a .xyzrgb: 1 0 0 is red, not 1/255 of it)."""
    for c in "xyz":
        if c not in columns:
            raise DataError(f"{path}: no {c} column (found {', '.join(columns)})")
    xyz = np.stack([columns[c] for c in "xyz"], axis=1)
    origin = bulk_origin(xyz)  # the finite minimum (of the bulk, where stray points lie far away)
    columns = dict(columns)
    for k, c in enumerate("xyz"):
        columns[c] = (xyz[:, k] - origin[k]).astype(np.float32)
    for names in (("red", "green", "blue"), ("r", "g", "b")):
        if all(c in columns for c in names):
            rgb = np.stack([columns[c] for c in names], axis=1)
            if not (np.isfinite(rgb).all() and (rgb >= 0).all() and (rgb <= 65535).all()):
                raise DataError(f"{path}: colours must be finite numbers in 0..255 (or 0..1, or 0..65535)")
            if rgb.size and rgb.max() <= 1 and (fractions or not (rgb == np.round(rgb)).all()):
                rgb = rgb * 255  # colours as fractions
            elif rgb.size and rgb.max() > 255:
                rgb = rgb / 257  # 16-bit colours
            for k, c in enumerate(names):
                columns[c] = np.rint(rgb[:, k]).astype(np.uint8)
    return _from_columns(path, columns, origin)
