"""Helpers shared by the bench/ suites."""

import contextlib
import importlib
import os
import resource


def scaled(n: int) -> int:
    """n times CLVIS_BENCH_SCALE (default 1), at least 1024: CI's smoke runs
    shrink every size; the figures come from full runs."""
    scale = float(os.environ.get("CLVIS_BENCH_SCALE", "1"))
    return max(1024, int(n * scale))


def run(benchmark, fn, *, op, impl, role, n, nbytes, queue=None, rounds=11, cpu=True, **info):
    """Time fn (finishing `queue` inside the timing) and record what the
    report needs: op (the benchmark group), impl, role ("clvis", "clvis-host",
    "peer" or "copy"), n elements and the bytes model; and the process's CPU
    time (user + system, all its threads) of each timed round, as extra_info
    "cpu_s" (other tenants of a shared machine do not inflate it the way they
    inflate wall time). cpu=False, or a reason string, where this process's
    CPU time is not the op's (its work runs in other processes): no "cpu_s",
    and the reason as "cpu_not_recorded"."""
    benchmark.group = op
    benchmark.extra_info.update(op=op, impl=impl, role=role, n=int(n), bytes=int(nbytes), **info)
    times: list[float] = []
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
        times.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
        return r

    benchmark.pedantic(call, rounds=rounds, warmup_rounds=1, iterations=1)
    if cpu is not True:
        benchmark.extra_info["cpu_not_recorded"] = cpu or "the op's work runs in other processes"
        return
    # the timed rounds come after the warm-up one; --benchmark-cprofile calls
    # fn once more after them (profiled), --benchmark-disable only once
    benchmark.extra_info["cpu_s"] = times[1 : 1 + rounds] if len(times) > rounds else times


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


@contextlib.contextmanager
def threads(**counts):
    """Run a peer with `counts` threads per library (numba=2, torch=4), then
    give each library back the count it had: a case's setting must not carry
    into the cases after it, nor into the rest of a pytest session."""
    mods = {name: importlib.import_module(name) for name in counts}
    before = {name: m.get_num_threads() for name, m in mods.items()}
    try:
        for name, m in mods.items():
            m.set_num_threads(counts[name])
        yield
    finally:
        for name, m in mods.items():
            m.set_num_threads(before[name])
