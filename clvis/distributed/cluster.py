"""The Dask side shared by the distributed renderers: the client (given, an
address, or a ``LocalCluster`` of one-thread worker processes started and
owned here), waits that always have a bound, the one per-process registry
of what the workers hold, the one frame task, and the errors.

No scheduling of our own: tasks go to Dask with a loose wish for the worker
that holds their inputs (``allow_other_workers``), so a lost worker's tasks
run elsewhere.

Every wait on the cluster is bounded: ``timeout`` for a frame or a build,
``connect_timeout`` for reaching a scheduler (a refused connection fails at
once), and the smaller of the two for letting go at :meth:`ClusterOwner.close`.
A wait past its bound raises :class:`clvis.errors.ClusterTimeout` saying what
was waited for and on which workers; a renderer used after ``close()``, a
scheduler not reached and data lost for good raise
:class:`clvis.errors.ClusterError`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any
from urllib.parse import urlsplit

from ..errors import ClusterError, ClusterTimeout, DeviceError
from . import composite as _c

__all__ = [
    "REGISTRY",
    "ClusterOwner",
    "WorkerRegistry",
    "composite_task",
    "connected_workers",
    "current_worker",
    "device_error",
    "frame_seconds",
    "render_partial",
    "start_cluster",
]

CONNECT_TIMEOUT = 10.0  # seconds to reach a scheduler given by address (and for it to have a worker)
FRAME_RETRIES = 2  # frames submitted again after data was lost with a worker
START_POLL = 0.02  # seconds between looks at a LocalCluster's start (start_cluster)
STALL_CHECK = 1.0  # seconds between looks for tasks Dask left waiting for workers that are gone
PROBE_QUIET = 1.0  # seconds a tcp:// scheduler address may stay silent before it is asked as a web server is
PROBE_REQUEST = b"HEAD / HTTP/1.0\r\n\r\n"  # what it is asked then: a Dask scheduler speaks first
WORKERS_PER_CORE = 4  # a LocalCluster started here: at most this many worker processes per CPU core


def _distributed() -> Any:
    """The dask.distributed module (an optional extra: ImportError naming it)."""
    try:
        import distributed
    except ImportError as e:  # pragma: no cover - the extra is missing
        raise ImportError("clvis.distributed needs dask.distributed: pip install 'clvis[distributed]'") from e
    return distributed


def current_worker() -> str | None:
    """The address of the Dask worker running this (None outside a task)."""
    try:
        return _distributed().get_worker().address
    except ValueError:
        return None


def connected_workers(client: Any, timeout: float | None = None) -> dict[str, dict]:
    """The scheduler's record of every worker now connected, by address,
    waited for at most `timeout` seconds (None: no bound; ClusterTimeout).

    Asks the scheduler directly. ``client.scheduler_info()`` returns the
    client's cached identity, which its own periodic refresh (every 2 s, with
    no workers in it) can overwrite between the fetch and the return: an empty
    ``"workers"`` on a cluster of two (dask.distributed 2026.8)."""
    try:
        info = client.sync(client.scheduler.identity, n_workers=-1, callback_timeout=timeout)
    except TimeoutError:
        raise ClusterTimeout(f"the scheduler's list of workers: no answer within {timeout:g} s") from None
    return dict(info.get("workers", {}))


def device_error(e: BaseException) -> DeviceError:
    """A DeviceError naming this worker and what its OpenCL said."""
    w = current_worker() or "the client"
    return DeviceError(f"worker {w}: no usable OpenCL device ({type(e).__name__}: {e})")


# ---------------------------------------------------------------- the workers' side


class WorkerRegistry:
    """What one worker process holds for the renderers, by token: the
    renderers built there (a Rasterizer of its partitions, an IsoRenderer per
    brick) and partitions read but not built yet. A frame task that finds its
    token missing (a new process, a task moved) builds it again from its
    handle. One per process: :data:`REGISTRY`."""

    def __init__(self) -> None:
        self._items: dict[str, Any] = {}
        self._lock = threading.Lock()

    def put(self, token: str, item: Any) -> Any:
        with self._lock:
            self._items[token] = item
        return item

    def get(self, token: str) -> Any:
        with self._lock:
            return self._items.get(token)

    def pop(self, token: str) -> Any:
        with self._lock:
            return self._items.pop(token, None)

    def forget(self, tokens: Sequence[str]) -> None:
        with self._lock:
            for t in tokens:
                self._items.pop(t, None)

    def tokens(self) -> list[str]:
        with self._lock:
            return sorted(self._items)


REGISTRY = WorkerRegistry()


def forget(tokens: Sequence[str]) -> None:
    """Run on every worker: let go of these tokens."""
    REGISTRY.forget(tokens)


def render_partial(render_one: Callable[[Any, Any, dict], _c.Partial], parts: list, view: dict) -> _c.Partial:
    """Task, the same for points and volumes: ``render_one(handle, data,
    view)`` → the Partial of one part (its ``counts`` included) for each
    (handle, data) in `parts`, composited here by the min key, timed
    ("render <worker>", "composite <worker>"); nothing sent yet (partials of
    one worker move nothing)."""
    worker = current_worker()
    t0 = time.perf_counter()
    partials = [render_one(handle, data, view) for handle, data in parts]
    t1 = time.perf_counter()
    out = _c.composite(partials, worker)
    out.sent = {}
    out.seconds = {f"render {worker}": t1 - t0, f"composite {worker}": time.perf_counter() - t1}
    return out


def composite_task(*parts: _c.Partial) -> _c.Partial:
    """Task: min-key composite of `parts` on this worker, timed."""
    t0 = time.perf_counter()
    w = current_worker()
    out = _c.composite(parts, w)
    k = f"composite {w}"
    out.seconds[k] = out.seconds.get(k, 0.0) + time.perf_counter() - t0
    return out


def frame_seconds(frame: float, seconds: dict) -> dict:
    """{"frame": client wall time, "render"/"composite": the busiest worker's
    seconds, "per_worker": {"render <address>": s, ...}}."""
    out: dict = {"frame": frame}
    for what in ("render", "composite"):
        vals = [v for k, v in seconds.items() if k.startswith(what + " ")]
        out[what] = max(vals) if vals else 0.0
    out["per_worker"] = dict(seconds)
    return out


# ---------------------------------------------------------------- the client's side


def _ignore_sigint() -> None:
    with contextlib.suppress(ValueError):  # not the main thread: nothing to do
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def _quiet_workers() -> Any:
    """A WorkerPlugin that makes every worker process ignore SIGINT, those the
    nanny starts again after a loss included."""
    plugin: Any = _distributed().WorkerPlugin  # the extra is imported when called: mypy takes the base as Any

    class IgnoreSigint(plugin):
        idempotent = True
        name = "clvis-ignore-sigint"

        def setup(self, worker: Any) -> None:
            _ignore_sigint()

    return IgnoreSigint()


def local_workers_max() -> int:
    """The most worker processes a LocalCluster started here may have:
    WORKERS_PER_CORE per CPU core this process may run on (one-thread
    workers beyond that only compete for the cores, and each costs its own
    memory: a few thousand would take the machine down)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not Linux
        cores = os.cpu_count() or 1
    return WORKERS_PER_CORE * max(1, cores)


