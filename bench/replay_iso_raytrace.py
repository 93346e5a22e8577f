"""Replay one iso frame's raytrace_blocks launches on their captured inputs
under one or more work shapes (local size, PACKET) of the cpu profile, and
print each shape's per-launch process CPU time (min of --reps) and whether its
results are bit for bit those of the first shape.

    python bench/replay_iso_raytrace.py [--n 256] [--reps 5] [--size 512x512] [WG:PACKET ...]

Shapes default to 16:0 (one ray a work-item, the profile before packets) and
this tree's clvis.iso.raytrace.PROFILES["cpu"]; alternate them (16:0 2:8 16:0
2:8) to average out the machine's drift. bench_iso's scene (turbulence N^3, ZFP
rate 8, to 100 %). The results compared are the pixels' 64-bit hit keys and,
per pixel, the winning item's hit t, colour and depth (which other items
write depends on the order of the groups: the early exit of raytrace.cl's
ITEMS mode). A measuring script, not a test: it wraps
clvis.iso.render.raytrace_blocks for one frame to copy its inputs.
"""

from __future__ import annotations

import argparse
import resource
import time
from typing import Any

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

import clvis.iso.render as iso_render
from clvis import Camera, datasets, iso, runtime, zfp
from clvis.iso import raytrace


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _host(a: Any) -> Any:
    return a.get() if isinstance(a, cla.Array) else a


def capture(n: int, w: int, h: int) -> tuple[cl.CommandQueue, list[dict[str, Any]]]:
    """One frame; the host copies of each raytrace_blocks launch's inputs."""
    caps: list[dict[str, Any]] = []
    orig = iso_render.raytrace_blocks

    def wrap(q: cl.CommandQueue, *args: Any, **kw: Any) -> Any:
        q.finish()
        (bricks, slots, shape, spacing, origin, isov, cam, width, groups, ray_ids, ray_t, outputs) = args
        item_pixel, n_spec, hitkey = kw["items"]
        caps.append(
            dict(
                bricks=bricks.get(),
                slots=slots.get(),
                rest=(shape, spacing, origin, isov),
                cam=cam.get(),
                width=width,
                groups=tuple(g.get() for g in groups),
                ray_ids=ray_ids.get(),
                ray_t=ray_t.get(),
                outputs=tuple(o.get() for o in outputs),
                item_pixel=item_pixel.get(),
                n_spec=n_spec,
                hitkey=_host(hitkey),
                p0=kw.get("first_pixel", 0),
            )
        )
        return orig(q, *args, **kw)

    d = datasets.turbulence(n)
    zv = zfp.compress(d["volume"], 8)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"])
    lo = np.asarray(d["origin"], np.float64)
    hi = lo + (np.array(d["volume"].shape[::-1]) - 1) * np.asarray(d["spacing"][::-1])
    cam = Camera.fit(lo, hi, direction=(-0.6, 1.0, -0.45), aspect=w / h, fov_y=35)
    iso_render.raytrace_blocks = wrap  # type: ignore[assignment]
    try:
        r.render(cam, w, h, 0.5)
    finally:
        iso_render.raytrace_blocks = orig
    return r.queue, caps


def run(q: cl.CommandQueue, caps: list[dict[str, Any]], reps: int) -> tuple[list[float], list[Any]]:
    def dev(a: np.ndarray) -> cla.Array:
        return cla.to_device(q, np.ascontiguousarray(a))

    cpus, outs = [], []
    for c in caps:
        fixed = [dev(c[x]) for x in ("bricks", "slots", "cam", "item_pixel")]
        groups = tuple(dev(g) for g in c["groups"])
        ids = dev(c["ray_ids"])
        shape, spacing, origin, isov = c["rest"]
        best = float("inf")
        for _ in range(reps):
            rt = dev(c["ray_t"])
            o = tuple(dev(x) for x in c["outputs"])
            hk = dev(c["hitkey"]) if c["hitkey"] is not None else None
            raytrace.raytrace_kernel(q, 8, True)  # built before the clock
            q.finish()
            c0 = _cpu()
            ev = raytrace.raytrace_blocks(
                q,
                fixed[0],
                fixed[1],
                shape,
                spacing,
                origin,
                isov,
                fixed[2],
                c["width"],
                groups,  # type: ignore[arg-type]
                ids,
                rt,
                o,  # type: ignore[arg-type]
                items=(fixed[3], c["n_spec"], hk),
                first_pixel=c["p0"],
            )
            if ev is not None:
                ev.wait()
            best = min(best, _cpu() - c0)
        hit, t, rgba, depth = (x.get() for x in o)
        if hk is not None:
            key = hk.get()
            won = key != np.uint64(2**64 - 1)
            e = (key[won] & np.uint64(0xFFFFFFFF)).astype(np.int64)
            res: Any = (key, t[e], rgba[e], depth[e])
        else:
            res = (hit, t, rgba, depth)
        cpus.append(best)
        outs.append(res)
    return cpus, outs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("shape", nargs="*", help="WG:PACKET work shapes of the cpu profile")
    ap.add_argument("--n", type=int, default=256)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--size", default="512x512")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.lower().split("x"))
    mine = raytrace.PROFILES["cpu"]
    shapes = a.shape or ["16:0", f"{mine['wg']}:{mine['packet']}"]
    t0 = time.perf_counter()
    q, caps = capture(a.n, w, h)
    if runtime.tuning_profile(q) != "cpu":
        raise SystemExit("replay_iso_raytrace: the device's tuning profile is not 'cpu'")
    launches = [int(c["groups"][0].size) for c in caps]
    items = [int(c["groups"][2].sum()) for c in caps]
    scene_s = time.perf_counter() - t0
    print(f"{q.device.name}: {len(caps)} launches, groups {launches}, items {items}, scene {scene_s:.1f} s")
    ref = None
    try:
        for s in shapes:
            wg, packet = (int(v) for v in s.split(":"))
            raytrace.PROFILES["cpu"] = {"wg": wg, "packet": packet}
            cpus, outs = run(q, caps, a.reps)
            if ref is None:
                ref, same = outs, "(the reference)"
            else:
                pairs = (xy for o, r in zip(outs, ref, strict=True) for xy in zip(o, r, strict=True))
                same = str(all(np.array_equal(x, y) for x, y in pairs))
            per = ", ".join(f"{c * 1e3:.1f}" for c in cpus)
            total = sum(cpus) * 1e3
            print(
                f"wg {wg} packet {packet}: CPU per launch (min of {a.reps}) {per} ms, "
                f"sum {total:.1f} ms; identical {same}"
            )
    finally:
        raytrace.PROFILES["cpu"] = mine


if __name__ == "__main__":
    main()
