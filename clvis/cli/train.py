"""clvis train: train a post network on pairs made by clvis's renderers,
export it to ONNX (fp32, fp16, int8) and write its model card."""

from __future__ import annotations

import argparse
import os
import sys

from ._common import CliError, Parser, count, folder, size

_HELP = """\
Train one of the post family's networks (clvis.post) with PyTorch:

  infill   in-fill of isosurface images stopped at 85/90/95 % completion
           (a W-Net: two U-Nets of 4-8-16-32 channels; ~31 k parameters)
  lidar    the LiDAR RGBDA U-Net: depth-filtered sparse scans to dense renders
  narvis   NARVis's gated U-Net predicting per-pixel kernels over the input
           colours: rasterizer G-buffers of the hurricane and seven training
           flows to the Gaussian renderer's image of them
  narvis-scan  the same network for clouds without velocity (LAS/LAZ/PLY
           scans): colours, depth and the kNN splat radius plane of towns
           and photo-textured shapes to 3DGS's splat of isotropic Gaussians

The training pairs are rendered here from closed-form volumes and scenes
with deterministic seeds (clvis.training.data); held-out frames come from kinds
never trained on. Writes NAME.onnx, NAME.fp16.onnx, NAME.int8.onnx (when
int8 loses at most 0.3 dB) and the model card NAME.json into --out; the
shipped models in clvis/post/models were made by this command, as their
cards say. Needs the train extra: pip install 'clvis[train]'.
"""


