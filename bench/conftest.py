"""pytest-benchmark setup shared by the bench/ suites.

Sizes follow the targets in clvis.benchreport; set CLVIS_BENCH_SCALE (e.g. 0.001) to shrink
every size for a quick smoke run (CI runs the suites that way, with
--benchmark-disable, to keep the code working; figures come from full runs).
"""

import os

import pytest

import clvis
from clvis import runtime


@pytest.fixture(scope="session")
def queue():
    return clvis.default_queue()


def pytest_benchmark_update_json(config, benchmarks, output_json):
    q = clvis.default_queue()
    caps = runtime.capabilities(q)
    output_json["clvis"] = {
        "version": clvis.__version__,
        "device": runtime.describe(q.device),
        "device_slug": runtime.device_slug(q),
        "tuning": runtime.tuning_profile(q),
        "capabilities": {k: getattr(caps, k) for k in caps.__dataclass_fields__},
        "scale": float(os.environ.get("CLVIS_BENCH_SCALE", "1")),
    }
