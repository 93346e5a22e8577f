"""The kernels are usable without Python: C host programs build
kernels_cl/primitives/scan.cl and kernels_cl/raster/{render,resolve}.cl from
their ABI comments alone and run them on PoCL through the system's OpenCL ICD
loader.

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


def _host(tmp_path, source):
    """(executable, environment naming PoCL for the ICD loader) for a C host."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        _unavailable("no C compiler (cc/gcc) on PATH")
    exe = tmp_path / source.stem
    build = subprocess.run(
        [cc, "-std=c99", "-O2", "-Wall", str(source), "-lOpenCL", "-o", str(exe)],
        capture_output=True,
        text=True,
    )
    if build.returncode != 0:
        _unavailable(
            "the OpenCL headers or ICD loader are missing (Debian: opencl-headers "
            f"ocl-icd-opencl-dev): {build.stderr.strip()[-400:]}"
        )
    pocl = _pocl_library()
    if pocl is None:
        _unavailable("no PoCL library found (pip install 'pyopencl[pocl]')")
    vendors = tmp_path / "vendors"
    vendors.mkdir(exist_ok=True)
    (vendors / "pocl.icd").write_text(pocl + "\n")
    return exe, dict(os.environ, OCL_ICD_VENDORS=str(vendors))


def test_c_host_runs_scan(tmp_path):
    exe, env = _host(tmp_path, HOST)
    run = subprocess.run(
        [str(exe), str(runtime.KERNEL_ROOT)], capture_output=True, text=True, env=env, timeout=600
    )
    assert run.returncode == 0, run.stdout + run.stderr
    lines = [ln for ln in run.stdout.splitlines() if ln.startswith("scan.cl")]
    assert len(lines) == 4 and all(ln.endswith(": OK") for ln in lines), run.stdout


def test_c_host_runs_raster(tmp_path):
    """render.cl + resolve.cl driven from C give the reference's visibility,
    index and depth buffers bit for bit."""
    import numpy as np

    from clvis.camera import Camera, camera_buffer
    from clvis.reference import raster as ref

    exe, env = _host(tmp_path, HOST.parent / "raster_host.c")
    rng = np.random.default_rng(0)
    pos = rng.normal(size=(50_000, 3)).astype(np.float32)
    pos[::997] = np.nan
    W, H = 97, 61
    cam = Camera.look_at((0.5, -5, 1), (0, 0, 0), (0, 0, 1), fov_y=50, aspect=W / H, near=0.5, far=20)
    header = np.array([len(pos), W, H, 1000], "<u4").tobytes()
    header += np.array([cam.near, cam.far], "<f4").tobytes() + camera_buffer(cam).astype("<f4").tobytes()
    (tmp_path / "in.bin").write_bytes(header + pos.astype("<f4").tobytes())
    run = subprocess.run(
        [str(exe), str(runtime.KERNEL_ROOT), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    out = (tmp_path / "out.bin").read_bytes()
    npix = W * H
    vis = np.frombuffer(out, "<u8", npix).reshape(H, W)
    index = np.frombuffer(out, "<u4", npix, offset=8 * npix).reshape(H, W)
    depth = np.frombuffer(out, "<f4", npix, offset=12 * npix).reshape(H, W)
    np.testing.assert_array_equal(vis, ref.visibility(pos, cam, W, H))
    want = ref.rasterize(pos, cam, W, H)
    np.testing.assert_array_equal(index, want.index)
    np.testing.assert_array_equal(depth, want.depth)
    assert want.covered.sum() > npix // 4
