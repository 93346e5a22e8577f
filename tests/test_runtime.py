"""clvis.runtime: device choice, capabilities, builds, options, errors."""

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest

import clvis
from clvis import runtime

PROBE = str(Path(__file__).parent / "kernels" / "probe.cl")
REPO = Path(__file__).resolve().parent.parent


def test_some_device_found():
    assert runtime.devices(), "no OpenCL device: install pyopencl[pocl]"


def test_required_platforms():
    """The test command names the platforms it installed; each must load."""
    wanted = [
        p.strip().lower() for p in os.environ.get("CLVIS_REQUIRE_PLATFORMS", "").split(",") if p.strip()
    ]
    if not wanted:
        pytest.skip("CLVIS_REQUIRE_PLATFORMS is not set (the README's test command sets it)")
    names = [d.platform.name.lower() for d in runtime.devices()]
    missing = [w for w in wanted if not any(w in n for n in names)]
    assert not missing, f"platforms not found: {missing}; found {names}"


def test_select_device(monkeypatch):
    devs = runtime.devices()
    monkeypatch.delenv("CLVIS_DEVICE", raising=False)
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    assert runtime.select_device(0) == devs[0]
    assert runtime.select_device(str(len(devs) - 1)) == devs[-1]
    d = runtime.select_device("portable")
    assert "portable computing language" in d.platform.name.lower()
    monkeypatch.setenv("CLVIS_DEVICE", "PORTABLE")
    assert runtime.select_device() == d
    with pytest.raises(clvis.DeviceError, match="matches no device"):
        runtime.select_device("no-such-device-anywhere")
    n = len(devs)
    with pytest.raises(
        clvis.DeviceError, match=f"there {'is' if n == 1 else 'are'} {n} device{'s' * (n != 1)} "
    ):
        runtime.select_device(n + 3)


def test_default_order(monkeypatch):
    """No CLVIS_DEVICE or PYOPENCL_CTX: a GPU, else PoCL, else the first."""
    monkeypatch.delenv("CLVIS_DEVICE", raising=False)
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    devs = runtime.devices()
    gpus = [d for d in devs if d.type & cl.device_type.GPU]
    pocl = [d for d in devs if "portable" in d.platform.name.lower()]
    assert runtime.select_device() == (gpus or pocl or devs)[0]


def test_pyopencl_ctx(monkeypatch):
    monkeypatch.delenv("CLVIS_DEVICE", raising=False)
    monkeypatch.setenv("PYOPENCL_CTX", "0:0")
    assert runtime.select_device() == cl.get_platforms()[0].get_devices()[0]


def test_capabilities(device):
    caps = runtime.capabilities(device)
    ext = device.extensions.split()
    assert caps.compute_units >= 1 and caps.max_work_group_size >= 1
    assert caps.max_alloc_bytes == device.max_mem_alloc_size
    assert caps.int64_atomics_native == (
        "cl_khr_int64_base_atomics" in ext and "cl_khr_int64_extended_atomics" in ext
    )
    assert caps.int64_atomics == caps.int64_atomics_native
    assert caps.device_type in ("CPU", "GPU", "ACCELERATOR", "OTHER")


def _probe(queue):
    out = cla.to_device(queue, np.array([9, 1 << 50], np.uint64))
    k = runtime.get_kernel(queue, PROBE, "probe", {})
    runtime.launch(queue, k, 1, 1, out.data)
    return out.get()


def test_int64_atomics_forced_off(device):
    """Kernels see CLVIS_INT64_ATOMICS exactly when the device has the
    extensions and the option allows; with it, the 64-bit atomic really runs."""
    q = runtime.queue_for(device)
    native = runtime.capabilities(device).int64_atomics_native
    got = _probe(q)
    assert got[0] == int(native)
    if native:
        assert got[1] == 7 | (1 << 40)
    with runtime.configure(int64_atomics=False):
        assert not runtime.capabilities(device).int64_atomics
        assert "-DCLVIS_INT64_ATOMICS=1" not in runtime.build_options(device, {})
        assert _probe(q)[0] == 0
    assert runtime.capabilities(device).int64_atomics == native


