/* scan_host.c — uses kernels_cl/primitives/scan.cl from plain C, following
 * only the ABI comment at the top of that file: proof that clvis's kernels
 * embed in an application without Python.
 *
 *   cc -std=c99 -O2 scan_host.c -lOpenCL -o scan_host
 *   ./scan_host <path to kernels_cl> [platform name substring]
 *
 * For each work shape (WG=1, ITEMS=16: CPU form; WG=64, ITEMS=4: GPU form)
 * and both scan kinds it scans n uints on the chosen platform's first device
 * and compares with a serial scan. Prints one line per case, exits 0 when all
 * match.
 */
#include "host_common.h"

/* One scan of n uints, following scan.cl's ABI; returns 0 when it matches. */
static int run_case(cl_context ctx, cl_command_queue q, cl_device_id dev,
                    const char *source, const char *root, unsigned wg,
                    unsigned items, cl_uint exclusive, size_t n)
{
    char options[4096];
    snprintf(options, sizeof options, "-I %s/include -DT=uint -DWG=%u -DITEMS=%u",
             root, wg, items);
    cl_int err;
    cl_program prg = clCreateProgramWithSource(ctx, 1, &source, NULL, &err);
    CHECK(err);
    if (clBuildProgram(prg, 1, &dev, options, NULL, NULL) != CL_SUCCESS) {
        char log[16384];
        clGetProgramBuildInfo(prg, dev, CL_PROGRAM_BUILD_LOG, sizeof log, log, NULL);
        fprintf(stderr, "build failed (%s):\n%s\n", options, log);
        return 1;
    }
    cl_kernel reduce = clCreateKernel(prg, "scan_reduce", &err);
    CHECK(err);
    cl_kernel down = clCreateKernel(prg, "scan_downsweep", &err);
    CHECK(err);

    /* partition: G ranges of per_group elements, per_group a multiple of TILE */
    const cl_ulong tile = (cl_ulong)wg * items;
    const cl_ulong groups_wanted = 16;
    cl_ulong per_group = (n + groups_wanted - 1) / groups_wanted;
    per_group = (per_group + tile - 1) / tile * tile;
    const cl_ulong G = (n + per_group - 1) / per_group;

    cl_uint *x = malloc(n * sizeof *x), *y = malloc(n * sizeof *y);
    for (size_t i = 0; i < n; ++i)
        x[i] = (cl_uint)((i * 2654435761u) >> 20);
    cl_mem in = clCreateBuffer(ctx, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, n * sizeof *x, x, &err);
    CHECK(err);
    cl_mem out = clCreateBuffer(ctx, CL_MEM_WRITE_ONLY, n * sizeof *x, NULL, &err);
    CHECK(err);
    cl_mem partials = clCreateBuffer(ctx, CL_MEM_READ_WRITE, G * sizeof(cl_uint), NULL, &err);
    CHECK(err);
    cl_mem total = clCreateBuffer(ctx, CL_MEM_WRITE_ONLY, sizeof(cl_uint), NULL, &err);
    CHECK(err);
    const cl_ulong n64 = n;

    CHECK(clSetKernelArg(reduce, 0, sizeof in, &in));
    CHECK(clSetKernelArg(reduce, 1, sizeof n64, &n64));
    CHECK(clSetKernelArg(reduce, 2, sizeof per_group, &per_group));
    CHECK(clSetKernelArg(reduce, 3, sizeof partials, &partials));
    CHECK(clSetKernelArg(down, 0, sizeof in, &in));
    CHECK(clSetKernelArg(down, 1, sizeof out, &out));
    CHECK(clSetKernelArg(down, 2, sizeof n64, &n64));
    CHECK(clSetKernelArg(down, 3, sizeof per_group, &per_group));
    CHECK(clSetKernelArg(down, 4, sizeof partials, &partials));
    CHECK(clSetKernelArg(down, 5, sizeof exclusive, &exclusive));
    CHECK(clSetKernelArg(down, 6, sizeof total, &total));
    const size_t global = (size_t)G * wg, local = wg;
    CHECK(clEnqueueNDRangeKernel(q, reduce, 1, NULL, &global, &local, 0, NULL, NULL));
    CHECK(clEnqueueNDRangeKernel(q, down, 1, NULL, &global, &local, 0, NULL, NULL));
    cl_uint got_total = 0;
    CHECK(clEnqueueReadBuffer(q, out, CL_TRUE, 0, n * sizeof *y, y, 0, NULL, NULL));
    CHECK(clEnqueueReadBuffer(q, total, CL_TRUE, 0, sizeof got_total, &got_total, 0, NULL, NULL));

    size_t bad = 0;
    cl_uint run = 0;
    for (size_t i = 0; i < n; ++i) {
        const cl_uint want = exclusive ? run : run + x[i];
        run += x[i];
        bad += (y[i] != want);
    }
    const int ok = (bad == 0 && got_total == run);
    printf("scan.cl T=uint WG=%u ITEMS=%u %s n=%zu groups=%llu: %s\n", wg, items,
           exclusive ? "exclusive" : "inclusive", n, (unsigned long long)G,
           ok ? "OK" : "MISMATCH");
    clReleaseMemObject(in);
    clReleaseMemObject(out);
    clReleaseMemObject(partials);
    clReleaseMemObject(total);
    clReleaseKernel(reduce);
    clReleaseKernel(down);
    clReleaseProgram(prg);
    free(x);
    free(y);
    return ok ? 0 : 1;
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: %s <kernels_cl dir> [platform name substring]\n", argv[0]);
        return 2;
    }
    const char *root = argv[1];
    char name[256];
    cl_device_id dev = pick_device(argc > 2 ? argv[2] : "Portable Computing Language",
                                   name, sizeof name);
    printf("platform: %s\n", name);
    char path[4096];
    snprintf(path, sizeof path, "%s/primitives/scan.cl", root);
    char *source = read_file(path);

    cl_int err;
    cl_context ctx = clCreateContext(NULL, 1, &dev, NULL, NULL, &err);
    CHECK(err);
    cl_command_queue q = clCreateCommandQueue(ctx, dev, 0, &err);
    CHECK(err);
    int failures = 0;
    const unsigned shapes[2][2] = {{1, 16}, {64, 4}};
    for (int s = 0; s < 2; ++s)
        for (cl_uint ex = 0; ex < 2; ++ex)
            failures += run_case(ctx, q, dev, source, root, shapes[s][0], shapes[s][1], ex, 1000003);
    clReleaseCommandQueue(q);
    clReleaseContext(ctx);
    free(source);
    return failures ? 1 : 0;
}
