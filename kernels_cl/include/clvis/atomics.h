/* clvis/atomics.h — atomic minimum on 32- and 64-bit unsigned words.
 *
 * CLVIS_INT64_ATOMICS (set by the clvis runtime when the device reports both
 * cl_khr_int64_base_atomics and cl_khr_int64_extended_atomics, and not
 * forced off) enables clvis_atomic_min_u64. Every file tests whether it is
 * defined, never its value (-DCLVIS_INT64_ATOMICS=0 turns it on; leave it
 * undefined for off). Without it, kernels must take
 * their documented fallback path; clvis_has_atomic_min_u64() tells which
 * build this is at compile time (as a constant the compiler folds).
 *
 * Word order: some kernels update the two 32-bit halves of a 64-bit word
 * separately (the fallback of a 64-bit min). clvis_hi_word / clvis_lo_word
 * give the index of each half in a uint view of a ulong array; the device must
 * be little-endian (every CPU and GPU OpenCL device in use is).
 */
#ifndef CLVIS_ATOMICS_H
#define CLVIS_ATOMICS_H

#ifndef __ENDIAN_LITTLE__
#error "clvis kernels that split 64-bit words need a little-endian device"
#endif

#define clvis_lo_word(i) (2u * (i))
#define clvis_hi_word(i) (2u * (i) + 1u)

/* benign race (early-z): raster/render.cl's early-z test reads the word
 * this atomic min updates with a plain load; why that is safe is explained
 * there. */
inline void clvis_atomic_min_u32(volatile global uint *p, uint v)
{
    atomic_min(p, v);
}

#ifdef CLVIS_INT64_ATOMICS
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable
#define clvis_has_atomic_min_u64() 1

/* benign race (early-z): as above, for the 64-bit depth|index entries */
/* benign race (iso-skip): iso/raytrace.cl's ITEMS mode reads the high word of
 * the hit key this atomic min updates with a plain load; why, there. */
inline void clvis_atomic_min_u64(volatile global ulong *p, ulong v)
{
    atom_min(p, v);
}
#else
#define clvis_has_atomic_min_u64() 0
#endif

#endif /* CLVIS_ATOMICS_H */
