"""Device choice, capabilities, program cache, allocation and launch helpers.

Device choice (first that applies):

1. ``CLVIS_DEVICE``: an index into :func:`devices` (as ``clvis info`` numbers
   them) or a case-insensitive substring of "platform name device name";
2. ``PYOPENCL_CTX``, with pyopencl's own meaning;
3. the first GPU;
4. PoCL's CPU device;
5. any device.

Programs are built from ``kernels_cl/<family>/<file>.cl`` with
``-I kernels_cl/include`` and ``-D`` defines only, and cached in the process
per (context, file, options). On disk, builds are cached where the driver
allows, through pyopencl's policy: drivers that cache compiled kernels
themselves (PoCL's kcache, NVIDIA's compute cache) are left to it, and for the
others (Intel's CPU runtime, ...) pyopencl keeps program binaries keyed by the
source, every included header and the options. (clvis once exported binaries
itself: on PoCL that compiles every kernel of a program up front, ~6 s a
program, more than any cache hit saves.)

Options (:func:`configure`, or the environment at import). Strings are
accepted as the environment gives them (``max_alloc_bytes="5"``); a value
clvis cannot use raises ValueError from :func:`configure`/:func:`set_options`,
while a bad environment variable is ignored with a
:class:`~clvis.errors.ClvisWarning` naming it and the values it accepts, and
the default applies: importing clvis (and ``clvis info``) never fails because
of the environment.

- ``tuning``: ``None`` (by device type), ``"cpu"`` or ``"gpu"``: which set of
  ``-D`` work shapes the families build with (``CLVIS_TUNING``). Both give the
  same results; tests run both on every device.
- ``int64_atomics``: ``False`` builds every kernel as if the device lacked
  ``cl_khr_int64_base_atomics``/``cl_khr_int64_extended_atomics``, so fallback
  paths can be tested on devices that have them (``CLVIS_NO_INT64_ATOMICS=1``).
- ``max_alloc_bytes``: a cap on one allocation, below the device's own limit,
  to emulate a smaller device (``CLVIS_MAX_ALLOC``).

A renderer captures the options once (:func:`capture`) and runs under them
(:func:`pinned`, per thread), so changing them applies to the next renderer.
The launch layer (:func:`local_size`, :func:`items`, :func:`fill`,
:func:`arg`, :data:`EXACT_FP`, :func:`seconds`) is what every family sizes,
fills and times its launches with.

One module per concern; this package re-exports every public name:

- :mod:`~clvis.runtime.settings`: the options and where they come from;
- :mod:`~clvis.runtime.device`: device choice, queues, capabilities;
- :mod:`~clvis.runtime.program`: kernel sources, compiler options, the build
  and the program/kernel cache;
- :mod:`~clvis.runtime.memory`: pools, allocation and memory checks;
- :mod:`~clvis.runtime.dispatch`: the launch layer;
- :mod:`~clvis.runtime.config`: options captured per renderer and pinned;
- :mod:`~clvis.runtime.timing`: timings from event profiling.
"""

from __future__ import annotations

from .config import LaunchConfig, capture, pinned
from .device import (
    Capabilities,
    capabilities,
    default_queue,
    describe,
    device_slug,
    devices,
    queue_for,
    select_device,
    set_default_device,
    tuning_profile,
)
from .dispatch import EXACT_FP, arg, fill, items, launch, local_size, nbytes
from .memory import (
    allocator,
    check_alloc,
    check_memory,
    empty,
    fill_zero,
    free_held,
    free_pools,
    host_available_bytes,
    zeros,
)
from .program import INCLUDE_DIR, KERNEL_ROOT, build_options, get_kernel, get_program
from .settings import Options, configure, options, set_options
from .timing import marker, seconds

__all__ = [
    "EXACT_FP",
    "INCLUDE_DIR",
    "KERNEL_ROOT",
    "Capabilities",
    "LaunchConfig",
    "Options",
    "allocator",
    "arg",
    "build_options",
    "capabilities",
    "capture",
    "check_alloc",
    "check_memory",
    "configure",
    "default_queue",
    "describe",
    "device_slug",
    "devices",
    "empty",
    "fill",
    "fill_zero",
    "free_held",
    "free_pools",
    "get_kernel",
    "get_program",
    "host_available_bytes",
    "items",
    "launch",
    "local_size",
    "marker",
    "nbytes",
    "options",
    "pinned",
    "queue_for",
    "seconds",
    "select_device",
    "set_default_device",
    "set_options",
    "tuning_profile",
    "zeros",
]
