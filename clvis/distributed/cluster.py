"""The Dask side shared by the distributed renderers: the client (given, or a
``LocalCluster`` of one-thread worker processes started and owned here),
waits that always have a timeout, where futures live, and the tasks and
errors common to points and volumes.

No scheduling of our own: tasks go to Dask with a loose wish for the worker
that holds their inputs (``allow_other_workers``), so a lost worker's tasks
run elsewhere.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from ..errors import DeviceError
from . import composite as _c

__all__ = [
    "ClusterOwner",
    "composite_task",
    "current_worker",
    "device_error",
    "frame_seconds",
    "start_cluster",
]


def _distributed():
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


def device_error(e: BaseException) -> DeviceError:
    """A DeviceError naming this worker and what its OpenCL said."""
    w = current_worker() or "the client"
    return DeviceError(f"worker {w}: no usable OpenCL device ({type(e).__name__}: {e})")


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


def start_cluster(workers: int, **kw: Any) -> Any:
    """A LocalCluster of `workers` processes, one thread each, the dashboard on a free port."""
    d = _distributed()
    kw.setdefault("processes", True)
    return d.LocalCluster(n_workers=workers, threads_per_worker=1, dashboard_address=":0", **kw)


class ClusterOwner:
    """Holds a Dask client; starts (and closes) a LocalCluster when given none."""

    def __init__(self, client: Any, workers: int, timeout: float) -> None:
        d = _distributed()
        self.timeout = float(timeout)
        self._cluster = None
        self._own_client = False
        if client is None:
            if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
                raise ValueError(f"workers: expected a positive int, got {workers!r}")
            self._cluster = start_cluster(workers)
            client = d.Client(self._cluster, timeout=self.timeout)
            self._own_client = True
        elif isinstance(client, str):
            client = d.Client(client, timeout=self.timeout)
            self._own_client = True
        elif not isinstance(client, d.Client):
            raise TypeError(f"client: expected a dask.distributed.Client, an address or None, got {client!r}")
        self.client = client

    def _gather(self, futures: Sequence[Any]) -> list:
        d = _distributed()
        futures = list(futures)
        d.wait(futures, timeout=self.timeout, return_when="ALL_COMPLETED")
        for f in futures:  # the first failure in the partitions' order, whichever failed first
            if f.status == "error":
                f.result(timeout=self.timeout)
        return self.client.gather(futures)

    def _who_has(self, futures: Sequence[Any]) -> dict:
        """future key → the address of one worker holding it (None: nowhere yet)."""
        has = self.client.who_has(list(futures))
        return {k: (sorted(v)[0] if v else None) for k, v in has.items()}

    @staticmethod
    def _pin(worker: str | None) -> dict:
        return {} if worker is None else {"workers": [worker], "allow_other_workers": True}

    def _near(self, where: dict, future: Any) -> dict:
        return self._pin(where.get(future.key))

    def submit_frame(self, task: Any, view: dict) -> list:
        """The futures of one frame's bands, nothing waited for: `task`
        (parts, view) → a full-frame Partial runs once per worker over the
        partitions that worker holds (self._handles, with self._arrays);
        then direct-send (self.compositing "direct": each worker's frame cut
        into one band of rows per worker, band j composited on worker j) or
        a binary tree of pairwise composites ("tree")."""
        client = self.client
        where = self._who_has(self._handles)
        groups: dict[str | None, list] = {}
        for i, h in enumerate(self._handles):
            groups.setdefault(where.get(h.key), []).append((h, self._arrays[i]))
        workers = list(groups)
        partials = [
            client.submit(task, parts, view, pure=False, **self._pin(w)) for w, parts in groups.items()
        ]
        if self.compositing == "tree" or len(partials) == 1:
            level = partials
            while len(level) > 1:
                nxt = [
                    client.submit(composite_task, level[k], level[k + 1], pure=False)
                    for k in range(0, len(level) - 1, 2)
                ]
                level = nxt + ([level[-1]] if len(level) % 2 else [])
            return level
        out = []
        for j, band in enumerate(_c.bands(view["height"], len(partials))):
            pieces = [
                client.submit(_c.split, p, band, j == 0, pure=False, **self._pin(workers[i]))
                for i, p in enumerate(partials)
            ]
            out.append(client.submit(composite_task, *pieces, pure=False, **self._pin(workers[j])))
        return out

    def _frame(self, task: Any, view: dict) -> tuple[_c.Partial, float, dict, int]:
        """(the frame as one Partial, client seconds, worker → bytes sent, workers used)."""
        t0 = time.perf_counter()
        final = self._gather(self.submit_frame(task, view))
        frame = time.perf_counter() - t0
        whole = _c.assemble(final)
        sent = dict(whole.sent)
        for p in final:  # each band's last hop: to the client
            if p.worker is not None:
                sent[p.worker] = sent.get(p.worker, 0) + p.nbytes
        used = len({k.split(" ", 1)[1] for k in whole.seconds if k.startswith("render ")})
        return whole, frame, sent, used

    def _run_on_workers(self, fn: Any, *args: Any) -> None:
        """fn(*args) on every worker while the client runs (closing: letting
        go of this object's state there); a worker gone took its state with it."""
        if self.client is not None and self.client.status == "running":
            try:
                self.client.run(fn, *args)
            except Exception:
                pass

    def close(self) -> None:
        """Drop the partitions; close the client and cluster started here."""
        for name in ("_handles", "_arrays"):
            if hasattr(self, name):
                setattr(self, name, [])
        if self._own_client and self.client is not None:
            self.client.close()
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def __enter__(self) -> Any:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
