/* scan.cl — prefix sums (inclusive or exclusive): reduce-then-scan, and a
 * single-pass chained scan with decoupled fallback for 32-bit integers on
 * CPU devices.
 *
 * ABI
 * ---
 * Defines (all optional):
 *   T      element type: int, uint, long, ulong or float          (default uint)
 *   WG     work-group size, a power of two; launch with exactly
 *          this local size (reqd_work_group_size)                  (default 1)
 *   ITEMS  elements per work-item per tile; TILE = WG * ITEMS      (default 16)
 *   CLVIS_INT64_ATOMICS  set by the host when the device has
 *          cl_khr_int64_base_atomics: enables scan_chained
 *   SCAN_TEST_FALLBACK   testing only: scan_chained ignores what other
 *          groups publish, so every look-back takes the fallback
 *   Include path: -I kernels_cl/include (uses clvis/workgroup.h, clvis/inline.h).
 *
 * Partition shared by the kernels: the n elements are split into G contiguous
 * ranges of `per_group` elements (a multiple of TILE; the last range may be
 * shorter), G = ceil(n / per_group), n > 0. Range g is
 * [g * per_group, min(n, (g + 1) * per_group)). Launch with global size
 * G * WG and local size WG.
 *
 * Reduce-then-scan (any T, any WG), two launches:
 *
 * kernel scan_reduce(global const T *in, ulong n, ulong per_group,
 *                    global T *partials)
 *     partials[g] = sum of range g. partials holds G elements.
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
 *     Memory traffic: reads n (reduce), reads n + writes n (downsweep):
 *     3 n words, plus G words of partials.
 *
 * Chained scan (WG == 1, T int or uint, CLVIS_INT64_ATOMICS), one launch:
 *
 * kernel scan_chained(global const T *in, global T *out, ulong n,
 *                     ulong per_group, global ulong *status, uint exclusive,
 *                     global T *total)
 *     out and total as scan_downsweep (out must not overlap in). status holds
 *     G + 1 ulongs, zero before the launch. Global size G, local size 1.
 *     Each group takes the next range index from the counter status[G] (so
 *     ranges are handed out in the order groups start), sums its range,
 *     publishes status[g] = 1 << 32 | sum, then looks back: a predecessor's
 *     published word (1: its range's sum, 2: the sum of everything up to its
 *     end) is added; an unpublished range is summed by this group itself, 4096
 *     elements at a time, stopping as soon as its owner publishes. No group
 *     ever waits for another (no forward-progress assumption). Then it
 *     publishes 2 << 32 | inclusive sum and scans its range, which its first
 *     read left in cache. State and value share one word written and read
 *     with 64-bit atomics, so no ordering between memory locations is needed.
 *     Integer sums are exact in any order: the output is identical to the
 *     reduce-then-scan's.
 *
 *     Memory traffic: reads n + writes n from memory (the second read of a
 *     range hits the cache), plus any ranges summed in fallback.
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
 * then only sets the number of independent accumulators of its sums); with
 * WG > 1 a tile of TILE elements is loaded coalesced into local memory, each
 * work-item scans ITEMS consecutive elements and a work-group scan joins the
 * work-items (the GPU form).
 */
#include "clvis/inline.h"
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
#define INT32_int 1
#define INT32_uint 1
#define INT32_long 0
#define INT32_ulong 0
#define INT32_float 0
#if CAT(SIZEOF_, T) == 8
#define VW 4
#else
#define VW 8
#endif
#define TV CAT(T, VW)           /* e.g. int8, long4 */
/* vloadN / vstoreN written inline (clvis/inline.h: PoCL calls them out of line) */
#define VLOAD(k, p) CAT(CLVIS_IL_VLOAD, VW)(TV, (p) + (k) * VW)
#define VSTORE(v, k, p) CAT(CLVIS_IL_VSTORE, VW)((v), (p) + (k) * VW)

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
CLVIS_DEFINE_WG_TOTAL(wg_total, T, wg_scan)

#if WG > 1
/* local-memory index with one pad word every 32, against bank conflicts */
#define PAD(i) ((i) + ((i) >> 5))
#define TILE_LOCAL (TILE + (TILE >> 5) + 1)
#endif

/* This work-item's share of the sum of in[start, end): elements lid,
 * lid + WG, ... in ITEMS independent accumulators (a fixed summation order
 * for floats that the compiler can still vectorise). */
