"""Tables and target checks from pytest-benchmark JSON written by bench/.

Every benchmark's extra_info names its op, impl, role ("clvis", "clvis-host",
"peer" or "copy"), element count n and bytes model (DESIGN.md). For each op
the report gives, per implementation, the best and median time, throughput
(elements per second), GB/s by the bytes model and % of the copy kernel's GB/s
measured in the same run; and for clvis on device arrays its speed-up over
each peer (peer time / clvis time). Targets are checked on those ratios.

Figures use each implementation's best round: on a shared machine other
tenants only ever add time, and they do so unevenly between rows measured
seconds apart (the copy kernel's median moved from 4.8 ms to 3.1 ms between
two runs here), which makes ratios of medians swing more than ratios of bests.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Iterable
from pathlib import Path


@dataclasses.dataclass
class Row:
    op: str
    impl: str
    role: str
    n: int
    bytes: int
    median_s: float
    min_s: float
    rounds: int
    copy_gbs: float | None = None
    info: dict = dataclasses.field(default_factory=dict)

    @property
    def cpu_s(self) -> float | None:
        """The least process CPU time (user + system, all its threads) of the
        timed rounds, where recorded (not necessarily the round of min_s)."""
        cpu = self.info.get("cpu_s")
        # a peer timed on a subset scales its CPU time as its time ("time_scale"); an
        # ideal n-thread peer (its time / n) does not: the threads' CPU adds up ("cpu_scale")
        scale = self.info.get("cpu_scale", self.info.get("time_scale", 1.0))
        return min(cpu) * float(scale) if cpu else None

    @property
    def elems_per_s(self) -> float:
        return self.n / self.min_s

    @property
    def gbs(self) -> float:
        return self.bytes / self.min_s / 1e9

    @property
    def copy_pct(self) -> float | None:
        return None if not self.copy_gbs else 100.0 * self.gbs / self.copy_gbs


@dataclasses.dataclass
class Target:
    op: str
    what: str  # "copy_pct", the impl name of a peer, or "info:<key>" (a figure the clvis row records)
    at_least: float
    devices: str  # "cpu" or "gpu": the tuning profile it applies to
    at_most: bool = False  # for "info:" targets: the figure must be <= at_least instead
    label: str = ""
    impl: str = ""  # the row whose figure is checked (its impl name); "" is the op's clvis row

    def describe(self) -> str:
        op = f"{self.op} ({self.impl})" if self.impl else self.op
        if self.what == "copy_pct":
            return f"{op}: >= {self.at_least:g}% of copy bandwidth"
        if self.what.startswith("info:"):
            return f"{op}: {self.label or self.what[5:]} {'<=' if self.at_most else '>='} {self.at_least:g}"
        return f"{op}: >= {self.at_least:g}x {self.what}"


SORT_OP = "radix_sort[uint32 keys + uint32 values]"
ISO_OP = "iso[turbulence 256^3, 512x512, to 100%]"
DISTRIBUTED_OP = "distributed[2^26 points, 16 LAS tiles, 1920x1080]"
VIEW_POINTS_OP = "view_points[hurricane 2,000,000 points, 640x360 interaction]"
VIEW_NARVIS_OP = "view_narvis[hurricane 2,000,000 points, 512x512]"
VIEW_ISO_OP = "view_iso[marschner-lobb 64^3, 1280x720 still: first frame after a stop]"
NARVIS_FAST = "MACR render + NARVis fp32 (the fast path)"
NARVIS_GR = "Gaussian renderer, 2,000,000 Gaussians (the slow path)"
SCAN_FAST = "MACR render + depth filter + narvis-scan fp32 (the fast path)"
#: the aerial scan at 4 points a pixel of 512 x 512 (bench/bench_post.py)
SCAN_GR = "Gaussian renderer, 1,048,576 Gaussians (the slow path)"
TARGETS = {
    "primitives": [
        # on PoCL's CPU device (2 cores). "np.cumsum" as users call it
        # (~350 M/s): np.cumsum(x), which sums int32 in int64; the report
        # also shows np.cumsum(x, dtype=x.dtype), clvis's exact output.
        Target("scan[int32]", "pyopencl.ExclusiveScanKernel", 5, "cpu"),
        Target("scan[int32]", "numpy.cumsum(x)", 2, "cpu"),
        Target("scan[int32]", "copy_pct", 40, "cpu"),
        Target("compact[int32, half kept]", "numpy boolean mask", 2, "cpu"),
        Target(SORT_OP, "numpy argsort(stable) + gather", 4, "cpu"),
        Target(SORT_OP, "pyopencl.algorithm.RadixSort", 10, "cpu"),
        # goals on a GPU with NVIDIA's OpenCL
        Target("scan[int32]", "copy_pct", 70, "gpu"),
        Target(SORT_OP, "copy_pct", 40, "gpu"),
    ],
    "raster": [
        # on PoCL's CPU device (2 cores), 2^24 points at 1920x1080
        Target("raster[morton order]", "numpy reference render (np.minimum.at)", 12, "cpu"),
        Target("raster[morton order]", "copy_pct", 25, "cpu"),
        Target("raster[morton order]", "np.minimum.at alone (keys precomputed)", 1, "cpu"),
        # the same float32 projection and scatter compiled by numba on 2 threads
        Target("raster[morton order]", "numba parallel (2 threads, visibility only)", 1.5, "cpu"),
        # goal on a GPU with NVIDIA's OpenCL
        Target("raster[morton order]", "copy_pct", 60, "gpu"),
    ],
    "iso": [
        # on PoCL's CPU device (2 cores): a 256^3 volume at 512x512
        Target(ISO_OP, "info:pass_reduction", 5, "cpu", label="passes without / with speculation"),
        Target(
            ISO_OP,
            "info:decoded_per_isovalue_block",
            1 / 3,
            "cpu",
            at_most=True,
            label="blocks decoded / blocks holding the isovalue (BCMC's)",
        ),
        Target(
            ISO_OP,
            "info:device_memory_fraction",
            0.25,
            "cpu",
            at_most=True,
            label="device memory / decoded volume",
        ),
        # issue 23: 3x marching_cubes (today ~1.4x); the frame time target,
        # <= 120 ms (half of 245), is in bench/results/iso-cpu.md
        Target(ISO_OP, "skimage.measure.marching_cubes", 3, "cpu"),
        # ZFP decoding on 2 cores against one zfpy thread ("2 x zfpy", the
        # ideal two-thread zfp, is in the table beside it)
        Target("zfp_decode[turbulence 256^3, rate 8]", "zfpy (serial)", 2.5, "cpu"),
        Target("zfp_decode[turbulence 256^3, rate 16]", "zfpy (serial)", 3, "cpu"),
    ],
    "distributed": [
        # on PoCL's CPU device (2 cores): Dask workers of one thread each
        Target(DISTRIBUTED_OP, "1 worker (one thread)", 1.6, "cpu"),
        Target(
            DISTRIBUTED_OP,
            "info:composite_fraction",
            0.2,
            "cpu",
            at_most=True,
            label="compositing / frame (busiest worker)",
        ),
        Target(
            DISTRIBUTED_OP,
            "info:cloud_over_memory_limit",
            1,
            "cpu",
            label="cloud bytes / each worker's memory_limit (it rendered)",
        ),
    ],
    "view": [
        # issue 28, on PoCL's CPU device (2 cores): wall time, so other tenants count
        Target(VIEW_POINTS_OP, "info:fps", 10, "cpu", label="interaction frames per second"),
        Target(VIEW_NARVIS_OP, "info:fps", 3, "cpu", label="NARVis frames per second"),
        Target(
            VIEW_ISO_OP,
            "info:median_ms",
            300,
            "cpu",
            at_most=True,
            label="ms to the first frame after a stop",
        ),
    ],
    "post": [
        # issue 21 section 2, onnxruntime's CPU provider with 2 threads: the
        # fp32 network per frame (pack + inference + unpack; NARVis with its
        # OpenCL kernel-prediction head), median wall ms
        *(
            Target(op, "info:median_ms", ms, "cpu", at_most=True, label="fp32 network, median ms a frame")
            for op, ms in (
                ("infill[512x512]", 100),
                ("infill[1280x720]", 300),
                ("lidar[512x512]", 175),
                ("narvis[512x512]", 300),
                ("narvis-scan[512x512]", 300),  # the same graph and head as NARVis's
            )
        ),
        # MACR's G-buffers + NARVis against the Gaussian renderer on the same view
        Target("narvis[512x512]", NARVIS_GR, 4, "cpu", impl=NARVIS_FAST),
        # the same for scans; their Gaussians are small and round, so GR's tile
        # renderer is cheap (bench/results/README.md, 2026-11-29 session 9)
        Target("narvis-scan[512x512]", SCAN_GR, 4, "cpu", impl=SCAN_FAST),
    ],
    "gauss": [
        # on PoCL's CPU device (2 cores)
        Target(
            "render[1e5 Gaussians, 512x512]", "numpy brute force (extrapolated from a ray subset)", 500, "cpu"
        ),
        Target("bvh_build[1e6 Gaussians]", "np.argsort of the Morton codes alone", 1, "cpu"),
        # the tile renderer against the LBVH march (the same image)
        Target("render[1e5 Gaussians, 512x512]", "GaussianRenderer(method='bvh'), the LBVH march", 10, "cpu"),
        Target(
            "render[1e6 Gaussians, 1920x1080]", "GaussianRenderer(method='bvh'), the LBVH march", 5, "cpu"
        ),
    ],
}


def load(path: str | os.PathLike[str]) -> tuple[list[Row], dict]:
    """Rows (copy bandwidth filled in) and the run's clvis section."""
    data = json.loads(Path(path).read_text())
    rows = []
    for b in data.get("benchmarks", []):
        info = b.get("extra_info", {})
        if "op" not in info:
            continue
        st = b["stats"]
        # a peer timed on a subset (e.g. 1/4096 of the rays of a frame) and
        # scaled to the whole op: extra_info "time_scale"
        f = float(info.get("time_scale", 1.0))
        rows.append(
            Row(
                op=info["op"],
                impl=info["impl"],
                role=info["role"],
                n=info["n"],
                bytes=info["bytes"],
                median_s=st["median"] * f,
                min_s=st["min"] * f,
                rounds=st["rounds"],
                info=info,
            )
        )
    # one clvis row and one copy kernel an op: the ratios and --compare divide by them
    for role in ("clvis", "copy"):
        seen: dict[str, str] = {}
        for r in rows:
            if r.role == role and r.op in seen:
                raise ValueError(f"{r.op}: two rows of role {role!r} ({seen[r.op]!r}, {r.impl!r})")
            if r.role == role:
                seen[r.op] = r.impl
    copy = {r.op: r.gbs for r in rows if r.role == "copy"}
    for r in rows:
        r.copy_gbs = copy.get(r.op)
    return rows, data.get("clvis", {})


