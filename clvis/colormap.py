"""Colormap lookup tables from matplotlib's data, and the rule that maps a scalar
through one.

``lut(name, n)`` is an ``(n, 4)`` uint8 RGBA table: entry ``i`` is matplotlib's
own colour for index ``i`` of the colormap resampled to ``n`` entries. The
tables are read from matplotlib (imported on first use), never typed in here.

Index rule (what the kernels compute; ``apply`` is its reference), for a table
of ``n`` entries (1 <= n <= 2**24) and finite ``vmin <= vmax``, with every
operation in IEEE float32 round-to-nearest (no fused or reassociated
arithmetic)::

    scale = float32(1 / (vmax - vmin))   # divided in float64, then rounded
                                         # (scale = 0 when vmax == vmin)
    t     = (float32(v) - float32(vmin)) * scale
    x     = floor(t * float32(n))
    i     = 0 if x < 0 or x is NaN, n - 1 if x >= n - 1, else int(x)
    rgba  = (0, 0, 0, 0) if v is NaN, else lut[i]

So ``v <= vmin`` gives entry 0 and ``v >= vmax`` entry ``n - 1``, as
matplotlib's "int(t * N), clipped" does, and ±inf clamp to the ends. ``t`` is
NaN for a non-NaN ``v`` only when ``v`` is ±inf and ``scale`` is 0, or when
``v == vmin`` and ``scale`` overflowed to inf (``vmax - vmin`` below about
3e-39); those give entry 0, as matplotlib's ``vmin == vmax`` case does.
"""

from __future__ import annotations

import difflib
import functools
import numbers
import operator
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__all__ = [
    "ASPRS_CLASSES",
    "apply",
    "categorical",
    "class_name",
    "class_palette",
    "lut",
    "names",
    "value_range",
]

_MAX_ENTRIES = 2**24  # float32(n) and float32(n - 1) are exact up to here
_F32_MAX = float(np.finfo(np.float32).max)


def names() -> list[str]:
    """Every colormap name matplotlib knows (``_r`` reversed ones included), sorted."""
    import matplotlib

    return sorted(matplotlib.colormaps)


def lut(name: str = "viridis", n: int = 256) -> np.ndarray:
    """The ``(n, 4)`` uint8 RGBA table of matplotlib colormap `name` with `n`
    entries: ``matplotlib.colormaps[name].resampled(n)(np.arange(n), bytes=True)``.

    Raises ValueError for an unknown name (listing some valid ones) or
    ``n`` outside 1..2**24; TypeError for a name that is not a string or an
    `n` that is not an integer.
    """
    if not isinstance(name, str):
        raise TypeError(f"name: expected a colormap name (str), got {type(name).__name__}")
    n = _count("n", n)
    if not 1 <= n <= _MAX_ENTRIES:
        raise ValueError(f"n: a colormap table needs 1..{_MAX_ENTRIES} entries, got {n}")
    return _table(name, n).copy()


@functools.lru_cache(maxsize=64)
def _table(name: str, n: int) -> np.ndarray:
    import matplotlib

    try:
        cmap = matplotlib.colormaps[name]
    except KeyError:
        known = sorted(matplotlib.colormaps)
        close = difflib.get_close_matches(name, known, n=5)
        some = close or [k for k in ("viridis", "magma", "inferno", "plasma", "twilight") if k in known]
        raise ValueError(
            f"unknown colormap {name!r}; valid names include {', '.join(some)} "
            f"(clvis.colormap.names() lists all {len(known)})"
        ) from None
    table = np.ascontiguousarray(cmap.resampled(n)(np.arange(n), bytes=True), dtype=np.uint8)
    table.flags.writeable = False
    return table


def apply(values: npt.ArrayLike, lut: np.ndarray, vmin: float, vmax: float) -> np.ndarray:
    """Colours of `values` through `lut` by the module's index rule: an array of
    shape ``values.shape + (4,)``, uint8, NaN values ``(0, 0, 0, 0)``.

    `values`: real numbers (converted to float32 first); `lut`: ``(n, 4)``
    uint8; `vmin`, `vmax`: finite in float32, ``vmin <= vmax``.
    """
    table = np.asarray(lut)
    if table.dtype != np.uint8:
        raise TypeError(f"lut: expected uint8, got {table.dtype.name}")
    if table.ndim != 2 or table.shape[1] != 4 or not 1 <= table.shape[0] <= _MAX_ENTRIES:
        raise ValueError(f"lut: expected shape (n, 4) with 1 <= n <= {_MAX_ENTRIES}, got {table.shape}")
    v = np.asarray(values)
    if v.dtype.kind not in "biuf":
        raise TypeError(f"values: expected real numbers, got dtype {v.dtype.name}")
    lo, hi = _limit("vmin", vmin), _limit("vmax", vmax)
    if lo > hi:
        raise ValueError(f"vmin ({lo!r}) must be <= vmax ({hi!r})")
    n = table.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):
        v = v.astype(np.float32)
        scale = (
            np.float32(np.float64(1.0) / (np.float64(hi) - np.float64(lo))) if hi != lo else np.float32(0.0)
        )
        t = (v - np.float32(lo)) * scale
        x = np.floor(t * np.float32(n))
    i = np.where(x >= n - 1, n - 1, np.where(x > 0, x, 0)).astype(np.intp)
    out = table[i]
    out[np.isnan(v)] = 0
    return out


