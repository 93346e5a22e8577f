"""Run every kernel of every family under Oclgrind and fail on what it finds.

    python tests/oclgrind/audit.py [--jobs N] [--config cpu:int64 ...] [--case NAME ...]
                                   [--log-dir DIR]

(``./dev.sh oclgrind`` runs it with the test environment.) Each configuration
(tuning profile "cpu" or "gpu" × 64-bit atomics on or off) runs
tests/oclgrind/cases.py as

    oclgrind --data-races --check-api --build-options -cl-opt-disable python cases.py TUNING ATOMICS

Oclgrind's library is preloaded into Python, so pyopencl sees the Oclgrind
simulator as its only platform (cases.py checks that). Every kernel is
interpreted work-item by work-item; Oclgrind reports on stderr each invalid
memory access, each data race (a non-atomic access and another access to the
same byte, at least one a write, from two work-items with no barrier between
them) and each OpenCL API error. Programs are built with -cl-opt-disable so
that every reported access carries its source line (the optimiser merges
loads across branches and gives them line 0), and pyopencl's binary cache is
off (PYOPENCL_NO_CACHE) so that the flag reaches every build.

The run fails (exit 1) on:

- an invalid access, or any diagnostic other than a data race (Oclgrind's
  divergence, alignment and array-bounds checks report this way too);
- a data race that is not documented as benign (below);
- an API error, except clGetDeviceInfo answering CL_INVALID_VALUE for
  'param_name': pyopencl and clvis.runtime ask for vendor properties
  (NVIDIA's, AMD's, OpenCL 2.x ones) that Oclgrind does not have, and handle
  the error;
- a case that raised, a workload that exited non-zero, unrecognised output;
- (a full run only) a kernel of kernels_cl/<family>/*.cl that no
  configuration launched, so a new kernel cannot slip past the audit.

The 64-bit atomics off configurations run only the cases whose device code
changes with them (unless --case names the cases): a configuration with them
off runs after the one with them on and the same tuning, and takes from it
the kernels each case launched. A case runs again when one of its kernels
lies in a file that reads CLVIS_INT64_ATOMICS (in its text or a header it
includes) outside kernels_cl/primitives, or when all its kernels lie in
kernels_cl/primitives (the primitives' own cases: scan's chained and
reduce-then-scan paths are theirs to cover, in every configuration). The
other cases build the same programs (the define is read nowhere in them) on
the same inputs, so a second run would repeat the first; the summary names
them.

Documented benign races. A comment in the kernel source containing
``benign race (TAG)`` marks the block it opens: the line it starts on and
the following ones, up to the first blank line or the first line indented
less than the marker's (the end of the enclosing block). A race is benign when both of its
accesses lie on lines marked with the same TAG, in the kernel's own .cl file
or a header it includes (the explanation of why belongs in that comment). An
access Oclgrind reports without a source line never matches.

Oclgrind's --uninitialized check is not used: Oclgrind 21.10 crashes with it
on most of the cases, and flags counters the host zeroed with
clEnqueueFillBuffer as uninitialised.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from collections import defaultdict, deque
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
KERNELS_CL = REPO / "kernels_cl"
CASES_PY = HERE / "cases.py"
CONFIGS = [("cpu", "int64"), ("gpu", "int64"), ("cpu", "no-int64"), ("gpu", "no-int64")]
OCLGRIND_ARGS = ["--data-races", "--check-api", "--build-options", "-cl-opt-disable"]

MARKER = re.compile(r"benign race \(([a-z0-9-]+)\)")
_KERNEL_DEF = re.compile(r"\bkernel\s+(?:__attribute__\s*\(\(.*?\)\)\s*)*void\s+(\w+)\s*\(", re.DOTALL)
_RACE = re.compile(r"^(Read-write|Write-write) data race at (global|local) memory address")
_INVALID = re.compile(r"^Invalid (read|write) of size")
_API = "Oclgrind - OpenCL runtime error detected"
_AT = re.compile(r"^At line (\d+) \(column (\d+)\) of (.+):$")
MARK_TIME = "@@time"  # cases.py's line after each case


# ---------------------------------------------------------------------------
# the sources: kernels and benign-race markers


def _strip_comments(text: str) -> str:
    """C comments replaced by spaces (newlines kept, so offsets and lines stay)."""
    return re.sub(r"/\*.*?\*/|//[^\n]*", lambda m: re.sub(r"[^\n]", " ", m.group(0)), text, flags=re.DOTALL)


def kernel_files(root: Path = KERNELS_CL) -> dict[str, Path]:
    """Every kernel of kernels_cl/<family>/*.cl → its file. Kernel names are
    unique across the tree (the audit maps Oclgrind's reports by name)."""
    out: dict[str, Path] = {}
    for path in sorted(root.glob("*/*.cl")):
        if path.parent.name == "include":
            continue
        for name in _KERNEL_DEF.findall(_strip_comments(path.read_text())):
            if name in out and out[name] != path:
                raise SystemExit(f"audit: kernel {name} is defined in {out[name]} and {path}")
            out[name] = path
    return out


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def marked_lines(text: str) -> dict[int, set[str]]:
    """1-based line → the tags of the benign-race markers covering it. A
    marker covers the block it opens: the line it is on and the following
    ones, up to the first blank line or the first line indented less than
    the marker's line (the end of the enclosing block)."""
    lines = text.splitlines()
    out: dict[int, set[str]] = defaultdict(set)
    for i, line in enumerate(lines):
        for tag in MARKER.findall(line):
            base = _indent(line)
            j = i
            while j < len(lines) and lines[j].strip() and _indent(lines[j]) >= base:
                out[j + 1].add(tag)
                j += 1
    return dict(out)


