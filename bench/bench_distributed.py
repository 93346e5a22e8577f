"""Benchmarks of clvis.distributed: sort-last rendering on Dask workers,
against the single-process renderers in the same session.

Points: a 2^26-point terrain written as 16 LAS tiles (4 x 4, point format 2:
xyz + RGB) at bench time, read and rendered on the workers at 1920x1080 and
composited by direct-send. Rows of the op (one frame each):

- "2 workers": a LocalCluster of 2 worker processes, one thread each (Dask's
  threads_per_worker=1 and PoCL limited to one core: POCL_CPU_MAX_CU_COUNT=1);
- "1 worker (one thread)": the same with one worker, holding every tile;
- "single process Rasterizer": clvis.Rasterizer of the concatenated cloud in
  this process (PoCL on every core), the non-distributed path.

The 2-worker row records, from the frame's stats: compositing seconds of the
busiest worker (min-key merging of its own tiles and of its direct-send
band) and their fraction of the frame, the bytes each worker sends per frame,
and the workers' per-tile render time, from which the projected frame time at
8, 64 and 512 workers for 10^10 points at 1920x1080 is computed (the model
is in bench/results/distributed-cpu.md). The workers of the 2-worker cluster
have a memory_limit of 3/4 of the cloud's bytes (16 B/point: xyz float32 +
RGBA), so the cloud exceeds every worker's limit; Dask's pause and terminate
thresholds are off for them (the partitions live in OpenCL device memory, not
in Dask's managed memory, which stays at the handles' few bytes).

Volumes: a 512^3 volume (turbulence) as .npy, bricks read on the workers by
memory-mapped slicing, against one IsoRenderer of the whole volume.

    clvis bench distributed          (CLVIS_BENCH_SCALE shrinks both)
"""

import contextlib
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from benchutil import run, scaled

distributed = pytest.importorskip("distributed")
laspy = pytest.importorskip("laspy")

import clvis  # noqa: E402
from clvis.distributed import DistributedRasterizer, concatenate  # noqa: E402
from clvis.distributed.cluster import connected_workers  # noqa: E402
from clvis.distributed.iso import DistributedIsoRenderer  # noqa: E402
from clvis.io import read_points  # noqa: E402

