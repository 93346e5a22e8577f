"""Timings from OpenCL event profiling (clvis's queues enable it)."""

from __future__ import annotations

import pyopencl as cl


def marker(queue: cl.CommandQueue) -> cl.Event:
    """An event that completes when everything enqueued before it has: with
    the event of a later command, :func:`seconds` of the commands between."""
    return cl.enqueue_marker(queue)


def seconds(first: cl.Event | None, last: cl.Event | None = None, *, wait: bool = True) -> float | None:
    """Device seconds from the start of `first` to the end of `last` (default:
    `first` alone), from OpenCL event profiling (clvis's queues enable it).
    wait=False: None instead of waiting for `last` to complete. None too when
    an event is missing or its queue was made without profiling."""
    last = first if last is None else last
    if first is None or last is None:
        return None
    if not wait and last.command_execution_status != cl.command_execution_status.COMPLETE:
        return None
    try:
        last.wait()
        return max(0, last.profile.end - first.profile.start) * 1e-9
    except cl.Error:  # PROFILING_INFO_NOT_AVAILABLE: a queue of the caller's without profiling
        return None
