"""``clvis eval``: a shipped (or trained) post network on its held-out suite.

The suite of a network holds scenes from generator *families* its training
never used (leave-family-out, not other views or seeds of its own
generators), at several image sizes, densities / completions and, for
NARVis, both camera samplers. Every frame is scored (PSNR, SSIM:
clvis.metrics) for the network and for every classical baseline on the
same input; a row of the table is one (family, size, setting, sampler)
with the mean PSNR and SSIM and the worst frame's PSNR of each.

Families (TRAINED: what the shipped networks' training used):

- in-fill (trained on "waves", "ripples" (Marschner–Lobb), "blobs", and
  with --mix data.MORE_TRAIN_VOLUMES):
  "gyroid", "turbulence", "noise" (smoothed noise fields), "shapes"
  (distance fields of random spheres and boxes), "layers" (CT-like nested
  shells); completions 0.85, 0.9, 0.95; baseline push-pull (and the raw
  partial image).
- LiDAR (trained on "town"): "terrain" (the embedded one), "photo" (a
  town's geometry under scikit-image's sample photographs); scan densities
  1-30 %, points 1-3 pixels a side; baselines push-pull and the
  depth-filtered input.
- NARVis (trained on the hurricane, hemisphere views, viridis over
  temperature): flows of other geometries (clvis.training.flows:
  "convection", "lorenz", "jet", "ring") and "hurricane/magma" (the
  trained geometry through a colormap never seen); 0.25x, 1x, 4x the
  training's particles a pixel; the hemisphere and grid samplers;
  baselines the plain rasterization, push-pull of its RGB, and a classical
  splat of the same G-buffers (``splat``).
- narvis-scan (trained on "town", "photo_town", "shapes":
  clvis.training.data.SCAN_TRAIN): "terrain" (the embedded one), "aerial"
  (a LAS-like strip scan of farmland) and "object" (a scanned-object-like
  painted surface); 0.25x, 1x, 4x the training's points a pixel; random
  views; the network reads the G-buffers through its depth filter (the
  spec's ``depth_filter``: clvis.raster.filter_gbuffers); baselines the
  plain rasterization, push-pull of its RGB, the classical splat with the
  radius plane as each pixel's sigma, and that splat of the filtered
  G-buffers (``filtered-splat``).

``--quick`` is the suite ``clvis train`` runs at its end: one size, one
density, one frame per family. Needs no torch (onnxruntime runs the
network, through clvis.post.load's checked files).
"""

from __future__ import annotations

import json
import os
import time
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..io.files import write_replacing
from ..metrics import as_picture, metrics
from ..post.inputs import IsoPlanes
from ..post.specs import SPECS, spec
from ..post.splat import splat
from ..raster.depth_filter import filter_gbuffers
from . import data as _data
from . import flows as _flows

TRAINED = {n: s.trained_families for n, s in SPECS.items()}
FAMILIES = {n: s.eval_families for n, s in SPECS.items()}
BASELINES = {n: s.baselines for n, s in SPECS.items()}
#: the NARVis training's particles a pixel (2 M at 512 x 512)
NARVIS_POINTS_PER_PIXEL = 2_000_000 / 512**2


@dataclass(frozen=True)
class Case:
    """One row of a suite: a family at a size (w, h), a setting (in-fill:
    the volume's side, its completions are rows of their own; LiDAR: the
    scan density; NARVis: the density factor), a sampler and frame count;
    LiDAR: the scan's point size (pixels a side, as ``clvis render
    --point-size``)."""

    family: str
    size: tuple[int, int]
    setting: float
    sampler: str = "orbit"
    frames: int = 1
    point_size: int = 1