def check_local_workers(workers: Any) -> int:
    """`workers` for a LocalCluster started here: a positive int, at most
    local_workers_max() (ValueError saying why)."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: expected a positive int, got {workers!r}")
    most = local_workers_max()
    if workers > most:
        raise ValueError(
            f"workers: {workers} local worker processes; at most {most} here ({WORKERS_PER_CORE} per CPU "
            "core: more only compete for the cores and memory; a cluster of several machines: give its "
            "scheduler's address)"
        )
    return workers


# what Dask sets in this process's own environment to pass to the workers it
# spawns: its nanny's pre-spawn variables (MALLOC_TRIM_THRESHOLD_,
# OMP_NUM_THREADS, MKL_NUM_THREADS, OPENBLAS_NUM_THREADS by default) and
# __DASK_PARENT_PID
_DASK_PARENT = "__DASK_PARENT_PID"


def dask_environ_keys() -> tuple[str, ...]:
    """The environment variables Dask's nanny sets in the process that starts
    a LocalCluster (``distributed.nanny.pre-spawn-environ``, and the parent
    pid that names the workers' process titles)."""
    import dask

    spawn = dask.config.get("distributed.nanny.pre-spawn-environ", default={}) or {}
    return (*sorted(str(k) for k in spawn), _DASK_PARENT)


def environ_snapshot() -> dict[str, str | None]:
    """The values of dask_environ_keys() now (None: unset)."""
    return {k: os.environ.get(k) for k in dask_environ_keys()}


def restore_environ(snapshot: dict[str, str | None]) -> None:
    """The variables of `snapshot` as they were: Dask's nanny updates this
    process's os.environ before it spawns a worker (so that the worker
    inherits OMP_NUM_THREADS=1, MALLOC_TRIM_THRESHOLD_=65536) and never
    restores it, so that a user's later subprocesses (a training, a
    compiler) ran single-threaded and with another malloc; a library call
    must leave the process as it found it."""
    for k, v in snapshot.items():
        if v is None:
            os.environ.pop(k, None)
        elif os.environ.get(k) != v:
            os.environ[k] = v


def _block_sigint() -> None:
    """SIGINT held back (blocked) in this thread, and so in the threads it
    starts and the processes they spawn (a signal mask is inherited through
    thread creation, fork and exec); POSIX only.

    multiprocessing's resource tracker is started first, if it does not run
    yet: the first spawn starts it and unblocks SIGINT in the spawning thread
    after (Python 3.11), which would be Dask's IO loop thread, so that the
    threads it starts next, and the workers they spawn, would see SIGINT."""
    if not hasattr(signal, "pthread_sigmask"):
        return
    with contextlib.suppress(Exception):
        from multiprocessing import resource_tracker

        resource_tracker.ensure_running()
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})


