"""A non-editable install carries the OpenCL sources and finds them."""

import os
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_wheel_ships_kernels(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(ROOT)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    wheel = next(tmp_path.glob("clvis-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    sources = [p.relative_to(ROOT).as_posix() for p in (ROOT / "kernels_cl").rglob("*") if p.is_file()]
    assert sources
    for s in sources:
        assert f"clvis/{s}" in names, s
    assert "clvis/view/static/index.html" in names  # the viewer's page

    # unpacked on its own, away from the checkout, it builds and runs a kernel
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    code = (
        "import numpy as np, clvis, clvis.runtime as r; "
        "print(r.KERNEL_ROOT); print(clvis.scan(np.arange(5, dtype=np.int32)).tolist())"
    )
    env = dict(os.environ, PYTHONPATH=str(site))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env)
    assert out.returncode == 0, out.stderr
    root, result = out.stdout.strip().splitlines()
    assert Path(root) == site / "clvis" / "kernels_cl"
    assert result == "[0, 0, 1, 3, 6]"