def ratios(rows: list[Row], impl: str = "") -> dict[tuple[str, str], float]:
    """(op, peer impl) -> peer best / clvis (device arrays) best; with
    `impl`, over the best of the op's row of that impl name instead."""
    clv = {r.op: r for r in rows if (r.impl == impl if impl else r.role == "clvis")}
    out = {}
    for r in rows:
        if r.role == "peer" and r.op in clv:
            out[(r.op, r.impl)] = r.min_s / clv[r.op].min_s
    return out


def check(rows: list[Row], family: str, profile: str) -> list[tuple[Target, float | None, bool]]:
    """Each target of `family` for `profile`: (target, measured, met)."""
    results = []
    for t in TARGETS.get(family, []):
        if t.devices != profile:
            continue
        rat = ratios(rows, t.impl)
        clv = {r.op: r for r in rows if (r.impl == t.impl if t.impl else r.role == "clvis")}
        if t.what == "copy_pct":
            value = clv[t.op].copy_pct if t.op in clv else None
        elif t.what.startswith("info:"):
            value = clv[t.op].info.get(t.what[5:]) if t.op in clv else None
        else:
            value = rat.get((t.op, t.what))
        met = value is not None and (value <= t.at_least if t.at_most else value >= t.at_least)
        results.append((t, value, met))
    return results