def test_int64_atomics_env():
    code = "import clvis; print(clvis.capabilities().int64_atomics)"
    env = dict(os.environ, CLVIS_NO_INT64_ATOMICS="1")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_kernel_build_error(device, tmp_path):
    bad = tmp_path / "bad.cl"
    bad.write_text("kernel void k(global int *a) { a[0] = undefined_thing; }\n")
    q = runtime.queue_for(device)
    with pytest.raises(clvis.KernelBuildError) as info:
        runtime.get_kernel(q, str(bad), "k", {"FOO": 3})
    e = info.value
    assert e.path == str(bad) and e.defines == {"FOO": 3}
    assert "undefined_thing" in e.log
    assert "-DFOO=3" in str(e) and str(bad) in str(e)
    assert isinstance(e, clvis.ClvisError)


def test_bad_define_name(device):
    with pytest.raises(ValueError, match="not a C identifier"):
        runtime.get_kernel(runtime.queue_for(device), "primitives/scan.cl", "scan_reduce", {"T=int -DX": 1})


@pytest.mark.parametrize("value", ["1 -DX=2", "a b", '"x"', "x\\", "", "a=b", float("nan"), None, [1]])
def test_bad_define_value(device, value):
    with pytest.raises(ValueError, match="define FOO"):
        runtime.build_options(device, {"FOO": value})


def test_define_values(device):
    opts = runtime.build_options(
        device, {"A": 3, "B": "uint", "C": "(1<<4)", "D": 1.5, "E": True, "F": np.int64(-2)}
    )
    assert {"-DA=3", "-DB=uint", "-DC=(1<<4)", "-DD=1.5", "-DE=1", "-DF=-2"} <= set(opts)


def _copy_package(root):
    """clvis/ and kernels_cl/ copied under `root`, as a checkout there would have them."""
    ignore = shutil.ignore_patterns("__pycache__")
    shutil.copytree(REPO / "clvis", root / "clvis", ignore=ignore)
    shutil.copytree(REPO / "kernels_cl", root / "kernels_cl", ignore=ignore)


