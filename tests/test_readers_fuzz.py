"""Mutated files for every reader: each read either succeeds or raises a clvis
error (a ClvisError), in a child process under an address-space limit, so a
crash (a signal such as lazrs's SIGABRT on a failed allocation) or a
MemoryError shows up as a failed case instead of killing or exhausting pytest.

The files are generated here (no data files in the repository) and mutated with
a fixed seed: random bytes, extreme integers written into the header region,
huge numbers in text headers, truncation. One child process reads all the
cases and reports one JSON line per case; after a crash the remaining cases
run in a fresh child.
"""

import gzip
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fuzz.seeds import _cloud, _las, _vdb

from clvis.io import save_npz, write_ply

laspy = pytest.importorskip("laspy")
nibabel = pytest.importorskip("nibabel")
tinyvdb = pytest.importorskip("tinyvdb")

LIMIT_BYTES = 1536 << 20  # RLIMIT_AS of the child: 1.5 GiB
# CLVIS_FUZZ_SCALE=10 runs ten times the cases (a longer search, by hand)
SCALE = int(os.environ.get("CLVIS_FUZZ_SCALE", "1"))
ROOT = Path(__file__).resolve().parents[1]

# The child: imports first (they map shared libraries), then the limit, then the cases.
CHILD = r"""
import json, resource, sys
import clvis.io, clvis.io.volumes, clvis.gauss.sparse, clvis.gauss.gaussians
import laspy, lazrs, nibabel, plyfile, tinyvdb
from clvis.errors import ClvisError
from fuzz.harness import _memory_error as memory_error
limit = int(sys.argv[2])
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
readers = {"points": clvis.io.read_points, "volume": clvis.io.volumes.read_volume,
           "vdb": clvis.gauss.sparse.read_vdb, "gaussians": clvis.gauss.gaussians.Gaussians.load}
cases = json.load(open(sys.argv[1]))
start = int(sys.argv[3])

for i in range(start, len(cases)):
    kind, path = cases[i]
    print(json.dumps({"i": i, "start": True}), flush=True)
    try:
        readers[kind](path)
        out = {"i": i, "outcome": "ok"}
    except ClvisError as e:
        named = path in str(e)
        if memory_error(e):
            out = {"i": i, "outcome": "memory", "detail": repr(e)[:300]}
        else:
            out = {"i": i, "outcome": "clvis" if named else "unnamed", "detail": repr(e)[:300]}
    except BaseException as e:
        out = {"i": i, "outcome": "other", "detail": f"{type(e).__name__}: {e}"[:300]}
    print(json.dumps(out), flush=True)
# VmHWM: this process's own peak (ru_maxrss keeps the parent's across exec)
with open("/proc/self/status") as f:
    print(json.dumps({"maxrss_kb": int(next(l.split()[1] for l in f if l.startswith("VmHWM:")))}), flush=True)
"""


# ---------------------------------------------------------------- base files
# (made by tests/fuzz/seeds.py's _cloud, _las and _vdb, as the fuzzer's seeds)


def _bases(tmp):
    """[(name, kind, suffix, bytes, header_bytes, cases)]: header_bytes is where the
    integer mutations go."""
    out = []

    def add(name, kind, suffix, head, cases):
        data = (tmp / f"{name}{suffix}").read_bytes()
        out.append((name, kind, suffix, data, min(head, len(data)), cases))

    write_ply(tmp / "bin.ply", _cloud(12))
    add("bin", "points", ".ply", 400, 40)
    write_ply(tmp / "txt.ply", _cloud(6, seed=1), text=True)
    add("txt", "points", ".ply", 400, 25)
    start = _las(tmp / "las3.las", 30, 3)
    add("las3", "points", ".las", start + 20, 40)
    start = _las(tmp / "laz3.laz", 60, 3)
    add("laz3", "points", ".laz", start + 60, 70)
    start = _las(tmp / "laz7.laz", 60, 7)
    add("laz7", "points", ".laz", start + 80, 70)
    np.save(tmp / "arr.npy", np.random.default_rng(2).normal(size=(20, 3)).astype(np.float32))
    add("arr", "points", ".npy", 128, 30)
    save_npz(tmp / "cloud.npz", _cloud(10, seed=3))
    add("cloud", "points", ".npz", 4096, 30)
    rng = np.random.default_rng(4)
    np.savez(tmp / "gauss.npz", means=rng.normal(size=(5, 3)), scales=rng.random((5, 3)))
    add("gauss", "gaussians", ".npz", 4096, 20)
    np.save(tmp / "vol.npy", rng.random((4, 5, 6)))
    add("vol", "volume", ".npy", 128, 20)
    nibabel.save(nibabel.Nifti1Image(rng.random((6, 5, 4)).astype(np.float32), np.eye(4)), tmp / "vol.nii")
    add("vol", "volume", ".nii", 352, 50)
    (tmp / "volz.nii.gz").write_bytes(gzip.compress((tmp / "vol.nii").read_bytes()[:352] + bytes(480)))
    add("volz", "volume", ".nii.gz", 1 << 20, 10)
    _vdb(tmp, tmp / "grid.vdb")
    add("grid", "vdb", ".vdb", 1 << 20, 60)
    return out


