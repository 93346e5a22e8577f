/* clvis/zfp.h — decoding one block of a ZFP fixed-rate stream of 3-D float32 data.
 *
 * Inline functions only, for kernels that decode whole volumes
 * (iso/zfp.cl, iso/macrocell.cl) or just the blocks they need (iso/cache.cl),
 * and the block-grid helpers (iso/raytrace.cl too). Includes clvis/inline.h
 * (min and popcount inline: PoCL calls them out of line); include guard
 * CLVIS_ZFP_H. The format, as
 * zfp 1.0 writes it in fixed-rate mode (zfp_stream_set_rate(rate, float, 3,
 * align 0); zfpy.compress_numpy(v, rate=r, write_header=False)):
 *
 * - maxbits = 64 * rate bits per 4x4x4 block, rate an integer in 1..32, so
 *   block b is the `rate` 64-bit words [b * rate, (b + 1) * rate) of the
 *   stream; words are little-endian, bits read least significant first.
 * - Blocks run x fastest, then y, then z; for a C-order float [Z][Y][X]
 *   array, zfp's nx = X, ny = Y, nz = Z; ceil(X/4) * ceil(Y/4) * ceil(Z/4)
 *   blocks. Edge blocks were padded on encode: decode all 64 values, keep the
 *   in-range ones.
 * - Inside a block: 1 bit (0: all 64 values are +0.0f), 8 bits of exponent
 *   emax + 127, then embedded bit-plane coding of 64 negabinary uint
 *   coefficients (planes 31 down to 0, at most maxbits - 9 bits), in the
 *   sequency order clvis_zfp_perm3; then the inverse lifting transform along z, y
 *   and x; value = (float)i * (float)2^(emax - 30), each rounded to nearest
 *   even as zfp does on an IEEE host (2^(emax - 30) is 0 below 2^-149).
 * - In-block order of decoded values: index x + 4 y + 16 z.
 *
 * Bit-exact with zfp's own decoder: integer steps wrap in 32 bits (done in
 * uint), and values that come out subnormal are rounded in integer
 * arithmetic, so devices that flush float denormals decode the same bits.
 *
 * Safety: the reader of a block loads only words [0, rate) of that block
 * (a word index past them reads as 0 and is never loaded), whatever the
 * bits say. Any bit pattern decodes to some finite or infinite values (never
 * NaN): a corrupt stream of the right length gives garbage, not a crash.
 *
 * API (every name starts with clvis_zfp_ / CLVIS_ZFP_; the rest are helpers):
 *   int clvis_zfp_decode_block3i(global const ulong *stream, ulong block, uint rate,
 *                          int *q)
 *       the integer values of block `block` into private q[64]; returns
 *       emax, or CLVIS_ZFP_ZERO_BLOCK for an all-zero block. Reads only words
 *       [block * rate, (block + 1) * rate) of `stream`.
 *   void clvis_zfp_decode_brick(global const ulong *stream, uint rate, uint nblocks, uint b,
 *                         global float *brick)
 *       block b's 64 values into brick (x + 4 y + 16 z); NaN without reading
 *       when b >= nblocks.
 *   int clvis_zfp_grid_cell(ulong b, uint nx, uint ny, uint nz, uint *c)
 *       cell b of an x-fastest grid as c = (x, y, z); 0 if b is beyond it
 *       (the block grid: nx = ceil(X / 4), ...).
 *   uint clvis_zfp_blocks(uint n), uint clvis_zfp_block_id(x, y, z, nbx, nby)
 *       blocks along an axis of n samples (ceil(n / 4)); the id x + nbx (y + nby z).
 *   int clvis_zfp_decode_volume_block(stream, rate, nx, ny, nz, ulong b, uint *c,
 *                                     uint *e, int *q, int *emax)
 *       the prologue of a kernel with a work-item per block of a volume: block
 *       b's grid coordinates c[3], in-volume extent e[3] (<= 4 per axis) and
 *       decoded integers q[64], *emax; 0 (nothing done) when b is beyond the grid.
 *   float clvis_zfp_value(const int *q, uint k, int emax)
 *       value k of a decoded block (+0.0f for an all-zero block).
 *   float clvis_zfp_dequantize(int i, int emax)
 *       value of integer i of a block with exponent emax (not for
 *       CLVIS_ZFP_ZERO_BLOCK: those values are +0.0f). So value k of a block is
 *       emax == CLVIS_ZFP_ZERO_BLOCK ? 0.0f : clvis_zfp_dequantize(q[k], emax).
 *
 *   void clvis_zfp_values(const int *q, int emax, float *v)
 *       all 64 values of a decoded block into private v[64] (clvis_zfp_value
 *       of each; 16 lanes at a time when the block's scale is normal).
 *
 * Why the decoder is shaped this way (CPU profile: entropy decoding was 87 %
 * of the time when each bit was read and deposited one at a time):
 * - planes first: each bit plane is decoded whole into a 64-bit word A[k]
 *   (bit i = coefficient i), and one 32 x 64 bit transpose (two 32 x 32
 *   matrices in the halves of 64-bit words, 5 stages as ulong16 operations)
 *   turns the planes into coefficients; no per-bit scatter;
 * - the bits come through a 64-bit window over a private copy of the
 *   block's words, refilled only when a read needs more bits; each unary
 *   run after a group test is one trailing-zero count (a bit count of the
 *   trailing-zero mask, clvis_il_ctz64: OpenCL 1.2 has no ctz, and PoCL
 *   calls popcount out of line) instead of a loop per bit;
 * - dequantization is one multiply per value (a loop the compiler
 *   vectorizes) when 2^(emax - 30) is normal (nearly every block) and the
 *   per-value integer rounding otherwise.
 * One work-item still decodes one block (as zfp's CUDA decoder does): the
 * plane parser is serial by nature; the transpose and the 16-lane steps are
 * what a CPU's vector units get.
 */
