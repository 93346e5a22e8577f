/* clvis/bvh.h — the LBVH node layout (kernels_cl/gauss/bvh.cl builds it) and
 * its loads. The ray–box test a traversal needs is clvis/ray.h's.
 *
 * Tree
 * ----
 * n primitives (axis-aligned boxes), sorted along a 30-bit Morton curve of
 * their centres: position j of the sorted order is primitive order[j]. The
 * tree is Karras's (HPG 2012) binary radix tree over the sorted codes:
 *
 *   n >= 2: n - 1 internal nodes, node 0 the root. Internal node i covers a
 *           contiguous range of sorted positions that starts or ends at i.
 *   n == 1: one node; its box is the primitive's box, left = CLVIS_BVH_LEAF | 0,
 *           right = CLVIS_BVH_NONE.
 *   n == 0: no node.
 *
 * A child word c is either CLVIS_BVH_LEAF | j (sorted position j: primitive
 * order[j], box leaf_boxes[j]) or an internal node index (< n - 1), or
 * CLVIS_BVH_NONE (only the right child of a 1-primitive tree). Internal node
 * boxes are the exact float unions (component min / max, no rounding) of their
 * children's boxes.
 *
 * clvis_bvh_node, 32 bytes, no padding (numpy: clvis.gauss.bvh.BVH_NODE_DTYPE):
 *
 *   offset  0  float lo[3]   box minimum corner (x, y, z)
 *   offset 12  uint  left    left child word
 *   offset 16  float hi[3]   box maximum corner (x, y, z)
 *   offset 28  uint  right   right child word
 *
 * Leaf boxes: leaf_boxes, n * 6 floats, row j = (lo x, y, z, hi x, y, z) of
 * primitive order[j] (clvis_bvh_leaf_box loads one).
 *
 * clvis_bvh_node_lo/hi(global const clvis_bvh_node *node) -> float3
 * clvis_bvh_leaf_box(global const float *leaf_boxes, uint j, float3 *lo, float3 *hi)
 *     load a box as float3.
 */
#ifndef CLVIS_BVH_H
#define CLVIS_BVH_H

typedef struct {
    float lo[3];    /* box minimum corner */
    uint left;      /* left child word: CLVIS_BVH_LEAF | j, or an internal node index */
    float hi[3];    /* box maximum corner */
    uint right;     /* right child word, or CLVIS_BVH_NONE (1-primitive tree only) */
} clvis_bvh_node;   /* 32 bytes */

#define CLVIS_BVH_LEAF 0x80000000u   /* child & LEAF: a leaf; child & ~LEAF = position j in the sorted order */
#define CLVIS_BVH_NONE 0xFFFFFFFFu   /* no child (only the right child of a 1-primitive tree) */

inline float3 clvis_bvh_node_lo(global const clvis_bvh_node *node)
{
    return (float3)(node->lo[0], node->lo[1], node->lo[2]);
}

inline float3 clvis_bvh_node_hi(global const clvis_bvh_node *node)
{
    return (float3)(node->hi[0], node->hi[1], node->hi[2]);
}

inline void clvis_bvh_leaf_box(global const float *leaf_boxes, uint j, float3 *lo, float3 *hi)
{
    /* scalar loads: PoCL makes slow code of vload3 */
    global const float *r = leaf_boxes + 6 * (size_t)j;
    *lo = (float3)(r[0], r[1], r[2]);
    *hi = (float3)(r[3], r[4], r[5]);
}

#endif /* CLVIS_BVH_H */
