"""Run one call in a forked child under an address-space limit and a timeout,
and say how it ended: "ok", "clvis" (a ClvisError naming what it was given),
"unnamed" (a ClvisError that does not name the file), "foreign" (any other
exception, MemoryError included), "crash" (a signal or an exit without a
report: lazrs's abort on a failed allocation, a segfault), "hang" (killed at
the timeout). The child's peak resident set (ru_maxrss from wait4) comes back
with it, so a reader that takes gigabytes shows up even when it succeeds.

The children are forked by a server process of their own (a fresh Python
started once, with exec, that imports the readers' libraries and nothing
else), never by the caller: a fork copies only the calling thread, and a
caller that has started thread pools (lazrs's rayon pool after any LAZ read,
the OpenCL runtimes') hands its child a pool without threads, so lazrs's
parallel decoder waited forever in the child for workers that were not there
(a LAZ case after tests/test_io.py in one pytest session hung until the
timeout). The server never runs a reader itself, so its children start as a
single-threaded process whatever the caller did. Its children also measure the
same under pytest as in ``./dev.sh fuzz``: the limit is the child's address
space at the fork plus the budget, and the peak is the growth over its
resident set at the start.

The regression tests and ``./dev.sh fuzz`` (tests/fuzz/run.py) share it.
"""

from __future__ import annotations

import atexit
import ctypes
import dataclasses
import os
import pickle
import resource
import select
import signal
import struct
import subprocess
import sys
import time
import traceback
from collections.abc import Callable

# RLIMIT_AS of a case: 4 GiB, as the audit that found the crashes used
LIMIT_BYTES = 4 << 30
# what the readers import lazily, imported once by the server so that a child
# does not (time and memory counted against the case otherwise)
PRELOAD = (
    "clvis.io",
    "clvis.gauss",
    "laspy",
    "lazrs",
    "nibabel",
    "nibabel.cifti2",
    "plyfile",
    "tinyvdb",
    "pye57",
    "pypcd4",
    "vtkmodules.vtkIOXML",
    "vtkmodules.vtkIOLegacy",
    "vtkmodules.util.numpy_support",
    "clvis.gauss.sparse",
)
# how much longer than a case's own timeout the caller waits for the server's answer
SERVER_GRACE = 60.0


def _status_bytes(key: str) -> int:
    """A size from /proc/self/status (VmSize, VmRSS), in bytes; 0 where absent."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


@dataclasses.dataclass
class Outcome:
    kind: str  # ok | clvis | unnamed | foreign | crash | hang
    detail: str = ""
    peak_rss: int = 0  # bytes
    seconds: float = 0.0

    @property
    def failed(self) -> bool:
        return self.kind in ("unnamed", "foreign", "crash", "hang")


def _memory_error(e: BaseException | None) -> bool:
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, MemoryError):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def _classify(fn: Callable, args: tuple, name: str | None) -> tuple[str, str]:
    from clvis.errors import ClvisError

    try:
        fn(*args)
    except ClvisError as e:
        if _memory_error(e):  # a MemoryError dressed up: the check came too late
            return "foreign", f"MemoryError under {type(e).__name__}: {e}"[:500]
        if name is not None and name not in str(e):
            return "unnamed", f"{type(e).__name__}: {e}"[:500]
        return "clvis", f"{type(e).__name__}: {e}"[:300]
    except BaseException as e:  # noqa: BLE001 - the point is to see everything
        tb = traceback.format_exc(limit=-3)
        return "foreign", f"{type(e).__name__}: {e}"[:300] + "\n" + tb[-1200:]
    return "ok", ""


def _die_with_parent() -> None:
    """SIGKILL this process when the one that started it ends (Linux's
    PR_SET_PDEATHSIG), so that a killed caller or server leaves no case running."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _run_forked(fn: Callable, args: tuple, limit_bytes: int, timeout: float, name: str | None) -> tuple:
    """The server's part: fn(*args) in a child forked here; (kind, detail, peak, seconds)."""
    parent = os.getpid()
    r, w = os.pipe()
    t0 = time.monotonic()
    pid = os.fork()
    if pid == 0:  # the child: report, then leave without running the parent's cleanup
        code = 0
        try:
            os.close(r)
            _die_with_parent()
            if os.getppid() != parent:  # the server ended before the line above
                raise SystemExit
            # the budget on top of the address space the fork inherited
            limit = _status_bytes("VmSize") + limit_bytes
            base_rss = _status_bytes("VmRSS")
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
            kind, detail = _classify(fn, args, name)
            os.write(w, pickle.dumps((kind, detail, base_rss)))
        except BaseException:  # noqa: BLE001
            code = 3
        finally:
            os._exit(code)
    os.close(w)
    data = b""
    deadline = t0 + timeout
    hung = False
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            hung = True
            os.kill(pid, signal.SIGKILL)
            break
        ready, _, _ = select.select([r], [], [], min(left, 1.0))
        if ready:
            chunk = os.read(r, 1 << 16)
            if not chunk:
                break
            data += chunk
    os.close(r)
    _, status, usage = os.wait4(pid, 0)
    seconds = time.monotonic() - t0
    peak = usage.ru_maxrss * 1024
    if hung:
        return "hang", f"killed after {timeout} s", peak, seconds
    if os.WIFSIGNALED(status):
        sig = signal.Signals(os.WTERMSIG(status)).name
        return "crash", f"killed by {sig}", peak, seconds
    try:
        kind, detail, base_rss = pickle.loads(data)
    except Exception:  # noqa: BLE001
        return "crash", f"exit status {os.WEXITSTATUS(status)} without a report", peak, seconds
    return kind, detail, max(peak - base_rss, 0), seconds


