"""read_vdb on hostile files: a DataError naming the file, never another error."""

import struct

import numpy as np
import pytest

from clvis.errors import DataError
from clvis.gauss.sparse import read_vdb

pytest.importorskip("tinyvdb")


def _s(text: str) -> bytes:
    b = text.encode()
    return struct.pack("<I", len(b)) + b


def _header(grid_count: int) -> bytes:
    out = struct.pack("<qIIIB", 0x56444220, 224, 11, 0, 1) + b"0EA4B2C5-0F55-4B24-9C25-5CFD16E1E1CE"
    return out + struct.pack("<II", 0, grid_count)


@pytest.mark.parametrize(
    "tail",
    [
        b"",  # grids declared, none present
        _s("density") + _s("Tree_float_5_4_3") + _s("") + struct.pack("<qqq", 1 << 40, 1 << 41, 1 << 42),
        struct.pack("<I", 0xFFFFFFF0) + b"abc",  # a name of 4 GB
    ],
)
@pytest.mark.parametrize("grid_count", [1, 0x7FFFFFFF, 0xFFFFFFFF])
def test_vdb_lying_counts(tmp_path, tail, grid_count):
    path = tmp_path / "bad.vdb"
    path.write_bytes(_header(grid_count) + tail)
    with pytest.raises(DataError) as e:
        read_vdb(path)
    assert str(path) in str(e.value)


def test_vdb_random_bytes(tmp_path):
    rng = np.random.default_rng(5)
    path = tmp_path / "noise.vdb"
    for _ in range(20):
        path.write_bytes(
            _header(1) + rng.integers(0, 256, int(rng.integers(0, 400)), dtype=np.uint8).tobytes()
        )
        with pytest.raises(DataError) as e:
            read_vdb(path)
        assert str(path) in str(e.value)
