/* histogram.cl — counts of integer keys per bin.
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/workgroup.h).
 * Defines (all optional):
 *   KEY_T       key type: uint or int                              (default uint)
 *   WG          work-group size; launch with exactly this local size (default 1)
 *   LOCAL_BINS  bins histogram_local keeps in local memory          (default 4096)
 *
 * A key k counts in bin k when 0 <= k < nbins; any other key (negative, or
 * nbins or more) counts in overflow[0] instead. Both kernels ADD to counts
 * (nbins uints) and overflow (1 uint): the host zeroes them first.
 *
 * kernel histogram_local(global const KEY_T *keys, ulong n, ulong per_group,
 *                        uint nbins, global uint *counts,
 *                        global uint *overflow)
 *     nbins <= LOCAL_BINS. n > 0 keys in G = ceil(n / per_group) contiguous
 *     ranges of per_group keys; global size G * WG, local size WG. Each group
 *     counts its range in local memory, then adds its non-zero bins to counts
 *     with global atomics.
 *
 * kernel histogram_global(global const KEY_T *keys, ulong n, uint nbins,
 *                         global uint *counts, global uint *overflow)
 *     Any nbins. Any global size (a multiple of WG); work-item i counts keys
 *     i, i + global size, ... with global atomic increments. For many bins,
 *     where collisions are rare.
 *
 * Memory traffic: n keys read; counts written G * (non-zero bins) times
 * (local) or n times (global), atomically.
 */
#ifndef KEY_T
#define KEY_T uint
#endif
#include "clvis/workgroup.h"

#ifndef WG
#define WG 1
#endif
#ifndef LOCAL_BINS
#define LOCAL_BINS 4096
#endif

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void histogram_local(global const KEY_T *restrict keys, const ulong n,
                     const ulong per_group, const uint nbins,
                     global uint *restrict counts, global uint *restrict overflow)
{
    const uint lid = get_local_id(0);
    ulong start, end;
    clvis_group_range(n, per_group, &start, &end);
    local uint bins[LOCAL_BINS + 1];         /* bins[nbins]: out of range */
    clvis_wg_zero(bins, nbins + 1u);
    for (ulong i = start + lid; i < end; i += WG) {
        const uint k = (uint)keys[i];
        const uint b = (k < nbins) ? k : nbins;
#if WG == 1
        bins[b]++;
#else
        atomic_inc(&bins[b]);
#endif
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint b = lid; b < nbins; b += WG) {
        if (bins[b])
            atomic_add(&counts[b], bins[b]);
    }
    if (lid == 0 && bins[nbins])
        atomic_add(overflow, bins[nbins]);
}

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void histogram_global(global const KEY_T *restrict keys, const ulong n,
                      const uint nbins, global uint *restrict counts,
                      global uint *restrict overflow)
{
    const ulong stride = get_global_size(0);
    for (ulong i = get_global_id(0); i < n; i += stride) {
        const uint k = (uint)keys[i];
        if (k < nbins)
            atomic_inc(&counts[k]);
        else
            atomic_inc(overflow);
    }
}
