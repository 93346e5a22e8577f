/* raster_host.c — renders a point cloud with kernels_cl/raster/render.cl and
 * resolve.cl from plain C, following only their ABI comments (and those of
 * the headers they include): the rasterizer embeds without Python.
 *
 *   cc -std=c99 -O2 raster_host.c -lOpenCL -o raster_host
 *   ./raster_host <kernels_cl dir> <input> <output> [platform name substring]
 *
 * input (little-endian): uint32 n, W, H, batch; float near, far; float cam[20]
 * (clvis/camera.h: M = projection @ view row-major, then the depth row);
 * then n points of 3 floats.
 * output: W*H ulong visibility words, W*H uint index, W*H float depth.
 * Uses render_visibility when the device has 64-bit atomics, else the
 * two-pass render_depth + render_index; prints which.
 */
#include "host_common.h"

static void read_exact(FILE *f, void *dst, size_t bytes, const char *what)
{
    if (fread(dst, 1, bytes, f) != bytes) {
        fprintf(stderr, "short input reading %s\n", what);
        exit(2);
    }
}

static cl_kernel kernel(cl_program prg, const char *name)
{
    cl_int err;
    cl_kernel k = clCreateKernel(prg, name, &err);
    CHECK(err);
    return k;
}

int main(int argc, char **argv)
{
    if (argc < 4) {
        fprintf(stderr, "usage: %s <kernels_cl dir> <input> <output> [platform]\n", argv[0]);
        return 2;
    }
    const char *root = argv[1];
    FILE *in = fopen(argv[2], "rb");
    if (!in) {
        perror(argv[2]);
        return 2;
    }
    cl_uint head[4];
    cl_float near_far[2], cam[20];
    read_exact(in, head, sizeof head, "header");
    read_exact(in, near_far, sizeof near_far, "near, far");
    read_exact(in, cam, sizeof cam, "camera");
    const cl_uint n = head[0], W = head[1], H = head[2], batch = head[3];
    cl_float *pos = malloc((size_t)n * 3 * sizeof *pos + 1);
    read_exact(in, pos, (size_t)n * 3 * sizeof *pos, "points");
    fclose(in);

    char name[256];
    cl_device_id dev = pick_device(argc > 4 ? argv[4] : "Portable Computing Language",
                                   name, sizeof name);
    char ext[8192];
    CHECK(clGetDeviceInfo(dev, CL_DEVICE_EXTENSIONS, sizeof ext, ext, NULL));
    const int int64 = strstr(ext, "cl_khr_int64_base_atomics") != NULL
                      && strstr(ext, "cl_khr_int64_extended_atomics") != NULL;
    printf("platform: %s; %s\n", name, int64 ? "64-bit atomics" : "two-pass fallback");

    cl_int err;
    cl_context ctx = clCreateContext(NULL, 1, &dev, NULL, NULL, &err);
    CHECK(err);
    cl_command_queue q = clCreateCommandQueue(ctx, dev, 0, &err);
    CHECK(err);

    /* render.cl and resolve.cl: -I include, the division flag, and the
     * 64-bit atomics define when the device has them */
    char options[4096], path[4096];
    snprintf(options, sizeof options, "-I %s/include -cl-fp32-correctly-rounded-divide-sqrt%s",
             root, int64 ? " -DCLVIS_INT64_ATOMICS=1" : "");
    cl_program prg[2];
    const char *files[2] = {"raster/render.cl", "raster/resolve.cl"};
    for (int f = 0; f < 2; ++f) {
        snprintf(path, sizeof path, "%s/%s", root, files[f]);
        char *source = read_file(path);
        const char *src = source;
        prg[f] = clCreateProgramWithSource(ctx, 1, &src, NULL, &err);
        CHECK(err);
        if (clBuildProgram(prg[f], 1, &dev, options, NULL, NULL) != CL_SUCCESS) {
            char log[16384];
            clGetProgramBuildInfo(prg[f], dev, CL_PROGRAM_BUILD_LOG, sizeof log, log, NULL);
            fprintf(stderr, "building %s failed (%s):\n%s\n", files[f], options, log);
            return 1;
        }
        free(source);
    }

    const cl_uint nb = (n + batch - 1) / batch;
    const size_t npix = (size_t)W * H;
    cl_mem d_pos = clCreateBuffer(ctx, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR,
                                  (size_t)n * 3 * sizeof *pos + 4, pos, &err);
    CHECK(err);
    cl_mem d_bounds = clCreateBuffer(ctx, CL_MEM_READ_WRITE, (size_t)(nb + 1) * 6 * sizeof(float),
                                     NULL, &err);
    CHECK(err);
    cl_mem d_cam = clCreateBuffer(ctx, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, sizeof cam, cam, &err);
    CHECK(err);
    cl_mem d_vis = clCreateBuffer(ctx, CL_MEM_READ_WRITE, npix * 8, NULL, &err);
    CHECK(err);
    cl_mem d_drawn = clCreateBuffer(ctx, CL_MEM_READ_WRITE, nb + 1, NULL, &err);
    CHECK(err);
    cl_mem d_index = clCreateBuffer(ctx, CL_MEM_WRITE_ONLY, npix * 4, NULL, &err);
    CHECK(err);
    cl_mem d_depth = clCreateBuffer(ctx, CL_MEM_WRITE_ONLY, npix * 4, NULL, &err);
    CHECK(err);
    cl_mem d_rgba = clCreateBuffer(ctx, CL_MEM_WRITE_ONLY, npix * 4, NULL, &err);
    CHECK(err);
    const cl_uchar ones = 0xFF;     /* the visibility buffer starts all ones: empty */
    CHECK(clEnqueueFillBuffer(q, d_vis, &ones, 1, 0, npix * 8, 0, NULL, NULL));

    if (n > 0) {
        /* batch_bounds: item b computes batch b's box */
        cl_kernel kb = kernel(prg[0], "batch_bounds");
        CHECK(clSetKernelArg(kb, 0, sizeof d_pos, &d_pos));
        CHECK(clSetKernelArg(kb, 1, sizeof n, &n));
        CHECK(clSetKernelArg(kb, 2, sizeof batch, &batch));
        CHECK(clSetKernelArg(kb, 3, sizeof d_bounds, &d_bounds));
        size_t global = nb;
        CHECK(clEnqueueNDRangeKernel(q, kb, 1, NULL, &global, NULL, 0, NULL, NULL));
        clReleaseKernel(kb);

        /* the visibility pass(es): global nb * L, local L (here L = 1) */
        const char *passes[2] = {"render_visibility", NULL};
        if (!int64) {
            passes[0] = "render_depth";
            passes[1] = "render_index";
        }
        const cl_mem no_ids = NULL;
        const cl_uint walk = 0; /* render.cl: forwards, lane by lane */
        for (int p = 0; p < 2 && passes[p]; ++p) {
            cl_kernel k = kernel(prg[0], passes[p]);
            CHECK(clSetKernelArg(k, 0, sizeof d_pos, &d_pos));
            CHECK(clSetKernelArg(k, 1, sizeof no_ids, &no_ids));
            CHECK(clSetKernelArg(k, 2, sizeof n, &n));
            CHECK(clSetKernelArg(k, 3, sizeof batch, &batch));
            CHECK(clSetKernelArg(k, 4, sizeof d_bounds, &d_bounds));
            CHECK(clSetKernelArg(k, 5, sizeof d_cam, &d_cam));
            CHECK(clSetKernelArg(k, 6, sizeof(cl_float), &near_far[0]));
            CHECK(clSetKernelArg(k, 7, sizeof(cl_float), &near_far[1]));
            CHECK(clSetKernelArg(k, 8, sizeof W, &W));
            CHECK(clSetKernelArg(k, 9, sizeof H, &H));
            CHECK(clSetKernelArg(k, 10, sizeof d_vis, &d_vis));
            CHECK(clSetKernelArg(k, 11, sizeof d_drawn, &d_drawn));
            CHECK(clSetKernelArg(k, 12, sizeof walk, &walk));
            size_t g = nb, l = 1;
            CHECK(clEnqueueNDRangeKernel(q, k, 1, NULL, &g, &l, 0, NULL, NULL));
            clReleaseKernel(k);
        }
    }

    /* resolve: one work-item per pixel; white points (color_mode 0), no soft z */
    cl_kernel kr = kernel(prg[1], "resolve");
    const cl_mem null_mem = NULL;
    const cl_uint zero = 0;
    const cl_float fzero = 0.0f;
    CHECK(clSetKernelArg(kr, 0, sizeof d_vis, &d_vis));
    CHECK(clSetKernelArg(kr, 1, sizeof W, &W));
    CHECK(clSetKernelArg(kr, 2, sizeof H, &H));
    CHECK(clSetKernelArg(kr, 3, sizeof zero, &zero));            /* color_mode */
    CHECK(clSetKernelArg(kr, 4, sizeof null_mem, &null_mem));    /* colors */
    CHECK(clSetKernelArg(kr, 5, sizeof null_mem, &null_mem));    /* tf_src */
    CHECK(clSetKernelArg(kr, 6, sizeof zero, &zero));            /* tf_stride */
    CHECK(clSetKernelArg(kr, 7, sizeof zero, &zero));            /* tf_offset */
    CHECK(clSetKernelArg(kr, 8, sizeof null_mem, &null_mem));    /* lut */
    CHECK(clSetKernelArg(kr, 9, sizeof zero, &zero));            /* lut_n */
    CHECK(clSetKernelArg(kr, 10, sizeof fzero, &fzero));         /* tf_min */
    CHECK(clSetKernelArg(kr, 11, sizeof fzero, &fzero));         /* tf_scale */
    CHECK(clSetKernelArg(kr, 12, sizeof null_mem, &null_mem));   /* accum */
    CHECK(clSetKernelArg(kr, 13, sizeof d_index, &d_index));
    CHECK(clSetKernelArg(kr, 14, sizeof d_depth, &d_depth));
    CHECK(clSetKernelArg(kr, 15, sizeof d_rgba, &d_rgba));
    size_t gp = npix;
    CHECK(clEnqueueNDRangeKernel(q, kr, 1, NULL, &gp, NULL, 0, NULL, NULL));
    clReleaseKernel(kr);

    void *vis = malloc(npix * 8), *index = malloc(npix * 4), *depth = malloc(npix * 4);
    CHECK(clEnqueueReadBuffer(q, d_vis, CL_TRUE, 0, npix * 8, vis, 0, NULL, NULL));
    CHECK(clEnqueueReadBuffer(q, d_index, CL_TRUE, 0, npix * 4, index, 0, NULL, NULL));
    CHECK(clEnqueueReadBuffer(q, d_depth, CL_TRUE, 0, npix * 4, depth, 0, NULL, NULL));
    FILE *out = fopen(argv[3], "wb");
    if (!out || fwrite(vis, 8, npix, out) != npix || fwrite(index, 4, npix, out) != npix
        || fwrite(depth, 4, npix, out) != npix) {
        perror(argv[3]);
        return 2;
    }
    fclose(out);
    printf("raster: %u points, %u x %u: done\n", n, W, H);
    cl_mem mems[8] = {d_pos, d_bounds, d_cam, d_vis, d_drawn, d_index, d_depth, d_rgba};
    for (int i = 0; i < 8; ++i)
        clReleaseMemObject(mems[i]);
    clReleaseProgram(prg[0]);
    clReleaseProgram(prg[1]);
    clReleaseCommandQueue(q);
    clReleaseContext(ctx);
    free(pos);
    free(vis);
    free(index);
    free(depth);
    return 0;
}