def start_cluster(workers: int, *, close_timeout: float = CONNECT_TIMEOUT, **kw: Any) -> Any:
    """A LocalCluster of `workers` processes, one thread each, the dashboard
    on a free port.

    Its worker processes never see SIGINT: a terminal's Ctrl-C reaches the
    whole process group, and the process that started them stops them
    (their tracebacks would say nothing). The cluster is started in a thread
    of its own that blocks SIGINT; Dask's IO loop thread, the threads that
    spawn the workers and so the workers inherit the mask (and a worker
    plugin, ClusterOwner's, makes them ignore it as well). The calling
    thread and the caller's SIGINT handler are left as they are: a Ctrl-C
    while the cluster starts (the handler's KeyboardInterrupt, or whatever
    else the wait raises) lets the start run to its end (Dask's start cut
    at an arbitrary point would leave its worker processes behind), closes
    the cluster (waiting at most `close_timeout` seconds), puts this
    process's environment back (restore_environ) and is raised then."""
    d = _distributed()
    kw.setdefault("processes", True)
    # the workers report their failures through the futures; their own logs
    # (a cluster stopped on purpose: heartbeats to a closed scheduler) say nothing more
    kw.setdefault("silence_logs", logging.CRITICAL)
    environ = environ_snapshot()
    # shared by single list operations (atomic under the GIL; a signal's
    # handler runs between them, never inside). The starting thread notes
    # that it runs (`ran`), then starts nothing if the caller has given up
    # already (`abandoned`), puts the cluster in `made` (its error in
    # `failed`) and notes its end (`done`). The caller that gives up notes
    # it, then waits for `done` if the thread ran (if it did not, it will
    # see `abandoned`) and closes what `made` holds. The caller waits by
    # polling: Thread.join() interrupted by a signal's exception marks the
    # thread stopped while it runs (CPython 3.11, bpo-45274's fix), and
    # is_alive() says False from then on.
    ran: list = []
    made: list = []
    failed: list = []
    done: list = []
    abandoned: list = []

    def start() -> None:
        ran.append(True)
        try:
            if not abandoned:
                _block_sigint()
                made.append(
                    d.LocalCluster(n_workers=workers, threads_per_worker=1, dashboard_address=":0", **kw)
                )
        except BaseException as e:  # noqa: BLE001 - handed to the caller's thread
            failed.append(e)
        finally:
            done.append(True)

    try:
        threading.Thread(target=start, name="clvis-start-cluster", daemon=True).start()
        while not done:
            time.sleep(START_POLL)
        restore_environ(environ)  # the workers have theirs; this process keeps its own
        if failed:
            raise failed[0]
        return made[0]  # the caller's from here on: an interrupt before, and the cluster is closed below
    except BaseException:  # a Ctrl-C, or the start's error: raised once the start ended and was undone
        abandoned.append(True)
        cluster = None
        while True:
            try:  # another Ctrl-C meanwhile is taken as the first one (raised below), not as a way out
                if ran and not done:
                    time.sleep(START_POLL)
                    continue
                if cluster is None and made:
                    cluster = made.pop()
                if cluster is not None:
                    with _quiet_logs(), contextlib.suppress(Exception):
                        cluster.close(timeout=close_timeout)
                restore_environ(environ)
                break
            except BaseException:  # noqa: BLE001 - see above
                continue
        raise


