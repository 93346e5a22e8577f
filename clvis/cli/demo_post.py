"""The demo's post part: each shipped network on a held-out frame (a volume
kind and a scene it never saw in training), scored against the slow
render it replaces and against push-pull, and a contact sheet per network
(input / push-pull / network / target / error). NARVis: the storm (the
generalisation set's scene) from a view never trained on, against the
Gaussian renderer. narvis-scan: a frame of a held-out scan family (an
aerial strip scan) at half the panel size, against its 3DGS splat of
isotropic kNN Gaussians, with the classical splat of the radius plane as a
third baseline."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyopencl as cl

#: the error panel: |network - target| (mean over R, G, B) on this scale
ERROR_SCALE = 0.25


def _panel(rgb: np.ndarray, text: str) -> np.ndarray:
    from .. import images

    rgba = np.empty((*rgb.shape[:2], 4), np.uint8)
    rgba[..., :3] = np.rint(np.clip(rgb, 0, 1) * 255)
    rgba[..., 3] = 255
    return images.label(rgba, text)


def _sheet(
    path: Path,
    inp: np.ndarray,
    pp: np.ndarray,
    out: np.ndarray,
    target: np.ndarray,
    scores,
    splat: np.ndarray | None = None,
) -> Path:
    """input / push-pull / [the classical splat /] network / target / error."""
    from .. import images

    err = np.abs(out - target).mean(axis=2).astype(np.float32)
    s = scores
    panels = [
        _panel(inp, f"input {s['input']['psnr']:.1f} dB, SSIM {s['input']['ssim']:.3f}"),
        _panel(pp, f"push-pull {s['pushpull']['psnr']:.1f} dB, SSIM {s['pushpull']['ssim']:.3f}"),
    ]
    if splat is not None:
        panels.append(_panel(splat, f"splat {s['splat']['psnr']:.1f} dB, SSIM {s['splat']['ssim']:.3f}"))
    panels += [
        _panel(out, f"network {s['network']['psnr']:.1f} dB, SSIM {s['network']['ssim']:.3f}"),
        _panel(target, "target (the slow render)"),
        images.label(
            images.attribute_image(err, "magma", 0.0, ERROR_SCALE), f"|network - target|, 0..{ERROR_SCALE}"
        ),
    ]
    return images.save_png(path, images.side_by_side(panels))


def _scores(inp, pp, out, target, splat=None) -> dict:
    from ..metrics import metrics

    pairs = [("input", inp), ("pushpull", pp)] + ([("splat", splat)] if splat is not None else [])
    return {k: metrics(v, target) for k, v in pairs + [("network", out)]}


#: the baselines a demo line may carry, and their names in it
_BASELINES = {"input": "input", "pushpull": "push-pull", "splat": "splat"}


def gains(s: dict) -> tuple[float, float, str]:
    """(the network's PSNR gain over its raw input, over the best baseline, that
    baseline's name): push-pull is not always the one to beat (on sparse scans
    and particle G-buffers it floods the background and scores below the raw
    input; on scans the classical splat of the radius plane, where scored,
    beats both), so the gain is measured against whichever scores highest."""
    net = s["network"]["psnr"]
    best = max((k for k in _BASELINES if k in s), key=lambda k: s[k]["psnr"])
    return net - s["input"]["psnr"], net - s[best]["psnr"], _BASELINES[best]


def _line(name: str, s: dict, seconds: float) -> str:
    over_input, over_best, best = gains(s)
    splat = f"splat {s['splat']['psnr']:5.1f} dB / {s['splat']['ssim']:.3f}   " if "splat" in s else ""
    return (
        f"  {name:11} input {s['input']['psnr']:5.1f} dB / {s['input']['ssim']:.3f}   "
        f"push-pull {s['pushpull']['psnr']:5.1f} dB / {s['pushpull']['ssim']:.3f}   {splat}"
        f"network {s['network']['psnr']:5.1f} dB / {s['network']['ssim']:.3f} "
        f"({over_input:+.1f} dB over the input, {over_best:+.1f} dB over the best baseline, {best})   "
        f"inference {seconds * 1e3:.0f} ms"
    )


def demo(out_dir: str | Path, q: cl.CommandQueue, size: tuple[int, int] = (640, 360)) -> bool:
    """Both networks on held-out frames; True when each output is the shape
    it should be, finite, and closer to the target than its raw input."""
    from .. import post
    from ..training import data

    w, h = size
    out_dir = Path(out_dir)
    print(
        f"\npost: the shipped networks on held-out frames ({w}x{h}), PSNR / SSIM against the slow render:\n"
    )
    ok = True

    f = data.iso_frames(("gyroid",), 1, 2027, w, h, views=1, completions=(0.85,))[0]
    rgba, hit, active = f.planes(0.85)
    target = f.rgb
    inp = np.where(active[..., None], np.array([1.0, 0.0, 1.0], np.float32), rgba[..., :3])
    pp = np.asarray(post.pushpull(rgba, ~active, queue=q))[..., :3]
    net = post.load("infill", queue=q)
    got = net(
        post.IsoPlanes(rgba, hit, active, f.candidates_at(0.85), f.crossing_rate(0.85), f.t, f.next_t[0.85])
    )
    out = got[..., :3].astype(np.float32) / 255
    s = _scores(np.where(active[..., None], 0, rgba[..., :3]), pp, out, target)
    print(_line("infill", s, net.stats["inference"]) + f"   ({f.source}, 85% of the rays)")
    path = _sheet(out_dir / "post-infill.png", inp, pp, out, target, s)
    print(f"  contact sheet: {path} (input: magenta = rays still running)")
    ok &= got.shape == (h, w, 4) and s["network"]["psnr"] > s["input"]["psnr"]

    lf = data.lidar_frames(("terrain",), 1, 2027, w, h, views=1)[0]
    kept = lf.rgbda[..., 4] > 0
    inp = np.where(kept[..., None], lf.rgbda[..., :3], 0).astype(np.float32)
    pp = np.asarray(post.pushpull(np.ascontiguousarray(lf.rgbda[..., :3]), kept, queue=q))
    net = post.load("lidar", queue=q)
    got = net(lf.rgbda)
    out = got[..., :3].astype(np.float32) / 255
    s = _scores(inp, pp, out, lf.rgb)
    print(_line("lidar", s, net.stats["inference"]) + f"   ({lf.source})")
    path = _sheet(out_dir / "post-lidar.png", inp, pp, out, lf.rgb, s)
    print(f"  contact sheet: {path}")
    ok &= got.shape == (h, w, 4) and s["network"]["psnr"] > s["input"]["psnr"]
    # the training's particles per pixel (2 M at 512 x 512): the network learned that density
    sc = data.narvis_scene("storm", max(20_000, round(2_000_000 * w * h / 512**2)), 2027)
    cam = data.narvis_cameras(sc, "hemisphere", w / h)[45]  # an odd azimuth: never trained on
    net = post.load("narvis", queue=q)
    g = sc.gbuffers(sc.rasterizer(queue=q), cam, w, h, net.planes)
    target = np.clip(np.asarray(sc.gaussian_renderer(queue=q).render(cam, w, h).rgba)[..., :3], 0, 1)
    inp = np.where(g.covered[..., None], g.rgba[..., :3] / np.float32(255), 0).astype(np.float32)
    pp = np.asarray(post.pushpull(np.ascontiguousarray(inp), g.covered, queue=q))
    got = net(g)
    out = got[..., :3].astype(np.float32) / 255
    s = _scores(inp, pp, out, target)
    print(_line("narvis", s, net.stats["inference"]) + f"   ({sc.source})")
    path = _sheet(out_dir / "post-narvis.png", inp, pp, out, target, s)
    print(f"  contact sheet: {path} (target: the Gaussian renderer)")
    ok &= got.shape == (h, w, 4) and s["network"]["psnr"] > s["input"]["psnr"]
    ok &= _scan(out_dir, q, (max(w // 2, 16), max(h // 2, 16)))
    print("\nmore: clvis iso --infill, clvis render --post lidar|narvis [--compare], clvis bench post")
    return bool(ok)


#: the demo's narvis-scan frame: a held-out family (clvis.training.data.SCAN_HELD_OUT)
SCAN_FAMILY = "aerial"


def _scan(out_dir: Path, q: cl.CommandQueue, size: tuple[int, int]) -> bool:
    """narvis-scan on one view of a held-out scan family (never in its
    training) at `size` (half the other panels: the kNN radius, the 3DGS
    target and the classical splat are the costly part), scored against
    that target beside the raster, push-pull and the classical splat with
    the radius plane as each pixel's sigma (clvis eval's baselines)."""
    from .. import post
    from .._arrays import on_host
    from ..post.splat import splat
    from ..training import data

    w, h = size
    n = int(data.SCAN_POINTS_PER_PIXEL * w * h)  # the training's points a pixel
    sc = data.scan_scene(SCAN_FAMILY, n, 2027)
    cam = data.scan_cameras(sc, np.random.default_rng(2027), 1, w / h)[0]
    net = post.load("narvis-scan", queue=q)
    g = sc.gbuffers(sc.rasterizer(queue=q), cam, w, h, net.planes)
    target = np.clip(np.asarray(sc.gaussian_renderer(queue=q).render(cam, w, h).rgba)[..., :3], 0, 1)
    covered = np.asarray(g.covered)
    inp = np.where(covered[..., None], np.asarray(g.rgba)[..., :3] / np.float32(255), 0).astype(np.float32)
    pp = np.asarray(post.pushpull(np.ascontiguousarray(inp), covered, queue=q))
    sp = on_host(splat(inp, covered, None, opacity=data.SCAN_OPACITY, sigma=np.asarray(g.radius_px)))
    if net.spec.depth_filter is not None:  # the network's pipeline: the depth filter first
        from ..raster import filter_gbuffers

        g = filter_gbuffers(g, *net.spec.depth_filter, queue=q)
    got = net(g)
    out = got[..., :3].astype(np.float32) / 255
    s = _scores(inp, pp, out, target, sp)
    print(_line("narvis-scan", s, net.stats["inference"]) + f"   ({sc.source}, {w}x{h}, held out)")
    path = _sheet(out_dir / "post-narvis-scan.png", inp, pp, out, target, s, splat=sp)
    print(f"  contact sheet: {path} (target: the 3DGS splat of isotropic kNN Gaussians)")
    return bool(got.shape == (h, w, 4) and s["network"]["psnr"] > s["input"]["psnr"])
