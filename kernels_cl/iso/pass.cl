/* pass.cl — the bookkeeping of one pass of the progressive isosurface
 * raycaster (Dyken, Usher, Kumar 2024): grouping the pass's items by block,
 * and resolving each ray's nearest hit over its speculated candidates.
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/atomics.h).
 * Defines: CLVIS_INT64_ATOMICS (set by the clvis
 * runtime where the device has 64-bit atomics and they are not forced off)
 * selects how resolve_hits finds the nearest hit (see there). Whether it is
 * defined counts, not its value (-DCLVIS_INT64_ATOMICS=0 turns it on), as in
 * raytrace.cl, which must be built alike. One work-item
 * per element; global size >= the element count, any local size.
 * An item e = i * n_spec + k is the k-th candidate block of active ray i
 * (kernels_cl/iso/traverse.cl writes cand_block[e], cand_t[e]).
 *
 * kernel valid_items(global const uint *cand_block, uint n, global uchar *valid)
 *     valid[e] = cand_block[e] != 0xFFFFFFFF.
 *
 * View order. The items are grouped by block in a front-to-back order of
 * the blocks, so that raytrace.cl (ITEMS mode with CLVIS_INT64_ATOMICS) meets
 * a ray's nearer candidates first and can skip the farther ones once the ray
 * has a nearer hit. The order is that of the block key
 *     key(b) = x' + nbx (y' + nby z'),  x' = (flip & 1) ? nbx - 1 - bx : bx,
 *     y' = (flip & 2) ? nby - 1 - by : by,  z' = (flip & 4) ? nbz - 1 - bz : bz
 * for block b = bx + nbx (by + nby bz): a bijection of the block ids, its own
 * inverse (flip = 0: key(b) = b; clvis.reference.iso.traverse.view_key).
 * The host sets bit a of flip where the rays run towards lower indices along
 * axis a (clvis.iso.render.view_flips); a ray whose direction is < 0 along
 * the flipped axes and >= 0 along the others meets its blocks in ascending
 * key order. Any flip gives the same image: only the order of the groups
 * depends on it.
 *
 * kernel item_keys(global const uint *cand_block, global const uint *index, uint n,
 *                  uint nbx, uint nby, uint nbz, uint flip, global uint *keys)
 *     keys[j] = key(cand_block[index[j]]).
 *
 * kernel group_heads(global const uint *keys, uint n, global uchar *heads)
 *     heads[j] = 1 where j == 0 or keys[j] != keys[j - 1] (keys sorted: the
 *     items' block ids), else 0.
 *
 * kernel group_info(global const uint *keys, global const uint *starts, uint ngroups, uint n,
 *                   uint nbx, uint nby, uint nbz, uint flip,
 *                   global uint *group_blocks, global uint *group_counts)
 *     For group g (starts: the positions of the heads, ascending):
 *     group_blocks[g] = key(keys[starts[g]]) (the block id: key is its own
 *     inverse), group_counts[g] = (g + 1 < ngroups ? starts[g + 1] : n) - starts[g].
 *
 * kernel resolve_hits(global const uint *active, uint count, uint n_spec,
 *                     global const uchar *item_hit, global const float *item_t,
 *                     global const float4 *item_rgba, global const float *item_depth,
 *                     global const ulong *hitkey,
 *                     global float *ray_t, global uchar *hit, global float *hit_t,
 *                     global float4 *rgba, global float *depth, global uchar *still)
 *     Per active ray i (pixel p = active[i]): the winning item is, with
 *     CLVIS_INT64_ATOMICS, the low word of hitkey[p] unless hitkey[p] is all
 *     ones (raytrace.cl ITEMS mode did the 64-bit atomic min of (t bits << 32
 *     | e)); without, the first item e = i n_spec + k (k ascending) with
 *     item_hit[e] — the same item, since candidates run front to back and
 *     their blocks do not overlap in t (and ties in t go to the lower e in
 *     both). A winner's t, rgba and depth go to pixel p, hit[p] = 1,
 *     ray_t[p] = +INFINITY and still[i] = 0; otherwise still[i] = 1 when
 *     ray_t[p] (where traverse.cl left the ray) is finite, else 0.
 *
 * The image on the device (IsoRenderer.render(host=False)): whole-image
 * planes indexed by pixel p = py * W + px, a tile's pixels p0 .. p0 + n - 1.
 *
 * kernel tile_image(uint p0, uint n,
 *                   global const uchar *hit, global const float *hit_t,
 *                   global const float4 *rgba, global const float *depth,
 *                   global uchar *img_hit, global float *img_t, global float4 *img_rgba,
 *                   global float *img_depth, global uchar *img_active)
 *     Per tile pixel j < n (the tile's arrays, as resolve_hits leaves them),
 *     p = p0 + j: img_hit[p] = hit[j], img_t[p] = hit_t[j], img_rgba[p] =
 *     rgba[j], img_depth[p] = depth[j], img_active[p] = 0.
 *
 * kernel mark_active(uint p0, global const uint *active, uint count, global uchar *img_active)
 *     img_active[p0 + active[i]] = 1 for i < count (the tile's rays still
 *     running; run after tile_image).
 *
 * kernel mark_candidates(uint p0, global const uint *active, uint count, uint n_spec,
 *                        global const uint *cand_block, global const float *cand_t,
 *                        global uchar *img_cand, global float *img_next_t)
 *     img_cand[p0 + active[i]] = the number of k < n_spec with
 *     cand_block[i * n_spec + k] != 0xFFFFFFFF, for i < count (n_spec <= 255):
 *     the candidate blocks a macro_traverse from the rays' resume t found
 *     (IsoImage.candidates, the blocks left on each running ray, counted up
 *     to n_spec); img_next_t[p0 + active[i]] = cand_t[i * n_spec], the first
 *     one's t (IsoImage.next_t: where the ray's next candidate block begins),
 *     +inf when it found none. The host zeroes the tile's img_cand and fills
 *     its img_next_t with +inf first.
 */
