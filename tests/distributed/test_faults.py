"""Faults and waits of the distributed renderers on real, bounded
LocalClusters: a worker killed during a frame of a volume built from an
array (its bricks are sent again from the client), the only worker killed
(its partitions and bricks are made again on the one that replaces it), a
worker that runs out of its memory limit, a worker stopped (SIGSTOP)
during a frame and at close (bounded waits, errors that say what timed
out), scheduler addresses that refuse connections, are no Dask scheduler
or have no workers (fail in seconds), files a worker cannot read or finds
elsewhere, and a renderer used after close()."""

import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from dask_cluster import (
    TIMEOUT,
    banner_server,
    distributed,
    http_like_server,
    local_cluster,
    silent_scheduler,
    web_server,
)

from clvis import Camera, datasets
from clvis.distributed import DistributedIsoRenderer, DistributedRasterizer
from clvis.distributed import cluster as dcluster
from clvis.distributed import composite as C
from clvis.distributed import iso as diso
from clvis.distributed.cluster import connected_workers
from clvis.errors import ClusterError, ClusterTimeout, ClvisError
from clvis.io import PointCloud, save_npz

W, H = 40, 32
_ML = datasets.marschner_lobb(25)


def _cam():
    return Camera.look_at((2.2, -2.6, 1.8), (0, 0, 0), (0, 0, 1), fov_y=40, aspect=W / H, near=0.05, far=20)


def _iso(client, **kw):
    return DistributedIsoRenderer(
        _ML["volume"], client, rate=16, spacing=_ML["spacing"], origin=_ML["origin"], brick=8, **kw
    )


def _same_image(a, b):
    assert np.array_equal(a.hit, b.hit)
    assert np.array_equal(a.depth, b.depth) and np.array_equal(a.rgba, b.rgba)


def _pid(client, worker):
    return client.run(os.getpid, workers=[worker])[worker]


def _sole_holders(client, dr) -> list[str]:
    """Workers whose death loses a brick for good: the one worker holding
    both a brick's scattered samples and its built handle. Dask may have
    copied both to the other worker too (a stolen task takes its inputs
    along): then killing one worker loses nothing, so both are named."""
    has = client.who_has(list(dr._arrays) + list(dr._handles))
    for a, h in zip(dr._arrays, dr._handles, strict=True):
        on_a, on_h = set(has[a.key]), set(has[h.key])
        if len(on_a) == 1 and on_h <= on_a:
            return sorted(on_a)
    return sorted(connected_workers(client))


def test_a_worker_killed_during_a_frame_of_an_array_volume(monkeypatch):
    """The bricks of an in-memory array were scattered from the client: a
    worker killed with the frame's tasks in flight takes some of them along
    ("lost scattered data"). The renderer sends them again and the frame,
    and every later one, equals the undisturbed image."""
    with local_cluster() as cluster, distributed.Client(cluster, timeout=TIMEOUT) as c:
        c.wait_for_workers(2, timeout=TIMEOUT)
        with _iso(c, timeout=TIMEOUT) as dr:
            want = dr.render(_cam(), W, H, 0.5)
            assert want.hit.sum() > 100 and len(dr.bricks) == 27
            held = {h.worker for h in dr._built}
            assert len(held) == 2  # both workers hold bricks
            victim = sorted(held)[0]
            pid = _pid(c, victim)
            view = {"camera": _cam(), "width": W, "height": H, "isovalue": 0.5, "speculation": True}
            frame, _ = dr.submit_frame(diso.render_one, view)  # in flight ...
            os.kill(pid, signal.SIGKILL)  # ... when the worker dies
            with pytest.raises(distributed.CancelledError, match="already forgotten|lost"):
                distributed.wait(frame, timeout=TIMEOUT)  # what broke every later frame
            # the next frames: lost bricks sent again from the client's array, rebuilt
            for _ in range(2):
                got = dr.render(_cam(), W, H, 0.5)
                _same_image(got, want)
            assert victim not in connected_workers(c)
            # killed during render() itself: it recovers inside the call
            held = sorted({h.worker for h in dr._built})
            pid = _pid(c, held[-1])
            killer = threading.Timer(0.05, os.kill, (pid, signal.SIGKILL))
            killer.start()
            _same_image(dr.render(_cam(), W, H, 0.5), want)
            _same_image(dr.render(_cam(), W, H, 0.5), want)
            # (the kill can land after both frames, on a busy machine or a fast
            # one: wait for the scheduler to drop that worker and render once
            # more, so the bricks and victims below are live ones)
            killer.join()
            deadline = time.monotonic() + TIMEOUT
            while held[-1] in connected_workers(c) and time.monotonic() < deadline:
                time.sleep(0.1)
            _same_image(dr.render(_cam(), W, H, 0.5), want)  # (what a late kill lost: sent again)
            # a loss that is not recovered (no retries left): a clvis error
            # naming the bricks and the worker that held them
            monkeypatch.setattr(dcluster, "FRAME_RETRIES", 0)
            victims = _sole_holders(c, dr)  # killing them loses some brick for good
            pids = c.run(os.getpid, workers=victims)  # all of them before the first dies
            for v in victims:
                os.kill(pids[v], signal.SIGKILL)
            deadline = time.monotonic() + TIMEOUT
            while set(victims) & set(connected_workers(c)) and time.monotonic() < deadline:
                time.sleep(0.1)
            on = "|".join(map(re.escape, victims))
            lost = rf"after 0 recoveries; lost: bricks \(\(\d+, \d+\), .*\(were on ({on})\)"
            with pytest.raises(ClusterError, match=lost):
                dr.render(_cam(), W, H, 0.5)
            monkeypatch.undo()  # retries again: the next frame recovers
            _same_image(dr.render(_cam(), W, H, 0.5), want)