_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.MULTILINE)
INT64_DEFINE = "CLVIS_INT64_ATOMICS"


def reads_int64_define(path: Path, root: Path = KERNELS_CL, _seen: set[Path] | None = None) -> bool:
    """Whether `path`'s program reads CLVIS_INT64_ATOMICS: its own text or a
    header it includes (from kernels_cl/include, transitively)."""
    seen = _seen if _seen is not None else set()
    if path in seen or not path.is_file():
        return False
    seen.add(path)
    text = _strip_comments(path.read_text())
    if INT64_DEFINE in text:
        return True
    return any(reads_int64_define(root / "include" / inc, root, seen) for inc in _INCLUDE.findall(text))


def needs_no_int64(kernels: list[str], files: dict[str, Path], root: Path = KERNELS_CL) -> bool:
    """Whether a case that launched `kernels` (with 64-bit atomics on) must
    run again with them off (see the module's docstring)."""
    prims = root / "primitives"
    paths = [files.get(k) for k in kernels]
    if any(p is None for p in paths):
        return True  # a kernel the tree does not define: never skip what we cannot place
    if all(p.parent == prims for p in paths):
        return True
    return any(p.parent != prims and reads_int64_define(p, root) for p in paths)


class Sources:
    """Kernel files, marker tables (read once per file) and line texts."""

    def __init__(self, root: Path = KERNELS_CL):
        self.root = root
        self.kernels = kernel_files(root)
        self._text: dict[Path, list[str]] = {}
        self._marks: dict[Path, dict[int, set[str]]] = {}

    def resolve(self, kernel: str, file: str) -> Path | None:
        """The file an Oclgrind location names: input.cl is the kernel's
        program source; headers are named by their include path (the -I
        copy's, clvis-include-<uid>-<hash>/..., maps to kernels_cl/include)."""
        if file == "input.cl":
            return self.kernels.get(kernel)
        m = re.search(r"(?:^|/)clvis-include-[^/]+/(.+)$", file)
        if m:  # the build's -I copy of kernels_cl/include (clvis.runtime.program)
            p = self.root / "include" / m.group(1)
        elif "kernels_cl/" in file:
            p = self.root / file.rsplit("kernels_cl/", 1)[1]
        else:
            p = Path(file)
        return p if p.is_file() else None

    def _load(self, path: Path) -> None:
        if path not in self._text:
            text = path.read_text()
            self._text[path] = text.splitlines()
            self._marks[path] = marked_lines(text)

    def line(self, path: Path, n: int) -> str:
        self._load(path)
        lines = self._text[path]
        return lines[n - 1] if 1 <= n <= len(lines) else ""

    def tags(self, path: Path, n: int) -> set[str]:
        self._load(path)
        return self._marks[path].get(n, set())

    def all_tags(self) -> dict[str, list[str]]:
        """tag → the places (file:line) of its markers, over the whole tree."""
        out: dict[str, list[str]] = defaultdict(list)
        for path in sorted(self.root.rglob("*")):
            if path.suffix in (".cl", ".h") and path.is_file():
                for i, line in enumerate(path.read_text().splitlines()):
                    for tag in MARKER.findall(line):
                        out[tag].append(f"{path.relative_to(REPO)}:{i + 1}")
        return dict(out)


