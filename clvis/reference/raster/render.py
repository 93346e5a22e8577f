"""NumPy definitions of clvis.raster: what render, resolve and soft z compute.

Written for obviousness: the projection is ``Camera.project`` (float32, the
kernels' order of operations), visibility is ``np.minimum.at`` on
``depth key << 32 | index`` over every pixel of each point's square (point
size N: px - (N-1)//2 .. px + N//2 and the same rows, clipped to the image),
and every G-buffer plane is a gather by the winning index.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import numpy.typing as npt

from ... import colormap as _colormap
from ...camera import Camera, Projected, camera_buffer
from ...raster.render import EMPTY, GBuffers

__all__ = ["depth_key", "key_depth", "nonfinite", "rasterize", "splat", "visibility"]

MAX_ATTRIBUTES = 8  # restated from clvis.raster


def nonfinite(positions: npt.ArrayLike) -> int:
    """How many points have a NaN or infinite coordinate."""
    return int((~np.isfinite(np.asarray(positions, np.float32).reshape(-1, 3))).any(axis=1).sum())


def splat(pr: Projected, width: int, height: int, point_size: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(point, pixel) pairs: every visible point (its index in the input)
    with each pixel py * W + px of its point_size square inside the image."""
    idx = np.flatnonzero(pr.visible)
    if point_size == 1:  # a visible point's own pixel is inside the image
        return idx, pr.py[idx].astype(np.int64) * width + pr.px[idx]
    px, py = pr.px[idx].astype(np.int64), pr.py[idx].astype(np.int64)
    lo, hi = (point_size - 1) // 2, point_size // 2
    points, pixels = [], []
    for dy in range(-lo, hi + 1):
        for dx in range(-lo, hi + 1):
            x, y = px + dx, py + dy
            inside = (x >= 0) & (x < width) & (y >= 0) & (y < height)
            points.append(idx[inside])
            pixels.append(y[inside] * width + x[inside])
    return np.concatenate(points), np.concatenate(pixels)


def depth_key(depth: np.ndarray) -> np.ndarray:
    """clvis/keys.h's order-preserving uint32 key of float32 depths (no NaN)."""
    bits = np.asarray(depth, np.float32).view(np.uint32)
    return np.where(bits & np.uint32(0x80000000), ~bits, bits | np.uint32(0x80000000))


def key_depth(keys: np.ndarray) -> np.ndarray:
    """The inverse of depth_key."""
    keys = np.asarray(keys, np.uint32)
    bits = np.where(keys & np.uint32(0x80000000), keys ^ np.uint32(0x80000000), ~keys)
    return bits.astype(np.uint32).view(np.float32)


def visibility(
    positions: npt.ArrayLike, camera: Camera, width: int, height: int, point_size: int = 1
) -> np.ndarray:
    """(H, W) uint64: min over the points drawn in each pixel of
    depth_key(depth) << 32 | index; all ones where no point is drawn."""
    positions = np.asarray(positions, np.float32).reshape(-1, 3)
    pr = camera.project(positions, width, height)
    idx, pix = splat(pr, width, height, point_size)
    keys = (depth_key(pr.depth[idx]).astype(np.uint64) << np.uint64(32)) | idx.astype(np.uint64)
    vis = np.full(width * height, np.iinfo(np.uint64).max, np.uint64)
    np.minimum.at(vis, pix, keys)
    return vis.reshape(height, width)


def _colors(n, colors, attributes, color_by, colormap, value_range):
    """Per point RGBA (uint8 [n, 4]) as the kernels color them."""
    if color_by is not None:
        values = np.asarray(attributes[color_by]).astype(np.float32)
        vmin, vmax = value_range if value_range is not None else _colormap.value_range(values)
        return _colormap.apply(values, _colormap.lut(colormap), vmin, vmax)
    if colors is not None:
        c = np.asarray(colors, np.uint8)
        if c.shape[1] == 3:
            c = np.concatenate([c, np.full((n, 1), 255, np.uint8)], axis=1)
        return c
    return np.full((n, 4), 255, np.uint8)


