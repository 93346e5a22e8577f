"""Fixtures: every OpenCL device found, and both tuning profiles.

- ``device``: each device of each platform (PoCL always; Intel's CPU runtime
  when the test command exposes it).
- ``queue``: each (device, tuning profile) pair. The "gpu" profile's wide
  work-groups and local-memory tiles run on CPU devices too, so the GPU code
  paths are checked here even without a GPU.

CLVIS_REQUIRE_PLATFORMS (e.g. "portable,intel", set by the test command) makes
test_required_platforms fail when a named platform is missing, so a driver
that silently stops loading cannot shrink the matrix unnoticed.
"""

import contextlib
import contextvars
import dataclasses
import os
import threading

import hypothesis
import pytest

from clvis import runtime

hypothesis.settings.register_profile(
    "clvis",
    deadline=None,
    max_examples=int(os.environ.get("CLVIS_HYPOTHESIS_EXAMPLES", "40")),
    suppress_health_check=[hypothesis.HealthCheck.too_slow],
)
hypothesis.settings.load_profile("clvis")

DEVICES = runtime.devices()


def _id(device):
    return runtime.device_slug(device)


@pytest.fixture(scope="session", params=DEVICES, ids=[_id(d) for d in DEVICES])
def device(request):
    return request.param


@pytest.fixture(scope="session", params=["cpu", "gpu"])
def profile(request):
    return request.param


@pytest.fixture
def queue(device, profile):
    """The device's clvis queue, with the tuning profile in force for the test."""
    with runtime.configure(tuning=profile):
        yield runtime.queue_for(device)


@pytest.fixture
def options_flipping():
    """A context manager: while it is open, another thread keeps changing the
    process's options (int64_atomics and tuning, every half millisecond).
    Yields a one-element list counting the changes; restores the options."""
    # the process's options, outside any configure() block of this test (a
    # fresh context has none): what the flipping thread changes
    saved = contextvars.Context().run(runtime.options)
    stop = threading.Event()
    flips = [0]

    def flip():
        while not stop.is_set():
            i = flips[0]
            runtime.set_options(int64_atomics=bool(i % 2), tuning=("gpu", "cpu")[i % 2])
            flips[0] = i + 1
            stop.wait(0.0005)

    @contextlib.contextmanager
    def flipping():
        t = threading.Thread(target=flip, daemon=True)
        t.start()
        try:
            yield flips
        finally:
            stop.set()
            t.join()
            contextvars.Context().run(runtime.set_options, **dataclasses.asdict(saved))

    yield flipping
    contextvars.Context().run(runtime.set_options, **dataclasses.asdict(saved))


@pytest.fixture(autouse=True)
def _release_large(request):
    """After a 2^27-element test, give pooled device buffers back (on CPU
    devices they are host memory, and each device keeps its own pool)."""
    yield
    if request.node.get_closest_marker("large"):
        import gc

        gc.collect()
        runtime.free_pools()


def pytest_report_header(config):
    lines = ["clvis devices:"]
    lines += [f"  {i}: {runtime.describe(d)}" for i, d in enumerate(DEVICES)] or ["  none"]
    return lines
