"""Programs: kernels_cl/ found beside the package, compiler options (``-I``
and ``-D`` defines only, plus the few flags kernels ask for), builds, and the
per-context program and kernel cache (with pyopencl's on-disk cache where the
driver has none of its own)."""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import stat
import sys
import time
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pyopencl as cl

from ..errors import ClvisError, KernelBuildError
from .device import _lock, _state, capabilities, describe


def _find_kernel_root() -> Path:
    here = Path(__file__).resolve().parent.parent  # the clvis package
    # installed wheel: clvis/kernels_cl; source checkout: <repo>/kernels_cl
    for cand in (here / "kernels_cl", here.parent / "kernels_cl"):
        if (cand / "include" / "clvis").is_dir():
            return cand
    raise ClvisError(f"clvis's OpenCL sources (kernels_cl/) were not found beside {here}")


KERNEL_ROOT = _find_kernel_root()
INCLUDE_DIR = KERNEL_ROOT / "include"


# OpenCL compiler flags a kernel file may ask for (its ABI comment says which);
# anything else would make what is built differ from what is in the file
_FLAGS = {"-cl-fp32-correctly-rounded-divide-sqrt"}


# -D values: numbers, C identifiers and expressions of them without whitespace,
# quotes or backslashes (the options reach the compiler as one space-joined string)
_DEFINE_VALUE = re.compile(r"[A-Za-z0-9_.+\-*/%()<>!&|^~]+")


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
    """The -I path: a copy of INCLUDE_DIR named by a hash of the headers'
    contents (:func:`_private_include`), so that the option, part of the
    drivers' and pyopencl's binary cache keys, is the same for every checkout
    and install of the same headers: a second clone, a wheel beside an
    editable install, or CI's fresh clone on a warm cache build nothing
    again. The copy's path also has no whitespace, which the option cannot
    take (pyopencl joins options with spaces and PoCL 3 passes quotes on to
    clang literally). Where no temporary folder can hold the copy, INCLUDE_DIR
    itself when its path has no whitespace. The build never changes the
    process's working directory, which other threads read."""
    try:
        return str(_private_include())
    except (ClvisError, OSError):
        inc = str(INCLUDE_DIR)
        if re.search(r"\s", inc):
            raise
        return inc


_private: Path | None = None


def _headers_digest(root: Path) -> str:
    digest = hashlib.sha256()
    for f in sorted(root.rglob("*")):
        if f.is_file():
            digest.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes())
    return digest.hexdigest()


def _private_include() -> Path:
    """A copy of INCLUDE_DIR under the temporary folder (or /tmp, /var/tmp),
    named by the user and a hash of the headers' paths and contents: made once
    (renamed into place, so concurrent processes never see half a copy) and
    shared by every process of this user with the same headers. A copy found
    in place is used only when this user owns it, nobody else may write to
    it, and its contents hash the same (a shared /tmp cannot hand the
    compiler foreign headers)."""
    global _private
    if _private is not None and _private.is_dir():
        return _private
    import shutil
    import tempfile

    digest = _headers_digest(INCLUDE_DIR)
    uid = os.getuid() if hasattr(os, "getuid") else 0
    name = f"clvis-include-{uid}-{digest[:16]}"
    for base in (tempfile.gettempdir(), "/tmp", "/var/tmp"):
        if re.search(r"\s", base) or not os.path.isdir(base):
            continue
        target = Path(base) / name
        if not target.is_dir():
            if not os.access(base, os.W_OK):
                continue
            staging = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=base))
            try:
                copy = staging / "include"
                shutil.copytree(INCLUDE_DIR, copy, copy_function=shutil.copyfile)
                for f in (copy, *copy.rglob("*")):  # nobody else may write
                    f.chmod(0o755 if f.is_dir() else 0o644)
                try:
                    os.replace(staging / "include", target)
                except OSError:  # another process made it first
                    if not target.is_dir():
                        raise
            finally:
                shutil.rmtree(staging, ignore_errors=True)
        if not _trusted_copy(target, uid, digest):
            continue
        _private = target
        return target
    raise ClvisError(
        f"clvis's OpenCL headers are at {INCLUDE_DIR}, a path with whitespace, which the OpenCL "
        "compiler's -I option cannot take, and no temporary folder without whitespace was found "
        "to copy them to; set TMPDIR to one"
    )


def _trusted_copy(target: Path, uid: int, digest: str) -> bool:
    """`target` is this user's, writable by nobody else, with the headers
    hashing to `digest`."""
    try:
        st = target.lstat()
        if not stat.S_ISDIR(st.st_mode) or st.st_mode & 0o022:
            return False
        if hasattr(os, "getuid") and st.st_uid != uid:
            return False
        return _headers_digest(target) == digest
    except OSError:
        return False


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
    with warnings.catch_warnings():
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
