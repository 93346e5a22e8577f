/* edl.cl — eye-dome lighting: a screen-space shading pass over a depth image
 * that darkens each point by how far it lies behind its neighbours, so the
 * shape of a point cloud reads without normals (Boucheny 2009; the form
 * Potree and CloudCompare use). The definition is the docstring of
 * clvis/reference/raster/edl.py; the kernel computes it in float32 with the
 * device's log2 and exp (the reference bounds the difference: one colour step).
 *
 * ABI
 * ---
 * Defines (optional):
 *   EDL_SCALE  the factor of the response in the exponent (default 300.0f,
 *              Potree's): shade = exp(-EDL_SCALE * strength * response).
 *
 * Images are row-major, row 0 on top, w x h pixels, n = w * h.
 *
 * kernel edl(global const float *depth, global const uchar *rgba_in,
 *            global uchar *rgba_out, uint w, uint h, uint radius, float strength)
 *     depth: n floats, the view depth of the point in each pixel; a pixel
 *     holds a point when its depth is finite and > 0 (+INFINITY: empty).
 *     rgba_in, rgba_out: n * 4 bytes (r, g, b, a), distinct buffers.
 *     For a pixel holding a point at depth d: response = (1/8) * sum over the
 *     8 neighbours at (x + i*radius, y + j*radius), (i, j) in {-1, 0, 1}^2
 *     minus (0, 0), that lie inside the image and hold a point at depth dn,
 *     of max(0, log2(d) - log2(dn)); shade = exp(-EDL_SCALE * strength *
 *     response); out r, g, b = round-to-nearest-even(c * shade) (saturated),
 *     alpha copied. Other pixels are copied unchanged.
 *     Global size: any one-dimensional size >= n (items past n do nothing);
 *     any local size.
 */

#ifndef EDL_SCALE
#define EDL_SCALE 300.0f
#endif

inline int edl_holds(float d) { return isfinite(d) && d > 0.0f; }

kernel void edl(global const float *depth, global const uchar *rgba_in, global uchar *rgba_out,
                uint w, uint h, uint radius, float strength) {
    size_t i = get_global_id(0);
    size_t n = (size_t)w * h;
    if (i >= n) return;
    uchar4 c = vload4(i, rgba_in);
    float d = depth[i];
    if (!edl_holds(d)) {
        vstore4(c, i, rgba_out);
        return;
    }
    long x = (long)(i % w), y = (long)(i / w), r = (long)radius;
    float ld = log2(d);
    float sum = 0.0f;
    for (int j = -1; j <= 1; ++j) {
        for (int k = -1; k <= 1; ++k) {
            if (j == 0 && k == 0) continue;
            long nx = x + k * r, ny = y + j * r;
            if (nx < 0 || ny < 0 || nx >= (long)w || ny >= (long)h) continue;
            float dn = depth[(size_t)ny * w + (size_t)nx];
            if (!edl_holds(dn)) continue;
            sum += fmax(0.0f, ld - log2(dn));
        }
    }
    float response = sum / 8.0f;
    float shade = exp(-EDL_SCALE * strength * response);
    float4 rgb = convert_float4(c) * shade;
    uchar4 o = convert_uchar4_sat_rte(rgb);
    o.w = c.w;
    vstore4(o, i, rgba_out);
}
