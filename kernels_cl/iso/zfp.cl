/* zfp.cl — decoding ZFP fixed-rate streams of 3-D float32 volumes.
 *
 * ABI
 * ---
 * Include path: -I kernels_cl/include (includes clvis/zfp.h).
 * No defines, no compiler flags. The block-decoding kernels carry
 * vec_type_hint(ulong16): they do their own vector work (zfp.h's transpose
 * and dequantization), and the hint keeps Intel's CPU compiler from also
 * vectorizing across work-items, whose data-dependent bit parsing then
 * diverges lane by lane (3x slower there; PoCL and GPUs ignore it). Includes clvis/zfp.h (the stream format and
 * the per-block decode, documented there); bit-exact with zfp 1.0's own
 * decompression (zfpy.compress_numpy(v, rate=r, write_header=False)).
 *
 * stream: the headerless fixed-rate stream as ulong words (little-endian
 *   64-bit words; a byte buffer of 8 * words bytes). With rate r (an integer
 *   in 1..32) every 4x4x4 block takes exactly r words: block b is words
 *   [b r, (b + 1) r). The host must pass a buffer of at least nblocks * r
 *   words; no kernel reads any other word (not even for corrupt contents).
 * Volume: a C-order float array [nz][ny][nx] (numpy [Z, Y, X]); blocks
 *   (bx, by, bz) with b = bx + nbx (by + nby bz), nb_ = ceil(n_ / 4): x
 *   fastest. In-block order of values (a "brick"): index x + 4 y + 16 z.
 *
 * kernel decode_volume(global const ulong *stream, uint rate,
 *                      uint nx, uint ny, uint nz, global float *out)
 *     out[(z ny + y) nx + x] = the decoded value of voxel (x, y, z), for the
 *     whole volume (out: nx ny nz floats). One work-item per block: global
 *     size >= nbx nby nbz (extra items return), any local size (clvis: 64).
 *
 * kernel decode_blocks(global const ulong *stream, uint rate,
 *                      uint nblocks_total, global const uint *ids, uint count,
 *                      global float *out_bricks)
 *     out_bricks[64 j + i] = value i (x + 4 y + 16 z) of block ids[j], for
 *     j < count (out_bricks: 64 count floats). An id >= nblocks_total (the
 *     stream's block count) reads nothing and gives a brick of NaN. One
 *     work-item per id: global size >= count, any local size (clvis: 64).
 */
#include "clvis/zfp.h"

kernel __attribute__((vec_type_hint(ulong16))) void decode_volume(global const ulong *stream, uint rate, uint nx, uint ny, uint nz,
                          global float *out)
{
    uint c[3], e[3];
    int q[64], emax;
    if (!clvis_zfp_decode_volume_block(stream, rate, nx, ny, nz, get_global_id(0), c, e, q, &emax))
        return;
    float v[64];
    clvis_zfp_values(q, emax, v);
    uint x0 = 4u * c[0], y0 = 4u * c[1], z0 = 4u * c[2];
    for (uint z = 0; z < e[2]; ++z)
        for (uint y = 0; y < e[1]; ++y) {
            global float *row = out + ((ulong)(z0 + z) * ny + (y0 + y)) * nx + x0;
            if (e[0] == 4u) {
                /* clvis/inline.h's vload4 / vstore4 (the builtins are calls on PoCL) */
                const float *src = v + 16u * z + 4u * y;
                const float4 r4 = CLVIS_IL_VLOAD4(float4, src);
                CLVIS_IL_VSTORE4(r4, row);
            }
            else
                for (uint x = 0; x < e[0]; ++x)
                    row[x] = v[16u * z + 4u * y + x];
        }
}

kernel __attribute__((vec_type_hint(ulong16))) void decode_blocks(global const ulong *stream, uint rate, uint nblocks_total,
                          global const uint *ids, uint count, global float *out_bricks)
{
    uint j = get_global_id(0);
    if (j >= count)
        return;
    clvis_zfp_decode_brick(stream, rate, nblocks_total, ids[j], out_bricks + (ulong)j * 64u);
}