def test_a_stopped_worker_times_out_with_a_clvis_error_and_close_is_bounded(tmp_path):
    """SIGSTOP one worker: a frame raises ClusterTimeout within about its
    timeout, naming the frame and the stopped worker; close() returns within
    a bounded time too (it does not wait for the stopped worker)."""
    timeout = 4.0
    with local_cluster() as cluster, distributed.Client(cluster, timeout=TIMEOUT) as c:
        c.wait_for_workers(2, timeout=TIMEOUT)
        dr = _iso(c, timeout=TIMEOUT, connect_timeout=2.0)
        pid = None
        try:
            dr.render(_cam(), W, H, 0.5)
            dr.timeout = timeout  # the frames' bound (the build may take longer on a busy machine)
            victim = sorted({h.worker for h in dr._built})[0]
            pid = _pid(c, victim)
            os.kill(pid, signal.SIGSTOP)
            t0 = time.monotonic()
            with pytest.raises(ClusterTimeout, match=r"frame .*not done within timeout=4 s") as e:
                dr.render(_cam(), W, H, 0.5)
            assert time.monotonic() - t0 < 3 * timeout + 5
            assert isinstance(e.value, TimeoutError) and isinstance(e.value, ClvisError)
            assert victim in str(e.value)
            t0 = time.monotonic()
            dr.close()
            assert time.monotonic() - t0 < 2 * timeout + 5
            with pytest.raises(ClusterError, match="DistributedIsoRenderer: closed"):
                dr.render(_cam(), W, H, 0.5)
        finally:
            if pid is not None:
                os.kill(pid, signal.SIGKILL)  # the nanny starts another
            dr.close()