def value_range(values: npt.ArrayLike) -> tuple[float, float]:
    """``(min, max)`` of the finite `values` as Python floats; ``(0.0, 1.0)``
    when none is finite."""
    v = np.asarray(values)
    if v.dtype.kind not in "biuf":
        raise TypeError(f"values: expected real numbers, got dtype {v.dtype.name}")
    finite = v[np.isfinite(v)]
    if finite.size == 0:
        return 0.0, 1.0
    return float(finite.min()), float(finite.max())


def _count(name: str, n) -> int:
    if isinstance(n, bool):
        raise TypeError(f"{name}: expected an integer, got bool")
    try:
        return operator.index(n)
    except TypeError:
        raise TypeError(f"{name}: expected an integer, got {type(n).__name__}") from None


def _limit(name: str, x) -> float:
    if not isinstance(x, numbers.Real):
        raise TypeError(f"{name}: expected a real number, got {type(x).__name__}")
    x = float(x)
    if not abs(x) <= _F32_MAX:
        raise ValueError(f"{name}: expected a number finite in float32, got {x!r}")
    return x


class TransferFunction:
    """A Gaussian's value -> colour (a matplotlib colormap) and an opacity factor
    (piecewise linear).

    Parameters
    ----------
    colormap : matplotlib colormap name.
    opacity : None (1 everywhere) or a sequence of (x, alpha) points, x in [0, 1]
        along the normalised value range (ascending), alpha in [0, 1]; linear
        in between, constant beyond the ends.
    value_range : (vmin, vmax) or None (the finite min and max of the values).
    entries : table size n. Value v takes entry
        clamp(floor(((v - vmin) * scale) * n), 0, n - 1), scale = 1 / (vmax - vmin)
        (0 when vmin == vmax), as clvis.colormap.apply does; entry i has the
        colormap's colour i and the opacity map at (i + 0.5) / n.
    """

    def __init__(
        self,
        colormap: str = "viridis",
        opacity: npt.ArrayLike | None = None,
        value_range: Sequence[float] | None = None,
        entries: int = 256,
    ) -> None:
        self.colormap = colormap
        self.lut = lut(colormap, entries)
        self.entries = int(entries)
        if opacity is None:
            self.opacity_points = np.array([[0.0, 1.0], [1.0, 1.0]])
        else:
            pts = np.asarray(opacity, dtype=np.float64)
            if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 1:
                raise ValueError(f"opacity: expected a sequence of (x, alpha) points, got shape {pts.shape}")
            if not np.isfinite(pts).all():
                raise ValueError("opacity: points must be finite")
            if (np.diff(pts[:, 0]) < 0).any():
                raise ValueError("opacity: x must be ascending")
            if ((pts[:, 1] < 0) | (pts[:, 1] > 1)).any():
                raise ValueError("opacity: alpha must lie in [0, 1]")
            self.opacity_points = pts
        if value_range is not None:
            lo, hi = (float(v) for v in value_range)
            if not (np.isfinite(np.float32(lo)) and np.isfinite(np.float32(hi))) or lo > hi:
                raise ValueError(f"value_range: expected finite vmin <= vmax, got {value_range!r}")
            value_range = (lo, hi)
        self.value_range = value_range

    def table(self) -> np.ndarray:
        """(entries, 4) float32: r, g, b in [0, 1] and the opacity factor."""
        n = self.entries
        x = (np.arange(n) + 0.5) / n
        pts = self.opacity_points
        t = np.empty((n, 4), np.float32)
        t[:, :3] = self.lut[:, :3].astype(np.float32) / np.float32(255)
        t[:, 3] = np.interp(x, pts[:, 0], pts[:, 1])
        return t

    def limits(self, values: npt.ArrayLike) -> tuple[np.float32, np.float32]:
        """(vmin, scale) as float32 for `values`."""
        lo, hi = self.value_range if self.value_range is not None else value_range(values)
        scale = np.float32(1.0 / (np.float64(hi) - np.float64(lo))) if hi != lo else np.float32(0)
        return np.float32(lo), scale

    def __repr__(self) -> str:
        return f"TransferFunction({self.colormap!r}, value_range={self.value_range})"