def suite(name: str, quick: bool = False) -> list[Case]:
    """The held-out suite of network `name` (the quick one: what ``clvis
    train`` runs at its end, and CI's subset draws from)."""
    if name not in FAMILIES:
        raise ValueError(f"model: expected one of {tuple(FAMILIES)}, got {name!r}")
    fam = FAMILIES[name]
    if name == "infill":
        if quick:
            return [Case(f, (320, 180), 64) for f in fam]
        # issue 21's range: 320x180 to 1920x1080, volumes of 32^3 to 256^3
        # (the rows added last, so the others keep their seeds: a case's
        # frames are drawn from its index)
        return (
            [Case(f, s, 64, frames=2) for f in fam for s in ((320, 180), (640, 360), (1280, 720))]
            + [Case(f, (640, 360), n) for f in fam for n in (32, 128)]
            + [Case(f, (1920, 1080), 64) for f in fam]
            + [Case(f, (640, 360), 256) for f in fam]
        )
    if name == "lidar":
        if quick:
            return [Case(f, (320, 240), d) for f in fam for d in (0.03, 0.1)] + [
                Case(f, (320, 240), 0.03, point_size=3) for f in fam
            ]
        return [
            Case(f, s, d, frames=2)
            for f in fam
            for s in ((320, 240), (640, 480))
            for d in (0.01, 0.03, 0.1, 0.3)
        ] + [
            # points drawn 2 and 3 pixels a side (the training's scans are 1)
            Case(f, (320, 240), d, frames=2, point_size=p)
            for f in fam
            for p in (2, 3)
            for d in (0.01, 0.03, 0.1, 0.3)
        ]
    if name == "narvis":
        samplers = ("hemisphere", "grid")
        if quick:
            return [Case(f, (256, 256), 1.0, s) for f in fam for s in samplers]
        return [
            Case(f, sz, d, s, frames=2)
            for f in fam
            for s in samplers
            for sz, ds in (((256, 256), (0.25, 1.0, 4.0)), ((512, 512), (1.0,)))
            for d in ds
        ]
    if name == "narvis-scan":
        if quick:
            return [Case(f, (256, 256), 1.0, "views") for f in fam]
        return [
            Case(f, sz, d, "views", frames=2)
            for f in fam
            for sz, ds in (((256, 256), (0.25, 1.0, 4.0)), ((512, 512), (1.0,)))
            for d in ds
        ]
    raise ValueError(f"model: expected one of {tuple(FAMILIES)}, got {name!r}")


# ---------------------------------------------------------------------------
# frames of each network's suite: (input for the network, target, baselines)


def _narvis_scene(family: str, n: int, seed: int) -> Any:
    if family == "hurricane/magma":
        sc = _data.narvis_scene("hurricane", n, seed)
        sc.colormap = "magma"
        sc.source += ", magma"
        return sc
    # PROBE_FLOWS: not in the suite, for cases of your own (bench/narvis_unseen.py)
    known = _flows.FLOWS + _flows.PROBE_FLOWS
    if family not in known:
        raise ValueError(f"family: expected one of {known + ('hurricane/magma',)}, got {family!r}")
    return _data.narvis_flow_scene(family, n, seed)


#: _frames' depth_filter default: the network's spec's
_SPEC = "spec"


def _scan_drawn(g: Any) -> tuple[np.ndarray, np.ndarray]:
    """The raster's RGB (0 where empty) and coverage of scan G-buffers."""
    covered = np.asarray(g.covered)
    rgb = np.where(covered[..., None], np.asarray(g.rgba)[..., :3] / np.float32(255), 0)
    return rgb.astype(np.float32), covered


def _scan_splat(g: Any) -> np.ndarray:
    """The classical splat of scan G-buffers: each covered pixel a round
    Gaussian of the radius plane's sigma."""
    rgb, covered = _scan_drawn(g)
    return np.asarray(splat(rgb, covered, None, opacity=_data.SCAN_OPACITY, sigma=np.asarray(g.radius_px)))


