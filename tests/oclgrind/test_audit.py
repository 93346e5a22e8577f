"""The Oclgrind audit's own logic (tests/oclgrind/audit.py): the kernel list,
the benign-race markers and how reports are judged, on Oclgrind's output
format; and, where Oclgrind is installed, one small case through it."""

import importlib.util
import re
import shutil
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("clvis_oclgrind_audit", HERE / "audit.py")
audit = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = audit  # dataclasses look their module up there
_spec.loader.exec_module(audit)

KERNELS_CL = audit.KERNELS_CL


def test_kernel_list_is_every_kernel():
    found = audit.kernel_files()
    for path in sorted(KERNELS_CL.glob("*/*.cl")):
        if path.parent.name == "include":
            continue
        text = audit._strip_comments(path.read_text())
        n = len(re.findall(r"\bkernel\b", text))
        names = [k for k, p in found.items() if p == path]
        assert len(names) == n > 0, (path, names)
    assert {
        "bvh_build",
        "render_visibility",
        "render_depth",
        "render_index",
        "scan_chained",
        "copy_bytes",
        "march",
        "cache_candidate_keys",
    } <= set(found)


def test_marked_lines_cover_the_block_a_marker_opens():
    text = """kernel void k(global int *a)
{
    /* benign race (t1): why */
    int x = a[0];
    if (x) {
        a[1] = x;
    }
}
/* benign race (t2): why */
inline void f(global int *a)
{
    a[0] = 1;
}

inline void g(global int *a) { a[0] = 2; }
    int y = a[2];   /* benign race (t3) */
int z;"""
    m = audit.marked_lines(text)
    assert {k for k, v in m.items() if "t1" in v} == {3, 4, 5, 6, 7}
    assert {k for k, v in m.items() if "t2" in v} == {9, 10, 11, 12, 13}
    assert {k for k, v in m.items() if "t3" in v} == {16}


def _line_of(path: Path, needle: str) -> int:
    lines = path.read_text().splitlines()
    hits = [i + 1 for i, s in enumerate(lines) if needle in s]
    assert len(hits) == 1, (path, needle, hits)
    return hits[0]


def test_known_benign_races_are_marked():
    """The lines Oclgrind reports for the documented races carry their
    markers (moving code away from its comment breaks the audit, and this
    says so without Oclgrind)."""
    src = audit.Sources()
    render = KERNELS_CL / "raster/render.cl"
    atomics = KERNELS_CL / "include/clvis/atomics.h"
    bvh = KERNELS_CL / "gauss/bvh.cl"
    assert "early-z" in src.tags(render, _line_of(render, "if (dkey > words[clvis_hi_word(p)])"))
    assert "early-z" in src.tags(atomics, _line_of(atomics, "atomic_min(p, v);"))
    assert "early-z" in src.tags(atomics, _line_of(atomics, "atom_min(p, v);"))
    for needle in (
        "slo = (float3)(vnodes[sword]",
        "shi = (float3)(vnodes[sword]",
        "node->lo[0] = lo.x;",
        "node->hi[0] = hi.x;",
    ):
        assert "lbvh-sibling" in src.tags(bvh, _line_of(bvh, needle)), needle
    # iso-skip: raytrace.cl's plain read of the hit key's high word against
    # the 64-bit atomic min (clvis_atomic_min_u64's atom_min)
    raytrace = KERNELS_CL / "iso/raytrace.cl"
    read = _line_of(raytrace, "const float t_best = as_float(((volatile global uint *)hitkey)")
    assert "iso-skip" in src.tags(raytrace, read)
    read8 = _line_of(raytrace, "ltstop[k] = on ? as_float(((volatile global uint *)hitkey)")  # PACKET=8
    assert "iso-skip" in src.tags(raytrace, read8)
    assert "iso-skip" in src.tags(atomics, _line_of(atomics, "atom_min(p, v);"))
    # the early-z read only: the MODE_INDEX read has no concurrent writer
    assert not src.tags(render, _line_of(render, "if (dkey == words[clvis_hi_word(p)])"))


