"""clvis.io.files: regular files only for readers; writes that replace a file
atomically (a failed overwrite keeps the previous file, no temporary file is
left) and name the file on ENOSPC."""

import errno
import os

import numpy as np
import pytest

import clvis.io.files as files
from clvis.errors import DataError
from clvis.gauss import Gaussians
from clvis.io import PointCloud, read_points, save_npz, write_ply


def _cloud(n=5):
    return PointCloud(np.arange(3 * n, dtype=np.float32).reshape(n, 3))


def _full_disk(monkeypatch):
    def fsync(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(files.os, "fsync", fsync)


@pytest.mark.parametrize("name", ["c.ply", "c.npz"])
def test_failed_overwrite_keeps_the_previous_file_and_names_it(tmp_path, monkeypatch, name):
    path = tmp_path / name
    write = write_ply if name.endswith(".ply") else save_npz
    write(path, _cloud(5))
    before = path.read_bytes()
    _full_disk(monkeypatch)
    with pytest.raises(OSError) as info:
        write(path, _cloud(9))
    assert info.value.errno == errno.ENOSPC
    assert info.value.filename == str(path) and str(path) in str(info.value)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # no .tmp left
    monkeypatch.undo()
    assert len(read_points(path)) == 5


def test_interrupted_write_leaves_no_temporary_file(tmp_path, monkeypatch):
    path = tmp_path / "c.ply"
    write_ply(path, _cloud(5))
    before = path.read_bytes()

    def fsync(fd):
        raise KeyboardInterrupt

    monkeypatch.setattr(files.os, "fsync", fsync)
    with pytest.raises(KeyboardInterrupt):
        write_ply(path, _cloud(9))
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["c.ply"]


def test_gaussians_save_replaces_atomically(tmp_path, monkeypatch):
    g = Gaussians(np.zeros((3, 3)), np.ones((3, 3)))
    g.save(tmp_path / "g")  # np.savez's naming: .npz added
    path = tmp_path / "g.npz"
    assert len(Gaussians.load(path).means) == 3
    before = path.read_bytes()
    _full_disk(monkeypatch)
    with pytest.raises(OSError, match="g.npz"):
        Gaussians(np.zeros((7, 3)), np.ones((7, 3))).save(path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["g.npz"]


def test_gaussians_save_says_where_and_load_finds_it_by_the_same_name(tmp_path):
    """save("g") wrote g.npz and returned None, and load("g") then said no
    such file; save("g.ply") wrote g.ply.npz, not the splat file a 3DGS user
    expects."""
    g = Gaussians(np.zeros((3, 3)), np.ones((3, 3)))
    assert g.save(tmp_path / "g") == tmp_path / "g.npz"
    assert len(Gaussians.load(tmp_path / "g").means) == 3
    assert len(Gaussians.load(str(tmp_path / "g.npz")).means) == 3
    for name in ("g.ply", "g.SPLAT", "g.spz"):
        with pytest.raises(ValueError, match="not a .* splat file"):
            g.save(tmp_path / name)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.npz"]
    with pytest.raises(FileNotFoundError):
        Gaussians.load(tmp_path / "h")


def test_write_into_a_missing_folder_names_the_target(tmp_path):
    path = tmp_path / "no" / "c.ply"
    with pytest.raises(FileNotFoundError) as info:
        write_ply(path, _cloud())
    assert info.value.filename == str(path)


def test_regular_file(tmp_path):
    (tmp_path / "f").write_bytes(b"x")
    assert files.regular_file(tmp_path / "f") == tmp_path / "f"
    with pytest.raises(FileNotFoundError):
        files.regular_file(tmp_path / "missing")
    with pytest.raises(DataError, match=r"not a regular file \(a directory\)"):
        files.regular_file(tmp_path)
    os.mkfifo(tmp_path / "p")
    with pytest.raises(DataError, match=r"not a regular file \(a FIFO\)"):
        files.regular_file(tmp_path / "p")
    with pytest.raises(DataError, match=r"not a regular file \(a device\)"):
        files.regular_file("/dev/zero")