#ifndef CLVIS_ZFP_H
#define CLVIS_ZFP_H

#include "clvis/inline.h"

/* clang (PoCL, Oclgrind) warns under -Wpsabi that the ulong16/int16 builtins
 * below change the ABI on an x86 target without AVX-512. Every function here
 * is inline, so no call crosses an ABI boundary: the warning is silenced for
 * this header only (push/pop), and users of PoCL no longer see "14 warnings
 * generated." on stderr. */
#if defined(__clang__)
#pragma clang diagnostic push
#pragma clang diagnostic ignored "-Wpsabi"
#endif

#define CLVIS_ZFP_BLOCK_VALUES 64
#define CLVIS_ZFP_EBIAS 127
#define CLVIS_ZFP_NBMASK 0xaaaaaaaau
#define CLVIS_ZFP_MAX_RATE 32u

/* coefficient k of the decoded sequence sits at block index clvis_zfp_perm3[k]
 * (x + 4 y + 16 z): (x, y, z) ordered by x + y + z, then x^2 + y^2 + z^2,
 * ties in zfp's order (part of the format) */
constant uchar clvis_zfp_perm3[64] = {
     0,
     1,  4, 16,
    20, 17,  5,
     2,  8, 32,
    21,
     6, 18, 24,  9, 33, 36,
     3, 12, 48,
    22, 25, 37,
    40, 34, 10,
     7, 19, 28, 13, 49, 52,
    41, 38, 26,
    23, 29, 53,
    11, 35, 44, 14, 50, 56,
    42,
    27, 39, 45, 30, 54, 57,
    60, 51, 15,
    43, 46, 58,
    61, 55, 31,
    62, 59, 47,
    63
};

/* A block's words in private memory: w[i] for i < rate, then zeros
 * (the reader never looks past them). Bit p of the block is bit p % 64 of
 * w[p / 64]; the decoder reads at most 64 rate bits, so two zero words of
 * padding let any 64-bit window start anywhere in the block. */
#define CLVIS_ZFP_WORDS (CLVIS_ZFP_MAX_RATE + 2u)

