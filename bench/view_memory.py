"""The viewer's resident memory over window sizes: a volume scene's frames
(``clvis.view.scenes.view_frames``, as the server renders them) at N sizes
one after another, as a window dragged wider and taller, the process's RSS
every five sizes. Each new size gives the pool's held blocks back and trims
the C heap after its frames.

    python bench/view_memory.py [--sizes 40] [--volume 64] [--pattern grow|wander]

``grow`` (the default) widens the window by 7x5 pixels a size, so the
frames themselves grow (900x600 .. 1173x795 over 40 sizes): RSS follows the
largest frame. ``wander`` gives as many sizes, each new, drawn at random
(seeded) from grow's range at 40 sizes: a leak would grow here too.

bench/results/README.md has the output. A measuring script, not a test.
"""

from __future__ import annotations

import argparse
import os
import random
import time

from clvis import datasets
from clvis.view import Orbit, VolumeScene
from clvis.view.scenes import view_frames


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, default=40)
    ap.add_argument("--volume", type=int, default=64, help="the Marschner-Lobb volume's side")
    ap.add_argument("--pattern", choices=("grow", "wander"), default="grow")
    args = ap.parse_args(argv)
    d = datasets.marschner_lobb(args.volume)
    scene = VolumeScene(d["volume"], d["spacing"], d["origin"], 0.5)
    orbit = Orbit(scene.lo, scene.hi)
    t0, first = time.perf_counter(), None
    if args.pattern == "grow":
        sizes = [(900 + 7 * i, 600 + 5 * i) for i in range(args.sizes)]
    else:  # each size new, from grow's range, in a random order
        pick = random.Random(0)
        seen: set[tuple[int, int]] = set()
        sizes = []
        while len(sizes) < args.sizes:
            s = (900 + pick.randrange(274), 600 + pick.randrange(196))
            if s not in seen:
                seen.add(s)
                sizes.append(s)
    for i, (w, h) in enumerate(sizes):
        for _ in view_frames(scene, orbit.camera(w / h), w, h, scene.settings, lambda: False):
            pass
        if i % 5 == 4:
            now = rss_mb()
            first = now if first is None else first
            print(f"{i + 1:4} sizes (last {w}x{h}): RSS {now:6.0f} MB", flush=True)
    n = (args.sizes - 5) // 5 * 5
    if n > 0:
        growth = (rss_mb() - first) / n
        print(f"growth {growth:.1f} MB a size over the last {n} ({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
