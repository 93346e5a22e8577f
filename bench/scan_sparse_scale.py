"""narvis-scan on clouds sparser on screen than its training frames, at full
size and with its frame rendered smaller (clvis.post.PostNetwork.render_scale).

For the held-out scan kinds (clvis.training.data.SCAN_HELD_OUT: never in
narvis-scan's training) at densities far under the training's lowest
(0.25 x SCAN_POINTS_PER_PIXEL points a frame pixel), two random views each
(the training's own scan_cameras), and laspy's simple.las from the tests'
data (1,065 points, Camera.fit's view of its box through a 60 degree lens), prints
per frame the view's median splat radius (pixels), the scale render_scale
picks, and PSNR / SSIM against the Gaussian renderer's target (the 3DGS
splat of the isotropic Gaussians) of: the network at full size, the network
at the scale, and the classical splat of the same (depth-filtered) G-buffers
at full size, the baseline a user has without the network.

    python bench/scan_sparse_scale.py [--size 512x384]

bench/results/README.md has the output. A measuring script, not a test.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from clvis import post
from clvis.camera import Camera
from clvis.metrics import metrics
from clvis.raster import filter_gbuffers
from clvis.training import data
from clvis.training.evaluate import _scan_splat


def _row(label, net, scene, cam, w, h):
    ras, gr = scene.rasterizer(), scene.gaussian_renderer()
    target = np.clip(np.asarray(gr.render(cam, w, h).rgba)[..., :3], 0, 1).astype(np.float32)

    def filtered(width, height):
        g = scene.gbuffers(ras, cam.with_aspect(width / height), width, height, net.planes)
        return filter_gbuffers(g, *net.spec.depth_filter, queue=ras.queue)

    g = filtered(w, h)
    median, scale = net.median_radius_px(g), net.render_scale(g)
    full = net(g)[..., :3]
    small = full
    if scale > 1:
        small = post.resized(
            net(filtered(round(w / scale), round(h / scale))), w, h, smooth=post.SCALED_SMOOTH
        )[..., :3]
    splat = _scan_splat(g)
    m = [metrics(x, target) for x in (full, small, splat)]
    cells = " | ".join(f"{r['psnr']:5.2f} / {r['ssim']:.3f}" for r in m)
    print(f"| {label} | {median:5.2f} | {scale} | {cells} |", flush=True)
    return m, scale


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", default="512x384")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    net = post.load("narvis-scan")
    print("| frame | median radius px | scale | network full size | network at the scale | classical splat |")
    print("|---|---|---|---|---|---|")
    rows = []
    rng = np.random.default_rng(7)
    for kind in data.SCAN_HELD_OUT:
        for density in (0.003, 0.01, 0.03):
            n = max(int(density * data.SCAN_POINTS_PER_PIXEL * w * h), 200)
            scene = data.scan_scene(kind, n, int(rng.integers(0, 2**31)))
            for v, cam in enumerate(data.scan_cameras(scene, rng, 2, w / h)):
                rows.append(_row(f"{kind} {density}x view {v} ({n:,} points)", net, scene, cam, w, h))
    las = Path(__file__).parents[1] / "tests" / "data" / "laspy_simple.laz"
    try:
        from clvis.io import read_points
    except ImportError:  # pragma: no cover
        read_points = None
    if read_points is not None and las.exists():
        cloud = read_points(las)
        scene = data.ScanScene(data.scan_cloud(cloud.positions, cloud.colors), "landscape", "simple.las")
        lo, hi = cloud.positions.min(0), cloud.positions.max(0)
        cam = Camera.fit(lo, hi, aspect=w / h, fov_y=60.0)
        rows.append(_row(f"laspy simple.las ({len(cloud.positions):,} points)", net, scene, cam, w, h))
    scaled = [m for m, scale in rows if scale > 1]
    gain = np.mean([m[1]["psnr"] - m[0]["psnr"] for m in scaled])
    ssim = np.mean([m[1]["ssim"] - m[0]["ssim"] for m in scaled])
    lower = sum(m[1]["psnr"] < m[0]["psnr"] for m in scaled)
    over = sum(m[1]["psnr"] > m[2]["psnr"] for m, _ in rows)
    print(
        f"\n{len(rows)} frames, {len(scaled)} scaled: there the scale gains {gain:+.2f} dB and SSIM "
        f"{ssim:+.3f} on average over full size ({lower} lower in PSNR); the network as run (scaled "
        f"where the rule says) is above the classical splat on {over} of {len(rows)}"
    )


if __name__ == "__main__":
    main()