def test_package_in_path_with_space(device, tmp_path):
    """Kernels build when the package's path has a space, from a working
    directory beside it and from one whose path has a space too: the headers
    are copied to a private folder without whitespace, and the process's
    working directory never changes meanwhile (another thread reading relative
    paths during the builds sees it unchanged every time)."""
    root = tmp_path / "with space" / "src dir"
    _copy_package(root)
    elsewhere = tmp_path / "other dir"
    elsewhere.mkdir()
    index = [runtime.describe(d) for d in runtime.devices()].index(runtime.describe(device))
    code = (
        "import os, threading, numpy as np, clvis\n"
        "assert clvis.__file__.startswith(os.environ['PYTHONPATH']), clvis.__file__\n"
        "cwd = os.getcwd()\n"
        "open('marker', 'w').close()\n"
        "seen, done = [], threading.Event()\n"
        "def watch():\n"
        "    while not done.is_set():\n"
        "        seen.append(os.getcwd() == cwd and os.path.exists('marker'))\n"
        "t = threading.Thread(target=watch)\n"
        "t.start()\n"
        "x = np.arange(1000, dtype=np.int32)\n"
        "assert (clvis.scan(x) == np.cumsum(x) - x).all()\n"
        "done.set(); t.join()\n"
        "assert seen and all(seen), (len(seen), seen.count(False))\n"
        "print(clvis.runtime.build_options(clvis.default_queue().device, {})[1])\n"
    )
    env = dict(os.environ, PYTHONPATH=str(root), CLVIS_DEVICE=str(index))
    for cwd in (root, elsewhere):
        out = subprocess.run([sys.executable, "-c", code], env=env, cwd=cwd, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        include = Path(out.stdout.strip())
        assert include.name.startswith("clvis-include-") and " " not in str(include)
        assert (include / "clvis").is_dir()


def test_include_option_is_the_same_for_every_checkout(tmp_path):
    """Two checkouts of the same headers build with the same -I option (the
    drivers' and pyopencl's cache keys hold it, so a second clone builds
    nothing again); a copy at that name that was changed, or that others may
    write to, is never used."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    code = "import clvis\nprint(clvis.runtime.build_options(clvis.default_queue().device, {})[1])\n"
    seen = []
    for name in ("a", "b"):
        _copy_package(tmp_path / name)
        env = dict(os.environ, PYTHONPATH=str(tmp_path / name), TMPDIR=str(tmp))
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        seen.append(Path(out.stdout.strip()))
    assert seen[0] == seen[1] and seen[0].parent == tmp
    assert (seen[0] / "clvis" / "camera.h").read_bytes() == (
        REPO / "kernels_cl/include/clvis/camera.h"
    ).read_bytes()
    header = seen[0] / "clvis" / "camera.h"
    for tamper in ("contents", "mode"):
        if tamper == "contents":
            header.write_text(header.read_text() + "\n#error foreign\n")
        else:
            header.write_bytes((REPO / "kernels_cl/include/clvis/camera.h").read_bytes())
            seen[0].chmod(0o777)
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        assert Path(out.stdout.strip()) != seen[0], tamper


@pytest.mark.parametrize(
    "var, value",
    [
        ("CLVIS_TUNING", "tpu"),
        ("CLVIS_MAX_ALLOC", "abc"),
        ("CLVIS_MAX_ALLOC", "-5"),
        ("CLVIS_NO_INT64_ATOMICS", "maybe"),
    ],
)
def test_bad_environment_warns(var, value):
    """A bad variable never stops clvis from importing: a ClvisWarning names it
    and what it accepts, and the default applies."""
    code = "import clvis\no = clvis.runtime.options()\nprint(o.tuning, o.int64_atomics, o.max_alloc_bytes)\n"
    env = dict(os.environ, **{var: value})
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "None True None"
    assert "ClvisWarning" in out.stderr and f"{var}={value!r} is ignored: expected" in out.stderr


def test_environment_sizes():
    code = "import clvis; print(clvis.runtime.options().max_alloc_bytes)"
    for value, expected in (("4096", "4096"), (" 2e9 ", "2000000000")):
        env = dict(os.environ, CLVIS_MAX_ALLOC=value)
        out = subprocess.run(
            [sys.executable, "-W", "error", "-c", code], env=env, capture_output=True, text=True
        )
        assert out.returncode == 0, out.stderr
        assert out.stdout.strip() == expected


def test_options_from_strings():
    with runtime.configure(max_alloc_bytes="5", int64_atomics="false", tuning=" GPU") as o:
        assert (o.max_alloc_bytes, o.int64_atomics, o.tuning) == (5, False, "gpu")
    for bad in ("abc", "-5", 0, 1.5, True, [5]):
        with pytest.raises(ValueError, match="max_alloc_bytes"):
            runtime.set_options(max_alloc_bytes=bad)
    with pytest.raises(ValueError, match="int64_atomics"):
        runtime.set_options(int64_atomics="maybe")
    with pytest.raises(ValueError, match="tuning"):
        runtime.set_options(tuning="tpu")
    assert runtime.options() == runtime.Options()


def _pyopencl_cache(device, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    ctx = runtime.queue_for(device).context
    cache = runtime.program._pyopencl_cache_dir(ctx)
    if cache is None:
        pytest.skip("the driver caches its builds itself: pyopencl's cache is not used")
    cache.mkdir(parents=True)
    return ctx, cache


def test_stale_cache_lock(device, tmp_path, monkeypatch):
    """A lock older than pyopencl's one-minute wait is reported at once, naming the file."""
    ctx, cache = _pyopencl_cache(device, tmp_path, monkeypatch)
    lock = cache / "lock"
    lock.touch()
    old = time.time() - 120
    os.utime(lock, (old, old))
    with pytest.raises(clvis.KernelBuildError, match="delete that file") as info:
        runtime.get_program(ctx, "primitives/scan.cl", {"T": "int", "UNIQUE": time.time_ns()})
    assert str(lock) in str(info.value)


def test_cache_failure_reported(device, tmp_path, monkeypatch):
    """What pyopencl raises after waiting a minute on a fresh lock (a bare
    KeyError) becomes a KernelBuildError naming the lock."""
    ctx, cache = _pyopencl_cache(device, tmp_path, monkeypatch)
    (cache / "lock").touch()

    def build(self, *args, **kwargs):
        raise KeyError("PYOPENCL_CACHE_FAILURE_FATAL")

    monkeypatch.setattr(cl.Program, "build", build)
    with pytest.raises(clvis.KernelBuildError, match="locked by") as info:
        runtime.get_program(ctx, "primitives/scan.cl", {"T": "int", "UNIQUE": time.time_ns()})
    assert str(cache / "lock") in str(info.value)


def test_program_cache(device):
    ctx = runtime.queue_for(device).context
    a = runtime.get_program(ctx, "primitives/scan.cl", {"T": "int"})
    assert runtime.get_program(ctx, "primitives/scan.cl", {"T": "int"}) is a
    assert runtime.get_program(ctx, "primitives/scan.cl", {"T": "uint"}) is not a


def test_max_alloc_cap():
    with runtime.configure(max_alloc_bytes=1000):
        assert runtime.capabilities().max_alloc_bytes == 1000
        with pytest.raises(
            clvis.DeviceError,
            match=r"x: needs one buffer of 4000 bytes, more than the max single "
            r"allocation of 1000 bytes",
        ):
            clvis.scan(np.zeros(1000, np.int32))
        clvis.scan(np.zeros(250, np.int32))  # exactly at the cap
    with pytest.raises(ValueError, match="max_alloc_bytes"):
        runtime.set_options(max_alloc_bytes=0)


def test_beyond_device_alloc(device):
    """An input larger than the device's max single allocation gets a clear
    DeviceError naming the sizes before anything is allocated or run
    (np.zeros is only reserved address space until touched)."""
    q = runtime.queue_for(device)
    limit = runtime.capabilities(device).max_alloc_bytes
    x = np.zeros(limit // 4 + 1, np.int32)
    with pytest.raises(
        clvis.DeviceError,
        match=rf"x: needs one buffer of {x.nbytes} bytes.*"
        rf"allocation of {limit} bytes",
    ):
        clvis.scan(x, queue=q)


def test_tuning_profiles(device):
    expected = "gpu" if device.type & (cl.device_type.GPU | cl.device_type.ACCELERATOR) else "cpu"
    assert runtime.tuning_profile(device) == expected
    with runtime.configure(tuning="gpu"):
        assert runtime.tuning_profile(device) == "gpu"
    with pytest.raises(ValueError, match="tuning"):
        runtime.set_options(tuning="fast")


def test_default_queue():
    q = clvis.default_queue()
    assert isinstance(q, cl.CommandQueue) and clvis.default_queue() is q


def test_other_context_rejected(device):
    ctx = cl.Context([device])  # not clvis's context for this device
    x = cla.to_device(cl.CommandQueue(ctx), np.arange(10, dtype=np.int32))
    with pytest.raises(ValueError, match="x: the device array belongs to another OpenCL context"):
        clvis.scan(x, queue=runtime.queue_for(device))


def test_view_with_offset(device):
    q = runtime.queue_for(device)
    x = cla.to_device(q, np.arange(100, dtype=np.int32))[10:]
    np.testing.assert_array_equal(clvis.scan(x, False).get(), np.cumsum(np.arange(10, 100)))


def test_device_slug(device):
    slug = runtime.device_slug(device)
    assert re.fullmatch(r"[a-z0-9-]+", slug)


def test_every_kernel_file_documents_its_abi():
    """Each .cl file opens with its ABI comment, which names every kernel."""
    files = sorted(runtime.KERNEL_ROOT.glob("*/*.cl"))
    assert files
    for f in files:
        text = f.read_text()
        assert text.lstrip().startswith("/*"), f
        comment = text[: text.index("*/")]
        assert "ABI" in comment, f
        names = re.findall(r"^kernel\b[^;{]*?\bvoid\s+(\w+)\s*\(", text, re.MULTILINE | re.DOTALL)
        assert names, f
        for name in names:
            assert f"kernel {name}(" in comment, (f, name)


# -- the launch layer ----------------------------------------------------------


def test_local_size_and_items(device):
    q = runtime.queue_for(device)
    top = runtime.capabilities(q).max_work_group_size
    assert runtime.local_size(q, 64) == min(64, top)
    assert runtime.local_size(q, 0) == 1
    big = runtime.local_size(q, 4 * top)
    assert big <= top and big & (big - 1) == 0 or big == top
    assert runtime.items(q, 0, 64) == (64, 64)  # one group, never an empty launch
    assert runtime.items(q, 1, 64) == (64, 64)
    assert runtime.items(q, 65, 64) == (128, 64)
    g, local = runtime.items(q, 10, 4 * top)
    assert g % local == 0 and g >= 10 and local <= top


@pytest.mark.parametrize(
    "dtype, value",
    [
        (np.uint8, 0),
        (np.uint32, 0xFFFFFFFF),
        (np.int32, -1),
        (np.float32, np.inf),
        (np.uint64, 2**64 - 1),
        (np.float32, 1.5),
        (np.uint16, 0x1234),
    ],
)
def test_fill(device, dtype, value):
    q = runtime.queue_for(device)
    a = runtime.empty(q, 37, dtype, "fill test")
    a.set(np.arange(37).astype(dtype))
    runtime.fill(q, a, value, start=5)
    want = np.arange(37).astype(dtype)
    want[5:] = np.asarray(value).astype(dtype)
    np.testing.assert_array_equal(a.get(), want)
    runtime.fill_zero(q, a)
    assert not a.get().any()
    runtime.fill(q, a[:0], value)  # nothing to fill


def test_arg(device):
    q = runtime.queue_for(device)
    a = runtime.empty(q, 4, np.float32, "arg test")
    assert runtime.arg(None) is None
    assert runtime.arg(a[:0]) is None
    assert runtime.arg(a) is a.base_data and runtime.arg(a.base_data) is a.base_data


def test_exact_fp_is_a_known_flag(device):
    assert runtime.build_options(device, {}, runtime.EXACT_FP)[2:3] == list(runtime.EXACT_FP)


def test_triple():
    from clvis._arrays import triple

    assert triple("spacing", (1, 2, 3), positive=True) == (1.0, 2.0, 3.0)
    assert triple("origin", np.array([-1, 0, 1]), positive=False) == (-1.0, 0.0, 1.0)
    with pytest.raises(TypeError, match="spacing"):
        triple("spacing", "123", positive=True)  # not (1, 2, 3)
    with pytest.raises(TypeError, match="spacing"):
        triple("spacing", 1.0, positive=True)
    with pytest.raises(ValueError, match="spacing"):
        triple("spacing", (1, 2), positive=True)
    with pytest.raises(ValueError, match="spacing"):
        triple("spacing", (1, 0, 2), positive=True)
    with pytest.raises(ValueError, match="origin"):
        triple("origin", (1, np.nan, 2), positive=False)
    with pytest.raises(ValueError, match="origin"):
        triple("origin", (1, 1e39, 2), positive=False)  # not finite as float32


def test_capture_and_pinned(device):
    q = runtime.queue_for(device)
    native = runtime.capabilities(q).int64_atomics_native
    with runtime.configure(tuning="gpu", int64_atomics=False):
        cfg = runtime.capture(q)
    assert cfg.tuning == "gpu" and cfg.int64_atomics is False
    with runtime.configure(tuning="cpu", int64_atomics=True):
        assert runtime.tuning_profile(q) == "cpu"
        with runtime.pinned(cfg):
            assert runtime.tuning_profile(q) == "gpu"
            assert runtime.capabilities(q).int64_atomics is False
            assert "-DCLVIS_INT64_ATOMICS=1" not in runtime.build_options(device, {})
        assert runtime.tuning_profile(q) == "cpu"
        assert runtime.capabilities(q).int64_atomics == native


def test_event_seconds(device):
    q = runtime.queue_for(device)
    assert q.properties & cl.command_queue_properties.PROFILING_ENABLE
    a = runtime.empty(q, 1 << 16, np.uint32, "timing test")
    start = runtime.marker(q)
    clvis.scan(a, queue=q)
    end = runtime.marker(q)
    s = runtime.seconds(start, end)
    assert s is not None and 0 <= s < 60
    assert runtime.seconds(None) is None
    plain = cl.CommandQueue(q.context, device)  # a caller's queue without profiling
    assert runtime.seconds(runtime.marker(plain)) is None
    assert runtime.nbytes(a, None, a[:10]) == a.nbytes + 40


def test_check_memory(device):
    q = runtime.queue_for(device)
    runtime.check_memory(q, "a small image", device_bytes=1 << 20, host_bytes=1 << 20)
    avail = runtime.host_available_bytes()
    assert avail is None or avail > 0
    with pytest.raises(
        clvis.DeviceError, match=r"a huge image: needs .* GB on the device and .* GB on the host"
    ):
        runtime.check_memory(q, "a huge image", device_bytes=1 << 62)
    with pytest.raises(clvis.DeviceError, match="available"):
        runtime.check_memory(q, "a huge image", host_bytes=1 << 60)


def test_configure_is_per_thread_and_never_leaks():
    """Two threads' overlapping configure() blocks: each sees its own options
    for its whole block, the other thread (and the main one) never sees them,
    and after both the process's options are as before."""
    import threading

    before = runtime.options()
    barrier = threading.Barrier(2)
    seen: dict[str, list] = {"a": [], "b": []}

    def work(name, **changes):
        with runtime.configure(**changes):
            for _ in range(50):
                barrier.wait()
                seen[name].append(runtime.options())
                with runtime.configure(max_alloc_bytes=1 << 20):  # nested blocks
                    assert runtime.options().max_alloc_bytes == 1 << 20
                seen[name].append(runtime.options())
        seen[name].append(runtime.options())

    a = threading.Thread(target=work, args=("a",), kwargs={"int64_atomics": False})
    b = threading.Thread(target=work, args=("b",), kwargs={"tuning": "gpu"})
    a.start()
    b.start()
    a.join()
    b.join()
    assert all(not o.int64_atomics and o.tuning == before.tuning for o in seen["a"][:-1])
    assert all(o.int64_atomics == before.int64_atomics and o.tuning == "gpu" for o in seen["b"][:-1])
    assert seen["a"][-1] == before and seen["b"][-1] == before
    assert runtime.options() == before
    with runtime.configure(int64_atomics=False):
        runtime.set_options(tuning="cpu")  # inside a block: for the rest of the block
        assert runtime.options().tuning == "cpu"
    assert runtime.options() == before


def test_on_host(device):
    """clvis._arrays.on_host: a host result's plane as the numpy array it is;
    a device array is refused (never read back behind the caller's back)."""
    from clvis._arrays import on_host

    a = np.arange(6, dtype=np.float32)
    assert on_host(a) is a
    d = cla.to_device(runtime.queue_for(device), a)
    with pytest.raises(TypeError, match="expected a host \\(numpy\\) array, got Array"):
        on_host(d)


_SCALARS_CL = """
kernel void scalars(global uint *out, uchar a, int b, uint c, ulong d, float e, global const uint *maybe,
                    ushort f) {
    out[0] = a; out[1] = (uint)b; out[2] = c; out[3] = (uint)d; out[4] = (uint)(d >> 32);
    out[5] = as_uint(e); out[6] = maybe ? maybe[0] : 0xFFFFFFFFu; out[7] = f;
}
"""


def test_launch_types_scalars_once(device, tmp_path):
    """runtime.launch gives a kernel pyopencl's typed setter for the pattern of
    scalars it is launched with (the untyped one costs a C++ exception per
    try): the same bytes reach the kernel as through the untyped setter, a
    NULL buffer too, and a new pattern at the same positions re-types it."""
    src = tmp_path / "scalars.cl"
    src.write_text(_SCALARS_CL)
    q = runtime.queue_for(device)
    k = runtime.get_kernel(q, str(src), "scalars", {})
    out = cla.zeros(q, 8, np.uint32)
    one = cla.to_device(q, np.array([77], np.uint32))
    args = (np.uint8(200), np.int32(-5), np.uint32(0xDEADBEEF), np.uint64(2**63 + 9), np.float32(-1.25))
    want = [200, 2**32 - 5, 0xDEADBEEF, 9, 2**31, int(np.float32(-1.25).view(np.uint32))]
    for maybe, w in ((one.data, 77), (None, 0xFFFFFFFF)):
        runtime.launch(q, k, 1, 1, out.data, *args, maybe, np.uint16(7))
        assert out.get().tolist() == [*want, w, 7]
        # the untyped setter of a fresh kernel object gives the same
        plain = cl.Kernel(k.program, "scalars")
        plain.set_args(out.data, *args, maybe, np.uint16(7))
        cl.enqueue_nd_range_kernel(q, plain, (1,), (1,))
        assert out.get().tolist() == [*want, w, 7]
    assert k._clvis_arg_dtypes[1:3] == (np.dtype(np.uint8), np.dtype(np.int32))
    # another pattern: the int position as uint32, the uint one as int32 (same bits)
    runtime.launch(q, k, 1, 1, out.data, args[0], np.uint32(3), np.int32(-1), *args[3:], None, np.uint16(1))
    assert out.get().tolist()[1:3] == [3, 0xFFFFFFFF]
    assert k._clvis_arg_dtypes[2:4] == (np.dtype(np.uint32), np.dtype(np.int32))


@pytest.mark.parametrize(
    "shape", [(), (0,), (5,), 7, np.int64(3), (3, 4), (5, 1, 2), (2, 0, 3), (np.int64(4), np.uint32(3))]
)
def test_empty_is_cla_empty(device, shape):
    """runtime.empty builds its arrays with pyopencl's fast constructor: the
    same array as cla.empty from the pool (shape, C strides, size, flags...)."""
    q = runtime.queue_for(device)
    a = runtime.empty(q, shape, np.float32, "empty test")
    b = cla.empty(q, shape, np.float32, allocator=runtime.allocator(q))
    for name in (
        "shape",
        "strides",
        "size",
        "nbytes",
        "dtype",
        "offset",
        "queue",
        "context",
        "allocator",
        "events",
    ):
        assert getattr(a, name) == getattr(b, name), name
    assert type(a.size) is type(b.size) and all(type(s) is int for s in a.shape)
    assert (a.base_data is None) == (b.base_data is None)
    assert (a.flags.c_contiguous, a.flags.f_contiguous) == (b.flags.c_contiguous, b.flags.f_contiguous)
    if a.size:
        a.set(np.arange(a.size, dtype=np.float32).reshape(a.shape))
        np.testing.assert_array_equal(a.get().ravel(), np.arange(a.size))


@pytest.mark.parametrize("shape", [(-1,), (2.0,), (True,), (3, -2)])
def test_empty_bad_shape(device, shape):
    q = runtime.queue_for(device)
    with pytest.raises(ValueError):
        runtime.empty(q, shape, np.float32, "empty test")


def test_free_held_gives_back_only_the_freed_blocks(device):
    """runtime.free_held(queue): the queue's pool gives the blocks it kept
    back from freed arrays to the driver; arrays in use stay as they were."""
    q = runtime.queue_for(device)
    pool = runtime.allocator(q)
    keep = runtime.empty(q, 1000, np.float32, "free_held test")
    keep.set(np.arange(1000, dtype=np.float32))
    gone = runtime.empty(q, 3000, np.float32, "free_held test")
    active = pool.active_blocks
    del gone
    assert pool.held_blocks >= 1 and pool.active_blocks == active - 1
    runtime.free_held(q)
    assert pool.held_blocks == 0 and pool.active_blocks == active - 1
    np.testing.assert_array_equal(keep.get(), np.arange(1000, dtype=np.float32))


def test_free_held_trims_the_c_heap(device, monkeypatch):
    """A CPU device's buffers are host memory: freed, glibc kept their pages
    in its heap (a viewer grew 4 MB a window size). free_held trims it."""
    from clvis.runtime import memory

    calls = []
    monkeypatch.setattr(memory, "trim_heap", lambda: calls.append(1) or True)
    q = runtime.queue_for(device)
    gone = runtime.empty(q, 3000, np.float32, "free_held test")
    del gone
    runtime.free_held(q)
    assert calls == [1]


_TRIM = """
import ctypes, os, sys
from clvis.runtime import memory

libc = ctypes.CDLL(None)
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]

def rss():
    return int(open("/proc/self/statm").read().split()[1]) * os.sysconf("SC_PAGE_SIZE")

libc.free(libc.malloc(16 << 20))  # a large block freed: glibc's mmap threshold rises to it (<= 32 MB)
blocks = [libc.malloc(2 << 20) for _ in range(60)]  # now from the heap, as a pool's buffers were
for b in blocks:
    ctypes.memset(b, 1, 2 << 20)
for b in blocks[::2]:  # every other one freed: holes between live blocks, which only a trim gives back
    libc.free(b)
before = rss()
assert memory.trim_heap()
print(before - rss())
"""


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or os.confstr("CS_GNU_LIBC_VERSION") is None,
    reason="malloc_trim is glibc's",
)
def test_trim_heap_gives_freed_heap_pages_back():
    # glibc's defaults (a LocalCluster's nanny set MALLOC_TRIM_THRESHOLD_ in a
    # test process's environment before clvis put it back; a fixed threshold
    # turns off the dynamic mmap threshold this relies on)
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    out = subprocess.run([sys.executable, "-c", _TRIM], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout) > 40 << 20  # of the 60 MB freed (0 without the trim)


_SIGACTION = """
import ctypes, signal, sys

class SA(ctypes.Structure):  # glibc's struct sigaction: the handler first
    _fields_ = [("handler", ctypes.c_void_p), ("mask", ctypes.c_ulong * 16), ("flags", ctypes.c_int),
                ("restorer", ctypes.c_void_p)]

libc = ctypes.CDLL(None)

def installed(sig):
    sa = SA()
    assert libc.sigaction(int(sig), None, ctypes.byref(sa)) == 0
    return sa.handler, sa.flags & 0xFFFFFFFF
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads glibc's struct sigaction")
@pytest.mark.parametrize(
    "setup",
    [
        "signal.signal(signal.SIGTERM, lambda s, f: None)",  # Python's handlers
        # a handler Python does not know of (signal.getsignal says SIG_DFL): kept too
        "import faulthandler; faulthandler.register(signal.SIGTERM)",
    ],
)
def test_opening_devices_keeps_pythons_signal_handlers(setup):
    """PoCL (loaded by platform enumeration) and Intel's CPU runtime (at its
    first context) put one-shot (SA_RESETHAND) SIGINT / SIGTERM handlers in
    front of Python's: a second signal while the first was being passed on
    ended the process by the default action, mid-write (`clvis gauss` left
    its .gauss.png.<random>.tmp, 2 of 8 times signalled as `timeout` does:
    the process, then its group). clvis puts Python's back."""
    code = _SIGACTION + (
        "import signal, clvis\n"
        f"{setup}\n"
        "before = {s: installed(s) for s in (signal.SIGINT, signal.SIGTERM)}\n"
        "from clvis import runtime\n"
        "for d in runtime.devices():\n"
        "    runtime.queue_for(d)\n"
        "runtime.default_queue()\n"
        "after = {s: installed(s) for s in (signal.SIGINT, signal.SIGTERM)}\n"
        "print(len(runtime.devices()), before == after, before, after)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    n, same, *rest = out.stdout.split(" ", 2)
    assert int(n) >= 1 and same == "True", out.stdout
