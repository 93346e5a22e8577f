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
The launch layer at the end of this module (:func:`local_size`, :func:`items`,
:func:`fill`, :func:`arg`, :data:`EXACT_FP`, :func:`seconds`) is what every
family sizes, fills and times its launches with.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import re
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pyopencl as cl
import pyopencl.array as cla
import pyopencl.tools

from .errors import ClvisError, ClvisWarning, DeviceError, KernelBuildError

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


# --------------------------------------------------------------------------
# kernel sources


def _find_kernel_root() -> Path:
    here = Path(__file__).resolve().parent
    # installed wheel: clvis/kernels_cl; source checkout: <repo>/kernels_cl
    for cand in (here / "kernels_cl", here.parent / "kernels_cl"):
        if (cand / "include" / "clvis").is_dir():
            return cand
    raise ClvisError(f"clvis's OpenCL sources (kernels_cl/) were not found beside {here}")


KERNEL_ROOT = _find_kernel_root()
INCLUDE_DIR = KERNEL_ROOT / "include"


# --------------------------------------------------------------------------
# options

_TUNINGS = ("cpu", "gpu")
_TRUE = ("1", "true", "yes", "on")
_FALSE = ("0", "false", "no", "off")


def _tuning_value(v: object) -> str | None:
    if v is None:
        return None
    if isinstance(v, str) and v.strip().lower() in _TUNINGS:
        return v.strip().lower()
    raise ValueError(f"tuning: expected None, 'cpu' or 'gpu', got {v!r}")


def _flag_value(name: str, v: object) -> bool:
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)) and v in (0, 1):
        return bool(v)
    if isinstance(v, str) and v.strip().lower() in _TRUE + _FALSE:
        return v.strip().lower() in _TRUE
    raise ValueError(
        f"{name}: expected True or False (1/0, 'true'/'false', 'yes'/'no', 'on'/'off'), got {v!r}"
    )


def _size_value(name: str, v: object) -> int | None:
    """A positive whole number of bytes; strings ("5", "2e9") as the environment gives them."""
    if v is None:
        return None
    size: object = v
    if isinstance(v, str):
        try:
            size = int(v.strip())
        except ValueError:
            with contextlib.suppress(ValueError):
                size = float(v.strip())
    if isinstance(size, (float, np.floating)) and np.isfinite(size) and float(size).is_integer():
        size = int(size)
    if isinstance(size, (bool, np.bool_)) or not isinstance(size, (int, np.integer)) or size <= 0:
        raise ValueError(f"{name}: expected a positive whole number of bytes, got {v!r}")
    return int(size)


@dataclasses.dataclass
class Options:
    """The options in force (see the module docstring). Strings are accepted as
    the environment would give them (``max_alloc_bytes="5"``,
    ``int64_atomics="false"``); a value clvis cannot use raises ValueError
    naming the option."""

    tuning: str | None = None
    int64_atomics: bool = True
    max_alloc_bytes: int | None = None

    def __post_init__(self) -> None:
        self.tuning = _tuning_value(self.tuning)
        self.int64_atomics = _flag_value("int64_atomics", self.int64_atomics)
        self.max_alloc_bytes = _size_value("max_alloc_bytes", self.max_alloc_bytes)


# environment variable -> (option, how to read it, what it accepts)
_ENV: dict[str, tuple[str, Callable[[str], object], str]] = {
    "CLVIS_TUNING": ("tuning", _tuning_value, "'cpu' or 'gpu' (unset: by device type)"),
    "CLVIS_NO_INT64_ATOMICS": (
        "int64_atomics",
        lambda s: not _flag_value("CLVIS_NO_INT64_ATOMICS", s),
        "1/true/yes/on or 0/false/no/off",
    ),
    "CLVIS_MAX_ALLOC": (
        "max_alloc_bytes",
        lambda s: _size_value("CLVIS_MAX_ALLOC", s),
        "a positive whole number of bytes",
    ),
}


def _env_options() -> Options:
    """The options the environment asks for. A value clvis cannot use is
    ignored with a ClvisWarning naming the variable and what it accepts (the
    default applies): importing clvis never fails because of the environment."""
    changes: dict[str, object] = {}
    for var, (name, parse, accepted) in _ENV.items():
        raw = os.environ.get(var, "")
        if not raw.strip():
            continue
        try:
            changes[name] = parse(raw)
        except ValueError:
            default = getattr(Options(), name)
            warnings.warn(
                f"{var}={raw!r} is ignored: expected {accepted}; using the default ({name}={default!r})",
                ClvisWarning,
                stacklevel=2,
            )
    return Options(**changes)  # type: ignore[arg-type]  # each value parsed for its field above


