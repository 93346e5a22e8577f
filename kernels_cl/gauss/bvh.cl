/* bvh.cl — a linear BVH over axis-aligned boxes, built on the device: the
 * binary radix tree of Karras ("Maximizing parallelism in the construction of
 * BVHs, octrees and k-d trees", HPG 2012) over the Morton codes of the box
 * centres, with Karras's node numbering, built and refitted in one bottom-up
 * pass (the agglomerative order of Apetrei, "Fast and simple agglomerative
 * LBVH construction", 2014, which makes the same tree without Karras's
 * per-node searches).
 *
 * ABI
 * ---
 * No defines. Include path: -I kernels_cl/include (clvis/bvh.h, clvis/keys.h,
 * clvis/morton.h). Every kernel is 1-D, any local size; the global size may
 * exceed the item count (extra items return). Buffers are whole cl_mem
 * objects (offset 0).
 *
 * boxes: n rows of 6 floats, row i = (lo x, y, z, hi x, y, z) of primitive i,
 * 1 <= n < 2^31. The tree (clvis_bvh_node, 32 bytes: float lo[3], uint left,
 * float hi[3], uint right; CLVIS_BVH_LEAF, CLVIS_BVH_NONE) is spelled out in
 * clvis/bvh.h. Host steps, in order, on one in-order queue:
 *
 * 1. kernel bvh_bounds(global const float *boxes, uint n, uint chunk,
 *                      global uint *res)
 *      Item g takes rows [g*chunk, (g+1)*chunk), then those plus G*chunk, ...
 *      (G = global size; chunk = ceil(n / G) gives each item one contiguous
 *      range, chunk = 1 interleaves the items). res: 16 uints, all set to
 *      0xFFFFFFFF by the host before the launch; afterwards
 *        res[0..2]   clvis_key_f32 (keys.h) of the min x, y, z of the centres
 *        res[3..5]   ~clvis_key_f32 of their max x, y, z
 *        res[6..8]   clvis_key_f32 of the min lo x, y, z (the union of the boxes)
 *        res[9..11]  ~clvis_key_f32 of the max hi x, y, z
 *        res[12]     the first bad row, or 0xFFFFFFFF if there is none
 *        res[13..15] unused
 *      (atomic_min on each word). Centre c = (lo + hi) * 0.5f per axis, in
 *      float32. A row is bad when lo <= hi fails on an axis or lo + hi is not
 *      finite: that catches every NaN and infinity, lo > hi, and centres that
 *      overflow. Bad rows take no part in the bounds. Zeros may come back as
 *      -0.0 or +0.0 depending on how rows fall to items.
 *
 * 2. kernel bvh_morton(global const float *boxes, uint n, float lox, float loy,
 *                      float loz, float sx, float sy, float sz,
 *                      global uint *codes, global uint *iota)
 *      One item per box: codes[i] = clvis_morton3(q_x, q_y, q_z) of its centre
 *      c (as above), q_a = clamp(trunc((c_a - lo_a) * s_a), 0, 1023) in float32
 *      (clvis_morton_quantize of clvis/morton.h),
 *      exactly as raster/morton.cl's morton_codes: lo = the min centre and s_a
 *      = (float)(1023.0 / ((double)max_a - (double)lo_a)) (the extent too
 *      in double: clvis.morton.scale), or 0 for a flat axis.
 *      iota[i] = i.
 *
 *    The host then sorts (codes, iota) by code, stably (clvis.radix_sort):
 *    the sorted codes, and order[j] = the primitive at sorted position j.
 *
 * 3. kernel bvh_gather(global const float *boxes, global const uint *order,
 *                      uint n, global float *leaf_boxes)
 *      One item per position j: leaf_boxes row j = boxes row order[j]. (Read
 *      as 3 float2 per row: the buffers must be 8-byte aligned, as cl_mem is.)
 *
 * 4. kernel bvh_build(global const uint *codes, global const float *leaf_boxes,
 *                     uint n, global clvis_bvh_node *nodes, global uint *meet)
 *      codes: sorted (n). nodes: max(n - 1, 1) nodes, written completely.
 *      meet: max(n - 1, 1) uints, all set to 0xFFFFFFFF by the host. One item
 *      per leaf (global size >= n).
 *
 *      The tree. Key k_j = (codes[j], j) (64 bits: code above, position
 *      below; so keys are distinct and equal codes split by position, i.e.
 *      Karras's delta(i, j) = clz(codes[i] ^ codes[j]), or 32 + clz(i ^ j)
 *      for equal codes). X(x) = k_x ^ k_{x+1}. A node covering positions
 *      [l, r] other than [0, n - 1] is the left child of the node whose split
 *      is r when l == 0 or (r != n - 1 and X(r) < X(l - 1)), else the right
 *      child of the node whose split is l - 1; a node with split g has
 *      children [.., g] and [g + 1, ..]. Karras's numbering: the root is node
 *      0, a left child covering [l, r] is node r, a right child node l; a
 *      one-position range is a leaf, child word CLVIS_BVH_LEAF | position.
 *
 *      The walk. Item j starts at leaf j and climbs while it can: a node is
 *      finished (its box, the union of its children's, written with both
 *      child words) by the item that arrives second. A leaf sibling is always
 *      ready, so no one waits for it: of two leaves the left one's item goes
 *      on, a leaf next to an internal sibling stops at once. Two internal
 *      siblings meet through meet[g] (g = their parent's split): each writes
 *      its node, mem_fence(CLK_GLOBAL_MEM_FENCE), then atomic_xchg(meet + g,
 *      its outer end); the one that gets 0xFFFFFFFF back stops, the other
 *      fences and reads its sibling's node through a volatile pointer. No
 *      item ever waits for another.
 *
 *      Union: lo = right.lo < left.lo ? right.lo : left.lo per axis, hi =
 *      right.hi > left.hi ? right.hi : left.hi (exact; a tie, -0.0 against
 *      +0.0, keeps the left child's value), so the boxes do not depend on the
 *      order of arrival. n == 1: node 0 = (box 0, LEAF | 0, NONE).
 */
