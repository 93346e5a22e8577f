/* scan.cl — prefix sums (inclusive or exclusive) by reduce-then-scan.
 *
 * ABI
 * ---
 * Defines (all optional):
 *   T      element type: int, uint, long, ulong or float          (default uint)
 *   WG     work-group size, a power of two; launch with exactly
 *          this local size (reqd_work_group_size)                  (default 1)
 *   ITEMS  elements per work-item per tile; TILE = WG * ITEMS      (default 16)
 *   Include path: -I kernels_cl/include (uses clvis/workgroup.h).
 *
 * Partition shared by both kernels: the n elements are split into G contiguous
 * ranges of `per_group` elements (a multiple of TILE; the last range may be
 * shorter), G = ceil(n / per_group), n > 0. Group g owns
 * [g * per_group, min(n, (g + 1) * per_group)). Both kernels are launched with
 * global size G * WG and local size WG.
 *
 * kernel scan_reduce(global const T *in, ulong n, ulong per_group,
 *                    global T *partials)
 *     partials[g] = sum of group g's range. partials holds G elements.
 *
 * kernel scan_downsweep(global const T *in, global T *out, ulong n,
 *                       ulong per_group, global const T *partials,
 *                       uint exclusive, global T *total)
 *     out[i] = in[0] + ... + in[i]      (exclusive == 0)
 *     out[i] = in[0] + ... + in[i - 1]  (exclusive != 0; out[0] = 0)
 *     total[0] = in[0] + ... + in[n - 1] (written by the last group).
 *     partials must hold scan_reduce's output for the same n, per_group, G.
 *     out may be the same buffer as in (in-place scan).
 *
 * Memory traffic: reads n + writes 0 (reduce), reads n + writes n (downsweep):
 * 3 n words, plus G words of partials.
 *
 * Arithmetic: integers wrap modulo 2^bits (as numpy's cumsum with the same
 * dtype). float sums are rounded in a fixed order that depends only on n,
 * per_group, WG and ITEMS, so repeated runs give identical bits; the order
 * differs from a sequential sum, so results differ from it by rounding.
 * NaN and Inf propagate as IEEE 754 says.
 *
 * Within a range each group walks tiles in order, carrying the running sum.
 * With WG == 1 one work-item takes two 32-byte vectors of consecutive elements
 * at a time with an in-register prefix (the fast form for CPU devices; ITEMS
 * then only sets the reduce's independent accumulators); with WG > 1 a
 * tile of TILE elements is loaded coalesced into local memory, each work-item
 * scans ITEMS consecutive elements and a work-group scan joins the work-items
 * (the GPU form).
 */
#include "clvis/workgroup.h"

#ifndef T
#define T uint
#endif
#ifndef WG
#define WG 1
#endif
#ifndef ITEMS
#define ITEMS 16
#endif
#define TILE (WG * ITEMS)

/* WG == 1 works on 32-byte vectors (8 lanes of 32-bit T, 4 of 64-bit T): the
 * widest that CPU drivers without AVX-512 code generation handle well (PoCL
 * 3.0 fails to build kernels using 512-bit vectors on such targets). */
#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)
#define SIZEOF_int 4
#define SIZEOF_uint 4
#define SIZEOF_float 4
#define SIZEOF_long 8
#define SIZEOF_ulong 8
#if CAT(SIZEOF_, T) == 8
#define VW 4
#else
#define VW 8
#endif
#define TV CAT(T, VW)           /* e.g. int8, long4 */
#define VLOAD CAT(vload, VW)
#define VSTORE CAT(vstore, VW)

#if VW == 8
/* in-register inclusive prefix: shift by 1, 2, 4 lanes and add */
inline TV vprefix(TV a)
{
    a += (TV)((T)0, a.s0123, a.s456);
    a += (TV)((T)0, (T)0, a.s0123, a.s45);
    a += (TV)((T)0, (T)0, (T)0, (T)0, a.s0123);
    return a;
}
/* the lanes moved up by one, `first` in lane 0 */
inline TV vshift(TV a, T first) { return (TV)(first, a.s0123, a.s456); }
#define VLAST(a) ((a).s7)
#else
inline TV vprefix(TV a)
{
    a += (TV)((T)0, a.s012);
    a += (TV)((T)0, (T)0, a.s01);
    return a;
}
inline TV vshift(TV a, T first) { return (TV)(first, a.s012); }
#define VLAST(a) ((a).s3)
#endif