def add_parser(sub: argparse._SubParsersAction[Parser]) -> Parser:
    from ..post.names import NAMES

    p = sub.add_parser(
        "train",
        help="train a post network (infill, lidar, narvis, narvis-scan) and export it to ONNX",
        description=_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", choices=NAMES, help="the network to train")
    p.add_argument("--steps", type=count(1, 10**7), default=2000, help="optimizer steps (default 2000)")
    p.add_argument(
        "--size", type=count(32, 4096), default=256, metavar="N", help="training crops N x N (default 256)"
    )
    p.add_argument(
        "--out",
        type=folder,
        default=".",
        metavar="DIR",
        help="where the model and its card go (default .); a model of the same name there is replaced "
        "once the new one is written whole (a run stopped before that leaves it as it was); one run "
        "of a network into a folder at a time: a second is refused, naming the first",
    )
    p.add_argument("--seed", type=count(0, 2**31 - 1), default=0, help="the data's and the weights' seed")
    p.add_argument(
        "--frames",
        type=count(1, 10_000),
        default=None,
        metavar="N",
        help="volumes, scenes or (narvis) views to render for training (default: the release run's)",
    )
    p.add_argument(
        "--frame-size", type=size, default=None, metavar="WxH", help="frame size (default: the release run's)"
    )
    p.add_argument(
        "--points",
        type=count(1000, 10**8),
        default=None,
        metavar="N",
        help="narvis: the scenes' particles (default 2,000,000)",
    )
    p.add_argument(
        "--target",
        choices=("max_response", "splat"),
        default=None,
        help="narvis: the Gaussian renderer's model for the targets: max_response (the ray model, "
        "default) or splat (3DGS's forward pass, the paper's GR)",
    )
    p.add_argument(
        "--eval",
        choices=("quick", "full", "none"),
        default="quick",
        help="then score the model on its held-out suite (clvis eval) into its card (default quick)",
    )
    p.add_argument(
        "--cache",
        default=None,
        metavar="DIR",
        help="narvis: keep the rendered frames in DIR and read them back on a run with the same data "
        "(default $XDG_CACHE_HOME/clvis/train or ~/.cache/clvis/train)",
    )
    p.add_argument("--no-cache", action="store_true", help="render every frame, keep none")
    p.add_argument(
        "--time-limit",
        type=count(1, 10**7),
        default=None,
        metavar="S",
        help="stop training after S seconds (rendering not counted) if --steps are not done by then; "
        "the learning rate's schedule ends with whichever comes first",
    )
    p.add_argument(
        "--init",
        default=None,
        metavar="ONNX",
        help="start from the weights of this ONNX export of the same network (e.g. the shipped "
        "clvis/post/models/infill.onnx; lidar's export folded its batch norms into its "
        "convolutions: they start as those and stay frozen; default: random weights)",
    )
    p.add_argument(
        "--mix",
        type=float,
        default=None,
        metavar="F",
        help="infill: take a share F (0-1) of the crops from variety frames of seven families "
        "(random sizes, speculation, colours, 80-97 %% completion) beside the release frames",
    )
    p.add_argument(
        "--planes",
        default=None,
        metavar="P,Q,...",
        help="narvis, narvis-scan: the G-buffer planes the network takes (e.g. rgb,depth,vel2d,radius); "
        "infill: its optional input planes, candidates then prior or depth (e.g. candidates,depth); "
        "default: the release run's",
    )
    p.add_argument(
        "--lr", type=float, default=None, metavar="X", help="peak learning rate (default: the release run's)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    return p


def _command(args: argparse.Namespace) -> list[str]:
    """The command line that repeats this run (for the model card)."""
    c = ["clvis", "train", args.model, "--steps", str(args.steps), "--size", str(args.size)]
    c += ["--out", str(args.out), "--seed", str(args.seed)]
    if args.frames is not None:
        c += ["--frames", str(args.frames)]
    if args.frame_size is not None:
        c += ["--frame-size", f"{args.frame_size[0]}x{args.frame_size[1]}"]
    if args.points is not None:
        c += ["--points", str(args.points)]
    if args.time_limit is not None:
        c += ["--time-limit", str(args.time_limit)]
    if args.target is not None:
        c += ["--target", args.target]
    if args.init is not None:
        c += ["--init", str(args.init)]
    if args.mix is not None:
        c += ["--mix", str(args.mix)]
    if args.lr is not None:
        c += ["--lr", str(args.lr)]
    if args.planes is not None:
        c += ["--planes", args.planes]
    return c + ["--eval", args.eval]


def default_cache() -> str:
    """Where clvis train keeps rendered frames unless told: $XDG_CACHE_HOME/clvis/train
    (~/.cache/clvis/train)."""
    import os

    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "clvis", "train")


def _missing(module: str) -> bool:
    """Whether `module` cannot be imported (looked up, not imported: torch takes seconds)."""
    import importlib.util

    try:
        return importlib.util.find_spec(module) is None
    except (ImportError, ValueError):
        return True


def held_out_table(held_out: dict) -> str:
    """The card's held-out rows as a table: PSNR (dB) and SSIM of the raw
    input, push-pull and the network, and the network's gain over each."""
    cols = (("input", "input"), ("pushpull", "push-pull"), ("network", "network"))
    width = max([len("held-out")] + [len(str(k)) for k in held_out])
    head = f"  {'held-out':<{width}}" + "".join(f" {label + ' dB':>13} {'SSIM':>6}" for _, label in cols)
    head += f" {'vs input':>9} {'vs push-pull':>12}"
    lines = [head]
    for key, row in held_out.items():
        line = f"  {key:<{width}}"
        for k, _ in cols:
            line += f" {row[k]['psnr']:13.2f} {row[k]['ssim']:6.3f}" if k in row else f" {'-':>13} {'-':>6}"
        if all(k in row for k, _ in cols):
            net = row["network"]["psnr"]
            line += f" {net - row['input']['psnr']:+9.2f} {net - row['pushpull']['psnr']:+12.2f}"
        lines.append(line)
    if not held_out:
        lines.append("  (no held-out frame)")
    return "\n".join(lines)


def cmd(args: argparse.Namespace) -> int:
    missing = [m for m in ("torch", "onnx", "pytorch_msssim") if _missing(m)]
    try:
        if missing:
            raise ModuleNotFoundError(name=missing[0])
        from ..training import train
    except ImportError as e:  # torch, onnx or pytorch-msssim missing
        raise CliError(
            "clvis train needs the train extra, which installs PyTorch, onnx and pytorch-msssim "
            f"({', '.join(missing) or e.name or e} missing): pip install '.[train]' in the clone"
        ) from None
    log = (
        (lambda s: None)
        if args.quiet
        else (lambda s: print(f"clvis train: {s}", file=sys.stderr, flush=True))
    )
    if args.target is not None and args.model != "narvis":
        raise CliError(f"--target: {args.model}'s targets are not Gaussian renders (narvis only)")
    if args.mix is not None and args.model != "infill":
        raise CliError(f"--mix: {args.model} has no variety frames to mix in (infill only)")
    if args.mix is not None and not 0.0 < args.mix < 1.0:
        raise CliError(f"--mix {args.mix}: expected a share between 0 and 1")
    if args.lr is not None and not 0.0 < args.lr < 1.0:
        raise CliError(f"--lr {args.lr}: expected a learning rate between 0 and 1")
    if args.init is not None and not os.path.isfile(args.init):
        raise CliError(f"--init {args.init}: no such file")
    planes = None
    if args.planes is not None and args.model == "infill":
        planes = [p.strip() for p in args.planes.split(",") if p.strip()]
        try:
            train.infill_planes(planes)
        except ValueError as e:
            raise CliError(f"--planes {args.planes}: {e}") from None
    elif args.planes is not None:
        if "planes" not in train.SPECS[args.model]["arch"]:
            raise CliError(f"--planes: {args.model} takes no G-buffer planes (narvis, narvis-scan only)")
        from ..post.names import gbuffer_channels

        planes = [p.strip() for p in args.planes.split(",") if p.strip()]
        try:
            gbuffer_channels(tuple(planes))
            # the network itself (its head's depth selection needs "depth"): said as --planes'
            train.TRAINERS[args.model].build(**{**train.SPECS[args.model]["arch"], "planes": planes})
        except ValueError as e:
            raise CliError(f"--planes {args.planes}: {e}") from None
    fw, fh = args.frame_size or train.SPECS[args.model]["frame_size"]
    if args.size > min(fw, fh):
        raise CliError(f"--size {args.size}: larger than the frames ({fw}x{fh})")

    def evaluated(card: dict) -> None:
        """The table of the card's held-out rows, then (--eval) the held-out
        suite into the card: run by train while the model's folder is still
        this run's (train.claim), so a second run cannot replace the model
        between the two."""
        print(f"{args.out}/{card['name']}.onnx: held-out frames, mean per row")
        print(held_out_table(card["held_out"]))
        if args.eval == "none":
            return
        from ..training import evaluate as ev

        quick = args.eval == "quick"
        try:
            result = ev.evaluate(args.model, model_dir=args.out, quick=quick, log=log)
        except BaseException:  # Ctrl-C or an error: the model is written all the same; say so
            print(
                f"clvis train: {args.out}/{card['name']}.onnx and its card are written; its held-out "
                f"suite is not (clvis eval {args.model} --model-dir {args.out}"
                f"{' --quick' if quick else ''} --write-card)",
                file=sys.stderr,
            )
            raise
        print(ev.table(result))
        ev.write_card(
            result,
            args.out,
            ["clvis", "eval", args.model, "--model-dir", str(args.out)] + (["--quick"] if quick else []),
        )

    train.train(
        args.model,
        steps=args.steps,
        size=args.size,
        out=args.out,
        seed=args.seed,
        frames=args.frames,
        frame_size=args.frame_size,
        points=args.points,
        target=args.target or "max_response",
        command=_command(args),
        log=log,
        cache=None if args.no_cache else (args.cache or default_cache()),
        time_limit=args.time_limit,
        init=args.init,
        mix=args.mix,
        lr=args.lr,
        planes=planes,
        after=evaluated,
        # what it removes of killed runs is said even with --quiet
        say=lambda s: print(f"clvis train: {s}", file=sys.stderr, flush=True),
    )
    return 0
