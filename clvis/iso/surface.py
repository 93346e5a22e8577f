"""iso family: colouring isosurface images. A second field sampled at the
hits (``sample_hits``, kernel ``kernels_cl/iso/surface.cl``; the definition
is clvis.reference.iso.surface), the surface in a colour of one's own or a
field's colours under the renderer's shading (``color_surface``), and several
isosurfaces in one image, the nearest hit per pixel (``composite``).

The renderer shades a hit as ``clip(base * (AMBIENT + DIFFUSE x) +
SPECULAR x^32)`` (x = |normal . view direction|, base SURFACE_COLOR; clvis/iso.h's
CLVIS_ISO_SHADE_* constants). Its green channel never saturates and grows
with x, so x is found again from it (Newton's method on the convex
polynomial, from above), and another colour c shades the same way:
``clip(c * (AMBIENT + DIFFUSE x) + SPECULAR x^32, 0, 1)``, the highlight
white; SURFACE_COLOR gives back the image's own colours (within 1e-5).

    r = clvis.IsoRenderer(volume)
    img = r.render(cam, 640, 480, 0.5)
    vals = clvis.iso.sample_hits(img, field=temperature)  # NaN off the surface
    rgba = clvis.iso.color_surface(img, values=vals, colormap="coolwarm")
    two = clvis.iso.composite([r.render(cam, 640, 480, v) for v in (0.3, 0.6)],
                              colors=[(0.9, 0.3, 0.2), (0.3, 0.6, 1.0)])
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import pyopencl as cl
import pyopencl.array as cla

from .. import colormap, runtime
from .._arrays import buf, check_array, is_device, resolve_queue, result, to_device, to_host, triple
from ..camera import Camera, ray_buffer, same_camera
from .render import CANDIDATES, IsoImage

__all__ = ["SURFACE_COLOR", "color_surface", "composite", "sample_hits", "surface_colors"]

_SRC = "iso/surface.cl"
PROFILES = {"cpu": {"WG": 64}, "gpu": {"WG": 256}}
# the renderer's base colour (clvis/iso.h CLVIS_ISO_SHADE_BASE_*)
SURFACE_COLOR = (0.9, 0.75, 0.4)
AMBIENT, DIFFUSE, SPECULAR, SHININESS = 0.15, 0.75, 0.3, 32  # _facing's powers are for 32


def _facing(green: np.ndarray) -> np.ndarray:
    """x in [0, 1] from the shaded green g = G (AMBIENT + DIFFUSE x) +
    SPECULAR x^32 (G the base green): Newton from the linear part's root,
    which lies above (the polynomial is convex and increasing), until it
    moves less than 1e-9."""
    g0 = SURFACE_COLOR[1]
    g = green.astype(np.float64)
    x = np.clip((g / g0 - AMBIENT) / DIFFUSE, 0.0, 1.0)
    for _ in range(50):
        x2 = x * x
        x4 = x2 * x2
        x8 = x4 * x4
        x16 = x8 * x8
        f = g0 * (AMBIENT + DIFFUSE * x) + SPECULAR * (x16 * x16) - g
        step = f / (g0 * DIFFUSE + SHININESS * SPECULAR * (x16 * x8 * x4 * x2 * x))
        x = np.clip(x - step, 0.0, 1.0)
        if not x.size or np.abs(step).max() < 1e-9:
            break
    return x


def _plane(image: IsoImage, name: str) -> np.ndarray:
    a = getattr(image, name)
    return to_host(a)


def sample_hits(
    image: IsoImage,
    camera: Camera | None = None,
    field: Any = None,
    spacing: Sequence[float] = (1.0, 1.0, 1.0),
    origin: Sequence[float] = (0.0, 0.0, 0.0),
    *,
    queue: cl.CommandQueue | None = None,
) -> np.ndarray | cla.Array:
    """(H, W) float32: `field` (a 3-D [z, y, x] array, numpy or device; any
    grid: `spacing` (dz, dy, dx) and `origin` (x, y, z) place it in the
    world) at the point where each pixel's ray hit the surface of `image`,
    by trilinear interpolation; NaN at pixels without a hit and at hits
    outside the field's box. A host image gives numpy, a device image
    (render(host=False)) a device array on the same queue.

    The rays are those of the camera the image was rendered with
    (``image.camera``, which the renderer records): ``sample_hits(img,
    field=f)`` or ``sample_hits(img, None, f)``. A `camera` given must be
    that one (the same view and projection, to 1e-9): another camera's rays
    would put each hit somewhere else, so it is a ValueError. An image made
    by hand (``image.camera`` None) needs its `camera`."""
    if not isinstance(image, IsoImage):
        raise TypeError(f"image: expected a clvis.iso.IsoImage, got {type(image).__name__}")
    if camera is not None and not isinstance(camera, Camera):
        hint = " (the field goes third, or as field=...)" if field is None else ""
        raise TypeError(f"camera: expected a clvis.Camera or None, got {type(camera).__name__}{hint}")
    if field is None:
        raise TypeError("field: the field to sample is missing (sample_hits(image, field=...))")
    recorded = getattr(image, "camera", None)
    if recorded is not None and not isinstance(recorded, Camera):
        raise TypeError(f"image.camera: expected a clvis.Camera or None, got {type(recorded).__name__}")
    if camera is None:
        if recorded is None:
            raise ValueError(
                "camera: the image records no camera (it was not made by IsoRenderer); pass the "
                "camera it was rendered with: sample_hits(image, camera, field)"
            )
        camera = recorded
    elif recorded is not None and not same_camera(camera, recorded):
        raise ValueError(
            f"camera: {camera!r} is not the camera the image was rendered with ({recorded!r}; "
            "its rays would put the hits elsewhere): leave camera out (sample_hits(image, "
            "field=...)) to use the image's own"
        )
    host = not is_device(image.hit)
    queue = resolve_queue(queue, hit=image.hit, t=image.t, field=field)
    if not is_device(field):
        field = np.asarray(field)
        if field.dtype.kind not in "biuf":
            raise TypeError(f"field: expected a real array, got dtype {field.dtype}")
        field = np.ascontiguousarray(field, np.float32)
    field = check_array("field", field, dtypes=[np.float32], ndim=3)
    if min(field.shape) < 2:
        raise ValueError(f"field: every axis needs at least 2 samples, got shape {tuple(field.shape)}")
    dz, dy, dx = triple("spacing", spacing, positive=True)
    ox, oy, oz = triple("origin", origin, positive=False)
    if len(image.hit.shape) != 2 or tuple(image.t.shape) != tuple(image.hit.shape):
        raise ValueError(
            f"image: expected (H, W) hit and t planes, got {tuple(image.hit.shape)} and "
            f"{tuple(image.t.shape)}"
        )
    h, w = (int(s) for s in image.hit.shape)
    n = h * w
    runtime.check_memory(
        queue, f"sample_hits: field {tuple(field.shape)}", device_bytes=int(field.nbytes) + 9 * n
    )
    out = runtime.empty(queue, (h, w), np.float32, "surface values")
    if n:
        cam = runtime.empty(queue, 22, np.float32, "camera rays")
        cam.set(ray_buffer(camera, w, h), queue=queue)
        hit = to_device(queue, "hit", np.ascontiguousarray(image.hit, np.uint8) if host else image.hit)
        t = to_device(queue, "t", np.ascontiguousarray(image.t, np.float32) if host else image.t)
        fd = to_device(queue, "field", field)
        nz, ny, nx = (int(s) for s in field.shape)
        k = runtime.get_kernel(queue, _SRC, "sample_hits", {}, runtime.EXACT_FP)
        wg = PROFILES[runtime.tuning_profile(queue)]["WG"]
        f32, u32 = np.float32, np.uint32
        runtime.launch(
            queue,
            k,
            *runtime.items(queue, n, wg),
            buf(cam),
            u32(w),
            u32(n),
            buf(hit),
            buf(t),
            buf(fd),
            u32(nx),
            u32(ny),
            u32(nz),
            f32(dx),
            f32(dy),
            f32(dz),
            f32(ox),
            f32(oy),
            f32(oz),
            buf(out),
        )
    return result(out, host)


def _rgb(name: str, c: Any) -> np.ndarray:
    """An rgb colour: three numbers in 0..1, or a colour's name ("red",
    "#e04020": colormap.named_colour)."""
    if isinstance(c, str):
        return np.array(colormap.named_colour(name, c), np.float64)
    try:
        a = np.asarray(c, np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected (r, g, b) in 0..1 or a colour name, got {c!r}") from None
    if a.shape != (3,) or not np.isfinite(a).all() or (a < 0).any() or (a > 1).any():
        raise ValueError(f"{name}: expected (r, g, b) in 0..1 or a colour name, got {c!r}")
    return a


def surface_colors(n: int) -> list[tuple[float, float, float]]:
    """n surface colours: the renderer's own first, then matplotlib's tab10
    from its second (the colours of several isovalues in one image; they
    repeat after 10)."""
    tab = colormap.lut("tab10", 10)[:, :3].astype(np.float64) / 255
    table = [SURFACE_COLOR] + [(float(r), float(g), float(b)) for r, g, b in tab[1:]]
    return [table[i % len(table)] for i in range(int(n))]


def color_surface(
    image: IsoImage,
    color: Sequence[float] | None = None,
    *,
    values: npt.ArrayLike | cla.Array | None = None,
    colormap_name: str = "viridis",
    value_range: Sequence[float] | None = None,
    nan_color: Sequence[float] | None = None,
) -> np.ndarray:
    """(H, W, 4) float32: the image's surface in `color` ((r, g, b) in 0..1;
    default the renderer's) or, with `values` ((H, W), e.g. sample_hits'),
    in the colours of `colormap_name` over `value_range` (default the finite
    values' min..max), under the renderer's shading (the module doc); hits
    whose value is NaN take `nan_color` (default `color`). Alpha 1 at hits,
    0 (and rgb 0) elsewhere. Device images are read back."""
    if not isinstance(image, IsoImage):
        raise TypeError(f"image: expected a clvis.iso.IsoImage, got {type(image).__name__}")
    rgba, hit = _plane(image, "rgba").astype(np.float32), _plane(image, "hit").astype(bool)
    base = _rgb("color", SURFACE_COLOR if color is None else color)
    x = np.zeros(hit.shape)
    x[hit] = _facing(rgba[..., 1][hit])
    light, highlight = AMBIENT + DIFFUSE * x, SPECULAR * x**SHININESS
    col = np.broadcast_to(base.astype(np.float32), rgba.shape[:2] + (3,))
    if values is not None:
        v = to_host(values).astype(np.float32, copy=False)
        if v.shape != hit.shape:
            raise ValueError(f"values: expected shape {hit.shape}, got {v.shape}")
        if value_range is None:
            lo, hi = colormap.value_range(v[hit])
        else:
            lo, hi = (float(x) for x in value_range)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ValueError(f"value_range: expected finite vmin <= vmax, got {value_range!r}")
        mapped = colormap.apply(v, colormap.lut(colormap_name), lo, hi)[..., :3].astype(np.float32) / 255
        nan = _rgb("nan_color", base if nan_color is None else nan_color).astype(np.float32)
        col = np.where(np.isfinite(v)[..., None], mapped, nan)
    out = np.zeros(rgba.shape, np.float32)
    out[..., :3] = np.clip(col * light[..., None] + highlight[..., None], 0.0, 1.0)
    out[..., 3] = 1.0
    out[~hit] = 0.0
    return out


def composite(
    images: Sequence[IsoImage],
    colors: Sequence[Sequence[float]] | None = None,
    *,
    planes: Sequence[npt.ArrayLike] | None = None,
) -> IsoImage:
    """Several isosurfaces of one camera and size in one host image: each
    pixel shows its nearest hit (the least depth; ties: the first image),
    coloured by color_surface in its image's colour (`colors`, one per image;
    default surface_colors), or taken from `planes` ((H, W, 4) each, one per
    image, e.g. color_surface(image, values=...); then `colors` is not used).
    ``active``: rays still running in any image; ``candidates``: the sum of
    the images' (the candidate blocks left over every isovalue), capped at
    CANDIDATES, None where an image has none; ``next_t``: the nearest of the
    images' (None where an image has none); ``completion``: the least
    of the images'; ``stats``: {"images": their stats}; ``camera``: the
    images' (ValueError where two record different cameras; None where one
    records none)."""
    imgs = list(images)
    if not imgs or not all(isinstance(i, IsoImage) for i in imgs):
        raise TypeError("images: expected a non-empty sequence of clvis.iso.IsoImage")
    shape = tuple(imgs[0].hit.shape)
    if any(tuple(i.hit.shape) != shape for i in imgs):
        raise ValueError(f"images: expected one size, got {[tuple(i.hit.shape) for i in imgs]}")
    cams = [getattr(i, "camera", None) for i in imgs]
    known = [c for c in cams if c is not None]
    if any(not same_camera(known[0], c) for c in known[1:]):
        raise ValueError(
            "images: rendered with different cameras; their depths do not compare (composite "
            "images of one camera and size)"
        )
    if planes is not None:
        rgba = np.stack([np.asarray(p, np.float32) for p in planes])
        if rgba.shape != (len(imgs), *shape, 4):
            raise ValueError(f"planes: expected {len(imgs)} of shape {(*shape, 4)}, got {rgba.shape}")
    else:
        cols = surface_colors(len(imgs)) if colors is None else list(colors)
        if len(cols) != len(imgs):
            raise ValueError(f"colors: expected one per image ({len(imgs)}), got {len(cols)}")
        rgba = np.stack([color_surface(i, c) for i, c in zip(imgs, cols, strict=True)])
    hits = np.stack([_plane(i, "hit").astype(bool) for i in imgs])
    depth = np.where(hits, np.stack([_plane(i, "depth") for i in imgs]), np.inf).astype(np.float32)
    t = np.where(hits, np.stack([_plane(i, "t") for i in imgs]), np.inf).astype(np.float32)
    sel = np.argmin(depth, axis=0)[None]
    # the candidate blocks left over every isovalue's ray, up to CANDIDATES (None: an image has none)
    left = None
    if all(getattr(i, "candidates", None) is not None for i in imgs):
        total = np.stack([_plane(i, "candidates").astype(np.int64) for i in imgs]).sum(axis=0)
        left = np.minimum(total, CANDIDATES).astype(np.uint8)
    # where the next candidate block begins over every isovalue's ray: the nearest
    next_t = None
    if all(getattr(i, "next_t", None) is not None for i in imgs):
        next_t = np.stack([_plane(i, "next_t") for i in imgs]).min(axis=0).astype(np.float32)
    return IsoImage(
        rgba=np.take_along_axis(rgba, sel[..., None], axis=0)[0],
        depth=np.take_along_axis(depth, sel, axis=0)[0],
        hit=np.asarray(hits.any(axis=0)),
        t=np.take_along_axis(t, sel, axis=0)[0],
        active=np.asarray(np.stack([_plane(i, "active").astype(bool) for i in imgs]).any(axis=0)),
        completion=min(float(i.completion) for i in imgs),
        stats={"images": [i.stats for i in imgs]},
        candidates=left,
        next_t=next_t,
        camera=cams[0] if len(known) == len(cams) else None,
    )
