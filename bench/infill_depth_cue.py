"""Where a running ray's next candidate block lies, against the depth of the
finished hits beside it: a per-pixel cue the in-fill W-Net does not have.

    python bench/infill_depth_cue.py [FAMILY,FAMILY,...] [--frames 4] [--size 640x360]

For each family (default: the seven the shipped W-Net trained on and the five
of its held-out suite, clvis.post.specs.InfillSpec), the rays still running at
85, 90 and 95 % of a render (64^3, ZFP rate 8, no speculation, orbit views;
seed 11) are split by where they end in the complete render:

- *miss*: in the background;
- *same*: on a surface within 4 voxels (along the ray's parameter t) of the
  nearest finished hit's t, the surface its neighbours show;
- *elsewhere*: on a surface farther than that (behind a hole, another layer).

Columns: the share of running rays that miss, of the hitting ones that land
elsewhere; how well each cue ranks them (ROC AUC, 0.5 = no better than
chance; either direction): ``k`` the candidate blocks left (IsoImage.candidates, what the
shipped W-Net reads), ``gap`` the next candidate block's t minus the nearest
finished hit's t (what it does not); and where the squared RGB error of
push-pull and of the shipped network falls among the three kinds of ray, with
the network's error over push-pull's on each.

``--gates``: a second table. Could the gap be used without training, as a
rule at inference? Per family, the running rays' squared RGB error of the
network against push-pull's, in dB (positive: the network is better), for the
network alone and for frames that take push-pull's colour where
|gap| <= T voxels and at least K candidate blocks are left (the rays most
likely continuing their neighbours' surface), the network's elsewhere; and the
oracle that takes push-pull's colour exactly on the *same* rays.

The next candidate's t is IsoImage.next_t. bench/results/README.md has the output.
A measuring script, not a test.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.ndimage import distance_transform_edt

from clvis import post
from clvis.iso import IsoRenderer
from clvis.post import IsoPlanes
from clvis.post.pushpull import pushpull
from clvis.post.specs import spec
from clvis.training import data

#: a surface this many voxels (in t) from the neighbours' is "elsewhere"
FAR_VOXELS = 4.0
SIDE = 64


def _auc(score: np.ndarray, label: np.ndarray) -> float:
    """How well `score` ranks the positives apart from the negatives: the ROC
    AUC or 1 - it, whichever is larger (either direction counts)."""
    from scipy.stats import rankdata

    pos, neg = int(label.sum()), int((~label).sum())
    if pos == 0 or neg == 0:
        return float("nan")
    ranks = rankdata(score)
    auc = float((ranks[label].sum() - pos * (pos + 1) / 2) / (pos * neg))
    return max(auc, 1.0 - auc)


def _rays(fam: str, frames: int, w: int, h: int, net) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(11)
    step = 2.0 / (SIDE - 1)
    out: dict[str, list] = {k: [] for k in ("k", "gap", "miss", "far", "epp", "enet")}
    for _ in range(frames):
        vol, iso = data.procedural_volume(fam, rng, SIDE)
        r = IsoRenderer(vol, rate=8, spacing=(step,) * 3, origin=(-1.0, -1.0, -1.0))
        cam = data.orbit_camera(rng, (-1, -1, -1), (1, 1, 1), w / h, (0.45, 0.95))
        snaps, img = {}, None
        for img in r.passes(cam, w, h, iso, speculation=False):
            for c in data.COMPLETIONS:
                if c not in snaps and img.completion >= c:
                    snaps[c] = (img.active.copy(), img.candidates.copy(), img.t.copy(), img.next_t.copy())
        assert img is not None
        rgb = np.where(img.hit[..., None], img.rgba[..., :3], 0).astype(np.float32)
        for active, cand, t, nxt in snaps.values():
            run = active.astype(bool)
            shown = img.hit & ~run
            if not run.any() or not shown.any():
                continue
            _, (iy, ix) = distance_transform_edt(~shown, return_indices=True)
            near_t = t[iy, ix]
            gap = nxt - near_t
            vals = np.concatenate([rgb * shown[..., None], shown[..., None]], 2).astype(np.float32)
            pp = np.asarray(pushpull(vals, ~run))[..., :3]
            got = net(IsoPlanes(vals, shown, run, cand, None, t, nxt))[..., :3] / np.float32(255)
            out["k"].append(cand[run].astype(np.float64))
            out["gap"].append(np.where(np.isfinite(gap), gap, 1e3)[run])
            out["miss"].append(~img.hit[run])
            with np.errstate(invalid="ignore"):
                out["far"].append(np.abs(img.t - near_t)[run] > FAR_VOXELS * step)
            out["epp"].append(((pp - rgb) ** 2).sum(-1)[run])
            out["enet"].append(((got - rgb) ** 2).sum(-1)[run])
        del r
    return {k: np.concatenate(v) for k, v in out.items()}


#: (T voxels, K blocks) of the --gates table: push-pull where |gap| <= T and k >= K
GATES = ((1, 1), (2, 1), (4, 1), (1, 4), (2, 4), (1, 8), (2, 8))


def _gates(families: list[str], frames: int, w: int, h: int, net) -> None:
    step = 2.0 / (SIDE - 1)
    heads = ["network"] + [f"T{t} K{k}" for t, k in GATES] + ["oracle"]
    print("family     " + " ".join(f"{c:>8s}" for c in heads))
    total = np.zeros(len(heads))
    for fam in families:
        d = _rays(fam, frames, w, h, net)
        epp, enet = d["epp"], d["enet"]
        errs = [enet.sum()]
        for t, k in GATES:
            gate = (np.abs(d["gap"]) <= t * step) & (d["k"] >= k)
            errs.append(np.where(gate, epp, enet).sum())
        same = ~d["miss"] & ~d["far"]
        errs.append(np.where(same, epp, enet).sum())
        db = -10.0 * np.log10(np.asarray(errs) / max(epp.sum(), 1e-12))
        total += db
        print(f"{fam:10s} " + " ".join(f"{v:+8.2f}" for v in db), flush=True)
    print(f"{'mean':10s} " + " ".join(f"{v:+8.2f}" for v in total / len(families)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    s = spec("infill")
    ap.add_argument("families", nargs="?", default=",".join(s.trained_families + s.eval_families))
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--size", default="640x360")
    ap.add_argument("--gates", action="store_true", help="the gating table instead (see above)")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    net = post.load("infill")
    if a.gates:
        _gates(a.families.split(","), a.frames, w, h, net)
        return
    print(
        "family      rays   miss  elsewhere | AUC miss: k  gap | AUC elsewhere: k  gap |"
        " push-pull error: miss / same / elsewhere | network / push-pull: miss / same / elsewhere"
    )
    for fam in a.families.split(","):
        d = _rays(fam, a.frames, w, h, net)
        miss, hits = d["miss"], ~d["miss"]
        far = hits & d["far"]
        same = hits & ~far
        tot = d["epp"].sum()
        share = " / ".join(f"{d['epp'][m].sum() / tot:.2f}" for m in (miss, same, far))
        ratio = " / ".join(
            f"{d['enet'][m].sum() / max(d['epp'][m].sum(), 1e-12):.2f}" for m in (miss, same, far)
        )
        print(
            f"{fam:10s} {len(miss):6d}  {miss.mean():.2f}  {far[hits].mean():9.2f} |"
            f"        {_auc(d['k'], miss):.2f}  {_auc(d['gap'], miss):.2f} |"
            f"             {_auc(d['k'][hits], far[hits]):.2f}  {_auc(d['gap'][hits], far[hits]):.2f} |"
            f" {share:>40s} | {ratio}",
            flush=True,
        )


if __name__ == "__main__":
    main()
