"""Frame CPU of IsoRenderer.render under speculation schedules, alternated in
one process: each variant DIV:FIRST[:CAPACITY] sets the renderer's schedule
(render.PROFILES' spec_div and spec_first; 1:2 is the paper's, the gpu
profile's) and optionally the cold cache's initial capacity. Prints each
variant's median process CPU over --rounds cold-cache frames, the frame's
SHA-1 (rgba, depth, hit, t, active: the image must not depend on the
schedule), candidates per ray per pass, blocks decoded and items.

    python bench/sweep_iso_schedule.py [--rounds 6] [--size 512x512]
        [--dir -0.6,1.0,-0.45] [--iso 0.5] [--data turbulence] [--n 256] 1:2 2:3 ...

bench_iso's scene by default (turbulence 256^3, ZFP rate 8, Camera.fit from
--dir). Run from the checkout root with PYTHONPATH=. so its clvis is used.
A measuring script, not a test.
"""

from __future__ import annotations

import argparse
import hashlib
import resource

import numpy as np

from clvis import Camera, datasets, iso, zfp


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _sha(img: iso.IsoImage) -> str:
    h = hashlib.sha1()
    for a in (img.rgba, img.depth, img.hit, img.t, img.active):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:12]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--size", default="512x512")
    ap.add_argument("--dir", default="-0.6,1.0,-0.45", help="the view direction of Camera.fit")
    ap.add_argument("--iso", type=float, default=0.5)
    ap.add_argument("--data", default="turbulence", help="turbulence or marschner_lobb")
    ap.add_argument("--n", type=int, default=256)
    ap.add_argument("variants", nargs="*", default=["1:2", "2:3"], help="DIV:FIRST[:CAPACITY]")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.lower().split("x"))
    d = getattr(datasets, a.data)(a.n)
    zv = zfp.compress(d["volume"], 8)
    r = iso.IsoRenderer(zv, spacing=d["spacing"], origin=d["origin"])
    lo = np.asarray(d["origin"], np.float64)
    hi = lo + (np.array(d["volume"].shape[::-1]) - 1) * np.asarray(d["spacing"][::-1])
    view = tuple(float(x) for x in a.dir.split(","))
    cam = Camera.fit(lo, hi, direction=view, aspect=w / h, fov_y=35)
    variants = {v: tuple(int(x) for x in v.split(":")) for v in a.variants}
    cpu: dict[str, list[float]] = {v: [] for v in variants}
    info: dict[str, str] = {}
    r.render(cam, w, h, a.iso)  # builds the kernels
    for _ in range(a.rounds):
        for v, (div, first, *cap) in variants.items():
            r._spec = (div, first)
            r.reset_cache(cap[0] if cap else None)
            c0 = _cpu()
            img = r.render(cam, w, h, a.iso)
            cpu[v].append((_cpu() - c0) * 1e3)
            st = img.stats
            info.setdefault(
                v,
                f"sha {_sha(img)} n_spec {st['n_spec_per_pass']} decoded {st['blocks_decoded']} "
                f"items {sum(st['items_per_pass'])}",
            )
    base = float(np.median(cpu[a.variants[0]]))
    for v in variants:
        m = float(np.median(cpu[v]))
        print(f"{v:12s} median {m:6.1f} ms CPU ({m / base:.3f} of {a.variants[0]})  {info[v]}")
    load = " ".join(open("/proc/loadavg").read().split()[:3])
    print(f"{a.data} {a.n}^3 {a.size} dir {a.dir} iso {a.iso}, {a.rounds} rounds, load {load}")


if __name__ == "__main__":
    main()
