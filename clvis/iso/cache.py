"""The device LRU block cache of the progressive isosurface raycaster
(Dyken, Usher, Kumar 2024), kernels in ``kernels_cl/iso/cache.cl``.

Per pass the renderer marks the blocks it needs (:func:`mark_blocks`: the
visible blocks and their +x/+y/+z/+xy/+xz/+yz/+xyz neighbours, which the dual
grid's cells reach) and calls :meth:`BlockCache.update` with those flags.
The policy (``clvis.reference.iso.cache`` is the same, step by step, on the host):

1. missing = the needed blocks not cached, ascending block id (m of them).
2. candidate slots = free slots and slots whose block is not needed this
   pass. If m exceeds them (i.e. more blocks are needed than there are
   slots), the cache grows first to max(needed count, min(nblocks,
   ceil(1.5 capacity))) slots, copying bricks, ages and block_of_slot on the
   device; the new slots are free.
3. ages (passes since last needed): occupied slots whose block is needed get
   0, the other occupied slots age + 1 (saturating at 0xFFFFFFFE); free
   slots stay 0.
4. the candidates are ordered free slots first (by index), then by age
   descending (least recently used first), ties by slot index; the first m
   take missing[0..m) in that order. A block there before is evicted (its
   slot_of_block entry goes back to -1). New blocks get age 0. A block
   needed this pass is never evicted in it.
5. the new blocks are decoded into their slots (one work-item per block).

Lists are built on the device with :func:`clvis.compact_indices` and
:func:`clvis.radix_sort`. A pass reads back the missing count (4 bytes) and,
only when the free slots (capacity - occupied, known on the host) do not
suffice, the candidates' count; the sort only runs then, on keys below
2^bits(passes seen + 1) (cache.cl's cache_candidate_keys), so a cache that
has seen fewer than 255 passes sorts in one 8-bit digit pass. The ageing is
done in the same launch as the slot flags.

Device state: ``bricks`` (capacity, 64) float32, ``slot_of_block``
(nblocks,) int32 (-1: absent), ``block_of_slot`` (capacity,) uint32
(0xFFFFFFFF: free), ``ages`` (capacity,) uint32 — the buffers
``kernels_cl/iso/raytrace.cl`` reads (bricks, slot_of_block).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .. import runtime
from .._arrays import buffer_of, check_array, is_device, resolve_queue, to_device
from ..errors import DataError
from ..primitives import compact_indices, radix_sort
from .zfp import BRICK_VALUES, ZfpVolume

__all__ = ["AGE_MAX", "FREE", "PROFILES", "BlockCache", "default_capacity", "grown_capacity", "mark_blocks"]

FREE = 0xFFFFFFFF  # slot_of_block / block_of_slot: none
AGE_MAX = 0xFFFFFFFE  # ages saturate here


def default_capacity(nblocks: int) -> int:
    """The initial capacity when none is given: 1/16 of the blocks, at least
    64, at most nblocks, at least 1."""
    return max(1, min(nblocks, max(64, -(-nblocks // 16))))


def grown_capacity(capacity: int, n_needed: int, nblocks: int) -> int:
    """The capacity after a pass that needs more free slots than there are:
    max(n_needed, min(nblocks, ceil(1.5 capacity)))."""
    return max(n_needed, min(nblocks, -(-3 * capacity // 2)))


_SRC = "iso/cache.cl"
# the local size of every cache kernel, per tuning profile (a fixed one: PoCL
# would compile a work-group function for every size the driver chose)
PROFILES = {"cpu": {"wg": 64}, "gpu": {"wg": 64}}
_NEEDED_T = {np.dtype(np.uint8): "uchar", np.dtype(np.uint32): "uint"}


def _u32(v) -> np.uint32:
    return np.uint32(int(v))


def _items(queue, n: int) -> tuple[int, int]:
    return runtime.items(queue, n, PROFILES[runtime.tuning_profile(queue)]["wg"])


def _kernel(queue, name: str, needed_dtype=np.uint8):
    return runtime.get_kernel(queue, _SRC, name, {"NEEDED_T": _NEEDED_T[np.dtype(needed_dtype)]})


def mark_blocks(
    visible_ids: Any,
    blocks: ZfpVolume | Sequence[int],
    needed: cla.Array | None = None,
    *,
    queue: cl.CommandQueue | None = None,
) -> cla.Array:
    """Flags of the blocks a pass needs: each block of `visible_ids` (uint32
    block ids; ids >= nblocks are ignored) and its +x, +y, +z, +xy, +xz, +yz,
    +xyz neighbours inside the grid `blocks` = (nbz, nby, nbx) (a
    :class:`~clvis.zfp.ZfpVolume` gives its own grid).

    needed: a device array (uint8 or uint32, nblocks) to OR the marks into;
    by default a zeroed uint8 one is made. Returns the device array.
    """
    if isinstance(blocks, ZfpVolume):
        blocks = blocks.blocks
    nbz, nby, nbx = (int(b) for b in blocks)
    nblocks = nbz * nby * nbx
    queue = resolve_queue(queue, visible_ids=visible_ids, needed=needed)
    v = check_array("visible_ids", visible_ids, ndim=1)
    if is_device(v):
        if v.dtype != np.uint32:
            raise TypeError(f"visible_ids: a device array of ids must be uint32, got {v.dtype}")
    else:
        if v.size and v.dtype.kind not in "iu":
            raise TypeError(f"visible_ids: expected integers, got {v.dtype}")
        v = v.astype(np.int64)
        v = v[(v >= 0) & (v < nblocks)].astype(np.uint32)
    vd = to_device(queue, "visible_ids", v)
    if needed is None:
        needed = runtime.zeros(queue, max(nblocks, 1), np.uint8, "needed flags")[:nblocks]
    else:
        _check_needed(needed, nblocks)
    if vd.size and nblocks:
        k = _kernel(queue, "mark_blocks", needed.dtype)
        runtime.launch(
            queue,
            k,
            *_items(queue, vd.size),
            vd.base_data,
            _u32(vd.size),
            _u32(nbx),
            _u32(nby),
            _u32(nbz),
            needed.base_data,
        )
    return needed


def _shared_stream(stream: Any, zfp_volume: ZfpVolume, queue) -> cla.Array:
    """`stream` checked as zfp_volume's words on the queue's context."""
    if not is_device(stream):
        raise TypeError("stream: expected a device array (pyopencl.array.Array) of the volume's words")
    words = max(1, len(zfp_volume.stream) // 8)
    if stream.dtype != np.uint64 or stream.shape != (words,) or stream.offset:
        raise ValueError(
            f"stream: expected the volume's {words} uint64 words without offset "
            f"(zfp_volume.to_device), got {stream.dtype} of shape {tuple(stream.shape)}"
        )
    if stream.context.int_ptr != queue.context.int_ptr:
        raise ValueError("stream: the device array belongs to another OpenCL context than the queue")
    return stream


def _check_needed(needed, nblocks: int):
    if not is_device(needed):
        raise TypeError("needed: expected a device array (pyopencl.array.Array)")
    if needed.dtype not in _NEEDED_T and needed.dtype != np.bool_:
        raise TypeError(f"needed: dtype {needed.dtype} is not supported; expected uint8, bool or uint32")
    if needed.ndim != 1 or needed.size != nblocks:
        raise ValueError(f"needed: expected {nblocks} flags (one per block), got shape {tuple(needed.shape)}")
    if needed.offset or not needed.flags.c_contiguous:
        raise ValueError("needed: a device array with an offset (or not contiguous) is not supported")


class BlockCache:
    """A device LRU cache of decoded 4^3 bricks of a :class:`~clvis.zfp.ZfpVolume`
    (policy in the module docstring).

    capacity: the initial number of slots (default: 1/16 of the blocks, at
    least 64, at most the block count). The cache grows when a pass needs more.
    stream: the volume's compressed stream already on the queue's device (another
    cache's :attr:`stream`, or ``zfp_volume.to_device(queue)``) to decode from
    instead of uploading it again (IsoRenderer.reset_cache: a cold cache, not a
    new upload of the volume).
    """

    def __init__(
        self,
        zfp_volume: ZfpVolume,
        capacity: int | None = None,
        *,
        queue: cl.CommandQueue | None = None,
        stream: cla.Array | None = None,
    ):
        if not isinstance(zfp_volume, ZfpVolume):
            raise TypeError(f"zfp_volume: expected a clvis.zfp.ZfpVolume, got {type(zfp_volume).__name__}")
        self.volume = zfp_volume
        self.queue = q = resolve_queue(queue)
        self.nblocks = zfp_volume.nblocks
        if capacity is None:
            capacity = default_capacity(self.nblocks)
        elif isinstance(capacity, bool) or not isinstance(capacity, (int, np.integer)) or capacity < 1:
            raise ValueError(f"capacity: expected a positive integer, got {capacity!r}")
        if stream is None:
            self._stream = zfp_volume.to_device(q)
        else:
            self._stream = _shared_stream(stream, zfp_volume, q)
        self.capacity = int(capacity)
        self.bricks = runtime.zeros(q, (self.capacity, BRICK_VALUES), np.float32, "cache bricks")
        self.block_of_slot = runtime.fill(
            q, runtime.empty(q, self.capacity, np.uint32, "cache block_of_slot"), FREE
        )
        self.ages = runtime.zeros(q, self.capacity, np.uint32, "cache ages")
        self.slot_of_block = runtime.fill(
            q, runtime.empty(q, max(self.nblocks, 1), np.int32, "cache slot_of_block"), -1
        )[: self.nblocks]
        self.occupied = 0
        # at least every slot's age: ages rise by one a pass at most (set_ages raises it)
        self._age_bound = 0
        self.decoded_total = 0
        self.decoded_last = 0
        self.evicted_last = 0

    @property
    def nbytes(self) -> int:
        """Device bytes of the cache buffers (bricks, block_of_slot, ages,
        slot_of_block; the compressed stream not counted)."""
        return runtime.nbytes(self.bricks, self.block_of_slot, self.ages, self.slot_of_block)

    @property
    def stream(self) -> cla.Array:
        """The compressed stream on the device (uint64 words) the cache decodes from."""
        return self._stream

    @property
    def stream_nbytes(self) -> int:
        """Device bytes of the compressed stream the cache decodes from."""
        return runtime.nbytes(self._stream)

    def get_state(self) -> dict:
        """Host copies: slot_of_block, block_of_slot, ages, bricks, capacity."""
        return {
            "slot_of_block": self.slot_of_block.get() if self.nblocks else np.zeros(0, np.int32),
            "block_of_slot": self.block_of_slot.get(),
            "ages": self.ages.get(),
            "bricks": self.bricks.get(),
            "capacity": self.capacity,
        }

    # -- steps ---------------------------------------------------------------

    def _grow(self, new: int) -> None:
        q, old = self.queue, self.capacity
        bricks = runtime.empty(q, (new, BRICK_VALUES), np.float32, "cache bricks")
        bos = runtime.empty(q, new, np.uint32, "cache block_of_slot")
        ages = runtime.empty(q, new, np.uint32, "cache ages")
        for src, dst in ((self.bricks, bricks), (self.block_of_slot, bos), (self.ages, ages)):
            cl.enqueue_copy(
                q,
                buffer_of(dst),
                buffer_of(src),
                byte_count=src.nbytes,
                src_offset=src.offset,
                dst_offset=dst.offset,
            )
        runtime.fill(q, bricks, 0, start=self.bricks.size)
        runtime.fill(q, ages, 0, start=old)
        runtime.fill(q, bos, FREE, start=old)
        self.bricks, self.block_of_slot, self.ages, self.capacity = bricks, bos, ages, new

    def _slot_lists(self, nd, age: bool):
        """Slot flags (free, candidate) of the cache as it stands; age: the
        pass's ageing in the same launch (cache.cl's cache_slot_flags)."""
        q, cap = self.queue, self.capacity
        free_f = runtime.empty(q, cap, np.uint8, "cache free flags")
        cand_f = runtime.empty(q, cap, np.uint8, "cache candidate flags")
        runtime.launch(
            q,
            _kernel(q, "cache_slot_flags", nd.dtype),
            *_items(q, cap),
            self.block_of_slot.base_data,
            nd.base_data,
            _u32(cap),
            _u32(int(age)),
            free_f.base_data,
            cand_f.base_data,
            self.ages.base_data,
        )
        return free_f, cand_f

    def _free_or_candidates(self, nd, m, age: bool):
        """(the first m free slots or None, the eviction candidates or None).
        The free count is the host's (capacity - occupied), so the free slots
        are listed without a read-back; the candidates' count is read back."""
        free_f, cand_f = self._slot_lists(nd, age)
        if self.capacity - self.occupied >= m:
            count = runtime.empty(self.queue, 1, np.uint32, "cache free count")
            free, _ = compact_indices(free_f, count=count, queue=self.queue)
            return free[:m], None
        return None, compact_indices(cand_f, queue=self.queue)

    def set_ages(self, ages: Any) -> None:
        """Overwrite the slots' ages (uint32, one per slot; a test's way to
        reach saturation). Write ages only through here: the cache keeps a
        bound of every age, which sizes its LRU sort."""
        a = np.asarray(ages, np.uint32)
        if a.shape != (self.capacity,):
            raise ValueError(f"ages: expected {self.capacity} values, got shape {a.shape}")
        self.ages.set(a, queue=self.queue)
        self._age_bound = min(AGE_MAX, max(self._age_bound, int(a.max(initial=0))))

    def update(self, needed: Any) -> int:
        """One pass: cache every block flagged in `needed` (a device array of
        nblocks uint8/bool/uint32 flags, nonzero = needed; numpy is uploaded).
        Returns the number of blocks decoded."""
        q = self.queue
        if not is_device(needed):
            h = check_array("needed", needed, ndim=1)
            if h.dtype.kind not in "biu":
                raise TypeError(f"needed: expected integer or bool flags, got {h.dtype}")
            h = (h != 0).astype(np.uint8)
            if h.size != self.nblocks:
                raise ValueError(f"needed: expected {self.nblocks} flags (one per block), got {h.size}")
            needed = to_device(q, "needed", h) if h.size else runtime.empty(q, 1, np.uint8, "needed")[:0]
        else:
            resolve_queue(q, needed=needed)
            _check_needed(needed, self.nblocks)
        nd = needed.view(np.uint8) if needed.dtype == np.bool_ else needed
        self.decoded_last = self.evicted_last = 0
        if self.nblocks == 0:
            return 0
        nb = self.nblocks

        # 1. missing blocks, ascending
        miss_f = runtime.empty(q, nb, np.uint8, "cache missing flags")
        runtime.launch(
            q,
            _kernel(q, "cache_missing", nd.dtype),
            *_items(q, nb),
            nd.base_data,
            self.slot_of_block.base_data,
            _u32(nb),
            miss_f.base_data,
        )
        missing = compact_indices(miss_f, queue=q)
        m = int(missing.size)

        # 2. candidate slots; grow when they do not suffice. 3. ages: in the
        # same launch as the first slot flags (the flags do not read the ages;
        # a grow copies the aged ones and its new slots are free)
        slots = None
        nfree = self.capacity - self.occupied
        if m:
            slots, cand = self._free_or_candidates(nd, m, age=True)
            if slots is None and cand.size < m:
                n_needed = self.capacity - int(cand.size) + m
                self._grow(grown_capacity(self.capacity, n_needed, nb))
                nfree = self.capacity - self.occupied
                slots, cand = self._free_or_candidates(nd, m, age=False)
            if slots is None and cand.size < m:  # cannot happen: grown to n_needed
                raise DataError(f"block cache: {m} blocks to place but {cand.size} candidate slots")
        else:
            self._slot_lists(nd, age=True)
        # every age is at most the passes seen so far (one ageing a pass)
        self._age_bound = min(AGE_MAX, self._age_bound + 1)
        if not m:
            return 0

        # 4. least recently used candidates (only when the free slots do not suffice)
        if slots is None:
            c = int(cand.size)
            keys = runtime.empty(q, c, np.uint32, "cache candidate keys")
            # keys top - age (free slots 0), below 2^bits(top): the order of
            # 0xFFFFFFFF - age in as few digit passes as the ages allow, and
            # no range-check read (top exceeds every age by construction)
            top = self._age_bound + 1
            runtime.launch(
                q,
                _kernel(q, "cache_candidate_keys"),
                *_items(q, c),
                cand.base_data,
                _u32(c),
                self.block_of_slot.base_data,
                self.ages.base_data,
                _u32(top),
                keys.base_data,
            )
            _, order = radix_sort(keys, cand, key_bits=top.bit_length(), check=False, queue=q)
            slots = order[:m]
            self.evicted_last = m - nfree
        runtime.launch(
            q,
            _kernel(q, "cache_assign"),
            *_items(q, m),
            missing.base_data,
            slots.base_data,
            _u32(m),
            self.block_of_slot.base_data,
            self.slot_of_block.base_data,
            self.ages.base_data,
        )

        # 5. decode
        zv = self.volume
        runtime.launch(
            q,
            _kernel(q, "cache_decode"),
            *_items(q, m),
            self._stream.base_data,
            _u32(zv.rate),
            _u32(nb),
            missing.base_data,
            slots.base_data,
            _u32(m),
            self.bricks.base_data,
        )
        self.occupied += m - self.evicted_last
        self.decoded_last = m
        self.decoded_total += m
        return m

    def __repr__(self) -> str:
        return (
            f"BlockCache(capacity={self.capacity}, occupied={self.occupied}, nblocks={self.nblocks}, "
            f"decoded_total={self.decoded_total})"
        )
