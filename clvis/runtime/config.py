"""Options captured per renderer (:func:`capture`) and run under, per thread
(:func:`pinned`), whatever :func:`~clvis.runtime.configure` does meanwhile."""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Iterator

import pyopencl as cl

from .device import _as_device, _device_type, _native_capabilities
from .settings import Options, _in_force, _pins


@dataclasses.dataclass(frozen=True)
class LaunchConfig:
    """What a renderer runs with, fixed when it is made (:func:`capture`):
    the options then in force, and what they mean on its device (the tuning
    profile, whether kernels are built with 64-bit atomics). Later
    :func:`configure`/:func:`set_options` calls, in this thread or another,
    apply to renderers made after them."""

    options: Options
    tuning: str
    int64_atomics: bool


def capture(queue: cl.CommandQueue) -> LaunchConfig:
    """The options in force (in this thread, see :func:`pinned`) for `queue`'s device."""
    o = _in_force()
    device = _as_device(queue)
    native = _native_capabilities(device)
    tuning = o.tuning or ("gpu" if _device_type(device) in ("GPU", "ACCELERATOR") else "cpu")
    return LaunchConfig(dataclasses.replace(o), tuning, bool(native.int64_atomics_native and o.int64_atomics))


@contextlib.contextmanager
def pinned(config: LaunchConfig) -> Iterator[LaunchConfig]:
    """Run the block (in this thread only) under `config`'s options, whatever
    configure() does meanwhile: capabilities(), tuning_profile() and
    get_kernel() (through build_options) follow it, so a renderer, and the
    primitives it calls, never mixes kernels and buffers of two settings."""
    saved = getattr(_pins, "config", None)
    _pins.config = config
    try:
        yield config
    finally:
        _pins.config = saved
