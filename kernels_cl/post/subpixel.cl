/* subpixel.cl — NARVis's sub-pixel rule (clvis.post.subpixel): the network's
 * output blended toward the input's colours where the Gaussians it stands
 * in for are under a pixel across (there the Gaussian renderer's image is
 * the point raster's), held back where the window looks like a volume of
 * points (dense coverage, colour noise between neighbours at one depth).
 * The definitions are the docstring of clvis/reference/post/subpixel.py.
 *
 * The window sums are sliding sums in 64-bit fixed point (radius and colour
 * noise in units of 2^-24, coverage and the noise's count as integers), so
 * adding the entering pixel and taking off the leaving one is exact: a sum
 * is the reference's to within the terms' rounding to 2^-24 (the rounding
 * of the radius and the noise to float32 is of the same order).
 *
 * ABI
 * ---
 * Defines:
 *   REACH   the window's half side m (default 8): (2m+1)^2 pixels, clipped
 *           at the image's edges.
 *   VOLUME  1: the volume score (the depth-consistent colour noise, the
 *           coverage fraction) holds the blend back; 0 (default): the
 *           sigma rule alone (tau, c_lo, c_hi, f_lo, f_hi and the depth
 *           channel are not read).
 * Launch sizes: any 1-D global size >= the kernel's item count (below);
 * items past it do nothing; any local size (clvis: 64; a WG define that
 * clvis passes is not read by the kernels).
 * Build with -cl-fp32-correctly-rounded-divide-sqrt (the radius, noise and
 * coverage means and the blend's ramps divide); the file sets FP_CONTRACT
 * OFF itself.
 *
 * planes: the network's input (1, C, hp, wp) float32, channel c of pixel
 * (x, y) at [c*hp*wp + y*wp + x]: 0..2 R, G, B, 3 the coverage (covered:
 * > 0), rc the radius plane (sigma in pixels), dc the view depth.
 *
 * kernel subpixel_terms(global const float *planes, uint wp, uint hp, uint rc,
 *                       uint dc, float tau, global long *terms)
 *     One item per pixel (hp*wp items, pixel = y*wp + x): terms[4*pixel ..
 *     +3] = (round(radius * 2^24) if covered else 0, covered, round(q *
 *     2^24) * v, v), q and v the depth-consistent colour noise of the
 *     reference (the covered 8-neighbours n with |z_n - z| <= tau * z).
 *
 * kernel subpixel_rows(global const long *terms, uint wp, uint hp,
 *                      global long *sums)
 *     One item per row (hp items): sums[4*pixel + k] = the sum of terms
 *     k over |dx| <= REACH along the row (a sliding sum).
 *
 * kernel subpixel_blend(global const float *planes, global const long *sums,
 *                       uint wp, uint hp, float lo, float hi, float c_lo,
 *                       float c_hi, float f_lo, float f_hi,
 *                       global float *image)
 *     One item per column (wp items), sliding down it: S, N, Q, V = the
 *     column sums of `sums` over |dy| <= REACH; R = S/N, F = N / the
 *     clipped window's area, C = Q/V (0 where V = 0); w = clamp((hi - R) /
 *     (hi - lo), 0, 1) * (1 - clamp((C - c_lo) / (c_hi - c_lo), 0, 1) *
 *     clamp((F - f_lo) / (f_hi - f_lo), 0, 1)) (VOLUME 0: the first factor
 *     alone), 0 where N = 0; image (1, 3, hp, wp), in place: image_c = w *
 *     planes_c + (1 - w) * image_c. Each item reads and writes only its
 *     own column of image.
 *
 * Memory traffic per pixel: terms: 3 + 8 (depth, coverage of the
 * neighbours, cached) + 3 * 9 colours floats read, 32 bytes written; rows
 * and blend: 2 x 32 bytes of sums read, 32 written; blend: 6 floats read,
 * 3 written.
 */
#pragma OPENCL FP_CONTRACT OFF

#ifndef REACH
#define REACH 8
#endif
#ifndef VOLUME
#define VOLUME 0
#endif

#define FIX 16777216.0f /* 2^24 */

