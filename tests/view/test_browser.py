"""The viewer as a person uses it, in a real browser: Chromium headless,
driven over the DevTools protocol. Load the page, wait for the first frame,
drag to orbit (real mouse events), check that the picture and the camera
followed, switch modes; the same for a volume (progressive iso, then the
in-fill network). The page is 640 x 360 (every frame, the networks' ones
included, costs a quarter of a 1280 x 720 one: the same paths in a quarter of
the time); CLVIS_VIEW_SCREENSHOT=PATH keeps the screenshot of the point view
there, taken at 1280 x 720 (docs/view.png is one).

Skips, with the reason, only where no Chromium is installed and
CLVIS_REQUIRE_BROWSER is unset; CI installs it and sets that, so there a
missing browser fails.
"""

from __future__ import annotations

import asyncio
import base64
import hashlib
import io
import json
import os
import shutil
import subprocess
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("tornado", reason="the view extra (tornado) is not installed")

import tornado.websocket  # noqa: E402

import clvis  # noqa: E402
from clvis import PointCloud, datasets  # noqa: E402
from clvis.view import Frame, PointScene, Scene, ViewServer, VolumeScene  # noqa: E402

# 16:9 either way; drags are given on a 1280 x 720 page and scaled (_px), so
# they turn the view by the same angles (an orbit's degrees per pixel follow
# the view's height)
WIDTH, HEIGHT = (1280, 720) if os.environ.get("CLVIS_VIEW_SCREENSHOT") else (640, 360)
TIMEOUT = 180.0  # the first frame builds the kernels (PoCL, two busy cores)


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        path = shutil.which(name)
        if path:
            return path
    reason = "Chromium is not installed (apt-get install chromium); the browser test needs it"
    if os.environ.get("CLVIS_REQUIRE_BROWSER", "") not in ("", "0"):
        pytest.fail(reason + " and CLVIS_REQUIRE_BROWSER is set")
    pytest.skip(reason)


class Browser:
    """One headless Chromium and a DevTools session on its page."""

    def __init__(self, path: str, profile: Path):
        args = [
            path,
            "--headless=new",
            "--no-sandbox",  # CI runs as root, where Chromium's sandbox refuses to start
            "--disable-gpu",
            "--no-first-run",
            "--disable-extensions",
            "--remote-debugging-port=0",
            f"--user-data-dir={profile}",
            f"--window-size={WIDTH},{HEIGHT}",
            "about:blank",
        ]
        self.proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        port_file = profile / "DevToolsActivePort"
        deadline = time.monotonic() + 60
        while not port_file.exists() or not port_file.read_text().strip():
            if self.proc.poll() is not None:
                raise RuntimeError(f"chromium exited: {self.proc.stderr.read().decode()[-2000:]}")
            if time.monotonic() > deadline:
                raise RuntimeError("chromium did not open its DevTools port in 60 s")
            time.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
            pages = [t for t in json.load(r) if t["type"] == "page"]
        self.ws_url = pages[0]["webSocketDebuggerUrl"]
        self.loop = asyncio.new_event_loop()

        async def connect():
            return await tornado.websocket.websocket_connect(self.ws_url, max_message_size=1 << 28)

        self.ws = self.loop.run_until_complete(connect())
        self.id = 0
        # the page's size, whatever the headless window's decorations take
        self.call(
            "Emulation.setDeviceMetricsOverride",
            width=WIDTH,
            height=HEIGHT,
            deviceScaleFactor=1,
            mobile=False,
        )

    def call(self, method: str, **params):
        return self.loop.run_until_complete(self._call(method, params))

    async def _call(self, method, params):
        self.id += 1
        my = self.id
        await self.ws.write_message(json.dumps({"id": my, "method": method, "params": params}))
        while True:
            msg = await asyncio.wait_for(self.ws.read_message(), 60)
            if msg is None:
                raise RuntimeError("the DevTools connection closed")
            m = json.loads(msg)
            if m.get("id") == my:
                if "error" in m:
                    raise RuntimeError(f"{method}: {m['error']}")
                return m.get("result", {})

    def js(self, expression: str):
        r = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in r:
            raise RuntimeError(f"{expression}: {r['exceptionDetails']}")
        return r["result"].get("value")

    def wait_for(self, expression: str, what: str, timeout: float = TIMEOUT):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            v = self.js(expression)
            if v:
                return v
            time.sleep(0.1)
        status = self.js("document.getElementById('status').textContent")
        raise AssertionError(f"timed out waiting for {what}; the status line says: {status!r}")

    def mouse(self, kind: str, x: float, y: float, buttons: int = 1):
        self.call(
            "Input.dispatchMouseEvent",
            type=kind,
            x=x,
            y=y,
            button="left",
            buttons=buttons,
            clickCount=1 if kind != "mouseMoved" else 0,
        )

    def drag(self, x0, y0, x1, y1, steps=12):
        self.mouse("mousePressed", x0, y0)
        for i in range(1, steps + 1):
            self.mouse("mouseMoved", x0 + (x1 - x0) * i / steps, y0 + (y1 - y0) * i / steps)
        self.mouse("mouseReleased", x1, y1, buttons=0)

    def key(self, key: str, code: str, vk: int):
        """One key press, to whatever has the focus (as a person typing)."""
        for kind in ("keyDown", "keyUp"):
            self.call("Input.dispatchKeyEvent", type=kind, key=key, code=code, windowsVirtualKeyCode=vk)

    def choose(self, select: str, value: str):
        """Pick `value` in the page's <select id=select>, as a person does."""
        self.js(
            f"(() => {{ const m = document.getElementById({json.dumps(select)});"
            f" m.value = {json.dumps(value)}; m.dispatchEvent(new Event('change')); }})()"
        )

    def canvas_hash(self) -> str:
        url = self.js("document.getElementById('view').toDataURL('image/png')")
        return hashlib.sha256(url.encode()).hexdigest()

    def screenshot(self) -> bytes:
        return base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])

    def close(self):
        try:
            self.ws.close()
            self.loop.close()
        finally:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    b = Browser(_chromium(), tmp_path_factory.mktemp("chromium-profile"))
    yield b
    b.close()


