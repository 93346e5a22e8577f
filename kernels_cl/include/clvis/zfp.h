/* clvis/zfp.h — decoding one block of a ZFP fixed-rate stream of 3-D float32 data.
 *
 * Inline functions only, for kernels that decode whole volumes
 * (iso/zfp.cl, iso/macrocell.cl) or just the blocks they need (iso/cache.cl),
 * and the block-grid helpers (iso/raytrace.cl too). No other header needed;
 * include guard CLVIS_ZFP_H. The format, as
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
 * GPU note: one work-item decodes a whole block with 64-entry private
 * arrays indexed at run time (coefficient deposit, permutation); that suits
 * CPUs. A GPU layout (a sub-group per block, planes in registers) is future
 * work.
 */
#ifndef CLVIS_ZFP_H
#define CLVIS_ZFP_H

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

/* A bit reader over one block's words. */
typedef struct {
    global const ulong *words;  /* the block's first word */
    uint next;                  /* the next word to load */
    uint nwords;                /* the block's words (= rate) */
    uint avail;                 /* bits left in buf */
    ulong buf;                  /* unread bits, next one lowest; higher bits 0 */
} clvis_zfp_reader;

inline clvis_zfp_reader clvis_zfp_reader_at(global const ulong *stream, ulong block, uint rate)
{
    clvis_zfp_reader r;
    r.words = stream + block * (ulong)rate;
    r.next = 0u;
    r.nwords = rate;
    r.avail = 0u;
    r.buf = 0ul;
    return r;
}

inline ulong clvis_zfp_load_word(clvis_zfp_reader *r)
{
    ulong w = r->next < r->nwords ? r->words[r->next] : 0ul;   /* never past the block */
    r->next += 1u;
    return w;
}

inline uint clvis_zfp_read_bit(clvis_zfp_reader *r)
{
    if (r->avail == 0u) {
        r->buf = clvis_zfp_load_word(r);
        r->avail = 64u;
    }
    uint bit = (uint)(r->buf & 1ul);
    r->buf >>= 1;
    r->avail -= 1u;
    return bit;
}

/* the next n bits (0 <= n <= 64), the first one lowest */
inline ulong clvis_zfp_read_bits(clvis_zfp_reader *r, uint n)
{
    ulong v = r->buf;
    if (r->avail >= n) {
        r->buf = n < 64u ? r->buf >> n : 0ul;
        r->avail -= n;
    } else {
        ulong w = clvis_zfp_load_word(r);
        uint used = n - r->avail;          /* 1..64 bits of w; avail <= 63 here */
        v |= w << r->avail;
        r->buf = used < 64u ? w >> used : 0ul;
        r->avail = 64u - used;
    }
    return n < 64u ? v & ((1ul << n) - 1ul) : v;
}

/* Embedded decoding of 64 uint coefficients with at most `budget` bits
 * (zfp's rate-constrained decode_few_ints with maxprec 64: all 32 planes). */
inline void clvis_zfp_decode_ints(clvis_zfp_reader *r, uint budget, uint *u)
{
    for (uint i = 0; i < 64u; ++i)
        u[i] = 0u;
    uint n = 0u;                           /* coefficients significant so far */
    for (int k = 31; k >= 0 && budget != 0u; --k) {
        /* the first n bits of plane k, verbatim */
        uint m = min(n, budget);
        budget -= m;
        ulong x = clvis_zfp_read_bits(r, m);
        /* group tests, each followed by a unary run to the next one-bit */
        while (budget != 0u && n < 64u) {
            budget -= 1u;
            if (!clvis_zfp_read_bit(r))
                break;
            while (budget != 0u && n < 63u) {
                budget -= 1u;
                if (clvis_zfp_read_bit(r))
                    break;
                n += 1u;
            }
            x |= 1ul << n;                 /* set even if the budget ran out, as zfp does */
            n += 1u;
        }
        /* deposit plane k */
        while (x != 0ul) {
            uint i = 63u - (uint)clz(x & (~x + 1ul));   /* lowest set bit */
            u[i] |= 1u << k;
            x &= x - 1ul;
        }
    }
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
    clvis_zfp_reader r = clvis_zfp_reader_at(stream, block, rate);
    if (!clvis_zfp_read_bit(&r)) {
        for (uint i = 0; i < 64u; ++i)
            q[i] = 0;
        return CLVIS_ZFP_ZERO_BLOCK;
    }
    int emax = (int)clvis_zfp_read_bits(&r, 8u) - CLVIS_ZFP_EBIAS;
    uint u[64];
    clvis_zfp_decode_ints(&r, 64u * rate - 9u, u);
    for (uint i = 0; i < 64u; ++i)
        q[clvis_zfp_perm3[i]] = as_int((u[i] ^ CLVIS_ZFP_NBMASK) - CLVIS_ZFP_NBMASK);
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
    int emax = clvis_zfp_decode_block3i(stream, b, rate, q);
    for (uint i = 0; i < 64u; ++i)
        brick[i] = clvis_zfp_value(q, i, emax);
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
    e[0] = min(4u, nx - 4u * c[0]);
    e[1] = min(4u, ny - 4u * c[1]);
    e[2] = min(4u, nz - 4u * c[2]);
    return 1;
}

#endif /* CLVIS_ZFP_H */