# ---------------------------------------------------------------------------
# Oclgrind's output


@dataclasses.dataclass
class Access:
    entity: str  # "Global(3,0,0) Local(3,0,0) Group(0,0,0)"
    instruction: str
    file: str | None = None  # as Oclgrind names it
    line: int = 0
    source: str = ""  # the text Oclgrind shows (headers: unreliable)


@dataclasses.dataclass
class Diagnostic:
    header: str
    body: list[str]
    case: str
    kernel: str = ""
    accesses: list[Access] = dataclasses.field(default_factory=list)

    @property
    def kind(self) -> str:
        if _RACE.match(self.header):
            return "race"
        if _INVALID.match(self.header):
            return "invalid access"
        if self.header == _API:
            return "api"
        return "other"

    @property
    def title(self) -> str:
        """The header without the address (which differs between reports)."""
        return re.sub(
            r" at (global|local|private|constant) memory address 0x[0-9a-f]+", r" (\1)", self.header
        )

    def field(self, name: str) -> str:
        """The value of a body line "Name: value" (or "Name value")."""
        for line in self.body:
            if line.startswith((name + ":", name + " ")):
                return line[len(name) :].lstrip(":").strip()
        return ""

    def text(self) -> str:
        return "\n".join([self.header] + ["\t" + b for b in self.body])


@dataclasses.dataclass
class RunOutput:
    diagnostics: list[Diagnostic]
    errors: list[tuple[str, str]]  # (case, traceback)
    launched: dict[str, int] | None
    stray: list[str]  # lines that are neither markers nor Oclgrind's
    seconds: dict[str, float] = dataclasses.field(default_factory=dict)  # per case
    case_kernels: dict[str, list[str]] | None = None  # case -> the kernels it launched


def _accesses(body: list[str]) -> list[Access]:
    out: list[Access] = []
    cur: Access | None = None
    expect = ""
    for line in body:
        s = line.strip()
        m = re.match(r"^(?:First entity|Second entity|Entity):\s*(.*)$", s)
        if m:
            cur = Access(m.group(1), "")
            out.append(cur)
            expect = "instruction"
            continue
        if cur is None:
            continue
        m = _AT.match(s)
        if m:
            cur.line, cur.file = int(m.group(1)), m.group(3)
            expect = "source"
        elif expect == "instruction" and s:
            cur.instruction, expect = s, ""
        elif expect == "source":
            cur.source, expect = s, ""
    return out


