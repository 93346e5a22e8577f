"""pytest-benchmark setup shared by the bench/ suites.

Sizes follow the targets in clvis.benchreport; set CLVIS_BENCH_SCALE (e.g. 0.001) to shrink
every size for a quick smoke run (CI runs the suites that way, with
--benchmark-disable, to keep the code working; figures come from full runs).

The JSON (--benchmark-json, --benchmark-autosave/save) names the OpenCL device
three times, so runs on two devices cannot be confused: in its "clvis" section,
in each benchmark's extra_info ("device") and in machine_info["clvis"], which
--benchmark-compare checks (pytest-benchmark's "Benchmark machine_info is
different" and a "clvis: the saved run is of ..." line when the saved run is
another device's or another scale's). Cases of the suite that failed or were
skipped (a peer's library missing, ...) are listed in the "clvis" section's
not_measured, so a report says what is absent instead of dropping it.
"""

import os
from pathlib import Path

import pytest

import clvis
from clvis import runtime

_HERE = Path(__file__).resolve().parent
_not_measured: list[dict] = []
_root: list[Path] = []  # the session's rootdir: report node ids are relative to it


def pytest_configure(config):
    _root[:] = [Path(config.rootpath)]


@pytest.fixture(scope="session")
def queue():
    return clvis.default_queue()


def _device() -> dict:
    q = clvis.default_queue()
    return {
        "device": runtime.describe(q.device),
        "device_slug": runtime.device_slug(q),
        "scale": float(os.environ.get("CLVIS_BENCH_SCALE", "1")),
    }


def pytest_benchmark_update_machine_info(config, machine_info):
    machine_info["clvis"] = _device()


@pytest.hookimpl(hookwrapper=True)
def pytest_benchmark_compare_machine_info(config, benchmarksession, machine_info, compared_benchmark):
    """--benchmark-compare against a saved run of another device or scale:
    said in clvis's words. pytest-benchmark's own warning (which prints the
    whole machine_info) fails with a ValueError (5.3: an INTERNALERROR) when
    the storage is outside the working directory; that failure is dropped,
    this warning stands for it."""
    now, saved = machine_info.get("clvis"), compared_benchmark.get("machine_info", {}).get("clvis")
    if now != saved:
        was = f"{saved['device']} at scale {saved['scale']:g}" if saved else "an unnamed device (older)"
        benchmarksession.logger.warning(
            f"clvis: the saved run is of {was}, this run of {now['device']} at scale {now['scale']:g}: "
            "the compared figures are not of the same device and sizes"
        )
    outcome = yield
    if outcome.excinfo is not None and isinstance(outcome.excinfo[1], ValueError):
        outcome.force_result([])


def pytest_runtest_logreport(report):
    """A bench case that failed or was skipped: kept for the JSON's not_measured."""
    if not (report.failed or report.skipped):
        return
    path = Path(report.nodeid.split("::")[0])
    if (_root[0] / path if _root else path).resolve().parent != _HERE:
        return
    if report.skipped and isinstance(report.longrepr, tuple):
        why = str(report.longrepr[2]).removeprefix("Skipped: ")
    else:
        crash = getattr(report.longrepr, "reprcrash", None)
        why = crash.message if crash is not None else str(report.longrepr)
    lines = why.strip().splitlines()
    _not_measured.append(
        {
            "test": report.nodeid,
            "outcome": report.outcome,
            "when": report.when,
            "why": lines[0] if lines else "",
        }
    )


def pytest_benchmark_update_json(config, benchmarks, output_json):
    q = clvis.default_queue()
    caps = runtime.capabilities(q)
    dev = _device()
    output_json["clvis"] = {
        "version": clvis.__version__,
        **dev,
        "tuning": runtime.tuning_profile(q),
        "capabilities": {k: getattr(caps, k) for k in caps.__dataclass_fields__},
        "not_measured": list(_not_measured),
    }
    for b in output_json.get("benchmarks", []):
        b.setdefault("extra_info", {})["device"] = dev["device"]