inline void clvis_zfp_load_block(global const ulong *stream, ulong block, uint rate, ulong *w)
{
    global const ulong *src = stream + block * (ulong)rate;
    for (uint i = 0; i < CLVIS_ZFP_WORDS; ++i)
        w[i] = i < rate ? src[i] : 0ul;   /* never past the block */
}

/* bits [pos, pos + 64) of the block, the first one lowest (pos <= 64 rate) */
inline ulong clvis_zfp_peek(const ulong *w, uint pos)
{
    uint i = pos >> 6, s = pos & 63u;
    return (w[i] >> s) | ((w[i + 1u] << 1) << (63u - s));
}

/* trailing zero bits of x (64 for x = 0) */
inline uint clvis_zfp_ctz64(ulong x)
{
    return clvis_il_ctz64(x);
}

/* Embedded decoding of 64 uint coefficients with at most `budget` bits from
 * bit `pos` of the block (zfp's rate-constrained decode_few_ints with maxprec
 * 64: all 32 planes), plane-major: plane k goes to A[k] (bit i = bit k of
 * coefficient i); planes the budget does not reach are 0.
 *
 * The bits come through a 64-bit window `cur` (bits [pos, pos + avail) of
 * the block, higher bits 0), refilled from w only when a read needs more
 * than it holds; each unary run to the next one-bit (after a group test) is
 * one trailing-zero count instead of a bit-by-bit loop. */
inline void clvis_zfp_decode_planes(const ulong *w, uint pos, uint budget, ulong *A)
{
    for (uint k = 0; k < 32u; ++k)
        A[k] = 0ul;
    uint n = 0u;                           /* coefficients significant so far */
    ulong cur = clvis_zfp_peek(w, pos);
    uint avail = 64u;
    for (int k = 31; k >= 0 && budget != 0u; --k) {
        /* the first n bits of plane k, verbatim (m <= 64) */
        uint m = clvis_il_umin(n, budget);
        if (m > avail) {
            cur = clvis_zfp_peek(w, pos);
            avail = 64u;
        }
        ulong x = m < 64u ? cur & ((1ul << m) - 1ul) : cur;
        cur = m < 64u ? cur >> m : 0ul;
        budget -= m;
        pos += m;
        avail -= m;
        /* group tests, each followed by a unary run to the next one-bit */
        while (budget != 0u && n < 64u) {
            if (avail == 0u) {
                cur = clvis_zfp_peek(w, pos);
                avail = 64u;
            }
            ulong bit = cur & 1ul;
            cur >>= 1;
            budget -= 1u;
            pos += 1u;
            avail -= 1u;
            if (bit == 0ul)
                break;
            /* zfp reads at most lim more bits, stopping after a one-bit */
            uint lim = clvis_il_umin(budget, 63u - n);
            uint z = clvis_zfp_ctz64(cur);     /* exact while z < avail */
            if (z >= avail && lim > avail) {
                cur = clvis_zfp_peek(w, pos);
                avail = 64u;
                z = clvis_zfp_ctz64(cur);
            }
            uint used = z < lim ? z + 1u : lim;   /* <= 63 */
            n += clvis_il_umin(z, lim);
            cur >>= used;
            budget -= used;
            pos += used;
            avail -= used;
            x |= 1ul << n;                 /* set even if the budget ran out, as zfp does */
            n += 1u;
        }
        A[k] = x;
    }
}

/* After clvis_zfp_transpose, the value at block index i (x + 4 y + 16 z)
 * is lane clvis_zfp_lane_of[i] of (P lo, Q lo, P hi, Q hi): lanes 0..63 of
 * the low words of P, of Q, then the high words of P and Q. (The lane's
 * coefficient is row r of the transpose, see there, mapped through
 * clvis_zfp_perm3.) */