kernel void subpixel_terms(global const float *planes, uint wp, uint hp, uint rc, uint dc, float tau,
                           global long *terms)
{
    const size_t item = get_global_id(0);
    const size_t npix = (size_t)wp * hp;
    if (item >= npix)
        return;
    const bool cov = planes[3 * npix + item] > 0.0f;
    long r = 0, q = 0, v = 0;
    if (cov) {
        r = (long)rint(planes[(size_t)rc * npix + item] * FIX);
#if VOLUME
        const int x = (int)(item % wp), y = (int)(item / wp);
        const float z = planes[(size_t)dc * npix + item];
        const float c0 = planes[item], c1 = planes[npix + item], c2 = planes[2 * npix + item];
        float s = 0.0f;
        int n = 0;
        for (int dy = -1; dy <= 1; ++dy) {
            for (int dx = -1; dx <= 1; ++dx) {
                const int xx = x + dx, yy = y + dy;
                if ((dx == 0 && dy == 0) || xx < 0 || yy < 0 || xx >= (int)wp || yy >= (int)hp)
                    continue;
                const size_t j = (size_t)yy * wp + xx;
                if (!(planes[3 * npix + j] > 0.0f) || !(fabs(z - planes[(size_t)dc * npix + j]) <= tau * z))
                    continue;
                s += fabs(c0 - planes[j]) + fabs(c1 - planes[npix + j]) + fabs(c2 - planes[2 * npix + j]);
                ++n;
            }
        }
        if (n > 0) {
            q = (long)rint(s / (float)n * FIX);
            v = 1;
        }
#endif
    }
    vstore4((long4)(r, cov ? 1 : 0, q, v), item, terms);
}

kernel void subpixel_rows(global const long *terms, uint wp, uint hp, global long *sums)
{
    const size_t y = get_global_id(0);
    if (y >= hp)
        return;
    const size_t row = y * wp;
    const int w = (int)wp;
    long4 s = (long4)(0);
    for (int x = 0; x <= min(REACH, w - 1); ++x)
        s += vload4(row + x, terms);
    for (int x = 0; x < w; ++x) {
        vstore4(s, row + x, sums);
        if (x + REACH + 1 < w)
            s += vload4(row + x + REACH + 1, terms);
        if (x - REACH >= 0)
            s -= vload4(row + x - REACH, terms);
    }
}

kernel void subpixel_blend(global const float *planes, global const long *sums, uint wp, uint hp, float lo,
                           float hi, float c_lo, float c_hi, float f_lo, float f_hi, global float *image)
{
    const size_t x = get_global_id(0);
    if (x >= wp)
        return;
    const size_t npix = (size_t)wp * hp;
    const int h = (int)hp, xi = (int)x;
    const float across = (float)(min(xi + REACH, (int)wp - 1) - max(xi - REACH, 0) + 1);
    long4 s = (long4)(0);
    for (int y = 0; y <= min(REACH, h - 1); ++y)
        s += vload4((size_t)y * wp + x, sums);
    for (int y = 0; y < h; ++y) {
        const size_t item = (size_t)y * wp + x;
        if (s.s1 > 0) {
            const float n = (float)s.s1;
            const float r = (float)s.s0 / FIX / n;
            float w = clamp((hi - r) / (hi - lo), 0.0f, 1.0f);
#if VOLUME
            const float c = s.s3 > 0 ? (float)s.s2 / FIX / (float)s.s3 : 0.0f;
            const float f = n / (across * (float)(min(y + REACH, h - 1) - max(y - REACH, 0) + 1));
            w *= 1.0f - clamp((c - c_lo) / (c_hi - c_lo), 0.0f, 1.0f) * clamp((f - f_lo) / (f_hi - f_lo), 0.0f, 1.0f);
#endif
            for (int k = 0; k < 3; ++k) {
                const size_t i = (size_t)k * npix + item;
                image[i] = w * planes[i] + (1.0f - w) * image[i];
            }
        }
        if (y + REACH + 1 < h)
            s += vload4((size_t)(y + REACH + 1) * wp + x, sums);
        if (y - REACH >= 0)
            s -= vload4((size_t)(y - REACH) * wp + x, sums);
    }
}
