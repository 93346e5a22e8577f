"""The splat radius range narvis-scan trained on (its spec's radius_px_trained).

For frames of the training kinds (clvis.training.data.SCAN_TRAIN) at 0.25x, 1x
and 4x SCAN_POINTS_PER_PIXEL, 256 and 512 pixels square, two random views each
(the training's own scan_cameras), prints each frame's median of the radius
plane (GBuffers.radius_px, pixels) over its covered pixels, then the range
over all frames. ``clvis render --post narvis`` says so when a cloud's median
lies over twice the largest or under half the smallest
(clvis.post.specs.NetworkSpec.unlike_training).

    python bench/scan_radius_range.py [KIND,KIND,...]

Pass held-out kinds (terrain, aerial, object) to see where they fall.
"""

from __future__ import annotations

import sys

import numpy as np

from clvis import post
from clvis.training import data


def main(kinds: tuple[str, ...]) -> None:
    planes = post.load("narvis-scan").planes
    rng = np.random.default_rng(5)
    medians = []
    for size in (256, 512):
        for kind in kinds:
            for d in (0.25, 1.0, 4.0):
                n = max(int(d * data.SCAN_POINTS_PER_PIXEL * size * size), 1000)
                sc = data.scan_scene(kind, n, int(rng.integers(0, 2**31)))
                ras = sc.rasterizer()
                for cam in data.scan_cameras(sc, rng, 2, 1.0):
                    g = sc.gbuffers(ras, cam, size, size, planes)
                    r, c = np.asarray(g.radius_px), np.asarray(g.covered)
                    med = float(np.median(r[c]))
                    medians.append(med)
                    print(
                        f"{kind:10s} {size} {d:5.2f}x  median radius {med:6.2f} px  "
                        f"p90 {np.percentile(r[c], 90):6.2f}  covered {c.mean():.2f}",
                        flush=True,
                    )
    m = np.array(medians)
    p5, p50, p95 = np.percentile(m, [5, 50, 95])
    print(
        f"median radius over {len(m)} frames: min {m.min():.2f} p5 {p5:.2f} p50 {p50:.2f} "
        f"p95 {p95:.2f} max {m.max():.2f}"
    )


if __name__ == "__main__":
    main(tuple(sys.argv[1].split(",")) if len(sys.argv) > 1 else data.SCAN_TRAIN)
