"""Per-kernel split of one IsoRenderer frame (bench_iso's scene: turbulence
N^3, ZFP rate 8, 512x512 or --size, to 100%, cold block cache), from OpenCL event
profiling and, with --cpu, the process CPU time around each launch (each
launch is then waited for before the next: the renderer's queue is in order,
so this changes little).

    python bench/profile_iso.py [--n 256] [--rounds 3] [--size 512x512] [--cpu]

A measuring script, not a test: it wraps pyopencl.enqueue_nd_range_kernel
(through which clvis.runtime.launch enqueues) for the life of this process.
"""

from __future__ import annotations

import argparse
import collections
import resource
import time
from typing import Any

import numpy as np
import pyopencl as cl

from clvis import Camera, datasets, iso, zfp


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=256)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--size", default="512x512", help="WxH (the camera's aspect follows)")
    ap.add_argument("--cpu", action="store_true", help="CPU time per kernel (waits after each launch)")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.lower().split("x"))

    events: list[tuple[str, cl.Event]] = []
    cpus: dict[str, float] = collections.defaultdict(float)
    enqueue = cl.enqueue_nd_range_kernel

    def recording(queue: cl.CommandQueue, kernel: cl.Kernel, *args: Any, **kw: Any) -> cl.Event:
        if a.cpu:
            queue.finish()
            c0 = _cpu()
        e = enqueue(queue, kernel, *args, **kw)
        if a.cpu:
            e.wait()
            cpus[kernel.function_name] += _cpu() - c0
        events.append((kernel.function_name, e))
        return e

    cl.enqueue_nd_range_kernel = recording  # type: ignore[assignment]
    d = datasets.turbulence(a.n)
    zv = zfp.compress(d["volume"], 8)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"])
    lo = np.asarray(d["origin"], np.float64)
    hi = lo + (np.array(d["volume"].shape[::-1]) - 1) * np.asarray(d["spacing"][::-1])
    cam = Camera.fit(lo, hi, direction=(-0.6, 1.0, -0.45), aspect=w / h, fov_y=35)
    r.render(cam, w, h, 0.5)  # builds the kernels
    for i in range(a.rounds):
        events.clear()
        cpus.clear()
        r.reset_cache()
        c0, t0 = _cpu(), time.perf_counter()
        img = r.render(cam, w, h, 0.5)
        wall, cpu = time.perf_counter() - t0, _cpu() - c0
        span = img.stats["seconds"]
        per: dict[str, float] = collections.defaultdict(float)
        for name, e in events:
            e.wait()
            per[name] += (e.profile.end - e.profile.start) * 1e-9
        load = " ".join(open("/proc/loadavg").read().split()[:3])
        print(
            f"round {i}: wall {wall * 1e3:.0f} ms, process CPU {cpu * 1e3:.0f} ms, device span "
            f"{span * 1e3:.0f} ms, passes {img.stats['passes']}, blocks decoded "
            f"{img.stats['blocks_decoded']}, load {load}"
        )
        rows = sorted(per.items(), key=lambda kv: -kv[1]) + [("(all kernels)", sum(per.values()))]
        for name, s in rows:
            c = sum(cpus.values()) if name.startswith("(") else cpus[name]
            line = f"   {name:24s} {s * 1e3:7.1f} ms {100 * s / span:5.1f} % of the span"
            print(line + (f"   CPU {c * 1e3:7.1f} ms {100 * c / cpu:5.1f} %" if a.cpu else ""))


if __name__ == "__main__":
    main()
