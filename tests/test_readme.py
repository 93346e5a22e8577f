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


def test_readme_examples_run(tmp_path, monkeypatch):
    pytest.importorskip("laspy")
    shutil.copy(ROOT / "tests" / "data" / "laspy_simple.laz", tmp_path / "scan.laz")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "readme"}
    times = []
    for i, block in enumerate(BLOCKS):
        t0 = time.perf_counter()
        exec(compile(block, f"README.md python block {i + 1}", "exec"), namespace)  # noqa: S102
        times.append(time.perf_counter() - t0)
    print("README blocks, seconds:", ", ".join(f"{t:.1f}" for t in times))
