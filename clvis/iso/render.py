"""iso family: progressive isosurface raycasting over ZFP-compressed volumes
(Dyken, Usher, Kumar, TVCG 2024).

A pass, for the rays still active (kernels_cl/iso/):

1. macrocell traversal (traverse.cl): each ray walks the coarse grid, then
   the fine grid (the ZFP blocks) inside active coarse cells, and records up
   to n_spec candidate blocks whose range holds the isovalue (speculation:
   n_spec = min(floor(W H s / active rays), 64), s the starting count, at
   least 2 in the first pass, on the gpu profile, the paper's; the cpu
   profile halves the budget, floor(W H s / (2 active rays)), and takes 3 in
   the first pass: see PROFILES; 1 without speculation);
2. grouping: the (ray, candidate) items are compacted and sorted by block
   (clvis.compact_indices, clvis.radix_sort), the blocks in a front-to-back
   order for the frame's rays (pass.cl's View order, :func:`view_flips`);
3. the LRU block cache (clvis.iso.cache) decodes the blocks the pass needs
   (the candidates and their +x/+y/+z neighbours) that it does not hold;
4. block raytracing (raytrace.cl, ITEMS mode): a work-group per block with
   its 5^3 dual brick in local memory, the first root of each cell's cubic;
   with 64-bit atomics an item behind its ray's nearest hit so far stops
   (it could not win; the front-to-back order makes these the common case);
5. resolve (pass.cl): each ray keeps its nearest hit over its candidates,
   by a 64-bit atomic min of (t bits << 32 | item) where the device has
   64-bit atomics, else by scanning its candidates in order (same result);
   rays without a hit go on from where the traversal left them: at the
   entry of their next candidate block, which the traversal walked on to
   find; a ray with no candidate block left cannot hit, so it is finished
   (no hit) in the pass that traced its last candidate, not one pass later
   (at a given completion fewer of the rays still running are such sure
   misses; to 95 % without speculation, 2 passes fewer over 6 frames).

Tiles. Each ray is independent of the others, so the image is traced in
tiles: ranges of `tile_pixels` pixels in row-major order (bands of whole rows
by default), one after the other, each running the pass loop to its end over
the renderer's shared compressed volume, macrocell grids and block cache. A
tile holds the state of its own rays only (ray t, hit outputs, 64-bit hit
keys, the active list, and each pass's items: rays x n_spec candidates and
their sort keys), so device memory is bounded by the tile, not the image:
at most PIXEL_BYTES + ITEM_BYTES * max(start_speculation, 2) bytes per tile
pixel (one item per pixel without speculation), TILE_BYTES (256 MiB) per tile
by default. Kernels compute each ray from its image pixel (the tile's first
pixel p0 is a kernel argument), so a tiled image is the untiled one: the same
hits, t, depths and colours, bit for bit. n_spec is a tile's own (its pixels
and its active rays); the candidates do not depend on how they are split into
passes, so that changes the passes, not the image. The host image (rgba,
depth, hit, t, active, candidates, next_t: HOST_PIXEL_BYTES per pixel) is allocated once and
each tile is read back into it when it is done (host=False: the same planes
on the device, each tile written into them by pass.cl's tile_image and
mark_active, nothing read back but the pass loop's counts);
runtime.check_memory checks both figures before anything is allocated. width x height must stay below
2^31 (MAX_PIXELS): the kernels index pixels with 32-bit integers.

Completion is per tile: a tile stops once `completion` of its rays entering
the volume are finished, so the whole image reaches at least `completion`
(IsoImage.completion is the global fraction: finished rays over all rays
entering the volume) and no part of it is left behind. Where a render stops
early, a finished ray's pixel is that of the complete render; a ray still
running shows no hit. With one tile (an image within the budget) this is the
untiled pass loop.

``passes()`` yields after every pass of every tile (tiles not started yet
show no hits, their entering rays active). ``progress``, when given, is called
after each pass with {"tile", "tiles", "passes", "rays_done", "rays_total"}.

An IsoRenderer captures the runtime options (tuning profile, 64-bit atomics)
and its kernels when it is made; every pass runs under them (runtime.pinned),
whatever runtime.configure does meanwhile, in this thread or another.
``stats["seconds"]`` is device time from event profiling, from the start of
the render to the end of the pass.

The rules (rays, dual grid, root finding, shading) are clvis.reference.iso's.
"""

from __future__ import annotations

import numbers
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import limits, runtime
from .._arrays import positive_int, resolve_queue, to_host, triple
from ..camera import Camera, check_aspect, ray_buffer
from ..errors import DataError
from ..images import Picture, float_rgba8
from ..io.volumes import volume_parts
from ..primitives import compact, compact_indices, radix_sort
from .cache import BlockCache, mark_blocks
from .cache import _kernel as _cache_kernel
from .macrocell import macrocell_grids, range_bits
from .raytrace import raytrace_blocks, raytrace_kernel
from .traverse import init_rays, macro_traverse, traverse_kernel
from .zfp import ZfpVolume, compress

