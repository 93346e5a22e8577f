/* clvis/morton.h — 30-bit Morton codes (10 bits per axis, x lowest).
 *
 * clvis_morton3(qx, qy, qz) interleaves the low 10 bits of each: bit 3k of the
 * code is bit k of qx, bit 3k + 1 of qy, bit 3k + 2 of qz.
 *
 * clvis_morton_quantize(v): the grid coordinate of a scaled position v =
 * (x - lo) * s (float32, s = 1023 / extent): 0 for v <= 0, 1023 for
 * v >= 1023, else (uint)v (truncation; callers pass no NaN). Used by raster/morton.cl's
 * morton_codes and gauss/bvh.cl's bvh_morton, so both order points alike.
 */
#ifndef CLVIS_MORTON_H
#define CLVIS_MORTON_H

/* spread the low 10 bits of v to every third bit */
inline uint clvis_spread3(uint v)
{
    v &= 0x3FFu;
    v = (v | (v << 16)) & 0x030000FFu;
    v = (v | (v << 8)) & 0x0300F00Fu;
    v = (v | (v << 4)) & 0x030C30C3u;
    v = (v | (v << 2)) & 0x09249249u;
    return v;
}

inline uint clvis_morton3(uint qx, uint qy, uint qz)
{
    return clvis_spread3(qx) | (clvis_spread3(qy) << 1) | (clvis_spread3(qz) << 2);
}

/* a scaled coordinate to the 10-bit grid: clamp to [0, 1023], truncate */
inline uint clvis_morton_quantize(float v)
{
    return v <= 0.0f ? 0u : v >= 1023.0f ? 1023u : (uint)v;
}

#endif /* CLVIS_MORTON_H */