def _probe(address: str, timeout: float) -> None:
    """Fail fast on a tcp:// scheduler that refuses, does not answer or is
    no Dask scheduler (_first_words)."""
    parts = urlsplit(address if "://" in address else "tcp://" + address)
    known = _schemes()
    if known and parts.scheme not in known:
        raise ClusterError(
            f"scheduler {address}: not a Dask address (scheme {parts.scheme + '://'!r}; Dask's: "
            f"{', '.join(s + '://' for s in known)})"
        )
    if parts.scheme not in ("tcp", "tls", "ws", "wss"):
        return  # inproc://, ucx://: Dask's own connect, bounded by the timeout
    try:
        port = parts.port
    except ValueError:
        port = -1
    if port is None or port < 0 or not parts.hostname:
        raise ClusterError(f"scheduler {address}: not a host:port address")
    if parts.scheme != "tcp":
        return  # tls://, ws://, wss://: Dask's own connect, bounded by the timeout
    try:
        sock = socket.create_connection((parts.hostname, port), timeout=timeout)
    except TimeoutError:
        raise ClusterTimeout(f"scheduler {address}: no answer within connect_timeout={timeout:g} s") from None
    except OSError as e:
        raise ClusterError(f"scheduler {address}: cannot connect ({e.strerror or e})") from None
    with sock:
        said = _first_words(sock, min(PROBE_QUIET, timeout))
    if said:
        raise ClusterError(
            f"scheduler {address}: what answered there is not a Dask scheduler (it said {said!r})"
        )


def _first_words(sock: socket.socket, quiet: float) -> str:
    """What the peer of `sock` (just connected) says, when that is not the
    start of a Dask message; "" when it is, or says nothing.

    A Dask scheduler speaks first: its handshake, at once. A peer that says
    nothing for `quiet` seconds is asked what a web client asks (``HEAD /``),
    for a web server (``python -m http.server``) answers only a whole
    request: Dask's own handshake is none, and the Client waited out its
    connect_timeout to say "not reached". A peer silent after that too, or
    that closes, is left to Dask's own connect (bounded by its timeout). A
    Dask scheduler too busy to speak within `quiet` (stopped for 1.5 s:
    measured) still speaks first and is taken as one; it reads the request
    as a message of exabytes and drops that connection, with a MemoryError
    in its log."""
    data = _read_some(sock, quiet)
    if data is None:
        return ""
    if not data:
        with contextlib.suppress(OSError):
            sock.sendall(PROBE_REQUEST)
            data = _read_some(sock, quiet) or b""
    if len(data) < 8 or _dask_prelude(data):
        return ""  # nothing, or too little to tell: Dask's own connect says
    line = (data.decode("ascii", "replace").strip().splitlines() or [""])[0][:60]
    return line if line and line.isprintable() else data[:16].hex(" ")


def _read_some(sock: socket.socket, wait: float) -> bytes | None:
    """The first bytes (16 at least, when it sends that many) that the peer
    sends within `wait` seconds; b"" when it sent nothing, None when it
    closed without a word."""
    data = b""
    deadline = time.monotonic() + wait
    while len(data) < 16:
        left = deadline - time.monotonic()
        if left <= 0:
            break
        sock.settimeout(left)
        try:
            chunk = sock.recv(64 - len(data))
        except TimeoutError:
            break
        except OSError:  # reset
            return data or None
        if not chunk:
            return data or None
        data += chunk
    return data


def _dask_prelude(data: bytes) -> bool:
    """Whether `data` (8 bytes at least) can start a Dask TCP message: its
    length in bytes, then its number of frames (each 8 bytes in this
    machine's order, struct's "Q"), then each frame's length."""
    (total,) = struct.unpack("Q", data[:8])
    if not 16 <= total < 2**40:
        return False
    if len(data) < 16:
        return True
    (frames,) = struct.unpack("Q", data[8:16])
    return 0 < frames < 2**20 and 8 + 8 * frames <= total


def _schemes() -> list[str]:
    """The address schemes this Dask knows (tcp, tls, inproc, ws, ...)."""
    try:
        from distributed.comm.registry import backends
    except ImportError:  # pragma: no cover - a Dask that moved it: its own connect says
        return []
    return sorted(backends)


def _line(e: BaseException, most: int = 200) -> str:
    """e's first line, at most `most` characters."""
    text = (str(e).strip().splitlines() or [""])[0]
    return text if len(text) <= most else text[: most - 3] + "..."


