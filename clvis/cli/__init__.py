"""The clvis command line.

clvis info                   OpenCL platforms and devices, the one clvis uses, its capabilities
clvis demo                   runs the kernel families on generated data and prints the figures
clvis render [FILE]          renders a point cloud (default: an embedded synthetic hurricane)
                             and writes PNGs of its G-buffers
clvis iso [FILE]             progressive isosurface raycasting of a ZFP-compressed volume
                             (default: an embedded Marschner-Lobb volume)
clvis gauss [FILE]           Gaussians from a volume at three levels of detail, ray marched
                             (default: an embedded explosion), PNGs side by side
clvis bench {families}
                             a benchmark suite with its peers, as a table (and JSON)
clvis train {models}
                             trains a post network on renders made here, exports it to ONNX
clvis eval {models}
                             scores a post network on its held-out suite against the baselines
clvis view [FILE]            an interactive viewer in the browser (points, progressive iso, Gaussians)
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
from collections.abc import Sequence

from .._version import __version__
from . import bench, demo, gauss, heldout, info, iso, raster, train, view
from ._common import Parser, glue_values, run

_COMMANDS = {
    "info": info,
    "demo": demo,
    "render": raster,
    "iso": iso,
    "gauss": gauss,
    "bench": bench,
    "train": train,
    "eval": heldout,
    "view": view,
}
_EPILOG = """\
A bad argument or a file clvis cannot use is one line on stderr and exit
status 2 (CLVIS_DEBUG=1: the traceback instead). `clvis COMMAND --help`
tells more about each command.
"""


def _parser() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    from ..post.names import NAMES

    p = argparse.ArgumentParser(
        prog="clvis",
        description=(__doc__ or "").format(families="|".join(bench.FAMILIES), models="|".join(NAMES)),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"clvis {__version__}")
    sub = p.add_subparsers(dest="cmd", metavar="COMMAND", parser_class=Parser)
    commands = {name: module.add_parser(sub) for name, module in _COMMANDS.items()}
    return p, commands


def main(argv: Sequence[str] | None = None) -> int:
    """Run the clvis command line on `argv` (default sys.argv[1:]); the exit status.

    A bare `clvis` prints the help and exits 0, as `clvis --help` does.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    # Ctrl-C (SIGINT) and SIGTERM: one line and 128 + the signal, no traceback.
    # SIGTERM is raised as an exception too, so what is being written is removed
    # on the way out (clvis.io.files, save_png) instead of left as a temporary file.
    previous = _on_sigterm()
    sigint = signal.getsignal(signal.SIGINT)
    try:
        return _main(argv)
    except _Terminated:
        return _interrupted(argv, signal.SIGTERM)
    except KeyboardInterrupt:
        return _interrupted(argv, signal.SIGINT)
    finally:
        if previous is not None:
            with contextlib.suppress(ValueError, OSError, TypeError):
                signal.signal(signal.SIGTERM, previous)
                signal.signal(signal.SIGINT, sigint)


class _Terminated(BaseException):
    """SIGTERM, raised where the main thread is, as KeyboardInterrupt is for SIGINT."""


def _raise_terminated(signum, frame):
    raise _Terminated


def _on_sigterm():
    """Raise _Terminated on SIGTERM (main thread only; elsewhere Python cannot set
    a handler); the handler it replaced, or None."""
    if threading.current_thread() is not threading.main_thread():
        return None
    try:
        return signal.signal(signal.SIGTERM, _raise_terminated)
    except (ValueError, OSError):
        return None


def _interrupted(argv: list[str], sig: signal.Signals) -> int:
    # a second Ctrl-C while exiting would print a traceback
    with contextlib.suppress(ValueError, OSError):
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    cmd = next((a for a in argv if not a.startswith("-")), "")
    what = "interrupted" if sig == signal.SIGINT else "terminated"
    with contextlib.suppress(Exception):
        sys.stderr.write(f"clvis{' ' + cmd if cmd else ''}: {what}\n")
        sys.stderr.flush()
    return 128 + int(sig)


def _main(argv: list[str]) -> int:
    p, commands = _parser()
    if not argv:
        p.print_help()
        return 0
    for i, tok in enumerate(argv):  # the command: the first word that is no option
        if not tok.startswith("-"):
            if tok in commands:
                argv[i + 1 :] = glue_values(commands[tok], argv[i + 1 :])
            break
    try:
        args = p.parse_args(argv)
        if args.cmd is None:  # only options, such as `clvis --verbose`
            p.print_help()
            return 0
        return run(args.cmd, _COMMANDS[args.cmd].cmd, args)
    except SystemExit as e:  # argparse: --help, --version, a bad argument
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    except BrokenPipeError:  # `clvis info | head -1`: the reader has all it wanted
        _quiet_stdout()
        return 141  # 128 + SIGPIPE, as a pipeline reports a process it stopped


def _quiet_stdout():
    """Point the process's stdout at /dev/null, so that Python's final flush of
    what is still buffered does not fail a second time, with a message."""
    stdout = sys.stdout
    if stdout is not sys.__stdout__ or stdout is None:
        return
    try:
        fd = os.open(os.devnull, os.O_WRONLY)
        os.dup2(fd, stdout.fileno())
        os.close(fd)
    except (OSError, ValueError, AttributeError):
        pass