def test_a_stopped_scheduler_times_out_with_a_clvis_error():
    """The scheduler itself stops answering (SIGSTOP) after the client
    connected: building a renderer raises ClusterTimeout within about its
    timeout (asking it for its workers waited forever before)."""
    port = _closed_port()
    address = f"tcp://127.0.0.1:{port}"
    cmd = [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1"]
    cmd += ["--port", str(port), "--no-dashboard"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    c = None
    try:
        deadline = time.monotonic() + TIMEOUT
        while c is None:
            try:
                c = distributed.Client(address, timeout=5)
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        os.kill(proc.pid, signal.SIGSTOP)
        t0 = time.monotonic()
        with pytest.raises(ClusterTimeout, match="the scheduler's list of workers: no answer within 3 s"):
            DistributedIsoRenderer(np.zeros((8, 8, 8), np.float32), c, brick=4, timeout=3)
        assert time.monotonic() - t0 < 3 * 3 + 5
    finally:
        proc.kill()
        proc.wait(TIMEOUT)
        if c is not None:
            c.close(timeout=10)


def test_render_after_close_says_closed(tmp_path):
    rng = np.random.default_rng(0)
    path = tmp_path / "t.npz"
    save_npz(path, PointCloud(rng.uniform(0, 1, (500, 3))))
    with DistributedRasterizer([path], workers=1, timeout=TIMEOUT) as dr:
        cam = Camera.look_at((3, -2, 2), (0.5, 0.5, 0.5), (0, 0, 1), aspect=W / H)
        assert (dr.render(cam, W, H).index != C.ids_of(C.EMPTY_KEY)).any()
    with pytest.raises(ClusterError, match="DistributedRasterizer: closed; make a new one"):
        dr.render(cam, W, H)
    with pytest.raises(ClusterError, match="closed"):
        dr.sample()
    dr.close()  # twice: harmless


def test_a_local_cluster_leaves_this_processs_environment_as_it_was(tmp_path, monkeypatch):
    """Dask's nanny sets its pre-spawn variables (OMP_NUM_THREADS=1,
    MALLOC_TRIM_THRESHOLD_=65536, ...) and __DASK_PARENT_PID in the process
    that starts a LocalCluster and never takes them back: after a
    DistributedRasterizer(workers=1) every later subprocess of the user's ran
    on one OpenMP thread. Now the variables are as they were, while the
    cluster runs (after each frame) and after it closed."""
    from clvis.distributed.cluster import dask_environ_keys

    keys = dask_environ_keys()
    assert {"OMP_NUM_THREADS", "MALLOC_TRIM_THRESHOLD_", "__DASK_PARENT_PID"} <= set(keys)
    for k in keys:  # the user's own: one unset, one of theirs
        monkeypatch.delenv(k, raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "7")
    before = {k: os.environ.get(k) for k in keys}
    rng = np.random.default_rng(0)
    path = tmp_path / "t.npz"
    save_npz(path, PointCloud(rng.uniform(0, 1, (500, 3))))
    with DistributedRasterizer([path], workers=1, timeout=TIMEOUT) as dr:
        assert {k: os.environ.get(k) for k in keys} == before
        cam = Camera.look_at((3, -2, 2), (0.5, 0.5, 0.5), (0, 0, 1), aspect=W / H)
        dr.render(cam, W, H)
        assert {k: os.environ.get(k) for k in keys} == before
    assert {k: os.environ.get(k) for k in keys} == before


def _children():
    """This process's child processes but multiprocessing's own helpers
    (the resource tracker, the forkserver: one per process, not workers)."""
    psutil = pytest.importorskip("psutil")  # a dependency of dask.distributed
    out = set()
    for p in psutil.Process().children(recursive=True):
        try:
            cmd = " ".join(p.cmdline())
            if p.status() == psutil.STATUS_ZOMBIE:
                continue
        except psutil.Error:  # gone meanwhile
            continue
        if "resource_tracker" not in cmd and "forkserver" not in cmd:
            out.add(p.pid)
    return out


def _ctrl_c_while_starting(start):
    """start() with SIGINT sent to this process (from another thread, as a
    terminal's Ctrl-C) as soon as a worker process of the LocalCluster it
    starts exists: the start then waits for that worker to join (its
    imports: a second or more). The SIGINT handler meanwhile records the
    signal and raises KeyboardInterrupt while start() runs. Returns what
    start returned or raised ("out"), the seconds from the signal to its end
    ("took"), the signals the handler saw ("got"), whether the handler was
    still the one installed ("kept"), the LocalClusters made meanwhile and
    not closed when start() ended ("open") and clvis's starting threads
    still running then ("starting")."""
    from distributed.deploy.spec import SpecCluster

    got: list = []
    armed = [True]

    def handler(signum, frame):
        got.append(signum)
        if armed:
            raise KeyboardInterrupt

    before = _children()
    clusters = set(SpecCluster._instances)
    sent: list = []
    done: list = []

    def watch():
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline and not done:
            if _children() - before:
                sent.append(time.monotonic())
                os.kill(os.getpid(), signal.SIGINT)
                return
            time.sleep(0.01)

    old = signal.signal(signal.SIGINT, handler)
    watcher = threading.Thread(target=watch, daemon=True)
    try:
        watcher.start()
        try:
            out = start()
        except BaseException as e:  # noqa: BLE001 - what the test looks at
            out = e
        ended = time.monotonic()
        armed.clear()
        opened = [repr(c) for c in set(SpecCluster._instances) - clusters if c.status.name != "closed"]
        starting = [t.name for t in threading.enumerate() if t.name == "clvis-start-cluster"]
        done.append(True)
        watcher.join(TIMEOUT)
        kept = signal.getsignal(signal.SIGINT) is handler
    finally:
        signal.signal(signal.SIGINT, old)
    if not isinstance(out, BaseException):
        out.close()
    assert sent, "no worker process started"
    return {
        "out": out,
        "took": ended - sent[0],
        "got": got,
        "kept": kept,
        "open": opened,
        "starting": starting,
    }


def _no_worker_left(started_before):
    deadline = time.monotonic() + 10
    while (left := _children() - started_before) and time.monotonic() < deadline:
        time.sleep(0.1)
    return not left


def _check_stopped(r, before):
    """A Ctrl-C while starting stopped it: KeyboardInterrupt, no cluster
    open and no start running when it was raised, no worker left."""
    assert isinstance(r["out"], KeyboardInterrupt), r["out"]
    assert r["got"] == [signal.SIGINT] and r["kept"]
    assert r["took"] < 15, f"{r['took']:.1f} s from the Ctrl-C to the KeyboardInterrupt"
    assert not r["open"] and not r["starting"], r
    assert _no_worker_left(before)


def test_a_ctrl_c_while_a_local_cluster_starts_stops_it():
    """SIGINT was ignored while the LocalCluster started (so that its
    workers inherited the ignoring): a Ctrl-C in those seconds was lost and
    the render ran to its end. Now the start runs in a thread of its own,
    the caller's handler sees the Ctrl-C at once, the started cluster is
    closed (no worker process left) and the KeyboardInterrupt is raised
    then, not before; the handler and the environment are as they were."""
    from clvis.distributed.cluster import dask_environ_keys

    env = {k: os.environ.get(k) for k in dask_environ_keys()}
    before = _children()
    _check_stopped(_ctrl_c_while_starting(lambda: dcluster.start_cluster(1)), before)
    assert {k: os.environ.get(k) for k in dask_environ_keys()} == env


def test_a_ctrl_c_while_a_renderers_local_cluster_starts_stops_it(tmp_path):
    """The same through DistributedRasterizer(workers=1), as `clvis render
    --workers 1` builds it: no renderer, no worker process left."""
    path = tmp_path / "t.npz"
    save_npz(path, PointCloud(np.random.default_rng(0).uniform(0, 1, (500, 3))))
    before = _children()
    r = _ctrl_c_while_starting(
        lambda: DistributedRasterizer([path], workers=1, timeout=TIMEOUT, connect_timeout=10)
    )
    _check_stopped(r, before)


def test_local_workers_never_see_sigint():
    """A terminal's Ctrl-C reaches the whole process group: the workers of
    a LocalCluster started here hold SIGINT back (blocked; the thread that
    starts the cluster blocks it and Dask's threads and the workers inherit
    the mask) from their first instruction, in a fresh process too (where
    multiprocessing's resource tracker, started by the first spawn,
    unblocked it in the spawning thread: the workers saw SIGINT)."""
    if not sys.platform.startswith("linux"):
        pytest.skip("reads /proc/PID/status")
    code = (
        "import psutil\n"
        "from clvis.distributed.cluster import start_cluster\n"
        "c = start_cluster(2)\n"
        "for p in psutil.Process().children():\n"
        "    if 'resource_tracker' not in ' '.join(p.cmdline()):\n"
        "        st = dict(ln.split(':', 1) for ln in open(f'/proc/{p.pid}/status'))\n"
        "        print(int(st['SigBlk'], 16) | int(st['SigIgn'], 16))\n"
        "c.close()\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=TIMEOUT)
    assert r.returncode == 0, r.stderr
    masks = [int(x) for x in r.stdout.split()]
    assert len(masks) == 2 and all(m & (1 << (signal.SIGINT - 1)) for m in masks), r.stdout


def _closed_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now
    return port


def test_a_refused_scheduler_fails_in_seconds():
    port = _closed_port()
    for cls in (DistributedRasterizer, DistributedIsoRenderer):
        t0 = time.monotonic()
        src = ["x.npz"] if cls is DistributedRasterizer else np.zeros((8, 8, 8), np.float32)
        with pytest.raises(ClusterError, match=f"scheduler tcp://127.0.0.1:{port}: cannot connect"):
            cls(src, f"tcp://127.0.0.1:{port}", timeout=TIMEOUT)
        assert time.monotonic() - t0 < 5


def test_a_silent_scheduler_fails_after_connect_timeout():
    """A port that accepts and never speaks Dask: the Client's own connect
    waits connect_timeout, not the render timeout."""
    with silent_scheduler() as address:
        t0 = time.monotonic()
        with pytest.raises(ClusterError, match=f"scheduler {address}: not reached within"):
            DistributedRasterizer(["x.npz"], address, timeout=600, connect_timeout=2)
        assert time.monotonic() - t0 < 20
    with pytest.raises(ValueError, match="connect_timeout: expected a positive number"):
        DistributedRasterizer(["x.npz"], "tcp://127.0.0.1:1", connect_timeout=0)


def _wait_replaced(c, victim):
    """Until the scheduler has dropped `victim` and the nanny's new worker has joined."""
    deadline = time.monotonic() + TIMEOUT
    while time.monotonic() < deadline:
        now = connected_workers(c)
        if victim not in now and now:
            return
        time.sleep(0.1)
    raise AssertionError(f"{victim} not replaced within {TIMEOUT} s")


@pytest.mark.parametrize("kind", ["points", "volume file"])
def test_the_only_worker_killed_between_and_during_frames(tmp_path, kind):
    """One worker (clvis render --workers 1): SIGKILL it and its nanny
    starts another. What it held is made again there: the next frames, and
    a frame in flight at the kill, equal the undisturbed one. (The handles
    were pinned to the dead worker, and Dask never gives a task whose
    pinned workers are gone to a worker that joins later: every frame
    after waited out its whole timeout.)"""
    if kind == "points":
        rng = np.random.default_rng(5)
        src = tmp_path / "p.npz"
        save_npz(src, PointCloud(rng.uniform(-1, 1, (3000, 3)), attributes={"a": rng.random(3000)}))
    else:
        src = tmp_path / "v.npy"
        np.save(src, _ML["volume"].astype(np.float32))
    with local_cluster(n_workers=1) as cluster, distributed.Client(cluster, timeout=TIMEOUT) as c:
        c.wait_for_workers(1, timeout=TIMEOUT)
        if kind == "points":
            dr = DistributedRasterizer([src], c, timeout=20)
            view = dr._view(_cam(), W, H, "a", "viridis", None, None, 1)

            def render():
                g = dr.render(_cam(), W, H, color_by="a")
                return g.index, g.depth, g.rgba
        else:
            dr = DistributedIsoRenderer(
                src, c, rate=16, spacing=_ML["spacing"], origin=_ML["origin"], brick=8, timeout=20
            )
            view = {"camera": _cam(), "width": W, "height": H, "isovalue": 0.5, "speculation": True}

            def render():
                img = dr.render(_cam(), W, H, 0.5)
                return img.hit, img.depth, img.rgba

        with dr:
            want = render()
            for during in (False, True):
                (victim,) = connected_workers(c)
                inflight = dr.submit_frame(render_one_of(dr), view)[0] if during else None
                os.kill(_pid(c, victim), signal.SIGKILL)
                _wait_replaced(c, victim)
                t0 = time.monotonic()
                if inflight is not None:  # the frame in flight at the kill completes
                    whole = C.assemble(dr._gather(inflight, "the frame in flight"), (H, W))
                    assert np.array_equal(whole.planes["rgba"], want[2])
                for got, exp in zip(render(), want, strict=True):
                    assert np.array_equal(got, exp)
                assert time.monotonic() - t0 < 15


def render_one_of(dr):
    from clvis.distributed import raster

    return raster.render_one if isinstance(dr, DistributedRasterizer) else diso.render_one


def test_a_worker_out_of_its_memory_limit_is_a_clvis_error_in_seconds(tmp_path):
    """A partition larger than a worker's memory limit: its nanny restarts
    the worker each time it builds it, and the build fails with a
    ClusterError naming the file, in seconds (it waited out the whole
    timeout: Dask kept the build for the first, dead, worker)."""
    rng = np.random.default_rng(1)
    path = tmp_path / "big.npz"
    n = 3_000_000  # ~50 MB of points, ~250 MB on a worker with its device buffers
    save_npz(path, PointCloud(rng.random((n, 3), np.float32), attributes={"i": rng.random(n, np.float32)}))
    with (
        local_cluster(n_workers=1, memory_limit="250MB") as cluster,
        distributed.Client(cluster, timeout=TIMEOUT) as c,
    ):
        c.wait_for_workers(1, timeout=TIMEOUT)
        t0 = time.monotonic()
        with pytest.raises(
            ClusterError, match=r"big\.npz: the worker running it died, \d+ times \(out of memory"
        ):
            DistributedRasterizer([path], c, timeout=40)
        assert time.monotonic() - t0 < 30


def test_a_port_where_no_dask_scheduler_answers_is_a_clvis_error():
    """A web server's port: its reply, read as Dask's, was a MemoryError of
    exabytes ("out of host memory" on the command line); an http:// or a
    port-less address was Dask's bare ValueError."""
    with http_like_server() as hostport:
        address = f"tcp://{hostport}"
        with pytest.raises(ClusterError, match=f"scheduler {address}: what answered there is not a Dask sch"):
            DistributedRasterizer(["x.npz"], address, timeout=TIMEOUT, connect_timeout=5)
        with pytest.raises(ClusterError, match=r"not a Dask address \(scheme 'http://'; Dask's: .*tcp://"):
            DistributedIsoRenderer(np.zeros((8, 8, 8), np.float32), f"http://{hostport}", timeout=TIMEOUT)
    for address in ("localhost", "tcp://127.0.0.1:99999"):
        with pytest.raises(ClusterError, match=f"scheduler {re.escape(address)}: not a host:port address"):
            DistributedRasterizer(["x.npz"], address, timeout=TIMEOUT)


def test_a_web_server_that_waits_for_a_request_is_no_dask_scheduler_in_seconds(tmp_path):
    """`python -m http.server` answers only a whole HTTP request: Dask's
    handshake is none, so the Client waited out connect_timeout (10 s) and
    said "not reached". Now the probe asks it as a web client would once it
    stays silent (a Dask scheduler speaks first): a ClusterError in about a
    second. A server that speaks first (an SSH banner) is told at once; a
    real scheduler still connects."""
    with web_server(tmp_path) as hostport:
        for address in (hostport, f"tcp://{hostport}"):
            t0 = time.monotonic()
            said = r"what answered there is not a Dask scheduler \(it said 'HTTP/1\.0 200 OK'\)"
            with pytest.raises(ClusterError, match=rf"scheduler {address}: {said}"):
                DistributedRasterizer(["x.npz"], address, timeout=TIMEOUT, connect_timeout=10)
            assert time.monotonic() - t0 < 5
    with banner_server() as hostport:
        with pytest.raises(ClusterError, match=r"not a Dask scheduler \(it said 'SSH-2\.0-OpenSSH_9\.6'\)"):
            DistributedIsoRenderer(
                np.zeros((8, 8, 8), np.float32), hostport, timeout=TIMEOUT, connect_timeout=10
            )
        t0 = time.monotonic()
        with pytest.raises(ClusterError, match="not a Dask scheduler"):
            dcluster._probe(hostport, 10.0)
        assert time.monotonic() - t0 < dcluster.PROBE_QUIET  # told before the probe would ask anything


def test_the_probe_takes_a_dask_schedulers_first_words_as_dask():
    """The probe reads a scheduler's handshake (it speaks first) and
    leaves: nothing sent, no error, in well under the wait for a silent
    peer; a bare scheduler, no worker needed."""
    with distributed.LocalCluster(n_workers=0, dashboard_address=":0") as cluster:
        for _ in range(3):
            t0 = time.monotonic()
            dcluster._probe(cluster.scheduler_address, 10.0)
            assert time.monotonic() - t0 < dcluster.PROBE_QUIET
        with distributed.Client(cluster.scheduler_address, timeout=TIMEOUT) as c:
            assert c.scheduler_info()["address"] == cluster.scheduler_address


def test_a_scheduler_without_workers_fails_after_connect_timeout():
    """Its tasks would wait out the whole timeout (then: not done)."""
    with distributed.LocalCluster(n_workers=0, dashboard_address=":0") as cluster:
        t0 = time.monotonic()
        address = cluster.scheduler_address
        with pytest.raises(
            ClusterError, match=f"scheduler {address}: no worker joined it within connect_timeout=2 s"
        ):
            DistributedRasterizer(["x.npz"], address, timeout=30, connect_timeout=2)
        assert time.monotonic() - t0 < 15


def test_local_workers_are_bounded_by_the_cores():
    """workers=100000 started that many processes (the machine went down first)."""
    most = dcluster.local_workers_max()
    assert most >= dcluster.WORKERS_PER_CORE
    with pytest.raises(ValueError, match=f"workers: {most + 1} local worker processes; at most {most} here"):
        DistributedRasterizer(["x.npz"], workers=most + 1)


def _deny_on_worker(name):
    """Run on a worker: opening a path that ends with `name` raises
    PermissionError, as for a file whose mode changed after the client
    looked (a test running as root reads any file)."""
    import builtins

    real = builtins.open

    def guarded(file, *a, **k):
        if str(file).endswith(name):
            raise PermissionError(13, "Permission denied", str(file))
        return real(file, *a, **k)

    builtins.open = guarded


def test_a_file_a_worker_may_not_read_names_it_and_the_reason(tmp_path):
    """NIfTI said "Cannot work out file type" (nibabel's guess, the reason
    lost); point files said neither where nor that it was a permission."""
    nibabel = pytest.importorskip("nibabel")
    pytest.importorskip("laspy")
    from pathlib import Path

    nii = tmp_path / "locked.nii"
    nibabel.save(nibabel.Nifti1Image(np.zeros((8, 8, 8), np.float32), np.eye(4)), nii)
    las = tmp_path / "locked.laz"
    las.write_bytes((Path(__file__).parents[1] / "data" / "laspy_simple.laz").read_bytes())
    with local_cluster(n_workers=1) as cluster, distributed.Client(cluster, timeout=TIMEOUT) as c:
        c.wait_for_workers(1, timeout=TIMEOUT)
        (w,) = connected_workers(c)
        c.run(_deny_on_worker, "locked.nii")
        c.run(_deny_on_worker, "locked.laz")
        with pytest.raises(
            ClvisError, match=f"{re.escape(str(nii))}: cannot read it on worker {w}: Permission denied$"
        ):
            DistributedIsoRenderer(nii, c, brick=8, timeout=TIMEOUT)
        with pytest.raises(
            ClvisError, match=f"{re.escape(str(las))}: cannot read it on worker {w}: Permission denied$"
        ):
            DistributedRasterizer([las], c, timeout=TIMEOUT)


def test_relative_paths_are_read_where_the_client_found_them(tmp_path, monkeypatch):
    """Workers started in another folder (a dask worker elsewhere, on a
    shared file system) were sent the paths as given: "no such file"."""
    rng = np.random.default_rng(3)
    (tmp_path / "d").mkdir()
    save_npz(tmp_path / "d" / "t.npz", PointCloud(rng.uniform(0, 1, (500, 3))))
    np.save(tmp_path / "d" / "v.npy", _ML["volume"].astype(np.float32))
    with local_cluster(n_workers=1) as cluster, distributed.Client(cluster, timeout=TIMEOUT) as c:
        c.wait_for_workers(1, timeout=TIMEOUT)
        monkeypatch.chdir(tmp_path / "d")  # the client's folder; the worker's is another
        assert str(tmp_path / "d") not in c.run(os.getcwd).values()
        with DistributedRasterizer(["t.npz"], c, timeout=TIMEOUT) as dr:
            assert dr.n == 500
        with DistributedIsoRenderer("v.npy", c, brick=8, timeout=TIMEOUT) as di:
            assert di.volume_shape == _ML["volume"].shape
