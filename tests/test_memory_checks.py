"""Memory is checked before it is allocated: calls that would need more than
the host or device has raise DeviceError naming the bytes, instead of a numpy
MemoryError followed by a segfault (a failed host allocation of a CPU device's
buffer). Each runs in a child process under a 4 GiB address-space limit."""

import os
import subprocess
import sys

import pytest

PRELUDE = """
import resource, sys
import numpy as np
import clvis
from clvis import runtime
from clvis.errors import DeviceError
q = runtime.queue_for(runtime.devices()[int(sys.argv[1])])
resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
try:
{body}
except DeviceError as e:
    print("DeviceError:", e)
    sys.exit(0)
print("no error")
sys.exit(1)
"""


def _child(device, body: str) -> str:
    from clvis import runtime

    index = [runtime.describe(d) for d in runtime.devices()].index(runtime.describe(device))
    code = PRELUDE.format(body="\n".join("    " + line for line in body.strip().splitlines()))
    out = subprocess.run(
        [sys.executable, "-c", code, str(index)],
        capture_output=True,
        text=True,
        timeout=300,
        env=dict(os.environ),
    )
    assert out.returncode == 0, (out.returncode, out.stdout[-2000:], out.stderr[-2000:])
    return out.stdout


@pytest.mark.parametrize("side", [16000, 20000])
def test_rasterize_larger_than_memory_is_refused(device, side):
    out = _child(
        device,
        f"""
pts = np.random.default_rng(0).random((1000, 3)).astype(np.float32)
cam = clvis.Camera.look_at((0.5, 0.5, 3), (0.5, 0.5, 0.5), (0, 1, 0), 40)
clvis.rasterize(pts, cam, {side}, {side}, queue=q)
""",
    )
    assert f"raster image {side}x{side}" in out and "GB" in out


def test_histogram_of_a_billion_bins_is_refused(device):
    out = _child(device, "clvis.histogram(np.zeros(100, np.int32), 10**9, queue=q)")
    assert "histogram of 1000000000 bins" in out and "GB" in out


def test_clvis_render_larger_than_host_memory_is_refused_up_front(tmp_path):
    # 1,065 points at 16000x16000 grew at ~97 B a pixel until the OOM killer (rc 137,
    # nothing on stderr); under an 8 GiB limit it must stop at once, naming the bytes
    import resource

    laz = os.path.join(os.path.dirname(__file__), "data", "laspy_simple.laz")

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (8 << 30, 8 << 30))

    out = subprocess.run(
        [sys.executable, "-m", "clvis", "render", laz, "--size", "16000x16000", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=limit,
    )
    assert out.returncode == 2, out.stderr[-2000:]
    assert out.stderr.startswith("clvis render: error: clvis render --size 16000x16000: needs"), out.stderr
    assert len(out.stderr.splitlines()) == 1 and "available" in out.stderr
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    "call", ["clvis.scan(x, queue=q)", "clvis.histogram(x, 4, queue=q)", "clvis.radix_sort(x, queue=q)"]
)
def test_zero_stride_view_claiming_2_31_elements_is_refused_before_the_copy(device, call):
    # made contiguous before any size check: numpy's MemoryError
    out = _child(device, f"x = np.broadcast_to(np.int32(1), (2**31,))\n{call}")
    assert "needs a contiguous copy of 8.59 GB" in out


def test_clvis_iso_larger_than_host_memory_is_refused_up_front(tmp_path):
    # clvis iso --size 16000x16000 peaked at 19.7 GB
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (8 << 30, 8 << 30))

    out = subprocess.run(
        [sys.executable, "-m", "clvis", "iso", "--size", "16000x16000", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=limit,
    )
    assert out.returncode == 2, out.stderr[-2000:]
    assert out.stderr.startswith("clvis iso: error: clvis iso --size 16000x16000: needs"), out.stderr
    assert len(out.stderr.splitlines()) == 1
    assert not list(tmp_path.iterdir())