__all__ = [
    "CANDIDATES",
    "HOST_PIXEL_BYTES",
    "ITEM_BYTES",
    "MAX_PIXELS",
    "PIXEL_BYTES",
    "PROFILES",
    "TILE_BYTES",
    "IsoImage",
    "IsoRenderer",
]

MAX_SPEC = 64
# width x height stays below this: the kernels index pixels (and pass items
# within a tile) with 32-bit integers (clvis.limits.ISO)
MAX_PIXELS = limits.ISO.max_pixels + 1
# IsoImage.candidates counts the candidate blocks left on a running ray up to
# this many (a macro_traverse with n_spec = CANDIDATES from its resume t)
CANDIDATES = 8
# device bytes per tile pixel: ray t, enters flag, active id (and its
# compacted copy), still flag, hit, hit t, depth, rgba, 64-bit hit key; and
# the candidates step after a pass (_Tile.candidates): counts and next t (the
# host path's) and the copy of ray t. Its CANDIDATES blocks and t's a running
# ray reuse the pool's memory the pass's items went back to (at least one
# item a pixel, ITEM_BYTES = 71, against 8 * CANDIDATES = 64 bytes a ray)
PIXEL_BYTES = 4 + 1 + 4 + 4 + 1 + 1 + 4 + 4 + 16 + 8 + (1 + 4 + 4)
# device bytes per pass item: candidate block and t, valid flag, item id, item
# hit / t / rgba / depth, sort key, sorted key and item, group head, group
# start, and the radix sort's and compaction's working copies
ITEM_BYTES = 4 + 4 + 1 + 4 + 1 + 4 + 16 + 4 + 4 + 4 + 4 + 1 + 4 + 16
# the default device budget of one tile's rays and pass items
TILE_BYTES = 256 * 2**20
# host bytes per image pixel: rgba, depth, hit, t, active, candidates, next_t
HOST_PIXEL_BYTES = 16 + 4 + 1 + 4 + 1 + 1 + 4
_PASS = "iso/pass.cl"
_PASS_KERNELS = (
    "valid_items",
    "item_keys",
    "group_heads",
    "group_info",
    "resolve_hits",
    "tile_image",
    "mark_active",
    "mark_candidates",
)
# wg: the local size of pass.cl's one-item-per-element kernels (a fixed one:
# PoCL would compile a work-group function for every size the driver chose).
# The speculation schedule (see _n_spec): spec_div divides the pass's item
# budget (the tile's pixels x start_speculation), spec_first is the first
# pass's candidates per ray. gpu: the paper's (fill the device: n_spec = W H s /
# active rays, two in the first pass); cpu: half the items a pass after the
# first, three in the first: fewer items for the same three passes at 256^3,
# 512x512 (bench/results/iso-cpu.md, 2026-11-28 session 4). Only the passes
# change with it, not the image.
PROFILES = {
    "cpu": {"wg": 64, "spec_div": 2, "spec_first": 3},
    "gpu": {"wg": 64, "spec_div": 1, "spec_first": 2},
}


def _real(name: str, v: Any) -> float:
    """v as a float: a real number (not a bool, not a string: float("0.5")
    would take one)."""
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
        raise TypeError(f"{name}: expected a real number, got {type(v).__name__}")
    return float(v)


@dataclass(repr=False)
class IsoImage(Picture):
    """The image after a pass: ``rgba`` (H, W, 4) float32 (shaded surface,
    alpha 1 at hits), ``depth`` (H, W) view depth (+inf where no hit yet),
    ``hit`` (H, W) bool, ``t`` (H, W) the hit's ray parameter (world distance
    from the ray's origin on the near plane; +inf elsewhere), ``active``
    (H, W) bool (rays still running),
    ``completion`` (the fraction of the rays entering the volume that are
    finished), ``stats`` and ``candidates`` (H, W) uint8: per running ray the
    candidate blocks (range holds the isovalue) left on it from where it
    resumes, counted up to CANDIDATES (8: 8 or more; >= 1, since a ray with
    none left is finished at once), 0 elsewhere and, in ``passes()``, at the
    rays of tiles not traced yet; None for an image not from the renderer.
    ``next_t`` (H, W) float32: per running ray the ray parameter t where its
    next candidate block begins (the first of those ``candidates`` counts;
    the finished hits' ``t`` is on the same scale), +inf elsewhere and where
    ``candidates`` is 0; None for an image not from the renderer.
    ``camera``: the :class:`clvis.Camera` the image was rendered with (its
    rays give ``t`` its meaning: :func:`clvis.iso.sample_hits` uses it); None
    for an image made by hand.
    From ``render(..., host=False)`` the seven planes are
    ``pyopencl.array.Array`` of the same shapes and dtypes.
    ``to_uint8(background=None)`` and ``save_png(path)``: the shaded surface
    as a picture, as for every image type (:class:`clvis.images.Picture`)."""

    rgba: np.ndarray | cla.Array
    depth: np.ndarray | cla.Array
    hit: np.ndarray | cla.Array
    t: np.ndarray | cla.Array
    active: np.ndarray | cla.Array
    completion: float
    stats: dict[str, Any]
    candidates: np.ndarray | cla.Array | None = None
    next_t: np.ndarray | cla.Array | None = None
    camera: Camera | None = None

    def to_uint8(self, background: Sequence[int] | None = None) -> np.ndarray:
        """(H, W, 4) uint8 RGBA: the shaded surface where a ray hit it, transparent
        elsewhere, or over the RGB `background` (0..255 each)."""
        rgba = np.array(to_host(self.rgba), np.float32)
        hit = to_host(self.hit).astype(bool, copy=False)
        rgba[..., 3] = hit
        return float_rgba8(rgba, background, premultiplied=False)


