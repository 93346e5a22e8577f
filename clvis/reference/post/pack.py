"""NumPy reference of clvis.post.pack: images to and from the networks' tensors.

A tensor is NCHW float32 with batch 1: (1, C, Hp, Wp), Hp and Wp the image's
height and width rounded up to a multiple of the network's stride. Pixels
past the image (the bottom rows and right columns) are padding. pack_iso
writes it as finished rays that missed (all 0); pack_rgbda and
pack_gbuffers as the image reflected about its last row and column
(numpy.pad's "symmetric" mode), so the LiDAR and NARVis networks see the
scan go on past its edge: an empty band, which no network saw in training,
cost the LiDAR U-Net 0.2-1.9 dB on photographs whose sides are not
multiples of its stride; the in-fill W-Net, measured both ways on its full
held-out suite, lost 0.03 dB on average with the reflection.
``kernels_cl/post/pack.cl`` gives these results bit for bit (on
devices that keep float32 denormals: the depth normalisation's division is
IEEE float32 on both sides).

pack_iso (the in-fill network): from an iso image's ``rgba`` (H x W x 4,
shaded colour at hits), ``hit`` and ``active`` (H x W, nonzero = true),
channels R, G, B, HIT, ACTIVE. A pixel is shown where hit and not active:
R, G, B = its r, g, b and HIT = 1; elsewhere R = G = B = HIT = 0. ACTIVE = 1
where active, else 0. Padding: all 0. A hit pixel's r, g, b must be finite.
With ``candidates`` (H x W uint8, clvis.iso.IsoImage.candidates: the
candidate blocks left on each running ray) a sixth channel CANDIDATES =
min(candidates, CANDIDATES_CAP) / CANDIDATES_CAP in float32 where active,
else 0 (CANDIDATES_CAP = 8, the renderer's count limit clvis.iso.CANDIDATES).
With ``crossing_rate`` too (rho in [0, 1]: the frame's finished rays that hit
per candidate block the render has tested, clvis.post.pack.crossing_rate) a seventh
channel HIT_PRIOR = 1 - (1 - rho)^k where active, else 0, k =
min(candidates, CANDIDATES_CAP): how likely a running ray with k blocks left
is to end on the surface if each block is crossed with probability rho. The
power is k float32 products 1 * m * m ... (m = float32(1 - rho)) in order.
With ``depth`` = (t, next_t) instead of ``crossing_rate`` (H x W float32:
an IsoImage's t, a finished hit's ray parameter, and its next_t, where a
running ray's next candidate block begins) a seventh and eighth channel
DEPTH, NEXT: with lo, hi the minimum and maximum of the finite t where hit
and not active and the finite next_t where active, DEPTH = (t - lo) / (hi -
lo) at those finished hits, NEXT = (next_t - lo) / (hi - lo) at those running
rays, in float32 (one subtraction, one division); 0 elsewhere, and
everywhere when hi - lo is not > 0.

pack_rgbda (the LiDAR U-Net, following the LiDAR paper's authors'
conventions): from ``rgbda`` (H x W x 5 [r, g, b, depth, alpha], a
FilteredImage's), channels R, G, B, A, D. A pixel is kept where alpha > 0 and
depth is finite: R, G, B, A as given, ``D = (depth - dmin) / (dmax - dmin)``
in float32 with dmin, dmax the minimum and maximum depth over the kept pixels
of this image (D = 0 when dmax == dmin). Elsewhere R = G = B = A = 0, D =
-1. No kept pixel: every pixel empty. Errors: a NaN anywhere, a depth of
-inf where alpha > 0.

pack_gbuffers (the NARVis U-Net): from rasterizer G-buffers (``index``,
``rgba`` and the planes named), the channels of
clvis.post.nets.gbuffer_channels(planes): R, G, B = rgba / 255 in float32
and COVERAGE = 1 at covered pixels (index != 0xFFFFFFFF); then depth, then
the screen velocity (vel2d's x and y, vel_angle, vel_speed), then the splat
radius in pixels (``radius_px``, where "radius" is named), then each other
named plane (an attribute, as float32) in the order given. Every channel is
0 at empty pixels. A covered pixel whose value is NaN or
infinite is an error.

unpack_rgba8: from (1, C, Hp, Wp), C = 3 or 4, the top-left height x width
pixels as H x W x 4 uint8: ``rint(clip(v, 0, 1) * 255)`` in float32 (rint:
half to even), NaN -> 0, alpha 255 when C = 3.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ...errors import DataError

MAX_SIDE = 32768
MAX_PIXELS = 2**28
#: pack_iso's CANDIDATES channel saturates here (clvis.iso.CANDIDATES)
CANDIDATES_CAP = 8

_F = np.float32


def padded_shape(height: int, width: int, stride: int = 1) -> tuple[int, int]:
    return -(-height // stride) * stride, -(-width // stride) * stride


def _nchw(planes: list[np.ndarray], hp: int, wp: int, mirror: bool = True) -> np.ndarray:
    """The planes as (1, C, hp, wp), padded by reflection (or with 0)."""
    out = np.empty((1, len(planes), hp, wp), _F)
    for c, p in enumerate(planes):
        h, w = p.shape
        pad = ((0, hp - h), (0, wp - w))
        out[0, c] = np.pad(p, pad, mode="symmetric") if mirror else np.pad(p, pad)
    return out


def pack_iso(
    rgba: npt.ArrayLike,
    hit: npt.ArrayLike,
    active: npt.ArrayLike,
    *,
    candidates: npt.ArrayLike | None = None,
    crossing_rate: float | None = None,
    depth: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
    stride: int = 1,
) -> np.ndarray:
    rgba = np.asarray(rgba, _F)
    hit, active = np.asarray(hit).astype(bool), np.asarray(active).astype(bool)
    if not np.isfinite(rgba[hit][:, :3]).all():
        raise DataError("rgba: a hit pixel with a NaN or infinite r, g or b")
    shown = hit & ~active
    rgb = [np.where(shown, rgba[..., c], _F(0)) for c in range(3)]
    hp, wp = padded_shape(shown.shape[0], shown.shape[1], stride)
    planes = [*rgb, shown.astype(_F), active.astype(_F)]
    if candidates is not None:
        k = np.minimum(np.asarray(candidates).astype(np.uint32), CANDIDATES_CAP)
        planes.append(np.where(active, k.astype(_F) / _F(CANDIDATES_CAP), _F(0)))
        if crossing_rate is not None:
            miss = _F(1) - _F(crossing_rate)
            p = np.ones(k.shape, _F)
            for j in range(CANDIDATES_CAP):
                p = np.where(k > j, p * miss, p)
            planes.append(np.where(active, _F(1) - p, _F(0)))
        if depth is not None:
            if crossing_rate is not None:
                raise ValueError(
                    "depth: the depth planes come after the candidates plane, without crossing_rate"
                )
            t, nxt = (np.asarray(a, _F) for a in depth)
            done = shown & np.isfinite(t)
            run = active & np.isfinite(nxt)
            vals = np.concatenate([t[done], nxt[run]])
            lo = vals.min() if vals.size else _F(0)
            span = _F(vals.max() - lo) if vals.size else _F(0)
            with np.errstate(invalid="ignore", over="ignore"):
                d = np.where(done, (t - lo) / span, _F(0)) if span > 0 else np.zeros(t.shape, _F)
                n = np.where(run, (nxt - lo) / span, _F(0)) if span > 0 else np.zeros(t.shape, _F)
            planes += [d.astype(_F), n.astype(_F)]
    elif crossing_rate is not None:
        raise ValueError("crossing_rate: the hit-prior plane needs candidates")
    elif depth is not None:
        raise ValueError("depth: the depth planes come after the candidates plane, without crossing_rate")
    return _nchw(planes, hp, wp, mirror=False)


def pack_rgbda(rgbda: npt.ArrayLike, *, stride: int = 1) -> np.ndarray:
    rgbda = np.asarray(rgbda, _F)
    depth, alpha = rgbda[..., 3], rgbda[..., 4]
    if np.isnan(rgbda).any() or ((alpha > 0) & (depth == -np.inf)).any():
        raise DataError("rgbda: NaN values, or depth -inf where alpha > 0")
    kept = (alpha > 0) & np.isfinite(depth)
    d = np.full(depth.shape, _F(-1))
    if kept.any():
        dmin, dmax = depth[kept].min(), depth[kept].max()
        span = _F(dmax - dmin)
        d[kept] = (depth[kept] - dmin) / span if span > 0 else _F(0)
    planes = [np.where(kept, rgbda[..., c], _F(0)) for c in (0, 1, 2, 4)]
    hp, wp = padded_shape(depth.shape[0], depth.shape[1], stride)
    return _nchw([*planes, d], hp, wp)


def gbuffer_sources(gbuffers: Any, planes: Sequence[str]) -> list[tuple[str, np.ndarray]]:
    """(channel name, (H, W) float32 values) of the planes after R, G, B and
    the coverage, in the tensor's order."""
    planes = list(planes)
    out = []
    if "depth" in planes:
        out.append(("depth", np.asarray(gbuffers.depth, _F)))
    if "vel2d" in planes:
        v = np.asarray(gbuffers.vel2d, _F)
        out += [("vel_x", v[..., 0]), ("vel_y", v[..., 1])]
        out += [
            ("vel_angle", np.asarray(gbuffers.vel_angle, _F)),
            ("vel_speed", np.asarray(gbuffers.vel_speed, _F)),
        ]
    if "radius" in planes:
        out.append(("radius_px", np.asarray(gbuffers.radius_px, _F)))
    for p in planes:
        if p not in ("rgb", "coverage", "depth", "vel2d", "radius"):
            out.append((p, np.asarray(gbuffers.attributes[p]).astype(_F)))
    return out


def pack_gbuffers(gbuffers: Any, planes: Sequence[str], *, stride: int = 1) -> np.ndarray:
    covered = np.asarray(gbuffers.index) != np.uint32(0xFFFFFFFF)
    rgba = np.asarray(gbuffers.rgba)
    chans = [np.where(covered, rgba[..., c].astype(_F) / _F(255), _F(0)) for c in range(3)]
    chans.append(covered.astype(_F))
    for name, v in gbuffer_sources(gbuffers, planes):
        if not np.isfinite(v[covered]).all():
            raise DataError(f"{name}: a covered pixel with a NaN or infinite value")
        chans.append(np.where(covered, v, _F(0)))
    hp, wp = padded_shape(covered.shape[0], covered.shape[1], stride)
    return _nchw(chans, hp, wp)


def unpack_rgba8(nchw: npt.ArrayLike, height: int, width: int) -> np.ndarray:
    x = np.asarray(nchw, _F)[0, :, :height, :width]
    v = np.rint(np.clip(np.nan_to_num(x, nan=0.0), _F(0), _F(1)) * _F(255)).astype(np.uint8)
    out = np.full((height, width, 4), 255, np.uint8)
    out[..., : v.shape[0]] = np.moveaxis(v, 0, -1)
    return out
