"""Mutation fuzzing of every clvis reader: ``./dev.sh fuzz [--minutes N |
--cases N] [--seed S]``.

Seeds come from tests/fuzz/seeds.py (made by clvis, laspy, nibabel and
tinyvdb, plus the third-party files of tests/data); mutants from
tests/fuzz/mutate.py (``--formats vti,vtk,pcd``: only those seeds). Each case
is read in a child forked by the harness's server under an address-space limit (4 GiB) and a
timeout (harness.run_limited). Per format
it reports the cases, how they ended, and the largest peak resident set.

A case fails when it crashes (a signal), hangs (the timeout), raises anything
but a clvis error naming the file (MemoryError included), or peaks above
256 MB of resident memory for a file under 1 MB. Failing mutants are kept in
--keep (default: a folder under the temporary directory) for reproduction; the
exit status is 1 when any case failed.
"""

from __future__ import annotations

import argparse
import collections
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from harness import LIMIT_BYTES, run_limited  # noqa: E402
from mutate import mutate  # noqa: E402
from seeds import companion, make_seeds  # noqa: E402

RSS_LIMIT = 256 << 20  # bytes, for a file under 1 MB
SMALL_FILE = 1 << 20
KINDS = ("ok", "clvis", "crash", "hang", "foreign", "unnamed", "rss")


def _readers():
    import clvis.io
    from clvis.gauss import Gaussians, read_vdb

    return {
        "points": clvis.io.read_points,
        "volume": clvis.io.read_volume,
        "vdb": read_vdb,
        "gaussians": Gaussians.load,
    }


def fuzz(
    minutes: float | None,
    cases: int | None,
    seed: int,
    keep: Path,
    timeout: float = 10.0,
    log=print,
    formats: set[str] | None = None,
) -> dict:
    """Run the fuzzer; {format: Counter of outcome kinds, plus 'peak' bytes},
    and the list of failures."""
    readers = _readers()
    work = Path(tempfile.mkdtemp(prefix="clvis-fuzz-"))
    try:
        seeds = [s for s in make_seeds(work / "seeds") if formats is None or s[0] in formats]
        if not seeds:
            raise SystemExit(f"no seeds for the formats {sorted(formats or ())}")
        by_format = collections.defaultdict(list)
        for fmt, _reader, path in seeds:
            by_format[fmt].append(path.read_bytes())
        # the seeds themselves read, within the limits
        stats: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
        peaks: dict[str, int] = collections.defaultdict(int)
        failures = []
        for fmt, reader, path in seeds:
            r = run_limited(readers[reader], str(path), name=str(path), timeout=timeout)
            if r.kind != "ok" or r.peak_rss > RSS_LIMIT:
                failures.append((fmt, "seed", str(path), r))
                log(f"seed {path.name}: {r.kind} {r.detail[:300]} peak {r.peak_rss >> 20} MiB")
        rng = np.random.default_rng(seed)
        deadline = None if minutes is None else time.monotonic() + 60 * minutes
        t0 = time.monotonic()
        keep.mkdir(parents=True, exist_ok=True)
        i = 0
        while True:
            if cases is not None and i >= cases:
                break
            if deadline is not None and time.monotonic() >= deadline:
                break
            fmt, reader, path = seeds[int(rng.integers(0, len(seeds)))]
            data, ops = mutate(rng, path.read_bytes(), fmt, by_format[fmt])
            case = work / f"m{i % 4}-{path.name}"
            case.write_bytes(data)
            other = companion(path)
            if other is not None:  # the pair's other file, unchanged, beside the mutant
                case.with_suffix(other.suffix).write_bytes(other.read_bytes())
            r = run_limited(readers[reader], str(case), name=str(case), timeout=timeout)
            kind = r.kind
            if kind in ("ok", "clvis") and len(data) < SMALL_FILE and r.peak_rss > RSS_LIMIT:
                kind = "rss"
            stats[fmt][kind] += 1
            peaks[fmt] = max(peaks[fmt], r.peak_rss)
            if kind not in ("ok", "clvis"):
                saved = keep / f"{kind}-{i}-{path.name}"
                saved.write_bytes(data)
                if other is not None:
                    saved.with_suffix(other.suffix).write_bytes(other.read_bytes())
                failures.append((fmt, ops, str(saved), r))
                log(f"#{i} {fmt} {ops}: {kind}: {r.detail[:400]} (peak {r.peak_rss >> 20} MiB) -> {saved}")
            case.unlink()
            if other is not None:
                case.with_suffix(other.suffix).unlink()
            i += 1
            if i % 1000 == 0:
                log(f"... {i} mutants, {time.monotonic() - t0:.0f} s")
    finally:  # the seeds and the last mutant go with the run
        shutil.rmtree(work, ignore_errors=True)
    elapsed = time.monotonic() - t0
    return {"stats": stats, "peaks": peaks, "failures": failures, "cases": i, "seconds": elapsed}


def report(result: dict) -> str:
    stats, peaks = result["stats"], result["peaks"]
    lines = [
        f"{result['cases']} mutants in {result['seconds']:.0f} s, each in a forked child "
        f"(RLIMIT_AS {LIMIT_BYTES >> 30} GiB)",
        f"{'format':8} {'cases':>6} " + " ".join(f"{k:>7}" for k in KINDS) + "  peak RSS",
    ]
    total = collections.Counter()
    for fmt in sorted(stats):
        c = stats[fmt]
        total.update(c)
        lines.append(
            f"{fmt:8} {sum(c.values()):6} "
            + " ".join(f"{c[k]:7}" for k in KINDS)
            + f"  {peaks[fmt] / 2**20:.0f} MiB"
        )
    lines.append(
        f"{'all':8} {sum(total.values()):6} "
        + " ".join(f"{total[k]:7}" for k in KINDS)
        + f"  {max(peaks.values(), default=0) / 2**20:.0f} MiB"
    )
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=None, help="run this long (default 5 without --cases)")
    ap.add_argument("--cases", type=int, default=None, help="run this many mutants")
    ap.add_argument("--seed", type=int, default=int(time.time()) % 100000)
    ap.add_argument("--timeout", type=float, default=10.0, help="seconds a case may take")
    ap.add_argument(
        "--formats", default=None, help="only these seed formats, comma-separated (e.g. vti,vtk,pcd)"
    )
    ap.add_argument("--keep", type=Path, default=Path(tempfile.gettempdir()) / "clvis-fuzz-failures")
    args = ap.parse_args(argv)
    minutes = args.minutes if args.minutes is not None or args.cases is not None else 5.0
    print(f"clvis fuzz: seed {args.seed}", flush=True)
    formats = set(args.formats.split(",")) if args.formats else None
    result = fuzz(
        minutes,
        args.cases,
        args.seed,
        args.keep,
        args.timeout,
        log=lambda s: print(s, flush=True),
        formats=formats,
    )
    print(report(result))
    if result["failures"]:
        print(f"{len(result['failures'])} failures; mutants kept in {args.keep}")
        return 1
    print("no crash, hang, foreign exception or peak RSS over 256 MB for a file under 1 MB")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONWARNINGS", "ignore")
    sys.exit(main())