constant uchar clvis_zfp_lane_of[64] = {
     0, 16, 28, 17,  8, 12, 26, 11,  2, 14, 19, 44,  9, 23, 50, 53,
    24, 20,  6, 27,  4, 10,  5, 56, 22, 21, 40, 54,  7, 36, 33, 59,
    18, 30,  3, 60,  1, 13, 48, 46, 29, 32, 38, 45, 34, 62, 61, 47,
    25, 15, 42, 37, 31, 52, 49, 43, 58, 41, 35, 55, 57, 51, 39, 63
};

/* One stage j of a 32 x 32 bit transpose, on rows r (in P) and r + j (in Q):
 * swaps the j x j bit blocks off the diagonal. */
#define CLVIS_ZFP_TSTAGE(P, Q, j, mask)                                        \
    {                                                                          \
        ulong16 t_ = (((P) >> (ulong)(j)) ^ (Q)) & (ulong16)(mask);            \
        (Q) ^= t_;                                                             \
        (P) ^= t_ << (ulong)(j);                                               \
    }

/* Planes A[0..31] (bit i of A[k] = bit k of coefficient i) to coefficients:
 * the two 32 x 32 bit matrices in the low and high words transposed at
 * once, 5 stages of 16 swaps done as ulong16 operations. Between stages the
 * rows are regrouped so that each stage pairs lane l of P with lane l of Q.
 * On return lane l of P is the coefficient pair (row) r(l), lane l of Q
 * row r(l) + 1, r = (0, 16, 8, 24, 4, 20, 12, 28, 2, 18, ...) (5-bit
 * reversal of 2 l); low word: coefficient r, high word: coefficient 32 + r. */
inline void clvis_zfp_transpose(const ulong16 *A, ulong16 *pp, ulong16 *pq)
{
    ulong16 P = A[0], Q = A[1], t;
    CLVIS_ZFP_TSTAGE(P, Q, 16, 0x0000ffff0000fffful)
    t = (ulong16)(P.lo, Q.lo);
    Q = (ulong16)(P.hi, Q.hi);
    P = t;
    CLVIS_ZFP_TSTAGE(P, Q, 8, 0x00ff00ff00ff00fful)
    t = (ulong16)(P.s012389ab, Q.s012389ab);
    Q = (ulong16)(P.s4567cdef, Q.s4567cdef);
    P = t;
    CLVIS_ZFP_TSTAGE(P, Q, 4, 0x0f0f0f0f0f0f0f0ful)
    t = (ulong16)(P.s014589cd, Q.s014589cd);
    Q = (ulong16)(P.s2367abef, Q.s2367abef);
    P = t;
    CLVIS_ZFP_TSTAGE(P, Q, 2, 0x3333333333333333ul)
    t = (ulong16)(P.even, Q.even);
    Q = (ulong16)(P.odd, Q.odd);
    P = t;
    CLVIS_ZFP_TSTAGE(P, Q, 1, 0x5555555555555555ul)
    *pp = P;
    *pq = Q;
}

/* inverse lifting of the 4 values p[0], p[s], p[2s], p[3s] (wrapping int32) */
inline void clvis_zfp_inv_lift(int *p, uint s)
{
    uint x = as_uint(p[0]), y = as_uint(p[s]), z = as_uint(p[2u * s]), w = as_uint(p[3u * s]);
    y += as_uint(as_int(w) >> 1);
    w -= as_uint(as_int(y) >> 1);
    y += w;
    w -= y - w;
    z += x;
    x -= z - x;
    y += z;
    z -= y - z;
    w += x;
    x -= w - x;
    p[0] = as_int(x);
    p[s] = as_int(y);
    p[2u * s] = as_int(z);
    p[3u * s] = as_int(w);
}

/* the inverse decorrelating transform of a block (index x + 4 y + 16 z):
 * along z, then y, then x */
inline void clvis_zfp_inv_xform3(int *q)
{
    for (uint i = 0; i < 16u; ++i)
        clvis_zfp_inv_lift(q + i, 16u);                          /* i = x + 4 y */
    for (uint z = 0; z < 4u; ++z)
        for (uint x = 0; x < 4u; ++x)
            clvis_zfp_inv_lift(q + 16u * z + x, 4u);
    for (uint i = 0; i < 16u; ++i)
        clvis_zfp_inv_lift(q + 4u * i, 1u);                      /* i = y + 4 z */
}

