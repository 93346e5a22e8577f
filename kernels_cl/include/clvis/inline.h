/* clvis/inline.h — OpenCL builtins written out inline, with the builtin's
 * exact result.
 *
 * ABI
 * ---
 * Header only; include guard CLVIS_INLINE_H; no defines, no build options.
 *
 * Why: PoCL 3 (its CPU device) compiles these builtins as calls into its
 * kernel library instead of inline code: isfinite, isnan, fabs, fmin, fmax,
 * clamp, copysign, min, floor, any, select, popcount, and vloadN / vstoreN
 * (and sqrt, which stays a call: see DESIGN.md). Each costs a call,
 * the argument shuffles around it, branches and, for the vector ones, a
 * vzeroupper, inside loops that run once or more per point, pixel or bit
 * run. The helpers below are the same results by comparison, bit mask or
 * integer conversion, which the compiler keeps inline; other devices
 * compile them to the same instructions as the builtins.
 *
 * Each returns exactly what the builtin returns for every input, NaN and
 * infinities included, except where the line says otherwise:
 *   int   clvis_il_isfinite(float x)   isfinite(x) (1 / 0): exponent bits
 *   int   clvis_il_isnan(float x)      isnan(x) (1 / 0): magnitude bits
 *   int8  clvis_il_isfinite8(float8 x) isfinite(x) of a float8 (-1 / 0)
 *   int   clvis_il_any8(int8 v)        any(v): the sign bit of the lanes' OR
 *   uint8 clvis_il_select8(uint8 a, uint8 b, int8 c)
 *                                      select(a, b, c) for c of -1 / 0 lanes
 *                                      only (a comparison's result)
 *   float clvis_il_fabs(float x)       fabs(x), float3 / float4 too: a bit mask
 *   float clvis_il_fmin(a, b), clvis_il_fmax(a, b)
 *                                      fmin / fmax (a NaN argument gives the
 *                                      other one), float3 lanes too; for
 *                                      a = -0, b = +0 (or the reverse) the
 *                                      result is the second argument, a sign
 *                                      of zero OpenCL leaves open
 *   float clvis_il_clamp(x, lo, hi)    clamp(x, lo, hi) =
 *                                      fmin(fmax(x, lo), hi) as the two above
 *                                      (x NaN gives lo; lo > hi is undefined
 *                                      for the builtin, here it gives hi)
 *   float clvis_il_copysign(x, y)      copysign(x, y): |x|'s bits with y's
 *                                      sign bit (NaN x and y included)
 *   uint  clvis_il_umin(uint a, uint b), ulong clvis_il_ulmin(a, b)   min
 *   int   clvis_il_imin(int a, int b), clvis_il_imax(int a, int b)    min, max
 *   float clvis_il_floor(float x)      floor(x): |x| < 2^23 through int,
 *                                      -0 kept; larger, inf and NaN: x
 *   float8 clvis_il_vload8(global const float *p)
 *                                      vload8(0, p): eight loads the
 *                                      compiler merges into one (p needs only
 *                                      float alignment, as for vload8)
 *   CLVIS_IL_VLOAD8(TV, p), CLVIS_IL_VLOAD4(TV, p)
 *                                      vload8(0, p) / vload4(0, p) as the
 *                                      vector type TV (int8, ulong4, ...)
 *   CLVIS_IL_VSTORE8(v, p), CLVIS_IL_VSTORE4(v, p)
 *                                      vstore8(v, 0, p) / vstore4(v, 0, p)
 *                                      lane by lane (the compiler merges the
 *                                      element accesses into vector ones)
 *   uint  clvis_il_ctz64(ulong x)      trailing zero bits of x, 64 for 0
 *                                      (popcount(~x & (x - 1)) without the
 *                                      popcount call)
 */
#ifndef CLVIS_INLINE_H
#define CLVIS_INLINE_H

inline int clvis_il_isfinite(float x)
{
    return (as_uint(x) & 0x7F800000u) != 0x7F800000u;
}

inline int clvis_il_isnan(float x)
{
    return (as_uint(x) & 0x7FFFFFFFu) > 0x7F800000u;
}

inline int8 clvis_il_isfinite8(float8 x)
{
    return (as_int8(x) & (int8)(0x7F800000)) != (int8)(0x7F800000);
}