def _race(a_file, a_line, b_file, b_line, kernel="render_visibility", src_text=""):
    return f"""
Read-write data race at global memory address 0x1200000000002bc
\tKernel: {kernel}
\t
\tFirst entity:  Global(1,0,0) Local(0,0,0) Group(1,0,0)
\t  %call = call spir_func i64 @_Z8atom_minPU3AS1Vmm(i64 addrspace(1)* noundef %0, i64 noundef %1)
\tAt line {a_line} (column 5) of {a_file}:
\t  (source not available)
\t
\tSecond entity: Global(0,0,0) Local(0,0,0) Group(0,0,0)
\t  %2 = load volatile i32, i32 addrspace(1)* %arrayidx, align 4
\tAt line {b_line} (column 13) of {b_file}:
\t  {src_text}
\t
"""


def _render_lines():
    render = KERNELS_CL / "raster/render.cl"
    atomics = KERNELS_CL / "include/clvis/atomics.h"
    read = _line_of(render, "if (dkey > words[clvis_hi_word(p)])")
    amin = _line_of(atomics, "atom_min(p, v);")
    return render, read, amin


def test_header_paths_resolve_to_kernels_cl_include():
    """A header is named by the path the build included it from: the
    checkout's kernels_cl/include, or clvis.runtime's -I copy of it
    (clvis-include-<uid>-<hash>/, absolute or relative)."""
    src = audit.Sources()
    want = audit.KERNELS_CL / "include" / "clvis" / "atomics.h"
    for name in (
        "/tmp/clvis-include-0-0123456789abcdef/clvis/atomics.h",
        "clvis-include-0-0123456789abcdef/clvis/atomics.h",
        "/elsewhere/kernels_cl/include/clvis/atomics.h",
    ):
        assert src.resolve("render_visibility", name) == want, name
    assert src.resolve("render_visibility", "clvis-include-0-x/clvis/nope.h") is None


def test_judge_races():
    src = audit.Sources()
    render, read, amin = _render_lines()
    text = render.read_text().splitlines()[read - 1].strip()
    unmarked = _line_of(render, "vstore3(lo, 0, bounds + 6 * b);")
    log = "\n".join(
        [
            "@@case rasterize",
            _race("kernels_cl/include/clvis/atomics.h", amin, "input.cl", read, src_text=text),
            _race("/somewhere/kernels_cl/include/clvis/atomics.h", amin, "input.cl", unmarked),
            _race(
                "kernels_cl/include/clvis/atomics.h", amin, "input.cl", 0, src_text="(source not available)"
            ),
            # the right line number, but Oclgrind shows other source: not this file
            _race("kernels_cl/include/clvis/atomics.h", amin, "input.cl", read, src_text="x = 1;"),
            "@@case (end)",
        ]
    )
    out = audit.parse(log)
    assert not out.stray and not out.errors
    assert [d.case for d in out.diagnostics] == ["rasterize"] * 4
    verdicts = [audit.judge(src, d) for d in out.diagnostics]
    assert verdicts[0][0] == "benign" and verdicts[0][2] == "early-z"
    assert "raster/render.cl:" in verdicts[0][1] and "clvis/atomics.h:" in verdicts[0][1]
    assert [v[0] for v in verdicts[1:]] == ["fail", "fail", "fail"]
    assert "(no source line)" in verdicts[2][1]
    assert "another line" in verdicts[3][1]
    # tags must agree: an early-z access racing with an lbvh-sibling one is not benign
    bvh = KERNELS_CL / "gauss/bvh.cl"
    store = _line_of(bvh, "node->lo[0] = lo.x;")
    d = audit.parse(
        _race(
            "kernels_cl/gauss/bvh.cl", store, "kernels_cl/include/clvis/atomics.h", amin, kernel="bvh_build"
        )
    ).diagnostics[0]
    assert audit.judge(src, d)[0] == "fail"


def test_judge_other_diagnostics():
    src = audit.Sources()
    log = """@@case copy

Invalid write of size 4 at global memory address 0x2000000000044
\tKernel: copy_bytes
\tEntity: Global(3,0,0) Local(3,0,0) Group(0,0,0)
\t  store i32 5, i32 addrspace(1)* %arrayidx7, align 4
\tAt line 7 (column 39) of input.cl:
\t  x
\t

Oclgrind - OpenCL runtime error detected
\tFunction: clGetDeviceInfo
\tError:    CL_INVALID_VALUE
\tFor argument 'param_name'


Oclgrind - OpenCL runtime error detected
\tFunction: clEnqueueNDRangeKernel
\tError:    CL_INVALID_WORK_GROUP_SIZE
\tlocal size does not divide global size

Work-group divergence detected (barrier):
\tKernel: copy_bytes
@@error {"case": "copy", "traceback": "Traceback ...\\nValueError: x"}
something else
@@launched {"copy_bytes": 2}
"""
    out = audit.parse(log)
    # any line of unknown form starts a diagnostic of its own, which fails
    assert [d.header for d in out.diagnostics][-1] == "something else"
    assert [audit.judge(src, d)[0] for d in out.diagnostics] == ["fail", "ignored", "fail", "fail", "fail"]
    assert [d.kind for d in out.diagnostics] == ["invalid access", "api", "api", "other", "other"]
    assert out.errors == [("copy", "Traceback ...\nValueError: x")]
    assert out.launched == {"copy_bytes": 2}