def _frames(
    name: str,
    case: Case,
    seed: int,
    planes: Sequence[str],
    target: str = "max_response",
    depth_filter: tuple[int, float] | None | str = _SPEC,
):
    """Yield (setting label, network input, target rgb, {baseline: rgb}) for
    the case's frames; `target`: the Gaussian renderer's model (narvis);
    `depth_filter` (narvis-scan): (levels, strength) of the filter before
    the network, None for none, by default its spec's."""
    from ..post.pack import pack_gbuffers
    from ..post.pushpull import pushpull

    w, h = case.size
    if name == "infill":
        frames = _data.iso_frames((case.family,), case.frames, seed, w, h, views=1, n=int(case.setting))
        for f in frames:
            for c in _data.COMPLETIONS:
                rgba, hit, active = f.planes(c)
                pp = pushpull(rgba, ~active)[..., :3]
                yield (
                    f"{int(case.setting)}^3 at {c:.0%}",
                    IsoPlanes(rgba, hit, active, f.candidates_at(c), f.crossing_rate(c), f.t, f.next_t[c]),
                    f.rgb,
                    {
                        "input": rgba[..., :3],
                        "pushpull": pp,
                    },
                )
    elif name == "lidar":
        d = float(case.setting)
        dense = int(4 * w * h * 2)  # ~8 points a pixel, as the training's 3 M at 960 x 720 is 4.3
        for lf in _data.lidar_frames(
            (case.family,),
            case.frames,
            seed,
            w,
            h,
            views=1,
            dense_points=dense,
            sparse=(d, d),
            point_size=case.point_size,
            index=True,
        ):
            rgb = np.ascontiguousarray(lf.rgbda[..., :3])
            pp = pushpull(rgb, lf.rgbda[..., 4] > 0)
            label = f"{d:.0%} scan" + (f", {case.point_size} px" if case.point_size > 1 else "")
            # the scan as depth_filter gives it: rgbda and the point index (the guard's whole points)
            yield label, lf.filtered(), lf.rgb, {"input": rgb, "pushpull": pp}
    elif name == "narvis-scan":
        n = max(int(case.setting * _data.SCAN_POINTS_PER_PIXEL * w * h), 1000)
        rng = np.random.default_rng(seed)
        ssc = _data.scan_scene(case.family, n, int(rng.integers(0, 2**31)))
        ras, gr = ssc.rasterizer(), ssc.gaussian_renderer()
        prefilter = spec(name).depth_filter if depth_filter == _SPEC else depth_filter
        for cam in _data.scan_cameras(ssc, rng, case.frames, w / h):
            g = ssc.gbuffers(ras, cam, w, h, planes)
            target = np.clip(np.asarray(gr.render(cam, w, h).rgba)[..., :3], 0, 1).astype(np.float32)
            plain, covered = _scan_drawn(g)
            base = {
                "raster": plain,
                "pushpull": pushpull(np.ascontiguousarray(plain), covered),
                "splat": _scan_splat(g),
            }
            if prefilter is not None:
                # the network's pipeline: the depth filter first; the splat
                # of the same filtered G-buffers is a baseline of its own
                levels, strength = typing.cast(tuple, prefilter)
                g = filter_gbuffers(g, levels, strength, queue=ras.queue)
                base["filtered-splat"] = _scan_splat(g)
            yield f"{case.setting:g}x points", g, target, base
        # the case's scene is done: drop its renderers and give back what the
        # queues' pools kept of them (each scene's Gaussians, BVH and tile
        # keys are other sizes, so the pools held every case's: the full
        # NARVis suite grew past 21 GB here and was killed beside a training)
        queues = (gr.queue, ras.queue)
        gr = ras = g = None
        _data._free_held(queues)
    else:
        n = max(int(case.setting * NARVIS_POINTS_PER_PIXEL * w * h), 1000)
        sc = _narvis_scene(case.family, n, seed)
        cams = _data.narvis_cameras(sc, case.sampler, w / h)
        rng = np.random.default_rng(seed)
        cams = [cams[int(i)] for i in rng.permutation(len(cams))[: case.frames]]
        ras, gr = sc.rasterizer(), sc.gaussian_renderer(model=target)
        for cam in cams:
            g = sc.gbuffers(ras, cam, w, h, planes)
            target = np.clip(np.asarray(gr.render(cam, w, h).rgba)[..., :3], 0, 1).astype(np.float32)
            covered = np.asarray(g.covered)
            plain = np.where(covered[..., None], np.asarray(g.rgba)[..., :3] / np.float32(255), 0).astype(
                np.float32
            )
            x = np.asarray(pack_gbuffers(g, ("rgb", "vel2d")))[0]  # r g b coverage vel_x vel_y angle speed
            yield (
                f"{case.setting:g}x points",
                g,
                target,
                {
                    "raster": plain,
                    "pushpull": pushpull(np.ascontiguousarray(plain), covered),
                    "splat": splat(plain, covered, np.stack([x[4], x[5]], -1)),
                },
            )
        # as in the narvis-scan branch: the scene's blocks back to the pools
        queues = (gr.queue, ras.queue)
        gr = ras = g = None
        _data._free_held(queues)