class _HostImage:
    """The image on the host, flat per pixel; tiles are read back into it."""

    def __init__(self, npix: int) -> None:
        self.rgba = np.zeros((npix, 4), np.float32)
        self.depth = np.full(npix, np.inf, np.float32)
        self.hit = np.zeros(npix, np.uint8)
        self.t = np.full(npix, np.inf, np.float32)
        self.active = np.zeros(npix, bool)
        self.candidates = np.zeros(npix, np.uint8)
        self.next_t = np.full(npix, np.inf, np.float32)

    def image(self, w: int, h: int, copy: bool) -> IsoImage:
        c = np.copy if copy else (lambda a: a)
        return IsoImage(
            c(self.rgba).reshape(h, w, 4),
            c(self.depth).reshape(h, w),
            c(self.hit).view(bool).reshape(h, w),
            c(self.t).reshape(h, w),
            c(self.active).reshape(h, w),
            1.0,
            {},
            c(self.candidates).reshape(h, w),
            c(self.next_t).reshape(h, w),
        )

    def mark_active(self, p0: int, ids: Any, count: int) -> None:
        """Mark pixels p0 + ids[:count] (a device list) as running."""
        if count:
            self.active[p0 + ids[:count].get().astype(np.int64)] = True

    def write_tile(self, tile: _Tile, active: Any) -> None:
        """The tile's part of the image, `active` its rays still running (blocks)."""
        q, sl = tile.q, slice(tile.p0, tile.p0 + tile.n)
        # three reads enqueued without waiting, the fourth blocks: one wait, not four
        events = [
            a.get_async(queue=q, ary=b)[1]
            for a, b in ((tile.rgba, self.rgba[sl]), (tile.depth, self.depth[sl]), (tile.hit, self.hit[sl]))
        ]
        tile.hit_t.get(queue=q, ary=self.t[sl])
        cl.wait_for_events(events)
        self.active[sl] = False
        self.mark_active(tile.p0, active, int(active.size))
        left = tile.candidates(active)
        if left is None:
            self.candidates[sl] = 0
            self.next_t[sl] = np.inf
        else:
            cand, next_t = left
            ev = cand.get_async(queue=q, ary=self.candidates[sl])[1]
            next_t.get(queue=q, ary=self.next_t[sl])
            ev.wait()


class _DeviceImage:
    """The image on the device (render(host=False)): whole-image planes the
    tiles are written into by pass.cl's tile_image and mark_active; nothing
    is read back."""

    def __init__(self, renderer: IsoRenderer, npix: int) -> None:
        q = self.q = renderer.queue
        self.launch = renderer._launch
        self.rgba = runtime.zeros(q, (npix, 4), np.float32, "iso image rgba")
        self.depth = runtime.empty(q, npix, np.float32, "iso image depth")
        self.hit = runtime.zeros(q, npix, np.uint8, "iso image hit mask")
        self.t = runtime.empty(q, npix, np.float32, "iso image t")
        self.active = runtime.zeros(q, npix, np.uint8, "iso image active mask")
        self.candidates = runtime.zeros(q, npix, np.uint8, "iso image candidates left")
        self.next_t = runtime.empty(q, npix, np.float32, "iso image next candidate t")
        for a in (self.depth, self.t, self.next_t):
            runtime.fill(q, a, np.float32(np.inf))

    def image(self, w: int, h: int, copy: bool) -> IsoImage:
        def c(a: Any) -> Any:
            return a.copy(queue=self.q) if copy else a

        return IsoImage(
            c(self.rgba).reshape(h, w, 4),
            c(self.depth).reshape(h, w),
            c(self.hit).view(np.bool_).reshape(h, w),
            c(self.t).reshape(h, w),
            c(self.active).view(np.bool_).reshape(h, w),
            1.0,
            {},
            c(self.candidates).reshape(h, w),
            c(self.next_t).reshape(h, w),
        )

    def mark_active(self, p0: int, ids: Any, count: int) -> None:
        if count:
            self.launch(
                "mark_active", count, np.uint32(p0), ids.base_data, np.uint32(count), self.active.base_data
            )

    def write_tile(self, tile: _Tile, active: Any) -> None:
        u32 = np.uint32
        self.launch(
            "tile_image",
            tile.n,
            u32(tile.p0),
            u32(tile.n),
            tile.hit.base_data,
            tile.hit_t.base_data,
            tile.rgba.base_data,
            tile.depth.base_data,
            self.hit.base_data,
            self.t.base_data,
            self.rgba.base_data,
            self.depth.base_data,
            self.active.base_data,
        )
        self.mark_active(tile.p0, active, int(active.size))
        sl = slice(tile.p0, tile.p0 + tile.n)
        runtime.fill(self.q, self.candidates[sl], np.uint8(0))
        runtime.fill(self.q, self.next_t[sl], np.float32(np.inf))
        tile.candidates(active, (self.candidates, self.next_t), tile.p0)