# ---------------------------------------------------------------- categories

# The ASPRS standard point classes (LAS 1.4, point formats 6-10; 0..12 hold for
# formats 0-5 too): code -> (name, RGB). Colours chosen here so that the
# families read at a glance: ground brown, vegetation greens from low to
# high, buildings red, water blue, noise magenta, wires yellow.
ASPRS_CLASSES: dict[int, tuple[str, tuple[int, int, int]]] = {
    0: ("never classified", (150, 150, 150)),
    1: ("unclassified", (205, 205, 205)),
    2: ("ground", (166, 118, 66)),
    3: ("low vegetation", (178, 223, 138)),
    4: ("medium vegetation", (92, 184, 72)),
    5: ("high vegetation", (26, 120, 40)),
    6: ("building", (220, 70, 50)),
    7: ("low point (noise)", (255, 0, 255)),
    8: ("model key point", (255, 255, 0)),
    9: ("water", (50, 110, 230)),
    10: ("rail", (140, 80, 160)),
    11: ("road surface", (90, 90, 90)),
    12: ("overlap", (255, 160, 0)),
    13: ("wire guard", (250, 230, 120)),
    14: ("wire conductor", (255, 210, 60)),
    15: ("transmission tower", (230, 130, 200)),
    16: ("wire connector", (200, 160, 220)),
    17: ("bridge deck", (120, 200, 220)),
    18: ("high noise", (255, 0, 128)),
}


def named_colour(name: str, text: str) -> tuple[float, float, float]:
    """The colour `text` names, (r, g, b) in 0..1: a CSS/X11 name ("white",
    "steelblue"), matplotlib's "tab:blue" or "C0", or "#rrggbb" / "#rgb", as
    matplotlib reads them (a user of PyVista or matplotlib writes
    color="red"). ValueError naming the argument `name` otherwise."""
    from matplotlib.colors import to_rgb

    try:
        if text.strip().startswith("#") and len(text.strip()) not in (4, 7):
            raise ValueError("not #rgb or #rrggbb")  # matplotlib drops an #rrggbbaa's alpha
        r, g, b = to_rgb(text.strip())
    except ValueError:
        close = difflib.get_close_matches(text.strip().lower(), _colour_names(), n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        raise ValueError(f"{name}: {text!r} is not a colour name or #rrggbb{hint}") from None
    return float(r), float(g), float(b)


@functools.cache
def _colour_names() -> list[str]:
    from matplotlib.colors import CSS4_COLORS

    return sorted(CSS4_COLORS)


def class_palette() -> np.ndarray:
    """``(256, 4)`` uint8 RGBA: the ASPRS class colours for codes 0..18, and for
    the user-definable codes 19..255 hues a golden angle apart (distinct
    neighbours, stable from file to file)."""
    table = np.empty((256, 4), np.uint8)
    table[:, 3] = 255
    for code in range(256):
        if code in ASPRS_CLASSES:
            table[code, :3] = ASPRS_CLASSES[code][1]
        else:
            import colorsys

            h = (code * 0.618033988749895) % 1.0
            table[code, :3] = [round(255 * c) for c in colorsys.hsv_to_rgb(h, 0.65, 0.95)]
    return table


def class_name(code: int) -> str:
    """The ASPRS name of class `code`, or "class N" for a user-definable one."""
    return ASPRS_CLASSES[code][0] if code in ASPRS_CLASSES else f"class {code}"


def categorical(values: npt.ArrayLike) -> bool:
    """Whether `values` are class codes: whole numbers in 0..255 (a uint8
    attribute, or floats that hold only such values), at least one."""
    v = np.asarray(values)
    if v.size == 0:
        return False
    if v.dtype == np.uint8:
        return True
    if v.dtype.kind not in "iuf":
        return False
    lo, hi = (
        np.nanmin(v) if v.dtype.kind == "f" else v.min(),
        np.nanmax(v) if v.dtype.kind == "f" else v.max(),
    )
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo and hi <= 255):
        return False
    return bool(np.all(np.mod(v[np.isfinite(v)], 1) == 0)) if v.dtype.kind == "f" else True