#pragma OPENCL FP_CONTRACT OFF

#include "clvis/bvh.h"
#include "clvis/keys.h"
#include "clvis/morton.h"

/* PoCL makes slow code of vload3/vstore3 and of isless & co. here: rows are read
 * as scalars or float2, comparisons are operators */

inline float3 bvh_min3(float3 a, float3 b) { return select(a, b, b < a); }
inline float3 bvh_max3(float3 a, float3 b) { return select(a, b, b > a); }

/* ---------------------------------------------------------------- 1. bounds */

kernel void bvh_bounds(global const float *boxes, uint n, uint chunk, global uint *res)
{
    const ulong stride = (ulong)get_global_size(0) * chunk;
    float3 clo = (float3)(INFINITY), chi = (float3)(-INFINITY);
    float3 blo = (float3)(INFINITY), bhi = (float3)(-INFINITY);
    uint bad = 0xFFFFFFFFu;
    for (ulong base = (ulong)get_global_id(0) * chunk; base < n; base += stride) {
        const uint end = (uint)min(base + chunk, (ulong)n);
        for (uint i = (uint)base; i < end; ++i) {
            global const float *p = boxes + 6 * (size_t)i;
            const float3 lo = (float3)(p[0], p[1], p[2]);
            const float3 hi = (float3)(p[3], p[4], p[5]);
            const float3 s = lo + hi;
            /* false for NaN; lo <= hi with a finite sum: lo and hi are finite */
            const int3 ok = (lo <= hi) & (fabs(s) <= (float3)(MAXFLOAT));
            if (!(ok.x & ok.y & ok.z)) {
                bad = min(bad, i);
                continue;
            }
            const float3 c = s * 0.5f;
            clo = bvh_min3(clo, c);
            chi = bvh_max3(chi, c);
            blo = bvh_min3(blo, lo);
            bhi = bvh_max3(bhi, hi);
        }
    }
    if (chi.x >= clo.x) {       /* this item saw a good row */
        atomic_min(res + 0, clvis_key_f32(as_uint(clo.x)));
        atomic_min(res + 1, clvis_key_f32(as_uint(clo.y)));
        atomic_min(res + 2, clvis_key_f32(as_uint(clo.z)));
        atomic_min(res + 3, ~clvis_key_f32(as_uint(chi.x)));
        atomic_min(res + 4, ~clvis_key_f32(as_uint(chi.y)));
        atomic_min(res + 5, ~clvis_key_f32(as_uint(chi.z)));
        atomic_min(res + 6, clvis_key_f32(as_uint(blo.x)));
        atomic_min(res + 7, clvis_key_f32(as_uint(blo.y)));
        atomic_min(res + 8, clvis_key_f32(as_uint(blo.z)));
        atomic_min(res + 9, ~clvis_key_f32(as_uint(bhi.x)));
        atomic_min(res + 10, ~clvis_key_f32(as_uint(bhi.y)));
        atomic_min(res + 11, ~clvis_key_f32(as_uint(bhi.z)));
    }
    if (bad != 0xFFFFFFFFu)
        atomic_min(res + 12, bad);
}

