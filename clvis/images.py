"""G-buffer planes to images a person looks at, the labels, colour bars and
grids that make them readable, and PNG files (Pillow).

Images are ``[H, W, C]`` uint8 arrays, row 0 on top. Every colour image from
a plane here is RGBA with empty pixels transparent black ``(0, 0, 0, 0)``;
colours come from ``clvis.colormap`` by its index rule. `colormap` arguments
take a matplotlib name or an ``(n, 4)`` uint8 table.

For the pictures the commands write: `opaque` puts an image over a background
colour (``BACKGROUND`` by default), `label` adds a band of text above it (on
``BAND``, darker, so a band never reads as part of the picture),
`colorbar` draws a colormap's ramp with its value range written under the
ends, and `compose` lays labelled panels out in a grid. Text uses Pillow's
built-in font (scalable with FreeType, Pillow >= 10.1; else its bitmap font):
no font file is read.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from . import colormap as cm
from ._arrays import nonnegative_int

if TYPE_CHECKING:  # Pillow is imported when a picture is made, not with clvis
    from PIL import ImageFont

__all__ = [
    "BACKGROUND",
    "Picture",
    "attribute_image",
    "colorbar",
    "compose",
    "depth_image",
    "font",
    "from_premultiplied",
    "label",
    "label_height",
    "legend",
    "opaque",
    "save_png",
    "side_by_side",
    "velocity_images",
]

BACKGROUND = (24, 24, 28)  # behind empty pixels: a dark grey
BAND = (8, 8, 10)  # label bands, colour bars and the gaps between panels: darker
TEXT = (235, 235, 235)  # the labels' text
MIN_TEXT, MAX_TEXT = 8, 24  # font sizes in pixels a label may take


class Picture:
    """What every rendered image type shares (GBuffers, FilteredImage,
    IsoImage, GaussianImage): ``to_uint8(background=None)`` is the picture
    as ``(H, W, 4)`` uint8 RGBA, row 0 on top, straight alpha with empty
    pixels transparent black; given a ``background`` (an RGB colour, three
    0..255 integers such as ``BACKGROUND``) it lies over that colour, every
    alpha 255. ``save_png(path, background=None)`` writes that picture
    (:func:`save_png`: folders made, the file complete or absent) and returns
    the path. The post networks' outputs are that array already."""

    def to_uint8(self, background: Sequence[int] | None = None) -> np.ndarray:
        raise NotImplementedError

    def __repr__(self) -> str:
        """One line: each plane's shape and dtype (``device`` for a device
        array), a long dict (the stats) by its keys; never the pixels."""

        def short(v: Any) -> str:
            shape, dtype = getattr(v, "shape", None), getattr(v, "dtype", None)
            if shape is not None and dtype is not None:
                where = "" if isinstance(v, np.ndarray) else " device"
                return f"<{'x'.join(map(str, shape))} {np.dtype(dtype).name}{where}>"
            if isinstance(v, Mapping):
                text = "{" + ", ".join(f"{k!r}: {short(v[k])}" for k in v.keys()) + "}"
                return text if len(text) <= 120 else f"{{{len(v)} entries: {', '.join(map(str, v.keys()))}}}"
            text = repr(v)
            return text if len(text) <= 40 else text[:37] + "..."

        import dataclasses

        if not dataclasses.is_dataclass(self):
            return object.__repr__(self)
        parts = [f"{f.name}={short(getattr(self, f.name))}" for f in dataclasses.fields(self)]
        return f"{type(self).__name__}({', '.join(parts)})"

    def save_png(self, path: str | os.PathLike[str], background: Sequence[int] | None = None) -> Path:
        """Write :meth:`to_uint8` of `background` to the PNG file `path`; the path."""
        return save_png(path, self.to_uint8(background))


def rgba8(rgba: npt.ArrayLike, background: Sequence[int] | None = None) -> np.ndarray:
    """Picture.to_uint8 of a ``(H, W, 4)`` uint8 straight-alpha image: a copy,
    or `opaque` over `background`."""
    a = _rgba("rgba", rgba)
    return a.copy() if background is None else opaque(a, background)