def _connect(address: str, timeout: float) -> Any:
    """A Client of the scheduler at `address`, made within `timeout` seconds
    (Dask's own connect can wait longer on a peer that accepts and stays
    silent: it is left to finish, and closed, in the background)."""
    d = _distributed()
    box: dict = {}

    def connect() -> None:
        try:
            box["client"] = d.Client(address, timeout=timeout)
        except BaseException as e:  # noqa: BLE001 - handed to the caller's thread
            box["error"] = e

    def close_late() -> None:
        t.join()
        if "client" in box:
            with contextlib.suppress(Exception):
                box["client"].close(timeout=timeout)

    t = threading.Thread(target=connect, name="clvis-connect", daemon=True)
    t.start()
    t.join(timeout + 1.0)
    if t.is_alive():
        threading.Thread(target=close_late, name="clvis-connect-close", daemon=True).start()
        raise ClusterTimeout(f"scheduler {address}: not reached within connect_timeout={timeout:g} s")
    e = box.get("error")
    if isinstance(e, (OSError, TimeoutError)):
        raise (ClusterTimeout if isinstance(e, TimeoutError) else ClusterError)(
            f"scheduler {address}: not reached within connect_timeout={timeout:g} s "
            f"({type(e).__name__}: {_line(e)})"
        ) from None
    if isinstance(e, ValueError):  # Dask's own check of the address
        raise ClusterError(f"scheduler {address}: {_line(e)}") from None
    if isinstance(e, Exception):
        # something else answered: an HTTP server's reply read as a Dask
        # message's length is a MemoryError of exabytes; a web server on
        # ws:// a WebSocketError
        raise ClusterError(
            f"scheduler {address}: what answered there is not a Dask scheduler "
            f"({type(e).__name__}: {_line(e)})"
        ) from None
    if e is not None:
        raise e
    return box["client"]


def _await_a_worker(client: Any, address: str, timeout: float) -> None:
    """Return once the scheduler at `address` has a worker, waited for at
    most `timeout` seconds (ClusterError: none joined): tasks on a
    scheduler without workers would wait out the whole render timeout."""
    deadline = time.monotonic() + timeout
    while not connected_workers(client, timeout):
        if time.monotonic() >= deadline:
            raise ClusterError(
                f"scheduler {address}: no worker joined it within connect_timeout={timeout:g} s "
                f"(start some: dask worker {address})"
            )
        time.sleep(0.2)


