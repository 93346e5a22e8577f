"""The in-fill network on real volumes nobody here made: its picture of the
rays still running against push-pull's, scored against the complete render,
on orbit views of each volume's isosurface (Otsu's threshold, as ``clvis
iso`` picks it; ZFP rate 8, no speculation, as the held-out suite renders, so the
stop comes close to each completion).

    python bench/infill_real.py FILE [FILE ...] [--views 4] [--size 1280x720] [--model-dir DIR]

FILE: any volume ``clvis iso`` reads (clvis.io.read_volume; a 4-D NIfTI file:
its first volume). Volumes that ship inside wheels, none generated here:
pyvista's ``examples/channels.vti`` and ``examples/frog_tissues.vti`` (``pip
download --no-deps pyvista`` and unzip the wheel), nibabel's
``nibabel/tests/data/example4d.nii.gz`` and ``nibabel/tests/data/anatomical.nii`` (installed
with nibabel). Views are drawn as the held-out suite draws them
(clvis.training.data.orbit_camera, zoom 0.45-0.95, seed 0); the volume is
scaled into [-1, 1] along its longest side.

Per volume and completion: PSNR / SSIM of the input (running rays black),
push-pull, the network, and the network with its guard (clvis.post.guard),
the mean over the views and the worst view's network - push-pull. bench/
results/README.md has the output. A measuring script, not a test.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from clvis import post
from clvis.io.volumes import otsu_level, read_volume
from clvis.iso import IsoRenderer
from clvis.metrics import as_picture, metrics
from clvis.post.pack import crossing_rate
from clvis.post.pushpull import pushpull
from clvis.training import data

COMPLETIONS = (0.85, 0.9, 0.95)


def _volume(path: str) -> tuple[np.ndarray, tuple[float, float, float]]:
    name = path.lower()
    v = read_volume(path, volume_index=0 if name.endswith((".nii", ".nii.gz")) and _is4d(path) else None)
    return np.ascontiguousarray(v.data, np.float32), v.spacing


def _is4d(path: str) -> bool:
    import nibabel

    return len(nibabel.load(path).shape) == 4


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--views", type=int, default=4)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--model-dir", default=None, help="a trained model's folder (default: the shipped)")
    ap.add_argument("--speculation", action="store_true", help="as clvis iso does by default")
    a = ap.parse_args()
    w, h = (int(s) for s in a.size.split("x"))
    net = post.load("infill", directory=a.model_dir)
    methods = ("input", "pushpull", "network", "guarded")
    print(
        f"{'volume':22s} {'done':>5s} {'running':>7s} "
        + " ".join(f"{m:>14s}" for m in methods)
        + "  net-pp mean/worst dB"
    )
    for path in a.files:
        (vol, spacing) = _volume(path)
        iso = otsu_level(vol)
        extent = np.array(spacing, np.float64) * (np.array(vol.shape) - 1)  # z, y, x
        step = 2.0 / float(extent.max())
        sp = tuple(float(s) * step for s in spacing)
        hi = tuple(float(e) * step / 2 for e in extent[::-1])  # x, y, z
        lo = tuple(-v for v in hi)
        r = IsoRenderer(vol, rate=8, spacing=sp, origin=lo)
        rng = np.random.default_rng(a.seed)
        running: dict[float, list[float]] = {c: [] for c in COMPLETIONS}
        scores: dict[float, dict[str, list[tuple[float, float]]]] = {
            c: {m: [] for m in methods} for c in COMPLETIONS
        }
        for _ in range(a.views):
            cam = data.orbit_camera(rng, lo, hi, w / h, (0.45, 0.95))
            snaps = {}
            img = None
            for img in r.passes(cam, w, h, iso, speculation=a.speculation):
                for c in COMPLETIONS:
                    if c not in snaps and img.completion >= c:
                        snaps[c] = (
                            img.active.copy(),
                            img.candidates.copy(),
                            int(sum(img.stats["items_per_pass"])),
                            img.next_t.copy(),
                        )
            assert img is not None
            target = np.where(img.hit[..., None], img.rgba[..., :3], np.float32(0)).astype(np.float32)
            for c in COMPLETIONS:
                active, cand, tested, next_t = snaps.get(
                    c, (img.active, img.candidates, int(sum(img.stats["items_per_pass"])), img.next_t)
                )
                rgba = np.concatenate([target, img.hit[..., None].astype(np.float32)], axis=2)
                rgba[active] = 0.0
                hit = img.hit & ~active
                x = post.IsoPlanes(rgba, hit, active, cand, crossing_rate(hit, active, tested), img.t, next_t)
                running[c].append(float(active.mean()))
                # the network's uint8 picture; the baselines as 8-bit pictures too
                out = {
                    "input": as_picture(rgba[..., :3]),
                    "pushpull": as_picture(pushpull(rgba, ~active)[..., :3]),
                    "network": net(x, guard=False)[..., :3] / np.float32(255),
                    "guarded": net(x, guard=True)[..., :3] / np.float32(255),
                }
                for m, o in out.items():
                    q = metrics(o, target)
                    scores[c][m].append((q["psnr"], q["ssim"]))
        for c in COMPLETIONS:
            s = {m: np.array(v) for m, v in scores[c].items()}
            d = s["network"][:, 0] - s["pushpull"][:, 0]
            cells = " ".join(f"{s[m][:, 0].mean():6.2f}/{s[m][:, 1].mean():.3f}" for m in methods)
            print(
                f"{Path(path).name[:22]:22s} {c:5.0%} {np.mean(running[c]):6.1%} {cells}"
                f"  {d.mean():+.2f} / {d.min():+.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
