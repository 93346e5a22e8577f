"""The README's Python examples, run as written: every ```python block, in
order, in one namespace (a later block may use what an earlier one made, as
a reader going down the page would), in a temporary folder holding the
files the examples name."""

import re
import shutil
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BLOCKS = re.findall(r"^```python\n(.*?)^```", (ROOT / "README.md").read_text(encoding="utf-8"), re.M | re.S)


def test_readme_has_examples():
    assert len(BLOCKS) >= 4


def test_examples_that_start_workers_run_as_scripts():
    """A block that starts Dask worker processes (workers=N) does its work
    under `if __name__ == "__main__":`: spawned workers import the script
    again, and unguarded work would run in each of them (and fail)."""
    starting = [b for b in BLOCKS if re.search(r"workers=\d", b)]
    assert starting, "the README's distributed example is gone: update this test"
    for b in starting:
        guard = b.find('if __name__ == "__main__":')
        first = min(m.start() for m in re.finditer(r"workers=\d", b))
        assert 0 <= guard < first, b


def test_the_distributed_example_runs_as_a_script(tmp_path):
    """The block that starts workers, saved as a file and run by `python`
    (spawned workers re-import it), as a reader would copy it."""
    pytest.importorskip("distributed")
    pytest.importorskip("laspy")
    import subprocess
    import sys

    block = next(b for b in BLOCKS if re.search(r"workers=\d", b))
    shutil.copy(ROOT / "tests" / "data" / "laspy_simple.laz", tmp_path / "scan.laz")
    (tmp_path / "example.py").write_text(block, encoding="utf-8")
    env = {**__import__("os").environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run(
        [sys.executable, "example.py"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert (tmp_path / "iso.png").is_file()


def test_readme_examples_run(tmp_path, monkeypatch):
    pytest.importorskip("laspy")
    shutil.copy(ROOT / "tests" / "data" / "laspy_simple.laz", tmp_path / "scan.laz")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__main__"}  # as `python example.py` runs it: guarded blocks too
    times = []
    for i, block in enumerate(BLOCKS):
        t0 = time.perf_counter()
        exec(compile(block, f"README.md python block {i + 1}", "exec"), namespace)  # noqa: S102
        times.append(time.perf_counter() - t0)
    print("README blocks, seconds:", ", ".join(f"{t:.1f}" for t in times))
