"""What a running ray's neighbourhood tells about where it ends, per in-fill
family: whether a per-frame cue would help the W-Net guess if a ray still
running at a stop ends on the surface or in the background.

    python bench/infill_cues.py [FAMILY,FAMILY,...] [--frames 4] [--size 320x180]

For each family (default: the seven the shipped W-Net trained on and the five
of its held-out suite, clvis.post.specs.InfillSpec) and completion: the share
of the finished rays that hit (what a frame shows of itself), the share of the
running rays that end on the surface (what the network must guess, read off the
complete render), that share by candidate blocks left on the ray (IsoImage.
candidates: 1-2, 3-6, 7+), the hit prior's guess of that share (the mean
over the running rays of 1 - (1 - rate)^min(k, 8), rate the frame's crossing
rate: its finished hits per candidate block tested, clvis.post.pack.
crossing_rate; k the blocks left), and the correlation over all frames of
each guess with the share. Frames as the held-out suite draws them (clvis.training.data.iso_frames,
64^3, no speculation, seed 7). bench/results/README.md has the output. A
measuring script, not a test.
"""

from __future__ import annotations

import argparse

import numpy as np

from clvis.post.specs import spec
from clvis.training import data

#: a running ray has at least one candidate block left
BINS = ((1, 3), (3, 7), (7, 256))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    s = spec("infill")
    ap.add_argument("families", nargs="?", default=",".join(s.trained_families + s.eval_families))
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--size", default="320x180")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    pairs = []
    print(f"{'family':11s} done  finished-hit  running-hit  prior-guess  by candidates left 1-2 / 3-6 / 7+")
    for fam in a.families.split(","):
        frames = data.iso_frames((fam,), a.frames, 7, w, h, views=1, n=64)
        for c in data.COMPLETIONS:
            rows = []
            for f in frames:
                run = f.active[c]
                if not run.any() or run.all():
                    continue
                k = f.candidates[c][run].astype(int)
                ends = f.hit[run]
                by = [
                    ends[(k >= lo) & (k < hi)].mean() if ((k >= lo) & (k < hi)).sum() > 20 else np.nan
                    for lo, hi in BINS
                ]
                # the hit prior's guess: 1 - (1 - rate)^k, rate the frame's crossing rate
                guess = (1 - (1 - f.crossing_rate(c)) ** np.minimum(k, 8)).mean()
                rows.append((f.hit[~run].mean(), ends.mean(), guess, *by))
                pairs.append(rows[-1][:3])
            r = np.array(rows)
            by_k = " / ".join(
                "  -" if np.isnan(col).all() else f"{np.nanmean(col):.2f}" for col in r[:, 3:].T
            )
            print(
                f"{fam:11s} {c:.0%}  {r[:, 0].mean():12.2f}  {r[:, 1].mean():11.2f}"
                f"  {r[:, 2].mean():11.2f}  {by_k}",
                flush=True,
            )
    p = np.array(pairs)
    print(
        f"over {len(p)} frames, correlation with running-hit: "
        f"finished-hit {np.corrcoef(p[:, 0], p[:, 1])[0, 1]:+.2f}, "
        f"hit-prior guess {np.corrcoef(p[:, 2], p[:, 1])[0, 1]:+.2f} (mean |guess - running-hit| "
        f"{np.abs(p[:, 2] - p[:, 1]).mean():.2f})"
    )


if __name__ == "__main__":
    main()
