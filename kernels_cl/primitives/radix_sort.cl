/* radix_sort.cl — one pass of a stable LSD radix sort (keys, optional values).
 *
 * ABI
 * ---
 * Defines (all optional):
 *   KEY_T       key storage word: uint (32-bit keys) or ulong (64-bit)  (uint)
 *   KEY_ORDER   how the bits order: 0 unsigned, 1 signed two's complement,
 *               2 IEEE float (-inf < -0.0 < +0.0 < +inf < NaN; see
 *               clvis/keys.h)                                           (0)
 *   HAS_VALUES  1: move a value with each key                           (0)
 *   VAL_T       value type (any 32-bit type as uint)                    (uint)
 *   RADIX_BITS  bits per pass; RADIX = 2^RADIX_BITS digits              (8)
 *   WG          work-group size, a power of two; launch with exactly
 *               this local size                                         (1)
 *   ITEMS       keys per work-item per tile (used when WG > 1)          (8)
 *   MSD_BITS    radix_bucket_lsd only: the width of the top digit the
 *               buckets come from (the MSD pass's RADIX_BITS)     (RADIX_BITS)
 *   LSD_PASSES  radix_bucket_lsd only, required: its passes      (none)
 *   STAGE       radix_scatter, WG == 1 only: 1 stages each digit's keys
 *               (values) in a private line of 16 and writes full lines
 *               with non-temporal vector stores (where the compiler has
 *               __builtin_nontemporal_store; plain vector stores otherwise).
 *               keys_out and vals_out must be aligned to 16 of their
 *               words (the host checks CL_DEVICE_MEM_BASE_ADDR_ALIGN).
 *               For the MSD pass of arrays past the cache, RADIX_BITS <= 8
 *               (2^RADIX_BITS lines of keys and values in private memory) (0)
 *   Include path: -I kernels_cl/include (clvis/keys.h, clvis/workgroup.h).
 *
 * Partition (as scan.cl): n keys, 0 < n < 2^32, in G contiguous ranges of
 * per_group keys (the last may be shorter), G = ceil(n / per_group); global
 * size G * WG, local size WG. With WG == 1 per_group is any positive count;
 * with WG > 1 it must be TILE = WG * ITEMS (one tile per group, so hist holds
 * per-tile counts).
 * digit(k) = (key(k) >> shift) & (RADIX - 1), key() from KEY_ORDER.
 *
 * kernel radix_upsweep(global const KEY_T *keys, ulong n, ulong per_group,
 *                      uint shift, global uint *hist, global KEY_T *orbits)
 *     hist[d * G + g] = number of keys with digit d in group g's range
 *     (RADIX * G elements, digit-major); orbits[g] = bitwise OR of the raw key
 *     words of the range (the host checks a key_bits promise with it).
 *
 * kernel radix_scatter(global const KEY_T *keys_in, global KEY_T *keys_out,
 *                      global const VAL_T *vals_in, global VAL_T *vals_out,
 *                      ulong n, ulong per_group, uint shift,
 *                      global const uint *offsets)
 *     offsets = exclusive prefix sum of hist (RADIX * G elements, as above):
 *     offsets[d * G + g] is where group g's first key of digit d goes. Writes
 *     every key (and value) to its place in keys_out (vals_out), stably. The
 *     in and out buffers must not overlap. With HAS_VALUES == 0 the value
 *     arguments are not read and may be NULL.
 *
 * kernel radix_bucket_lsd(global KEY_T *keys_a, global KEY_T *keys_b,
 *                         global VAL_T *vals_a, global VAL_T *vals_b,
 *                         ulong n, uint G, global const uint *offsets)
 *                                          (WG == 1 and LSD_PASSES only)
 *     The rest of an MSD-first sort: after one upsweep -> scan -> scatter
 *     pass on the most significant digit (MSD_BITS wide: that pass's
 *     kernels built with RADIX_BITS = MSD_BITS) into keys_a (vals_a),
 *     `offsets` that pass's scanned hist, bucket d (the keys of top digit d)
 *     is [offsets[d G], offsets[(d + 1) G]) (the last ends at n). Work-item d
 *     (global size 2^MSD_BITS, local size 1) sorts bucket d stably on digits
 *     shift = 0, RADIX_BITS, ..., (LSD_PASSES - 1) RADIX_BITS, ping-ponging
 *     between a and b inside the bucket's range: the sorted bucket ends in
 *     keys_b (vals_b) when LSD_PASSES is odd, in keys_a when even. Nothing
 *     outside the bucket is read or written. One read counts every pass's
 *     digits; a pass whose digit all the bucket's keys share is skipped
 *     (clustered keys such as Morton codes), with one copy at the end when
 *     the skips leave the bucket in the other buffer. This kernel's
 *     RADIX_BITS is its own digit (8 to 12; 2^RADIX_BITS x LSD_PASSES
 *     private counters), (LSD_PASSES - 1) RADIX_BITS < bits of KEY_T; the
 *     last digit may reach into the top digit's bits (equal in a bucket).
 *
 * A sort of B-bit keys is ceil(B / RADIX_BITS) passes with shift = 0,
 * RADIX_BITS, ..., each upsweep -> exclusive scan of hist (scan.cl with
 * T = uint) -> scatter, ping-ponging between two buffers. Keys are moved as raw
 * words, so the output holds the input's exact bits.
 *
 * Memory traffic per pass: n K (upsweep) + n (2K + 2V) (scatter), K and V the
 * key and value sizes.
 *
 * MSD first (the CPU form for arrays past the last-level cache): LSD passes
 * over arrays larger than the cache scatter into RADIX open write streams
 * per thread, and each store misses (write-allocate, TLB); at 2^24 pairs the
 * sort moved only 4-6 GB/s. One pass on the top digit cuts the keys into
 * RADIX buckets of ~n / RADIX; each bucket (2^16 pairs = 512 KiB at 2^24,
 * both buffers) then takes its remaining LSD passes in the core's L2. The
 * top digit takes what the 8-bit LSD digits leave of the key's bits, 5 to
 * 12 (clvis/primitives.py): a 44-bit key (the Gaussian tile renderer's 12
 * bits of tile above 32 of depth) is one 12-bit pass into 4096 buckets, one
 * a tile, then 4 LSD passes in each, not an 8-bit top digit of which only 4
 * bits vary (16 buckets of n / 16, out of cache for their 5 LSD passes).
 * The top-digit scatter (STAGE, up to 8 bits) writes whole lines with
 * non-temporal stores: its output is read back only bucket by bucket, and a
 * plain store to a line past the cache first reads the line (staging alone,
 * without the non-temporal store, measured no faster). The buckets then
 * take as few passes as their size pays for (clvis/primitives.py
 * _bucket_digits): 24 bits of 2^16-key buckets in 2 passes of 12 bits
 * (4096 counters, in L1) rather than 3 of 8.
 *
 * With WG == 1 a work-item walks its range in order and writes each key to its
 * digit's next slot (the fast form for CPU devices; RADIX_BITS 8). With
 * WG > 1 a group's tile of WG * ITEMS keys is ranked in local memory
 * (per-work-item digit counters, scanned digit-major), reordered by digit in
 * local memory and written out in runs of equal digits (the GPU form;
 * RADIX * WG counters must fit in local memory, so RADIX_BITS 4 suits WG
 * 128-256). Groups carry no state from tile to tile: an earlier form that did
 * was miscompiled by PoCL 3.0 (LLVM 14), and per-tile counts are the usual
 * GPU layout anyway.
 */
