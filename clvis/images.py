"""G-buffer planes to images a person looks at, and PNG files (Pillow).

Images are ``[H, W, C]`` uint8 arrays, row 0 on top. Every colour image here is
RGBA with empty pixels transparent black ``(0, 0, 0, 0)``; colours come from
``clvis.colormap`` by its index rule. `colormap` arguments take a matplotlib
name or an ``(n, 4)`` uint8 table.
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path

import numpy as np

from . import colormap as cm
from ._arrays import nonnegative_int

__all__ = ["attribute_image", "depth_image", "save_png", "side_by_side", "velocity_images"]


def save_png(path, image) -> Path:
    """Write `image` (``(H, W, 4)`` RGBA, ``(H, W, 3)`` RGB or ``(H, W)`` grey,
    uint8, H and W >= 1) to the PNG file `path`, creating its parent folders.
    The file appears complete or not at all. Returns the path."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"image: expected uint8, got {image.dtype.name}")
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] in (3, 4))) \
            or image.shape[0] < 1 or image.shape[1] < 1:
        raise ValueError(f"image: expected shape (H, W), (H, W, 3) or (H, W, 4) with H, W >= 1, "
                         f"got {image.shape}")
    from PIL import Image

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(6)}.tmp")
    try:
        with open(tmp, "xb") as f:
            Image.fromarray(np.ascontiguousarray(image)).save(f, format="PNG")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def depth_image(depth, colormap="magma", near=None, far=None) -> np.ndarray:
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


def velocity_images(vel2d) -> tuple[np.ndarray, np.ndarray]:
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


def attribute_image(plane, colormap="viridis", vmin=None, vmax=None) -> np.ndarray:
    """RGBA image of an attribute plane ``(H, W)`` float (NaN = empty,
    transparent black) through ``colormap.apply``; `vmin` and `vmax` default
    to the finite range of the plane."""
    plane = _plane("plane", plane)
    lo, hi = cm.value_range(plane)
    return cm.apply(plane, _table(colormap), lo if vmin is None else vmin,
                    hi if vmax is None else vmax)


def side_by_side(images, pad=4) -> np.ndarray:
    """RGBA images ``(H_i, W_i, 4)`` uint8 placed left to right, `pad`
    transparent columns between neighbours, each top-aligned and padded with
    transparent rows to the tallest."""
    pad = nonnegative_int("pad", pad)
    images = [np.asarray(im) for im in images]
    if not images:
        raise ValueError("images: expected at least one image")
    for k, im in enumerate(images):
        if im.dtype != np.uint8 or im.ndim != 3 or im.shape[2] != 4:
            raise ValueError(f"images[{k}]: expected an (H, W, 4) uint8 RGBA image, "
                             f"got shape {im.shape} {im.dtype.name}")
    height = max(im.shape[0] for im in images)
    width = sum(im.shape[1] for im in images) + pad * (len(images) - 1)
    out = np.zeros((height, width, 4), np.uint8)
    x = 0
    for im in images:
        out[:im.shape[0], x:x + im.shape[1]] = im
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