/* The integer block of block `block` of `stream` into q[64] (index
 * x + 4 y + 16 z); returns emax, or CLVIS_ZFP_ZERO_BLOCK for an all-zero block
 * (q is then all 0). */
#define CLVIS_ZFP_ZERO_BLOCK (-1000)
inline int clvis_zfp_decode_block3i(global const ulong *stream, ulong block, uint rate, int *q)
{
    ulong w[CLVIS_ZFP_WORDS];
    clvis_zfp_load_block(stream, block, rate, w);
    if (!(w[0] & 1ul)) {
        for (uint i = 0; i < 64u; ++i)
            q[i] = 0;
        return CLVIS_ZFP_ZERO_BLOCK;
    }
    int emax = (int)((w[0] >> 1) & 0xfful) - CLVIS_ZFP_EBIAS;
    /* planes and lanes through unions, not vload16 / vstore16 (calls on PoCL) */
    union { ulong16 v[2]; ulong s[32]; } A;
    clvis_zfp_decode_planes(w, 9u, 64u * rate - 9u, A.s);
    ulong16 P, Q;
    clvis_zfp_transpose(A.v, &P, &Q);
    /* negabinary to two's complement, then each value to its block index */
    uint16 nb = (uint16)CLVIS_ZFP_NBMASK;
    union { int16 v[4]; int s[64]; } lanes;
    lanes.v[0] = as_int16((convert_uint16(P) ^ nb) - nb);
    lanes.v[1] = as_int16((convert_uint16(Q) ^ nb) - nb);
    lanes.v[2] = as_int16((convert_uint16(P >> (ulong)32) ^ nb) - nb);
    lanes.v[3] = as_int16((convert_uint16(Q >> (ulong)32) ^ nb) - nb);
    for (uint i = 0; i < 64u; ++i)
        q[i] = lanes.s[clvis_zfp_lane_of[i]];
    clvis_zfp_inv_xform3(q);
    return emax;
}

/* (float)i * (float)2^(emax - 30) rounded as on an IEEE host: the product
 * is exact while 2^(emax - 30) is normal; below, its rounding to a
 * subnormal (ties to even) is done on the bits. emax = CLVIS_ZFP_ZERO_BLOCK: +0. */
inline float clvis_zfp_dequantize(int i, int emax)
{
    int e = emax - 30;
    if (e >= -126)                         /* both factors normal, so is the product (or inf) */
        return convert_float_rte(i) * as_float((uint)(e + 127) << 23);
    uint bits = as_uint(convert_float_rte(i));
    uint sign = bits & 0x80000000u;
    uint mag = bits & 0x7fffffffu;
    if (e < -149 || mag == 0u)             /* 2^e rounds to +0: the product is +-0 */
        return as_float(sign);
    /* |f| = M 2^t, M a 24-bit integer; f * 2^e = M 2^(t + e) */
    uint m = (mag & 0x7fffffu) | 0x800000u;
    int t = (int)(mag >> 23) - 150 + e;
    if (t + 23 >= -126)                    /* a normal result: exact */
        return as_float(sign | ((uint)(t + 23 + 127) << 23) | (m & 0x7fffffu));
    int shift = -149 - t;                  /* bits below 2^-149 to round off, >= 1 */
    if (shift > 25)
        return as_float(sign);
    uint q = m >> shift;
    uint rem = m & ((1u << shift) - 1u);
    uint tie = 1u << (shift - 1);
    if (rem > tie || (rem == tie && (q & 1u)))
        q += 1u;                           /* may carry into the smallest normal: still right */
    return as_float(sign | q);
}

/* Value k of a decoded block: +0.0f for an all-zero block, else
 * clvis_zfp_dequantize(q[k], emax). */
inline float clvis_zfp_value(const int *q, uint k, int emax)
{
    return emax == CLVIS_ZFP_ZERO_BLOCK ? 0.0f : clvis_zfp_dequantize(q[k], emax);
}