#: a frame's PSNR is capped here in the means (an input equal to its target,
#: every ray finished, scores inf)
PSNR_CAP = 100.0


def _summary(rows: list[dict[str, float]]) -> dict[str, float]:
    p = [min(r["psnr"], PSNR_CAP) for r in rows]
    return {
        "psnr": float(np.mean(p)),
        "ssim": float(np.mean([r["ssim"] for r in rows])),
        "worst_psnr": float(np.min(p)),
    }


def evaluate(
    name: str,
    *,
    model_dir: str | os.PathLike | None = None,
    quick: bool = False,
    cases: Sequence[Case] | None = None,
    seed: int = 2026,
    guard: bool | None = None,
    log: Callable[[str], None] | None = print,
) -> dict:
    """Score network `name` (from `model_dir`, default the shipped models)
    on its held-out suite (`cases`: a subset of your own), called with
    `guard` (clvis.post.guard; None: the network's default). Returns
    {"model", "quick", "guard", "seconds", "rows": [{family, size, setting,
    sampler, frames, network: {psnr, ssim, worst_psnr}, <baseline>: {...},
    ...}]}."""
    from .. import post

    if name not in FAMILIES:
        raise ValueError(f"model: expected one of {tuple(FAMILIES)}, got {name!r}")
    net = post.load(name, directory=model_dir, threads=int(os.environ.get("CLVIS_EVAL_THREADS", "0")) or None)
    guarded = net.guard if guard is None else guard
    # narvis: the targets of the model the network was trained on (its card's data)
    model = ((net.card or {}).get("data") or {}).get("target_model", "max_response")
    t0 = time.perf_counter()
    out_rows = []
    for i, case in enumerate(cases if cases is not None else suite(name, quick)):
        per: dict[str, dict[str, list]] = {}
        for label, x, target, base in _frames(name, case, seed + 7919 * i, net.planes or (), model):
            got = net(x, guard=guarded)[..., :3] / np.float32(255)
            scores = {
                "network": metrics(got, target),
                **{k: metrics(as_picture(v), target) for k, v in base.items()},
            }
            for k, v in scores.items():
                per.setdefault(label, {}).setdefault(k, []).append(v)
        for label, methods in per.items():
            row = {
                "family": case.family,
                "size": f"{case.size[0]}x{case.size[1]}",
                "setting": label,
                "sampler": case.sampler,
                "frames": len(methods["network"]),
                **{k: _summary(v) for k, v in methods.items()},
            }
            out_rows.append(row)
            if log is not None:
                log(_line(name, row))
    return {
        "model": name,
        "quick": quick,
        "guard": guarded,
        "seconds": round(time.perf_counter() - t0, 1),
        "rows": out_rows,
    }


def _best_baseline(name: str, row: dict) -> tuple[str, dict]:
    """The baseline of the highest mean PSNR on the row (the raw input
    counts: a network that scores below no network at all is below it)."""
    k = max((b for b in BASELINES[name] if b in row), key=lambda b: row[b]["psnr"])
    return k, row[k]