/* ---------------------------------------------------------------- 2. Morton codes */

kernel void bvh_morton(global const float *boxes, uint n, float lox, float loy, float loz,
                       float sx, float sy, float sz, global uint *codes, global uint *iota)
{
    const uint i = get_global_id(0);
    if (i >= n)
        return;
    global const float2 *r = (global const float2 *)boxes + 3 * (size_t)i;
    const float2 a = r[0], b = r[1], c = r[2];      /* lo x, lo y | lo z, hi x | hi y, hi z */
    const float cx = (a.x + b.y) * 0.5f, cy = (a.y + c.x) * 0.5f, cz = (b.x + c.y) * 0.5f;
    codes[i] = clvis_morton3(clvis_morton_quantize((cx - lox) * sx), clvis_morton_quantize((cy - loy) * sy),
                             clvis_morton_quantize((cz - loz) * sz));
    iota[i] = i;
}

/* ---------------------------------------------------------------- 3. leaf boxes */

kernel void bvh_gather(global const float *boxes, global const uint *order, uint n,
                       global float *leaf_boxes)
{
    const uint j = get_global_id(0);
    if (j >= n)
        return;
    global const float2 *src = (global const float2 *)boxes + 3 * (size_t)order[j];
    global float2 *dst = (global float2 *)leaf_boxes + 3 * (size_t)j;
    const float2 a = src[0], b = src[1], c = src[2];
    dst[0] = a;
    dst[1] = b;
    dst[2] = c;
}

/* ---------------------------------------------------------------- 4. hierarchy and boxes */

/* benign race (lbvh-sibling): the stores of a finished node race, in
 * Oclgrind's report, with the loads of its box by the item that finishes its
 * parent (bvh_build); the atomic_xchg hand-off there orders them (see there). */
inline void bvh_store(global clvis_bvh_node *node, float3 lo, float3 hi, uint left, uint right)
{
    node->lo[0] = lo.x; node->lo[1] = lo.y; node->lo[2] = lo.z; node->left = left;
    node->hi[0] = hi.x; node->hi[1] = hi.y; node->hi[2] = hi.z; node->right = right;
}

/* X(x): the xor of the keys at positions x and x + 1 (x + 1 < n); the smaller,
 * the longer their common prefix */
inline ulong bvh_xor(global const uint *codes, uint x)
{
    return ((ulong)(codes[x] ^ codes[x + 1]) << 32) | (x ^ (x + 1));
}

/* the node covering [l, r] (not [0, n - 1]) is the left child of its parent */
inline int bvh_is_left(global const uint *codes, uint n, uint l, uint r)
{
    if (l == 0)
        return 1;
    if (r == n - 1)
        return 0;
    return bvh_xor(codes, r) < bvh_xor(codes, l - 1);
}