def _si(x: float) -> str:
    for unit, f in (("G", 1e9), ("M", 1e6), ("k", 1e3)):
        if x >= f:
            return f"{x / f:.2f} {unit}"
    return f"{x:.0f} "


def format_table(rows: list[Row], meta: dict | None = None) -> str:
    rat = ratios(rows)
    lines = []
    if meta:
        lines.append(
            f"device: {meta.get('device', '?')}   tuning: {meta.get('tuning', '?')}   "
            f"clvis {meta.get('version', '?')}   scale {meta.get('scale', 1)}"
        )
        # cases of the suite that failed or were skipped (a peer's library
        # missing, ...): no row, no ratio, so the table says so
        for m in meta.get("not_measured", []):
            lines.append(f"not measured: {m.get('test', '?')} ({m.get('outcome', '?')}: {m.get('why', '')})")
    head = (
        f"{'implementation':38} {'best':>9} {'median':>9} {'throughput':>14} {'GB/s':>7} "
        f"{'% copy':>7} {'clvis speed-up':>15} {'cpu':>9}"
    )
    for op in dict.fromkeys(r.op for r in rows):
        ops = [r for r in rows if r.op == op]
        n = ops[0].n
        lines += ["", f"{op}   n = {n:,}", head, "-" * len(head)]
        notes: list[str] = []
        for r in sorted(ops, key=lambda r: ["clvis", "clvis-host", "peer", "copy"].index(r.role)):
            name = r.impl if r.role != "clvis" else "clvis (device arrays)"
            if r.role == "clvis-host":  # a variant with its own name (e.g. a precision) keeps it
                name = "clvis (numpy in/out, transfers)" if r.impl == "clvis-host" else f"clvis, {r.impl}"
            pct = f"{r.copy_pct:6.0f}%" if r.copy_pct is not None else "      -"
            speed = f"{rat[(op, r.impl)]:14.1f}x" if (op, r.impl) in rat else ""
            cpu = f"{r.cpu_s * 1e3:7.2f}ms" if r.cpu_s is not None else ""
            if r.info.get("cpu_not_recorded"):
                cpu = "-"
                notes.append(f"cpu of {name}: not recorded ({r.info['cpu_not_recorded']})")
            lines.append(
                f"{name:38} {r.min_s * 1e3:7.2f}ms {r.median_s * 1e3:7.2f}ms "
                f"{_si(r.elems_per_s) + 'el/s':>14} {r.gbs:7.1f} {pct} {speed:>15} {cpu:>9}"
            )
        lines += notes
    return "\n".join(lines)