def parse(text: str) -> RunOutput:
    """Split the workload's stderr into Oclgrind's diagnostics (each tagged
    with the case that was running) and the workload's own @@ lines."""
    diags: list[Diagnostic] = []
    errors: list[tuple[str, str]] = []
    stray: list[str] = []
    launched = None
    case_kernels = None
    seconds: dict[str, float] = {}
    case = "(start)"
    cur: Diagnostic | None = None
    for raw in text.splitlines():
        if raw.startswith("@@"):
            cur = None
            kind, _, rest = raw[2:].partition(" ")
            if kind == "case":
                case = rest
            elif kind == "error":
                e = json.loads(rest)
                errors.append((e["case"], e["traceback"]))
            elif kind == "launched":
                launched = json.loads(rest)
            elif kind == "case-kernels":
                case_kernels = json.loads(rest)
            elif kind == "time":
                name, _, sec = rest.partition(" ")
                seconds[name] = float(sec)
            else:
                stray.append(raw)
            continue
        if not raw.strip():
            continue
        if raw[0] in " \t":
            if cur is not None:
                cur.body.append(raw.strip("\t").rstrip() if raw.startswith("\t") else raw.rstrip())
            else:
                stray.append(raw)
            continue
        cur = Diagnostic(raw.rstrip(), [], case)
        diags.append(cur)
    for d in diags:
        d.kernel = d.field("Kernel")
        d.accesses = _accesses(d.body)
    return RunOutput(diags, errors, launched, stray, seconds, case_kernels)


# ---------------------------------------------------------------------------
# judging


def _api_ignored(d: Diagnostic) -> bool:
    return (
        d.field("Function") == "clGetDeviceInfo"
        and d.field("Error") == "CL_INVALID_VALUE"
        and d.field("For argument") == "'param_name'"
    )


def _where(src: Sources, d: Diagnostic, a: Access) -> tuple[Path | None, str]:
    if not a.file or a.line <= 0:
        return None, "(no source line)"
    path = src.resolve(d.kernel, a.file)
    if path is None:
        return None, f"{a.file}:{a.line} (not found)"
    rel = path.relative_to(REPO) if path.is_relative_to(REPO) else path
    if (
        a.file == "input.cl"
        and a.source
        and a.source != "(source not available)"
        and src.line(path, a.line).strip() != a.source.strip()
    ):
        # the program source is not the file we think: never match a marker
        return None, f"{rel}:{a.line} (Oclgrind shows another line: {a.source!r})"
    return path, f"{rel}:{a.line}"


def judge(src: Sources, d: Diagnostic) -> tuple[str, str, str]:
    """(verdict, key, note): verdict "benign", "ignored" or "fail"; key
    groups equal reports; note is the benign tag or why it fails."""
    if d.kind == "api":
        key = f"API {d.field('Function')} {d.field('Error')} {d.field('For argument')}"
        return ("ignored" if _api_ignored(d) else "fail"), key, ""
    places = []
    tagsets = []
    for a in d.accesses:
        path, where = _where(src, d, a)
        places.append(where)
        tagsets.append(src.tags(path, a.line) if path is not None else set())
    key = f"{d.title} in {d.kernel or '?'}: " + " × ".join(sorted(places) or ["(no location)"])
    if d.kind != "race":
        return "fail", key, d.kind
    common = set.intersection(*tagsets) if len(tagsets) == 2 else set()
    if common:
        return "benign", key, ",".join(sorted(common))
    return "fail", key, "race not documented as benign"


# ---------------------------------------------------------------------------
# running


@dataclasses.dataclass
class ConfigResult:
    tuning: str
    atomics: str
    seconds: float
    returncode: int
    output: RunOutput
    log: str
    skipped: list[str] = dataclasses.field(default_factory=list)  # cases left out (see the docstring)

    @property
    def name(self) -> str:
        return f"{self.tuning}/{self.atomics}"


def _command(oclgrind: str, tuning: str, atomics: str, cases: list[str]) -> list[str]:
    return [oclgrind, *OCLGRIND_ARGS, sys.executable, str(CASES_PY), tuning, atomics, *cases]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYOPENCL_NO_CACHE"] = "1"
    env["OCLGRIND_MAX_ERRORS"] = str(2**31 - 1)  # the default stops reporting after 1000
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    for k in ("CLVIS_DEVICE", "PYOPENCL_CTX", "CLVIS_TUNING", "CLVIS_NO_INT64_ATOMICS", "CLVIS_MAX_ALLOC"):
        env.pop(k, None)
    return env


