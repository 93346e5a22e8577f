"""Options: tuning, 64-bit atomics and the allocation cap, from
:func:`configure`/:func:`set_options` or the environment at import (the rules
are in :mod:`clvis.runtime`'s docstring), and the options in force in this
thread (:func:`_in_force`: a renderer's pinned ones, else the process's)."""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import os
import threading
import warnings
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from ..errors import ClvisWarning

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
# configure()'s override: context-local (each thread, and each asyncio task, has
# its own), so blocks nest per thread and one thread's block never changes
# another's options or outlives its own block
_override: contextvars.ContextVar[Options | None] = contextvars.ContextVar("clvis_options", default=None)
_set_lock = threading.Lock()


def _check_options(o: Options) -> None:
    # Options checks its fields when made (dataclasses.replace makes a new one);
    # this catches fields assigned on an existing instance
    Options(o.tuning, o.int64_atomics, o.max_alloc_bytes)


def _current() -> Options:
    """This context's options: its configure() block's, else the process's."""
    o = _override.get()
    return _options if o is None else o


def options() -> Options:
    """A copy of the options in force."""
    return dataclasses.replace(_current())


def set_options(**changes: Any) -> None:
    """Change options for the rest of the process (see the module docstring);
    inside a :func:`configure` block, for the rest of that block."""
    global _options
    with _set_lock:
        new = dataclasses.replace(_current(), **changes)
        _check_options(new)
        if _override.get() is not None:
            _override.set(new)
        else:
            _options = new


@contextlib.contextmanager
def configure(**changes: Any) -> Iterator[Options]:
    """Change options inside a ``with`` block, e.g.
    ``with clvis.runtime.configure(int64_atomics=False): ...``. The change holds
    in this thread (this context) only, until the block ends; blocks nest."""
    new = dataclasses.replace(_current(), **changes)
    _check_options(new)
    token = _override.set(new)
    try:
        yield options()
    finally:
        _override.reset(token)


_pins = threading.local()


def _in_force() -> Options:
    """The options this thread runs under: its pinned ones, else its configure()
    block's, else the process's."""
    pinned_cfg = getattr(_pins, "config", None)
    return pinned_cfg.options if pinned_cfg is not None else _current()