#include "clvis/atomics.h"

kernel void valid_items(global const uint *cand_block, uint n, global uchar *valid)
{
    uint e = get_global_id(0);
    if (e < n)
        valid[e] = cand_block[e] != 0xFFFFFFFFu ? 1 : 0;
}

/* the view-order key of block b (see View order); key(key(b)) = b */
inline uint view_key(uint b, uint nbx, uint nby, uint nbz, uint flip)
{
    uint bx = b % nbx, by = b / nbx % nby, bz = b / nbx / nby;
    if (flip & 1u)
        bx = nbx - 1u - bx;
    if (flip & 2u)
        by = nby - 1u - by;
    if (flip & 4u)
        bz = nbz - 1u - bz;
    return bx + nbx * (by + nby * bz);
}

kernel void item_keys(global const uint *cand_block, global const uint *index, uint n,
                      uint nbx, uint nby, uint nbz, uint flip, global uint *keys)
{
    uint j = get_global_id(0);
    if (j < n)
        keys[j] = view_key(cand_block[index[j]], nbx, nby, nbz, flip);
}

kernel void group_heads(global const uint *keys, uint n, global uchar *heads)
{
    uint j = get_global_id(0);
    if (j < n)
        heads[j] = (j == 0u || keys[j] != keys[j - 1u]) ? 1 : 0;
}

kernel void group_info(global const uint *keys, global const uint *starts, uint ngroups, uint n,
                       uint nbx, uint nby, uint nbz, uint flip,
                       global uint *group_blocks, global uint *group_counts)
{
    uint g = get_global_id(0);
    if (g >= ngroups)
        return;
    uint s = starts[g];
    group_blocks[g] = view_key(keys[s], nbx, nby, nbz, flip);
    group_counts[g] = (g + 1u < ngroups ? starts[g + 1u] : n) - s;
}

kernel void resolve_hits(global const uint *active, uint count, uint n_spec,
                         global const uchar *item_hit, global const float *item_t,
                         global const float4 *item_rgba, global const float *item_depth,
                         global const ulong *hitkey,
                         global float *ray_t, global uchar *hit, global float *hit_t,
                         global float4 *rgba, global float *depth, global uchar *still)
{
    uint i = get_global_id(0);
    if (i >= count)
        return;
    uint p = active[i];
    uint win = 0xFFFFFFFFu;
#ifdef CLVIS_INT64_ATOMICS
    ulong key = hitkey[p];
    if (key != 0xFFFFFFFFFFFFFFFFul)
        win = (uint)key;
#else
    for (uint k = 0; k < n_spec; ++k)
        if (item_hit[i * n_spec + k]) {
            win = i * n_spec + k;
            break;
        }
#endif
    if (win != 0xFFFFFFFFu) {
        hit[p] = 1;
        hit_t[p] = item_t[win];
        rgba[p] = item_rgba[win];
        depth[p] = item_depth[win];
        ray_t[p] = INFINITY;
        still[i] = 0;
    } else {
        still[i] = isfinite(ray_t[p]) ? 1 : 0;
    }
}

kernel void tile_image(uint p0, uint n, global const uchar *hit, global const float *hit_t,
                       global const float4 *rgba, global const float *depth, global uchar *img_hit,
                       global float *img_t, global float4 *img_rgba, global float *img_depth,
                       global uchar *img_active)
{
    uint j = get_global_id(0);
    if (j >= n)
        return;
    uint p = p0 + j;
    img_hit[p] = hit[j];
    img_t[p] = hit_t[j];
    img_rgba[p] = rgba[j];
    img_depth[p] = depth[j];
    img_active[p] = 0;
}

kernel void mark_active(uint p0, global const uint *active, uint count, global uchar *img_active)
{
    uint i = get_global_id(0);
    if (i < count)
        img_active[p0 + active[i]] = 1;
}

kernel void mark_candidates(uint p0, global const uint *active, uint count, uint n_spec,
                            global const uint *cand_block, global const float *cand_t,
                            global uchar *img_cand, global float *img_next_t)
{
    uint i = get_global_id(0);
    if (i >= count)
        return;
    uint k = 0;
    for (uint e = i * n_spec; e < (i + 1u) * n_spec; ++e)
        k += cand_block[e] != 0xFFFFFFFFu;
    uint p = p0 + active[i];
    img_cand[p] = (uchar)k;
    img_next_t[p] = cand_block[i * n_spec] != 0xFFFFFFFFu ? cand_t[i * n_spec] : INFINITY;
}