def test_which_cases_run_again_without_int64_atomics():
    """The no-int64 configurations skip a case only when its programs do not
    read CLVIS_INT64_ATOMICS (outside the primitives, whose own cases run in
    every configuration)."""
    files = audit.kernel_files()
    reads = {p.relative_to(KERNELS_CL).as_posix() for p in set(files.values()) if audit.reads_int64_define(p)}
    # through clvis/atomics.h (iso, raster) or in the file itself (scan)
    assert {"raster/render.cl", "iso/raytrace.cl", "iso/pass.cl", "primitives/scan.cl"} <= reads
    assert not reads & {"gauss/tiles.cl", "gauss/bvh.cl", "raster/edl.cl", "primitives/radix_sort.cl"}
    need = audit.needs_no_int64
    assert need(["batch_bounds", "render_visibility"], files)  # raster: another kernel without
    assert need(["raytrace_blocks", "scan_chained"], files)
    assert need(["scan_chained"], files) and need(["radix_upsweep", "scan_reduce"], files)
    assert not need(["tile_count", "scan_chained", "tile_render8"], files)  # gauss_tiles
    assert not need(["edl"], files)
    assert need(["no_such_kernel"], files)
    # the host code that reads the option lies in those families: a module
    # that starts reading it beside kernels that do not fails here
    pkg = KERNELS_CL.parent / "clvis"
    readers = {
        p.relative_to(pkg).as_posix()
        for p in pkg.rglob("*.py")
        if "int64_atomics" in p.read_text() and p.parts[-2] not in ("runtime", "cli")
    }
    assert readers == {"primitives.py", "raster/render.py", "iso/render.py"}, readers


def test_case_kernels_are_parsed():
    out = audit.parse('@@case scan\n@@case-kernels {"scan": ["scan_chained", "scan_reduce"]}\n')
    assert out.case_kernels == {"scan": ["scan_chained", "scan_reduce"]} and not out.stray


def test_outputs_of_several_workloads_merge():
    a = audit.parse(
        '@@case scan\n@@time scan 1.5\n@@launched {"scan_reduce": 2}\n'
        '@@case-kernels {"scan": ["scan_reduce"]}\n'
    )
    b = audit.parse(
        '@@case copy\n@@error {"case": "copy", "traceback": "x"}\n'
        '@@launched {"scan_reduce": 1, "copy_bytes": 3}\n'
    )
    m = audit.merge([a, b])
    assert m.launched == {"scan_reduce": 3, "copy_bytes": 3}
    assert m.seconds == {"scan": 1.5} and m.errors == [("copy", "x")]
    assert m.case_kernels == {"scan": ["scan_reduce"]}
    # a workload that never said what it launched (it crashed): the merge says so too
    assert audit.merge([a, audit.parse("@@case scan\n")]).launched is None
    assert audit.case_names()[:3] == ["scan", "compact", "radix_sort"] and len(audit.case_names()) >= 18


@pytest.mark.skipif(shutil.which("oclgrind") is None, reason="Oclgrind is not installed")
def test_one_case_under_oclgrind(capsys):
    """The whole path on the smallest case: preload, the Oclgrind platform
    alone, launches recorded, nothing reported."""
    assert audit.main(["--config", "cpu:int64", "--case", "copy"]) == 0
    out = capsys.readouterr().out
    assert "oclgrind audit: passed" in out and "1 kernels launched" in out
    # two workloads share the cases, one each here: copy's kernel ran in one, and a name
    # cases.py lacks is an error of the other
    assert audit.main(["--config", "cpu:int64", "--case", "copy", "--case", "nonesuch", "-j", "2"]) == 1
    out = capsys.readouterr().out
    assert "case nonesuch raised" in out and "1 kernels launched" in out
