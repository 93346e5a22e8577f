"""`clvis bench`: a family's benchmark suite with its peers, as a table (and
JSON), or the table of an earlier run's JSON."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ._common import Parser, real

if TYPE_CHECKING:  # benchreport is imported when a report is read, not at start-up
    from ..benchreport import Row


def _report(path: str) -> tuple[list[Row], dict]:
    """--report: the (rows, meta) of a pytest-benchmark JSON file, read while
    the arguments are parsed, so a wrong file is an argument error."""
    import argparse

    from .. import benchreport

    try:
        return benchreport.load(path)
    except FileNotFoundError:
        raise argparse.ArgumentTypeError(f"{path}: no such file") from None
    except OSError as e:
        raise argparse.ArgumentTypeError(f"{path}: {e.strerror or e}") from None
    except (ValueError, KeyError, TypeError, AttributeError) as e:  # not JSON, or not a benchmark's
        raise argparse.ArgumentTypeError(
            f"{path}: not a pytest-benchmark JSON file ({type(e).__name__}: "
            f"{str(e).splitlines()[0] if str(e) else ''})"
        ) from None


# the suites: bench/bench_<family>.py (and the layers' distributed and view)
FAMILIES = ("primitives", "raster", "gauss", "iso", "post", "distributed", "view")


def add_parser(sub: argparse._SubParsersAction[Parser]) -> Parser:
    b = sub.add_parser("bench", help="run a benchmark suite and print its table")
    b.add_argument("family", choices=FAMILIES)
    b.add_argument(
        "--scale", type=real(0.0, open_lo=True), help="multiply every size (e.g. 0.01 for a smoke run)"
    )
    b.add_argument("--json", help="where to write the JSON (default bench/results/<device>/<family>.json)")
    b.add_argument(
        "--report",
        type=_report,
        metavar="JSON",
        help="print the table of an existing JSON instead of running",
    )
    b.add_argument("--check", action="store_true", help="exit 1 if a target is missed")
    b.add_argument(
        "--compare",
        nargs="?",
        const=SAVED,
        type=_report,
        metavar="BASELINE",
        help="compare with a saved run of the same device (default: the JSON this run replaces) on "
        "the normalised figures (clvis's best time / the copy kernel's or fastest peer's in the same run)",
    )
    b.add_argument(
        "--fail-on",
        type=_percent,
        metavar="PCT",
        help="with --compare: exit 1 when an op's normalised figure is more than PCT slower (e.g. 15%%)",
    )
    b.add_argument("--select", metavar="EXPR", help="run only the cases pytest -k EXPR selects")
    return b


# --compare without a path: the run's own saved JSON, read before it runs
SAVED: tuple[list[Row], dict] = ([], {"saved": True})


def _percent(text: str) -> float:
    """--fail-on: "15%" or "15" -> 0.15."""
    try:
        v = float(text.strip().removesuffix("%"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: not a percentage such as 15%") from None
    if not 0 < v < 10000:
        raise argparse.ArgumentTypeError(f"{text!r}: give a percentage above 0, such as 15%")
    return v / 100


def _missing(module: str) -> bool:
    """Whether `module` cannot be imported (looked up, not imported)."""
    import importlib.util

    try:
        return importlib.util.find_spec(module) is None
    except (ImportError, ValueError):
        return True


def _env_scale() -> float | None:
    """CLVIS_BENCH_SCALE as the suites read it (1 when unset; None when not a number)."""
    try:
        return float(os.environ.get("CLVIS_BENCH_SCALE") or 1)
    except ValueError:
        return None


def _bench_dir() -> Path | None:
    for cand in (Path.cwd() / "bench", Path(__file__).resolve().parents[2] / "bench"):
        if (cand / "bench_primitives.py").is_file():
            return cand
    return None


def cmd(args: argparse.Namespace) -> int:
    from .. import benchreport, runtime

    if args.fail_on is not None and args.compare is None:
        print("clvis bench: error: --fail-on needs --compare", file=sys.stderr)
        return 2
    baseline = args.compare
    if baseline is SAVED and args.report:
        print("clvis bench: error: --compare with --report needs the baseline's path", file=sys.stderr)
        return 2
    if args.report:
        rows, meta = args.report
    else:
        bench = _bench_dir()
        if bench is None:
            print(
                "clvis bench needs the bench/ folder of a source checkout (run it from the repository root)",
                file=sys.stderr,
            )
            return 2
        missing = [m for m in ("pytest", "pytest_benchmark") if _missing(m)]
        if missing:
            print(
                f"clvis bench: error: the suites run under pytest with pytest-benchmark "
                f"({', '.join(missing)} not installed): pip install '.[test]' in the clone "
                "(the test extra)",
                file=sys.stderr,
            )
            return 2
        suite = bench / f"bench_{args.family}.py"
        if not suite.is_file():
            print(f"clvis bench: error: {suite} is missing", file=sys.stderr)
            return 2
        q = runtime.default_queue()
        out = (
            Path(args.json)
            if args.json
            else (bench / "results" / runtime.device_slug(q) / f"{args.family}.json")
        )
        scale = args.scale if args.scale is not None else _env_scale()
        if not args.json and (args.select or scale != 1) and out.is_file():
            # a smoke or selected run would replace the saved full run (in a clone, the committed figures)
            why = f"--select {args.select!r}" if args.select else f"scale {scale}"
            print(
                f"clvis bench: error: a run at {why} would replace the full run saved at {out}; "
                "give --json PATH for it (--compare BASELINE still compares with the saved one)",
                file=sys.stderr,
            )
            return 2
        if baseline is SAVED:
            if not out.is_file():
                print(f"clvis bench: error: --compare: no saved run at {out}", file=sys.stderr)
                return 2
            baseline = benchreport.load(out)
        out.parent.mkdir(parents=True, exist_ok=True)
        # pytest-benchmark writes its JSON even when cases failed: written beside
        # `out` and moved over it only when the run passed, a failed run leaves
        # the saved one (the default --compare baseline) as it was and its own
        # JSON as <family>.failed.json
        part = out.with_name(f".{out.name}.{os.getpid()}.part")
        env = dict(os.environ)
        if args.scale is not None:
            env["CLVIS_BENCH_SCALE"] = str(args.scale)
        cmd = [
            sys.executable,
            "-m",
            "pytest",
            str(suite),
            "-q",
            "-p",
            "no:cacheprovider",
            f"--benchmark-json={part}",
            "--benchmark-disable-gc",
            *(["-k", args.select] if args.select else []),
        ]
        print("running:", " ".join(cmd), flush=True)
        try:
            r = subprocess.run(
                cmd,
                check=False,
                cwd=bench.parent,
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
            if r.returncode != 0:
                print(r.stdout[-4000:])
                kept = "left as it was" if out.is_file() else "not written"
                failed = out.with_name(f"{out.stem}.failed.json")
                if part.is_file():  # what did run, for --report (its not_measured names the failures)
                    os.replace(part, failed)
                    kept += f"; what ran is in {failed}"
                print(f"clvis bench: the suite failed (exit {r.returncode}); {out} {kept}", file=sys.stderr)
                return r.returncode
            os.replace(part, out)
        finally:
            part.unlink(missing_ok=True)
        rows, meta = benchreport.load(out)
        print(f"results: {out}")
    print(benchreport.format_table(rows, meta))
    results = benchreport.check(rows, args.family, meta.get("tuning", "cpu"))
    try:
        full = float(meta.get("scale", 1)) == 1
    except (TypeError, ValueError):
        full = False
    if results and not full:
        # the targets are figures of the full sizes: a smoke run's would read as missed
        print(f"\ntargets: not judged (they are set for scale 1; this run is at scale {meta.get('scale')})")
        if args.check:
            print("clvis bench: error: --check needs a run at scale 1", file=sys.stderr)
            return 2
    elif results:
        print(f"\ntargets ({meta.get('tuning', 'cpu')} device):")
        print(benchreport.format_checks(results))
    regressed = False
    if baseline is not None:
        base_rows, base_meta = baseline
        if base_meta.get("device_slug") != meta.get("device_slug"):
            print(
                f"clvis bench: error: --compare: the baseline ran on {base_meta.get('device', '?')}, "
                f"this run on {meta.get('device', '?')}",
                file=sys.stderr,
            )
            return 2
        # a smoke run (CLVIS_BENCH_SCALE / --scale) against a full one compares other sizes
        if float(base_meta.get("scale", 1)) != float(meta.get("scale", 1)):
            print(
                f"clvis bench: error: --compare: the baseline ran at scale {base_meta.get('scale', 1)}, "
                f"this run at scale {meta.get('scale', 1)} (other sizes)",
                file=sys.stderr,
            )
            return 2
        changes = benchreport.compare(base_rows, rows, args.fail_on)
        print("\ncompared with the baseline (normalised: clvis best / anchor best, same run):")
        print(benchreport.format_compare(changes))
        left = benchreport.uncompared(base_rows, rows)
        if left:
            print("not compared:\n" + "\n".join(f"  {w}" for w in left))
        regressed = any(c.regressed for c in changes)
        if regressed:
            print(f"\nregression beyond {100 * args.fail_on:g}%", file=sys.stderr)
    if args.check and not all(ok for _, _, ok in results):
        return 1
    return 1 if regressed else 0
