"""What a bench suite's pytest-benchmark JSON holds when run the way a user
tracking clvis in CI would (pytest bench/bench_<family>.py --benchmark-json
/ --benchmark-autosave): the device of every figure, and the cases that were
not measured (a peer's library missing) by name."""

import json
import os
import subprocess
import sys
from pathlib import Path

from clvis import benchreport

ROOT = Path(__file__).resolve().parents[2]


def _run(tmp_path, *args, env=None, cwd=None):
    e = {**os.environ, "CLVIS_BENCH_SCALE": "0.001", **(env or {})}
    e["PYTHONPATH"] = os.pathsep.join([str(tmp_path), str(ROOT), e.get("PYTHONPATH", "")])
    cmd = [
        sys.executable,
        "-m",
        "pytest",
        str(ROOT / "bench" / "bench_primitives.py"),
        "-q",
        "-p",
        "no:cacheprovider",
    ]
    # from tmp_path, not the clone: nothing written there
    cwd = cwd or tmp_path
    return subprocess.run([*cmd, *args], cwd=cwd, env=e, capture_output=True, text=True, timeout=300)


def test_json_names_the_device_and_what_was_not_measured(tmp_path):
    # numba "not installed": a plugin that makes its import fail
    (tmp_path / "no_numba.py").write_text("import sys\nsys.modules['numba'] = None\n")
    out = tmp_path / "run.json"
    store = tmp_path / "store"
    (tmp_path / "elsewhere").mkdir()
    p = _run(
        tmp_path,
        "-p",
        "no_numba",
        "-k",
        "radix_sort and (clvis or numba or copy)",
        f"--benchmark-json={out}",
        "--benchmark-storage=file://store",
        "--benchmark-autosave",
    )
    assert p.returncode == 1, p.stdout[-2000:]  # the numba case fails, saying why
    data = json.loads(out.read_text())
    dev = data["clvis"]["device"]
    assert dev and all(b["extra_info"]["device"] == dev for b in data["benchmarks"])
    assert data["machine_info"]["clvis"]["device"] == dev and data["machine_info"]["clvis"]["scale"] == 0.001
    (miss,) = data["clvis"]["not_measured"]
    assert miss["test"].endswith("test_radix_sort[numba]") and "numba" in miss["why"]
    rows, meta = benchreport.load(out)
    assert "test_radix_sort[numba] (failed: ModuleNotFoundError" in benchreport.format_table(rows, meta)
    # the autosaved run is another device's (edited here): pytest-benchmark's
    # --benchmark-compare says so instead of comparing silently
    (saved,) = store.rglob("*.json")
    s = json.loads(saved.read_text())
    s["machine_info"]["clvis"]["device"] = "Other platform / other device"
    saved.write_text(json.dumps(s))
    p = _run(tmp_path, "-k", "histogram and clvis", "--benchmark-storage=file://store", "--benchmark-compare")
    assert p.returncode == 0, p.stdout[-2000:]
    assert "machine_info is different" in p.stdout + p.stderr and "Other platform" in p.stdout + p.stderr
    assert "clvis: the saved run is of Other platform / other device at scale 0.001" in p.stdout + p.stderr
    # the storage outside the working directory: pytest-benchmark's own warning
    # fails there (INTERNALERROR, exit 3); clvis's still says it
    p = _run(
        tmp_path,
        "-k",
        "histogram and clvis",
        f"--benchmark-storage=file://{store}",
        "--benchmark-compare",
        cwd=str(tmp_path / "elsewhere"),
    )
    assert p.returncode == 0, p.stdout[-2000:]
    assert "clvis: the saved run is of Other platform" in p.stdout + p.stderr


def test_a_case_gives_back_the_thread_count_it_set(tmp_path):
    """bench_primitives' numba peer runs on 2 threads; numba's count before the
    case (1 here) is back after it, not left at 2 for the rest of the session."""
    (tmp_path / "numba_one.py").write_text(
        "import numba\n"
        "numba.set_num_threads(1)\n"
        "def pytest_sessionfinish(session):\n"
        f"    open({str(tmp_path / 'after')!r}, 'w').write(str(numba.get_num_threads()))\n"
    )
    p = _run(tmp_path, "-p", "numba_one", "-k", "radix_sort and numba", "--benchmark-disable")
    assert p.returncode == 0, p.stdout[-2000:]
    assert (tmp_path / "after").read_text() == "1"
