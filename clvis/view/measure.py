"""The viewer's frame budget, measured without a browser: what the server
does for each frame (render, post, JPEG encode), camera moving as a drag
moves it. ``clvis view --measure`` prints it."""

from __future__ import annotations

import statistics
import time

from .orbit import Orbit
from .scenes import Scene
from .server import _QUALITY, encode_jpeg

__all__ = ["measure"]


def _frame(scene: Scene, camera, w, h, settings, quality):
    """(seconds to the first frame, to the last, CPU seconds, frames, the
    first frame's seconds per stage)."""
    t0, c0 = time.perf_counter(), time.process_time()
    first = None
    n = 0
    stages: dict = {}
    for f in scene.frames(camera, w, h, settings, lambda: False):
        t = time.perf_counter()
        encode_jpeg(f.image, quality)
        n += 1
        if first is None:
            first = time.perf_counter() - t0
            stages = dict(f.times, encode=time.perf_counter() - t)
    return first, time.perf_counter() - t0, time.process_time() - c0, n, stages


def measure(
    scene: Scene, width: int, height: int, mode: str, frames: int = 10, interactive: bool = True
) -> dict:
    """Median figures over `frames` views, each 3 degrees of orbit from the
    last (after one unmeasured frame that builds what the mode needs).
    interactive: frames at half size and interaction JPEG quality, as while
    dragging; else full size (a still frame; for a progressive mode, the
    first pass after a camera stop, and the last)."""
    settings = dict(scene.settings, mode=mode)
    if interactive:
        width, height = max(16, width // 2), max(16, height // 2)
    orbit = Orbit(scene.lo, scene.hi, points=scene.fit_points)
    orbit.fit(width / height)
    quality = _QUALITY[interactive]
    _frame(scene, orbit.camera(width / height), width, height, settings, quality)
    rows = []
    for _ in range(frames):
        orbit.orbit(3 * height / 180, 0, height)
        rows.append(_frame(scene, orbit.camera(width / height), width, height, settings, quality))
    med = statistics.median
    first = med(r[0] for r in rows)
    stages = {k: med(r[4].get(k, 0.0) for r in rows) for k in rows[0][4]}
    return {
        "mode": mode,
        "size": f"{width}x{height}",
        "first_ms": 1e3 * first,
        "last_ms": 1e3 * med(r[1] for r in rows),
        "cpu_ms": 1e3 * med(r[2] for r in rows),
        "frames": med(r[3] for r in rows),
        "fps": 1.0 / first if first > 0 else float("inf"),
        "stages_ms": {k: 1e3 * v for k, v in stages.items()},
    }
