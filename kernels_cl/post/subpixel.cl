/* subpixel.cl — NARVis's sub-pixel rule (clvis.post.subpixel): the network's
 * output blended toward the input's colours where the Gaussians it stands
 * in for are under a pixel across (there the Gaussian renderer's image is
 * the point raster's). The definitions are the docstring of
 * clvis/reference/post/subpixel.py; results are within float32 rounding of
 * it (the window sums' order).
 *
 * ABI
 * ---
 * Defines:
 *   REACH  the window's half side m (default 8): (2m+1)^2 pixels, clipped
 *          at the image's edges.
 *   WG     the local size hint (any; default 64). Launch any 1-D global
 *          size >= the item count; items past it do nothing.
 *
 * planes: the network's input (1, C, hp, wp) float32, channel c of pixel
 * (x, y) at [c*hp*wp + y*wp + x]: 0..2 R, G, B, 3 the coverage, rc the
 * radius plane (sigma in pixels).
 *
 * kernel subpixel_rows(global const float *planes, uint wp, uint hp, uint rc,
 *                      global float *sums)
 *     One item per pixel (hp*wp items, pixel = y*wp + x): along its row,
 *     |dx| <= REACH, sums[2*pixel] = sum of radius * coverage, sums[2*pixel
 *     + 1] = sum of coverage.
 *
 * kernel subpixel_blend(global const float *planes, global const float *sums,
 *                       uint wp, uint hp, float lo, float hi,
 *                       global float *image)
 *     One item per pixel: S, N = the column sums of `sums` over |dy| <=
 *     REACH; w = clamp((hi - S/N) / (hi - lo), 0, 1), 0 where N = 0;
 *     image (1, 3, hp, wp), in place: image_c = w * planes_c + (1 - w) *
 *     image_c. Each item reads and writes only its own pixel of image.
 *
 * Memory traffic: 2 (2m+1) + 2 floats read per pixel per kernel (rows
 * shared with the neighbours, cached), 2 + 3 written.
 */
#pragma OPENCL FP_CONTRACT OFF

#ifndef REACH
#define REACH 8
#endif

kernel void subpixel_rows(global const float *planes, uint wp, uint hp, uint rc, global float *sums)
{
    const size_t item = get_global_id(0);
    const size_t npix = (size_t)wp * hp;
    if (item >= npix)
        return;
    const int x = (int)(item % wp);
    const size_t row = item - (size_t)x;
    const int x0 = max(x - REACH, 0), x1 = min(x + REACH, (int)wp - 1);
    float s = 0.0f, n = 0.0f;
    for (int xx = x0; xx <= x1; ++xx) {
        const float cov = planes[3 * npix + row + xx];
        s += planes[(size_t)rc * npix + row + xx] * cov;
        n += cov;
    }
    sums[2 * item] = s;
    sums[2 * item + 1] = n;
}

kernel void subpixel_blend(global const float *planes, global const float *sums, uint wp, uint hp, float lo,
                           float hi, global float *image)
{
    const size_t item = get_global_id(0);
    const size_t npix = (size_t)wp * hp;
    if (item >= npix)
        return;
    const int y = (int)(item / wp);
    const size_t x = item - (size_t)y * wp;
    const int y0 = max(y - REACH, 0), y1 = min(y + REACH, (int)hp - 1);
    float s = 0.0f, n = 0.0f;
    for (int yy = y0; yy <= y1; ++yy) {
        const size_t i = (size_t)yy * wp + x;
        s += sums[2 * i];
        n += sums[2 * i + 1];
    }
    if (!(n > 0.0f))
        return; /* w = 0: the network's output as it is */
    const float w = clamp((hi - s / n) / (hi - lo), 0.0f, 1.0f);
    for (int c = 0; c < 3; ++c) {
        const size_t i = (size_t)c * npix + item;
        image[i] = w * planes[i] + (1.0f - w) * image[i];
    }
}
