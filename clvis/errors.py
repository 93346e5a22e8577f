"""clvis exceptions.

Every error clvis raises on purpose is a :class:`ClvisError` (or, for a wrong
argument type or value, a :class:`TypeError` / :class:`ValueError` naming the
argument). Catch ``ClvisError`` to handle all of clvis's own failures.
Settings clvis could not use and ignored (a bad environment variable) are
reported with a :class:`ClvisWarning`; a camera whose aspect ratio is not the
image's (a stretched picture) with an :class:`AspectWarning`.
"""

from __future__ import annotations

from collections.abc import Mapping


class ClvisError(Exception):
    """Base class of clvis's errors."""


class KernelBuildError(ClvisError):
    """An OpenCL program failed to build.

    Attributes: ``path`` (the ``.cl`` file), ``defines`` (dict of ``-D``
    defines), ``device`` (name) and ``log`` (the driver's build log).
    """

    def __init__(self, path: object, defines: Mapping[str, object], device: str, log: str) -> None:
        self.path = str(path)
        self.defines = dict(defines)
        self.device = device
        self.log = log
        flags = " ".join(f"-D{k}={v}" for k, v in sorted(self.defines.items()))
        super().__init__(
            f"building {self.path} for {device} failed (defines: {flags or 'none'})\n"
            f"--- build log ---\n{log.strip()}"
        )


class DeviceError(ClvisError):
    """No usable device, or a request beyond what the device can do."""


class DataError(ClvisError, ValueError):
    """Input data that clvis cannot use (malformed files, keys outside a promised
    range, ...). Also a ValueError, so code that catches bad values catches it."""


class ClvisWarning(UserWarning):
    """A setting clvis could not use and ignored; the message names it, the
    values it accepts and what clvis used instead."""


class AspectWarning(UserWarning):
    """A renderer was given a camera whose aspect ratio (``Camera.aspect``,
    width / height of its projection) differs from the image's width /
    height by more than 1 %: the picture comes out stretched. The message
    names both ratios; ``camera.with_aspect(width / height)`` is the same
    camera for that image. A projection made so on purpose: filter it,
    ``warnings.filterwarnings("ignore", category=clvis.AspectWarning)``."""


class ClusterError(ClvisError):
    """The Dask cluster under ``clvis.distributed`` failed us: a scheduler not
    reached, data lost with a worker that cannot be made again, a distributed
    renderer used after ``close()``. The message says which."""


class ClusterTimeout(ClusterError, TimeoutError):
    """A wait on the Dask cluster ran past its bound (``timeout``,
    ``connect_timeout``); the message says what was waited for and on which
    workers. Also a TimeoutError."""
