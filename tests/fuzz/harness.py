"""Run one call in a forked child under an address-space limit and a timeout,
and say how it ended: "ok", "clvis" (a ClvisError naming what it was given),
"unnamed" (a ClvisError that does not name the file), "foreign" (any other
exception, MemoryError included), "crash" (a signal or an exit without a
report: lazrs's abort on a failed allocation, a segfault), "hang" (killed at
the timeout). The child's peak resident set (ru_maxrss from wait4) comes back
with it, so a reader that takes gigabytes shows up even when it succeeds.

Both are counted from what the child had when it was forked: a fork inherits
the parent's address space and resident pages, which in a test session that
has loaded two OpenCL runtimes, torch and numba is already gigabytes. The
limit is that size plus the budget, and the peak is the growth over the
resident set at the start, so a case measures the same under pytest as in a
fresh ``./dev.sh fuzz`` process.

The regression tests and ``./dev.sh fuzz`` (tests/fuzz/run.py) share it. A
fork copies only the calling thread: call it from a process that has not
started thread pools the case would use (lazrs's parallel decoder after a LAZ
read hangs in the child), hence ``./dev.sh test`` runs tests/fuzz in a pytest
session of its own.
"""

from __future__ import annotations

import dataclasses
import os
import pickle
import resource
import select
import signal
import time
import traceback
from collections.abc import Callable

# RLIMIT_AS of a case: 4 GiB, as the audit that found the crashes used
LIMIT_BYTES = 4 << 30


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


def run_limited(
    fn: Callable,
    *args,
    limit_bytes: int = LIMIT_BYTES,
    timeout: float = 20.0,
    name: str | None = None,
) -> Outcome:
    """fn(*args) in a forked child with RLIMIT_AS = `limit_bytes`; `name` (a file
    path) must appear in a ClvisError's message."""
    r, w = os.pipe()
    t0 = time.monotonic()
    pid = os.fork()
    if pid == 0:  # the child: report, then leave without running the parent's cleanup
        code = 0
        try:
            os.close(r)
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
        return Outcome("hang", f"killed after {timeout} s", peak, seconds)
    if os.WIFSIGNALED(status):
        sig = signal.Signals(os.WTERMSIG(status)).name
        return Outcome("crash", f"killed by {sig}", peak, seconds)
    try:
        kind, detail, base_rss = pickle.loads(data)
    except Exception:  # noqa: BLE001
        return Outcome("crash", f"exit status {os.WEXITSTATUS(status)} without a report", peak, seconds)
    return Outcome(kind, detail, max(peak - base_rss, 0), seconds)
