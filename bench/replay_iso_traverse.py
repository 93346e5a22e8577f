"""Replay one iso frame's macro_traverse launches on their captured inputs with
one or more versions of kernels_cl/iso/traverse.cl, and print each version's
per-launch process CPU time (min of --reps) and whether its outputs (candidate
blocks, candidate t, resume t) are bit for bit those of the first version.

    python bench/replay_iso_traverse.py [--n 256] [--reps 5] [--size 512x512] [--from-first]
                                        [SRC.cl[:WG:PACKET] ...]

SRC defaults to this tree's traverse.cl; give older versions as files
(a version whose macro_traverse takes float2 ranges, before the active bits
of macrocell.cl's range_bits, gets the renderer's ranges)
(`git show REV:kernels_cl/iso/traverse.cl > /tmp/old.cl`), alternated to
average out the machine's drift. --from-first also replays each launch with
every listed ray's resume t moved to its first candidate's t (from the first
version's outputs): the same candidates, and what a perfect start-depth
pre-pass could save at most (the walk up to the first candidate). A :WG:PACKET suffix sets the local size and
the PACKET define (rays a work-item; default 16:0, one ray a work-item, which
an older file without PACKET also runs). bench_iso's scene (turbulence N^3, ZFP rate
8, to 100 %). A measuring script, not a test: it wraps
clvis.iso.render.macro_traverse for one frame to copy its inputs.
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path
from typing import Any

import numpy as np
import pyopencl as cl

import clvis.iso.render as iso_render
from clvis import Camera, datasets, iso, zfp
from clvis.runtime.dispatch import EXACT_FP
from clvis.runtime.program import build_options

ROOT = Path(__file__).resolve().parent.parent
_WG = 16  # the cpu profile's local size (clvis.iso.traverse.PROFILES)


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def capture(n: int, w: int, h: int) -> tuple[cl.CommandQueue, list[dict[str, Any]]]:
    """One frame; the host copies of each macro_traverse launch's inputs."""
    caps: list[dict[str, Any]] = []
    orig = iso_render.macro_traverse

    def wrap(
        q: cl.CommandQueue,
        shape: Any,
        spacing: Any,
        origin: Any,
        isov: float,
        cam: Any,
        width: int,
        fine: Any,
        coarse: Any,
        active: Any,
        count: Any,
        max_rays: int,
        ray_t: Any,
        n_spec: int,
        cb: Any,
        ct: Any,
        **kw: Any,
    ) -> Any:
        q.finish()
        caps.append(
            dict(
                shape=shape,
                spacing=spacing,
                origin=origin,
                iso=isov,
                cam=cam.get(),
                w=width,
                fine=fine.get(),
                coarse=coarse.get(),
                active=active.get(),
                count=count.get(),
                max_rays=max_rays,
                ray_t=ray_t.get(),
                n_spec=n_spec,
                p0=kw.get("first_pixel", 0),
            )
        )
        return orig(
            q,
            shape,
            spacing,
            origin,
            isov,
            cam,
            width,
            fine,
            coarse,
            active,
            count,
            max_rays,
            ray_t,
            n_spec,
            cb,
            ct,
            **kw,
        )

    d = datasets.turbulence(n)
    zv = zfp.compress(d["volume"], 8)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"])
    lo = np.asarray(d["origin"], np.float64)
    hi = lo + (np.array(d["volume"].shape[::-1]) - 1) * np.asarray(d["spacing"][::-1])
    cam = Camera.fit(lo, hi, direction=(-0.6, 1.0, -0.45), aspect=w / h, fov_y=35)
    iso_render.macro_traverse = wrap  # type: ignore[assignment]
    try:
        r.render(cam, w, h, 0.5)
    finally:
        iso_render.macro_traverse = orig
    fine_r, coarse_r = (g.get() for g in (r.grids.fine, r.grids.coarse))  # type: ignore[union-attr]
    for c in caps:
        c["fine_r"], c["coarse_r"] = fine_r, coarse_r
    return r.queue, caps