#include "clvis/keys.h"
#include "clvis/workgroup.h"

#ifndef KEY_T
#define KEY_T uint
#endif
#ifndef KEY_ORDER
#define KEY_ORDER 0
#endif
#ifndef HAS_VALUES
#define HAS_VALUES 0
#endif
#ifndef VAL_T
#define VAL_T uint
#endif
#ifndef RADIX_BITS
#define RADIX_BITS 8
#endif
#ifndef WG
#define WG 1
#endif
#ifndef ITEMS
#define ITEMS 8
#endif
#define RADIX (1u << RADIX_BITS)
#ifndef MSD_BITS
#define MSD_BITS RADIX_BITS
#endif
#define MSD_RADIX (1u << MSD_BITS)
#define TILE (WG * ITEMS)
#ifndef STAGE
#define STAGE 0
#endif
/* radix_scatter's staged form: LINE words a digit, written as one vector */
#define LINE 16
#define CLVIS_CAT_(a, b) a##b
#define CLVIS_CAT(a, b) CLVIS_CAT_(a, b)
#define KEY_V CLVIS_CAT(KEY_T, 16)
#define VAL_V CLVIS_CAT(VAL_T, 16)
#if defined(__clang__) && defined(__has_builtin)
#if __has_builtin(__builtin_nontemporal_store)
#define NT_STORE(v, p) __builtin_nontemporal_store((v), (p))
#endif
#endif
#ifndef NT_STORE
#define NT_STORE(v, p) (*(p) = (v))
#endif

