"""The tile renderer of GaussianRenderer (method="tiles", kernels_cl/gauss/tiles.cl).

The same image as the BVH march (march.cl): the same hit test, alpha and
compositing, in the same (t, id) order per pixel. Data flow per band of tile
rows:

1. ``tile_count``: each Gaussian's exact projected footprint (the outline
   ellipse of its cutoff ellipsoid, inflated by 1 %) against the tiles' pixel
   centres, in closed form a tile row (the ellipse's extent across the row's
   strip); the number of tiles it may touch.
2. ``clvis.primitives.scan`` of the counts: each Gaussian's first key, and the
   band's key count (one small read: the band is split when it exceeds the
   budget, ``tile_keys`` of the tuning profile or ``max_keys``).
3. ``tile_keys``: one key ``tile << 32 | key_f32(dmin)`` per (Gaussian, tile),
   dmin a lower bound of the Gaussian's view depth.
4. ``clvis.primitives.radix_sort`` of the keys with the Gaussian ids.
5. ``tile_ranges``: each tile's run of keys; ``gather_records``
   (gaussians.cl): the keys' records in key order (the render kernels stream
   them).
6. ``tile_render``: per pixel, the tile's list in dmin order; a hit is
   composited once no later candidate can come before it (its depth is below
   the next candidate's dmin), through a small pending buffer, with rounds over
   the same list when more than KP hits are pending.

Memory: keys and ids take 12 bytes a key plus the sort's temporaries (12
more), and the gathered records 56 (not the splat model); the key count is
known before anything is allocated for it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pyopencl as cl

from .. import primitives, runtime
from .._arrays import buffer_of
from ..camera import Camera, ray_buffer
from ..colormap import TransferFunction
from ..errors import DeviceError
from .gaussians import GAUSSIAN_DTYPE, gather_records

__all__ = ["KEY_BYTES", "PROFILES", "projection_rows", "render_tiles", "tile_lists"]

# per tuning profile: tile side in pixels (TS), pending-hit buffer (KP),
# pixels per work-item of the render ("lanes": 8, tile_render8's float8 rows,
# or 1, tile_render), work-items per group of the render (a divisor of
# TS * TS / lanes), of the one-item-per-Gaussian kernels, keys per band at
# most ("tile_keys"), rays per band at most when the image is read back
# ("tile_rays", as the BVH path). CPUs (PoCL, 10^5 Gaussians at 512^2):
# groups of one work-item spread over the cores (groups of 4 ran on one);
# 8-pixel tiles: the same CPU time as 16 on the bench scene (fewer candidates
# against 2.3x the keys), half of it on NARVis's 2 M needle-like Gaussians
# (1270 candidates a pixel against 3410).
# The splatting model renders with splat_render8 (rows of 8 pixels, render_wg)
# where lanes is 8, else splat_render ("splat_wg" pixels a group); with 8 lanes
# it bins with splat_count8 / splat_keys8 (8 Gaussians a work-item, float8),
# else splat_count / splat_keys (one a work-item); the same keys either way.
# The hit models' tile_keys bounds 8 tiles of a Gaussian at once in float8
# lanes (KEYS8) where lanes is 8 (PoCL: 0.56x its CPU time), but not on
# Intel's CPU runtime, which vectorises the one-tile form across work-items
# itself (KEYS8 took ~1.5x there: 0.034 against 0.022 s, on a 0.37 s render);
# the same keys either way.
PROFILES = {
    "cpu": {
        "ts": 8,
        "kp": 64,
        "lanes": 8,
        "render_wg": 1,
        "splat_wg": 16,
        "item_wg": 64,
        "tile_keys": 1 << 24,
        "tile_rays": 1 << 18,
    },
    "gpu": {
        "ts": 16,
        "kp": 32,
        "lanes": 1,
        "render_wg": 256,
        "splat_wg": 256,
        "item_wg": 256,
        "tile_keys": 1 << 25,
        "tile_rays": 1 << 22,
    },
}
KEY_BYTES = 24  # key 8 + id 4, and the radix sort's copies of both
GATHER_BYTES = GAUSSIAN_DTYPE.itemsize  # the gathered record a key (the hit models, not splat)
RAY_BYTES = 28


def projection_rows(camera: Camera, width: int, height: int) -> np.ndarray:
    """16 float32: the pixel-homogeneous projection rows Pu, Pv, Pw
    ((u w, v w, w) = P (x, y, z, 1), u, v continuous pixel coordinates, row 0
    on top) and the depth row D, as tiles.cl reads them."""
    m = np.asarray(camera.matrix, np.float64)
    pu = 0.5 * width * (m[0] + m[3])
    pv = 0.5 * height * (m[3] - m[1])
    return np.concatenate([pu, pv, m[3], np.asarray(camera.depth_row, np.float64)]).astype(np.float32)


def _kernels(q, r) -> dict:
    prof = PROFILES[r.config.tuning]
    if r.model == "splat":
        sd = {"TS": prof["ts"], "COLOR": int(r.colors)}
        ks = {
            name: runtime.get_kernel(q, "gauss/splat.cl", name, sd, runtime.EXACT_FP)
            for name in (
                "splat_count",
                "splat_keys",
                "splat_count8",
                "splat_keys8",
                "splat_render",
                "splat_render8",
            )
        }
        ks["tile_ranges"] = runtime.get_kernel(
            q, "gauss/tiles.cl", "tile_ranges", {"TS": prof["ts"]}, runtime.EXACT_FP
        )
        return ks
    lanes = prof["lanes"] if r.lanes is None else r.lanes
    defines = {
        "TS": prof["ts"],
        "KP": r.kp,
        "MODEL": {"max_response": 0, "absorption": 1}[r.model],
        "COLOR": int(r.colors),
        # tile_keys' bounds in float8 lanes with the 8-lane render, except on Intel's
        # CPU runtime (it vectorises the one-tile form across work-items: 1.5x faster there)
        "KEYS8": int(lanes == 8 and "intel" not in runtime.capabilities(q).platform.lower()),
    }
    return {
        name: runtime.get_kernel(q, "gauss/tiles.cl", name, defines, runtime.EXACT_FP)
        for name in ("tile_count", "tile_keys", "tile_ranges", "tile_render", "tile_render8")
    }


def render_tiles(
    r: Any,
    camera: Camera,
    w: int,
    h: int,
    tf: TransferFunction,
    *,
    host: bool,
    max_keys: int | None,
    progress: Callable[[int, int], None] | None,
    keep: list | None = None,
) -> tuple[Any, Any, Any, dict]:
    """rgba, depth, ray stats (host arrays, or device arrays of the whole
    image when host=False) and the stats dict, for GaussianRenderer `r`.
    keep: a list to append each band's (first tile row, end tile row, sorted
    keys, ids, ranges) to, as host arrays (tests, :func:`tile_lists`)."""
    q = r.queue
    prof = PROFILES[r.config.tuning]
    ts = prof["ts"]
    ks = _kernels(q, r)
    n = r.n
    tiles_x, tiles_y = -(-w // ts), -(-h // ts)
    budget = prof["tile_keys"] if max_keys is None else max_keys
    # a quarter of the device's memory at most for a band's keys
    key_bytes = KEY_BYTES + (0 if r.model == "splat" else GATHER_BYTES)
    budget = max(1, min(budget, runtime.capabilities(q).global_mem_bytes // (4 * key_bytes)))
    rows_cap = tiles_y if not host else max(1, min(tiles_y, prof["tile_rays"] // (w * ts)))
    cam = ray_buffer(camera, w, h)
    proj = projection_rows(camera, w, h)
    near = np.float32(camera.near - 1e-4 * (abs(camera.near) + 1e-3))
    tmin, tscale = tf.limits(r.gaussians.values)
    table = tf.table()
    what = f"Gaussian image {w}x{h}"
    out_rows = h if not host else min(h, rows_cap * ts)
    runtime.check_memory(
        q,
        what,
        device_bytes=w * out_rows * RAY_BYTES,
        host_bytes=w * h * RAY_BYTES if host else 0,
    )
    start = runtime.marker(q)
    camd = runtime.empty(q, cam.size, np.float32, "camera rays")
    camd.set(cam, queue=q, async_=True)
    projd = runtime.empty(q, proj.size, np.float32, "camera projection")
    projd.set(proj, queue=q, async_=True)
    tfd = runtime.empty(q, table.shape, np.float32, "transfer function")
    tfd.set(table, queue=q, async_=True)
    rgba = runtime.empty(q, (out_rows, w, 4), np.float32, "rgba")
    depth = runtime.empty(q, (out_rows, w), np.float32, "depth")
    stats = runtime.empty(q, (out_rows, w, 2), np.uint32, "ray stats")
    recs = r.records.base_data
    colors = recs if r._colors is None else r._colors.base_data
    counts = runtime.empty(q, max(n, 1), np.uint64, "tile counts per Gaussian")
    g_items = runtime.items(q, n, prof["item_wg"])
    splat = r.model == "splat"
    lanes = prof["lanes"] if r.lanes is None else r.lanes
    if splat:
        render = ks["splat_render8" if lanes == 8 else "splat_render"]
        group = prof["render_wg" if lanes == 8 else "splat_wg"]
    else:
        render = ks["tile_render8" if lanes == 8 else "tile_render"]
        group = prof["render_wg"]
    # a divisor of a tile's work-items (a profile's 8-lane form under the other's group size)
    wg = runtime.local_size(q, math.gcd(group, ts * ts // lanes))
    head: tuple[Any, ...]  # the count and keys kernels' leading arguments
    if splat:
        head = (recs, np.uint32(n), projd.base_data, near, np.uint32(w), np.uint32(h))
        splats = runtime.empty(q, (max(n, 1), 8), np.float32, "2D splats")
        # with 8 lanes the binning kernels take 8 Gaussians a work-item (float8)
        count_k, keys_k = (
            ks["splat_count8" if lanes == 8 else "splat_count"],
            ks["splat_keys8" if lanes == 8 else "splat_keys"],
        )
        if lanes == 8:
            g_items = runtime.items(q, -(-n // 8), prof["item_wg"])
    else:
        head = (recs, np.uint32(n), projd.base_data, near, np.float32(r.cutoff), np.uint32(w), np.uint32(h))
        count_k, keys_k = ks["tile_count"], ks["tile_keys"]
    if host:
        out_rgba = np.empty((h, w, 4), np.float32)
        out_depth = np.empty((h, w), np.float32)
        out_stats = np.empty((h, w, 2), np.uint32)
    bands = [(0, tiles_y)]  # split while a band's keys exceed the budget
    events: list[tuple[cl.Event, cl.Event, cl.Event, cl.Event]] = []
    total_keys = 0
    cand = 0  # sum over pixels of their tile's list length
    done_bands = 0
    render_bands = 0
    while bands:
        a, b = bands.pop(0)
        e0 = runtime.marker(q)
        if n:
            runtime.launch(
                q,
                count_k,
                *g_items,
                *head,
                np.uint32(a),
                np.uint32(b),
                *((splats.base_data,) if splat else ()),
                counts.base_data,
            )
            offsets, total_d = primitives.scan(counts[:n], return_total=True, queue=q)
            m = int(total_d.get()[0])
        else:
            offsets, m = None, 0
        if m > budget and b - a > 1:
            mid = (a + b) // 2
            bands[0:0] = [(a, mid), (mid, b)]
            continue
        if m >= 2**32:
            raise DeviceError(
                f"{what}: one row of {ts}-pixel tiles needs {m} keys; at most 2^32 - 1 (fewer "
                "or smaller Gaussians, or a smaller image)"
            )
        band_tiles = (b - a) * tiles_x
        ranges = runtime.zeros(q, (band_tiles, 2), np.uint32, "tile ranges")
        keys = ids = keyrecs = None
        e1 = e2 = e0
        if m:
            runtime.check_memory(q, f"{what}: {m} tile keys", device_bytes=m * key_bytes)
            keys = runtime.empty(q, m, np.uint64, "tile keys")
            ids = runtime.empty(q, m, np.uint32, "tile key ids")
            extra = (splats.base_data, offsets.base_data) if splat else (offsets.base_data, camd.base_data)
            runtime.launch(
                q,
                keys_k,
                *g_items,
                *head,
                np.uint32(a),
                np.uint32(b),
                *extra,
                keys.base_data,
                ids.base_data,
            )
            e1 = runtime.marker(q)
            tile_bits = max(1, int(band_tiles - 1).bit_length())
            keys, ids = primitives.radix_sort(keys, ids, key_bits=32 + tile_bits, queue=q)
            e2 = runtime.marker(q)
            runtime.launch(
                q,
                ks["tile_ranges"],
                *runtime.items(q, m, 256),
                keys.base_data,
                np.uint32(m),
                ranges.base_data,
            )
            if not splat:  # the keys' records in key order
                keyrecs = gather_records(q, r.records, ids, m)
        y0 = a * ts
        n_rows = min(b * ts, h) - y0
        lists = (
            (keys if keys is not None else counts).base_data,
            (ids if ids is not None else counts).base_data,
            ranges.base_data,
        )
        tf_args = (tfd.base_data, np.uint32(table.shape[0]), tmin, tscale)
        order = r.order.base_data
        # the band's tiles, rendered (and read back) rows_cap tile rows at a time
        for c in range(a, b, rows_cap):
            d = min(c + rows_cap, b)
            out_y0 = c * ts if host else 0
            band_args = (
                np.uint32(w),
                np.uint32(h),
                np.uint32(a),
                np.uint32((c - a) * tiles_x),
                np.uint32(n_rows),
                np.uint32(out_y0),
            )
            args: tuple[Any, ...]
            if splat:
                args = (recs, order, splats.base_data, *lists, *band_args, *tf_args, colors)
            else:
                model_args = (np.float32(r.cutoff * r.cutoff), np.float32(r.density))
                krecs = keyrecs.base_data if keyrecs is not None else recs
                args = (krecs, order, *lists, camd.base_data, *band_args, *tf_args, *model_args, colors)
            render_bands += 1
            e3 = runtime.launch(
                q,
                render,
                (d - c) * tiles_x * ts * ts // lanes,
                wg,
                *args,
                rgba.base_data,
                depth.base_data,
                stats.base_data,
            )
            if host:
                r0, r1 = c * ts, min(d * ts, h)
                for dst, src in ((out_rgba, rgba), (out_depth, depth), (out_stats, stats)):
                    cl.enqueue_copy(q, dst[r0:r1], buffer_of(src), wait_for=[e3])
                if progress is not None:
                    progress(w * r1, w * h)
        events.append((e0 if done_bands else start, e1, e2, e3))
        total_keys += m
        if keep is not None:
            keep.append(
                (
                    a,
                    b,
                    keys.get() if keys is not None else np.zeros(0, np.uint64),
                    ids.get() if ids is not None else np.zeros(0, np.uint32),
                    ranges.get(),
                )
            )
        if host:
            rng = ranges.get().astype(np.int64)
            lens = (rng[:, 1] - rng[:, 0]).reshape(b - a, tiles_x)
            px_w = np.minimum(ts, w - np.arange(tiles_x) * ts)
            px_h = np.minimum(ts, h - (a + np.arange(b - a)) * ts)
            cand += int((lens * px_h[:, None] * px_w[None, :]).sum())
        done_bands += 1
    info: dict = {
        "method": "tiles",
        "tile": ts,
        "kp": r.kp,
        "lanes": lanes,
        "keys": total_keys,
        "keys_per_gaussian": total_keys / max(n, 1),
        "bands": render_bands,  # render launches (read back one by one when host=True)
        "key_bands": done_bands,  # bands of tile rows binned and sorted apart
    }
    if not host:
        info["events"] = (start, events[-1][3])
        return rgba, depth, stats, info
    bin_s = sort_s = render_s = 0.0
    for e0, e1, e2, e3 in events:
        bin_s += runtime.seconds(e0, e1) or 0.0
        if e1 is not e2:
            sort_s += runtime.seconds(e1, e2) or 0.0
        render_s += runtime.seconds(e2, e3) or 0.0
    info.update(
        {
            "bin_s": bin_s,
            "sort_s": sort_s,
            "tile_render_s": render_s,
            "render_s": runtime.seconds(start, events[-1][3]),
            "candidates_per_pixel": cand / (w * h),
        }
    )
    return out_rgba, out_depth, out_stats, info


def tile_lists(r: Any, camera: Camera, width: int, height: int, *, max_keys: int | None = None) -> list:
    """The bins of one frame of GaussianRenderer `r` (method="tiles"): per
    band, (first tile row, end tile row, keys, ids, ranges) as host arrays,
    keys sorted (tile within the band << 32 | clvis_key_f32(depth bound)),
    ids the Gaussians' ids (the kernels hold record positions, mapped here
    through the renderer's order), ranges (tiles, 2) each tile's [first, end)
    keys."""
    if r.method != "tiles":
        raise ValueError(f"tile_lists: the renderer's method is {r.method!r}, not 'tiles'")
    keep: list = []
    with runtime.pinned(r.config):
        render_tiles(
            r,
            camera,
            width,
            height,
            r.transfer_function,
            host=True,
            max_keys=max_keys,
            progress=None,
            keep=keep,
        )
    order = r.order.get()  # record positions -> Gaussian ids
    return [(a, b, keys, order[ids], ranges) for a, b, keys, ids, ranges in keep]
