/* clvis/bvh.h — the LBVH node layout (kernels_cl/gauss/bvh.cl builds it) and
 * the ray–box test a traversal kernel needs.
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
 * Ray–box test
 * ------------
 * A ray o + t d. Compute inv_d = clvis_bvh_inv_dir(d) once per ray: 1 / d per
 * component, where a component with |d| < CLVIS_BVH_TINY_DIR (zero included)
 * is first replaced by CLVIS_BVH_TINY_DIR with d's sign (+0 -> +TINY, -0 ->
 * -TINY). So inv_d is finite and nonzero, and (lo - o) * inv_d is never NaN
 * for finite boxes and origins (it may be +-inf, which the min/max handle).
 * A ray parallel to a slab and inside it gets (-huge, +huge) there; outside
 * it, an empty interval. A ray lying exactly in a face plane (o on the face,
 * that component of d zero) moves the way the zero's sign says, as if tilted
 * by TINY: inwards it hits, outwards its interval on that axis ends at t = 0.
 *
 *   int clvis_bvh_slab(float3 o, float3 inv_d, float3 lo, float3 hi,
 *                      float tmin, float tmax, float *t_enter, float *t_exit)
 *
 * intersects [tmin, tmax] with the ray's parameter interval inside the closed
 * box [lo, hi]: *t_enter = max(tmin, entry), *t_exit = min(tmax, exit), and
 * returns 1 when *t_enter <= *t_exit (a hit), else 0. o, inv_d, lo, hi and
 * tmin must not be NaN (tmax may be INFINITY). Conservative: each axis's exit
 * distance is multiplied by 1 + 2 gamma(3) (1 - 2 gamma(3) when negative),
 * i.e. widened by about 3.6e-7 of its magnitude (Ize 2013, "Robust BVH ray
 * traversal"), so float rounding does not make a ray miss a box it touches
 * in exact arithmetic (a grazing miss may be reported as a hit).
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

/* |d| below this is replaced by +-CLVIS_BVH_TINY_DIR before 1/d */
#define CLVIS_BVH_TINY_DIR 1e-20f
/* 2 * gamma(3) = 2 * 3u / (1 - 3u), u = 2^-24, rounded up */
#define CLVIS_BVH_SLAB_PAD 3.58e-7f

inline float3 clvis_bvh_inv_dir(float3 d)
{
    float3 tiny = copysign((float3)(CLVIS_BVH_TINY_DIR), d);
    float3 safe = select(d, tiny, fabs(d) < (float3)(CLVIS_BVH_TINY_DIR));
    return (float3)(1.0f) / safe;
}

inline int clvis_bvh_slab(float3 o, float3 inv_d, float3 lo, float3 hi, float tmin, float tmax,
                          float *t_enter, float *t_exit)
{
    /* NaN-free by construction: compare-and-select (twice as fast as fmin/fmax on PoCL) */
    const float3 t0 = (lo - o) * inv_d;
    const float3 t1 = (hi - o) * inv_d;
    const float3 tn = select(t0, t1, t1 < t0);
    float3 tf = select(t0, t1, t1 > t0);
    /* widen the exits away from 0 by the pad (+-inf stay +-inf) */
    tf = tf * select((float3)(1.0f + CLVIS_BVH_SLAB_PAD), (float3)(1.0f - CLVIS_BVH_SLAB_PAD), tf < 0.0f);
    float a = tn.x > tn.y ? tn.x : tn.y;
    a = tn.z > a ? tn.z : a;
    a = tmin > a ? tmin : a;
    float b = tf.x < tf.y ? tf.x : tf.y;
    b = tf.z < b ? tf.z : b;
    b = tmax < b ? tmax : b;
    *t_enter = a;
    *t_exit = b;
    return a <= b;
}

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