def float_rgba8(
    rgba: npt.ArrayLike, background: Sequence[int] | None = None, *, premultiplied: bool
) -> np.ndarray:
    """Picture.to_uint8 of a ``(H, W, 4)`` float image with colour in [0, 1]
    (premultiplied by alpha or not), a band of rows at a time so float
    temporaries stay small for large images."""
    a = np.asarray(rgba)
    if a.ndim != 3 or a.shape[2] != 4:
        raise ValueError(f"rgba: expected shape (H, W, 4), got {a.shape}")
    bg = None if background is None else np.asarray(_colour("background", background), np.float32) / 255
    out = np.empty(a.shape, np.uint8)
    step = max(1, (1 << 20) // max(a.shape[1], 1))
    for y in range(0, a.shape[0], step):
        band = a[y : y + step].astype(np.float32, copy=False)
        alpha = np.clip(band[..., 3:4], 0.0, 1.0)
        rgb: np.ndarray = band[..., :3]
        if bg is None:
            if premultiplied:
                with np.errstate(divide="ignore", invalid="ignore"):
                    rgb = np.where(alpha > 0, rgb / alpha, 0.0)
            else:
                rgb = np.where(alpha > 0, rgb, 0.0)
            out[y : y + step, :, 3:] = np.rint(alpha * 255)
        else:
            rgb = (rgb if premultiplied else rgb * alpha) + (1 - alpha) * bg
            out[y : y + step, :, 3] = 255
        out[y : y + step, :, :3] = np.rint(np.clip(rgb, 0.0, 1.0) * 255)
    return out


def save_png(path: str | os.PathLike[str], image: npt.ArrayLike) -> Path:
    """Write `image` (``(H, W, 4)`` RGBA, ``(H, W, 3)`` RGB or ``(H, W)`` grey,
    uint8, H and W >= 1) to the PNG file `path`, creating its parent folders.
    The file appears complete or not at all. Returns the path."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"image: expected uint8, got {image.dtype.name}")
    if (
        not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] in (3, 4)))
        or image.shape[0] < 1
        or image.shape[1] < 1
    ):
        raise ValueError(
            f"image: expected shape (H, W), (H, W, 3) or (H, W, 4) with H, W >= 1, got {image.shape}"
        )
    from PIL import Image

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    from .io.files import replacing

    # atomic: a hidden temporary file renamed over `path` (removed on any failure)
    with replacing(path) as tmp, open(tmp, "xb") as f:
        Image.fromarray(np.ascontiguousarray(image)).save(f, format="PNG")
    return path


def depth_image(
    depth: npt.ArrayLike,
    colormap: str | npt.ArrayLike = "magma",
    near: float | None = None,
    far: float | None = None,
) -> np.ndarray:
    """RGBA image of a depth plane ``(H, W)`` float (inf or NaN = empty).

    Closer is brighter: depth `near` takes the colormap's last entry and `far`
    its first (depths outside clamp). `near` and `far` default to the smallest
    and largest finite depth; when they are equal every pixel gets the first
    entry. Empty pixels are transparent black.
    """
    depth = _plane("depth", depth)
    lo, hi = cm.value_range(depth)
    near = lo if near is None else cm._limit("near", near)
    far = hi if far is None else cm._limit("far", far)
    if near > far:
        raise ValueError(f"near ({near!r}) must be <= far ({far!r})")
    rgba = cm.apply(-depth, _table(colormap), -far, -near)
    rgba[~np.isfinite(depth)] = 0
    return rgba


def velocity_images(vel2d: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """``(angle_rgba, magnitude_rgba)`` of a screen-space velocity plane
    ``(H, W, 2)`` float: ``[vx, vy]`` in pixels, y pointing down, NaN where
    empty.

    Angle: ``atan2(vy, vx)`` in [-pi, pi] through the cyclic colormap
    "twilight" (a zero vector has angle 0). Magnitude: ``hypot(vx, vy)``
    through "inferno" from 0 to the 99th percentile of the finite magnitudes.
    A pixel with either component NaN is transparent black in both.
    """
    v = np.asarray(vel2d)
    if v.dtype.kind != "f":
        raise TypeError(f"vel2d: expected floats, got dtype {v.dtype.name}")
    if v.ndim != 3 or v.shape[2] != 2:
        raise ValueError(f"vel2d: expected shape (H, W, 2), got {v.shape}")
    vx, vy = v[..., 0].astype(np.float32), v[..., 1].astype(np.float32)
    empty = np.isnan(vx) | np.isnan(vy)
    angle = np.arctan2(vy, vx)
    with np.errstate(over="ignore"):
        mag = np.hypot(vx, vy)
    finite = mag[np.isfinite(mag)]
    top = float(np.percentile(finite, 99)) if finite.size else 1.0
    angle_rgba = cm.apply(angle, cm.lut("twilight"), -np.pi, np.pi)
    mag_rgba = cm.apply(mag, cm.lut("inferno"), 0.0, top)
    angle_rgba[empty] = 0
    mag_rgba[empty] = 0
    return angle_rgba, mag_rgba


def attribute_image(
    plane: npt.ArrayLike,
    colormap: str | npt.ArrayLike = "viridis",
    vmin: float | None = None,
    vmax: float | None = None,
) -> np.ndarray:
    """RGBA image of an attribute plane ``(H, W)`` float (NaN = empty,
    transparent black) through ``colormap.apply``; `vmin` and `vmax` default
    to the finite range of the plane."""
    plane = _plane("plane", plane)
    lo, hi = cm.value_range(plane)
    return cm.apply(plane, _table(colormap), lo if vmin is None else vmin, hi if vmax is None else vmax)


def side_by_side(images: Iterable[np.ndarray], pad: int = 4) -> np.ndarray:
    """RGBA images ``(H_i, W_i, 4)`` uint8 placed left to right, `pad`
    transparent columns between neighbours, each top-aligned and padded with
    transparent rows to the tallest."""
    pad = nonnegative_int("pad", pad)
    images = [np.asarray(im) for im in images]
    if not images:
        raise ValueError("images: expected at least one image")
    for k, im in enumerate(images):
        if im.dtype != np.uint8 or im.ndim != 3 or im.shape[2] != 4:
            raise ValueError(
                f"images[{k}]: expected an (H, W, 4) uint8 RGBA image, got shape {im.shape} {im.dtype.name}"
            )
    height = max(im.shape[0] for im in images)
    width = sum(im.shape[1] for im in images) + pad * (len(images) - 1)
    out = np.zeros((height, width, 4), np.uint8)
    x = 0
    for im in images:
        out[: im.shape[0], x : x + im.shape[1]] = im
        x += im.shape[1] + pad
    return out


def _plane(name: str, x) -> np.ndarray:
    x = np.asarray(x)
    if x.dtype.kind != "f":
        raise TypeError(f"{name}: expected floats, got dtype {x.dtype.name}")
    if x.ndim != 2:
        raise ValueError(f"{name}: expected shape (H, W), got {x.shape}")
    return x.astype(np.float32, copy=False)


def _table(colormap) -> np.ndarray:
    return cm.lut(colormap) if isinstance(colormap, str) else np.asarray(colormap)


# ---------------------------------------------------------------- pictures


def opaque(rgba: npt.ArrayLike, background: Sequence[int] = BACKGROUND) -> np.ndarray:
    """``(H, W, 4)`` uint8 RGBA `rgba` (straight alpha) over the RGB colour
    `background` (three 0..255 integers): the same shape, every alpha 255."""
    a = _rgba("rgba", rgba)
    bg = _colour("background", background)
    alpha = a[..., 3:4].astype(np.uint16)
    out = np.empty_like(a)
    out[..., :3] = (a[..., :3] * alpha + np.asarray(bg, np.uint16) * (255 - alpha) + 127) // 255
    out[..., 3] = 255
    return out


def from_premultiplied(rgba: npt.ArrayLike) -> np.ndarray:
    """``(H, W, 4)`` float RGBA with premultiplied colour in [0, 1] (what the
    Gaussian renderer gives) as uint8 RGBA with straight alpha; alpha 0 gives
    transparent black."""
    a = np.asarray(rgba, np.float32)
    if a.ndim != 3 or a.shape[2] != 4:
        raise ValueError(f"rgba: expected shape (H, W, 4), got {a.shape}")
    alpha = np.clip(a[..., 3:4], 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rgb = np.where(alpha > 0, a[..., :3] / alpha, 0.0)
    out = np.concatenate([np.clip(rgb, 0.0, 1.0), alpha], axis=2)
    return np.rint(out * 255).astype(np.uint8)


def font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    """Pillow's built-in font at `size` pixels (its bitmap font, about 11
    pixels, where Pillow is older than 10.1 or has no FreeType)."""
    return _font(int(size))


@functools.lru_cache(maxsize=32)
def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except (TypeError, OSError, ImportError, AttributeError):  # Pillow < 10.1, or no FreeType
        return ImageFont.load_default()


def _text_size(width: int) -> int:
    """The font size for labels of a panel `width` pixels wide."""
    return int(min(MAX_TEXT, max(MIN_TEXT + 4, round(width / 26))))


def label_height(width: int) -> int:
    """Rows of the band `label` adds above a panel `width` pixels wide (and
    of a `colorbar` of that width)."""
    return int(round(_text_size(width) * 1.5)) + 2


def _gap(f, size: int) -> float:
    """The space between words: the font's own, but at least 0.3 of its
    size (Pillow's default font's space is 2 pixels at 8 to 11, which read
    "rays still" as "raysstill" in a shrunk label)."""
    return max(float(f.getlength(" ")), math.ceil(0.3 * size))


def _length(f, text: str, size: int) -> float:
    """The width of `text` drawn word by word with _gap between the words."""
    words = text.split(" ")
    return sum(float(f.getlength(w)) for w in words) + _gap(f, size) * (len(words) - 1)


def _fit_text(text: str, size: int, width: int):
    """(font, text, size) with the text fitting `width` pixels: the font
    shrunk down to MIN_TEXT, then the text cut with an ellipsis."""
    while True:
        f = _font(size)
        if _length(f, text, size) <= width or size <= MIN_TEXT:
            break
        size -= 1
    if _length(f, text, size) <= width:
        return f, text, size
    while text and _length(f, text + "\u2026", size) > width:
        text = text[:-1]
    return f, ((text.rstrip() + "\u2026") if text else ""), size


def _draw_text(band: np.ndarray, pieces, size: int, colour=TEXT) -> np.ndarray:
    """`pieces`: [(text, "left" | "centre" | "right")] written on `band`
    (RGBA), vertically centred, with a margin of a third of the font size;
    words drawn one by one, _gap apart."""
    from PIL import Image, ImageDraw

    im = Image.fromarray(band)
    draw = ImageDraw.Draw(im)
    h, w = band.shape[:2]
    margin = max(2, size // 3)
    for text, where in pieces:
        f, text, fitted = _fit_text(text, size, max(1, w - 2 * margin))
        if not text:
            continue
        left = draw.textbbox((0, 0), text, font=f)[0]
        length = _length(f, text, fitted)
        _, top, _, bottom = draw.textbbox((0, 0), "Hg", font=f)  # one baseline for every text
        x = {
            "left": margin - left,
            "right": w - margin - left - length,
            "centre": (w - length) / 2 - left,
        }[where]
        y = (h - (bottom - top)) // 2 - top
        for word in text.split(" "):
            draw.text((round(x), y), word, fill=tuple(colour) + (255,), font=f)
            x += float(f.getlength(word)) + _gap(f, fitted)
    return np.asarray(im)


def label(image: npt.ArrayLike, text: str, background: Sequence[int] = BAND) -> np.ndarray:
    """`image` (``(H, W, 4)`` uint8 RGBA) with an opaque band of
    ``label_height(W)`` rows above it, `text` written in it (left-aligned,
    the font shrunk and then the text cut to fit the width). The image's own
    pixels are kept as they are (transparent ones too)."""
    image = _rgba("image", image)
    if not isinstance(text, str):
        raise TypeError(f"text: expected a str, got {type(text).__name__}")
    w = image.shape[1]
    band = np.empty((label_height(w), w, 4), np.uint8)
    band[:] = _colour("background", background) + (255,)
    band = _draw_text(band, [(text, "left")], _text_size(w))
    return np.concatenate([band, image], axis=0)


def colorbar(
    lut: str | npt.ArrayLike,
    vmin: float,
    vmax: float,
    width: int,
    *,
    title: str = "",
    background: Sequence[int] = BAND,
) -> np.ndarray:
    """A horizontal colour bar ``(label_height(width) + ramp rows, width, 4)``,
    opaque: its top rows are the ramp, column ``x`` the colour of the value
    ``vmin + (vmax - vmin) * x / (width - 1)`` through `lut` by the colormap
    index rule (column 0 is ``lut[0]``, the last column ``lut[-1]``); under it
    `vmin` at the left end, `vmax` at the right end and `title` between them.
    `lut`: a colormap name or an ``(n, 4)`` uint8 table."""
    table = _table(lut)
    width = nonnegative_int("width", width)
    if width < 2:
        raise ValueError(f"width: a colour bar needs at least 2 columns, got {width}")
    lo, hi = cm._limit("vmin", vmin), cm._limit("vmax", vmax)
    if lo > hi:
        raise ValueError(f"vmin ({lo!r}) must be <= vmax ({hi!r})")
    values = lo + (hi - lo) * np.arange(width, dtype=np.float64) / (width - 1)
    values[-1] = hi
    ramp_rows = max(4, _text_size(width) // 2)
    ramp = np.broadcast_to(cm.apply(values, table, lo, hi), (ramp_rows, width, 4)).copy()
    ramp[..., 3] = 255
    text = np.empty((label_height(width), width, 4), np.uint8)
    text[:] = _colour("background", background) + (255,)
    size = _text_size(width)
    ends = list(zip(_numbers(lo, hi), ("left", "right"), strict=True))
    f = _font(size)
    # the title is centred: each half of it must clear the longer end label
    # by a font size (the room between the ends is off-centre when one end
    # is longer: "value" ran into "1.301e+04" at 160 px)
    half = width / 2 - max(2, size // 3) - max(f.getlength(e) for e, _ in ends) - size
    pieces = ends + ([(title, "centre")] if title and f.getlength(title) / 2 <= half else [])
    return np.concatenate([ramp, _draw_text(text, pieces, size)], axis=0)


def _numbers(lo: float, hi: float) -> tuple[str, str]:
    """The colour bar's two ends, 4 significant digits, more (up to 12) until
    they differ where lo != hi (a cloud's z at 1e9 + 0..50 read "1e+09" at
    both ends); at least the whole digits of an end of 5 to 7 of them (a
    scan's easting 636024..637155 read "6.36e+05" and "6.372e+05", an
    intensity of 65535 "6.554e+04")."""
    top = max(abs(lo), abs(hi))
    whole = len(str(int(top))) if math.isfinite(top) and top >= 1 else 0
    for digits in range(whole if 4 < whole <= 7 else 4, 13):
        a, b = f"{lo:.{digits}g}", f"{hi:.{digits}g}"
        if a != b or lo == hi:
            return a, b
    return a, b


def compose(
    panels: Iterable[np.ndarray],
    columns: int | None = None,
    pad: int = 4,
    background: Sequence[int] | None = BAND,
) -> np.ndarray:
    """``(H_i, W_i, 4)`` uint8 RGBA panels in a grid of `columns` (default:
    all in one row), left to right and top to bottom, `pad` pixels between
    them, each top-aligned in its cell. Gaps and unfilled cells take the RGB
    colour `background` (opaque), or stay transparent with ``background=None``;
    the panels' own pixels are copied as they are."""
    panels = [_rgba(f"panels[{k}]", p) for k, p in enumerate(panels)]
    if not panels:
        raise ValueError("panels: expected at least one panel")
    pad = nonnegative_int("pad", pad)
    cols = len(panels) if columns is None else nonnegative_int("columns", columns)
    if cols < 1:
        raise ValueError(f"columns: expected at least 1, got {cols}")
    cols = min(cols, len(panels))
    rows = [panels[i : i + cols] for i in range(0, len(panels), cols)]
    widths = [max(row[c].shape[1] for row in rows if c < len(row)) for c in range(cols)]
    heights = [max(p.shape[0] for p in row) for row in rows]
    out = np.zeros((sum(heights) + pad * (len(rows) - 1), sum(widths) + pad * (cols - 1), 4), np.uint8)
    if background is not None:
        out[:] = _colour("background", background) + (255,)
    y = 0
    for row, h in zip(rows, heights, strict=True):
        x = 0
        for p, w in zip(row, widths):  # noqa: B905  (the last row may hold fewer panels)
            out[y : y + p.shape[0], x : x + p.shape[1]] = p
            x += w + pad
        y += h + pad
    return out


