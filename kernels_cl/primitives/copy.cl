/* copy.cl — device copy, the bandwidth yardstick of the benchmarks.
 *
 * ABI
 * ---
 * Defines: none.
 *
 * kernel copy_bytes(global const uchar *in, global uchar *out, ulong nbytes)
 *     out[0 .. nbytes) = in[0 .. nbytes). in and out are whole buffers (so
 *     aligned as the device aligns buffers, at least 16 bytes) and do not
 *     overlap. Any one-dimensional global size and local size: work-item i
 *     copies the 16-byte words i, i + global size, ...; work-item 0 also
 *     copies the nbytes % 16 trailing bytes.
 *
 * Memory traffic: nbytes read + nbytes written.
 */
kernel void copy_bytes(global const uchar *restrict in,
                       global uchar *restrict out, const ulong nbytes)
{
    global const uint4 *in4 = (global const uint4 *)in;
    global uint4 *out4 = (global uint4 *)out;
    const ulong words = nbytes / 16;
    const ulong stride = get_global_size(0);
    for (ulong w = get_global_id(0); w < words; w += stride)
        out4[w] = in4[w];
    if (get_global_id(0) == 0) {
        for (ulong i = words * 16; i < nbytes; ++i)
            out[i] = in[i];
    }
}