def rasterize(
    positions: npt.ArrayLike,
    camera: Camera,
    width: int,
    height: int,
    *,
    colors: npt.ArrayLike | None = None,
    attributes: Mapping[str, npt.ArrayLike] | None = None,
    velocity: npt.ArrayLike | None = None,
    radius: npt.ArrayLike | None = None,
    soft_z: bool | float | None = None,
    color_by: str | None = None,
    colormap: str = "viridis",
    value_range: tuple[float, float] | None = None,
    planes: Sequence[str] | None = None,
    point_size: int = 1,
) -> GBuffers:
    """clvis.rasterize in NumPy (positions as an (N, 3) array). planes: the
    attributes resolved (default: all of them when there are at most 8, else
    none), in the order given."""
    positions = np.asarray(positions, np.float32).reshape(-1, 3)
    n = positions.shape[0]
    H, W = height, width
    attributes = dict(attributes or {})
    if planes is None:
        planes = list(attributes) if len(attributes) <= MAX_ATTRIBUTES else []
    vis = visibility(positions, camera, W, H, point_size).ravel()
    covered = vis != np.iinfo(np.uint64).max
    win = (vis & np.uint64(0xFFFFFFFF)).astype(np.int64)[covered]

    index = np.full(H * W, EMPTY, np.uint32)
    index[covered] = win
    depth = np.full(H * W, np.inf, np.float32)
    depth[covered] = key_depth((vis[covered] >> np.uint64(32)).astype(np.uint32))

    pc = _colors(n, colors, attributes, color_by, colormap, value_range)
    rgba = np.zeros((H * W, 4), np.uint8)
    rgba[covered] = pc[win]
    if soft_z is not None and soft_z is not False and n:
        tol = np.float32(1.01 if soft_z is True else soft_z)
        pr = camera.project(positions, W, H)
        idx, pix = splat(pr, W, H, point_size)
        near = depth[pix]
        keep = pr.depth[idx] <= tol * near
        sums = np.zeros((H * W, 5), np.uint64)
        np.add.at(
            sums,
            pix[keep],
            np.concatenate(
                [pc[idx[keep]].astype(np.uint64), np.ones((int(keep.sum()), 1), np.uint64)], axis=1
            ),
        )
        cnt = sums[covered, 4:5]
        rgba[covered] = ((sums[covered, :4] + cnt // 2) // cnt).astype(np.uint8)

    resolved = {}
    for name in planes:
        a = np.asarray(attributes[name])
        if a.dtype == np.uint8 or a.dtype == np.bool_:
            plane = np.zeros(H * W, np.uint8)
            plane[covered] = a.astype(np.uint8)[win]
        else:
            plane = np.full(H * W, np.nan, np.float32)
            plane[covered] = a.astype(np.float32)[win]
        resolved[name] = plane.reshape(H, W)

    out = GBuffers(
        index=index.reshape(H, W), depth=depth.reshape(H, W), rgba=rgba.reshape(H, W, 4), attributes=resolved
    )
    out.stats = {"points": n, "points_nonfinite": nonfinite(positions)}
    cam = camera_buffer(camera)
    M = cam[:16].reshape(4, 4)
    if velocity is not None:
        p = positions[win]
        v = np.asarray(velocity, np.float32).reshape(-1, 3)[win]

        cx = ((M[0, 0] * p[:, 0] + M[0, 1] * p[:, 1]) + M[0, 2] * p[:, 2]) + M[0, 3]
        cy = ((M[1, 0] * p[:, 0] + M[1, 1] * p[:, 1]) + M[1, 2] * p[:, 2]) + M[1, 3]
        cw = ((M[3, 0] * p[:, 0] + M[3, 1] * p[:, 1]) + M[3, 2] * p[:, 2]) + M[3, 3]
        vcx = (M[0, 0] * v[:, 0] + M[0, 1] * v[:, 1]) + M[0, 2] * v[:, 2]
        vcy = (M[1, 0] * v[:, 0] + M[1, 1] * v[:, 1]) + M[1, 2] * v[:, 2]
        vcw = (M[3, 0] * v[:, 0] + M[3, 1] * v[:, 1]) + M[3, 2] * v[:, 2]
        ww = cw * cw
        vx = (np.float32(0.5) * np.float32(W)) * ((vcx * cw - cx * vcw) / ww)
        vy = -((np.float32(0.5) * np.float32(H)) * ((vcy * cw - cy * vcw) / ww))
        vel = np.full((H * W, 2), np.nan, np.float32)
        vel[covered, 0], vel[covered, 1] = vx, vy
        out.vel2d = vel.reshape(H, W, 2)
        out.vel_angle = np.arctan2(out.vel2d[..., 1], out.vel2d[..., 0])
        out.vel_speed = np.sqrt(out.vel2d[..., 0] * out.vel2d[..., 0] + out.vel2d[..., 1] * out.vel2d[..., 1])
    if radius is not None:
        focal = np.float32(0.5 * H * float(np.asarray(camera.projection)[1, 1]))
        r = np.asarray(radius, np.float32)[win]
        rp = np.full(H * W, np.nan, np.float32)
        # an orthographic camera draws a world unit as `focal` pixels at every depth
        rp[covered] = r * focal if camera.orthographic else (r * focal) / depth[covered]
        out.radius_px = rp.reshape(H, W)
    return out