def _rgba(name: str, x) -> np.ndarray:
    x = np.asarray(x)
    if x.dtype != np.uint8 or x.ndim != 3 or x.shape[2] != 4 or x.shape[0] < 1 or x.shape[1] < 1:
        raise ValueError(
            f"{name}: expected an (H, W, 4) uint8 RGBA image, got shape {x.shape} {x.dtype.name}"
        )
    return x


def _colour(name: str, c) -> tuple[int, int, int]:
    """Three integers 0..255, or a colour's name ("white", "#1e1e1e":
    colormap.named_colour). Floats are refused, whole ones too: (1.0, 1.0,
    1.0), white in the 0..1 convention of matplotlib and Open3D, would
    otherwise draw near-black."""
    if isinstance(c, str):
        r, g, b = cm.named_colour(name, c)
        return round(255 * r), round(255 * g), round(255 * b)
    try:
        vals = list(c)
        ok = len(vals) == 3 and all(
            isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)) and 0 <= v <= 255
            for v in vals
        )
    except TypeError:
        ok = False
    if not ok:
        hint = ""
        if isinstance(c, (tuple, list, np.ndarray)) and any(isinstance(v, (float, np.floating)) for v in c):
            hint = " (a 0..1 float colour: multiply by 255 and round)"
        raise ValueError(f"{name}: expected an RGB colour of three integers 0..255, got {c!r}{hint}")
    return int(vals[0]), int(vals[1]), int(vals[2])