inline T reduce_items(global const T *in, const ulong start, const ulong end)
{
    const uint lid = get_local_id(0);
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
    return acc;
}

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void scan_reduce(global const T *restrict in, const ulong n,
                 const ulong per_group, global T *restrict partials)
{
    ulong start, end;
    clvis_group_range(n, per_group, &start, &end);
    local T scratch[WG];
    wg_total(reduce_items(in, start, end), scratch, partials);
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

#if WG == 1
/* One work-item scans in[base, end) into out from `carry`, two vectors
 * (2 * VW elements) at a time: an in-register prefix of each, then the carry
 * added to all lanes, so the carried dependency is one add per 2 * VW
 * elements and the rest vectorises. Returns the carry after the range. */
inline T scan_serial(global const T *in, global T *out, ulong base,
                     const ulong end, T carry, const uint exclusive)
{
    for (; base + 2 * VW <= end; base += 2 * VW) {
        TV a = vprefix(VLOAD(0, in + base));
        TV b = vprefix(VLOAD(1, in + base));
        b += VLAST(a);
        const T sum = VLAST(b);
        if (exclusive) {
            b = vshift(b, VLAST(a));
            a = vshift(a, (T)0);
        }
        a += carry;
        b += carry;
        VSTORE(a, 0, out + base);
        VSTORE(b, 1, out + base);
        carry += sum;
    }
    for (; base < end; ++base) {
        const T x = in[base];
        out[base] = exclusive ? carry : carry + x;
        carry += x;
    }
    return carry;
}
#endif

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void scan_downsweep(global const T *in, global T *out, const ulong n,
                    const ulong per_group, global const T *partials,
                    const uint exclusive, global T *total)
{
    const ulong g = get_group_id(0);
    const ulong start = g * per_group;
    const ulong end = clvis_il_ulmin(n, start + per_group);
    ulong base = start;
    local T scratch[WG];
    T carry = sum_before(partials, g, scratch);

#if WG > 1
    local T tile[TILE_LOCAL];
    for (; base < end; base += TILE)
        carry += scan_tile(in, out, base, (uint)clvis_il_ulmin((ulong)TILE, end - base), carry,
                           exclusive, tile, scratch);
    if (get_local_id(0) == 0 && g == get_num_groups(0) - 1)
        total[0] = carry;
#else
    carry = scan_serial(in, out, base, end, carry, exclusive);
    if (g == get_num_groups(0) - 1)
        total[0] = carry;
#endif
}


#if WG == 1 && CAT(INT32_, T) && defined(CLVIS_INT64_ATOMICS)
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#define CAT_AS(t) CAT(as_, t)
#define PUBLISHED_SUM 1ul         /* status word: the range's sum */
#define PUBLISHED_PREFIX 2ul      /* status word: the sum through the range's end */
#define FALLBACK_CHUNK 4096

inline ulong status_word(const ulong state, const T value)
{
    return (state << 32) | (ulong)as_uint(value);
}

inline ulong read_status(volatile global ulong *status, const ulong k)
{
#ifdef SCAN_TEST_FALLBACK
    (void)status; (void)k;
    return 0;
#else
    return atom_add(&status[k], 0ul);
#endif
}

kernel __attribute__((reqd_work_group_size(1, 1, 1)))
void scan_chained(global const T *restrict in, global T *restrict out,
                  const ulong n, const ulong per_group,
                  volatile global ulong *status, const uint exclusive,
                  global T *restrict total)
{
    const ulong G = get_num_groups(0);
    const ulong g = atom_inc(&status[G]);       /* ranges in start order */
    const ulong start = g * per_group;
    const ulong end = clvis_il_ulmin(n, start + per_group);
    const T sum = reduce_items(in, start, end);
    atom_xchg(&status[g], status_word(PUBLISHED_SUM, sum));

    T prefix = 0;
    for (long k = (long)g - 1; k >= 0; --k) {
        ulong w = read_status(status, (ulong)k);
        if ((w >> 32) == 0) {
            /* not published: sum range k here, chunk by chunk, until done or
             * until its group publishes after all */
            const ulong ks = (ulong)k * per_group;
            const ulong ke = clvis_il_ulmin(n, ks + per_group);
            T own = 0;
            for (ulong pos = ks; pos < ke && (w >> 32) == 0; pos += FALLBACK_CHUNK) {
                own += reduce_items(in, pos, clvis_il_ulmin(ke, pos + FALLBACK_CHUNK));
                w = read_status(status, (ulong)k);
            }
            if ((w >> 32) == 0) {
                prefix += own;
                continue;
            }
        }
        prefix += CAT_AS(T)((uint)w);
        if ((w >> 32) == PUBLISHED_PREFIX)
            break;
    }
    atom_xchg(&status[g], status_word(PUBLISHED_PREFIX, prefix + sum));
    const T last = scan_serial(in, out, start, end, prefix, exclusive);
    if (g == G - 1)
        total[0] = last;
}
#endif