def _line(name: str, row: dict) -> str:
    cells = [f"{row['family']:<16} {row['size']:>9} {row['setting']:<13} {row['sampler']:<10}"]
    for k in ("network", *(b for b in BASELINES[name] if b in row)):
        m = row[k]
        cells.append(f"{k} {m['psnr']:5.2f}/{m['ssim']:.3f} (worst {m['worst_psnr']:5.2f})")
    b, bm = _best_baseline(name, row)
    d = row["network"]["psnr"] - bm["psnr"]
    best_ssim = max(row[k]["ssim"] for k in BASELINES[name] if k in row)
    flag = "  BELOW" if d < 0 or row["network"]["ssim"] < best_ssim else ""
    return " | ".join(cells) + f" | vs {b} {d:+.2f} dB{flag}"


def table(result: dict) -> str:
    """The result as a markdown table: per row, each method's mean PSNR /
    SSIM and worst-frame PSNR ("-" for a baseline the row has not: the
    filtered splat of a run without the depth filter), and the network's
    margin over the best baseline (negative: the network loses to it)."""
    name = result["model"]
    methods = ("network", *BASELINES[name])
    head = (
        "| family | size | setting | sampler | "
        + " | ".join(methods)
        + " | network - best baseline (PSNR; SSIM) |"
    )
    lines = [head, "|" + "---|" * (5 + len(methods))]
    for row in result["rows"]:
        b, bm = _best_baseline(name, row)
        cells = [row["family"], row["size"], row["setting"], row["sampler"]]
        cells += [
            f"{row[k]['psnr']:.2f} / {row[k]['ssim']:.3f} ({row[k]['worst_psnr']:.2f})" if k in row else "-"
            for k in methods
        ]
        best_ssim = max(row[k]["ssim"] for k in BASELINES[name] if k in row)
        net = row["network"]
        cells.append(f"{net['psnr'] - bm['psnr']:+.2f} dB ({b}), SSIM {net['ssim'] - best_ssim:+.3f}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_card(result: dict, model_dir: str | os.PathLike, command: Sequence[str] | None = None) -> Path:
    """Put the result into the card of the model in `model_dir`
    (``held_out_suite``); the card's file entries and their sha256 are left
    as they are. The folder is never taken as the shipped models' unasked
    (they are the installed package's files): give clvis.post.MODELS to
    rewrite theirs."""
    if model_dir is None:
        raise ValueError(
            "model_dir: the folder of the card to write (the shipped models' is clvis.post.MODELS, "
            "given on purpose)"
        )
    path = Path(model_dir) / f"{result['model']}.json"
    card = json.loads(path.read_text())
    card["held_out_suite"] = {
        "command": list(command) if command else None,
        "quick": result["quick"],
        "guard": result.get("guard", False),
        "seconds": result["seconds"],
        "trained_on": list(TRAINED[result["model"]]),
        "rows": result["rows"],
    }
    text = (json.dumps(card, indent=1, allow_nan=False) + "\n").encode()
    write_replacing(path, lambda f: f.write(text))  # atomic: a failed write keeps the card
    return path


def margins(result: dict) -> list[tuple[str, float, float]]:
    """Per row, (row label, network PSNR - the best baseline PSNR, network
    SSIM - the best baseline SSIM, each best taken on its own): what the
    "never below the baseline" target reads."""
    name = result["model"]
    out = []
    for row in result["rows"]:
        _, bm = _best_baseline(name, row)
        best_ssim = max(row[b]["ssim"] for b in BASELINES[name] if b in row)
        label = f"{row['family']} {row['size']} {row['setting']} {row['sampler']}"
        out.append((label, row["network"]["psnr"] - bm["psnr"], row["network"]["ssim"] - best_ssim))
    return out


__all__ = [
    "BASELINES",
    "FAMILIES",
    "TRAINED",
    "as_picture",
    "Case",
    "evaluate",
    "margins",
    "splat",
    "suite",
    "table",
    "write_card",
]