SCALE = float(os.environ.get("CLVIS_BENCH_SCALE", "1"))
N = scaled(1 << 26)
TILES = 16
W, H = (1920, 1080) if SCALE >= 0.05 else (480, 270)
SIDE = max(16, int(round(512 * SCALE ** (1 / 3))) // 4 * 4)  # the volume's edge
POINTS_OP = f"distributed[2^{np.log2(N):.0f} points, {TILES} LAS tiles, {W}x{H}]"
ISO_OP = f"distributed_iso[{SIDE}^3 .npy, 512x512]"
TIMEOUT = 1800
_cache: dict = {}


def _tmp() -> Path:
    if "tmp" not in _cache:
        _cache["tmpdir"] = tempfile.TemporaryDirectory(prefix="clvis-bench-distributed-")
        _cache["tmp"] = Path(_cache["tmpdir"].name)
    return _cache["tmp"]


def tiles() -> list[Path]:
    """16 LAS tiles of a terrain, 4 x 4 tiles of 100 m, 1 mm resolution."""
    if "tiles" not in _cache:
        rng = np.random.default_rng(0)
        paths = []
        per = N // TILES
        for i in range(TILES):
            n = per + (N - per * TILES if i == TILES - 1 else 0)
            x = (i % 4) * 100 + rng.random(n) * 100
            y = (i // 4) * 100 + rng.random(n) * 100
            z = 20 * np.sin(x / 37.0) * np.cos(y / 53.0) + rng.random(n) * 0.5
            header = laspy.LasHeader(point_format=2, version="1.2")
            header.scales, header.offsets = [0.001] * 3, [500000.0, 4000000.0, 0.0]
            las = laspy.LasData(header)
            las.x, las.y, las.z = x + 500000, y + 4000000, z
            c = ((z - z.min()) / (np.ptp(z) + 1e-9) * 65535).astype(np.uint16)
            las.red, las.green, las.blue = c, 65535 - c, np.full(n, 30000, np.uint16)
            p = _tmp() / f"tile{i:02d}.las"
            las.write(str(p))
            paths.append(p)
        _cache["tiles"] = paths
    return _cache["tiles"]


def camera(bounds):
    lo, hi = bounds
    return clvis.Camera.fit(lo, hi, aspect=W / H)


# this process's CPU time would leave out the frames' work (benchutil.run's cpu=)
WORKERS_CPU = "the frames run in the Dask worker processes"


def cloud_bytes() -> int:
    return 16 * N  # xyz float32 + RGBA: DESIGN.md's bytes model of rasterization


def _cluster(n_workers, memory_limit="auto"):
    # one core per worker (inherited by the processes); a value set before is given back
    saved = {k: os.environ.get(k) for k in ("POCL_CPU_MAX_CU_COUNT", "POCL_MAX_PTHREAD_COUNT")}
    os.environ.update(dict.fromkeys(saved, "1"))
    try:
        return distributed.LocalCluster(
            n_workers=n_workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            memory_limit=memory_limit,
        )
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _frames(benchmark, n_workers, impl, role, rounds):
    limit = int(0.75 * cloud_bytes()) if n_workers == 2 else "auto"
    config = {"distributed.worker.memory.pause": False, "distributed.worker.memory.terminate": False}
    import dask

    with (
        dask.config.set(config),
        _cluster(n_workers, limit) as cluster,
        distributed.Client(cluster) as client,
    ):
        client.wait_for_workers(n_workers, timeout=120)
        t0 = time.perf_counter()
        with DistributedRasterizer(tiles(), client, fields=[], morton=True, timeout=TIMEOUT) as dr:
            load = time.perf_counter() - t0
            cam = camera(dr.bounds)
            g = dr.render(cam, W, H)  # warm-up: kernels built on the workers
            stats = [g.stats]

            def frame():
                stats.append(dr.render(cam, W, H).stats)

            run(
                benchmark,
                frame,
                op=POINTS_OP,
                impl=impl,
                role=role,
                n=N,
                nbytes=cloud_bytes(),
                rounds=rounds,
                cpu=WORKERS_CPU,
            )
            best = min(stats[1:], key=lambda s: s["seconds"]["frame"])
            sec = best["seconds"]
            managed = sum(w["metrics"].get("managed_bytes", 0) for w in connected_workers(client).values())
            rss = max(w["metrics"]["memory"] for w in connected_workers(client).values())
            per_worker_sent = sorted(best["bytes_sent"].values())
            benchmark.extra_info.update(
                workers=n_workers,
                load_seconds=load,
                frame_seconds=sec["frame"],
                render_seconds=sec["render"],
                composite_seconds=sec["composite"],
                composite_fraction=sec["composite"] / sec["frame"],
                bytes_sent_per_worker=per_worker_sent,
                frame_bytes=int(sum(a.nbytes for a in (g.index, g.depth, g.rgba))) + 8 * W * H,
                covered=int(g.covered.sum()),
                memory_limit=limit if isinstance(limit, int) else None,
                cloud_over_memory_limit=cloud_bytes() / limit if isinstance(limit, int) else None,
                max_worker_rss=int(rss),
                dask_managed_bytes=int(managed),
                device_bytes=dr.device_bytes,
            )
            _cache[("stats", n_workers)] = benchmark.extra_info.copy()
            _cache["view"] = (cam, g)


@pytest.mark.parametrize("impl", ["2 workers", "1 worker (one thread)", "single process Rasterizer"])
def test_points(benchmark, queue, impl):
    rounds = 5 if SCALE < 0.5 else 3
    if impl == "2 workers":
        _frames(benchmark, 2, impl, "clvis", rounds)
    elif impl == "1 worker (one thread)":
        _frames(benchmark, 1, impl, "peer", rounds)
    else:
        whole = concatenate([read_points(p) for p in tiles()])
        whole.attributes = {}
        r = clvis.Rasterizer(whole, queue=queue)
        lo, hi = whole.bounds()
        cam = camera((lo, hi))
        g = r.render(cam, W, H)
        if "view" in _cache:  # the distributed frame is this one, bit for bit
            assert np.array_equal(_cache["view"][1].index, g.index)
            assert np.array_equal(_cache["view"][1].rgba, g.rgba)
        run(
            benchmark,
            lambda: r.render(cam, W, H),
            op=POINTS_OP,
            impl=impl,
            role="peer",
            n=N,
            nbytes=cloud_bytes(),
            rounds=rounds,
        )
        del r, whole


def volume_path() -> Path:
    if "volume" not in _cache:
        from clvis import datasets

        p = _tmp() / f"turbulence_{SIDE}.npy"
        np.save(p, datasets.turbulence(SIDE)["volume"])  # float32 already: no copy
        _cache["volume"] = p
    return _cache["volume"]


@pytest.mark.parametrize("impl", ["2 workers", "2 workers, full frames", "single process IsoRenderer"])
def test_volume(benchmark, queue, impl):
    p = volume_path()
    w = h = 512 if SCALE >= 0.05 else 128
    n = SIDE**3
    cam = clvis.Camera.fit((0, 0, 0), (SIDE - 1,) * 3, aspect=1.0)
    if impl != "single process IsoRenderer":
        fp = impl == "2 workers"  # each brick renders and sends its screen footprint only
        with _cluster(2) as cluster, distributed.Client(cluster) as client:
            client.wait_for_workers(2, timeout=120)
            with DistributedIsoRenderer(p, client, rate=8, brick=max(16, SIDE // 4), timeout=TIMEOUT) as dr:
                img = dr.render(cam, w, h, 0.5, footprints=fp)
                stats = [img.stats]
                run(
                    benchmark,
                    lambda: stats.append(dr.render(cam, w, h, 0.5, footprints=fp).stats),
                    op=ISO_OP,
                    impl=impl,
                    # one clvis row an op (the ratios' and --compare's); full frames is a variant
                    role="clvis" if fp else "clvis-host",
                    n=n,
                    nbytes=4 * n,
                    rounds=3,
                    cpu=WORKERS_CPU,
                )
                best = min(stats[1:], key=lambda s: s["seconds"]["frame"])
                sec = best["seconds"]
                benchmark.extra_info.update(
                    bricks=len(dr.bricks),
                    composite_fraction=sec["composite"] / sec["frame"],
                    hits=int(img.hit.sum()),
                    pixels_rendered=int(best["pixels"]),
                    bytes_sent_per_worker=sorted(best["bytes_sent"].values()),
                )
    else:
        r = clvis.IsoRenderer(np.load(p), 8, queue=queue)
        r.render(cam, w, h, 0.5)
        run(
            benchmark,
            lambda: r.render(cam, w, h, 0.5),
            op=ISO_OP,
            impl=impl,
            role="peer",
            n=n,
            nbytes=4 * n,
            rounds=3,
        )


class MemoryWatch:
    """Peak resident memory of this process and its descendants (the
    LocalCluster's nannies and workers), sampled every `interval` seconds in
    a thread (psutil, which distributed needs): the peak of the sum of their
    RSS and of their PSS (shared pages, e.g. a memory-mapped file read by
    two workers, split between the processes that map them), in phases
    named by mark()."""

    def __init__(self, interval: float = 0.2) -> None:
        import threading

        import psutil

        self._psutil, self._me = psutil, psutil.Process()
        self.phase, self.peaks, self.interval = "start", {}, interval
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _sample(self) -> None:
        ps = [self._me, *self._me.children(recursive=True)]
        rss = pss = top = 0
        for p in ps:
            try:
                m = p.memory_full_info()
            except (self._psutil.NoSuchProcess, self._psutil.AccessDenied):
                continue
            rss, pss = rss + m.rss, pss + getattr(m, "pss", m.rss)
            if p is not self._me:
                top = max(top, m.rss)
        old = self.peaks.get(self.phase, {"rss": 0, "pss": 0, "client": 0, "worker": 0, "processes": 0})
        client = self._me.memory_info().rss
        self.peaks[self.phase] = {
            "rss": max(old["rss"], rss),
            "pss": max(old["pss"], pss),
            "client": max(old["client"], client),
            "worker": max(old["worker"], top),
            "processes": max(old["processes"], len(ps)),
        }

    def _loop(self) -> None:
        while not self._stop.is_set():
            self._sample()
            self._stop.wait(self.interval)

    def mark(self, phase: str) -> None:
        self._sample()
        self.phase = phase
        self._sample()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()
        self._sample()

    def report(self) -> None:
        print("| phase | peak RSS, sum | peak PSS, sum | client RSS | largest child RSS | processes |")
        print("|---|---|---|---|---|---|")
        for k, m in self.peaks.items():
            print(
                f"| {k} | {m['rss'] / 2**30:.2f} GiB | {m['pss'] / 2**30:.2f} GiB | "
                f"{m['client'] / 2**30:.2f} GiB | {m['worker'] / 2**30:.2f} GiB | {m['processes']} |"
            )
        top = max(m["pss"] for m in self.peaks.values())
        print(f"peak PSS of the bench process and its workers: {top / 2**30:.2f} GiB")


ROWS = {
    "default": ("single", "per worker, footprints"),
    "all": ("single", "per worker, footprints", "per brick, footprints", "per brick, full frames"),
}


def compare_volume(
    side: int = 512, rounds: int = 3, brick: Any = 128, size: int = 512, rows: str = "default"
) -> None:
    """One process, the renderers in turn (A B A B ...): turbulence side^3
    as .npy, the single IsoRenderer (PoCL on every core) against 2
    one-thread workers (rows "default": one IsoRenderer per worker with
    footprints, the library's default; "all": also one per brick, with and
    without footprints); per row each frame's wall time, the median, and
    the CPU seconds per frame (client + workers), pixels rendered and bytes
    sent per worker, the agreement of the images with the single one's
    (hit pixels that differ, largest depth gap), the load average of the
    machine around each round, and the peak memory of this process and its
    workers per phase (MemoryWatch).
        python bench/bench_distributed.py [SIDE [ROUNDS [BRICK [SIZE [ROWS]]]]]
    (BRICK: an edge, or Z,Y,X: 128,256,256 cuts 256^3 into one slab per worker)"""
    import resource

    global SIDE
    SIDE = side
    watch = MemoryWatch()
    print(f"load average at the start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    watch.mark("generating the volume, writing the .npy")
    p = volume_path()
    watch.mark("building the single IsoRenderer, its first frame")
    cam = clvis.Camera.fit((0, 0, 0), (side - 1,) * 3, aspect=1.0)
    single = clvis.IsoRenderer(np.load(p), 8)
    one = single.render(cam, size, size, 0.5)

    def cpu():
        r = resource.getrusage(resource.RUSAGE_SELF)
        return r.ru_utime + r.ru_stime

    kinds = ROWS[rows]
    table: dict = {k: {"wall": [], "cpu": []} for k in kinds}
    loads = []
    watch.mark("starting the cluster, building the distributed renderers, first frames")
    with _cluster(2) as cluster, distributed.Client(cluster) as client:
        client.wait_for_workers(2, timeout=120)

        def worker_cpu():
            return sum(client.run(lambda: sum(os.times()[:2])).values())

        with (
            DistributedIsoRenderer(p, client, rate=8, brick=brick, timeout=TIMEOUT) as slabs,
            DistributedIsoRenderer(p, client, rate=8, brick=brick, timeout=TIMEOUT, per_worker=False)
            if len(kinds) > 2
            else contextlib.nullcontext() as dr,
        ):

            def frame(k):
                r = slabs if k.startswith("per worker") else dr
                return r.render(cam, size, size, 0.5, footprints=k.endswith("footprints"))

            imgs = {k: frame(k) for k in table if k != "single"}
            watch.mark("frames")
            for _ in range(rounds):
                loads.append(os.getloadavg()[0])
                for k in table:
                    c0, w0, t0 = cpu(), worker_cpu() if k != "single" else 0.0, time.perf_counter()
                    if k == "single":
                        single.render(cam, size, size, 0.5)
                    else:
                        imgs[k] = frame(k)
                    table[k]["wall"].append(time.perf_counter() - t0)
                    table[k]["cpu"].append(cpu() - c0 + (worker_cpu() - w0 if k != "single" else 0.0))
            loads.append(os.getloadavg()[0])
            bricks = len(dr.bricks) if dr is not None else len(slabs.bricks)
            print(
                f"turbulence {side}^3 .npy, {bricks} bricks of {brick} cells, "
                f"{len(slabs._specs)} per-worker renderers, ZFP rate 8, {size}x{size}"
            )
    watch.stop()
    print(
        f"load average (1 min) before each round and after the last: {', '.join(f'{x:.1f}' for x in loads)}"
    )
    print(
        "| row | frames | median | CPU s/frame | pixels rendered | bytes sent per worker | median / single |"
    )
    print("|---|---|---|---|---|---|---|")
    for k, r in table.items():
        med, c = np.median(r["wall"]), np.median(r["cpu"])
        frames = ", ".join(f"{x * 1e3:.0f}" for x in r["wall"]) + " ms"
        if k == "single":
            print(
                f"| single IsoRenderer | {frames} | {med * 1e3:.0f} ms | {c:.2f} | {size * size:,} | - | - |"
            )
            continue
        st = imgs[k].stats
        sent = ", ".join(f"{b / 1e6:.2f} MB" for b in sorted(st["bytes_sent"].values()))
        diff = int((imgs[k].hit != one.hit).sum())
        both = imgs[k].hit & one.hit
        gap = float(np.abs(imgs[k].depth[both] - one.depth[both]).max()) if both.any() else 0.0
        ratio = med / np.median(table["single"]["wall"])
        print(
            f"| 2 workers, {k} | {frames} | {med * 1e3:.0f} ms | {c:.2f} | {st['pixels']:,} | "
            f"{sent} | {ratio:.2f}x; hits differ at {diff} px, depth gap {gap:.2e} |"
        )
    watch.report()


if __name__ == "__main__":
    import sys

    args = [
        a if a in ROWS else tuple(int(x) for x in a.split(",")) if "," in a else int(a) for a in sys.argv[1:]
    ]
    compare_volume(*args)  # type: ignore[arg-type]
