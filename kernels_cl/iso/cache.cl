/* cache.cl — the device LRU block cache of the progressive isosurface
 * raycaster (Dyken, Usher, Kumar 2024): which ZFP blocks a pass needs, which
 * cache slots they get, and their decoding into those slots.
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/zfp.h).
 * No compiler flags. Defines:
 *   NEEDED_T  the element type of the `needed` flags: uchar (default) or uint;
 *             a block is needed when its flag is nonzero.
 * Includes clvis/zfp.h (the per-block decoder, stream format documented there;
 * the block-grid helpers).
 *
 * Blocks: the ZFP block grid of zfp.cl, nbx x nby x nbz blocks of 4^3 samples,
 * block id b = bx + nbx (by + nby bz), nblocks = nbx nby nbz < 2^32.
 * The cache (capacity C slots):
 *   float bricks[C][64]        slot s holds the brick of block block_of_slot[s]
 *                              (value x + 4 y + 16 z, clvis.zfp.decode_blocks)
 *   uint  block_of_slot[C]     block id in slot s, CACHE_FREE (0xFFFFFFFF) if free
 *   int   slot_of_block[nblocks]  slot of block b, -1 if not cached
 *   uint  ages[C]              passes since the slot's block was last needed
 *                              (0 for free slots; saturates at CACHE_AGE_MAX,
 *                              0xFFFFFFFE)
 * Invariant: slot_of_block[b] = s >= 0  <=>  block_of_slot[s] = b.
 *
 * Every kernel: one work-item per element, global size >= the element count
 * (extra items return), any local size (clvis: 64).
 *
 * kernel mark_blocks(global const uint *visible_ids, uint count,
 *                    uint nbx, uint nby, uint nbz, global NEEDED_T *needed)
 *     For j < count, block v = visible_ids[j] (ignored if v >= nblocks) and
 *     its +x, +y, +z, +xy, +xz, +yz, +xyz neighbours that lie inside the grid
 *     get needed[.] = 1 (the dual grid's cells of v reach those blocks'
 *     samples). Other flags are left as they are (the host zeroes `needed`).
 *
 * kernel cache_missing(global const NEEDED_T *needed, global const int *slot_of_block,
 *                      uint nblocks, global uchar *missing)
 *     missing[b] = needed[b] != 0 && slot_of_block[b] < 0, for b < nblocks.
 *
 * kernel cache_slot_flags(global const uint *block_of_slot, global const NEEDED_T *needed,
 *                         uint capacity, uint age, global uchar *free_flags,
 *                         global uchar *cand_flags, global uint *ages)
 *     For s < capacity: free_flags[s] = slot s is free; cand_flags[s] = slot s
 *     may take a new block this pass (free, or its block is not needed).
 *     age != 0: the pass's ageing too, in the same launch: every occupied slot
 *     s gets ages[s] = 0 if its block is needed, else min(ages[s] + 1,
 *     CACHE_AGE_MAX); free slots are not touched (age == 0: ages untouched;
 *     the host ages once a pass, so the flags of a grown cache are made with
 *     age = 0).
 *
 * kernel cache_candidate_keys(global const uint *cand_slots, uint count,
 *                             global const uint *block_of_slot, global const uint *ages,
 *                             uint top, global uint *keys)
 *     keys[j] = 0 for a free slot cand_slots[j], else top - ages[slot] (>= 1:
 *     the host passes top > every age, top <= 0xFFFFFFFF): ascending keys =
 *     free slots first, then the oldest. The host sorts (stably, candidates
 *     in slot order) so ties go by slot index. The order is that of the keys
 *     0xFFFFFFFF - age for every such top; a small top (the host's bound of
 *     the ages: the passes the cache has seen) keeps the keys below
 *     2^bits(top), so the sort runs fewer digit passes.
 *
 * kernel cache_assign(global const uint *ids, global const uint *slots, uint count,
 *                     global uint *block_of_slot, global int *slot_of_block,
 *                     global uint *ages)
 *     For j < count: block ids[j] (not cached) moves into slot slots[j]: the
 *     slot's previous block (if any) gets slot_of_block = -1, then
 *     block_of_slot[slots[j]] = ids[j], slot_of_block[ids[j]] = slots[j],
 *     ages[slots[j]] = 0. The slots must be distinct, the ids distinct and not
 *     cached, and no previous block among the ids (the host guarantees it:
 *     candidates hold blocks not needed in this pass).
 *
 * kernel cache_decode(global const ulong *stream, uint rate, uint nblocks,
 *                     global const uint *ids, global const uint *slots, uint count,
 *                     global float *bricks)
 *     bricks[64 slots[j] + i] = value i of block ids[j] (decoded as
 *     zfp.cl's decode_blocks does, bit for bit), for j < count; an id >=
 *     nblocks reads nothing and gives a brick of NaN.
 */
