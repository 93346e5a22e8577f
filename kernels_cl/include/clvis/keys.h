/* clvis/keys.h — order-preserving maps from numbers to unsigned integer keys.
 *
 * Each function takes the raw bits of a value (loaded as uint or ulong, whatever
 * the value's type) and returns an unsigned key whose unsigned order is the
 * total order of the values:
 *
 *   unsigned  identity
 *   signed    two's complement: flip the sign bit, so INT_MIN maps to 0
 *   float     IEEE 754: -inf < ... < -0.0 < +0.0 < ... < +inf < NaN
 *             (every NaN, whatever its sign or payload, maps to the largest key,
 *             so NaNs sort last and keep their input order in a stable sort)
 *
 * clvis_key_f32_inverse(key) gives back the float bits of a clvis_key_f32
 * key (a NaN's key, all ones, gives 0x7FFFFFFF, a NaN); as_float of it is the
 * depth of a depth key (raster/render.cl, raster/resolve.cl, post/pack.cl,
 * gauss/tiles.cl). Its one host copy is clvis/_keys.py.
 *
 * Only integer operations are used: no fp64 support is needed for the 64-bit
 * float keys. Radix sort moves the raw bits and calls these on the fly, so the
 * sorted output keeps every bit of the input (NaN payloads included).
 */
#ifndef CLVIS_KEYS_H
#define CLVIS_KEYS_H

#include "clvis/inline.h"

inline uint clvis_key_u32(uint bits) { return bits; }
inline uint clvis_key_i32(uint bits) { return bits ^ 0x80000000u; }
inline uint clvis_key_f32(uint bits)
{
    if ((bits & 0x7FFFFFFFu) > 0x7F800000u)     /* NaN */
        return 0xFFFFFFFFu;
    return (bits & 0x80000000u) ? ~bits : (bits | 0x80000000u);
}

/* the float bits whose clvis_key_f32 is key */
inline uint clvis_key_f32_inverse(uint key)
{
    return (key & 0x80000000u) ? (key ^ 0x80000000u) : ~key;
}

/* clvis_key_f32 on 8 lanes */
inline uint8 clvis_key_f32_8(uint8 bits)
{
    uint8 key = clvis_il_select8(bits | 0x80000000u, ~bits, (bits & 0x80000000u) != 0u);
    return clvis_il_select8(key, (uint8)(0xFFFFFFFFu), (bits & 0x7FFFFFFFu) > 0x7F800000u);
}

inline ulong clvis_key_u64(ulong bits) { return bits; }
inline ulong clvis_key_i64(ulong bits) { return bits ^ 0x8000000000000000ul; }
inline ulong clvis_key_f64(ulong bits)
{
    if ((bits & 0x7FFFFFFFFFFFFFFFul) > 0x7FF0000000000000ul)   /* NaN */
        return 0xFFFFFFFFFFFFFFFFul;
    return (bits & 0x8000000000000000ul) ? ~bits : (bits | 0x8000000000000000ul);
}

#endif /* CLVIS_KEYS_H */