def case_names() -> list[str]:
    """The cases of cases.py, in its order (read from its source: this module
    does not import it, which patches pyopencl)."""
    return re.findall(r"^@case\s*\ndef (\w+)\(", CASES_PY.read_text(), re.MULTILINE)


def merge(outputs: list[RunOutput]) -> RunOutput:
    """One configuration's output from its workloads' (each a share of the cases)."""
    launched: dict[str, int] | None = {}
    by_case: dict[str, list[str]] | None = None
    for o in outputs:
        if o.launched is None or launched is None:
            launched = None
        else:
            for k, n in o.launched.items():
                launched[k] = launched.get(k, 0) + n
        if o.case_kernels is not None:
            by_case = {**(by_case or {}), **o.case_kernels}
    return RunOutput(
        [d for o in outputs for d in o.diagnostics],
        [e for o in outputs for e in o.errors],
        launched,
        [s for o in outputs for s in o.stray],
        {k: v for o in outputs for k, v in o.seconds.items()},
        by_case,
    )


def run_config(
    oclgrind: str,
    tuning: str,
    atomics: str,
    cases: list[str] | None,
    jobs: int = 1,
    first: dict[str, float] | None = None,
) -> ConfigResult:
    """Run `cases` (None: all) in one configuration. jobs > 1: that many
    workloads at once (Oclgrind interprets a workload on one thread), each
    given the next case as it finishes one, the slowest of `first` (seconds
    by case) first."""
    t0 = time.perf_counter()
    if cases is not None and not cases:
        return ConfigResult(tuning, atomics, 0.0, 0, RunOutput([], [], {}, [], {}, {}), "")
    if jobs <= 1:
        p = subprocess.run(
            _command(oclgrind, tuning, atomics, cases or []),
            cwd=REPO,
            env=_env(),
            check=False,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            errors="replace",
        )
        return ConfigResult(
            tuning, atomics, time.perf_counter() - t0, p.returncode, parse(p.stdout), p.stdout
        )
    names = list(cases) if cases is not None else case_names()
    names.sort(key=lambda c: -(first or {}).get(c, 0.0))
    todo = deque(names)
    lock = threading.Lock()
    procs = [
        subprocess.Popen(
            _command(oclgrind, tuning, atomics, ["--serve"]),
            cwd=REPO,
            env=_env(),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            errors="replace",
        )
        for _ in range(min(jobs, len(names)))
    ]
    logs: list[list[str]] = [[] for _ in procs]

    def feed(p: subprocess.Popen) -> None:
        assert p.stdin is not None
        with lock:
            if todo:
                name = todo.popleft()
                try:
                    p.stdin.write(name + "\n")
                    p.stdin.flush()
                    return
                except OSError:  # the workload is gone: another one takes the case
                    todo.appendleft(name)
            with contextlib.suppress(OSError):
                p.stdin.close()

    def drain(i: int) -> None:
        p = procs[i]
        assert p.stdout is not None
        feed(p)
        for line in p.stdout:
            logs[i].append(line)
            if line.startswith(f"{MARK_TIME} "):
                feed(p)
        p.wait()

    with ThreadPoolExecutor(max_workers=len(procs) or 1) as ex:
        list(ex.map(drain, range(len(procs))))
    outputs = [parse("".join(lg)) for lg in logs]
    if todo:  # every workload exited early
        outputs.append(
            RunOutput([], [(c, "never ran: every workload had exited") for c in todo], {}, [], {}, {})
        )
    failed = [p.returncode for p in procs if p.returncode]
    # a failed workload's log last: the summary shows the end of the log
    order = sorted(range(len(procs)), key=lambda i: procs[i].returncode != 0)
    log = "".join("".join(logs[i]) for i in order)
    return ConfigResult(
        tuning, atomics, time.perf_counter() - t0, failed[0] if failed else 0, merge(outputs), log
    )