def format_checks(results: Iterable[tuple[Target, float | None, bool]]) -> str:
    lines = []
    for t, value, ok in results:
        if value is None:  # not in this run; --check still counts it as unmet
            lines.append(f"  [not measured] {t.describe()}")
            continue
        v = (
            f"{value:.0f}%"
            if t.what == "copy_pct"
            else f"{value:.3g}"
            if t.what.startswith("info:")
            else f"{value:.1f}x"
        )
        lines.append(f"  [{'met' if ok else 'MISSED'}] {t.describe()}: {v}")
    return "\n".join(lines)


@dataclasses.dataclass
class Change:
    """One op of a comparison with a baseline run of the same device."""

    op: str
    anchor: str  # what clvis's time is divided by: the op's other rows ("copy kernel + 2 peers") or "none"
    base: float  # baseline's clvis best / its anchor
    now: float
    base_s: float  # clvis's best time in seconds, baseline and now
    now_s: float
    fail_on: float | None
    note: str = ""  # anchors measured in one run only (left out of both figures), said, not dropped

    @property
    def change(self) -> float:
        """Relative slow-down of the normalised figure (+0.5 = 50 % slower)."""
        return self.now / self.base - 1.0

    @property
    def change_s(self) -> float:
        """Relative slow-down of clvis's best time itself."""
        return self.now_s / self.base_s - 1.0

    @property
    def regressed(self) -> bool:
        """Slower beyond fail_on both in time and normalised to the anchors: a
        machine slower for the whole run moves only the time, a noisy anchor
        only the normalised figure; a slower clvis moves both."""
        return self.fail_on is not None and self.change > self.fail_on and self.change_s > self.fail_on


