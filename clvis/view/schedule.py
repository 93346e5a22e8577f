"""Latest-wins scheduling: the viewer's render worker and each socket's outbox.

Interaction must never lag behind the mouse, so nothing waits in a queue:

- :class:`LatestWins` runs jobs on one worker thread, the newest of each key
  (the server's key is a page's view). A job submitted while another of its
  key waits replaces it (the waiting one is dropped, never run); a job of
  that key already running sees its ``superseded()`` turn true and stops at
  its next check (a progressive render checks between passes). A job that
  returns an iterator (a generator of frames) is stepped one item at a time,
  the keys taking turns: one page's progressive render does not hold
  another's frames back for more than one pass.
- :class:`Outbox` sends frames one at a time; a frame offered while one is
  being sent replaces the frame waiting behind it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable, Iterator
from typing import Any

__all__ = ["Job", "LatestWins", "Outbox"]

# a job: called on the worker thread with superseded(), true once a newer job
# of its key came; it returns None, or an iterator the worker steps through
Job = Callable[[Callable[[], bool]], Any]


class _Task:
    __slots__ = ("gen", "job", "steps")

    def __init__(self, gen: int, job: Job) -> None:
        self.gen, self.job = gen, job
        self.steps: Iterator[Any] | None = None  # the job's iterator once it started


class LatestWins:
    """One worker thread running the newest job submitted for each key.

    ``submit(job, key)`` returns the job's generation. ``dropped`` counts jobs
    replaced before they started; ``errors`` holds what jobs raised (the
    worker goes on), and ``on_error`` is called with each. ``cancel(key)``
    drops a key's job (its page went away).
    """

    def __init__(
        self, name: str = "clvis-view-render", on_error: Callable[[BaseException], None] | None = None
    ):
        self._cond = threading.Condition()
        # the keys with a job to start or to step on, in the order of their turns
        self._ready: dict[Hashable, _Task] = {}
        self._latest: dict[Hashable, int] = {}  # each key's newest job (while it waits or runs)
        self._closing: list[Iterator[Any]] = []  # superseded jobs' iterators, closed on the worker
        self._generation = 0
        self._running = False
        self._closed = False
        self.dropped = 0
        self.errors: list[BaseException] = []
        self.on_error = on_error
        self.thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self.thread.start()

    @property
    def generation(self) -> int:
        return self._generation

    def submit(self, job: Job, key: Hashable = None) -> int:
        with self._cond:
            if self._closed:
                raise RuntimeError("the render worker is closed")
            self._generation += 1
            old = self._ready.get(key)
            if old is not None:
                if old.steps is None:
                    self.dropped += 1
                else:
                    self._closing.append(old.steps)
            self._ready[key] = _Task(self._generation, job)  # a replaced job's turn kept
            self._latest[key] = self._generation
            self._cond.notify_all()
            return self._generation

    def cancel(self, key: Hashable) -> None:
        """Drop `key`'s job: a waiting one never runs, a running one sees
        ``superseded()`` and its iterator is closed (on the worker thread)."""
        with self._cond:
            self._latest.pop(key, None)
            old = self._ready.pop(key, None)
            if old is not None and old.steps is not None:
                self._closing.append(old.steps)
            self._cond.notify_all()

    def _loop(self) -> None:
        while True:
            with self._cond:
                while not self._ready and not self._closing and not self._closed:
                    self._cond.wait()
                closing, self._closing = self._closing, []
                task = key = None
                if self._closed:
                    closing += [t.steps for t in self._ready.values() if t.steps is not None]
                    self._ready.clear()
                elif self._ready:
                    key = next(iter(self._ready))
                    task = self._ready.pop(key)
                    self._running = True
            for steps in closing:
                self._close(steps)
            if task is None:
                if self._closed:
                    return
                continue
            more = False
            try:
                if task.steps is None:

                    def stale(key: Hashable = key, gen: int = task.gen) -> bool:
                        return self._latest.get(key) != gen or self._closed

                    result = task.job(stale)
                    if isinstance(result, Iterator):
                        task.steps = result
                if task.steps is not None:
                    next(task.steps)
                    more = True
            except StopIteration:
                pass
            except BaseException as e:  # noqa: BLE001  (reported; the worker must survive a bad frame)
                self._failed(e)
            finally:
                leftover = None
                with self._cond:
                    self._running = False
                    current = self._latest.get(key) == task.gen and not self._closed
                    if more and current:
                        self._ready[key] = task  # at the end: the other keys' jobs take their turn
                    else:
                        leftover = task.steps if more else None
                        if current:
                            del self._latest[key]
                    self._cond.notify_all()
                if leftover is not None:
                    self._close(leftover)

    def _failed(self, e: BaseException) -> None:
        self.errors.append(e)
        if self.on_error is not None:
            self.on_error(e)

    def _close(self, steps: Iterator[Any]) -> None:
        """A superseded job's iterator: closed, so that what it holds (a render's buffers) goes."""
        close = getattr(steps, "close", None)
        if close is not None:
            try:
                close()
            except BaseException as e:  # noqa: BLE001
                self._failed(e)

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Block until no job runs or waits; False on timeout."""
        with self._cond:
            return self._cond.wait_for(
                lambda: not self._ready and not self._running and not self._closing, timeout
            )

    def close(self, timeout: float | None = 5.0) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        if threading.current_thread() is not self.thread:
            self.thread.join(timeout)


class Outbox:
    """Frames to one receiver, one in flight at a time, latest wins.

    ``send(item)`` starts sending and must lead to one ``done()`` call when
    the receiver has it (both on the same thread, e.g. the event loop's).
    """

    def __init__(self, send: Callable[[Any], None]):
        self._send = send
        self._busy = False
        self._next: Any = None
        self.dropped = 0
        self.sent = 0

    def put(self, item: Any) -> None:
        if self._busy:
            if self._next is not None:
                self.dropped += 1
            self._next = item
            return
        self._busy = True
        self.sent += 1
        self._send(item)

    def done(self) -> None:
        if self._next is None:
            self._busy = False
            return
        item, self._next = self._next, None
        self.sent += 1
        self._send(item)
