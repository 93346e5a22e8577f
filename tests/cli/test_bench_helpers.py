"""bench/'s helpers as the suites use them: the CPU time of each timed round
(benchutil.run), rows the report cannot rank (two clvis rows of one op), and
process state a case changes and must give back."""

import importlib
import json
import os
import sys
import time
from pathlib import Path

import pytest

from clvis import benchreport

BENCH = Path(__file__).resolve().parents[2] / "bench"


@pytest.fixture
def bench_path(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCH))


class FakeBenchmark:
    """pytest-benchmark's fixture as benchutil.run calls it: pedantic runs the
    warm-up round and the timed rounds, then (as --benchmark-cprofile does)
    `extra` more calls; disabled (--benchmark-disable), a single call."""

    def __init__(self, extra=0, disabled=False):
        self.extra_info, self.group, self.extra, self.disabled = {}, None, extra, disabled

    def pedantic(self, target, rounds, warmup_rounds, iterations):
        if self.disabled:
            return target()
        for _ in range(warmup_rounds + rounds + self.extra):
            target()


def _spin(seconds):
    t = time.process_time()
    while time.process_time() - t < seconds:
        pass


def test_cpu_time_is_of_the_timed_rounds(bench_path):
    """--benchmark-cprofile's extra, profiled call is not a timed round: its
    CPU time used to land in cpu_s (the last `rounds` calls), the first timed
    round's dropped."""
    from benchutil import run

    calls = []

    def fn():
        calls.append(1)
        if len(calls) == 1 + 3 + 1:  # the profiled call after the 3 rounds
            _spin(0.2)

    b = FakeBenchmark(extra=1)
    run(b, fn, op="o", impl="i", role="peer", n=1, nbytes=1, rounds=3)
    assert len(b.extra_info["cpu_s"]) == 3 and max(b.extra_info["cpu_s"]) < 0.1
    b = FakeBenchmark(disabled=True)
    run(b, fn, op="o", impl="i", role="peer", n=1, nbytes=1, rounds=3)
    assert len(b.extra_info["cpu_s"]) == 1
    # work in other processes: no cpu_s, the reason instead (the table says it)
    b = FakeBenchmark()
    run(b, fn, op="o", impl="i", role="peer", n=1, nbytes=1, rounds=3, cpu="in the workers")
    assert "cpu_s" not in b.extra_info and b.extra_info["cpu_not_recorded"] == "in the workers"
    row = benchreport.Row("o", "i", "peer", 1, 1, 1e-3, 1e-3, 3, info=b.extra_info)
    assert "cpu of i: not recorded (in the workers)" in benchreport.format_table([row])


def test_two_clvis_rows_of_one_op_are_refused(tmp_path):
    """The ratios and --compare divide by the op's clvis row; with two (as
    bench_distributed's volume op had) the last one silently won."""

    def b(impl, role):
        info = {"op": "x", "impl": impl, "role": role, "n": 1, "bytes": 1}
        return {"extra_info": info, "stats": {"median": 1, "min": 1, "rounds": 1}}

    p = tmp_path / "r.json"
    p.write_text(json.dumps({"benchmarks": [b("2 workers", "clvis"), b("full frames", "clvis")]}))
    with pytest.raises(ValueError, match="two rows of role 'clvis'"):
        benchreport.load(p)


def test_cluster_gives_back_the_pocl_variables(bench_path, monkeypatch):
    """bench_distributed pins PoCL to one thread a worker while it starts the
    cluster; a value the user had set is back afterwards (it used to be deleted)."""
    pytest.importorskip("distributed")
    pytest.importorskip("laspy")
    bd = importlib.import_module("bench_distributed")
    seen = {}

    def cluster(**kw):
        seen.update({k: os.environ.get(k) for k in ("POCL_CPU_MAX_CU_COUNT", "POCL_MAX_PTHREAD_COUNT")})
        return "cluster"

    monkeypatch.setattr(bd.distributed, "LocalCluster", cluster)
    monkeypatch.setenv("POCL_MAX_PTHREAD_COUNT", "7")
    monkeypatch.delenv("POCL_CPU_MAX_CU_COUNT", raising=False)
    assert bd._cluster(1) == "cluster"
    assert seen == {"POCL_CPU_MAX_CU_COUNT": "1", "POCL_MAX_PTHREAD_COUNT": "1"}
    assert os.environ["POCL_MAX_PTHREAD_COUNT"] == "7" and "POCL_CPU_MAX_CU_COUNT" not in os.environ
    sys.modules.pop("bench_distributed", None)


def test_ideal_two_thread_peer_keeps_its_cpu_time():
    """bench_iso's "2 x zfpy" row halves zfpy's time (two ideal threads); its
    CPU time is the serial run's, not halved with it. A ray-subset peer's
    (time_scale alone) scales both."""
    two = benchreport.Row("o", "2 x zfpy", "peer", 1, 1, 1, 1, 1, info={"cpu_s": [4.0], "time_scale": 0.5})
    assert two.cpu_s == 2.0
    two.info["cpu_scale"] = 1.0
    assert two.cpu_s == 4.0
