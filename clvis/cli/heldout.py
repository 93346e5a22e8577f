"""clvis eval: a post network on its held-out suite (clvis.training.evaluate)."""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

from ._common import CliError, Parser

_HELP = """\
Score a post network on its held-out suite: scenes from generator families
its training never used (in-fill: gyroid, turbulence, noise fields,
distance fields of shapes, CT-like layers; LiDAR: the terrain, towns under
photographs; NARVis: convection cells, the Lorenz attractor, a jet, a
vortex ring, the hurricane through a colormap never seen; narvis-scan:
the terrain, a LAS-like aerial strip scan, a scanned-object-like surface),
at several sizes, completions / densities and (NARVis) both camera samplers. Prints
per family, size and setting the network against every classical baseline
on the same input (PSNR / SSIM, mean and the worst frame's PSNR), then the
table in markdown. The last column is the network minus the best baseline:
negative where the network makes the image worse than no network.
"""


def add_parser(sub: argparse._SubParsersAction[Parser]) -> Parser:
    from ..post.names import NAMES

    p = sub.add_parser(
        "eval",
        help="score a post network (infill, lidar, narvis, narvis-scan) on its held-out suite",
        description=_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("model", choices=NAMES, help="the network to score")
    p.add_argument(
        "--model-dir", default=None, metavar="DIR", help="where NAME.json is (default: the shipped models)"
    )
    p.add_argument("--quick", action="store_true", help="one size and one frame per family (what train runs)")
    p.add_argument(
        "--write-card",
        action="store_true",
        help="write the table into the card of the model in --model-dir (which it needs: the shipped "
        "models' card is rewritten only when their folder is given as --model-dir)",
    )
    p.add_argument(
        "--guard",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="call the network with its guard on or off (clvis.post.guard; default: the network's own)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    return p


def cmd(args: argparse.Namespace) -> int:
    from ..training import evaluate as ev

    if args.write_card and args.model_dir is None:
        # the shipped models' folder is the installed package's: a pip-installed
        # clvis's files, not the user's, edited on purpose only (the release
        # flow, from a clone, names it)
        from ..post.infer import MODELS

        raise CliError(
            f"--write-card: give --model-dir DIR, the folder of the card to write; the shipped "
            f"{args.model} card is the installed package's (to rewrite it on purpose: --model-dir {MODELS})"
        )
    log = None if args.quiet else (lambda s: print(f"clvis eval: {s}", file=sys.stderr, flush=True))
    # --write-card: the card is this command's from before the model is read until
    # the table is in it (a clvis train into the folder meanwhile is refused, and
    # this is refused while one runs: its model would change under the scoring)
    held: contextlib.AbstractContextManager[None] = contextlib.nullcontext()
    if args.write_card:
        from ..training.train import claim

        held = claim(
            Path(args.model_dir), args.model, log or (lambda s: None), what="clvis eval --write-card"
        )
    with held:
        return _score(args, ev, log)


def _score(args: argparse.Namespace, ev, log) -> int:
    """Score the model and print the table (and write it into the card)."""
    try:
        result = ev.evaluate(
            args.model, model_dir=args.model_dir, quick=args.quick, guard=args.guard, log=log
        )
    except ImportError as e:
        raise CliError(f"clvis eval needs onnxruntime: {e}") from None
    print(ev.table(result))
    below = [m for m in ev.margins(result) if m[1] < 0 or m[2] < 0]
    print(f"\n{len(below)} of {len(result['rows'])} rows below the best baseline ({result['seconds']:.0f} s)")
    if args.write_card:
        command = ["clvis", "eval", args.model] + (["--quick"] if args.quick else [])
        if not _shipped(args.model_dir):  # the command that scores that model again
            command[3:3] = ["--model-dir", str(args.model_dir)]
        if args.guard is not None:
            command.append("--guard" if args.guard else "--no-guard")
        print(f"card: {ev.write_card(result, args.model_dir, command)}")
    return 0


def _shipped(model_dir: str) -> bool:
    """Whether `model_dir` is the shipped models' folder (clvis eval's default)."""
    import os

    from ..post.infer import MODELS

    try:
        return os.path.samefile(model_dir, MODELS)
    except OSError:
        return False
