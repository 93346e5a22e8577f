"""Per-stage split of the viewer's NARVis frame (bench_view's scene: the
embedded hurricane, 2,000,000 points, mode narvis, 512x512, the camera 3
degrees of orbit further each round): wall and process CPU time (every
thread: PoCL's and onnxruntime's) of the G-buffer render, the pack kernel,
onnxruntime's inference, the kernel-prediction head (clvis.post.kpn's
kernels, where the card has a "head": the shipped one since issue 28), the
unpack kernel with the picture's read-back, the composite over the
background and the JPEG encode, the median over the rounds; with --ops,
onnxruntime's own profile of the inference by operator type (its op times,
summed over the runs, per run). --model-dir: a folder with another
narvis.json and its files (e.g. the full-graph model of before issue 28,
for an A/B).

    python bench/profile_view.py [--points 2000000] [--size 512x512] [--rounds 10] [--ops] [--model-dir D]

A measuring script, not a test: it calls the scene's and the network's
stages one by one, as PointScene.frames does in one go, on the default
OpenCL device.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import tempfile
import time

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from clvis import PointCloud, datasets
from clvis.post import infer
from clvis.post.pack import padded_shape, unpack_rgba8
from clvis.view import Orbit, PointScene
from clvis.view.scenes import _premultiplied_over_background
from clvis.view.server import _QUALITY, encode_jpeg

STAGES = ("render", "pack", "inference", "kpn head", "unpack + read back", "composite", "encode")


def _clock() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def _ops(path: str, x: np.ndarray, runs: int) -> None:
    """onnxruntime's profile of `runs` inferences on `x`, by operator type."""
    import onnxruntime as ort

    so = ort.SessionOptions()  # the settings clvis.post.infer uses
    so.intra_op_num_threads = os.cpu_count() or 1
    so.inter_op_num_threads = 1
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    so.add_session_config_entry("session.inter_op.allow_spinning", "0")
    so.enable_profiling = True
    so.profile_file_prefix = os.path.join(tempfile.mkdtemp(), "ort")
    session = ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])
    name = session.get_inputs()[0].name
    session.run(None, {name: x})  # warm-up (counted out below: the first run's events)
    for _ in range(runs):
        session.run(None, {name: x})
    with open(session.end_profiling()) as f:
        events = json.load(f)
    per_run = [e for e in events if e.get("cat") == "Node" and e["name"].endswith("_kernel_time")]
    nodes = len(per_run) // (runs + 1)
    per_run = per_run[nodes:]  # the warm-up's nodes came first
    total: collections.Counter[str] = collections.Counter()
    count: collections.Counter[str] = collections.Counter()
    for e in per_run:
        op = e["args"].get("op_name", "?")
        total[op] += e["dur"]
        count[op] += 1
    whole = sum(total.values())
    print(f"\nonnxruntime op times, {runs} runs ({nodes} nodes a run; wall us summed per op type)")
    for op, t in total.most_common(14):
        share = 100 * t / whole
        print(f"  {op:16s} {t / runs / 1e3:8.1f} ms a run  {count[op] // runs:4d} nodes  {share:5.1f} %")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=2_000_000)
    ap.add_argument("--size", default="512x512", help="WxH")
    ap.add_argument("--rounds", type=int, default=10)
    ap.add_argument("--ops", action="store_true", help="onnxruntime's profile by operator type too")
    ap.add_argument("--model-dir", default=None, help="narvis.json and its files from here")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.lower().split("x"))
    d = datasets.hurricane(a.points)
    cloud = PointCloud(d["positions"], colors=d["colors"], attributes=d["attributes"], velocity=d["velocity"])
    scene = PointScene(cloud)
    settings = dict(scene.settings, mode="narvis")
    scene._flow_raster()  # the radius plane, if the shipped narvis reads it (as the viewer's frames do)
    orbit = Orbit(scene.lo, scene.hi, points=scene.fit_points)
    orbit.fit(w / h)
    net = (
        scene._net("narvis")
        if a.model_dir is None
        else infer.load("narvis", directory=a.model_dir, queue=scene.raster.queue)
    )
    q = net.queue
    rows = []
    for r in range(a.rounds + 2):  # two warm-up rounds: kernels built, buffers made
        orbit.orbit(3 * h / 180, 0, h)
        camera = orbit.camera(w / h)
        t = [_clock()]
        g = scene._render(camera, w, h, settings, 1, screen_velocity=True, host=False)
        scene.raster.queue.finish()
        t.append(_clock())
        hh, ww = net._size(g)
        planes, output = net._buffers_for(*padded_shape(hh, ww, net.stride))
        net.spec.pack(g, net.planes, net.stride, planes, q)
        t.append(_clock())
        graph = net._graph_outputs(*planes.shape[2:])
        mapped_in, map_in = infer._map(q, planes, cl.map_flags.READ)
        io = net.session.io_binding()
        io.bind_input(net._in, "cpu", 0, np.float32, list(planes.shape), mapped_in.ctypes.data)
        maps = []
        for name, tensor in zip(net._outs, graph, strict=True):
            mapped_out, map_out = infer._map(q, tensor, cl.map_flags.WRITE_INVALIDATE_REGION)
            maps.append(map_out)
            io.bind_output(name, "cpu", 0, np.float32, list(tensor.shape), mapped_out.ctypes.data)
        net.session.run_with_iobinding(io)
        for m in maps:
            m.release()
        map_in.release()
        t.append(_clock())
        if net.head is not None:
            net.head(planes, *graph, out=output, queue=q)
            q.finish()
        t.append(_clock())
        rgba = unpack_rgba8(output, hh, ww, queue=q)
        picture = rgba.get() if isinstance(rgba, cla.Array) else rgba
        t.append(_clock())
        image = _premultiplied_over_background(picture)
        t.append(_clock())
        encode_jpeg(image, _QUALITY[True])
        t.append(_clock())
        if r >= 2:
            rows.append([[1e3 * (t[k + 1][j] - t[k][j]) for j in (0, 1)] for k in range(len(STAGES))])
    med = np.median(np.array(rows), axis=0)  # (stage, wall/cpu)
    frames = np.array(rows).sum(axis=1)  # (round, wall/cpu)
    print(f"NARVis frame, {a.points:,} points, {w}x{h}, median of {a.rounds} rounds; load {os.getloadavg()}")
    print(f"  {'stage':20s} {'wall ms':>9s} {'CPU ms':>9s} {'CPU %':>6s}")
    for name, (wall, cpu) in zip(STAGES, med, strict=True):
        print(f"  {name:20s} {wall:9.1f} {cpu:9.1f} {100 * cpu / med[:, 1].sum():6.1f}")
    fw, fc = np.median(frames, axis=0)
    print(f"  {'frame':20s} {fw:9.1f} {fc:9.1f}   ({1e3 / fw:.2f} fps on the median wall)")
    if a.ops:
        _ops(str(net.path), planes.get(), 5)


if __name__ == "__main__":
    main()
