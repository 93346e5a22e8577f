"""The viewer's frame budget (clvis view, issue 28): what the server does
for one frame (render, post, JPEG encode; the send is the browser's),
without a browser, the camera 3 degrees of orbit further each round as a
drag moves it. A page of 1280x720; interaction frames at half size, JPEG
quality 75 (clvis.view.server).

- view_points: the embedded hurricane (2,000,000 points), mode points, an
  interaction frame (640x360);
- view_narvis: the same cloud, mode narvis (MACR G-buffers + the NARVis
  network on onnxruntime), a frame at 512x512 ("inference_ms": the last
  timed frame's inference); beside it the network's inference alone
  (onnxruntime's run on the packed input);
- view_iso: the embedded marschner-lobb (64^3), mode iso, a still view as
  after a camera stop: the time to its first frame (the first pass at the
  interaction size, clvis.view.scenes.view_frames), and beside it the first
  pass at the full size (what the first frame was before).

Each row records its median in ms and frames per second from it (info
"median_ms", "fps"), the iso view its first full-size pass
("first_full_ms"), and the load average when it ran ("load_average"); the
targets (issue 28's, on PoCL with 2 cores) are in clvis.benchreport.

    clvis bench view            (CLVIS_BENCH_SCALE shrinks the cloud and the page)
"""

import os
import time

import numpy as np
import pytest
from benchutil import run, scaled

pytest.importorskip("tornado", reason="the view extra (tornado) is not installed")

from clvis import PointCloud, datasets  # noqa: E402
from clvis.view import Orbit, PointScene, VolumeScene  # noqa: E402
from clvis.view.scenes import view_frames  # noqa: E402
from clvis.view.server import _QUALITY, encode_jpeg  # noqa: E402

SCALE = float(os.environ.get("CLVIS_BENCH_SCALE", "1"))
POINTS = scaled(2_000_000)
PAGE = (1280, 720) if SCALE >= 0.05 else (256, 144)
HALF = (PAGE[0] // 2, PAGE[1] // 2)
NARVIS = (512, 512) if SCALE >= 0.05 else (128, 128)
POINTS_OP = f"view_points[hurricane {POINTS:,} points, {HALF[0]}x{HALF[1]} interaction]"
NARVIS_OP = f"view_narvis[hurricane {POINTS:,} points, {NARVIS[0]}x{NARVIS[1]}]"
ISO_OP = f"view_iso[marschner-lobb 64^3, {PAGE[0]}x{PAGE[1]} still: first frame after a stop]"
_cache: dict = {}


def _points():
    if "points" not in _cache:
        d = datasets.hurricane(POINTS)
        cloud = PointCloud(
            d["positions"], colors=d["colors"], attributes=d["attributes"], velocity=d["velocity"]
        )
        _cache["points"] = PointScene(cloud, description="the embedded hurricane")
    return _cache["points"]


def _volume():
    if "volume" not in _cache:
        d = datasets.marschner_lobb(64)
        _cache["volume"] = VolumeScene(d["volume"], d["spacing"], d["origin"], 0.5, 8)
    return _cache["volume"]


class _Drag:
    """The camera of a drag: 3 degrees of orbit further at each call."""

    def __init__(self, scene, w, h):
        self.orbit, self.w, self.h = Orbit(scene.lo, scene.hi, points=scene.fit_points), w, h
        self.orbit.fit(w / h)

    def __call__(self, w=None, h=None):
        self.orbit.orbit(3 * self.h / 180, 0, self.h)
        w, h = w or self.w, h or self.h
        return self.orbit.camera(w / h)


def _record(benchmark, **info):
    stats = getattr(benchmark, "stats", None)
    if stats is not None:  # not under --benchmark-disable
        benchmark.extra_info["median_ms"] = 1e3 * stats.stats.median
        benchmark.extra_info["fps"] = 1.0 / stats.stats.median
    benchmark.extra_info["load_average"] = list(os.getloadavg())
    benchmark.extra_info.update(info)


def _frame(scene, camera, w, h, settings, interactive=True):
    for f in scene.frames(camera, w, h, settings, lambda: False):
        encode_jpeg(f.image, _QUALITY[interactive])
    return f


def test_points_interaction_frame(benchmark, queue):
    scene = _points()
    settings = dict(scene.settings, mode="points")
    drag = _Drag(scene, *HALF)
    w, h = HALF
    run(
        benchmark,
        lambda: _frame(scene, drag(), w, h, settings),
        op=POINTS_OP,
        impl="clvis",
        role="clvis",
        n=POINTS,
        nbytes=POINTS * 16,
    )
    _record(benchmark)


@pytest.mark.parametrize("impl", ["frame", "inference alone"])
def test_narvis_frame(benchmark, queue, impl):
    scene = _points()
    settings = dict(scene.settings, mode="narvis")
    w, h = NARVIS
    drag = _Drag(scene, w, h)
    _frame(scene, drag(), w, h, settings)  # loads the network (its first inference is slower)
    net = scene._net("narvis")
    if impl == "frame":
        last = {}

        def frame():
            last["frame"] = _frame(scene, drag(), w, h, settings)

        run(
            benchmark,
            frame,
            op=NARVIS_OP,
            impl="clvis",
            role="clvis",
            n=w * h,
            nbytes=w * h * (net.channels_in + net.channels_out) * 4,
        )
        _record(benchmark, inference_ms=last["frame"].info["inference ms"])  # a timed frame's
        return
    planes, _ = next(iter(net._buffers.values()))
    x = planes.get()  # the packed input of the last frame
    name = net.session.get_inputs()[0].name
    run(
        benchmark,
        lambda: net.session.run(None, {name: x}),
        op=NARVIS_OP,
        impl="onnxruntime inference alone",
        role="clvis-host",
        n=w * h,
        nbytes=x.nbytes,
    )
    _record(benchmark)


@pytest.mark.parametrize("impl", ["preview", "full size"])
def test_iso_first_frame_after_a_stop(benchmark, queue, impl):
    scene = _volume()
    settings = dict(scene.settings, mode="iso")
    w, h = PAGE
    drag = _Drag(scene, w, h)

    def first_frames(count):
        """Seconds to each of the view's first `count` frames (each encoded)."""
        t0 = time.perf_counter()
        preview = (drag(*HALF), *HALF) if impl == "preview" else None
        frames = view_frames(scene, drag.orbit.camera(w / h), w, h, settings, lambda: False, preview)
        times = []
        for f in frames:
            encode_jpeg(f.image, _QUALITY["preview" in f.info])
            times.append(time.perf_counter() - t0)
            if len(times) == count:
                break
        frames.close()
        assert ("preview" in f.info) == (impl == "preview" and count == 1)
        return times

    first_frames(1)
    if impl == "preview":
        full = [first_frames(2)[1] for _ in range(3)]  # the first full-size pass (untimed here)
        run(
            benchmark,
            lambda: first_frames(1),
            op=ISO_OP,
            impl="clvis",
            role="clvis",
            n=w * h,
            nbytes=w * h * 26,
        )
        _record(benchmark, first_full_ms=1e3 * float(np.median(full)))
    else:
        run(
            benchmark,
            lambda: first_frames(1),
            op=ISO_OP,
            impl="the first pass at full size",
            role="clvis-host",
            n=w * h,
            nbytes=w * h * 26,
        )
        _record(benchmark)