def _anchors(rows: list[Row], op: str) -> dict[str, Row]:
    """impl -> row of the op's copy kernel and peers (its anchors)."""
    return {a.impl: a for a in rows if a.op == op and a.role in ("copy", "peer") and a.min_s > 0}


def _figure(clv: Row, anchors: list[Row]) -> tuple[float, str]:
    """(clvis best / geometric mean of the anchors' bests, the anchors' name);
    with no anchor, (clvis best in seconds, "none")."""
    if not anchors:
        return clv.min_s, "none"
    gm = math.exp(sum(math.log(a.min_s) for a in anchors) / len(anchors))
    copies = sum(a.role == "copy" for a in anchors)
    peers = len(anchors) - copies
    name = " + ".join(
        (["copy kernel"] if copies else []) + ([f"{peers} peer{'s' if peers > 1 else ''}"] if peers else [])
    )
    return clv.min_s / gm, name


def normalised(rows: list[Row]) -> dict[str, tuple[float, str, float]]:
    """op -> (clvis best / anchor, anchor's name, clvis best in seconds).

    The anchor is the geometric mean of the best times of the op's copy
    kernel and peers, which ran in the same process minutes apart: a machine
    that is slower for the whole run moves them and clvis alike, and the mean
    damps the noise of any one of them. An op with neither keeps its best
    time in seconds (anchor "none")."""
    out = {}
    for r in rows:
        if r.role == "clvis":
            value, name = _figure(r, list(_anchors(rows, r.op).values()))
            out[r.op] = (value, name, r.min_s)
    return out


def compare(base: list[Row], now: list[Row], fail_on: float | None = None) -> list[Change]:
    """Each op of `now` also in `base` with the same element count: its figures
    in both, normalised to the anchors measured in both runs (an anchor in one
    run only, e.g. a peer whose library is missing there, is left out of both
    figures and named in the Change's note). Ops left out: uncompared()."""
    bc = {r.op: r for r in base if r.role == "clvis"}
    out = []
    for r in now:
        b = bc.get(r.op)
        if r.role != "clvis" or b is None or b.n != r.n or b.min_s <= 0 or r.min_s <= 0:
            continue
        ab, an = _anchors(base, r.op), _anchors(now, r.op)
        common = [k for k in an if k in ab]
        vb, name = _figure(b, [ab[k] for k in common])
        vn, _ = _figure(r, [an[k] for k in common])
        notes = [f"{k}: not in the baseline" for k in an if k not in ab]
        notes += [f"{k}: not in this run" for k in ab if k not in an]
        out.append(Change(r.op, name, vb, vn, b.min_s, r.min_s, fail_on, "; ".join(notes)))
    return out


def uncompared(base: list[Row], now: list[Row]) -> list[str]:
    """Why each op measured in either run is not in compare()'s list."""
    bc = {r.op: r for r in base if r.role == "clvis"}
    nc = {r.op: r for r in now if r.role == "clvis"}
    out = [f"{op}: not in the baseline" for op in nc if op not in bc]
    out += [f"{op}: not in this run" for op in bc if op not in nc]
    out += [
        f"{op}: n = {bc[op].n:,} in the baseline, {r.n:,} now (another size)"
        for op, r in nc.items()
        if op in bc and bc[op].n != r.n
    ]
    return out


def format_compare(changes: list[Change]) -> str:
    lines = [f"{'op':56} {'anchor':24} {'baseline':>9} {'now':>9} {'change':>8} {'time':>8}"]
    for c in changes:
        flag = "  REGRESSED" if c.regressed else ""
        lines.append(
            f"{c.op[:56]:56} {c.anchor[:24]:24} {c.base:9.3g} {c.now:9.3g} {100 * c.change:+7.1f}% "
            f"{100 * c.change_s:+7.1f}%{flag}"
        )
        if c.note:
            lines.append(f"    (left out of both figures: {c.note})")
    return "\n".join(lines)