/* vec_type_hint: Intel's CPU compiler would run 8 or 16 walks in lock step */
kernel __attribute__((vec_type_hint(float4)))
void bvh_build(global const uint *codes, global const float *leaf_boxes, uint n,
               global clvis_bvh_node *nodes, global uint *meet)
{
    const uint j = get_global_id(0);
    if (j >= n)
        return;
    float3 lo, hi;
    if (n == 1) {
        clvis_bvh_leaf_box(leaf_boxes, 0, &lo, &hi);
        bvh_store(nodes, lo, hi, CLVIS_BVH_LEAF, CLVIS_BVH_NONE);
        return;
    }
    volatile global const clvis_bvh_node *vnodes = nodes;
    /* the current node: positions [l, r], child word `word`, box lo/hi, and
     * whether it is its parent's left child */
    uint l = j, r = j, word = CLVIS_BVH_LEAF | j;
    int left = bvh_is_left(codes, n, j, j);
    while (l != 0 || r != n - 1) {
        const uint split = left ? r : l - 1;
        const uint s = left ? r + 1 : l - 1;        /* the sibling's position next to us */
        uint end, sword;                             /* the sibling's far end, its word */
        float3 slo, shi;
        if (bvh_is_left(codes, n, s, s) != left) {
            /* the sibling is leaf s, ready: go on (of two leaves, the left one's item) */
            if (word & CLVIS_BVH_LEAF) {
                if (!left)
                    return;
                clvis_bvh_leaf_box(leaf_boxes, j, &lo, &hi);
            }
            end = s;
            sword = CLVIS_BVH_LEAF | s;
            clvis_bvh_leaf_box(leaf_boxes, s, &slo, &shi);
        } else {
            if (word & CLVIS_BVH_LEAF)
                return;                 /* the internal sibling's item finishes the parent */
            /* two internal siblings: the second to get here finishes the parent.
             * The fence puts our node (written last round) before the exchange. */
            mem_fence(CLK_GLOBAL_MEM_FENCE);
            end = atomic_xchg(meet + split, left ? l : r);
            if (end == 0xFFFFFFFFu)
                return;
            mem_fence(CLK_GLOBAL_MEM_FENCE);
            sword = left ? split + 1 : split;   /* left child of split g: node g; right: g + 1 */
            /* benign race (lbvh-sibling): the sibling's box, stored with
             * plain stores (bvh_store) by the item that got here first, is
             * loaded here without an atomic. Oclgrind reports every such
             * load against that store: across work-groups its detector
             * counts only atomics on the same address as ordering, and it
             * does not model mem_fence. The order holds all the same. The
             * first item stored the node, then fenced (its stores before its
             * later accesses), then exchanged meet[split]. Exchanges on one
             * word are atomic and totally ordered, and ours returned the
             * first item's end rather than 0xFFFFFFFF, so it came after the
             * first's exchange, which came after the first's stores; our own
             * fence keeps these loads after our exchange. Store, fence,
             * atomic | atomic, fence, load: the release/acquire fence pattern
             * (OpenCL 2.0 spells it atomic_work_item_fence with release and
             * acquire order), in the form OpenCL 1.2 can express, as in
             * Karras's and Apetrei's GPU builders. The loads go through a
             * volatile pointer so that the compiler issues them after the
             * fence rather than reusing an earlier value. Each node is stored
             * once and its box loaded at most once, by this hand-off; its
             * child words are never read here. */
            slo = (float3)(vnodes[sword].lo[0], vnodes[sword].lo[1], vnodes[sword].lo[2]);
            shi = (float3)(vnodes[sword].hi[0], vnodes[sword].hi[1], vnodes[sword].hi[2]);
        }
        const float3 llo = left ? lo : slo, lhi = left ? hi : shi;
        const float3 rlo = left ? slo : lo, rhi = left ? shi : hi;
        lo = bvh_min3(llo, rlo);
        hi = bvh_max3(lhi, rhi);
        const uint lw = left ? word : sword, rw = left ? sword : word;
        if (left)
            r = end;
        else
            l = end;
        /* the parent's number: 0 for the root, else its end next to its own parent's split */
        uint k = 0;
        if (l != 0 || r != n - 1) {
            left = bvh_is_left(codes, n, l, r);
            k = left ? r : l;
        }
        bvh_store(nodes + k, lo, hi, lw, rw);
        word = k;
    }
}