#include "clvis/zfp.h"

#ifndef NEEDED_T
#define NEEDED_T uchar
#endif

#define CACHE_FREE 0xFFFFFFFFu
#define CACHE_AGE_MAX 0xFFFFFFFEu

kernel void mark_blocks(global const uint *visible_ids, uint count, uint nbx, uint nby, uint nbz,
                        global NEEDED_T *needed)
{
    uint j = get_global_id(0);
    if (j >= count)
        return;
    uint c[3];
    if (!clvis_zfp_grid_cell(visible_ids[j], nbx, nby, nbz, c))
        return;
    for (uint dz = 0; dz < 2u; ++dz)
        for (uint dy = 0; dy < 2u; ++dy)
            for (uint dx = 0; dx < 2u; ++dx) {
                uint x = c[0] + dx, y = c[1] + dy, z = c[2] + dz;
                if (x < nbx && y < nby && z < nbz)
                    needed[clvis_zfp_block_id(x, y, z, nbx, nby)] = (NEEDED_T)1;
            }
}

kernel void cache_missing(global const NEEDED_T *needed, global const int *slot_of_block,
                          uint nblocks, global uchar *missing)
{
    uint b = get_global_id(0);
    if (b >= nblocks)
        return;
    missing[b] = (uchar)(needed[b] != (NEEDED_T)0 && slot_of_block[b] < 0);
}

kernel void cache_slot_flags(global const uint *block_of_slot, global const NEEDED_T *needed,
                             uint capacity, uint age, global uchar *free_flags,
                             global uchar *cand_flags, global uint *ages)
{
    uint s = get_global_id(0);
    if (s >= capacity)
        return;
    uint b = block_of_slot[s];
    uchar is_free = b == CACHE_FREE;
    uchar held = !is_free && needed[b] != (NEEDED_T)0;
    free_flags[s] = is_free;
    cand_flags[s] = (uchar)!held;
    if (age != 0u && !is_free) {
        uint a = ages[s];
        ages[s] = held ? 0u : (a >= CACHE_AGE_MAX ? CACHE_AGE_MAX : a + 1u);
    }
}

kernel void cache_candidate_keys(global const uint *cand_slots, uint count,
                                 global const uint *block_of_slot, global const uint *ages,
                                 uint top, global uint *keys)
{
    uint j = get_global_id(0);
    if (j >= count)
        return;
    uint s = cand_slots[j];
    keys[j] = block_of_slot[s] == CACHE_FREE ? 0u : top - ages[s];
}

kernel void cache_assign(global const uint *ids, global const uint *slots, uint count,
                         global uint *block_of_slot, global int *slot_of_block, global uint *ages)
{
    uint j = get_global_id(0);
    if (j >= count)
        return;
    uint s = slots[j], b = ids[j];
    uint old = block_of_slot[s];
    if (old != CACHE_FREE)
        slot_of_block[old] = -1;
    block_of_slot[s] = b;
    slot_of_block[b] = (int)s;
    ages[s] = 0u;
}

kernel __attribute__((vec_type_hint(ulong16))) void cache_decode(global const ulong *stream, uint rate, uint nblocks,
                         global const uint *ids, global const uint *slots, uint count,
                         global float *bricks)
{
    uint j = get_global_id(0);
    if (j >= count)
        return;
    clvis_zfp_decode_brick(stream, rate, nblocks, ids[j], bricks + (ulong)slots[j] * 64u);
}