/* The 64 values of a decoded block (q, emax from clvis_zfp_decode_block3i)
 * into v[64]: v[k] = clvis_zfp_value(q, k, emax), 16 at a time when the
 * block's scale 2^(emax - 30) is normal (then every product is exact to
 * round, as in clvis_zfp_dequantize's first case). */
inline void clvis_zfp_values(const int *q, int emax, float *v)
{
    if (emax == CLVIS_ZFP_ZERO_BLOCK) {
        for (uint i = 0; i < 64u; ++i)
            v[i] = 0.0f;
    } else if (emax - 30 >= -126) {
        /* element by element, not vload16 / vstore16 (calls on PoCL): the
         * compiler vectorizes the loop itself */
        float scale = as_float((uint)(emax - 30 + 127) << 23);
        for (uint i = 0; i < 64u; ++i)
            v[i] = convert_float_rte(q[i]) * scale;
    } else {
        for (uint i = 0; i < 64u; ++i)
            v[i] = clvis_zfp_dequantize(q[i], emax);
    }
}

/* Block b of the stream decoded into brick[0..63] (x + 4 y + 16 z); NaN
 * everywhere, reading nothing, when b >= nblocks (the stream's block count). */
inline void clvis_zfp_decode_brick(global const ulong *stream, uint rate, uint nblocks, uint b,
                             global float *brick)
{
    if (b >= nblocks) {
        for (uint i = 0; i < 64u; ++i)
            brick[i] = NAN;
        return;
    }
    int q[64];
    float v[64];
    clvis_zfp_values(q, clvis_zfp_decode_block3i(stream, b, rate, q), v);
    for (uint i = 0; i < 64u; ++i)
        brick[i] = v[i];
}

/* Cell b of a grid of nx x ny x nz cells, x fastest: its (x, y, z) into c[3];
 * 0 when b lies beyond the grid (the caller's work-item then has nothing to do). */
inline int clvis_zfp_grid_cell(ulong b, uint nx, uint ny, uint nz, uint *c)
{
    if (b >= (ulong)nx * ny * nz)
        return 0;
    c[0] = (uint)(b % nx);
    ulong rest = b / nx;
    c[1] = (uint)(rest % ny);
    c[2] = (uint)(rest / ny);
    return 1;
}

/* Blocks along an axis of n samples: ceil(n / 4). */
inline uint clvis_zfp_blocks(uint n)
{
    return (n + 3u) >> 2;
}

/* The id of block (x, y, z) of a grid nbx x nby blocks wide, x fastest
 * (the inverse of clvis_zfp_grid_cell; the grid has < 2^32 blocks). */
inline uint clvis_zfp_block_id(uint x, uint y, uint z, uint nbx, uint nby)
{
    return x + nbx * (y + nby * z);
}

/* The prologue of a kernel with one work-item per block of an nx x ny x nz
 * volume: block b's coordinates c[3] in the block grid, its in-volume extent
 * e[3] (min(4, n - 4 c) samples per axis), and its integers q[64] with *emax
 * (clvis_zfp_decode_block3i). Returns 0, decoding nothing, when b lies beyond
 * the grid (the work-item then has nothing to do). */
inline int clvis_zfp_decode_volume_block(global const ulong *stream, uint rate, uint nx, uint ny,
                                         uint nz, ulong b, uint *c, uint *e, int *q, int *emax)
{
    if (!clvis_zfp_grid_cell(b, clvis_zfp_blocks(nx), clvis_zfp_blocks(ny), clvis_zfp_blocks(nz), c))
        return 0;
    *emax = clvis_zfp_decode_block3i(stream, b, rate, q);
    e[0] = clvis_il_umin(4u, nx - 4u * c[0]);
    e[1] = clvis_il_umin(4u, ny - 4u * c[1]);
    e[2] = clvis_il_umin(4u, nz - 4u * c[2]);
    return 1;
}

#if defined(__clang__)
#pragma clang diagnostic pop
#endif

#endif /* CLVIS_ZFP_H */
