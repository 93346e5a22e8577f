"""The kernels are usable without Python: a C host program builds
kernels_cl/primitives/scan.cl from its ABI comment alone and runs it on PoCL
through the system's OpenCL ICD loader.

Needs a C compiler, the OpenCL headers and ICD loader (Debian:
opencl-headers ocl-icd-opencl-dev). Where they are missing the test is
skipped with that reason -- except when CLVIS_REQUIRE_EMBED=1 (CI sets it),
where a missing toolchain fails it.
"""

import glob
import os
import shutil
import subprocess
from pathlib import Path

import pyopencl
import pytest

from clvis import runtime

HOST = Path(__file__).parent / "embed" / "scan_host.c"


def _unavailable(reason):
    if os.environ.get("CLVIS_REQUIRE_EMBED") == "1":
        pytest.fail(f"CLVIS_REQUIRE_EMBED=1 but {reason}")
    pytest.skip(reason)


def _pocl_library():
    """PoCL's ICD library: the one pyopencl[pocl] ships, else a system one."""
    libs = glob.glob(os.path.join(os.path.dirname(pyopencl.__file__), ".libs", "libpocl*.so*"))
    libs += glob.glob("/usr/lib/*/libpocl.so*") + glob.glob("/usr/local/lib/libpocl.so*")
    return libs[0] if libs else None


def test_c_host_runs_scan(tmp_path):
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        _unavailable("no C compiler (cc/gcc) on PATH")
    exe = tmp_path / "scan_host"
    build = subprocess.run([cc, "-std=c99", "-O2", "-Wall", str(HOST), "-lOpenCL", "-o", str(exe)],
                           capture_output=True, text=True)
    if build.returncode != 0:
        _unavailable("the OpenCL headers or ICD loader are missing (Debian: opencl-headers "
                     f"ocl-icd-opencl-dev): {build.stderr.strip()[-400:]}")
    pocl = _pocl_library()
    if pocl is None:
        _unavailable("no PoCL library found (pip install 'pyopencl[pocl]')")
    vendors = tmp_path / "vendors"
    vendors.mkdir()
    (vendors / "pocl.icd").write_text(pocl + "\n")
    env = dict(os.environ, OCL_ICD_VENDORS=str(vendors))
    run = subprocess.run([str(exe), str(runtime.KERNEL_ROOT)], capture_output=True, text=True,
                         env=env, timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    lines = [ln for ln in run.stdout.splitlines() if ln.startswith("scan.cl")]
    assert len(lines) == 4 and all(ln.endswith(": OK") for ln in lines), run.stdout