#if KEY_ORDER == 0
#define KEY(k) (k)
#elif KEY_ORDER == 1
#define KEY(k) (sizeof(KEY_T) == 8 ? clvis_key_i64(k) : clvis_key_i32(k))
#else
#define KEY(k) (sizeof(KEY_T) == 8 ? clvis_key_f64(k) : clvis_key_f32(k))
#endif
#define DIGIT(k, shift) ((uint)(KEY(k) >> (shift)) & (RADIX - 1))

CLVIS_DEFINE_WG_SCAN(wg_scan, uint)

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void radix_upsweep(global const KEY_T *restrict keys, const ulong n,
                   const ulong per_group, const uint shift,
                   global uint *restrict hist, global KEY_T *restrict orbits)
{
    const ulong g = get_group_id(0);
    const ulong G = get_num_groups(0);
    const uint lid = get_local_id(0);
    ulong start, end;
    clvis_group_range(n, per_group, &start, &end);
    KEY_T ors = 0;

#if WG == 1
    uint count[RADIX];
    for (uint d = 0; d < RADIX; ++d)
        count[d] = 0;
    for (ulong i = start; i < end; ++i) {
        const KEY_T k = keys[i];
        ors |= k;
        count[DIGIT(k, shift)]++;
    }
    for (uint d = 0; d < RADIX; ++d)
        hist[d * G + g] = count[d];
    orbits[g] = ors;
#else
    local uint count[RADIX];
    local KEY_T or_scratch[WG];
    clvis_wg_zero(count, RADIX);
    for (ulong i = start + lid; i < end; i += WG) {
        const KEY_T k = keys[i];
        ors |= k;
        atomic_inc(&count[DIGIT(k, shift)]);
    }
    or_scratch[lid] = ors;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint s = WG / 2; s > 0; s >>= 1) {
        if (lid < s)
            or_scratch[lid] |= or_scratch[lid + s];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    for (uint d = lid; d < RADIX; d += WG)
        hist[d * G + g] = count[d];
    if (lid == 0)
        orbits[g] = or_scratch[0];
#endif
}

kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void radix_scatter(global const KEY_T *restrict keys_in,
                   global KEY_T *restrict keys_out,
                   global const VAL_T *restrict vals_in,
                   global VAL_T *restrict vals_out,
                   const ulong n, const ulong per_group, const uint shift,
                   global const uint *restrict offsets)
{
    const ulong g = get_group_id(0);
    const ulong G = get_num_groups(0);
    const uint lid = get_local_id(0);
    ulong start, end;
    clvis_group_range(n, per_group, &start, &end);

#if WG == 1
    uint next[RADIX];
    for (uint d = 0; d < RADIX; ++d)
        next[d] = offsets[d * G + g];
#if STAGE
    /* each digit's keys (values) gather in a private line of LINE words,
     * written whole with a non-temporal store when it fills: no read for
     * ownership of the destination line, no cache pollution */
    KEY_V stk[RADIX];
#if HAS_VALUES
    VAL_V stv[RADIX];
#endif
    {
        for (ulong i = start; i < end; ++i) {
            const KEY_T k = keys_in[i];
            const uint d = DIGIT(k, shift);
            const uint p = next[d]++;
            const uint s = p & (LINE - 1);
            ((private KEY_T *)&stk[d])[s] = k;
#if HAS_VALUES
            ((private VAL_T *)&stv[d])[s] = vals_in[i];
#endif
            if (s == LINE - 1) {
                const uint l0 = p - (LINE - 1);
                const uint first = offsets[d * G + g];
                if (l0 >= first) {
                    NT_STORE(stk[d], (global KEY_V *)(keys_out + l0));
#if HAS_VALUES
                    NT_STORE(stv[d], (global VAL_V *)(vals_out + l0));
#endif
                } else {    /* the digit's first line starts before this range */
                    for (uint j = first - l0; j < LINE; ++j) {
                        keys_out[l0 + j] = ((private KEY_T *)&stk[d])[j];
#if HAS_VALUES
                        vals_out[l0 + j] = ((private VAL_T *)&stv[d])[j];
#endif
                    }
                }
            }
        }
        /* each digit's last, partial line */
        for (uint d = 0; d < RADIX; ++d) {
            const uint p = next[d];
            const uint l0 = p & ~(LINE - 1u);
            const uint first = offsets[d * G + g];
            for (uint j = (first > l0 ? first : l0) - l0; j < p - l0; ++j) {
                keys_out[l0 + j] = ((private KEY_T *)&stk[d])[j];
#if HAS_VALUES
                vals_out[l0 + j] = ((private VAL_T *)&stv[d])[j];
#endif
            }
        }
        mem_fence(CLK_GLOBAL_MEM_FENCE);
        return;
    }
#endif
    for (ulong i = start; i < end; ++i) {
        const KEY_T k = keys_in[i];
        const uint p = next[DIGIT(k, shift)]++;
        keys_out[p] = k;
#if HAS_VALUES
        vals_out[p] = vals_in[i];
#endif
    }
#else
    /* One tile per group: the host sets per_group = TILE. */
    local KEY_T tkeys[TILE];
#if HAS_VALUES
    local VAL_T tvals[TILE];
#endif
    local uint counters[RADIX * WG];    /* counters[d * WG + t] */
    local uint dest_base[RADIX];        /* output slot of the tile's digit-d run, minus its start in the tile */
    local uint scratch[WG];
    const ulong base = start;
    const uint valid = (uint)(end - start);

    /* coalesced load; then each work-item takes ITEMS consecutive keys */
    for (uint i = 0; i < ITEMS; ++i) {
        const uint j = i * WG + lid;
        if (j < valid) {
            tkeys[j] = keys_in[base + j];
#if HAS_VALUES
            tvals[j] = vals_in[base + j];
#endif
        }
    }
    for (uint d = 0; d < RADIX; ++d)
        counters[d * WG + lid] = 0;
    barrier(CLK_LOCAL_MEM_FENCE);

    KEY_T k[ITEMS];
#if HAS_VALUES
    VAL_T v[ITEMS];
#endif
    uint rank[ITEMS];
    for (uint i = 0; i < ITEMS; ++i) {
        const uint j = lid * ITEMS + i;
        if (j < valid) {
            k[i] = tkeys[j];
#if HAS_VALUES
            v[i] = tvals[j];
#endif
            const uint c = DIGIT(k[i], shift) * WG + lid;
            rank[i] = counters[c];      /* this work-item's column only */
            counters[c] = rank[i] + 1;
        }
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    /* exclusive scan of counters in digit-major order: work-item t scans the
     * RADIX consecutive words [t * RADIX, (t + 1) * RADIX) */
    uint run = 0;
    for (uint d = 0; d < RADIX; ++d) {
        const uint c = counters[lid * RADIX + d];
        counters[lid * RADIX + d] = run;
        run += c;
    }
    uint all;
    const uint before = wg_scan(run, scratch, &all);
    for (uint d = 0; d < RADIX; ++d)
        counters[lid * RADIX + d] += before;
    barrier(CLK_LOCAL_MEM_FENCE);

    /* counters[d * WG] is where digit d's run starts in the tile */
    for (uint d = lid; d < RADIX; d += WG)
        dest_base[d] = offsets[d * G + g] - counters[d * WG];
    for (uint i = 0; i < ITEMS; ++i) {
        if (lid * ITEMS + i < valid) {
            const uint r = counters[DIGIT(k[i], shift) * WG + lid] + rank[i];
            tkeys[r] = k[i];
#if HAS_VALUES
            tvals[r] = v[i];
#endif
        }
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    /* runs of equal digits go to consecutive global slots */
    for (uint i = 0; i < ITEMS; ++i) {
        const uint j = i * WG + lid;
        if (j < valid) {
            const KEY_T key = tkeys[j];
            const uint p = dest_base[DIGIT(key, shift)] + j;
            keys_out[p] = key;
#if HAS_VALUES
            vals_out[p] = tvals[j];
#endif
        }
    }
#endif
}

#if WG == 1 && defined(LSD_PASSES)
kernel __attribute__((reqd_work_group_size(1, 1, 1)))
void radix_bucket_lsd(global KEY_T *restrict keys_a, global KEY_T *restrict keys_b,
                      global VAL_T *restrict vals_a, global VAL_T *restrict vals_b,
                      const ulong n, const uint G, global const uint *restrict offsets)
{
    const uint d = get_global_id(0);
    if (d >= MSD_RADIX)
        return;
    const ulong lo = offsets[d * G];
    const ulong hi = d + 1u < MSD_RADIX ? offsets[(d + 1u) * G] : n;
    if (lo == hi)    /* nothing to sort, nor to read (lo may be n) */
        return;
    global KEY_T *sk = keys_a, *dk = keys_b;
#if HAS_VALUES
    global VAL_T *sv = vals_a, *dv = vals_b;
#endif
    /* every pass's digit counts in one read of the bucket */
    uint count[LSD_PASSES][RADIX];
    for (uint p = 0; p < LSD_PASSES; ++p)
        for (uint e = 0; e < RADIX; ++e)
            count[p][e] = 0;
    for (ulong i = lo; i < hi; ++i) {
        const KEY_T k = sk[i];
        for (uint p = 0; p < LSD_PASSES; ++p)
            count[p][DIGIT(k, p * RADIX_BITS)]++;
    }
    for (uint p = 0; p < LSD_PASSES; ++p) {
        const uint shift = p * RADIX_BITS;
        uint *next = count[p];
        /* a digit every key of the bucket shares moves nothing: skip it */
        if (next[DIGIT(sk[lo], shift)] == (uint)(hi - lo))
            continue;
        uint at = (uint)lo;
        for (uint e = 0; e < RADIX; ++e) {
            const uint c = next[e];
            next[e] = at;
            at += c;
        }
        for (ulong i = lo; i < hi; ++i) {
            const KEY_T k = sk[i];
            const uint q = next[DIGIT(k, shift)]++;
            dk[q] = k;
#if HAS_VALUES
            dv[q] = sv[i];
#endif
        }
        global KEY_T *tk = sk;
        sk = dk;
        dk = tk;
#if HAS_VALUES
        global VAL_T *tv = sv;
        sv = dv;
        dv = tv;
#endif
    }
    /* the bucket must end where the host looks: b for odd LSD_PASSES */
    global KEY_T *want = (LSD_PASSES & 1) ? keys_b : keys_a;
    if (sk != want) {
        for (ulong i = lo; i < hi; ++i) {
            dk[i] = sk[i];
#if HAS_VALUES
            dv[i] = sv[i];
#endif
        }
    }
}
#endif
