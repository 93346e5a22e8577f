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

# Only what main() needs before it handles signals is imported here (each
# import is time in which Ctrl-C would be a traceback); the rest in the functions.
import os
import signal
import sys

from .._version import __version__

TYPE_CHECKING = False  # typing.TYPE_CHECKING, without importing typing
if TYPE_CHECKING:
    import argparse
    from collections.abc import Sequence
    from types import ModuleType

# each command -> its module in clvis.cli. They (and NumPy, PyOpenCL, the
# families) are imported by main(), after it handles Ctrl-C and SIGTERM: a
# signal in the second the imports take is one line too, not a traceback.
_COMMANDS = {
    "info": "info",
    "demo": "demo",
    "render": "raster",
    "iso": "iso",
    "gauss": "gauss",
    "bench": "bench",
    "train": "train",
    "eval": "heldout",
    "view": "view",
}
_EPILOG = """\
A bad argument or a file clvis cannot use is one line on stderr and exit
status 2 (CLVIS_DEBUG=1: the traceback instead). `clvis COMMAND --help`
tells more about each command.
"""


def _module(cmd: str) -> ModuleType:
    import importlib

    return importlib.import_module(f"{__name__}.{_COMMANDS[cmd]}")


def _parser() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    import argparse

    from ..post.names import NAMES
    from . import bench
    from ._common import Parser

    p = argparse.ArgumentParser(
        prog="clvis",
        description=(__doc__ or "").format(families="|".join(bench.FAMILIES), models="|".join(NAMES)),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"clvis {__version__}")
    sub = p.add_subparsers(dest="cmd", metavar="COMMAND", parser_class=Parser)
    commands = {name: _module(name).add_parser(sub) for name in _COMMANDS}
    return p, commands


def main(argv: Sequence[str] | None = None) -> int:
    """Run the clvis command line on `argv` (default sys.argv[1:]); the exit status.

    A bare `clvis` prints the help and exits 0, as `clvis --help` does.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    # Ctrl-C (SIGINT) and SIGTERM: one line and 128 + the signal, no traceback,
    # from here on: the commands and the libraries they use are imported in
    # _main. SIGTERM is raised as an exception too, so what is being written is
    # removed on the way out (clvis.io.files, save_png) instead of left as a
    # temporary file.
    previous: dict[int, object] = {}
    try:
        _received.clear()
        _deferred.clear()
        _ignore_on_exit.clear()
        _on_signals(previous)
        status = _main(argv)
        _check_signals()
        return status
    except _Terminated:
        return _interrupted(argv, signal.SIGTERM)
    except KeyboardInterrupt:
        return _interrupted(argv, signal.SIGINT)
    except Exception:
        if not _received:
            raise
        # what a library made of the signal (numpy's import, interrupted, raises
        # an ImportError): the signal is what happened
        return _interrupted(argv, signal.Signals(_received[0]))
    finally:
        for sig, handler in previous.items():
            try:
                signal.signal(sig, handler)  # type: ignore[arg-type]
            except (ValueError, OSError, TypeError):
                pass


def entry() -> int:
    """The process's entry (the `clvis` script, `python -m clvis`): main(),
    then, after a Ctrl-C or SIGTERM, the process ignores both while the
    interpreter shuts down. A second Ctrl-C in that time (Dask's threads and
    workers are still being joined) would otherwise end the process by the
    signal, not with main()'s 130/143. main() itself leaves the handlers as
    it found them (a library call changes no process-wide state)."""
    status = main()
    if _received or _ignore_on_exit:
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                signal.signal(sig, signal.SIG_IGN)
            except (ValueError, OSError):  # not the main thread
                pass
    return status


class _Terminated(BaseException):
    """SIGTERM, raised where the main thread is, as KeyboardInterrupt is for SIGINT."""


# the signals main()'s handlers saw: CPython (3.11) loses an exception that a
# handler raises while compile() runs, as when a module is imported from its
# source (no .pyc yet, PYTHONDONTWRITEBYTECODE): _check_signals raises it again
_received: list[int] = []


def _raise_signal(signum, frame):
    _received.append(signum)
    if _unsafe(frame):
        # raised here, the exception would be fatal (inside an extension
        # module's initialisation: "Critical nanobind error", an abort) or
        # printed and dropped ("Exception ignored in ... __del__"): the signal
        # is sent again in 50 ms, until it lands where it can be raised
        import threading

        _deferred.add(signum)
        t = threading.Timer(0.05, _send_again, (signum,))
        t.daemon = True
        t.start()
        return
    _deferred.clear()  # raised: no signal is sent again
    raise _Terminated if signum == signal.SIGTERM else KeyboardInterrupt


# a command that handled a Ctrl-C itself and returns 130 (clvis.cli._common.on_workers):
# entry() ignores the signals while the interpreter shuts down, as after _received
_ignore_on_exit: list[int] = []

# signals deferred by _raise_signal and not raised since
_deferred: set[int] = set()


def _send_again(signum: int) -> None:
    if signum in _deferred:
        os.kill(os.getpid(), signum)


def _unsafe(frame) -> bool:
    """Whether the main thread is importing a module, running a finaliser or
    inside the import system's callbacks (where a raised exception is lost or
    fatal)."""
    while frame is not None:
        code = frame.f_code
        if code.co_filename.startswith("<frozen importlib") or code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


def _on_signals(previous: dict[int, object]) -> None:
    """Raise _Terminated on SIGTERM and KeyboardInterrupt on SIGINT (where Python
    does, not where SIGINT is ignored), noting each; the handlers replaced go
    into `previous`. Main thread only: elsewhere Python cannot set a handler."""
    for sig in (signal.SIGTERM, signal.SIGINT):
        if sig == signal.SIGINT and signal.getsignal(sig) is not signal.default_int_handler:
            continue
        try:
            previous[sig] = signal.signal(sig, _raise_signal)
        except (ValueError, OSError):  # ValueError: not the main thread
            return


def _check_signals() -> None:
    """Raise for a signal whose exception was lost (see _received)."""
    if _received:
        _deferred.clear()
        raise _Terminated if _received[0] == signal.SIGTERM else KeyboardInterrupt


def _ctrl_c_handled() -> None:
    """A command for which Ctrl-C is the way to stop (clvis view) has
    stopped by it: main() returns the command's status, not 130, and does
    not say "interrupted" after the command's own line."""
    if _received and _received[0] == signal.SIGINT:
        _received.clear()
        _deferred.clear()


