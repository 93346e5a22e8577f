/* zfp.cl — decoding ZFP fixed-rate streams of 3-D float32 volumes.
 *
 * ABI
 * ---
 * No defines, no compiler flags. Includes clvis/zfp.h (the stream format and
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

kernel void decode_volume(global const ulong *stream, uint rate, uint nx, uint ny, uint nz,
                          global float *out)
{
    uint nbx = (nx + 3u) >> 2, nby = (ny + 3u) >> 2, nbz = (nz + 3u) >> 2;
    ulong b = get_global_id(0);
    uint c[3];
    if (!zfp_grid_cell(b, nbx, nby, nbz, c))
        return;
    uint bx = c[0], by = c[1], bz = c[2];

    int q[64];
    int emax = zfp_decode_block3i(stream, b, rate, q);

    uint x0 = 4u * bx, y0 = 4u * by, z0 = 4u * bz;
    uint ex = min(4u, nx - x0), ey = min(4u, ny - y0), ez = min(4u, nz - z0);
    for (uint z = 0; z < ez; ++z)
        for (uint y = 0; y < ey; ++y) {
            global float *row = out + ((ulong)(z0 + z) * ny + (y0 + y)) * nx + x0;
            const int *src = q + 16u * z + 4u * y;
            for (uint x = 0; x < ex; ++x)
                row[x] = emax == ZFP_ZERO_BLOCK ? 0.0f : zfp_dequantize(src[x], emax);
        }
}

kernel void decode_blocks(global const ulong *stream, uint rate, uint nblocks_total,
                          global const uint *ids, uint count, global float *out_bricks)
{
    uint j = get_global_id(0);
    if (j >= count)
        return;
    zfp_decode_brick(stream, rate, nblocks_total, ids[j], out_bricks + (ulong)j * 64u);
}