inline int clvis_il_any8(int8 v)
{
    int4 a = v.lo | v.hi;
    int2 b = a.lo | a.hi;
    return (b.x | b.y) < 0;
}

inline uint8 clvis_il_select8(uint8 a, uint8 b, int8 c)
{
    return (a & ~as_uint8(c)) | (b & as_uint8(c));
}

inline float clvis_il_fabs(float x)
{
    return as_float(as_uint(x) & 0x7FFFFFFFu);
}

inline float3 clvis_il_fabs3(float3 x)
{
    return as_float3(as_uint3(x) & (uint3)(0x7FFFFFFFu));
}

inline float4 clvis_il_fabs4(float4 x)
{
    return as_float4(as_uint4(x) & (uint4)(0x7FFFFFFFu));
}

inline float clvis_il_fmin(float a, float b)
{
    return (a < b || b != b) ? a : b;
}

inline float clvis_il_fmax(float a, float b)
{
    return (a > b || b != b) ? a : b;
}

inline float clvis_il_clamp(float x, float lo, float hi)
{
    return clvis_il_fmin(clvis_il_fmax(x, lo), hi);
}

inline float clvis_il_copysign(float x, float y)
{
    return as_float((as_uint(x) & 0x7FFFFFFFu) | (as_uint(y) & 0x80000000u));
}

inline float3 clvis_il_fmin3(float3 a, float3 b)
{
    return (float3)(clvis_il_fmin(a.x, b.x), clvis_il_fmin(a.y, b.y), clvis_il_fmin(a.z, b.z));
}

inline float3 clvis_il_fmax3(float3 a, float3 b)
{
    return (float3)(clvis_il_fmax(a.x, b.x), clvis_il_fmax(a.y, b.y), clvis_il_fmax(a.z, b.z));
}

inline uint clvis_il_umin(uint a, uint b)
{
    return a < b ? a : b;
}

inline ulong clvis_il_ulmin(ulong a, ulong b)
{
    return a < b ? a : b;
}

inline int clvis_il_imin(int a, int b)
{
    return a < b ? a : b;
}

inline int clvis_il_imax(int a, int b)
{
    return a > b ? a : b;
}

inline float clvis_il_floor(float x)
{
    if (!((as_uint(x) & 0x7FFFFFFFu) < 0x4B000000u))   /* |x| >= 2^23, inf, NaN: integral */
        return x;
    float t = (float)(int)x;                            /* x rounded toward zero, exact */
    t = t > x ? t - 1.0f : t;
    return as_float(as_uint(t) | (as_uint(x) & 0x80000000u));   /* floor(-0) = -0, (-1, 0) -> -1 */
}

#define CLVIS_IL_VLOAD8(TV, p) \
    ((TV)((p)[0], (p)[1], (p)[2], (p)[3], (p)[4], (p)[5], (p)[6], (p)[7]))
#define CLVIS_IL_VLOAD4(TV, p) ((TV)((p)[0], (p)[1], (p)[2], (p)[3]))
#define CLVIS_IL_VSTORE8(v, p)                                                 \
    {                                                                          \
        (p)[0] = (v).s0; (p)[1] = (v).s1; (p)[2] = (v).s2; (p)[3] = (v).s3;    \
        (p)[4] = (v).s4; (p)[5] = (v).s5; (p)[6] = (v).s6; (p)[7] = (v).s7;    \
    }
#define CLVIS_IL_VSTORE4(v, p)                                                 \
    {                                                                          \
        (p)[0] = (v).s0; (p)[1] = (v).s1; (p)[2] = (v).s2; (p)[3] = (v).s3;    \
    }

inline float8 clvis_il_vload8(global const float *p)
{
    return CLVIS_IL_VLOAD8(float8, p);
}

inline uint clvis_il_ctz64(ulong x)
{
    ulong m = ~x & (x - 1ul);               /* the trailing zeros as ones */
    m = m - ((m >> 1) & 0x5555555555555555ul);
    m = (m & 0x3333333333333333ul) + ((m >> 2) & 0x3333333333333333ul);
    m = (m + (m >> 4)) & 0x0F0F0F0F0F0F0F0Ful;
    return (uint)((m * 0x0101010101010101ul) >> 56);
}

#endif /* CLVIS_INLINE_H */
