"""Files on disk: what a reader may open, and writes that replace a file
atomically.

A reader opens regular files only: a FIFO would block the open (or the read)
forever, a device such as /dev/zero reads without end, a directory fails with
an OSError of its own. :func:`regular_file` refuses them up front with a
DataError.

A writer never leaves a partial file where the caller named one: it writes a
hidden temporary file beside the target (``.NAME.<random>.tmp``, the same
folder, so the rename stays on one file system), then renames it over the
target (:func:`os.replace`, atomic on POSIX and Windows). A failure anywhere,
an interrupt included, removes the temporary file and keeps the previous file
as it was. An OSError that does not name a file (ENOSPC from a write, EIO)
is raised again naming the target.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import stat
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

from ..errors import DataError

__all__ = ["MESH_SUFFIXES", "mesh_hint", "regular_file", "replacing", "write_replacing"]

#: triangle mesh formats (what a PyVista or Open3D user may hold): not read
MESH_SUFFIXES = (".stl", ".obj", ".off", ".glb", ".gltf", ".fbx", ".3ds", ".dae", ".3mf")


def mesh_hint(path: str | os.PathLike[str]) -> str:
    """For the message refusing a file of unknown format: where it is a
    triangle mesh, what to do with it (clvis draws points and volumes: sample
    its surface into points), else ""."""
    if not str(os.fspath(path)).lower().endswith(MESH_SUFFIXES):
        return ""
    return (
        "; it is a triangle mesh, and clvis draws points and volumes: sample its surface into points "
        "(Open3D: clvis.from_open3d(o3d.io.read_triangle_mesh(path).sample_points_uniformly(n)))"
    )


def regular_file(path: str | os.PathLike[str]) -> Path:
    """`path` as a Path when it is a regular file (symbolic links followed);
    FileNotFoundError when nothing is there, DataError naming it otherwise."""
    p = Path(os.fspath(path))
    try:
        st = p.stat()
    except FileNotFoundError:
        raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), str(p)) from None
    except OSError as e:
        raise DataError(f"{p}: cannot read: {e.strerror or e}") from None
    if not stat.S_ISREG(st.st_mode):
        what = (
            "a directory"
            if stat.S_ISDIR(st.st_mode)
            else "a FIFO"
            if stat.S_ISFIFO(st.st_mode)
            else "a device"
            if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode)
            else "a socket"
            if stat.S_ISSOCK(st.st_mode)
            else "not a regular file"
        )
        raise DataError(f"{p}: not a regular file ({what})")
    return p


def _named(e: OSError, path: Path, tmp: Path) -> OSError:
    """`e` naming `path` when it names no file (ENOSPC and EIO from a write do
    not) or the temporary one."""
    if e.filename is not None and e.filename != str(tmp):
        return e
    new = type(e)(e.errno, e.strerror or str(e), str(path))
    new.__cause__ = e.__cause__
    return new


@contextlib.contextmanager
def replacing(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path beside `path`: whatever the block writes there replaces
    `path` when the block ends normally, and is removed otherwise."""
    target = Path(os.fspath(path))
    tmp = target.with_name(f".{target.name}.{secrets.token_hex(6)}.tmp")
    try:
        yield tmp
        os.replace(tmp, target)
    except OSError as e:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise _named(e, target, tmp) from None
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_replacing(path: str | os.PathLike[str], write: Callable[[IO[Any]], object]) -> None:
    """write(file) into a temporary file that then replaces `path` (see :func:`replacing`)."""
    with replacing(path) as tmp, open(tmp, "xb") as f:
        write(f)
        f.flush()
        os.fsync(f.fileno())
