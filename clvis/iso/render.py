"""iso family: progressive isosurface raycasting over ZFP-compressed volumes
(Dyken, Usher, Kumar, TVCG 2024).

A pass, for the rays still active (kernels_cl/iso/):

1. macrocell traversal (traverse.cl): each ray walks the coarse grid, then
   the fine grid (the ZFP blocks) inside active coarse cells, and records up
   to n_spec candidate blocks whose range holds the isovalue (speculation:
   n_spec = min(floor(W H s / active rays), 64), s the starting count; 1
   without speculation);
2. grouping: the (ray, candidate) items are compacted and sorted by block
   (clvis.compact_indices, clvis.radix_sort);
3. the LRU block cache (clvis.iso.cache) decodes the blocks the pass needs
   (the candidates and their +x/+y/+z neighbours) that it does not hold;
4. block raytracing (raytrace.cl, ITEMS mode): a work-group per block with
   its 5^3 dual brick in local memory, the first root of each cell's cubic;
5. resolve (pass.cl): each ray keeps its nearest hit over its candidates,
   by a 64-bit atomic min of (t bits << 32 | item) where the device has
   64-bit atomics, else by scanning its candidates in order (same result);
   rays without a hit go on from where the traversal left them.

An IsoRenderer captures the runtime options (tuning profile, 64-bit atomics)
and its kernels when it is made; every pass runs under them (runtime.pinned),
whatever runtime.configure does meanwhile, in this thread or another.
``stats["seconds"]`` is device time from event profiling, from the start of
the render to the end of the pass.

The rules (rays, dual grid, root finding, shading) are clvis.reference.iso's.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyopencl as cl

from .. import runtime
from .._arrays import positive_int, resolve_queue, triple
from ..camera import Camera, ray_buffer
from ..errors import DataError
from ..primitives import compact, compact_indices, radix_sort
from .cache import BlockCache, mark_blocks
from .macrocell import macrocell_grids
from .raytrace import raytrace_blocks
from .traverse import init_rays, macro_traverse
from .zfp import ZfpVolume, compress

__all__ = ["PROFILES", "IsoImage", "IsoRenderer"]

MAX_SPEC = 64
_PASS = "iso/pass.cl"
_PASS_KERNELS = ("valid_items", "gather_u32", "group_heads", "group_info", "resolve_hits")
# the local size of pass.cl's one-item-per-element kernels (a fixed one: PoCL
# would compile a work-group function for every size the driver chose)
PROFILES = {"cpu": {"wg": 64}, "gpu": {"wg": 64}}

@dataclass
class IsoImage:
    """The image after a pass: ``rgba`` (H, W, 4) float32 (shaded surface,
    alpha 1 at hits), ``depth`` (H, W) view depth (+inf where no hit yet),
    ``hit`` (H, W) bool, ``t`` (H, W) the hit's ray parameter (world distance
    from the ray's origin on the near plane; +inf elsewhere), ``active``
    (H, W) bool (rays still running),
    ``completion`` (the fraction of the rays entering the volume that are
    finished) and ``stats``."""
    rgba: np.ndarray
    depth: np.ndarray
    hit: np.ndarray
    t: np.ndarray
    active: np.ndarray
    completion: float
    stats: dict


class IsoRenderer:
    """A ZFP-compressed volume on the device with its macrocell grids and a
    block cache, for progressive isosurface renders.

    Parameters
    ----------
    volume_or_zfp : a 3-D [z, y, x] array (compressed with `rate` through
        clvis.zfp.compress) or a clvis.zfp.ZfpVolume.
    rate : ZFP fixed rate in bits per value (1..32).
    spacing : (dz, dy, dx); origin : world (x, y, z) of sample [0, 0, 0].
    cache_capacity : initial block-cache slots (default: BlockCache's); the
        cache grows when a pass needs more.

    ``config`` holds the runtime options captured at construction
    (runtime.capture); a configure() change applies to renderers made after it.
    """

    def __init__(self, volume_or_zfp: ZfpVolume | Any, rate: int = 8,
                 spacing: Sequence[float] = (1.0, 1.0, 1.0), origin: Sequence[float] = (0.0, 0.0, 0.0), *,
                 cache_capacity: int | None = None, queue: cl.CommandQueue | None = None) -> None:
        self.queue = q = resolve_queue(queue)
        self.config = runtime.capture(q)
        zv = volume_or_zfp if isinstance(volume_or_zfp, ZfpVolume) else compress(volume_or_zfp, rate)
        if min(zv.shape) < 2:
            raise DataError(f"volume: every axis needs at least 2 samples, got shape {zv.shape}")
        self.volume = zv
        self.spacing = triple("spacing", spacing, positive=True)
        self.origin = triple("origin", origin, positive=False)
        with runtime.pinned(self.config):
            self._kernels = {name: runtime.get_kernel(q, _PASS, name, {}) for name in _PASS_KERNELS}
            self._wg = PROFILES[self.config.tuning]["wg"]
            self.grids = macrocell_grids(zv, queue=q, host=False)
            self.cache = BlockCache(zv, cache_capacity, queue=q)

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.volume.shape

    def reset_cache(self, capacity: int | None = None) -> None:
        """Start over with an empty block cache (a cold start, e.g. for timings)."""
        with runtime.pinned(self.config):
            self.cache = BlockCache(self.volume, capacity, queue=self.queue)

    def render(self, camera: Camera, width: int, height: int, isovalue: float, *, completion: float = 1.0,
               speculation: bool = True, start_speculation: int = 1) -> IsoImage:
        """Passes until `completion` of the rays are finished; the last image
        (read back once, at the end)."""
        last = None
        with runtime.pinned(self.config):
            for last in self._run(camera, width, height, isovalue, completion, speculation, start_speculation):
                pass
            return last()

    def passes(self, camera: Camera, width: int, height: int, isovalue: float, *, completion: float = 1.0,
               speculation: bool = True, start_speculation: int = 1) -> Iterator[IsoImage]:
        """Yield the partial image after each pass (see the module doc)."""
        run = self._run(camera, width, height, isovalue, completion, speculation, start_speculation)
        while True:
            # pinned while the pass runs, not while the caller holds the image
            with runtime.pinned(self.config):
                image = next(run, None)
                if image is None:
                    return
                image = image()
            yield image

    def _run(self, camera, width, height, isovalue, completion, speculation, start_speculation):
        """The pass loop: after each pass, a function that reads the image back."""
        if not isinstance(camera, Camera):
            raise TypeError(f"camera: expected a clvis.Camera, got {type(camera).__name__}")
        w, h = positive_int("width", width), positive_int("height", height)
        iso = float(isovalue)
        if not np.isfinite(np.float32(iso)):
            raise ValueError(f"isovalue: expected a finite number, got {isovalue!r}")
        completion = float(completion)
        if not 0.0 < completion <= 1.0:
            raise ValueError(f"completion: expected a fraction in (0, 1], got {completion!r}")
        s = positive_int("start_speculation", start_speculation)
        q, zv = self.queue, self.volume
        npix = w * h
        shape, spacing, origin = zv.shape, self.spacing, self.origin
        start = runtime.marker(q)
        cam = runtime.empty(q, 22, np.float32, "camera rays")
        cam.set(ray_buffer(camera, w, h), queue=q)
        ray_t, active_all, count = init_rays(q, cam, w, h, shape, spacing, origin)
        n_active = int(count.get()[0])
        active = active_all[:n_active]
        n_enter = max(n_active, 1)
        hit = runtime.zeros(q, npix, np.uint8, "hit mask")
        hit_t = runtime.empty(q, npix, np.float32, "hit t")
        depth = runtime.empty(q, npix, np.float32, "depth")
        for a in (hit_t, depth):
            runtime.fill(q, a, np.float32(np.inf))
        rgba = runtime.zeros(q, (npix, 4), np.float32, "rgba")
        int64 = self.config.int64_atomics
        hitkey = runtime.empty(q, npix, np.uint64, "hit keys") if int64 else None
        frame_bytes = runtime.nbytes(cam, ray_t, active_all, count, hit, hit_t, depth, rgba, hitkey)
        stats = {"passes": 0, "active_per_pass": [], "n_spec_per_pass": [], "items_per_pass": [],
                 "blocks_per_pass": [], "decoded_per_pass": [], "rays_entering": n_active,
                 "speculation": bool(speculation), "int64_atomics": bool(int64)}
        decoded0 = self.cache.decoded_total
        done = n_active == 0
        if done:            # no ray meets the volume: the (empty) image at once
            stats.update(blocks_decoded=0, cache_slots=self.cache.capacity)
            end = runtime.marker(q)
            yield lambda: self._image(w, h, hit, hit_t, rgba, depth, active, 1.0, stats, (start, end))
        while not done:
            n_spec = min(MAX_SPEC, max(1, (npix * s) // n_active)) if speculation else 1
            if speculation and stats["passes"] == 0:
                n_spec = max(n_spec, 2)     # the paper's two macro-traversal steps in the first pass
            n_items = n_active * n_spec
            cnt = runtime.empty(q, 1, np.uint32, "active count")
            cnt.set(np.array([n_active], np.uint32), queue=q)
            cand_block = runtime.empty(q, n_items, np.uint32, "candidate blocks")
            cand_t = runtime.empty(q, n_items, np.float32, "candidate t")
            macro_traverse(q, shape, spacing, origin, iso, cam, w, self.grids.fine, self.grids.coarse,
                           active, cnt, n_active, ray_t, n_spec, cand_block, cand_t)
            valid = runtime.empty(q, n_items, np.uint8, "valid items")
            self._launch("valid_items", n_items, cand_block.base_data, np.uint32(n_items), valid.base_data)
            item_ids = compact_indices(valid, queue=q)
            m = int(item_ids.size)
            item_hit = runtime.zeros(q, max(n_items, 1), np.uint8, "item hits")
            item_t = runtime.empty(q, max(n_items, 1), np.float32, "item t")
            item_rgba = runtime.empty(q, (max(n_items, 1), 4), np.float32, "item rgba")
            item_depth = runtime.empty(q, max(n_items, 1), np.float32, "item depth")
            if hitkey is not None:
                runtime.fill(q, hitkey, np.uint64(0xFFFFFFFFFFFFFFFF))
            ngroups = 0
            pass_arrays = [cnt, cand_block, cand_t, valid, item_ids, item_hit, item_t, item_rgba, item_depth]
            if m:
                keys = runtime.empty(q, m, np.uint32, "item blocks")
                self._launch("gather_u32", m, cand_block.base_data, item_ids.base_data, np.uint32(m),
                             keys.base_data)
                skeys, sitems = radix_sort(keys, item_ids, queue=q)
                heads = runtime.empty(q, m, np.uint8, "group heads")
                self._launch("group_heads", m, skeys.base_data, np.uint32(m), heads.base_data)
                starts = compact_indices(heads, queue=q)
                ngroups = int(starts.size)
                gblocks = runtime.empty(q, ngroups, np.uint32, "group blocks")
                gcounts = runtime.empty(q, ngroups, np.uint32, "group counts")
                pass_arrays += [keys, skeys, sitems, heads, starts, gblocks, gcounts]
                self._launch("group_info", ngroups, skeys.base_data, starts.base_data, np.uint32(ngroups),
                             np.uint32(m), gblocks.base_data, gcounts.base_data)
                needed = mark_blocks(gblocks, zv, queue=q)
                decoded = self.cache.update(needed)
                raytrace_blocks(q, self.cache.bricks, self.cache.slot_of_block, shape, spacing, origin, iso,
                                cam, w, (gblocks, starts, gcounts), sitems, cand_t,
                                (item_hit, item_t, item_rgba, item_depth), items=(active, n_spec, hitkey))
            else:
                decoded = 0
            still = runtime.empty(q, max(n_active, 1), np.uint8, "still active")
            pass_arrays.append(still)
            self._launch("resolve_hits", n_active, active.base_data, np.uint32(n_active), np.uint32(n_spec),
                         item_hit.base_data, item_t.base_data, item_rgba.base_data, item_depth.base_data,
                         runtime.arg(hitkey), ray_t.base_data, hit.base_data,
                         hit_t.base_data, rgba.base_data, depth.base_data, still.base_data)
            stats["passes"] += 1
            stats["active_per_pass"].append(n_active)
            stats["n_spec_per_pass"].append(n_spec)
            stats["items_per_pass"].append(m)
            stats["blocks_per_pass"].append(ngroups)
            stats["decoded_per_pass"].append(decoded)
            active = compact(active, still[:n_active], queue=q)
            n_active = int(active.size)
            frac = 1.0 - n_active / n_enter
            done = n_active == 0 or frac >= completion
            stats["blocks_decoded"] = self.cache.decoded_total - decoded0
            stats["cache_slots"] = self.cache.capacity
            # what is allocated: the arrays held (for the pass items, this pass's)
            stats["device_bytes"] = {
                "compressed volume": self.cache.stream_nbytes, "block cache": self.cache.nbytes,
                "macrocell grids": runtime.nbytes(self.grids.fine, self.grids.coarse),
                "rays and image": frame_bytes,
                "pass items": runtime.nbytes(*pass_arrays)}
            end = runtime.marker(q)
            yield lambda a=active, f=frac, st=dict(stats), ev=(start, end): self._image(
                w, h, hit, hit_t, rgba, depth, a, f, st, ev)

    def _launch(self, name, n, *args):
        runtime.launch(self.queue, self._kernels[name], *runtime.items(self.queue, n, self._wg), *args)

    def _image(self, w, h, hit, hit_t, rgba, depth, active, frac, stats, events) -> IsoImage:
        act = np.zeros(w * h, bool)
        if active.size:
            act[active.get()] = True
        image = IsoImage(rgba.get().reshape(h, w, 4), depth.get().reshape(h, w),
                         hit.get().reshape(h, w).astype(bool), hit_t.get().reshape(h, w), act.reshape(h, w),
                         frac, stats)
        stats["seconds"] = runtime.seconds(*events)     # read back: the events are done
        return image