_EXTREMES = [
    0,
    1,
    0x7F,
    0x80,
    0xFF,
    0x7FFF,
    0xFFFF,
    0x7FFFFFFF,
    0x80000000,
    0xFFFFFFFF,
    0xFFFF0001,
    1 << 40,
    (1 << 63) - 1,
    (1 << 64) - 1,
]


def _mutate(rng, data, head, suffix):
    b = bytearray(data)
    if suffix == ".nii.gz":  # mutate the decompressed header, then compress
        raw = bytearray(gzip.decompress(data))
        return gzip.compress(bytes(_mutate(rng, raw, 352, ".nii")))
    mode = rng.integers(0, 5)
    if mode == 0:  # random bytes anywhere
        for _ in range(rng.integers(1, 5)):
            b[rng.integers(0, len(b))] = rng.integers(0, 256)
    elif mode in (1, 2):  # an extreme integer in the header region
        width = (2, 4, 8)[rng.integers(0, 3)]
        at = int(rng.integers(0, max(1, head - width)))
        value = _EXTREMES[rng.integers(0, len(_EXTREMES))] & ((1 << 8 * width) - 1)
        b[at : at + width] = value.to_bytes(width, "little")
    elif mode == 3:  # a huge, negative or zero number in a text header
        text = bytes(b[:head])
        numbers = list(re.finditer(rb"\d+", text))
        if not numbers:
            return _mutate(rng, data, head, suffix)
        m = numbers[rng.integers(0, len(numbers))]
        new = [b"9" * 12, b"9" * 40, b"-1", b"0", b"4294967296", b"1e300"][rng.integers(0, 6)]
        b[m.start() : m.end()] = new
        if suffix == ".npy":  # keep the header length field consistent
            return bytes(b)
    else:  # truncation, or the tail cut off
        b = b[: rng.integers(0, len(b))]
    return bytes(b)


def _run(cases_path, n, tmp):
    """Run the child from case 0, restarting after a crash; {i: outcome}."""
    results, crashes, start = {}, {}, 0
    maxrss = []
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "tests"), os.environ.get("PYTHONPATH", "")]),
    )
    while start < n:
        proc = subprocess.run(
            [sys.executable, "-c", CHILD, str(cases_path), str(LIMIT_BYTES), str(start)],
            capture_output=True,
            text=True,
            env=env,
            timeout=300,
        )
        last = None
        for line in proc.stdout.splitlines():
            rec = json.loads(line)
            if "maxrss_kb" in rec:
                maxrss.append(rec["maxrss_kb"])
            elif "start" in rec:
                last = rec["i"]
            else:
                results[rec["i"]] = rec
        if proc.returncode == 0:
            break
        if last is None or last in results:  # died before or between cases
            pytest.fail(f"the fuzz child failed outside a case (rc {proc.returncode}): {proc.stderr[-2000:]}")
        crashes[last] = {
            "i": last,
            "outcome": "crash",
            "detail": f"rc {proc.returncode}: {proc.stderr[-300:]}",
        }
        start = last + 1
    results.update(crashes)
    return results, maxrss


def test_mutated_files_raise_only_clvis_errors(tmp_path):
    base_dir = tmp_path / "base"
    base_dir.mkdir()
    bases = _bases(base_dir)
    rng = np.random.default_rng(20261123)
    cases, labels = [], []
    for name, kind, suffix, data, head, count in bases:
        for j in range(count * SCALE):
            path = tmp_path / f"{name}-{j}{suffix}"
            path.write_bytes(_mutate(rng, data, head, suffix))
            cases.append((kind, str(path)))
            labels.append(f"{name}{suffix} #{j}")
        # the unmutated file reads
        cases.append((kind, str(base_dir / f"{name}{suffix}")))
        labels.append(f"{name}{suffix} (unmutated)")
    cases_path = tmp_path / "cases.json"
    cases_path.write_text(json.dumps(cases))
    results, maxrss = _run(cases_path, len(cases), tmp_path)
    assert len(results) == len(cases)
    bad = [
        f"{labels[i]}: {r['outcome']}: {r.get('detail', '')}"
        for i, r in sorted(results.items())
        if r["outcome"] not in ("ok", "clvis") or ("unmutated" in labels[i] and r["outcome"] != "ok")
    ]
    counts = {}
    for i, r in results.items():
        key = (labels[i].split(" ")[0], r["outcome"])
        counts[key] = counts.get(key, 0) + 1
    print(f"{len(cases)} cases: {sorted(counts.items())}; child max RSS {max(maxrss, default=0) // 1024} MiB")
    assert not bad, f"{len(bad)} of {len(cases)} cases failed:\n" + "\n".join(bad[:40])