_options = _env_options()


def _check_options(o: Options) -> None:
    # Options checks its fields when made (dataclasses.replace makes a new one);
    # this catches fields assigned on an existing instance
    Options(o.tuning, o.int64_atomics, o.max_alloc_bytes)


def options() -> Options:
    """A copy of the options in force."""
    return dataclasses.replace(_options)


def set_options(**changes: Any) -> None:
    """Change options for the rest of the process (see the module docstring)."""
    global _options
    new = dataclasses.replace(_options, **changes)
    _check_options(new)
    _options = new


@contextlib.contextmanager
def configure(**changes: Any) -> Iterator[Options]:
    """Change options inside a ``with`` block, e.g.
    ``with clvis.runtime.configure(int64_atomics=False): ...``."""
    global _options
    saved = _options
    set_options(**changes)
    try:
        yield options()
    finally:
        _options = saved


# --------------------------------------------------------------------------
# devices


def devices() -> list[cl.Device]:
    """Every OpenCL device of every platform, in platform order."""
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
            raise DeviceError(f"CLVIS_DEVICE={spec_s}: there are {len(found)} devices ({_listing(found)})")
        for d in found:
            if spec_s.lower() in f"{d.platform.name} {d.name}".lower():
                return d
        raise DeviceError(f"CLVIS_DEVICE={spec_s!r} matches no device ({_listing(found)})")
    if os.environ.get("PYOPENCL_CTX"):
        try:
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
                ctx = cl.Context([device])
                try:
                    q = cl.CommandQueue(ctx, device, properties=cl.command_queue_properties.PROFILING_ENABLE)
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


# --------------------------------------------------------------------------
# programs

# OpenCL compiler flags a kernel file may ask for (its ABI comment says which);
# anything else would make what is built differ from what is in the file
_FLAGS = {"-cl-fp32-correctly-rounded-divide-sqrt"}


# -D values: numbers, C identifiers and expressions of them without whitespace,
# quotes or backslashes (the options reach the compiler as one space-joined string)
_DEFINE_VALUE = re.compile(r"[A-Za-z0-9_.+\-*/%()<>!&|^~]+")

# the include option when the compiler runs with INCLUDE_DIR as its working directory
_HERE = "."


def _define_value(name: str, v: object) -> str:
    if isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        if not np.isfinite(v):
            raise ValueError(f"define {name}: expected a finite number, got {v!r}")
        return repr(float(v))
    if isinstance(v, str) and _DEFINE_VALUE.fullmatch(v):
        return v
    raise ValueError(
        f"define {name}: expected a number or a C identifier/expression without "
        f"whitespace or quotes, got {v!r}"
    )


def _include_option() -> str:
    """The -I path: pyopencl joins options with spaces, and no quoting works
    everywhere (PoCL 3 passes quotes on to clang literally), so a path with
    whitespace is given relative to the working directory, or as "." with the
    compiler run from INCLUDE_DIR (see _build; the working directory is the
    process's, so other threads' relative paths see it during such a build)."""
    inc = str(INCLUDE_DIR)
    if not re.search(r"\s", inc):
        return inc
    try:
        rel = os.path.relpath(inc)
    except (ValueError, OSError):  # another drive; a working directory since deleted
        rel = inc
    return rel if not re.search(r"\s", rel) else _HERE


@contextlib.contextmanager
def _working_directory(path: Path | None) -> Iterator[None]:
    if path is None:
        yield
        return
    try:
        old: str | None = os.getcwd()
    except OSError:
        old = None
    os.chdir(path)
    try:
        yield
    finally:
        if old is not None:
            os.chdir(old)


