/* clvis/colormap.h — the color of a point: fixed, per point, or through a
 * transfer function (a scalar mapped through a colormap table).
 *
 * clvis_point_color(id, color_mode, colors, tf_src, tf_stride, tf_offset,
 *                   lut, lut_n, tf_min, tf_scale) returns (r, g, b, a) as uint4:
 *   color_mode 0: (255, 255, 255, 255);
 *   color_mode 1: colors[id];
 *   color_mode 2: v = tf_src[id * tf_stride + tf_offset]; a NaN v gives (0, 0, 0, 0); else
 *     t = (v - tf_min) * tf_scale, f = floor(t * lut_n) (float32 operations),
 *     i = 0 when f is NaN or <= 0, lut_n - 1 when f >= lut_n - 1, else f;
 *     lut[i]. tf_scale = 1 / (vmax - vmin) rounded to float32 by the host (0
 *     when vmax == vmin), so no division happens here.
 * clvis.colormap.apply is the NumPy definition of mode 2.
 */
#ifndef CLVIS_COLORMAP_H
#define CLVIS_COLORMAP_H

#include "clvis/inline.h"

inline uint4 clvis_point_color(uint id, uint color_mode, global const uchar4 *colors,
                               global const float *tf_src, uint tf_stride, uint tf_offset,
                               global const uchar4 *lut, uint lut_n, float tf_min, float tf_scale)
{
    if (color_mode == 1)
        return convert_uint4(colors[id]);
    if (color_mode == 2) {
        float v = tf_src[(size_t)id * tf_stride + tf_offset];
        if (clvis_il_isnan(v))
            return (uint4)(0);
        float t = (v - tf_min) * tf_scale;
        float f = clvis_il_floor(t * (float)lut_n);
        uint i = !(f > 0.0f) ? 0u : f >= (float)(lut_n - 1) ? lut_n - 1 : (uint)f;
        return convert_uint4(lut[i]);
    }
    return (uint4)(255);
}

#endif /* CLVIS_COLORMAP_H */
