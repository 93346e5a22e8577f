"""The readers issue 27 added (.vti and legacy .vtk volumes, .pcd, .xyz/.txt/
.csv point clouds) and the VTK point sets (.vtp, .vtu, .vts, legacy .vtk POLYDATA) under
the fuzzer's mutants (tests/fuzz/seeds.py's seeds, tests/fuzz/mutate.py's
operators): each read, in a forked child under an
address-space limit, ends in a clvis error naming the file or reads; never a
crash, a hang or a foreign exception. And the mutant the first run found."""

import collections

import numpy as np
import pytest
from fuzz.harness import run_limited
from fuzz.mutate import mutate
from fuzz.seeds import make_seeds

import clvis.io as io
from clvis.errors import DataError

FORMATS = ("vti", "vtk", "vtp", "vtu", "vts", "pcd", "xyz", "pts", "txt", "csv")


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    out = [s for s in make_seeds(tmp_path_factory.mktemp("seeds")) if s[0] in FORMATS]
    assert {s[0] for s in out} == set(FORMATS)
    return out


def _reader(kind):
    return io.read_volume if kind == "volume" else io.read_points


def test_seeds_read(seeds):
    for _, kind, path in seeds:
        r = run_limited(_reader(kind), str(path), name=str(path), limit_bytes=1 << 30)
        assert r.kind == "ok", (path.name, r)


@pytest.mark.parametrize("fmt", ["vti", "vtk", "vtp", "vtu+vts", "pcd", "xyz+pts+txt+csv"])
def test_mutants_end_in_clvis_errors(seeds, tmp_path, fmt):
    mine = [s for s in seeds if s[0] in fmt.split("+")]
    others = collections.defaultdict(list)
    for f, _, p in mine:
        others[f].append(p.read_bytes())
    rng = np.random.default_rng(27)
    kinds = []
    for i in range(48):
        f, kind, path = mine[i % len(mine)]
        data, ops = mutate(rng, path.read_bytes(), f, others[f])
        m = tmp_path / f"m{i}{path.suffix}"
        m.write_bytes(data)
        r = run_limited(_reader(kind), str(m), name=str(m), limit_bytes=1 << 30, timeout=30)
        assert r.kind in ("ok", "clvis"), (i, ops, r)
        assert r.peak_rss < 256 << 20, (i, ops, r.peak_rss)
        kinds.append(r.kind)
    assert kinds.count("clvis") > 12  # the mutants reach the readers' checks


def test_a_non_ascii_byte_in_a_vti_tag_is_a_clvis_error(seeds, tmp_path):
    """The fuzzer's first find: a byte that is not UTF-8 inside <VTKFile ...>
    or <ImageData ...> escaped as UnicodeDecodeError."""
    src = next(p for f, _, p in seeds if f == "vti" and "binary" in p.name).read_bytes()
    for tag in (b'byte_order="', b'WholeExtent="'):
        at = src.index(tag) + len(tag)
        m = tmp_path / f"bad-{tag[:4].decode()}.vti"
        m.write_bytes(src[:at] + b"\xff" + src[at + 1 :])
        r = run_limited(io.read_volume, str(m), name=str(m), limit_bytes=1 << 30)
        assert r.kind in ("ok", "clvis"), r
    with pytest.raises(DataError, match="WholeExtent"):
        io.read_volume(m)
