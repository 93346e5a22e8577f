/* compact.cl — stable stream compaction: keep the rows whose flag is non-zero.
 *
 * ABI
 * ---
 * Defines (all optional):
 *   FLAG_T  flag type: uchar, ushort, uint or ulong              (default uchar)
 *   ELEM_T  element type copied by compact_scatter: uchar,
 *           ushort, uint or ulong (any data of that width)       (default uint)
 *   ROW     elements per row: row i is x[i*ROW .. i*ROW+ROW-1]    (default 1)
 *   WG      work-group size, a power of two; launch with exactly
 *           this local size                                      (default 1)
 *   ITEMS   rows per work-item per tile; TILE = WG * ITEMS       (default 16)
 *   Include path: -I kernels_cl/include (uses clvis/workgroup.h).
 *
 * Partition (as scan.cl): n rows, n > 0 and n < 2^32, split into G contiguous
 * ranges of per_group rows (a multiple of TILE; the last may be shorter),
 * G = ceil(n / per_group); global size G * WG, local size WG.
 *
 * kernel compact_count(global const FLAG_T *flags, ulong n, ulong per_group,
 *                      global uint *counts)
 *     counts[g] = number of non-zero flags in group g's range (G elements).
 *
 * kernel compact_scatter(global const ELEM_T *x, global const FLAG_T *flags,
 *                        global ELEM_T *out, ulong n, ulong per_group,
 *                        global const uint *counts, global uint *total)
 *     The kept rows, in input order, to out[0 .. total*ROW); total[0] = number
 *     kept (written by the last group). counts is compact_count's output for
 *     the same partition. out holds at least n*ROW elements and must not
 *     overlap x; nothing at or past out[total*ROW] is written.
 *
 * kernel compact_indices(global const FLAG_T *flags, global uint *out,
 *                        ulong n, ulong per_group, global const uint *counts,
 *                        global uint *total)
 *     The indices of the non-zero flags, ascending, to out[0 .. total);
 *     otherwise as compact_scatter.
 *
 * Memory traffic: flags read twice (n F bytes each), kept rows written once
 * (k R bytes); compact_scatter reads every row (n R bytes).
 *
 * A range's output starts at the sum of the counts of the ranges before it.
 * With WG == 1 one work-item walks its range writing without branches on the
 * flag (a row not kept is written where the next kept row will land, and then
 * overwritten); with WG > 1 each tile's work-items take ITEMS consecutive rows
 * and a work-group scan of their counts gives each its output offset.
 */
#include "clvis/workgroup.h"

#ifndef FLAG_T
#define FLAG_T uchar
#endif
#ifndef ELEM_T
#define ELEM_T uint
#endif
#ifndef ROW
#define ROW 1
#endif
#ifndef WG
#define WG 1
#endif
#ifndef ITEMS
#define ITEMS 16
#endif
#define TILE (WG * ITEMS)

CLVIS_DEFINE_WG_SCAN(wg_scan, uint)
CLVIS_DEFINE_WG_SUM(sum_before, uint, wg_scan)
CLVIS_DEFINE_WG_TOTAL(wg_total, uint, wg_scan)

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void compact_count(global const FLAG_T *restrict flags, const ulong n,
                   const ulong per_group, global uint *restrict counts)
{
    const uint lid = get_local_id(0);
    ulong start, end;
    clvis_group_range(n, per_group, &start, &end);
    uint c = 0;
    for (ulong i = start + lid; i < end; i += WG)
        c += (flags[i] != 0);
    local uint scratch[WG];
    wg_total(c, scratch, counts);
}

/* Copy row `i` of x, or write the index i, to output slot `pos`. */
inline void put(global const ELEM_T *x, global ELEM_T *out_rows,
                global uint *out_idx, const int write_index,
                const ulong i, const uint pos)
{
    if (write_index) {
        out_idx[pos] = (uint)i;
    } else {
        for (int r = 0; r < ROW; ++r)
            out_rows[(ulong)pos * ROW + r] = x[i * ROW + r];
    }
}

/* The body of both scatter kernels. write_index is a constant at each call,
 * so the compiler keeps one of put()'s branches. */
inline void compact_range(global const ELEM_T *x, global const FLAG_T *flags,
                          global ELEM_T *out_rows, global uint *out_idx,
                          const int write_index, const ulong n,
                          const ulong per_group, global const uint *counts,
                          global uint *total, local uint *scratch)
{
    const ulong g = get_group_id(0);
    const uint lid = get_local_id(0);
    ulong start, end;
    clvis_group_range(n, per_group, &start, &end);
    const uint first = sum_before(counts, g, scratch);
    const uint stop = first + counts[g];   /* this range's output is [first, stop) */

#if WG == 1
    uint pos = first;
    for (ulong i = start; i < end; ++i) {
        const uint keep = (flags[i] != 0);
        if (pos < stop)
            put(x, out_rows, out_idx, write_index, i, pos);
        pos += keep;
    }
#else
    uint pos = first;
    for (ulong base = start; base < end; base += TILE) {
        const ulong mine = base + (ulong)lid * ITEMS;
        uint c = 0;
        for (uint j = 0; j < ITEMS; ++j)
            c += (mine + j < end) && (flags[mine + j] != 0);
        uint tile_total;
        uint p = pos + wg_scan(c, scratch, &tile_total);
        for (uint j = 0; j < ITEMS; ++j) {
            if (mine + j < end && flags[mine + j] != 0)
                put(x, out_rows, out_idx, write_index, mine + j, p++);
        }
        pos += tile_total;
    }
#endif
    if (lid == 0 && g == get_num_groups(0) - 1)
        total[0] = stop;
}

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void compact_scatter(global const ELEM_T *restrict x,
                     global const FLAG_T *restrict flags,
                     global ELEM_T *restrict out, const ulong n,
                     const ulong per_group, global const uint *restrict counts,
                     global uint *restrict total)
{
    local uint scratch[WG];
    compact_range(x, flags, out, 0, 0, n, per_group, counts, total, scratch);
}

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void compact_indices(global const FLAG_T *restrict flags,
                     global uint *restrict out, const ulong n,
                     const ulong per_group, global const uint *restrict counts,
                     global uint *restrict total)
{
    local uint scratch[WG];
    compact_range(0, flags, 0, out, 1, n, per_group, counts, total, scratch);
}
