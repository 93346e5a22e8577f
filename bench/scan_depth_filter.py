"""The depth filter before narvis-scan (its spec's depth_filter): which strength.

For the rows of narvis-scan's full suite layout (256x256 at 0.25x, 1x, 4x
SCAN_POINTS_PER_PIXEL and 512x512 at 1x, two random views each) of the given
scan kinds, scores the shipped network on the raw G-buffers and on the
G-buffers through clvis.raster.filter_gbuffers (4 levels) at each strength,
against the 3DGS splat target, and prints per row the change each strength
makes (PSNR dB / SSIM), then the mean and the worst row per strength.

    python bench/scan_depth_filter.py KINDS STRENGTHS [SEED [MODEL_DIR]]
    python bench/scan_depth_filter.py town,photo_town,shapes 1.025,1.05,1.1,1.2,1.4 777 DIR
    python bench/scan_depth_filter.py town,photo_town,shapes 1.3,1.4,1.6,2.0 778 DIR

MODEL_DIR: where narvis-scan.json is (default: the shipped model). The
strength was picked with the model before the filter (its last run trained
on unfiltered frames): ``mkdir DIR; for f in narvis-scan.json
narvis-scan.onnx narvis-scan.fp16.onnx; do git show
31cf69f:clvis/post/models/$f > DIR/$f; done``.

The strength is picked on the training kinds (clvis.training.data.SCAN_TRAIN);
the held-out kinds (terrain, aerial, object) are `clvis eval narvis-scan`'s.
"""

from __future__ import annotations

import sys

import numpy as np

from clvis import post
from clvis.metrics import metrics
from clvis.raster import filter_gbuffers
from clvis.raster.depth_filter import LEVELS
from clvis.training import evaluate as ev


def main(kinds: list[str], strengths: list[float], seed: int, model_dir: str | None = None) -> None:
    net = post.load("narvis-scan", directory=model_dir)
    cases = [
        ev.Case(k, size, d, "views", frames=2)
        for k in kinds
        for size, ds in (((256, 256), (0.25, 1.0, 4.0)), ((512, 512), (1.0,)))
        for d in ds
    ]
    change: dict[float, list[tuple[float, float]]] = {s: [] for s in strengths}
    for i, case in enumerate(cases):
        per: dict[object, list[dict[str, float]]] = {}
        frames = ev._frames("narvis-scan", case, seed + 7919 * i, net.planes, depth_filter=None)
        for _label, raw, target, _base in frames:
            per.setdefault("raw", []).append(metrics(net(raw)[..., :3] / np.float32(255), target))
            for s in strengths:
                f = filter_gbuffers(raw, LEVELS, s)
                per.setdefault(s, []).append(metrics(net(f)[..., :3] / np.float32(255), target))
        mean = {k: (np.mean([m["psnr"] for m in v]), np.mean([m["ssim"] for m in v])) for k, v in per.items()}
        p0, s0 = mean["raw"]
        cells = []
        for s in strengths:
            d = (mean[s][0] - p0, mean[s][1] - s0)
            change[s].append(d)
            cells.append(f"{s:g}: {d[0]:+.2f}/{d[1]:+.3f}")
        print(
            f"{case.family:10s} {case.size[0]} {case.setting:4g}x raw {p0:.2f}/{s0:.3f} | " + " ".join(cells)
        )
    for s in strengths:
        d = np.asarray(change[s])
        print(
            f"strength {s:g}: mean {d[:, 0].mean():+.2f} dB / {d[:, 1].mean():+.3f}, "
            f"worst row {d[:, 0].min():+.2f} dB"
        )


if __name__ == "__main__":
    kinds = sys.argv[1].split(",") if len(sys.argv) > 1 else ["town", "photo_town", "shapes"]
    strengths = [float(s) for s in sys.argv[2].split(",")] if len(sys.argv) > 2 else [1.025, 1.4, 2.0]
    main(
        kinds,
        strengths,
        int(sys.argv[3]) if len(sys.argv) > 3 else 777,
        sys.argv[4] if len(sys.argv) > 4 else None,
    )