def legend(
    entries: Sequence[tuple[Sequence[int], str]],
    width: int,
    *,
    background: Sequence[int] = BAND,
) -> np.ndarray:
    """A legend band ``(rows, width, 4)``, opaque: each entry (RGB colour,
    text) as a square swatch and its text, as many to a row as fit (the
    widest entry sets the column width), in the order given."""
    width = nonnegative_int("width", width)
    if width < 2:
        raise ValueError(f"width: a legend needs at least 2 columns, got {width}")
    rgb_entries = [(_colour(f"entries[{k}]", c), str(t)) for k, (c, t) in enumerate(entries)]
    size = _text_size(width)
    row_h = label_height(width)
    sw = max(4, size * 3 // 4)
    margin = max(2, size // 3)
    f = _font(size)
    col_w = int(max([f.getlength(t) for _, t in rgb_entries] + [1])) + sw + 3 * margin
    cols = max(1, min(len(rgb_entries), (width - margin) // max(col_w, 1)))
    rows = max(1, -(-len(rgb_entries) // cols))
    out = np.empty((rows * row_h, width, 4), np.uint8)
    out[:] = _colour("background", background) + (255,)
    cell_w = max(1, (width - margin) // cols)
    for k, (c, t) in enumerate(rgb_entries):
        r, col = divmod(k, cols)
        x0, y0 = margin + col * cell_w, r * row_h
        ys = y0 + (row_h - sw) // 2
        out[ys : ys + sw, x0 : min(x0 + sw, width)] = c + (255,)
        tx = x0 + sw + margin
        if tx < width:
            band = out[y0 : y0 + row_h, tx : min(x0 + cell_w, width)]
            if band.shape[1] > 2 * margin:
                out[y0 : y0 + row_h, tx : min(x0 + cell_w, width)] = _draw_text(
                    np.ascontiguousarray(band), [(t, "left")], size
                )
    return out
