"""NumPy model of the device LRU block cache (clvis.iso.cache, kernels_cl/iso/cache.cl).

The policy, one :meth:`BlockCache.update` per pass (the same steps, the same
tie rules as the device):

1. missing = the needed blocks not cached, ascending block id (m of them).
2. candidates = slots that may take a block this pass: free slots and slots
   whose block is not needed. If m > #candidates the cache grows first:
   capacity := max(n_needed, min(nblocks, ceil(1.5 capacity))), n_needed
   being the number of needed blocks; the new slots are free, old contents
   stay in their slots.
3. ages: every occupied slot whose block is needed gets age 0, every other
   occupied slot age + 1 (saturating at AGE_MAX); free slots stay 0.
4. the candidates in slot order are sorted stably by key (0 for a free slot,
   0xFFFFFFFF - age for an occupied one): free slots first by index, then the
   least recently used (largest age) first, ties by slot index (the device
   sorts top - age under a bound top of the ages: the same order). The first m
   take the missing blocks: missing[j] goes to slot order[j]; a previous
   block there is evicted (slot_of_block = -1). New blocks get age 0.
5. the new blocks are decoded into their slots (the device does it; this
   model keeps no bricks: they are clvis.iso.zfp.decode_blocks of block_of_slot).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

FREE = 0xFFFFFFFF  # restated from clvis.iso.cache (the library never imports this module)
AGE_MAX = 0xFFFFFFFE


def default_capacity(nblocks: int) -> int:
    """The initial capacity when none is given: 1/16 of the blocks, at least
    64, at most nblocks, at least 1."""
    return max(1, min(nblocks, max(64, -(-nblocks // 16))))


def grown_capacity(capacity: int, n_needed: int, nblocks: int) -> int:
    return max(n_needed, min(nblocks, -(-3 * capacity // 2)))


def mark_blocks(visible_ids: npt.ArrayLike, blocks: Sequence[int]) -> np.ndarray:
    """uint8 flags per block (blocks = (nbz, nby, nbx)): 1 for each visible
    block (ids >= nblocks ignored) and its +x/+y/+z/+xy/+xz/+yz/+xyz
    neighbours inside the grid."""
    nbz, nby, nbx = blocks
    needed = np.zeros((nbz, nby, nbx), np.uint8)
    v = np.asarray(visible_ids, np.int64).ravel()
    v = v[(v >= 0) & (v < nbz * nby * nbx)]
    bz, by, bx = v // (nbx * nby), v // nbx % nby, v % nbx
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                z, y, x = bz + dz, by + dy, bx + dx
                ok = (z < nbz) & (y < nby) & (x < nbx)
                needed[z[ok], y[ok], x[ok]] = 1
    return needed.ravel()


class BlockCache:
    """The cache's bookkeeping on the host: slot_of_block (int32),
    block_of_slot (uint32), ages (uint32), capacity, and stats."""

    def __init__(self, nblocks: int, capacity: int | None = None):
        self.nblocks = int(nblocks)
        self.capacity = default_capacity(self.nblocks) if capacity is None else int(capacity)
        self.slot_of_block = np.full(self.nblocks, -1, np.int32)
        self.block_of_slot = np.full(self.capacity, FREE, np.uint32)
        self.ages = np.zeros(self.capacity, np.uint32)
        self.decoded_total = 0
        self.decoded_last = 0
        self.evicted_last = 0

    @property
    def occupied(self) -> int:
        return int(np.count_nonzero(self.block_of_slot != FREE))

    def update(self, needed: npt.ArrayLike) -> int:
        """Apply one pass's `needed` flags (nonzero = needed); returns the
        number of blocks newly assigned (and decoded)."""
        needed = np.asarray(needed).ravel().astype(bool)  # nonzero
        assert needed.shape == (self.nblocks,)
        missing = np.flatnonzero(needed & (self.slot_of_block < 0))
        m = len(missing)
        occ = self.block_of_slot != FREE
        held = np.zeros(self.capacity, bool)
        held[occ] = needed[self.block_of_slot[occ]]
        n_cand = self.capacity - int(held.sum())
        if m > n_cand:
            new = grown_capacity(self.capacity, int(needed.sum()), self.nblocks)
            grow = new - self.capacity
            self.block_of_slot = np.concatenate([self.block_of_slot, np.full(grow, FREE, np.uint32)])
            self.ages = np.concatenate([self.ages, np.zeros(grow, np.uint32)])
            held = np.concatenate([held, np.zeros(grow, bool)])
            occ = np.concatenate([occ, np.zeros(grow, bool)])
            self.capacity = new
        # ages
        a = self.ages.astype(np.int64)
        a[occ] = np.minimum(a[occ] + 1, AGE_MAX)
        a[held] = 0
        self.ages = a.astype(np.uint32)
        # choose slots
        cand = np.flatnonzero(~held)
        keys = np.where(occ[cand], 0xFFFFFFFF - a[cand], 0)
        order = cand[np.argsort(keys, kind="stable")][:m]
        old = self.block_of_slot[order]
        evict = old != FREE
        self.slot_of_block[old[evict].astype(np.int64)] = -1
        self.block_of_slot[order] = missing
        self.slot_of_block[missing] = order
        self.ages[order] = 0
        self.decoded_last = m
        self.decoded_total += m
        self.evicted_last = int(evict.sum())
        return m