def _px(x: float, y: float) -> tuple[float, float]:
    """A point given on a 1280 x 720 page, on this one."""
    return x * WIDTH / 1280, y * HEIGHT / 720


def _settled(b: Browser, mode: str) -> dict:
    """The header of the first full-size frame of `mode` that shows every event sent."""
    expr = (
        "(() => { const s = window.clvisView, h = s && s.header;"
        f" return h && !h.interactive && h.final && h.mode === {json.dumps(mode)}"
        " && (!s.seq || h.seq >= s.seq) ? h : null; })()"  # no event sent yet: the first frame
    )
    return b.wait_for(expr, f"a still frame of {mode}")


def _image_spread(png: bytes) -> float:
    from PIL import Image

    a = np.asarray(Image.open(io.BytesIO(png)).convert("L"), np.float32)
    return float(a.std())


def test_points_orbit_and_modes(browser, tmp_path):
    d = datasets.hurricane(200_000)
    cloud = PointCloud(d["positions"], colors=d["colors"], attributes=d["attributes"], velocity=d["velocity"])
    server = ViewServer(PointScene(cloud, description="the embedded hurricane"))
    try:
        b = browser
        b.call("Page.navigate", url=server.url)
        first = _settled(b, "points")
        assert (first["width"], first["height"]) == (WIDTH, HEIGHT)
        # the page's size came with its socket: no frame of the server's 1280x720 first
        assert server.frames == 1 and first["id"] == 1, first
        assert set(first["ms"]) >= {"render", "encode", "send"}
        cam0, img0 = first["camera"], b.canvas_hash()

        # keys work before any click on the view (a right arrow turns it), then f frames it again
        b.key("ArrowRight", "ArrowRight", 39)
        turned = _settled(b, "points")["camera"]
        assert abs(turned["azimuth"] - cam0["azimuth"]) > 5, (cam0, turned)
        b.key("f", "KeyF", 70)
        b.wait_for(
            f"Math.abs(window.clvisView.camera.azimuth - ({cam0['azimuth']})) < 1e-6 || null",
            "the fit view again",
        )
        _settled(b, "points")

        # drag to orbit: interaction frames at half size, then a full one
        b.js(
            "window.clvisView.sawInteractive = false; window.clvisView._w = setInterval(() => {"
            " const h = window.clvisView.header; if (h && h.interactive) window.clvisView.sawInteractive ="
            " [h.width, h.height]; }, 5)"
        )
        b.drag(*_px(640, 400), *_px(900, 330))
        after = _settled(b, "points")
        cam1, img1 = after["camera"], b.canvas_hash()
        assert img1 != img0, "the picture did not change after the drag"
        assert abs(cam1["azimuth"] - cam0["azimuth"]) > 30, (cam0, cam1)
        assert cam1["elevation"] < cam0["elevation"]  # dragged up: the view tilts down
        assert not np.allclose(cam1["eye"], cam0["eye"])
        assert np.allclose(cam1["target"], cam0["target"])  # an orbit, not a pan
        assert b.js("window.clvisView.sawInteractive") == [WIDTH // 2, HEIGHT // 2]
        latency = b.js("window.clvisView.latencyMs")
        assert latency is not None and latency > 0
        print(f"\nview: mouse release -> full frame shown {latency:.0f} ms; that frame's ms {after['ms']}")

        # a typed camera, as the other commands' options
        b.js("document.getElementById('copy').click()")
        b.js(
            "(() => { const t = document.getElementById('camera-text');"
            " t.value = '--eye 0,-250,120 --target 0,0,5 --up 0,0,1 --fov 40';"
            " document.getElementById('camera-apply').click(); })()"
        )
        typed = _settled(b, "points")["camera"]
        assert np.allclose(typed["eye"], (0, -250, 120)) and np.allclose(typed["target"], (0, 0, 5))
        assert typed["fov"] == 40 and typed["cli"].startswith("--eye 0,-250,120 --target 0,0,5")
        b.js("document.getElementById('copy').click()")  # hide it again
        # one of the NARVis samplers' views
        b.js(
            "(() => { const h = document.getElementById('hemisphere'); h.value = '40';"
            " h.dispatchEvent(new Event('change')); })()"
        )
        preset = _settled(b, "points")["camera"]
        want = list(clvis.hemisphere_cameras(cloud.positions.min(0), cloud.positions.max(0)))[40].eye
        assert np.allclose(preset["eye"], want, rtol=1e-4, atol=1e-3)
        img1 = b.canvas_hash()

        # colour by another attribute, then the LiDAR network
        b.choose("set-color_by", "pressure")
        b.wait_for("window.clvisView.settings.color_by === 'pressure'", "the colour setting")
        _settled(b, "points")
        assert b.canvas_hash() != img1

        png = b.screenshot()
        assert _image_spread(png) > 10
        keep = os.environ.get("CLVIS_VIEW_SCREENSHOT")
        if keep:
            Path(keep).write_bytes(png)
        (tmp_path / "points.png").write_bytes(png)

        for mode in ("narvis", "lidar", "narvis|gaussians"):
            b.choose("mode", mode)
            h = _settled(b, mode)
            assert h["ms"]["post"] > 0, h
        assert h["info"]["psnr dB"] > 5  # the split view: MACR + NARVis beside the Gaussian renderer
        assert b.js("window.clvisView.error") is None
    finally:
        server.close()


def test_volume_progressive_iso_and_infill(browser):
    d = datasets.marschner_lobb(48)
    server = ViewServer(
        VolumeScene(d["volume"], d["spacing"], d["origin"], 0.5, description="marschner-lobb")
    )
    try:
        b = browser
        b.js("window.clvisView = undefined")
        b.call("Page.navigate", url=server.url)
        # record every header: the passes of one view arrive one by one
        b.wait_for("window.clvisView && window.clvisView.config", "the page to connect")
        b.js(
            "window.clvisView.log = []; window.clvisView._w = setInterval(() => {"
            " const h = window.clvisView.header; const l = window.clvisView.log;"
            " if (h && (!l.length || l[l.length - 1].id !== h.id)) l.push(h); }, 2)"
        )
        first = _settled(b, "iso")
        assert first["info"]["completion"] == 1.0
        # the last pass says the view is done
        assert b.js("document.getElementById('status').textContent").startswith(
            f"iso {WIDTH}x{HEIGHT} done |"
        )
        img0 = b.canvas_hash()
        b.drag(*_px(640, 360), *_px(500, 360))
        after = _settled(b, "iso")
        assert b.canvas_hash() != img0
        assert after["camera"]["azimuth"] != first["camera"]["azimuth"]
        passes = [h["info"]["pass"] for h in b.js("window.clvisView.log") if h["id"] > first["id"]]
        assert max(passes) > 1, f"only one pass was shown: {passes}"

        b.choose("mode", "iso+infill")
        h = _settled(b, "iso+infill")
        assert h["info"]["completion"] == 1.0
        b.choose("mode", "infill|iso")
        h = _settled(b, "infill|iso")
        assert h["info"]["psnr dB"] > 15 and h["info"]["fast completion"] >= 0.85
        assert h["info"]["slow completion"] == 1  # the right half: the complete render
        assert b.js("document.getElementById('status').textContent").startswith(
            f"infill|iso {WIDTH}x{HEIGHT} done |"
        )
        assert b.js("window.clvisView.error") is None
    finally:
        server.close()


def test_an_openvdb_grid_in_mode_iso_and_its_refusal(browser, monkeypatch):
    """A .vdb grid's page lists mode iso beside gaussians with an isovalue
    field (0: the level set's surface); choosing it draws the isosurface
    progressively to a done frame. Where the dense volume would not fit in
    host memory the status line says so, and gaussians still draws."""
    from clvis.view import SparseScene

    path = Path(__file__).resolve().parents[1] / "data" / "openvdb_small.vdb"
    server = ViewServer(SparseScene(clvis.read_vdb(path), description="openvdb_small.vdb"))
    try:
        b = browser
        b.js("window.clvisView = undefined")
        b.call("Page.navigate", url=server.url)
        first = _settled(b, "gaussians")
        modes = b.js("[...document.getElementById('mode').options].map((o) => o.value)")
        assert modes == ["gaussians", "iso", "iso+infill", "infill|iso"]
        assert b.js("document.getElementById('set-isovalue').value") == "0"
        b.choose("mode", "iso")
        h = _settled(b, "iso")
        assert h["info"]["completion"] == 1.0 and h["id"] > first["id"]
        assert b.js("document.getElementById('status').textContent").startswith(
            f"iso {WIDTH}x{HEIGHT} done |"
        )
        assert b.js("window.clvisView.error") is None
    finally:
        server.close()

    from clvis import runtime

    server = ViewServer(SparseScene(clvis.read_vdb(path), description="big.vdb"))
    monkeypatch.setattr(runtime, "host_available_bytes", lambda: 100_000)
    try:
        b.js("window.clvisView = undefined")
        b.call("Page.navigate", url=server.url)
        _settled(b, "gaussians")
        b.choose("mode", "iso")
        error = b.wait_for("window.clvisView.error", "the refusal in the status line")
        assert error.startswith("DeviceError: big.vdb: the grid made dense is 38x39x40 voxels")
        assert b.js("document.getElementById('status').className") == "error"
        assert "mode gaussians" in b.js("document.getElementById('status').textContent")
        b.choose("mode", "gaussians")
        _settled(b, "gaussians")
        assert b.js("window.clvisView.error") is None
    finally:
        server.close()


class _Flat(Scene):
    """A scene of one grey level a view, a new level each view: no device, no
    kernels, just frames whose picture says which view they show."""

    kind = "points"
    modes = ["points"]
    settings = {"mode": "points"}
    choices = {"mode": ["points"]}
    lo, hi = np.zeros(3), np.ones(3)
    description = "flat"
    device = "none"

    def __init__(self):
        self.views = 0

    def frames(self, camera, width, height, settings, superseded):
        self.views += 1
        yield Frame(np.full((height, width, 3), 40 * self.views % 256, np.uint8))


# createImageBitmap wrapped, before the page's own script runs: while
# window.__hold is set, each decoded frame waits in window.__held until the
# test lets it go (the order a loaded browser may finish its decodes in)
_HOLD_DECODES = """(() => {
  const make = window.createImageBitmap.bind(window);
  window.__hold = false; window.__held = [];
  window.createImageBitmap = (...args) => {
    const p = make(...args);
    if (!window.__hold) return p;
    return new Promise((resolve, reject) => window.__held.push(() => p.then(resolve, reject)));
  };
})();"""


def test_a_frame_decoded_late_does_not_replace_a_newer_one(browser):
    """The page decodes each frame asynchronously (createImageBitmap of a Blob
    resolves in parallel, in no set order: on a loaded machine a frame can
    finish after the next one). The newest frame must stay on the screen, or
    the page shows a stale picture and waits for a frame that already came
    (the CI rehearsal's timeout in test_points_orbit_and_modes)."""
    b = browser
    scene = _Flat()
    server = ViewServer(scene, size=(WIDTH, HEIGHT))
    b.call("Page.enable")  # for the script below
    script = b.call("Page.addScriptToEvaluateOnNewDocument", source=_HOLD_DECODES)["identifier"]
    try:
        b.js("window.clvisView = undefined")
        b.call("Page.navigate", url=server.url)
        first = _settled(b, "points")
        b.js("window.__hold = true; window.clvisView.send({ type: 'fit' })")
        b.wait_for("window.__held.length === 1", "the first frame to arrive")
        b.js("window.clvisView.send({ type: 'fit' })")
        b.wait_for("window.__held.length === 2", "the second frame to arrive")
        level = 40 * scene.views % 256  # the newest view's grey
        # the newer frame's decode finishes first, the older one's after it
        b.js(
            "(async () => { const h = window.__held; await h[1](); await h[0]();"
            " await new Promise((r) => setTimeout(r, 100)); return true; })()"
        )
        h = b.js("window.clvisView.header")
        assert h["id"] == first["id"] + 2 and h["seq"] == b.js("window.clvisView.seq"), (first, h)
        pixel = b.js(
            "Array.from(document.getElementById('view').getContext('2d')"
            f".getImageData({WIDTH // 2}, {HEIGHT // 2}, 1, 1).data)"
        )
        assert all(abs(c - level) <= 3 for c in pixel[:3]), (pixel, level)
        assert b.js("window.clvisView.late") == 1  # the older frame, not drawn
        assert b.js("window.clvisView.error") is None
    finally:
        b.call("Page.removeScriptToEvaluateOnNewDocument", identifier=script)
        server.close()


class _Square(_Flat):
    """A square frame whatever the page's shape, with a PSNR of inf (a split
    view's identical halves): the page must read the header and draw the
    frame at its own aspect."""

    def frames(self, camera, width, height, settings, superseded):
        yield Frame(np.full((100, 100, 3), 200, np.uint8), info={"psnr dB": float("inf")})


def test_the_page_shows_an_infinite_psnr_and_draws_a_frame_at_its_aspect(browser):
    b = browser
    server = ViewServer(_Square(), size=(WIDTH, HEIGHT))
    try:
        b.js("window.clvisView = undefined")
        b.call("Page.navigate", url=server.url)
        _settled(b, "points")
        assert b.js("window.clvisView.error") is None
        assert "psnr dB inf" in b.js("document.getElementById('status').textContent")

        def pixel(x, y):
            ctx = "document.getElementById('view').getContext('2d')"
            return b.js(f"Array.from({ctx}.getImageData({x}, {y}, 1, 1).data)")

        # the square in the middle of the wide canvas, the page's background beside it
        assert all(abs(c - 200) <= 3 for c in pixel(WIDTH // 2, HEIGHT // 2)[:3])
        assert pixel(4, HEIGHT // 2)[:3] == [0x18, 0x18, 0x1C]
    finally:
        server.close()


def test_a_cleared_number_field_sends_nothing(browser):
    """Clearing the isovalue field (a user about to type another) is not
    isovalue 0: nothing is sent and the field shows the setting again."""
    d = datasets.marschner_lobb(24)
    server = ViewServer(VolumeScene(d["volume"], d["spacing"], d["origin"], 0.5, description="ml"))
    try:
        b = browser
        b.js("window.clvisView = undefined")
        b.call("Page.navigate", url=server.url)
        b.wait_for("window.clvisView && window.clvisView.config", "the page to connect")
        _settled(b, "iso")
        before = b.js("window.clvisView.seq")
        b.js(
            "(() => { const f = document.getElementById('set-isovalue'); f.value = '';"
            " f.dispatchEvent(new Event('change')); })()"
        )
        time.sleep(0.5)
        assert b.js("window.clvisView.seq") == before
        assert b.js("document.getElementById('set-isovalue').value") == "0.5"
        assert b.js("window.clvisView.settings.isovalue") == 0.5
    finally:
        server.close()


class _Busy(_Flat):
    """A point scene's controls (four settings of long values) and a long
    description without a space, no device: what the bar must fit."""

    modes = ["points", "lidar", "narvis-scan", "gaussians", "narvis-scan|gaussians"]
    description = (
        "/data/scans/a/very/long/path/without/any/space/scan_2024_north_tile_0042.laz: 12,345,678 points"
    )

    def __init__(self):
        super().__init__()
        self.settings = {
            "mode": "points",
            "color_by": "classification",
            "colormap": "viridis",
            "point_size": 1,
        }
        self.choices = {
            "mode": self.modes,
            "color_by": ["classification", "intensity", "return_number", "gps_time"],
            "colormap": ["viridis", "magma", "coolwarm"],
            "point_size": {"min": 1, "max": 16},
        }


@pytest.mark.parametrize("size", [(640, 400), (320, 240)])
def test_every_control_is_reachable_in_a_small_window(browser, size):
    """A small window: the bar wraps (and scrolls past half the height), the
    camera box and the status line wrap inside the window; each control can
    be scrolled to and is the element under its own centre (the camera box's
    field ran 70 px past a 640 px window, and a short window hid the bar's
    last rows). A screenshot of the page at that size comes back whole."""
    from PIL import Image

    b = browser
    w, h = size
    server = ViewServer(_Busy(), size=size)
    try:
        b.call("Emulation.setDeviceMetricsOverride", width=w, height=h, deviceScaleFactor=1, mobile=False)
        b.js("window.clvisView = undefined")
        b.call("Page.navigate", url=server.url)
        _settled(b, "points")
        b.js("document.getElementById('copy').click()")  # the camera box too
        b.wait_for("document.getElementById('camera-text').value.includes('--eye')", "the camera text")
        check = """(() => {
          const out = [], sel = '#bar select, #bar input, #bar button, #camera input, #camera button';
          for (const el of document.querySelectorAll(sel)) {
            el.scrollIntoView({block: 'nearest', inline: 'nearest'});
            const r = el.getBoundingClientRect(), cx = (r.left + r.right) / 2, cy = (r.top + r.bottom) / 2;
            const inside = r.width > 0 && r.left >= 0 && r.top >= 0
                           && r.right <= innerWidth && r.bottom <= innerHeight;
            const top = document.elementFromPoint(cx, cy);
            if (!inside || !(top === el || el.contains(top)))
              out.push([el.id || el.textContent, Math.round(r.left), Math.round(r.top), Math.round(r.right),
                        Math.round(r.bottom), top ? top.id || top.tagName : null]);
          }
          const s = document.getElementById('status'), sr = s.getBoundingClientRect();
          if (s.scrollWidth > s.clientWidth + 1 || sr.bottom > innerHeight + 0.5)
            out.push(['status', s.scrollWidth, s.clientWidth]);
          return out;
        })()"""
        assert b.js(check) == []
        assert b.js("document.getElementById('status').textContent").startswith(f"points {w}x{h} done |")
        shot = Image.open(io.BytesIO(b.screenshot()))
        assert shot.size == size
    finally:
        b.call(
            "Emulation.setDeviceMetricsOverride",
            width=WIDTH,
            height=HEIGHT,
            deviceScaleFactor=1,
            mobile=False,
        )
        server.close()


def test_a_page_beyond_the_most_the_server_shows_says_why(browser):
    server = ViewServer(_Flat(), size=(WIDTH, HEIGHT), max_pages=1)
    b = browser

    async def connect():  # another page holds the one place
        return await tornado.websocket.websocket_connect(f"ws://127.0.0.1:{server.port}/ws")

    try:
        other = b.loop.run_until_complete(connect())
        b.js("window.clvisView = undefined")
        b.call("Page.navigate", url=server.url)
        text = b.wait_for(
            "(() => { const e = document.getElementById('status'), t = e && e.textContent;"
            " return t && t.startsWith('disconnected') ? t : null; })()",
            "the page to be refused",
        )
        assert text == "disconnected: at most 1 pages at once: close one and reload"
        other.close()
    finally:
        server.close()
