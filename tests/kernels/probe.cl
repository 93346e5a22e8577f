/* probe.cl — test-only kernel: reports what clvis's build gave it.
 *
 * ABI
 * ---
 * kernel probe(global ulong *out)   global size 1
 *     out[0] = 1 if CLVIS_INT64_ATOMICS was defined, else 0;
 *     with it, out[1] = atom_min of out[1] and 7 (64-bit atomics really used).
 */
#ifdef CLVIS_INT64_ATOMICS
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable
#endif

kernel void probe(global ulong *out)
{
#ifdef CLVIS_INT64_ATOMICS
    out[0] = 1;
    atom_min(&out[1], (ulong)7 | ((ulong)1 << 40));
#else
    out[0] = 0;
#endif
}