def _oclgrind_version(oclgrind: str) -> str:
    try:
        out = subprocess.run([oclgrind, "--version"], capture_output=True, text=True, check=False).stdout
    except OSError:
        return "?"
    m = re.search(r"Oclgrind \S+", out)
    return m.group(0) if m else "?"


def report(src: Sources, results: list[ConfigResult], full: bool, out=None) -> bool:
    """Print the summary; True when the audit passes. `full`: every case in
    every configuration ran, so every kernel must have been launched."""
    out = out or sys.stdout
    ok = True
    groups: dict[tuple[str, str, str], dict] = {}
    for r in results:
        counts: dict[str, int] = defaultdict(int)
        for d in r.output.diagnostics:
            verdict, key, note = judge(src, d)
            counts[verdict] += 1
            g = groups.setdefault(
                (verdict, key, note), {"n": 0, "configs": set(), "cases": set(), "first": None}
            )
            g["n"] += 1
            g["configs"].add(r.name)
            g["cases"].add(d.case)
            if g["first"] is None:
                g["first"] = (r, d)
        launched = r.output.launched or {}
        print(
            f"{r.name:13s} {r.seconds:6.1f} s  {len(launched):3d} kernels launched  "
            f"{counts['benign']:5d} benign races  {counts['fail']:4d} failures  "
            f"{counts['ignored']:3d} API queries ignored",
            file=out,
        )
        if r.skipped:
            print(
                f"  not run again (the same programs as {r.tuning}/int64): {', '.join(r.skipped)}",
                file=out,
            )
        slow = sorted(r.output.seconds.items(), key=lambda kv: -kv[1])[:3]
        if slow:
            print("  slowest cases: " + ", ".join(f"{k} {v:.1f} s" for k, v in slow), file=out)
        if r.returncode != 0:
            ok = False
            print(f"  FAIL: the workload exited with status {r.returncode}", file=out)
            if r.output.launched is None:
                print("  its output ends:\n    " + "\n    ".join(r.log.splitlines()[-15:]), file=out)
        for case, tb in r.output.errors:
            ok = False
            print(f"  FAIL: case {case} raised:\n    " + "\n    ".join(tb.rstrip().splitlines()), file=out)
        if r.output.stray:
            ok = False
            print("  FAIL: unrecognised output:\n    " + "\n    ".join(r.output.stray[:20]), file=out)

    benign = [(k, g) for k, g in groups.items() if k[0] == "benign"]
    if benign:
        print("\ndocumented benign races (reports, configurations, cases):", file=out)
        for (_, key, tag), g in sorted(benign, key=lambda kg: kg[0][1]):
            print(
                f"  [{tag}] {key}\n      {g['n']} reports; {', '.join(sorted(g['configs']))}; "
                f"{', '.join(sorted(g['cases']))}",
                file=out,
            )
    used = {t for k in groups if k[0] == "benign" for t in k[2].split(",")}
    for tag, places in sorted(src.all_tags().items()):
        if full and tag not in used:
            print(f"note: marker ({tag}) matched no report (still needed?): {', '.join(places)}", file=out)

    fails = [(k, g) for k, g in groups.items() if k[0] == "fail"]
    for (_, key, note), g in sorted(fails, key=lambda kg: kg[0][1]):
        ok = False
        r, d = g["first"]
        print(
            f"\nFAIL ({note}): {key}\n  {g['n']} reports; {', '.join(sorted(g['configs']))}; cases "
            f"{', '.join(sorted(g['cases']))}\n  first report ({r.name}, case {d.case}):",
            file=out,
        )
        print("    " + d.text().replace("\n", "\n    "), file=out)
        print(
            "  reproduce: "
            + " ".join(_command("oclgrind", r.tuning, r.atomics, [d.case]))
            + "  (with PYOPENCL_NO_CACHE=1)",
            file=out,
        )

    kernels = src.kernels
    launched_any: dict[str, list[str]] = defaultdict(list)
    for r in results:
        for k in r.output.launched or {}:
            launched_any[k].append(r.name)
    missing = sorted(set(kernels) - set(launched_any))
    print(
        f"\nkernels launched: {len(set(kernels) & set(launched_any))} of {len(kernels)} "
        f"in kernels_cl/<family>/*.cl",
        file=out,
    )
    if missing and full:
        ok = False
        print(
            "FAIL: never launched (add them to tests/oclgrind/cases.py): "
            + ", ".join(f"{k} ({kernels[k].relative_to(REPO)})" for k in missing),
            file=out,
        )
    elif missing:
        print(f"(a partial run: {len(missing)} not launched)", file=out)
    print("\noclgrind audit: " + ("passed" if ok else "FAILED"), file=out)
    return ok


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--config",
        action="append",
        metavar="TUNING:ATOMICS",
        help="cpu|gpu:int64|no-int64 (default: all four)",
    )
    ap.add_argument("--case", action="append", default=[], help="run only these cases of cases.py")
    ap.add_argument(
        "--jobs",
        "-j",
        type=int,
        default=0,
        help="workloads run at once, each a share of a configuration's cases (Oclgrind interprets "
        "a workload on one thread; default: the machine's cores, at most 4)",
    )
    ap.add_argument("--log-dir", type=Path, help="keep each configuration's raw Oclgrind output here")
    ap.add_argument("--oclgrind", default=os.environ.get("OCLGRIND", "oclgrind"))
    args = ap.parse_args(argv)

    oclgrind = shutil.which(args.oclgrind)
    if oclgrind is None:
        print(f"audit: {args.oclgrind} not found (Debian/Ubuntu: apt-get install oclgrind)", file=sys.stderr)
        return 2
    configs = CONFIGS
    if args.config:
        configs = []
        for c in args.config:
            t, _, a = c.partition(":")
            if t not in ("cpu", "gpu") or a not in ("int64", "no-int64"):
                ap.error(f"--config: expected cpu|gpu:int64|no-int64, got {c!r}")
            configs.append((t, a))
    src = Sources()
    jobs = args.jobs or min(4, os.cpu_count() or 1)
    print(
        f"oclgrind audit: {_oclgrind_version(oclgrind)}, {len(configs)} configurations, "
        f"{len(src.kernels)} kernels; {' '.join(OCLGRIND_ARGS)}",
        flush=True,
    )
    t0 = time.perf_counter()
    # int64 first: a no-int64 configuration runs the cases that need it (the
    # docstring), by the kernels each case launched with the same tuning
    done: list[ConfigResult] = []
    for tuning, atomics in sorted(configs, key=lambda c: c[1] != "int64"):
        with_int64 = next((r for r in done if (r.tuning, r.atomics) == (tuning, "int64")), None)
        by_case = with_int64.output.case_kernels if with_int64 is not None else None
        first = {k: v for r in done for k, v in r.output.seconds.items()}
        if atomics == "no-int64" and not args.case and with_int64 is not None and by_case is not None:
            failed = {c for c, _ in with_int64.output.errors}
            run = [c for c, ks in by_case.items() if c in failed or needs_no_int64(ks, src.kernels)]
            run += sorted(failed - set(by_case))
            r = run_config(oclgrind, tuning, atomics, run, max(1, jobs), first)
            r.skipped = sorted(set(by_case) - set(run))
        else:
            r = run_config(oclgrind, tuning, atomics, args.case or None, max(1, jobs), first)
        done.append(r)
    results = sorted(done, key=lambda r: configs.index((r.tuning, r.atomics)))
    if args.log_dir:
        args.log_dir.mkdir(parents=True, exist_ok=True)
        for r in results:
            (args.log_dir / f"{r.tuning}-{r.atomics}.log").write_text(r.log)
    full = not args.case and set(configs) == set(CONFIGS)
    ok = report(src, results, full)
    print(f"total {time.perf_counter() - t0:.1f} s", flush=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