def view_flips(
    camera: Camera, shape: Sequence[int], spacing: Sequence[float], origin: Sequence[float]
) -> int:
    """The `flip` of pass.cl's view order (its View order): bit a set where the
    rays run towards lower indices along axis a (x, y, z) -- for a pinhole
    camera outside the volume's slab along a, the side of the eye (every ray
    that meets the box runs the same way); else the sign of the view
    direction. Only the order of the work changes with it, not the image."""
    n = np.array(shape[::-1], np.float64)  # nx, ny, nz
    lo = np.asarray(origin, np.float64)
    hi = lo + (n - 1) * np.asarray(spacing, np.float64)[::-1]
    flip = 0
    for a in range(3):
        if not camera.orthographic and camera.eye[a] > hi[a]:
            down = True
        elif not camera.orthographic and camera.eye[a] < lo[a]:
            down = False
        else:
            down = bool(camera.forward[a] < 0)
        flip |= int(down) << a
    return flip


class _Tile:
    """The device state of one tile's rays: pixels p0 .. p0 + n - 1."""

    def __init__(
        self, q, p0, n, cam, w, h, shape, spacing, origin, int64, rays=None, flip=0, n_rays=None
    ) -> None:
        """`rays`: init_rays' (ray_t, ids, count) of this tile when the caller has them
        (`n_rays`: count[0] when the caller has read it); `flip`: the view order of
        the pass's groups (pass.cl). `count` (a 1-element device array) holds the
        length of `active` for the pass's kernels, so no pass writes it."""
        self.q, self.p0, self.n, self.cam, self.w = q, p0, n, cam, w
        self.volume = (shape, spacing, origin)
        #: (isovalue, (fine, coarse) range bits): set by the pass loop; candidates() walks with them
        self.walk: tuple[float, tuple[cla.Array, cla.Array]] | None = None
        nb = [(int(s) + 3) // 4 for s in shape[::-1]]
        self.order = (np.uint32(nb[0]), np.uint32(nb[1]), np.uint32(nb[2]), np.uint32(flip))
        # the items' sort keys are view-ordered block ids (pass.cl's view_key):
        # below nb0 * nb1 * nb2, so the sort needs only that many bits' passes
        self.key_bits = (nb[0] * nb[1] * nb[2] - 1).bit_length()
        if rays is None:
            rays = init_rays(q, cam, w, h, shape, spacing, origin, pixels=(p0, n))
        self.ray_t, active_all, count = rays
        self.active = active_all[: int(count.get()[0]) if n_rays is None else n_rays]
        self.count = count
        self.hit = runtime.zeros(q, n, np.uint8, "hit mask")
        self.hit_t = runtime.empty(q, n, np.float32, "hit t")
        self.depth = runtime.empty(q, n, np.float32, "depth")
        for a in (self.hit_t, self.depth):
            runtime.fill(q, a, np.float32(np.inf))
        self.rgba = runtime.zeros(q, (n, 4), np.float32, "rgba")
        self.hitkey = runtime.empty(q, n, np.uint64, "hit keys") if int64 else None
        self.nbytes = runtime.nbytes(
            self.ray_t, active_all, count, self.hit, self.hit_t, self.depth, self.rgba, self.hitkey
        )

    def read(self, out: _HostImage | _DeviceImage, active=None) -> None:
        """Write the tile's part of the image (rays still running: `active`,
        default the tile's own list) into `out` (a host image: blocks until
        it is there; a device image: two launches)."""
        out.write_tile(self, self.active if active is None else active)

    def candidates(
        self, active: Any, img: tuple[cla.Array, cla.Array] | None = None, p0: int = 0
    ) -> tuple[cla.Array, cla.Array] | None:
        """The candidate blocks left on each running ray (`active`: the
        tile's list, its count in self.count), counted up to CANDIDATES, and
        the first one's t: a macro_traverse with n_spec = CANDIDATES from a
        copy of the rays' resume t (the tile's own rays do not move), then
        pass.cl's mark_candidates into `img` = (uint8 counts, float32 t's) at
        p0 + id (default: a zeroed and an +inf array of the tile's pixels,
        returned). None when no ray is running and no `img` is given."""
        n = int(active.size)
        if n == 0 or self.walk is None:
            return img
        q = self.q
        iso, (fine, coarse) = self.walk
        if img is None:
            img = (
                runtime.zeros(q, self.n, np.uint8, "candidates left"),
                runtime.empty(q, self.n, np.float32, "next candidate t"),
            )
            runtime.fill(q, img[1], np.float32(np.inf))
        cand_block = runtime.empty(q, n * CANDIDATES, np.uint32, "candidates left: blocks")
        cand_t = runtime.empty(q, n * CANDIDATES, np.float32, "candidates left: t")
        ray_t = self.ray_t.copy(queue=q)
        macro_traverse(
            q,
            *self.volume,
            iso,
            self.cam,
            self.w,
            fine,
            coarse,
            active,
            self.count,
            n,
            ray_t,
            CANDIDATES,
            cand_block,
            cand_t,
            first_pixel=self.p0,
        )
        k = runtime.get_kernel(q, _PASS, "mark_candidates", {})
        runtime.launch(
            q,
            k,
            *runtime.items(q, n, PROFILES[runtime.tuning_profile(q)]["wg"]),
            np.uint32(p0),
            active.base_data,
            np.uint32(n),
            np.uint32(CANDIDATES),
            cand_block.base_data,
            cand_t.base_data,
            img[0].base_data,
            img[1].base_data,
        )
        return img


class IsoRenderer:
    """A ZFP-compressed volume on the device with its macrocell grids and a
    block cache, for progressive isosurface renders.

    Parameters
    ----------
    volume_or_zfp : a 3-D [z, y, x] array (compressed with `rate` through
        clvis.zfp.compress), a clvis.Volume (clvis.read_volume's: its data,
        spacing and origin) or a clvis.zfp.ZfpVolume.
    rate : ZFP fixed rate in bits per value (1..32).
    spacing : (dz, dy, dx); origin : world (x, y, z) of sample [0, 0, 0];
        None: a Volume's own, else (1, 1, 1) and (0, 0, 0).
    cache_capacity : initial block-cache slots (default: BlockCache's); the
        cache grows when a pass needs more.

    ``config`` holds the runtime options captured at construction
    (runtime.capture); a configure() change applies to renderers made after it.
    """

    def __repr__(self) -> str:
        return (
            f"IsoRenderer(shape={tuple(self.volume.shape)}, rate={self.volume.rate}, "
            f"spacing={self.spacing}, origin={self.origin}, device={self.queue.device.name.strip()!r})"
        )

    def __init__(
        self,
        volume_or_zfp: ZfpVolume | Any,
        rate: int = 8,
        spacing: Sequence[float] | None = None,
        origin: Sequence[float] | None = None,
        *,
        cache_capacity: int | None = None,
        queue: cl.CommandQueue | None = None,
    ) -> None:
        self.queue = q = resolve_queue(queue)
        self.config = runtime.capture(q)
        volume_or_zfp, spacing, origin = volume_parts(volume_or_zfp, spacing, origin)
        zv = volume_or_zfp if isinstance(volume_or_zfp, ZfpVolume) else compress(volume_or_zfp, rate)
        if min(zv.shape) < 2:
            raise DataError(f"volume: every axis needs at least 2 samples, got shape {zv.shape}")
        self.volume = zv
        self.spacing = triple("spacing", spacing, positive=True)
        self.origin = triple("origin", origin, positive=False)
        with runtime.pinned(self.config):
            t0 = time.perf_counter()
            self._kernels = {name: runtime.get_kernel(q, _PASS, name, {}) for name in _PASS_KERNELS}
            self._build_kernels()
            self.build_seconds = time.perf_counter() - t0
            profile = PROFILES[self.config.tuning]
            self._wg = profile["wg"]
            self._spec = (profile["spec_div"], profile["spec_first"])
            self.grids = macrocell_grids(zv, queue=q, host=False)
            self.cache = BlockCache(zv, cache_capacity, queue=q)

    def _build_kernels(self) -> None:
        """Build (or fetch from the program cache) every kernel a pass runs,
        so that the first render's time is the passes' (build_seconds says
        how long this took): the iso kernels by name, the primitives (the
        compactions and the sort, whose builds depend only on the dtypes and
        the work shape) by running them on two elements."""
        q = self.queue
        for name in ("init_rays", "macro_traverse"):
            traverse_kernel(q, name)
        raytrace_kernel(q, 8, True)
        for name in ("mark_blocks", "cache_slot_flags", "cache_missing"):
            _cache_kernel(q, name)
        for name in ("cache_candidate_keys", "cache_assign", "cache_decode"):
            _cache_kernel(q, name)
        flags = runtime.zeros(q, 2, np.uint8, "warm-up flags")
        ids = runtime.zeros(q, 2, np.uint32, "warm-up ids")
        compact_indices(flags, queue=q)
        compact(ids, flags, queue=q)
        radix_sort(ids, ids, queue=q)
        q.finish()

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.volume.shape

    def reset_cache(self, capacity: int | None = None) -> None:
        """Start over with an empty block cache (a cold start, e.g. for timings).
        The compressed volume stays on the device (the new cache decodes from
        the same stream: a cold cache, not a new upload)."""
        with runtime.pinned(self.config):
            self.cache = BlockCache(self.volume, capacity, queue=self.queue, stream=self.cache.stream)

    def render(
        self,
        camera: Camera,
        width: int,
        height: int,
        isovalue: float,
        *,
        completion: float = 1.0,
        speculation: bool = True,
        start_speculation: int = 1,
        tile_pixels: int | None = None,
        progress: Callable[[dict], None] | None = None,
        host: bool = True,
    ) -> IsoImage:
        """Passes until `completion` of the rays are finished, tile by tile;
        the image (each tile read back once, when it is done). host=False:
        the image's planes stay on the device (``pyopencl.array.Array``;
        ``hit`` and ``active`` bool), each tile written into them by a kernel,
        and nothing but the pass loop's counts is read back. See the module
        doc for tiles, `tile_pixels` and `progress`."""
        last: Callable[..., IsoImage] | None = None
        with runtime.pinned(self.config):
            for last in self._run(  # noqa: B007  (the last image of the pass loop is the result)
                camera,
                width,
                height,
                isovalue,
                completion,
                speculation,
                start_speculation,
                tile_pixels,
                progress,
                host,
            ):
                pass
            assert last is not None  # _run yields at least once (no ray in the volume: the empty image)
            return last(copy=False)

    def passes(
        self,
        camera: Camera,
        width: int,
        height: int,
        isovalue: float,
        *,
        completion: float = 1.0,
        speculation: bool = True,
        start_speculation: int = 1,
        tile_pixels: int | None = None,
        progress: Callable[[dict], None] | None = None,
        host: bool = True,
    ) -> Iterator[IsoImage]:
        """Yield the partial image after each pass of each tile (see the module
        doc); host=False: device images, each its own copy (see render)."""
        run = self._run(
            camera,
            width,
            height,
            isovalue,
            completion,
            speculation,
            start_speculation,
            tile_pixels,
            progress,
            host,
        )
        while True:
            # pinned while the pass runs, not while the caller holds the image
            with runtime.pinned(self.config):
                image = next(run, None)
                if image is None:
                    return
                image = image()
            yield image

    def tile_plan(
        self,
        width: int,
        height: int,
        *,
        speculation: bool = True,
        start_speculation: int = 1,
        tile_pixels: int | None = None,
    ) -> tuple[int, int]:
        """(pixels per tile, device bytes a tile's rays and pass items may take):
        whole rows where a row fits TILE_BYTES (see the module doc)."""
        w, h = positive_int("width", width), positive_int("height", height)
        s = positive_int("start_speculation", start_speculation)
        per_pixel = PIXEL_BYTES + ITEM_BYTES * (max(s, 2) if speculation else 1)
        if tile_pixels is None:
            t = max(1, TILE_BYTES // per_pixel)
            if t >= w:
                t -= t % w
        else:
            t = positive_int("tile_pixels", tile_pixels)
        t = min(t, w * h)
        return t, t * per_pixel

    def _run(
        self,
        camera,
        width,
        height,
        isovalue,
        completion,
        speculation,
        start_speculation,
        tile_pixels,
        progress,
        host=True,
    ):
        """The pass loop, tile after tile: after each pass, a function that
        gives the image (copy=False: the renderer's image arrays themselves;
        host=False: the device image, else read back)."""
        if not isinstance(camera, Camera):
            raise TypeError(f"camera: expected a clvis.Camera, got {type(camera).__name__}")
        w, h = positive_int("width", width), positive_int("height", height)
        npix = w * h
        if npix >= MAX_PIXELS:
            raise ValueError(
                f"width x height: {w} x {h} = {npix} pixels; the kernels index pixels with "
                f"32-bit integers, so at most {MAX_PIXELS - 1}"
            )
        iso = _real("isovalue", isovalue)
        if not np.isfinite(np.float32(iso)):
            raise ValueError(f"isovalue: expected a finite number, got {isovalue!r}")
        completion = _real("completion", completion)
        if not 0.0 < completion <= 1.0:
            raise ValueError(f"completion: expected a fraction in (0, 1], got {completion!r}")
        s = positive_int("start_speculation", start_speculation)
        if progress is not None and not callable(progress):
            raise TypeError(f"progress: expected a callable or None, got {type(progress).__name__}")
        tile, tile_bytes = self.tile_plan(
            w, h, speculation=speculation, start_speculation=s, tile_pixels=tile_pixels
        )
        tiles = [(p0, min(tile, npix - p0)) for p0 in range(0, npix, tile)]
        image_bytes = npix * HOST_PIXEL_BYTES
        runtime.check_memory(
            self.queue,
            f"iso image {w}x{h} ({len(tiles)} tiles of {tile} pixels)",
            device_bytes=tile_bytes + (0 if host else image_bytes),
            host_bytes=image_bytes if host else 0,
        )
        check_aspect(camera, w, h)  # the arguments are good and the image fits: the render goes on
        q, zv = self.queue, self.volume
        shape, spacing, origin = zv.shape, self.spacing, self.origin
        start = runtime.marker(q)
        cam = runtime.empty(q, 22, np.float32, "camera rays")
        cam.set(ray_buffer(camera, w, h), queue=q)
        flip = view_flips(camera, shape, spacing, origin)
        out = _HostImage(npix) if host else _DeviceImage(self, npix)
        # the rays entering the volume, tile by tile: the totals of completion
        # and progress, and the active mask of the tiles not traced yet
        # (the first tile keeps its rays: it is traced next, and its own state
        # says which of them are running)
        entering, first_rays = [], None
        for ti, (p0, n) in enumerate(tiles):
            rays = init_rays(q, cam, w, h, shape, spacing, origin, pixels=(p0, n))
            k = int(rays[2].get()[0])
            entering.append(k)
            if ti == 0:
                first_rays = rays
            else:
                out.mark_active(p0, rays[1], k)
        n_total = sum(entering)
        int64 = self.config.int64_atomics
        stats: dict[str, Any] = {
            "passes": 0,
            "active_per_pass": [],
            "n_spec_per_pass": [],
            "items_per_pass": [],
            "blocks_per_pass": [],
            "decoded_per_pass": [],
            "rays_entering": n_total,
            "speculation": bool(speculation),
            "int64_atomics": bool(int64),
            "tiles": len(tiles),
            "tile_pixels": tile,
            "passes_per_tile": [0] * len(tiles),
            "completion_per_tile": [1.0] * len(tiles),
            "blocks_decoded": 0,
            "cache_slots": self.cache.capacity,
        }
        decoded0 = self.cache.decoded_total
        if n_total == 0:  # no ray meets the volume: the (empty) image at once
            end = runtime.marker(q)
            yield lambda copy=True: self._image(w, h, camera, out, None, 1.0, stats, (start, end), copy)
            return
        # the macrocell grids' active bits for this isovalue, once a frame
        # (how macro_traverse reads them: 32 KB of bits for 2 MB of ranges at 256^3)
        fine, coarse = self.grids.fine, self.grids.coarse
        assert isinstance(fine, cla.Array) and isinstance(coarse, cla.Array)  # built with host=False
        bits = (range_bits(fine, iso, queue=q), range_bits(coarse, iso, queue=q))
        finished = 0  # rays finished in the tiles before this one
        for ti, (p0, n) in enumerate(tiles):
            n_enter = entering[ti]
            if n_enter == 0:
                continue
            state = _Tile(
                q,
                p0,
                n,
                cam,
                w,
                h,
                shape,
                spacing,
                origin,
                int64,
                first_rays if ti == 0 else None,
                flip,
                n_enter if ti == 0 else None,
            )
            state.walk = (iso, bits)
            first_rays = None
            n_active = n_enter
            tile_done = False
            while not tile_done:
                n_spec = self._n_spec(n, s, n_active, stats["passes_per_tile"][ti]) if speculation else 1
                stats["active_per_pass"].append(n_active)
                m, ngroups, decoded, item_bytes = self._pass(state, iso, bits, n_active, n_spec)
                n_active = int(state.active.size)
                stats["passes"] += 1
                stats["passes_per_tile"][ti] += 1
                stats["n_spec_per_pass"].append(n_spec)
                stats["items_per_pass"].append(m)
                stats["blocks_per_pass"].append(ngroups)
                stats["decoded_per_pass"].append(decoded)
                tile_frac = 1.0 - n_active / n_enter
                stats["completion_per_tile"][ti] = tile_frac
                tile_done = n_active == 0 or tile_frac >= completion
                frac = (finished + n_enter - n_active) / n_total
                stats["blocks_decoded"] = self.cache.decoded_total - decoded0
                stats["cache_slots"] = self.cache.capacity
                # what is allocated: the arrays held (for the tile, its rays; for the pass items, this pass's)
                stats["device_bytes"] = {
                    "compressed volume": self.cache.stream_nbytes,
                    "block cache": self.cache.nbytes,
                    "macrocell grids": runtime.nbytes(self.grids.fine, self.grids.coarse),
                    "rays and image": state.nbytes + runtime.nbytes(cam),
                    "pass items": item_bytes,
                }
                end = runtime.marker(q)
                if tile_done:
                    state.read(out)  # the tile's part of the image, before its arrays go
                    finished += n_enter - n_active
                if progress is not None:
                    progress(
                        {
                            "tile": ti + 1,
                            "tiles": len(tiles),
                            "passes": stats["passes"],
                            "rays_done": finished if tile_done else finished + n_enter - n_active,
                            "rays_total": n_total,
                        }
                    )
                # the image after this pass, made only when the caller asks for it
                # the stats as of this pass: the per-pass lists copied, not shared with
                # the images of later passes (a held image keeps its own counts)
                sd = {k: list(v) if isinstance(v, list) else v for k, v in stats.items()}
                st, a, ev = (None if tile_done else state), state.active, (start, end)
                yield lambda copy=True, st=st, a=a, f=frac, sd=sd, ev=ev: self._image(
                    w, h, camera, out, (st, a), f, sd, ev, copy
                )

    def _n_spec(self, n: int, s: int, n_active: int, done: int) -> int:
        """Candidates per ray of a tile's pass with speculation: n tile pixels,
        s start_speculation, n_active rays, `done` passes before it. The
        items (n_active x n_spec) stay within the tile's budget, n x max(s, 2)
        (tile_plan): n // spec_div x s over the active rays, at least 1, at
        most MAX_SPEC; the first pass at least spec_first (the paper's two
        macro-traversal steps on the gpu profile) where the budget allows."""
        div, first = self._spec
        n_spec = min(MAX_SPEC, max(1, (n * s) // (div * n_active)))
        if done == 0:
            n_spec = max(n_spec, min(first, (n * max(s, 2)) // n_active, MAX_SPEC))
        return n_spec

    def _pass(
        self, t: _Tile, iso: float, bits: tuple[cla.Array, cla.Array], n_active: int, n_spec: int
    ) -> tuple[int, int, int, int]:
        """One pass over the tile's active rays; t.active becomes the rays
        still running. bits: the fine and coarse grids' range_bits for iso.
        Returns (items, blocks, blocks decoded, pass bytes)."""
        q, zv = self.queue, self.volume
        shape, spacing, origin = zv.shape, self.spacing, self.origin
        active = t.active
        fine, coarse = bits
        n_items = n_active * n_spec
        cand_block = runtime.empty(q, n_items, np.uint32, "candidate blocks")
        cand_t = runtime.empty(q, n_items, np.float32, "candidate t")
        macro_traverse(
            q,
            shape,
            spacing,
            origin,
            iso,
            t.cam,
            t.w,
            fine,
            coarse,
            active,
            t.count,
            n_active,
            t.ray_t,
            n_spec,
            cand_block,
            cand_t,
            first_pixel=t.p0,
        )
        valid = runtime.empty(q, n_items, np.uint8, "valid items")
        self._launch("valid_items", n_items, cand_block.base_data, np.uint32(n_items), valid.base_data)
        item_ids = compact_indices(valid, queue=q)
        m = int(item_ids.size)
        item_hit = runtime.zeros(q, max(n_items, 1), np.uint8, "item hits")
        item_t = runtime.empty(q, max(n_items, 1), np.float32, "item t")
        item_rgba = runtime.empty(q, (max(n_items, 1), 4), np.float32, "item rgba")
        item_depth = runtime.empty(q, max(n_items, 1), np.float32, "item depth")
        if t.hitkey is not None:
            runtime.fill(q, t.hitkey, np.uint64(0xFFFFFFFFFFFFFFFF))
        ngroups = 0
        # the next pass's active count (compact writes it: no pass writes a count)
        count = runtime.empty(q, 1, np.uint32, "active count")
        pass_arrays = [count, cand_block, cand_t, valid, item_ids, item_hit, item_t, item_rgba, item_depth]
        if m:
            keys = runtime.empty(q, m, np.uint32, "item blocks")
            self._launch(
                "item_keys",
                m,
                cand_block.base_data,
                item_ids.base_data,
                np.uint32(m),
                *t.order,
                keys.base_data,
            )
            # the keys are item_keys' view keys, below 2^key_bits by construction: no check read
            skeys, sitems = radix_sort(keys, item_ids, key_bits=t.key_bits, check=False, queue=q)
            heads = runtime.empty(q, m, np.uint8, "group heads")
            self._launch("group_heads", m, skeys.base_data, np.uint32(m), heads.base_data)
            starts = compact_indices(heads, queue=q)
            ngroups = int(starts.size)
            gblocks = runtime.empty(q, ngroups, np.uint32, "group blocks")
            gcounts = runtime.empty(q, ngroups, np.uint32, "group counts")
            pass_arrays += [keys, skeys, sitems, heads, starts, gblocks, gcounts]
            self._launch(
                "group_info",
                ngroups,
                skeys.base_data,
                starts.base_data,
                np.uint32(ngroups),
                np.uint32(m),
                *t.order,
                gblocks.base_data,
                gcounts.base_data,
            )
            needed = mark_blocks(gblocks, zv, queue=q)
            decoded = self.cache.update(needed)
            raytrace_blocks(
                q,
                self.cache.bricks,
                self.cache.slot_of_block,
                shape,
                spacing,
                origin,
                iso,
                t.cam,
                t.w,
                (gblocks, starts, gcounts),
                sitems,
                cand_t,
                (item_hit, item_t, item_rgba, item_depth),
                items=(active, n_spec, t.hitkey),
                first_pixel=t.p0,
            )
        else:
            decoded = 0
        still = runtime.empty(q, max(n_active, 1), np.uint8, "still active")
        pass_arrays.append(still)
        self._launch(
            "resolve_hits",
            n_active,
            active.base_data,
            np.uint32(n_active),
            np.uint32(n_spec),
            item_hit.base_data,
            item_t.base_data,
            item_rgba.base_data,
            item_depth.base_data,
            runtime.arg(t.hitkey),
            t.ray_t.base_data,
            t.hit.base_data,
            t.hit_t.base_data,
            t.rgba.base_data,
            t.depth.base_data,
            still.base_data,
        )
        active_out, count = compact(active, still[:n_active], count=count, queue=q)
        t.active, t.count = active_out[: int(count.get()[0])], count
        return m, ngroups, decoded, runtime.nbytes(*pass_arrays)

    def _launch(self, name, n, *args):
        runtime.launch(self.queue, self._kernels[name], *runtime.items(self.queue, n, self._wg), *args)

    def _image(self, w, h, camera, out, tile, frac, stats, events, copy) -> IsoImage:
        if tile is not None and tile[0] is not None:  # a tile still running: its part as it stands
            tile[0].read(out, tile[1])
        image = out.image(w, h, copy)
        image.completion, image.stats, image.camera = frac, stats, camera
        stats["seconds"] = runtime.seconds(*events)  # read back: the events are done
        return image