CLVIS_DEFINE_WG_SCAN(wg_scan, T)
CLVIS_DEFINE_WG_SUM(sum_before, T, wg_scan)

#if WG > 1
/* local-memory index with one pad word every 32, against bank conflicts */
#define PAD(i) ((i) + ((i) >> 5))
#define TILE_LOCAL (TILE + (TILE >> 5) + 1)
#endif

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void scan_reduce(global const T *restrict in, const ulong n,
                 const ulong per_group, global T *restrict partials)
{
    const ulong g = get_group_id(0);
    const uint lid = get_local_id(0);
    const ulong start = g * per_group;
    const ulong end = min(n, start + per_group);

    /* ITEMS independent accumulators: a fixed summation order for floats that
     * the compiler can still vectorise. */
    T lane[ITEMS];
    for (int i = 0; i < ITEMS; ++i)
        lane[i] = 0;
    ulong base = start;
    for (; base + TILE <= end; base += TILE) {
        global const T *p = in + base + lid;
        for (int i = 0; i < ITEMS; ++i)
            lane[i] += p[i * WG];
    }
    for (ulong i = base + lid; i < end; i += WG)
        lane[0] += in[i];

    T acc = 0;
    for (int i = 0; i < ITEMS; ++i)
        acc += lane[i];
    local T scratch[WG];
    T total;
    wg_scan(acc, scratch, &total);
    if (lid == 0)
        partials[g] = total;
}

#if WG > 1
/* Scan `valid` (<= TILE) elements at in[base..] into out[base..], starting
 * from carry; returns the tile's sum. Every work-item of the group calls it. */
inline T scan_tile(global const T *in, global T *out, const ulong base,
                   const uint valid, const T carry, const uint exclusive,
                   local T *tile, local T *scratch)
{
    const uint lid = get_local_id(0);
    for (uint i = 0; i < ITEMS; ++i) {
        const uint j = i * WG + lid;
        tile[PAD(j)] = (j < valid) ? in[base + j] : (T)0;
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    T v[ITEMS];
    T run = 0;
    for (uint i = 0; i < ITEMS; ++i) {
        v[i] = tile[PAD(lid * ITEMS + i)];
        run += v[i];
    }
    T sum;
    const T before = wg_scan(run, scratch, &sum);
    T pre = 0;
    for (uint i = 0; i < ITEMS; ++i) {
        const T inclusive = pre + v[i];
        tile[PAD(lid * ITEMS + i)] = carry + (before + (exclusive ? pre : inclusive));
        pre = inclusive;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint i = 0; i < ITEMS; ++i) {
        const uint j = i * WG + lid;
        if (j < valid)
            out[base + j] = tile[PAD(j)];
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    return sum;
}
#endif

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void scan_downsweep(global const T *in, global T *out, const ulong n,
                    const ulong per_group, global const T *partials,
                    const uint exclusive, global T *total)
{
    const ulong g = get_group_id(0);
    const ulong start = g * per_group;
    const ulong end = min(n, start + per_group);
    ulong base = start;
    local T scratch[WG];
    T carry = sum_before(partials, g, scratch);

#if WG > 1
    local T tile[TILE_LOCAL];
    for (; base < end; base += TILE)
        carry += scan_tile(in, out, base, (uint)min((ulong)TILE, end - base), carry,
                           exclusive, tile, scratch);
    if (get_local_id(0) == 0 && g == get_num_groups(0) - 1)
        total[0] = carry;
#else
    /* One work-item walks its range two vectors (2 * VW elements) at a time:
     * an in-register prefix of each, then the carry added to all lanes, so the
     * carried dependency is one add per 2 * VW elements and the rest
     * vectorises. */
    for (; base + 2 * VW <= end; base += 2 * VW) {
        TV a = vprefix(VLOAD(0, in + base));
        TV b = vprefix(VLOAD(1, in + base));
        b += VLAST(a);
        const T sum = VLAST(b);
        if (exclusive) {
            b = vshift(b, VLAST(a));
            a = vshift(a, (T)0);
        }
        VSTORE(a + carry, 0, out + base);
        VSTORE(b + carry, 1, out + base);
        carry += sum;
    }
    for (; base < end; ++base) {
        const T x = in[base];
        out[base] = exclusive ? carry : carry + x;
        carry += x;
    }
    if (g == get_num_groups(0) - 1)
        total[0] = carry;
#endif
}
