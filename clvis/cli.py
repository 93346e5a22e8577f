"""The clvis command line.

    clvis info                   OpenCL platforms and devices, the one clvis uses, its capabilities
    clvis demo                   runs the kernel families on generated data and prints the figures
    clvis bench primitives       the benchmark suite with its peers, as a table (and JSON)
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def _cmd_info(args) -> int:
    from . import __version__, runtime
    from .errors import ClvisError

    print(f"clvis {__version__}   kernels: {runtime.KERNEL_ROOT}")
    devs = runtime.devices()
    if not devs:
        print("no OpenCL platform found: pip install 'pyopencl[pocl]' for the portable CPU driver")
        return 1
    try:
        chosen = runtime.default_queue().device
    except ClvisError as e:
        print(f"error: {e}")
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


def _timed(fn, queue=None, repeat=3) -> float:
    """Best of `repeat` timed runs after one warm-up (which builds the
    kernels); a single timed run when that one takes over half a second."""
    def once():
        t0 = time.perf_counter()
        fn()
        if queue is not None:
            queue.finish()
        return time.perf_counter() - t0

    once()
    best = once()
    if best > 0.5:
        return best
    for _ in range(repeat - 1):
        best = min(best, once())
    return best


def _cmd_demo(args) -> int:
    import pyopencl.array as cla

    from . import __version__, primitives, runtime
    from .reference import primitives as ref

    q = runtime.default_queue()
    caps = runtime.capabilities(q)
    n = args.n
    print(f"clvis {__version__} on {runtime.describe(q.device)} "
          f"({caps.device_type}, {caps.compute_units} compute units, tuning {runtime.tuning_profile(q)})")
    print("\nprimitives on generated data, device-resident arrays; numpy on the host "
          "(best of 3 after a warm-up that builds the kernels):\n")
    rng = np.random.default_rng(0)
    x = rng.integers(0, 100, n).astype(np.int32)
    mask = rng.random(n) < 0.5
    keys = rng.integers(0, 1 << 32, n, dtype=np.uint64).astype(np.uint32)
    vals = np.arange(n, dtype=np.uint32)
    bins = rng.integers(0, 256, n).astype(np.int32)
    xd, md = cla.to_device(q, x), cla.to_device(q, mask)
    kd, vd, bd = cla.to_device(q, keys), cla.to_device(q, vals), cla.to_device(q, bins)

    def np_sort():
        o = np.argsort(keys, kind="stable")
        return keys[o], vals[o]

    cases = [
        ("scan int32 (exclusive)", lambda: primitives.scan(xd),
         lambda: np.cumsum(x, dtype=np.int32), "np.cumsum",   # the same int32 output
         lambda: np.array_equal(primitives.scan(xd).get(), ref.scan(x))),
        ("compact int32, half kept", lambda: primitives.compact(xd, md),
         lambda: x[mask], "boolean mask",
         lambda: np.array_equal(primitives.compact(xd, md).get(), ref.compact(x, mask))),
        ("radix sort uint32 keys+values", lambda: primitives.radix_sort(kd, vd),
         np_sort, "argsort+gather",
         lambda: all(np.array_equal(a.get(), b) for a, b in
                     zip(primitives.radix_sort(kd, vd), ref.radix_sort(keys, vals)))),
        ("histogram, 256 bins", lambda: primitives.histogram(bd, 256),
         lambda: np.bincount(bins, minlength=256), "np.bincount",
         lambda: np.array_equal(primitives.histogram(bd, 256).get(), ref.histogram(bins, 256))),
    ]
    print(f"  {'op (n = ' + format(n, ',') + ')':34} {'clvis':>16} {'numpy':>26} {'speed-up':>9}  reference")
    ok_all = True
    for name, fn, npfn, npname, check in cases:
        t_cl = _timed(fn, q)
        t_np = _timed(npfn)
        ok = bool(check())
        ok_all &= ok
        print(f"  {name:34} {t_cl * 1e3:7.2f} ms {n / t_cl / 1e6:5.0f} M/s   "
              f"{npname:>14} {t_np * 1e3:7.2f} ms {t_np / t_cl:8.1f}x  {'matches' if ok else 'MISMATCH'}")
    print("\nfull benchmarks with every peer: clvis bench primitives")
    return 0 if ok_all else 1


def _bench_dir() -> Path | None:
    for cand in (Path.cwd() / "bench", Path(__file__).resolve().parent.parent / "bench"):
        if (cand / "bench_primitives.py").is_file():
            return cand
    return None


def _cmd_bench(args) -> int:
    from . import benchreport, runtime

    if args.report:
        rows, meta = benchreport.load(args.report)
    else:
        bench = _bench_dir()
        if bench is None:
            print("clvis bench needs the bench/ folder of a source checkout "
                  "(run it from the repository root)", file=sys.stderr)
            return 2
        q = runtime.default_queue()
        out = Path(args.json) if args.json else (
            bench / "results" / runtime.device_slug(q) / f"{args.family}.json")
        out.parent.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ)
        if args.scale is not None:
            env["CLVIS_BENCH_SCALE"] = str(args.scale)
        cmd = [sys.executable, "-m", "pytest", str(bench / f"bench_{args.family}.py"), "-q",
               "-p", "no:cacheprovider", f"--benchmark-json={out}", "--benchmark-disable-gc"]
        print("running:", " ".join(cmd), flush=True)
        r = subprocess.run(cmd, cwd=bench.parent, env=env, stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)
        if r.returncode != 0:
            print(r.stdout[-4000:])
            return r.returncode
        rows, meta = benchreport.load(out)
        print(f"results: {out}")
    print(benchreport.format_table(rows, meta))
    results = benchreport.check(rows, args.family, meta.get("tuning", "cpu"))
    if results:
        print(f"\ntargets ({meta.get('tuning', 'cpu')} device):")
        print(benchreport.format_checks(results))
    if args.check and not all(ok for _, _, ok in results):
        return 1
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="clvis", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("info", help="platforms, devices and the chosen device's capabilities")
    d = sub.add_parser("demo", help="run the kernels on generated data and print the figures")
    d.add_argument("--n", type=int, default=1 << 24, help="elements (default 2^24)")
    b = sub.add_parser("bench", help="run a benchmark suite and print its table")
    b.add_argument("family", choices=["primitives"])
    b.add_argument("--scale", type=float, help="multiply every size (e.g. 0.01 for a smoke run)")
    b.add_argument("--json", help="where to write the JSON (default bench/results/<device>/<family>.json)")
    b.add_argument("--report", help="print the table of an existing JSON instead of running")
    b.add_argument("--check", action="store_true", help="exit 1 if a target is missed")
    args = p.parse_args(argv)
    return {"info": _cmd_info, "demo": _cmd_demo, "bench": _cmd_bench}[args.cmd](args)


if __name__ == "__main__":
    sys.exit(main())