def run(
    q: cl.CommandQueue, src: str, caps: list[dict[str, Any]], reps: int, wg: int = _WG, packet: int = 0
) -> tuple[list[float], list[Any]]:
    ctx = q.context
    opts = build_options(q.device, {"PACKET": packet}, EXACT_FP)
    k = cl.Kernel(cl.Program(ctx, src).build(options=opts), "macro_traverse")
    per = max(packet, 1)
    mf = cl.mem_flags

    def buf(a: np.ndarray) -> cl.Buffer:
        return cl.Buffer(ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a))

    cpus, outs = [], []
    for c in caps:
        grids = ("fine", "coarse") if "fine_bits" in src else ("fine_r", "coarse_r")
        fine, coarse, camb, act, cnt = (buf(c[x]) for x in (*grids, "cam", "active", "count"))
        m = c["max_rays"] * c["n_spec"]
        cb, ct = cl.Buffer(ctx, mf.READ_WRITE, 4 * m), cl.Buffer(ctx, mf.READ_WRITE, 4 * m)
        nz, ny, nx = c["shape"]
        dz, dy, dx = c["spacing"]
        ox, oy, oz = c["origin"]
        items = -(-c["max_rays"] // per)
        gs = (items + wg - 1) // wg * wg
        best = float("inf")
        for _ in range(reps):
            rt = buf(c["ray_t"])
            k.set_args(
                *(np.uint32(v) for v in (nx, ny, nz)),
                *(np.float32(v) for v in (dx, dy, dz, ox, oy, oz)),
                np.float32(c["iso"]),
                camb,
                np.uint32(c["w"]),
                np.uint32(c["p0"]),
                fine,
                coarse,
                act,
                cnt,
                rt,
                np.uint32(c["n_spec"]),
                cb,
                ct,
            )
            q.finish()
            c0 = _cpu()
            cl.enqueue_nd_range_kernel(q, k, (gs,), (wg,)).wait()
            best = min(best, _cpu() - c0)
        o = (np.empty(m, np.uint32), np.empty(m, np.uint32), np.empty(c["ray_t"].size, np.uint32))
        for host, dev in zip(o, (cb, ct, rt), strict=True):
            cl.enqueue_copy(q, host, dev)
        q.finish()
        cpus.append(best)
        outs.append(o)
    return cpus, outs


def from_first(c: dict[str, Any], out: Any) -> dict[str, Any]:
    """Launch c with each listed ray's ray_t set to its first candidate's t (out: the
    launch's outputs) where it has one: the walk from there gives the same candidates."""
    cnt, ns = int(c["count"][0]), c["n_spec"]
    first = out[1].view(np.float32).reshape(-1, ns)[:cnt, 0]
    has = np.isfinite(first)
    rt = c["ray_t"].copy()
    rt[c["active"][:cnt][has]] = first[has]
    return dict(c, ray_t=rt)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("src", nargs="*", help="traverse.cl versions (default: this tree's)")
    ap.add_argument("--n", type=int, default=256)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--size", default="512x512")
    ap.add_argument("--from-first", action="store_true", help="also start each ray at its first candidate")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.lower().split("x"))
    srcs = a.src or [str(ROOT / "kernels_cl/iso/traverse.cl")]
    t0 = time.perf_counter()
    q, caps = capture(a.n, w, h)
    launches = [(int(c["count"][0]), c["n_spec"]) for c in caps]
    scene_s = time.perf_counter() - t0
    print(f"{q.device.name}: {len(caps)} launches (rays, n_spec) {launches}, scene {scene_s:.1f} s")
    ref = None
    for spec in srcs:
        path, wg, packet = spec, _WG, 0
        parts = spec.rsplit(":", 2)
        if len(parts) == 3 and parts[1].isdigit() and parts[2].isdigit():
            path, wg, packet = parts[0], int(parts[1]), int(parts[2])
        cpus, outs = run(q, Path(path).read_text(), caps, a.reps, wg, packet)
        if ref is None:
            ref, same = outs, "(the reference)"
        else:
            same = str(
                all(
                    np.array_equal(x, y)
                    for o, r in zip(outs, ref, strict=True)
                    for x, y in zip(o, r, strict=True)
                )
            )
        per = ", ".join(f"{c * 1e3:.1f}" for c in cpus)
        total = sum(cpus) * 1e3
        print(f"{spec}: CPU per launch (min of {a.reps}) {per} ms, sum {total:.1f} ms; identical {same}")
        if a.from_first:
            starts = [from_first(c, o) for c, o in zip(caps, ref, strict=True)]
            cpus, outs = run(q, Path(path).read_text(), starts, a.reps, wg, packet)
            same = all(np.array_equal(o[j], r[j]) for o, r in zip(outs, ref, strict=True) for j in (0, 1))
            per = ", ".join(f"{c * 1e3:.1f}" for c in cpus)
            total = sum(cpus) * 1e3
            print(f"  started at the first candidate: {per} ms, sum {total:.1f} ms; same candidates {same}")


if __name__ == "__main__":
    main()
