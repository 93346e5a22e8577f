"""The .e57 reader under the fuzzer's mutants (tests/fuzz/seeds.py's E57
seeds, tests/fuzz/mutate.py's operators with e57_fields): each read, in a
forked child under an address-space limit, ends in a clvis error naming the
file or reads; never a crash, a hang or a foreign exception."""

import numpy as np
import pytest
from fuzz.harness import run_limited
from fuzz.mutate import E57_PAGE, _crc32c, e57_fields, mutate
from fuzz.seeds import make_seeds

import clvis.io as io

pye57 = pytest.importorskip("pye57", reason="the e57 extra (pye57) is in the test extra")


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    out = [s for s in make_seeds(tmp_path_factory.mktemp("seeds")) if s[0] == "e57"]
    assert len(out) == 2
    return out


def test_the_field_operator_keeps_the_page_checksums(seeds):
    data = seeds[0][2].read_bytes()
    rng = np.random.default_rng(0)
    for _ in range(20):
        m = e57_fields(rng, data, 0)
        assert m != data
        for at in range(0, len(m) - E57_PAGE + 1, E57_PAGE):
            assert _crc32c(m[at : at + 1020]) == int.from_bytes(m[at + 1020 : at + 1024], "big")


def test_e57_mutants_end_in_clvis_errors(seeds, tmp_path):
    for _, _, path in seeds:
        assert run_limited(io.read_points, str(path), name=str(path)).kind == "ok"
    rng = np.random.default_rng(57)
    others = [p.read_bytes() for _, _, p in seeds]
    kinds = []
    for i in range(60):
        _, _, path = seeds[i % 2]
        data, ops = mutate(rng, path.read_bytes(), "e57", others)
        m = tmp_path / f"m{i}.e57"
        m.write_bytes(data)
        r = run_limited(io.read_points, str(m), name=str(m), limit_bytes=1 << 30, timeout=30)
        assert r.kind in ("ok", "clvis"), (i, ops, r)
        kinds.append(r.kind)
    assert kinds.count("clvis") > 30  # the mutants reach the reader's checks
