"""The sweep that chose clvis.post.guard's parameters, on frames of the
networks' TRAINING families only (clvis.training.data: in-fill "waves",
"ripples", "blobs" at 320x180, 85/90/95 %; LiDAR "town" at 320x240, scan
densities 1/3/10/30 %), never the held-out suite's.

Each frame is scored three ways: with the shipped network, and with the
network made bad on purpose, "noise" (its RGB + Gaussian noise, sigma 0.15)
and, in-fill, "overpaint" (the surface push-pulled into every running ray,
the failure issue 21 saw on shapes) or, LiDAR, "swap" (its colours in BGR
order). A setting is good when the guarded frame stays at or above the best
classical fill with the bad networks and loses little against the shipped
one. Per setting and network, the mean and the worst frame of (guarded -
best baseline) PSNR, the frames below it, and the mean of (guarded - the
network alone).

    python bench/guard_sweep.py infill [--frames 6]
    python bench/guard_sweep.py lidar [--frames 3]

bench/results/post-guard.md has the output and what was chosen from it.
A measuring script, not a test.
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np

from clvis import post
from clvis.post import IsoPlanes
from clvis.post import guard as G
from clvis.post.pushpull import pushpull
from clvis.training import data


def _psnr(a, b):
    m = float(np.mean((np.clip(a, 0, 1) - b) ** 2))
    return min(100.0, 10 * np.log10(1 / m)) if m > 0 else 100.0


def _bad(c, kind, seed, overpaint=None):
    if kind == "none":
        return c
    c = c.copy()
    if kind == "noise":
        noise = np.random.default_rng(seed).normal(0, 0.15, c[..., :3].shape)
        c[..., :3] = np.clip(c[..., :3] + noise, 0, 1)
    elif kind == "swap":
        c[..., :3] = c[..., 2::-1].copy()
    elif kind == "overpaint":
        c = overpaint
    return c


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", choices=("infill", "lidar"))
    ap.add_argument("--frames", type=int, default=None, help="volumes (in-fill) or towns a density (LiDAR)")
    args = ap.parse_args()
    name = args.model
    net = post.load(name, threads=2)

    def run(x):
        h, w = x.rgba.shape[:2] if hasattr(x, "rgba") else x.shape[:2]
        return np.ascontiguousarray(np.moveaxis(net.infer(x)[0, :, :h, :w], 0, -1))

    if name == "infill":
        bad = ("none", "noise", "overpaint")
        grid = [
            {"ring": r, "tile": t, "prior": p, "margin": m}
            for r, t, p, m in itertools.product((2, 4, 8, 16), (32, 64), (4.0, 16.0), (0.0, 0.1, 0.25, 0.5))
        ]
        frames = []
        for f in data.iso_frames(data.TRAIN_VOLUMES, args.frames or 6, 331, 320, 180, views=1):
            # + the candidates and depth planes the shipped 8-plane W-Net
            # reads; the withheld rays take their nearest running ray's
            # count and next_t, as the guard gives them (guard.nearest_running)
            for c in data.COMPLETIONS:
                rgba, hit, active = f.planes(c)
                near = G.nearest_running(f.candidates_at(c), active)
                nxt = G.nearest_running(f.next_t[c], active, "next_t")
                frames.append((f"{f.source} {c:.0%}", f.rgb, rgba, hit, active, (near, f.t, nxt)))
    else:
        bad = ("none", "noise", "swap")
        grid = [
            {"fraction": q, "tile": t, "prior": p, "margin": m}
            for q, t, p, m in itertools.product(
                (0.1, 0.2), (32, 64, 128), (4.0, 16.0), (0.0, 0.25, 0.5, 0.75)
            )
        ]
        frames = []
        for d in (0.01, 0.03, 0.1, 0.3):
            for lf in data.lidar_frames(
                ("town",),
                args.frames or 3,
                253 + int(d * 100),
                320,
                240,
                views=1,
                dense_points=8 * 320 * 240,
                sparse=(d, d),
            ):
                frames.append((f"{lf.source} {d:.0%}", lf.rgb, lf.rgbda))

    def candidates(item, known, kind, seed):
        if name == "infill":
            _, _, rgba, hit, active, (near, t, nxt) = item
            shown = hit & ~active
            vals = np.concatenate([rgba[..., :3] * shown[..., None], shown[..., None]], 2).astype(np.float32)
            over = None
            if kind == "overpaint":
                sp = np.asarray(pushpull(np.ascontiguousarray(vals[..., :3]), hit & known))
                over = np.concatenate([sp, np.ones_like(sp[..., :1])], -1)
            n = _bad(
                run(
                    IsoPlanes(vals, hit & known, ~known, near if net.channels_in >= 6 else None, None, t, nxt)
                ),
                kind,
                seed,
                over,
            )
            n = np.where(known[..., None], vals, n).astype(np.float32)
            return [n, np.asarray(pushpull(vals, known)), vals * known[..., None]], vals[..., :3]
        rgbda = item[2].copy()
        rgbda[~known, 4] = 0
        rgb = np.ascontiguousarray(item[2][..., :3])
        return [_bad(run(rgbda), kind, seed), np.asarray(pushpull(rgb, known))], rgb

    scores: dict[tuple, list] = {}
    for item in frames:
        target = item[1]
        known = ~item[4] if name == "infill" else item[2][..., 4] > 0
        for kind in bad:
            full, truth = candidates(item, known, kind, 1)
            ps = [_psnr(c[..., :3], target) for c in full]
            helds = {}
            for s in grid:
                key = s.get("ring", s.get("fraction"))
                if key not in helds:
                    held = G.ring(known, item[4], int(key)) if name == "infill" else G.withheld(known, key)
                    helds[key] = held, candidates(item, known & ~held, kind, 2)[0]
                held, reduced = helds[key]
                errs = [np.sum((c[..., :3] - truth) ** 2, -1) for c in reduced]
                w = G.tile_weights(errs, held, tile=s["tile"], prior=s["prior"], margin=s["margin"])
                wp = G.interpolate(w, *known.shape, tile=s["tile"])
                out = sum(wp[i][..., None] * full[i] for i in range(len(full)))
                if name == "infill":
                    out = np.where(item[4][..., None], out, full[2])
                g = _psnr(out[..., :3], target)
                scores.setdefault((tuple(s.items()), kind), []).append((g - max(ps[1:]), g - ps[0]))
            scores.setdefault((("network alone",), kind), []).append((ps[0] - max(ps[1:]), 0.0))
        print(item[0], flush=True)
    print("setting | " + " | ".join(f"{k}: mean / worst / below / vs network" for k in bad))
    for s in [("network alone",)] + [tuple(g.items()) for g in grid]:
        cells = []
        for kind in bad:
            a = np.array(scores[(s, kind)])
            d, n = a[:, 0], a[:, 1]
            cells.append(f"{d.mean():+.2f} / {d.min():+.2f} / {(d < -0.01).sum()} / {n.mean():+.2f}")
        label = "network alone" if len(s) == 1 else ", ".join(f"{k} {v:g}" for k, v in s)
        print(f"{label} | " + " | ".join(cells))


if __name__ == "__main__":
    main()
