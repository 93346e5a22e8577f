"""Helpers shared by the bench/ suites."""

import os
import resource


def scaled(n: int) -> int:
    """n times CLVIS_BENCH_SCALE (default 1), at least 1024: CI's smoke runs
    shrink every size; the figures come from full runs."""
    scale = float(os.environ.get("CLVIS_BENCH_SCALE", "1"))
    return max(1024, int(n * scale))


def run(benchmark, fn, *, op, impl, role, n, nbytes, queue=None, rounds=11, **info):
    """Time fn (finishing `queue` inside the timing) and record what the
    report needs: op (the benchmark group), impl, role ("clvis", "clvis-host",
    "peer" or "copy"), n elements and the bytes model; and the process's CPU
    time (user + system) of each round, as extra_info "cpu_s" (other tenants
    of a shared machine do not inflate it the way they inflate wall time)."""
    benchmark.group = op
    benchmark.extra_info.update(op=op, impl=impl, role=role, n=int(n), bytes=int(nbytes), **info)
    cpu: list[float] = []
    # CLVIS_BENCH_SLOWDOWN=k runs each clvis case k times a round: a real,
    # known slow-down for testing `clvis bench --compare --fail-on`
    repeat = int(os.environ.get("CLVIS_BENCH_SLOWDOWN", "1")) if role == "clvis" else 1

    def call():
        r0 = resource.getrusage(resource.RUSAGE_SELF)
        for _ in range(repeat - 1):
            fn()
            if queue is not None:
                queue.finish()
        r = fn()
        if queue is not None:
            queue.finish()
        r1 = resource.getrusage(resource.RUSAGE_SELF)
        cpu.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
        return r

    benchmark.pedantic(call, rounds=rounds, warmup_rounds=1, iterations=1)
    benchmark.extra_info["cpu_s"] = cpu[-rounds:] if cpu else []


def run_copy(benchmark, queue, op, xd, n, out=None):
    """The op's bandwidth limit: the device copy kernel over its main array
    (into `out`, the buffer the op itself writes, where there is one)."""
    from clvis import primitives

    run(
        benchmark,
        lambda: primitives.copy(xd, out=out),
        op=op,
        impl="copy kernel",
        role="copy",
        n=n,
        nbytes=2 * xd.nbytes,
        queue=queue,
    )
