"""Latest-wins scheduling: the viewer's render worker and each socket's outbox.

Interaction must never lag behind the mouse, so nothing waits in a queue:

- :class:`LatestWins` runs jobs on one worker thread. A job submitted while
  another waits replaces it (the waiting one is dropped, never run); a job
  already running sees its ``superseded()`` turn true and stops at its next
  check (a progressive render checks between passes).
- :class:`Outbox` sends frames one at a time; a frame offered while one is
  being sent replaces the frame waiting behind it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

__all__ = ["Job", "LatestWins", "Outbox"]

# a job: called on the worker thread with superseded(), true once a newer job came
Job = Callable[[Callable[[], bool]], None]


class LatestWins:
    """One worker thread running the newest job submitted.

    ``submit(job)`` returns the job's generation. ``dropped`` counts jobs
    replaced before they started; ``errors`` holds what jobs raised (the
    worker goes on), and ``on_error`` is called with each.
    """

    def __init__(
        self, name: str = "clvis-view-render", on_error: Callable[[BaseException], None] | None = None
    ):
        self._cond = threading.Condition()
        self._pending: tuple[int, Job] | None = None
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

    def submit(self, job: Job) -> int:
        with self._cond:
            if self._closed:
                raise RuntimeError("the render worker is closed")
            if self._pending is not None:
                self.dropped += 1
            self._generation += 1
            self._pending = (self._generation, job)
            self._cond.notify_all()
            return self._generation

    def _loop(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                assert self._pending is not None
                gen, job = self._pending
                self._pending = None
                self._running = True
            try:

                def stale(gen: int = gen) -> bool:
                    return self._generation != gen or self._closed

                job(stale)
            except BaseException as e:  # noqa: BLE001  (reported; the worker must survive a bad frame)
                self.errors.append(e)
                if self.on_error is not None:
                    self.on_error(e)
            finally:
                with self._cond:
                    self._running = False
                    self._cond.notify_all()

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Block until no job runs or waits; False on timeout."""
        with self._cond:
            return self._cond.wait_for(lambda: self._pending is None and not self._running, timeout)

    def close(self, timeout: float | None = 5.0) -> None:
        with self._cond:
            self._closed = True
            self._pending = None
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
