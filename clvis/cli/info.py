"""`clvis info`: the OpenCL platforms and devices, the one clvis uses, its capabilities."""

from __future__ import annotations

import argparse
import sys

from ._common import Parser


def add_parser(sub: argparse._SubParsersAction[Parser]) -> Parser:
    return sub.add_parser("info", help="platforms, devices and the chosen device's capabilities")


def cmd(args: argparse.Namespace) -> int:
    from .. import __version__, runtime
    from ..errors import ClvisError

    print(f"clvis {__version__}   kernels: {runtime.KERNEL_ROOT}")
    devs = runtime.devices()
    if not devs:
        print("no OpenCL platform found: pip install 'pyopencl[pocl]' for the portable CPU driver")
        return 1
    try:
        chosen = runtime.default_queue().device
    except ClvisError as e:  # the devices are listed below: the error says what CLVIS_DEVICE missed
        print(f"clvis info: error: {e}", file=sys.stderr)
        chosen = None
    print("devices (CLVIS_DEVICE takes the index or part of the name):")
    for i, d in enumerate(devs):
        mark = "*" if chosen is not None and d.int_ptr == chosen.int_ptr else " "
        print(f" {mark} {i}: {runtime.describe(d)}  [{runtime.capabilities(d).device_type}]")
    if chosen is None:
        return 1
    caps = runtime.capabilities(chosen)
    print(f"\nclvis uses: {runtime.describe(chosen)}")
    rows = [
        ("OpenCL", caps.opencl_version),
        ("driver", caps.driver_version),
        ("compute units", caps.compute_units),
        ("max work-group size", caps.max_work_group_size),
        ("local memory", f"{caps.local_mem_bytes:,} bytes"),
        ("max single allocation", f"{caps.max_alloc_bytes:,} bytes"),
        ("global memory", f"{caps.global_mem_bytes:,} bytes"),
        ("64-bit atomics", _int64_text(caps)),
        ("subgroups", "yes" if caps.subgroups else "no"),
        ("fp64", "yes" if caps.fp64 else "no"),
        ("tuning profile", runtime.tuning_profile(chosen)),
    ]
    for k, v in rows:
        print(f"  {k:22} {v}")
    return 0


def _int64_text(caps) -> str:
    if caps.int64_atomics:
        return "yes"
    if caps.int64_atomics_native:
        return "no (forced off: CLVIS_NO_INT64_ATOMICS)"
    return "no (fallback paths)"
