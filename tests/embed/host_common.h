/* host_common.h — what the embedding hosts share: error checks, reading a
 * file, picking a device by platform name. Plain C99 and OpenCL 1.2 headers.
 */
#ifndef CLVIS_HOST_COMMON_H
#define CLVIS_HOST_COMMON_H
#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CHECK(call)                                                              \
    do {                                                                         \
        cl_int err_ = (call);                                                    \
        if (err_ != CL_SUCCESS) {                                                \
            fprintf(stderr, "%s:%d: %s failed: %d\n", __FILE__, __LINE__, #call, \
                    (int)err_);                                                  \
            exit(2);                                                             \
        }                                                                        \
    } while (0)

static char *read_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        perror(path);
        exit(2);
    }
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *text = malloc((size_t)size + 1);
    if (fread(text, 1, (size_t)size, f) != (size_t)size) {
        perror(path);
        exit(2);
    }
    text[size] = 0;
    fclose(f);
    return text;
}

static cl_device_id pick_device(const char *want, char *name, size_t name_len)
{
    cl_platform_id platforms[16];
    cl_uint np = 0;
    CHECK(clGetPlatformIDs(16, platforms, &np));
    for (cl_uint i = 0; i < np; ++i) {
        CHECK(clGetPlatformInfo(platforms[i], CL_PLATFORM_NAME, name_len, name, NULL));
        if (strstr(name, want)) {
            cl_device_id dev;
            CHECK(clGetDeviceIDs(platforms[i], CL_DEVICE_TYPE_ALL, 1, &dev, NULL));
            return dev;
        }
    }
    fprintf(stderr, "no OpenCL platform named like '%s'\n", want);
    exit(2);
}

#endif /* CLVIS_HOST_COMMON_H */