class ClusterOwner:
    """Holds a Dask client (starts, and closes, a LocalCluster when given
    none) and the handles of what the workers hold; submits and waits for
    frames.

    A subclass makes its handles on the workers, then gives them to
    :meth:`hold`: ``handles`` (futures of small objects naming what one
    worker built, each with a ``worker`` address), ``arrays`` (per handle,
    the futures of its data on the workers, or None), ``tokens`` (every
    registry token to let go of at close). It may override :meth:`_recover`
    to make data lost with a worker again (iso: bricks of an array)."""

    # compositing "auto": direct-send up to this many workers, the tree
    # beyond (composite.schedule; a subclass sets its family's constant)
    direct_send_max: int = _c.DIRECT_SEND_MAX_WORKERS_POINTS
    compositing: str = "auto"
    # the schedule the last frame used ("direct" or "tree"; None before one)
    frame_compositing: str | None = None

    def __init__(
        self, client: Any, workers: int, timeout: float, connect_timeout: float = CONNECT_TIMEOUT
    ) -> None:
        for name, v in (("timeout", timeout), ("connect_timeout", connect_timeout)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
                raise ValueError(f"{name}: expected a positive number of seconds, got {v!r}")
        d = _distributed()
        self.timeout = float(timeout)
        self.connect_timeout = float(connect_timeout)
        self._cluster = None
        self._own_client = False
        self._closed = False
        # this process's variables that Dask's nanny sets when it spawns (or
        # restarts) a worker: put back after each frame and at close
        self._environ = environ_snapshot()
        self._handles: list = []
        self._arrays: list = []
        self._tokens: list = []
        self.client: Any = None
        if client is None:
            self._cluster = start_cluster(check_local_workers(workers), close_timeout=self._close_timeout)
            try:
                client = d.Client(self._cluster, timeout=self.connect_timeout)
                client.register_plugin(_quiet_workers())
            except BaseException:
                self._close_cluster()
                raise
            self._own_client = True
        elif isinstance(client, str):
            address = client
            _probe(address, self.connect_timeout)
            client = _connect(address, self.connect_timeout)
            self._own_client = True
            try:
                _await_a_worker(client, address, self.connect_timeout)
            except BaseException:
                with _quiet_logs(), contextlib.suppress(Exception):
                    client.close(timeout=self._close_timeout)
                raise
        elif not isinstance(client, d.Client):
            raise TypeError(f"client: expected a dask.distributed.Client, an address or None, got {client!r}")
        self.client = client

    # -- what the workers hold
    def hold(self, handles: Sequence[Any], arrays: Sequence[Any], tokens: Sequence[str]) -> None:
        """The handles (futures) frames render, their data futures, and the
        tokens close() lets go of on every worker."""
        self._handles, self._arrays, self._tokens = list(handles), list(arrays), list(tokens)

    @property
    def closed(self) -> bool:
        return self._closed

    def _check_open(self) -> None:
        if self._closed:
            raise ClusterError(f"{type(self).__name__}: closed; make a new one to render again")

    def _recover(self) -> None:
        """Make again what a lost worker took along and Dask cannot recompute
        (here: nothing; files and dask arrays have their lineage)."""

    def _lost_parts(self) -> str:
        """What of this object's data is lost now and which worker held it
        ("" when it cannot say): for the error of a frame not recovered."""
        return ""

    # -- bounded waits
    def _gather(
        self, futures: Sequence[Any], what: str, where: dict | None = None, names: Sequence[str] | None = None
    ) -> list:
        """The results of `futures`, waited for at most self.timeout: a
        ClusterTimeout naming `what` and the workers of the unfinished
        (`where`: future key → worker); a task's own error as it is (the first
        in order); futures cancelled because their data was lost: ClusterError
        (_Lost); tasks Dask keeps for workers that are gone (_stalled):
        _Stalled; a task whose workers all died running it (Dask's
        KilledWorker): ClusterError naming it (`names[i]`: what future i is)."""
        d = _distributed()
        futures = list(futures)
        deadline = time.monotonic() + self.timeout
        while True:
            left = deadline - time.monotonic()
            try:
                d.wait(futures, timeout=max(min(left, STALL_CHECK), 0.001), return_when="ALL_COMPLETED")
                break
            except TimeoutError:
                if time.monotonic() >= deadline:
                    self._timed_out(futures, what, where)
                stuck = self._stalled(
                    futures, min(self._close_timeout, max(deadline - time.monotonic(), 0.1))
                )
                if stuck:
                    raise _Stalled(
                        f"{what}: {len(stuck)} of {len(futures)} tasks left waiting for workers now gone",
                        stuck,
                    ) from None
            except d.CancelledError:
                break  # the statuses below say which
        for i, f in enumerate(futures):  # the first failure in the partitions' order, whichever failed first
            if f.status == "error":
                try:
                    f.result(timeout=max(deadline - time.monotonic(), 1.0))
                except d.KilledWorker as e:
                    raise self._killed(what, names[i] if names else None, e) from None
        lost = [f for f in futures if f.status != "finished"]
        if lost:
            raise _Lost(f"{what}: {len(lost)} of {len(futures)} tasks cancelled (data lost with a worker)")
        out = []
        for f in futures:
            try:
                out.append(f.result(timeout=max(deadline - time.monotonic(), 0.001)))
            except TimeoutError:
                self._timed_out(futures, what, where)
            except d.CancelledError as e:
                raise _Lost(f"{what}: cancelled ({e})") from None
        return out

    def _stalled(self, futures: Sequence[Any], wait: float) -> list[int]:
        """The indices of `futures` whose tasks wait in Dask's no-worker
        state while a worker runs (asking the scheduler, `wait` seconds at
        most each time): pinned (``workers=``, loose) to workers that are
        gone when none ran, Dask never gives them to a worker that joins
        later (dask.distributed 2026.8), so they would wait out the whole
        timeout."""
        pending = [i for i, f in enumerate(futures) if f.status in ("pending", "lost")]
        if not pending:
            return []
        try:
            states = self._sync(
                "the scheduler's task states",
                self.client.scheduler.get_task_status,
                keys=[futures[i].key for i in pending],
                timeout=wait,
            )
            stuck = [i for i in pending if states.get(futures[i].key) == "no-worker"]
            if not stuck:
                return []
            workers = connected_workers(self.client, wait).values()
        except ClusterError:
            return []  # a scheduler that does not answer: the wait's own bound says so, in time
        running = any(info.get("status", "running") == "running" for info in workers)
        return stuck if running else []  # none running (paused, starting): they wait for one, bounded

    def _gather_built(
        self, handles: list, what: str, resubmit: Callable[[int], Any], names: Sequence[str] | None = None
    ) -> list:
        """The results of build tasks (`handles`, futures replaced in place
        when submitted again), as _gather gives them; a build that Dask left
        waiting for workers that are gone (its pin: the worker it was meant
        for died while no other ran) is submitted again by ``resubmit(i)``
        (FRAME_RETRIES times at most). Built, the handles lose their pins, so
        that a handle lost with its worker is made again on any worker (Dask
        recomputes it from its lineage; pinned to a worker that is gone, it
        would never run again when no other worker ran at the loss)."""
        for attempt in range(FRAME_RETRIES + 1):
            try:
                out = self._gather(handles, what, names=names)
                break
            except _Stalled as e:
                if attempt == FRAME_RETRIES:
                    raise ClusterError(f"{e}; still so after {FRAME_RETRIES} new submissions") from None
                for i in e.indices:
                    handles[i].cancel()
                    handles[i] = resubmit(i)
        with contextlib.suppress(ClusterError, KeyError):
            self._sync(
                "the scheduler's restrictions",
                self.client.scheduler.set_restrictions,
                worker={h.key: None for h in handles},
            )
        return out

    def _killed(self, what: str, name: str | None, e: BaseException) -> ClusterError:
        """The ClusterError of a task whose workers all died running it (a
        worker past 95 % of its memory limit is restarted by its nanny)."""
        try:
            workers = list(connected_workers(self.client, 5.0).values())
        except ClusterError:
            workers = []
        limits = [int(m) for info in workers if (m := info.get("memory_limit"))]
        limit = f"; their memory limit: {max(limits) / 2**20:,.0f} MiB" if limits else ""
        tries = getattr(e, "allowed_failures", None)
        times = f"{tries + 1} times" if isinstance(tries, int) else "each time"
        return ClusterError(
            f"{what}: {name + ': ' if name else ''}the worker running it died, {times} (out of memory? "
            f"a worker is restarted past 95 % of its memory limit{limit})"
        )

    def _timed_out(self, futures: Sequence[Any], what: str, where: dict | None) -> None:
        left = [f for f in futures if f.status not in ("finished", "error", "cancelled")]
        workers = sorted({w for f in left if (w := (where or {}).get(f.key)) is not None})
        on = f" (waiting on {', '.join(workers)})" if workers else ""
        with contextlib.suppress(ClusterError):
            if not connected_workers(self.client, min(self._close_timeout, 2.0)):
                on += " (the scheduler has no workers)"
        raise ClusterTimeout(
            f"{what}: {len(left)} of {len(futures)} tasks not done within timeout={self.timeout:g} s{on}"
        ) from None

    def _sync(self, what: str, fn: Callable, *args: Any, timeout: float | None = None, **kw: Any) -> Any:
        """fn(*args, **kw) on the client's loop, bounded (ClusterTimeout naming `what`)."""
        t = self.timeout if timeout is None else timeout
        try:
            return self.client.sync(fn, *args, callback_timeout=t, **kw)
        except TimeoutError:
            raise ClusterTimeout(f"{what}: no answer within {t:g} s") from None

    def _who_has(self, futures: Sequence[Any]) -> dict:
        """future key → the address of one worker holding it (None: nowhere yet)."""
        keys = list({f.key for f in futures})
        has = self._sync("the scheduler's who_has", self.client.scheduler.who_has, keys=keys)
        return {k: (sorted(v)[0] if v else None) for k, v in has.items()}

    @staticmethod
    def _pin(worker: str | None) -> dict:
        return {} if worker is None else {"workers": [worker], "allow_other_workers": True}

    def _near(self, where: dict, future: Any) -> dict:
        return self._pin(where.get(future.key))

    # -- frames
    def submit_frame(self, render_one: Callable, view: dict) -> tuple[list, dict]:
        """The futures of one frame's bands, nothing waited for, and future
        key → the worker it was meant for: render_partial(render_one, parts,
        view) once per worker over the handles that worker holds (with their
        data); then direct-send (self.compositing "direct": each worker's
        frame cut into one band of rows per worker, band j composited on
        worker j) or a binary tree of pairwise composites ("tree"); "auto"
        picks one by the number of workers (composite.schedule)."""
        client = self.client
        where = self._who_has(self._handles)
        groups: dict[str | None, list] = {}
        for i, h in enumerate(self._handles):
            groups.setdefault(where.get(h.key), []).append((h, self._arrays[i]))
        workers = list(groups)
        meant: dict = {}

        def submit(fn: Callable, *args: Any, worker: str | None = None) -> Any:
            f = client.submit(fn, *args, pure=False, **self._pin(worker))
            meant[f.key] = worker
            return f

        partials = [submit(render_partial, render_one, parts, view, worker=w) for w, parts in groups.items()]
        self.frame_compositing = _c.schedule(self.compositing, len(partials), self.direct_send_max)
        if self.frame_compositing == "tree" or len(partials) == 1:
            level = partials
            while len(level) > 1:
                nxt = [submit(composite_task, level[k], level[k + 1]) for k in range(0, len(level) - 1, 2)]
                level = nxt + ([level[-1]] if len(level) % 2 else [])
            return level, meant
        out = []
        for j, band in enumerate(_c.bands(view["height"], len(partials))):
            pieces = [submit(_c.split, p, band, j == 0, worker=workers[i]) for i, p in enumerate(partials)]
            out.append(submit(composite_task, *pieces, worker=workers[j]))
        return out, meant

    def _frame(self, render_one: Callable, view: dict) -> tuple[_c.Partial, float, dict, int]:
        """(the frame as one Partial, client seconds, worker → bytes sent,
        workers used). A frame whose tasks were cancelled because a worker
        took their data along is submitted again after :meth:`_recover`."""
        self._check_open()
        t0 = time.perf_counter()
        for attempt in range(FRAME_RETRIES + 1):
            futures, meant = self.submit_frame(render_one, view)
            try:
                final = self._gather(futures, f"frame ({len(futures)} composited bands)", meant)
                break
            except _Lost as e:
                if attempt == FRAME_RETRIES:
                    where = self._lost_parts()
                    raise ClusterError(
                        f"{e}; still lost after {FRAME_RETRIES} recoveries{'; ' + where if where else ''}"
                    ) from None
                self._recover()
            finally:  # a worker restarted meanwhile: its nanny set its variables here again
                restore_environ(self._environ)
        frame = time.perf_counter() - t0
        whole = _c.assemble(final, (view["height"], view["width"]))
        sent = dict(whole.sent)
        for p in final:  # each band's last hop: to the client
            if p.worker is not None:
                sent[p.worker] = sent.get(p.worker, 0) + p.nbytes
        used = len({k.split(" ", 1)[1] for k in whole.seconds if k.startswith("render ")})
        return whole, frame, sent, used

    # -- letting go
    def _run_on_workers(self, fn: Any, *args: Any) -> None:
        """fn(*args) on every worker while the client runs, bounded by the
        smaller of timeout and connect_timeout (closing: letting go of this
        object's state there); a worker gone took its state with it, one
        that does not answer keeps it until its process ends."""
        if self.client is not None and self.client.status == "running":
            with contextlib.suppress(Exception):
                self.client.run(fn, *args, on_error="ignore", callback_timeout=self._close_timeout)

    @property
    def _close_timeout(self) -> float:
        return min(self.timeout, self.connect_timeout)

    def _close_cluster(self) -> None:
        if self._cluster is not None:
            cluster, self._cluster = self._cluster, None
            with _quiet_logs(), contextlib.suppress(Exception):
                cluster.close(timeout=self._close_timeout)

    def close(self) -> None:
        """Let go of the handles and of what the workers hold for them; close
        the client and cluster started here. Every step is bounded; closing
        twice is harmless."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._tokens:
                self._run_on_workers(forget, self._tokens)
        finally:
            self._handles, self._arrays, self._tokens = [], [], []
            if self._own_client and self.client is not None:
                with _quiet_logs(), contextlib.suppress(Exception):
                    self.client.close(timeout=self._close_timeout)
            self._close_cluster()
            restore_environ(self._environ)

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Lost(ClusterError):
    """Futures cancelled: their inputs were lost with a worker (a frame
    tries again after _recover)."""


class _Stalled(_Lost):
    """Futures whose tasks Dask keeps for workers that are gone (see
    ClusterOwner._stalled); `indices`: which of those gathered."""

    def __init__(self, message: str, indices: list[int]) -> None:
        super().__init__(message)
        self.indices = indices


@contextlib.contextmanager
def _quiet_logs() -> Iterator[None]:
    """distributed's own warnings while a cluster is stopped on purpose
    (workers that went away, comms closed) say nothing the caller needs."""
    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)