# words a user may type for what is an option of the commands
_OPTION_WORDS = {
    "orbit": "a turntable is an option: clvis render|iso|gauss FILE --orbit N [--movie turn.mp4]",
    "movie": "a movie is an option: clvis render|iso|gauss FILE --orbit N --movie turn.mp4",
    "infill": "the in-fill network is an option: clvis iso FILE --completion 0.85 --infill",
    "post": "the networks are options: clvis render FILE --post lidar|narvis, clvis iso FILE --infill",
}


def _unknown_command(p: argparse.ArgumentParser, word: str, commands: list[str]) -> int:
    """argparse's usage and one line: no such command, the closest ones or
    the option meant (`clvis orbit`: --orbit); exit status 2."""
    import difflib

    hint = _OPTION_WORDS.get(word.lower())
    if hint is None and (os.path.exists(word) or os.path.splitext(word)[1]):
        from ..io.points import POINT_SUFFIXES
        from ..io.volumes import FORMATS

        name = word.lower()
        volume = name.endswith(FORMATS) or name.endswith((".vdb", ".vtk"))
        points = name.endswith(POINT_SUFFIXES)
        which = "iso|gauss" if volume and not points else "render|gauss" if points and not volume else None
        hint = "a file goes after the command: " + (
            f"clvis view {word}, or clvis {which} {word}" if which else f"clvis view|render|iso|gauss {word}"
        )
    if hint is None:
        close = difflib.get_close_matches(word.lower(), commands, n=2, cutoff=0.75)
        hint = f"did you mean {' or '.join(close)}?" if close else f"the commands: {', '.join(commands)}"
    p.print_usage(sys.stderr)
    sys.stderr.write(f"clvis: error: no command {word!r}; {hint}\n")
    return 2


def _interrupted(argv: list[str], sig: signal.Signals) -> int:
    _deferred.clear()
    # a second Ctrl-C while exiting would print a traceback
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except (ValueError, OSError):
        pass
    cmd = next((a for a in argv if not a.startswith("-")), "")
    what = "interrupted" if sig == signal.SIGINT else "terminated"
    try:
        sys.stderr.write(f"clvis{' ' + cmd if cmd else ''}: {what}\n")
        sys.stderr.flush()
    except Exception:  # noqa: BLE001  (no stderr to tell)
        pass
    return 128 + int(sig)


def _main(argv: list[str]) -> int:
    from ._common import glue_values, run

    p, commands = _parser()
    _check_signals()  # the imports are done
    if not argv:
        p.print_help()
        return 0
    for i, tok in enumerate(argv):  # the command: the first word that is no option
        if not tok.startswith("-"):
            if tok in commands:
                argv[i + 1 :] = glue_values(commands[tok], argv[i + 1 :])
            else:
                return _unknown_command(p, tok, list(commands))
            break
    try:
        args, extra = p.parse_known_args(argv)
        if extra:  # said by the command's parser (argparse's top level printed clvis's usage)
            _unrecognized(commands.get(args.cmd) or p, extra)
        if args.cmd is None:  # only options, such as `clvis --verbose`
            p.print_help()
            return 0
        return run(args.cmd, _module(args.cmd).cmd, args)
    except SystemExit as e:  # argparse: --help, --version, a bad argument
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    except BrokenPipeError:  # `clvis info | head -1`: the reader has all it wanted
        _quiet_stdout()
        return 141  # 128 + SIGPIPE, as a pipeline reports a process it stopped


def _unrecognized(parser, extra: list[str]) -> None:
    """The command's one-line error for words it does not take, with the
    nearest option for a misspelt one (--sise: --size); exits 2."""
    import difflib

    options = [s for s in parser._option_string_actions if s.startswith("--")]
    hints = []
    for word in extra:
        if word.startswith("--"):
            near = difflib.get_close_matches(word.split("=", 1)[0], options, n=1, cutoff=0.6)
            if near:
                hints.append(f"{word.split('=', 1)[0]}: did you mean {near[0]}?")
    parser.error(f"unrecognized arguments: {' '.join(extra)}" + (f" ({'; '.join(hints)})" if hints else ""))


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
