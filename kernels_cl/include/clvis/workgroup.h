/* clvis/workgroup.h — work-group collectives through local memory.
 *
 * CLVIS_DEFINE_WG_SCAN(NAME, TYPE) defines
 *
 *     TYPE NAME(TYPE x, local TYPE *scratch, TYPE *total)
 *
 * an exclusive prefix sum of one value per work-item over the work-group, in
 * local-id order (Hillis–Steele, log2(WG) steps). It returns the sum of the
 * values of the work-items with a smaller local id and stores the sum over the
 * whole group in *total. `scratch` holds WG elements of local memory.
 *
 * Requirements: the macro WG is the local size (a power of two, 1 allowed), the
 * work-group is one-dimensional, and every work-item of the group calls the
 * function (it contains barriers). On return `scratch` may be reused.
 *
 * CLVIS_DEFINE_WG_SUM(NAME, TYPE, SCAN) defines
 *
 *     TYPE NAME(global const TYPE *a, ulong count, local TYPE *scratch)
 *
 * the sum a[0] + ... + a[count - 1] computed by the whole work-group (each
 * work-item sums a strided part, then SCAN, a function made by
 * CLVIS_DEFINE_WG_SCAN for TYPE, joins them). Every work-item gets the sum.
 * The primitives use it to turn per-group partial results into the offset of
 * group g (count = g).
 *
 * CLVIS_DEFINE_WG_TOTAL(NAME, TYPE, SCAN) defines
 *
 *     void NAME(TYPE x, local TYPE *scratch, global TYPE *partials)
 *
 * the group-reduction epilogue of the primitives' first passes (scan_reduce,
 * compact_count): partials[get_group_id(0)] = the sum of x over the group
 * (SCAN, made by CLVIS_DEFINE_WG_SCAN, joins them; work-item 0 writes).
 *
 * Plain functions (no WG needed):
 *
 *     void clvis_group_range(ulong n, ulong per_group, ulong *start, ulong *end)
 *         the prologue of every primitive that cuts n elements into
 *         contiguous ranges of per_group, one per group: group
 *         get_group_id(0)'s elements [*start, *end) (the last range may be
 *         shorter, and empty when the group lies past n).
 *     void clvis_wg_zero(local uint *a, uint count)
 *         a[0..count) = 0 by the whole group, then a barrier (the local
 *         counters of histogram and radix sort); every work-item calls it.
 *
 * Only local memory and barriers are used: no subgroup operations and no
 * assumption about a warp or SIMD width, so it runs on every OpenCL 1.2 device.
 */
#ifndef CLVIS_WORKGROUP_H
#define CLVIS_WORKGROUP_H

#include "clvis/inline.h"

#define CLVIS_DEFINE_WG_SCAN(NAME, TYPE)                                        \
inline TYPE NAME(TYPE x, local TYPE *scratch, TYPE *total)                      \
{                                                                               \
    const uint lid = get_local_id(0);                                           \
    scratch[lid] = x;                                                           \
    barrier(CLK_LOCAL_MEM_FENCE);                                               \
    for (uint off = 1; off < WG; off <<= 1) {                                   \
        TYPE y = (lid >= off) ? scratch[lid - off] : (TYPE)0;                   \
        barrier(CLK_LOCAL_MEM_FENCE);                                           \
        scratch[lid] += y;                                                      \
        barrier(CLK_LOCAL_MEM_FENCE);                                           \
    }                                                                           \
    TYPE excl = (lid > 0) ? scratch[lid - 1] : (TYPE)0;                         \
    *total = scratch[WG - 1];                                                   \
    barrier(CLK_LOCAL_MEM_FENCE);                                               \
    return excl;                                                                \
}

#define CLVIS_DEFINE_WG_SUM(NAME, TYPE, SCAN)                                   \
inline TYPE NAME(global const TYPE *a, const ulong count, local TYPE *scratch)  \
{                                                                               \
    TYPE s = 0;                                                                 \
    for (ulong k = get_local_id(0); k < count; k += WG)                         \
        s += a[k];                                                              \
    TYPE total;                                                                 \
    SCAN(s, scratch, &total);                                                   \
    return total;                                                               \
}

#define CLVIS_DEFINE_WG_TOTAL(NAME, TYPE, SCAN)                                 \
inline void NAME(TYPE x, local TYPE *scratch, global TYPE *partials)            \
{                                                                               \
    TYPE total;                                                                 \
    SCAN(x, scratch, &total);                                                   \
    if (get_local_id(0) == 0)                                                   \
        partials[get_group_id(0)] = total;                                      \
}

inline void clvis_group_range(const ulong n, const ulong per_group, ulong *start, ulong *end)
{
    *start = get_group_id(0) * per_group;
    *end = clvis_il_ulmin(n, *start + per_group);
}

inline void clvis_wg_zero(local uint *a, const uint count)
{
    for (uint i = get_local_id(0); i < count; i += get_local_size(0))
        a[i] = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
}

#endif /* CLVIS_WORKGROUP_H */
