"""Device choice (the rules are in :mod:`clvis.runtime`'s docstring), the
queue and per-context state clvis keeps for each device, and what a device
offers under the options in force (:class:`Capabilities`)."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
import re
import signal
import threading
from collections.abc import Callable, Iterator, Sequence

import pyopencl as cl

from ..errors import DeviceError
from .settings import _in_force

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@functools.cache
def _raw_sigaction() -> Callable[[int, bytes | None], bytes] | None:
    """sigaction(sig, new) -> the old action's raw bytes, through libc
    (glibc's struct sigaction on Linux x86-64 and aarch64: handler, mask,
    flags, restorer), or None elsewhere. Looked up once a process."""
    import ctypes
    import platform
    import sys

    if not sys.platform.startswith("linux") or platform.machine() not in ("x86_64", "aarch64"):
        return None
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        call = libc.sigaction
    except (OSError, AttributeError):
        return None
    size = 8 + 128 + 8 + 8  # handler, sigset_t (1024 bits), flags (padded), restorer

    def action(sig: int, new: bytes | None) -> bytes:
        old = ctypes.create_string_buffer(size)
        buf = None if new is None else ctypes.create_string_buffer(new, size)
        if call(int(sig), buf, old) != 0:
            raise OSError(ctypes.get_errno(), "sigaction")
        return old.raw

    return action


@contextlib.contextmanager
def _python_signal_handlers() -> Iterator[None]:
    """SIGINT's and SIGTERM's handlers as they were before the block.

    OpenCL runtimes put their own handlers in front of Python's, below
    Python's view of them (``signal.getsignal`` still names Python's): PoCL
    when the ICD loader loads it (platform enumeration), Intel's CPU runtime
    at its first context. Both are one-shot (SA_RESETHAND, SA_NODEFER): the
    first signal resets the action to the default before their handler
    passes it on to Python's, so a second one in that moment (``timeout``
    signals the process and then its group; a double Ctrl-C) ended the
    process by the default action, silently, in the middle of writing a
    file. On Linux the actions the block changed are put back byte for byte
    (libc's sigaction: a handler Python does not know of, faulthandler's or
    an embedding application's, stays); elsewhere Python's own handlers are
    installed again where they are Python functions or SIG_IGN. Main thread
    only (elsewhere Python cannot set a handler, and another thread's
    changes could be undone)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    raw = _raw_sigaction()
    if raw is not None:
        try:
            before = {s: raw(s, None) for s in _SIGNALS}
        except OSError:
            raw = None
    if raw is None:
        python = {s: signal.getsignal(s) for s in _SIGNALS}
    try:
        yield
    finally:
        # a signal raised inside the restore (a pending KeyboardInterrupt)
        # must not leave the other signal's action unrestored: each is tried
        # twice, the first exception raised once both are done
        pending: BaseException | None = None
        for s in _SIGNALS:
            for _ in range(2):
                try:
                    if raw is not None:
                        if raw(s, None) != before[s]:
                            raw(s, before[s])
                    elif callable(python[s]) or python[s] == signal.SIG_IGN:
                        signal.signal(s, python[s])
                    break
                except (ValueError, OSError, TypeError):
                    break
                except BaseException as e:  # noqa: BLE001 (KeyboardInterrupt, raised again below)
                    pending = pending or e
        if pending is not None:
            raise pending


def devices() -> list[cl.Device]:
    """Every OpenCL device of every platform, in platform order."""
    with _python_signal_handlers():
        try:
            platforms = cl.get_platforms()
        except cl.Error:  # no ICD at all: PLATFORM_NOT_FOUND_KHR
            return []
        out = []
        for p in platforms:
            try:
                out.extend(p.get_devices())
            except cl.Error:
                pass
    return out


def describe(device: cl.Device) -> str:
    return f"{device.platform.name.strip()} / {device.name.strip()}"


def _device_type(device: cl.Device) -> str:
    t = device.type
    if t & cl.device_type.GPU:
        return "GPU"
    if t & cl.device_type.CPU:
        return "CPU"
    if t & cl.device_type.ACCELERATOR:
        return "ACCELERATOR"
    return "OTHER"


def select_device(spec: str | int | None = None) -> cl.Device:
    """The device clvis uses by default (rules in the module docstring)."""
    found = devices()
    if spec is None:
        spec = os.environ.get("CLVIS_DEVICE") or None
    if spec is not None:
        spec_s = str(spec).strip()
        if spec_s.isdigit():
            i = int(spec_s)
            if i < len(found):
                return found[i]
            count = f"is {len(found)} device" if len(found) == 1 else f"are {len(found)} devices"
            raise DeviceError(f"CLVIS_DEVICE={spec_s}: there {count} ({_listing(found)})")
        for d in found:
            if spec_s.lower() in f"{d.platform.name} {d.name}".lower():
                return d
        raise DeviceError(f"CLVIS_DEVICE={spec_s!r} matches no device ({_listing(found)})")
    if os.environ.get("PYOPENCL_CTX"):
        try:
            with _python_signal_handlers():
                return cl.create_some_context(interactive=False).devices[0]
        except (cl.Error, RuntimeError, ValueError) as e:
            raise DeviceError(f"PYOPENCL_CTX={os.environ['PYOPENCL_CTX']!r}: {e}") from e
    if not found:
        raise DeviceError(
            "no OpenCL device found: install a driver, e.g. PoCL with "
            "pip install 'pyopencl[pocl]' (or pip install \".[pocl]\" in a clvis checkout)"
        )
    for d in found:
        if _device_type(d) == "GPU":
            return d
    for d in found:
        if "portable computing language" in d.platform.name.lower():
            return d
    return found[0]


def _listing(found: Sequence[cl.Device]) -> str:
    return "; ".join(f"{i}: {describe(d)}" for i, d in enumerate(found)) or "none"


class _ContextState:
    """What clvis keeps per OpenCL context: programs, kernels, memory pool."""

    def __init__(self, context: cl.Context):
        self.context = context
        self.programs: dict = {}
        self.kernels: dict = {}
        self.pools: dict = {}


_lock = threading.RLock()
_queues: dict[int, cl.CommandQueue] = {}
_queue_contexts: dict[int, cl.Context] = {}  # Intel's CPU runtime frees a context
# its queues still use unless we hold it
_contexts: dict[int, _ContextState] = {}
_default: cl.CommandQueue | None = None


def queue_for(device: cl.Device) -> cl.CommandQueue:
    """clvis's in-order queue (and context) for `device`, made once, with
    event profiling enabled (timings in stats come from it: :func:`seconds`)."""
    with _lock:
        q = _queues.get(device.int_ptr)
        if q is None:
            try:
                with _python_signal_handlers():
                    ctx = cl.Context([device])
                    try:
                        q = cl.CommandQueue(
                            ctx, device, properties=cl.command_queue_properties.PROFILING_ENABLE
                        )
                    except cl.Error:  # a driver without profiling: stats' timings are then None
                        q = cl.CommandQueue(ctx, device)
            except cl.Error as e:
                raise DeviceError(f"cannot open {describe(device)}: {e}") from e
            _queues[device.int_ptr] = q
            _queue_contexts[device.int_ptr] = ctx
        return q


def default_queue() -> cl.CommandQueue:
    """The queue clvis runs on when given numpy arrays and no `queue`."""
    global _default
    with _lock:
        if _default is None:
            _default = queue_for(select_device())
        return _default


def set_default_device(spec: str | int | cl.Device | None) -> cl.CommandQueue:
    """Make `spec` (a device, or as CLVIS_DEVICE) the default; returns its queue."""
    global _default
    device = spec if isinstance(spec, cl.Device) else select_device(spec)
    with _lock:
        _default = queue_for(device)
        return _default


def _state(context: cl.Context) -> _ContextState:
    with _lock:
        s = _contexts.get(context.int_ptr)
        if s is None:
            s = _contexts[context.int_ptr] = _ContextState(context)
        return s


# --------------------------------------------------------------------------
# capabilities


@dataclasses.dataclass(frozen=True)
class Capabilities:
    platform: str
    device: str
    device_type: str
    driver_version: str
    opencl_version: str
    compute_units: int
    max_work_group_size: int
    local_mem_bytes: int
    max_alloc_bytes: int  # after the max_alloc_bytes option
    global_mem_bytes: int
    int64_atomics: bool  # what kernels are built for (option applied)
    int64_atomics_native: bool  # what the device reports
    subgroups: bool
    fp64: bool


def _as_device(obj: object) -> cl.Device:
    if isinstance(obj, cl.Device):
        return obj
    if isinstance(obj, cl.CommandQueue):
        return obj.device
    if isinstance(obj, cl.Context):
        return obj.devices[0]
    raise TypeError(f"expected a pyopencl Device, CommandQueue or Context, got {type(obj).__name__}")


_caps_cache: dict[int, Capabilities] = {}


def _native_capabilities(device: cl.Device) -> Capabilities:
    """What the device reports, queried once per device."""
    caps = _caps_cache.get(device.int_ptr)
    if caps is not None:
        return caps
    ext = device.extensions.split()
    native64 = "cl_khr_int64_base_atomics" in ext and "cl_khr_int64_extended_atomics" in ext
    subgroups = "cl_khr_subgroups" in ext or "cl_intel_subgroups" in ext
    if not subgroups:
        with contextlib.suppress(Exception):
            subgroups = device.max_num_sub_groups > 0
    caps = Capabilities(
        platform=device.platform.name.strip(),
        device=device.name.strip(),
        device_type=_device_type(device),
        driver_version=device.driver_version.strip(),
        opencl_version=device.version.strip(),
        compute_units=int(device.max_compute_units),
        max_work_group_size=int(device.max_work_group_size),
        local_mem_bytes=int(device.local_mem_size),
        max_alloc_bytes=int(device.max_mem_alloc_size),
        global_mem_bytes=int(device.global_mem_size),
        int64_atomics=native64,
        int64_atomics_native=native64,
        subgroups=bool(subgroups),
        fp64="cl_khr_fp64" in ext,
    )
    _caps_cache[device.int_ptr] = caps
    return caps


def capabilities(obj: cl.Device | cl.CommandQueue | cl.Context | None = None) -> Capabilities:
    """What `obj` (a device, queue or context; default: the default queue's
    device) offers, as clvis sees it under the current options."""
    device = _as_device(obj if obj is not None else default_queue())
    caps = _native_capabilities(device)
    o = _in_force()
    if o.int64_atomics and o.max_alloc_bytes is None:
        return caps
    max_alloc = caps.max_alloc_bytes
    if o.max_alloc_bytes is not None:
        max_alloc = min(max_alloc, int(o.max_alloc_bytes))
    return dataclasses.replace(
        caps, max_alloc_bytes=max_alloc, int64_atomics=caps.int64_atomics_native and o.int64_atomics
    )


def tuning_profile(obj: cl.Device | cl.CommandQueue | cl.Context | None = None) -> str:
    """'cpu' or 'gpu': the work shapes the kernel families use on this device."""
    tuning = _in_force().tuning
    if tuning is not None:
        return tuning
    device = _as_device(obj if obj is not None else default_queue())
    return "gpu" if _device_type(device) in ("GPU", "ACCELERATOR") else "cpu"


def device_slug(obj: cl.Device | cl.CommandQueue | cl.Context | None = None) -> str:
    """A short file-name-safe name of the device, for benchmark result folders."""
    caps = capabilities(obj)
    plat = caps.platform.lower()
    if "portable computing language" in plat:
        plat = "pocl"
    elif "intel" in plat:
        plat = "intel"
    elif "nvidia" in plat:
        plat = "nvidia"
    name = re.sub(r"^(pthread|cpu)-", "", caps.device.lower())
    slug = re.sub(r"[^a-z0-9]+", "-", f"{plat} {name}").strip("-")
    return slug[:60]
