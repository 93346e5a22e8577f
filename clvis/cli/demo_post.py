"""The demo's post part: each shipped network on a held-out frame (a volume
kind and a scene it never saw in training), scored against the slow
render it replaces and against push-pull, and a contact sheet per network
(input / push-pull / network / target / error). NARVis: the storm (the
generalisation set's scene) from a view never trained on, against the
Gaussian renderer."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

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


def _sheet(path: Path, inp: np.ndarray, pp: np.ndarray, out: np.ndarray, target: np.ndarray, scores) -> Path:
    from .. import images

    err = np.abs(out - target).mean(axis=2).astype(np.float32)
    panels = [
        _panel(inp, f"input {scores['input']['psnr']:.1f} dB, SSIM {scores['input']['ssim']:.3f}"),
        _panel(pp, f"push-pull {scores['pushpull']['psnr']:.1f} dB, SSIM {scores['pushpull']['ssim']:.3f}"),
        _panel(out, f"network {scores['network']['psnr']:.1f} dB, SSIM {scores['network']['ssim']:.3f}"),
        _panel(target, "target (the slow render)"),
        images.label(
            images.attribute_image(err, "magma", 0.0, ERROR_SCALE), f"|network - target|, 0..{ERROR_SCALE}"
        ),
    ]
    return images.save_png(path, images.side_by_side(panels))


def _scores(inp, pp, out, target) -> dict:
    from ..metrics import metrics

    return {k: metrics(v, target) for k, v in (("input", inp), ("pushpull", pp), ("network", out))}


def gains(s: dict) -> tuple[float, float, str]:
    """(the network's PSNR gain over its raw input, over the best baseline, that
    baseline's name): push-pull is not always the one to beat (on sparse scans
    and particle G-buffers it floods the background and scores below the raw
    input), so the gain is measured against whichever scores higher."""
    net = s["network"]["psnr"]
    best = max(("input", "pushpull"), key=lambda k: s[k]["psnr"])
    return net - s["input"]["psnr"], net - s[best]["psnr"], "push-pull" if best == "pushpull" else "input"


def _line(name: str, s: dict, seconds: float) -> str:
    over_input, over_best, best = gains(s)
    return (
        f"  {name:7} input {s['input']['psnr']:5.1f} dB / {s['input']['ssim']:.3f}   "
        f"push-pull {s['pushpull']['psnr']:5.1f} dB / {s['pushpull']['ssim']:.3f}   "
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
    got = net(SimpleNamespace(rgba=rgba, hit=hit, active=active))
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
    print("\nmore: clvis iso --infill, clvis render --post lidar|narvis [--compare], clvis bench post")
    return bool(ok)