def build_options(device: cl.Device, defines: Mapping[str, object], flags: Sequence[str] = ()) -> list[str]:
    """The compiler options clvis builds kernels_cl files with: the include
    path, `flags` (only those clvis kernels use) and `defines` as ``-D``.
    ValueError names a define whose name is not a C identifier or whose value
    is not a number or a whitespace-free C identifier/expression."""
    for f in flags:
        if f not in _FLAGS:
            raise ValueError(f"compiler flag {f!r} is not one clvis kernels use")
    opts = ["-I", _include_option(), *flags]
    for k, v in sorted(defines.items()):
        if not isinstance(k, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", k):
            raise ValueError(f"define name {k!r} is not a C identifier")
        opts.append(f"-D{k}={_define_value(k, v)}")
    if capabilities(device).int64_atomics:
        opts.append("-DCLVIS_INT64_ATOMICS=1")
    return opts


# pyopencl keeps program binaries for drivers without a cache of their own
# (Intel's CPU runtime, ...) under one lock file, held only while an entry is
# read or written. A waiter gives up after 60 s and then, unless
# PYOPENCL_CACHE_FAILURE_FATAL is set, fails with a KeyError naming that
# variable. A lock older than that was left by a process killed mid-build:
# report it at once instead of stalling a minute first.
_STALE_LOCK_S = 60.0


def _pyopencl_cache_dir(context: cl.Context) -> Path | None:
    """Where pyopencl caches binaries of builds in `context` (as pyopencl.cache
    decides), or None when it does not (PoCL and NVIDIA cache builds themselves)."""
    try:
        from pyopencl.characterize import has_src_build_cache

        if getattr(cl, "_PYOPENCL_NO_CACHE", False) or has_src_build_cache(context.devices[0]):
            return None
        base = getattr(context, "cache_dir", None)
        if base is not None:
            return Path(base)
        import platformdirs

        xdg = os.environ.get("XDG_CACHE_HOME")
        if sys.platform == "darwin" and xdg:
            root = os.path.join(xdg, "pyopencl")
        else:
            root = platformdirs.user_cache_dir("pyopencl", "pyopencl")
        version = ".".join(str(i) for i in sys.version_info)
        return Path(root) / f"pyopencl-compiler-cache-v2-py{version}"
    except Exception:  # only used to explain a failure: never the cause of one
        return None


def _cache_failure(cache: Path, error: BaseException | None) -> str:
    lock = cache / "lock"
    if lock.exists():
        return (
            f"pyopencl's compiler cache is locked by {lock}, left by a process that was killed while "
            f"building; delete that file (or set PYOPENCL_NO_CACHE=1)"
        )
    return (
        f"pyopencl's compiler cache in {cache} failed ({error!r}); delete that directory "
        f"(or set PYOPENCL_NO_CACHE=1)"
    )


def _build(context: cl.Context, path: Path, defines: Mapping[str, object], opts: list[str]) -> cl.Program:
    """Build `path` with `opts` (the options of the program cache's key, read once)."""
    device = context.devices[0]
    cache = _pyopencl_cache_dir(context)
    if cache is not None:
        with contextlib.suppress(OSError):
            if time.time() - (cache / "lock").stat().st_mtime > _STALE_LOCK_S:
                raise KernelBuildError(_display(path), defines, describe(device), _cache_failure(cache, None))
    prg = cl.Program(context, path.read_text())
    with warnings.catch_warnings(), _working_directory(INCLUDE_DIR if opts[1] == _HERE else None):
        # drivers log remarks on success (Intel: vectorisation reports);
        # pyopencl turns each into a CompilerWarning. Failures raise below.
        warnings.simplefilter("ignore", cl.CompilerWarning)
        try:
            prg.build(opts)  # the options of the cache key, read once
        except cl.Error as e:
            log = ""
            with contextlib.suppress(Exception):
                warnings.simplefilter("ignore", UserWarning)
                log = prg.get_build_info(device, cl.program_build_info.LOG)
            raise KernelBuildError(_display(path), defines, describe(device), log or str(e)) from None
        except (KeyError, RuntimeError) as e:
            # pyopencl's own cache failed (a KeyError naming PYOPENCL_CACHE_FAILURE_FATAL
            # after a minute on a stale lock, or a RuntimeError when that variable is set)
            if cache is None:
                raise
            raise KernelBuildError(_display(path), defines, describe(device), _cache_failure(cache, e)) from e
    return prg


def _display(path: Path) -> str:
    try:
        return str(path.relative_to(KERNEL_ROOT))
    except ValueError:
        return str(path)


def get_program(
    context: cl.Context, relpath: str, defines: Mapping[str, object], flags: Sequence[str] = ()
) -> cl.Program:
    """The built program kernels_cl/`relpath` (or an absolute path: a kernel
    of your own, built the same way) with `defines` and compiler `flags`, cached."""
    state = _state(context)
    device = context.devices[0]
    opts = build_options(device, defines, flags)
    key = (relpath, tuple(opts))
    with _lock:
        prg = state.programs.get(key)
        if prg is None:
            path = KERNEL_ROOT / relpath
            if not path.is_file():
                raise ClvisError(f"no kernel source {path}")
            prg = state.programs[key] = _build(context, path, defines, opts)
        return prg


def get_kernel(
    queue: cl.CommandQueue, relpath: str, name: str, defines: Mapping[str, object], flags: Sequence[str] = ()
) -> cl.Kernel:
    """Kernel `name` of kernels_cl/`relpath` built with `defines` (and compiler
    `flags`) for the queue's device."""
    prg = get_program(queue.context, relpath, defines, flags)
    state = _state(queue.context)
    key = (id(prg), name)
    with _lock:
        k = state.kernels.get(key)
        if k is None:
            try:
                k = cl.Kernel(prg, name)
            except cl.Error as e:
                # a build the driver reported as successful but without the
                # kernel: report it like a failed build, with the log
                log = ""
                with contextlib.suppress(Exception):
                    log = prg.get_build_info(queue.device, cl.program_build_info.LOG)
                raise KernelBuildError(
                    _display(KERNEL_ROOT / relpath),
                    defines,
                    describe(queue.device),
                    f"kernel {name!r} unavailable after the build: {e}\n{log}",
                ) from None
            state.kernels[key] = k
        return k


def launch(
    queue: cl.CommandQueue,
    kernel: cl.Kernel,
    global_size: int,
    local_size: int | None,
    *args: Any,
    wait_for: Sequence[cl.Event] | None = None,
) -> cl.Event:
    """Set `args` and enqueue a 1-D launch (serialised: kernels hold their args)."""
    with _lock:
        kernel.set_args(*args)
        return cl.enqueue_nd_range_kernel(
            queue,
            kernel,
            (int(global_size),),
            None if local_size is None else (int(local_size),),
            wait_for=wait_for,
        )


# --------------------------------------------------------------------------
# memory


def allocator(queue: cl.CommandQueue) -> cl.tools.MemoryPool:
    """A memory pool for the queue: repeated calls reuse device buffers."""
    state = _state(queue.context)
    with _lock:
        pool = state.pools.get(queue.int_ptr)
        if pool is None:
            pool = state.pools[queue.int_ptr] = cl.tools.MemoryPool(cl.tools.ImmediateAllocator(queue))
        return pool


def free_pools() -> None:
    """Give every pooled buffer back to the drivers."""
    with _lock:
        for s in _contexts.values():
            for pool in s.pools.values():
                pool.free_held()


def check_alloc(queue: cl.CommandQueue, nbytes: int, what: str) -> None:
    """DeviceError if one buffer of `nbytes` exceeds the device's max single allocation."""
    limit = capabilities(queue).max_alloc_bytes
    if nbytes > limit:
        raise DeviceError(
            f"{what}: needs one buffer of {nbytes} bytes, more than the max single allocation "
            f"of {limit} bytes on {describe(queue.device)}"
        )


def host_available_bytes() -> int | None:
    """Memory this process can still take on the host: the kernel's estimate of
    available memory (MemAvailable), lowered to the address-space limit
    (RLIMIT_AS) minus what the process already maps; None where neither is
    known."""
    avail = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        pass
    if avail is None:
        with contextlib.suppress(ValueError, OSError, AttributeError):
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            with open("/proc/self/statm") as f:
                mapped = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
            left = max(0, soft - mapped)
            avail = left if avail is None else min(avail, left)
    except (ImportError, OSError, ValueError, IndexError):
        pass
    return avail


def check_memory(queue: cl.CommandQueue, what: str, *, device_bytes: int = 0, host_bytes: int = 0) -> None:
    """DeviceError naming both figures when `device_bytes` more on the device or
    `host_bytes` more on the host would not fit: call it before a large
    allocation (a big image, a tile plan), so the caller gets a clear error
    instead of a driver failure, a swap storm or the OOM killer. On a CPU
    device, device memory is host memory: both count against the host."""
    caps = capabilities(queue)
    if device_bytes > caps.global_mem_bytes:
        raise DeviceError(
            f"{what}: needs {device_bytes / 1e9:.2f} GB on the device and "
            f"{host_bytes / 1e9:.2f} GB on the host; {describe(queue.device)} has "
            f"{caps.global_mem_bytes / 1e9:.2f} GB"
        )
    host_need = host_bytes + (device_bytes if caps.device_type == "CPU" else 0)
    avail = host_available_bytes()
    if avail is not None and host_need > avail:
        raise DeviceError(
            f"{what}: needs {device_bytes / 1e9:.2f} GB on the device and "
            f"{host_bytes / 1e9:.2f} GB on the host ({host_need / 1e9:.2f} GB of host memory "
            f"with a CPU device), but only {avail / 1e9:.2f} GB is available"
        )


def empty(queue: cl.CommandQueue, shape: int | Sequence[int], dtype: npt.DTypeLike, what: str) -> cla.Array:
    """A device array from the pool, after check_alloc; DeviceError if the driver refuses."""
    shape = (int(shape),) if isinstance(shape, (int, np.integer)) else tuple(shape)
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    check_alloc(queue, nbytes, what)
    try:
        return cla.empty(queue, shape, dtype, allocator=allocator(queue))
    except (cl.MemoryError, cl.Error) as e:
        raise DeviceError(f"{what}: allocating {nbytes} bytes on {describe(queue.device)} failed: {e}") from e


def fill_zero(queue: cl.CommandQueue, a: cla.Array) -> cla.Array:
    """Zero a device array's bytes: :func:`fill` with 0."""
    return fill(queue, a, 0)


def zeros(queue: cl.CommandQueue, shape: int | Sequence[int], dtype: npt.DTypeLike, what: str) -> cla.Array:
    """empty(), zeroed."""
    return fill_zero(queue, empty(queue, shape, dtype, what))


# --------------------------------------------------------------------------
# the launch layer
#
# Every family sizes, fills and times its launches with these, and every
# renderer runs under the options it captured (see LaunchConfig).

# the compiler flags of the kernels whose float32 results the references
# repeat exactly (each such kernel's ABI comment says so)
EXACT_FP = ("-cl-fp32-correctly-rounded-divide-sqrt",)


def local_size(queue: cl.CommandQueue, wanted: int) -> int:
    """`wanted` work-items per group, halved until the queue's device allows
    it (at least 1). Halving keeps a power of two a power of two: the work
    shapes of the PROFILES tables are, and tiles (64 pixels of march.cl) are
    multiples of them."""
    wg = max(1, int(wanted))
    limit = _native_capabilities(_as_device(queue)).max_work_group_size
    while wg > 1 and wg > limit:
        wg //= 2
    return wg


def items(queue: cl.CommandQueue, n: int, wg: int) -> tuple[int, int]:
    """(global, local) sizes of a 1-D launch with one work-item per element
    of `n`: local = local_size(queue, wg), global the next multiple of it.
    n == 0 gives one group, not zero: an empty launch is invalid before
    OpenCL 2.1, and every such kernel returns for items past its count."""
    local = local_size(queue, wg)
    return max(1, -(-int(n) // local)) * local, local


def fill(
    queue: cl.CommandQueue,
    a: cla.Array,
    value: Any = 0,
    *,
    start: int = 0,
    wait_for: Sequence[cl.Event] | None = None,
) -> cla.Array:
    """Set the elements of device array `a` from element `start` on to
    `value` (converted to a's dtype: np.float32(np.inf), -1, 0xFFFFFFFF, ...)
    with clEnqueueFillBuffer (pyopencl's Array.fill would build a kernel of
    its own). A pattern whose bytes are all equal (0, all ones) is sent as
    one byte. Returns `a`."""
    dtype = np.dtype(a.dtype)
    off = int(start) * dtype.itemsize
    nbytes = a.nbytes - off
    if nbytes <= 0:
        return a
    if value == 0:
        pattern = np.zeros(1, np.uint8)
    else:
        pattern = np.full(1, value, dtype).view(np.uint8)
        if (pattern == pattern[0]).all():
            pattern = pattern[:1].copy()
    cl.enqueue_fill_buffer(
        queue,
        a.base_data,  # type: ignore[arg-type]  # a Buffer: nbytes > 0
        pattern,
        a.offset + off,
        nbytes,
        wait_for=wait_for,
    )
    return a


def arg(a: cla.Array | cl.MemoryObjectHolder | None) -> cl.MemoryObjectHolder | cl.SVMPointer | None:
    """A buffer argument that may be absent: None (a NULL pointer) for None
    or an empty array, else the array's cl.Buffer. A cl.Buffer passes as is."""
    if a is None or isinstance(a, cl.MemoryObjectHolder):
        return a
    return a.base_data if a.size else None


def nbytes(*arrays: Any) -> int:
    """Device bytes of `arrays` (None counts 0): what a renderer's stats report
    as allocated, from the arrays it holds rather than from a formula."""
    return int(sum(a.nbytes for a in arrays if a is not None))


# -- options captured per renderer ------------------------------------------


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


_pins = threading.local()


def _in_force() -> Options:
    """The options this thread runs under: its pinned ones, else the process's."""
    pinned_cfg = getattr(_pins, "config", None)
    return pinned_cfg.options if pinned_cfg is not None else _options


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


# -- timings from event profiling --------------------------------------------


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