def _send(fd: int, data: bytes) -> None:
    view = memoryview(struct.pack("<Q", len(data)) + data)
    while view:
        view = view[os.write(fd, view) :]


def _receive(fd: int, deadline: float | None = None) -> object:
    """One message from `fd`; EOFError at its end, TimeoutError past `deadline`."""

    def exactly(n: int) -> bytes:
        data = b""
        while len(data) < n:
            if deadline is not None:
                left = deadline - time.monotonic()
                if left <= 0 or not select.select([fd], [], [], left)[0]:
                    raise TimeoutError
            chunk = os.read(fd, n - len(data))
            if not chunk:
                raise EOFError
            data += chunk
        return data

    (size,) = struct.unpack("<Q", exactly(8))
    return pickle.loads(exactly(size))


def _serve() -> None:
    """The server's loop: a request (fn, args, limit_bytes, timeout, name) on
    stdin, its outcome on stdout; ends at the end of stdin or with its caller.
    What the readers and children print goes to stderr, never into the answers."""
    import logging

    requests, answers = os.dup(0), os.dup(1)
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.dup2(2, 1)
    _die_with_parent()
    logging.getLogger("nibabel").setLevel(logging.CRITICAL)  # the header fields it fixes
    for module in PRELOAD:
        try:
            __import__(module)
        except ImportError:
            pass
    while True:
        try:
            request = _receive(requests)
        except EOFError:
            return
        except Exception:  # noqa: BLE001 - a request it cannot unpickle: the caller says why
            _send(answers, pickle.dumps(("harness", traceback.format_exc(limit=-3))))
            continue
        _send(answers, pickle.dumps(_run_forked(*request)))


_server: subprocess.Popen | None = None
_server_owner = 0  # the process that started it (a forked caller starts its own)


def _stop_server() -> None:
    global _server
    proc, _server = _server, None
    if proc is not None and _server_owner == os.getpid():
        proc.kill()
        proc.wait()
        for f in (proc.stdin, proc.stdout):
            if f is not None:
                f.close()


def _the_server() -> subprocess.Popen:
    global _server, _server_owner
    if _server is None or _server_owner != os.getpid() or _server.poll() is not None:
        _stop_server()
        # the caller's import path, so that the server unpickles what it is sent
        path = os.pathsep.join(p for p in sys.path if p)
        env = dict(os.environ, PYTHONPATH=path)
        _server = subprocess.Popen(
            [sys.executable, os.path.abspath(__file__), "--serve"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            env=env,
        )
        _server_owner = os.getpid()
    return _server


atexit.register(_stop_server)


def run_limited(
    fn: Callable,
    *args,
    limit_bytes: int = LIMIT_BYTES,
    timeout: float = 20.0,
    name: str | None = None,
) -> Outcome:
    """fn(*args) in a child forked by the server with RLIMIT_AS = `limit_bytes`
    over its size at the fork; `name` (a file path) must appear in a ClvisError's
    message. `fn` and `args` travel pickled: a module-level function or method."""
    request = pickle.dumps((fn, args, limit_bytes, timeout, name))
    server = _the_server()
    assert server.stdin is not None and server.stdout is not None
    try:
        _send(server.stdin.fileno(), request)
        answer = _receive(server.stdout.fileno(), time.monotonic() + timeout + SERVER_GRACE)
    except BaseException:  # Ctrl-C, a server that died or stopped answering: start afresh next time
        _stop_server()
        raise
    if answer[0] == "harness":
        raise RuntimeError(f"the fuzz harness's server could not take the call:\n{answer[1]}")
    return Outcome(*answer)


if __name__ == "__main__" and sys.argv[1:] == ["--serve"]:
    _serve()
