"""The viewer's frame budget, measured without a browser: what the server
does for each frame (render, post, JPEG encode), camera moving as a drag
moves it. ``clvis view --measure`` prints it; bench/bench_view.py records it."""

from __future__ import annotations

import statistics
import time

from .orbit import Orbit
from .scenes import Scene, view_frames
from .server import _QUALITY, encode_jpeg

__all__ = ["measure"]


def _view(scene: Scene, camera, w, h, settings, interactive, preview):
    """One view's frames, each encoded as the server encodes it: (seconds to
    the first frame, to the first full-size frame, to the last, CPU seconds,
    frames, the first frame's seconds per stage, the first full-size frame's
    info)."""
    t0, c0 = time.perf_counter(), time.process_time()
    first = first_full = None
    n = 0
    stages: dict = {}
    info: dict = {}
    for f in view_frames(scene, camera, w, h, settings, lambda: False, preview):
        t = time.perf_counter()
        encode_jpeg(f.image, _QUALITY[interactive or "preview" in f.info])
        n += 1
        now = time.perf_counter()
        if first is None:
            first = now - t0
            stages = dict(f.times, encode=now - t)
        if first_full is None and "preview" not in f.info:
            first_full = now - t0
            info = dict(f.info)
    assert first is not None and first_full is not None  # a view has at least one frame
    return first, first_full, time.perf_counter() - t0, time.process_time() - c0, n, stages, info


def measure(
    scene: Scene,
    width: int,
    height: int,
    mode: str,
    frames: int = 10,
    interactive: bool = True,
    scale: float = 0.5,
) -> dict:
    """Median figures over `frames` views, each 3 degrees of orbit from the
    last (after one unmeasured view that builds what the mode needs).
    interactive: frames at `scale` of the size and interaction JPEG quality,
    as while dragging; else full size (a still view, as after a camera stop:
    a progressive mode's first frame is its first pass at `scale` of the
    size, ``first_full_ms`` the first at full size, ``last_ms`` the last).
    ``cpu_ms``: this process's CPU time for the whole view (every thread:
    the OpenCL runtime's and onnxruntime's too)."""
    settings = dict(scene.settings, mode=mode, interacting=interactive)  # as the server's frames
    pw, ph = max(16, round(width * scale)), max(16, round(height * scale))
    if interactive:
        width, height = pw, ph
    orbit = Orbit(scene.lo, scene.hi, azimuth=scene.home_azimuth, points=scene.fit_points)
    orbit.fit(width / height)

    def view():
        preview = None if interactive else (orbit.camera(pw / ph), pw, ph)
        return _view(scene, orbit.camera(width / height), width, height, settings, interactive, preview)

    view()
    rows = []
    for _ in range(frames):
        orbit.orbit(3 * height / 180, 0, height)
        rows.append(view())
    med = statistics.median
    first = med(r[0] for r in rows)
    stages = {k: med(r[5].get(k, 0.0) for r in rows) for k in rows[0][5]}
    info = {k: med(r[6][k] for r in rows) for k, v in rows[0][6].items() if isinstance(v, (int, float))}
    return {
        "mode": mode,
        "size": f"{width}x{height}",
        "first_ms": 1e3 * first,
        "first_full_ms": 1e3 * med(r[1] for r in rows),
        "last_ms": 1e3 * med(r[2] for r in rows),
        "cpu_ms": 1e3 * med(r[3] for r in rows),
        "frames": med(r[4] for r in rows),
        "fps": 1.0 / first if first > 0 else float("inf"),
        "stages_ms": {k: 1e3 * v for k, v in stages.items()},
        "info": info,
    }
