"""What every clvis command shares: the argument types (image size, counts),
the one error class a command reports, the wrapper that turns errors into
one line on stderr and exit status 2, and the progress display."""

from __future__ import annotations

import argparse
import contextlib
import re
import shutil
import sys
import threading
import time

from ..raster import MAX_IMAGE_SIDE

# The one image-size rule of every command: each side in 1..MAX_SIDE, the
# rasterizer's limit (the smallest any renderer has). W * H then stays below
# 2^31, so the kernels' 32-bit pixel indices never overflow.
MAX_SIDE = MAX_IMAGE_SIDE
MAX_PIXELS = 2**31 - 1
SIZE_RULE = f"each side 1..{MAX_SIDE}"


class CliError(Exception):
    """A problem a command reports as one line on stderr, with exit status 2."""


class Parser(argparse.ArgumentParser):
    """A sub-command's parser: a bad argument is one line, without the usage text."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def glue_values(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """argv with `--opt VALUE` written `--opt=VALUE` where VALUE starts with a
    dash: argparse takes `-5x5` or `-1,2,3` for an option of its own, not for
    the value of the option before it."""
    takes_value = {s for a in parser._actions if a.option_strings and a.nargs is None
                   for s in a.option_strings}
    known = set(parser._option_string_actions)
    out, i = [], 0
    while i < len(argv):
        tok = argv[i]
        if tok == "--":
            out += argv[i:]
            break
        nxt = argv[i + 1] if i + 1 < len(argv) else None
        if (tok in takes_value and nxt is not None and nxt.startswith("-") and nxt != "--"
                and nxt.split("=", 1)[0] not in known):
            out.append(f"{tok}={nxt}")
            i += 2
            continue
        out.append(tok)
        i += 1
    return out


# ---------------------------------------------------------------- argument types

def size(text: str) -> tuple[int, int]:
    """'WxH' -> (W, H), each side in 1..MAX_SIDE (so W * H <= MAX_PIXELS)."""
    m = re.fullmatch(r"\s*([+-]?\d+)\s*[xX×]\s*([+-]?\d+)\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 1920x1080, got {text!r}")
    w, h = int(m.group(1)), int(m.group(2))
    if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE) or w * h > MAX_PIXELS:
        raise argparse.ArgumentTypeError(f"width and height must lie in 1..{MAX_SIDE}, got {text!r}")
    return w, h


def positive_int(text: str) -> int:
    try:
        n = int(text.replace("_", "").replace(",", ""))
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return n


# ---------------------------------------------------------------- running a command

def run(name: str, fn, args) -> int:
    """fn(args), with the errors a user can cause as one line on stderr and
    exit status 2: CliError, clvis's own errors (a file clvis cannot read, a
    device too small), and OSError (an unreadable file, an unwritable folder)."""
    from ..errors import ClvisError

    try:
        return fn(args)
    except (CliError, ClvisError, ImportError) as e:
        msg = str(e)
    except OSError as e:
        msg = f"{e.filename}: {e.strerror}" if e.filename and e.strerror else str(e)
    print(f"clvis {name}: error: {msg}", file=sys.stderr)
    return 2


def timed(fn, queue=None, repeat=3) -> float:
    """Best of `repeat` timed runs after one warm-up (which builds the
    kernels); a single timed run when that one takes over half a second."""
    def once():
        t0 = time.perf_counter()
        fn()
        if queue is not None:
            queue.finish()
        return time.perf_counter() - t0

    once()
    best = once()
    if best > 0.5:
        return best
    for _ in range(repeat - 1):
        best = min(best, once())
    return best


# ---------------------------------------------------------------- progress

class Progress:
    """Stage names and their elapsed times on stderr.

    On a terminal the running stage's line is rewritten in place a few times
    a second; elsewhere (a log, --progress into a pipe) each stage prints one
    line when it ends. Disabled, it prints nothing.
    """

    def __init__(self, enabled: bool, prefix: str = "clvis render"):
        self.enabled = enabled
        self.stream = sys.stderr
        self.tty = enabled and isatty(self.stream)
        self.prefix = prefix
        self.start = time.perf_counter()

    def _line(self, name: str, since: float, failed: bool = False) -> str:
        now = time.perf_counter()
        tail = "failed" if failed else f"(total {now - self.start:6.2f} s)"
        line = f"{self.prefix}: {name:<36} {now - since:6.2f} s  {tail}"
        if self.tty:            # one terminal row, or \r cannot rewrite it
            line = line[:shutil.get_terminal_size().columns - 1]
        return line

    def _write(self, text: str):
        self.stream.write(text)
        self.stream.flush()

    @contextlib.contextmanager
    def stage(self, name: str):
        if not self.enabled:
            yield
            return
        t0 = time.perf_counter()
        stop = threading.Event()
        ticker = None
        if self.tty:
            def tick():
                while not stop.wait(0.2):
                    self._write("\r\x1b[K" + self._line(name, t0))
            self._write("\r\x1b[K" + self._line(name, t0))
            ticker = threading.Thread(target=tick, daemon=True)
            ticker.start()
        failed = True
        try:
            yield
            failed = False
        finally:
            stop.set()
            if ticker is not None:
                ticker.join()
            self._write(("\r\x1b[K" if self.tty else "") + self._line(name, t0, failed) + "\n")


def isatty(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False
