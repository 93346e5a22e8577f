"""The server as a page (or anyone who can reach its socket) talks to it, without
a browser or a device: malformed events, strict JSON, a camera that would not
be finite, a page that goes away in the middle of a drag, the frame size and
the log lines (one test draws on the device: a .vdb grid's iso mode refused
in the page)."""

from __future__ import annotations

import asyncio
import json
import logging
import math
import struct
import urllib.error
import urllib.request

import numpy as np
import pytest

pytest.importorskip("tornado", reason="the view extra (tornado) is not installed")

import tornado.websocket  # noqa: E402

from clvis.view import Frame, Orbit, Scene, ViewServer  # noqa: E402
from clvis.view.server import MAX_SIZE, pack_message, to_json  # noqa: E402

WAIT = 20.0  # seconds for a reply (two busy cores)


class _Grey(Scene):
    """One flat frame a view (no device); `info` goes into every header."""

    kind = "points"
    modes = ["points"]
    lo, hi = np.zeros(3), np.ones(3)
    description = "grey"
    device = "none"

    def __init__(self, info: dict | None = None):
        self.settings = {"mode": "points", "point_size": 1}
        self.choices = {"mode": ["points"], "point_size": {"min": 1, "max": 16}}
        self.info = info or {}

    def frames(self, camera, width, height, settings, superseded):
        yield Frame(np.full((height, width, 3), 90, np.uint8), info=dict(self.info))


def _strict(text: str | bytes):
    def refuse(name):
        raise AssertionError(f"{name} is not JSON (the page's JSON.parse refuses it)")

    return json.loads(text, parse_constant=refuse)


class Page:
    """A socket to the server, as the page opens it."""

    def __init__(self, ws):
        self.ws = ws

    @classmethod
    async def open(cls, server: ViewServer, token: str | None = None, query: str = "") -> Page:
        q = "&".join(([f"token={token}"] if token else []) + ([query] if query else []))
        url = f"ws://127.0.0.1:{server.port}/ws" + (f"?{q}" if q else "")
        return cls(await tornado.websocket.websocket_connect(url))

    async def send(self, msg) -> None:
        await self.ws.write_message(msg if isinstance(msg, str) else json.dumps(msg))

    async def next(self, want, what: str):
        """The first message for which want(kind, message) holds (kind "frame"
        with the header for a frame, else the text message's type)."""

        async def read():
            while True:
                m = await self.ws.read_message()
                if m is None:
                    raise AssertionError(f"the socket closed while waiting for {what}")
                if isinstance(m, bytes):
                    (n,) = struct.unpack(">I", m[:4])
                    msg = _strict(m[4 : 4 + n])
                else:
                    msg = _strict(m)
                if want(msg["type"], msg):
                    return msg

        return await asyncio.wait_for(read(), WAIT)

    async def error(self):
        return (await self.next(lambda k, m: k == "error", "an error reply"))["message"]

    async def frame(self, what="a frame", **fields):
        return await self.next(lambda k, m: k == "frame" and all(m[f] == v for f, v in fields.items()), what)


@pytest.fixture()
def server():
    s = ViewServer(_Grey(), size=(320, 180))
    yield s
    s.close()


HUGE = "9" * 400  # json.loads reads it as an int no float holds


@pytest.mark.parametrize(
    "message, says",
    [
        ('{"type":"set","settings":[1,2]}', "settings: expected an object"),
        ('{"type":"set","settings":"abc"}', "settings: expected an object"),
        ('{"type":"set","settings":{"point_size":Infinity}}', "Infinity is not a JSON number"),
        ('{"type":"set","settings":{"point_size":1e999}}', "point_size: expected a number, got inf"),
        ('{"type":"set","settings":{"point_size":NaN}}', "NaN is not a JSON number"),
        ('{"type":"set","settings":{"point_size":' + HUGE + "}}", "point_size: expected a number"),
        ('{"type":"set","settings":{"point_size":true}}', "point_size: expected a number"),
        ('{"type":"drag","dx":' + HUGE + ',"dy":0}', "dx: expected a finite number"),
        ('{"type":"drag","dx":1e300,"dy":1e300,"pan":true}', "dx: expected a finite number"),
        ('{"type":"drag","dx":"left","dy":0}', "dx: expected a number"),
        ('{"type":"size","width":' + HUGE + ',"height":100}', "width: expected a finite number"),
        ('{"type":"zoom","factor":' + HUGE + "}", "factor: expected a finite number"),
        ("[" * 100_000, "message: nested too deeply"),
        ("not json", "Expecting value"),
        ("[1]", "expected a JSON object"),
    ],
)
def test_a_malformed_event_is_an_error_reply_and_the_socket_stays_open(server, message, says):
    async def go():
        page = await Page.open(server)
        await page.frame("the first frame")
        await page.send(message)
        error = await page.error()
        await page.send({"type": "fit"})  # still open, still rendering
        await page.frame("a frame after the error")
        page.ws.close()
        return error

    error = asyncio.run(go())
    assert says in error and len(error) <= 300
    assert server.scene.settings == {"mode": "points", "point_size": 1}


def test_an_unexpected_exception_is_an_error_reply_and_one_log_line(monkeypatch, capsys):
    s = ViewServer(_Grey(), token="s3cret-t0ken")

    def broken(changes):
        raise KeyError("a bug")

    monkeypatch.setattr(s.scene, "update", broken)

    async def go():
        page = await Page.open(s, "s3cret-t0ken")
        await page.send({"type": "set", "settings": {"point_size": 2}})
        error = await page.error()
        await page.send({"type": "fit"})
        await page.frame("a frame after the error")
        page.ws.close()
        return error

    try:
        assert asyncio.run(go()) == "KeyError: 'a bug'"
    finally:
        s.close()
    err = capsys.readouterr().err
    assert "clvis view: event 'set': KeyError: 'a bug'" in err and "s3cret" not in err
    assert "Traceback" not in err


def test_every_message_is_strict_json_and_a_non_finite_figure_a_string():
    assert to_json({"psnr dB": math.inf, "x": [-math.inf, math.nan, 1.5]}) == (
        '{"psnr dB":"inf","x":["-inf","nan",1.5]}'
    )
    packed = pack_message({"info": {"psnr dB": math.inf}}, b"jpeg")
    (n,) = struct.unpack(">I", packed[:4])
    assert _strict(packed[4 : 4 + n]) == {"info": {"psnr dB": "inf"}} and packed[4 + n :] == b"jpeg"

    s = ViewServer(_Grey(info={"psnr dB": math.inf}))  # a split view's identical halves

    async def go():
        page = await Page.open(s)
        h = await page.frame()
        page.ws.close()
        return h

    try:
        assert asyncio.run(go())["info"]["psnr dB"] == "inf"
    finally:
        s.close()


def test_a_pan_zoom_or_turn_that_would_make_the_camera_non_finite_changes_nothing():
    o = Orbit([0, 0, 0], [1, 1, 1])
    before = o.state()
    for move in (
        lambda: o.pan(1e300, 1e300, 360),
        lambda: o.pan(math.inf, 0, 360),
        lambda: o.orbit(1e308, 1e308, 1),
        lambda: o.orbit(math.nan, 0, 360),
    ):
        with pytest.raises(ValueError, match="the camera would not be finite"):
            move()
        assert o.state() == before
    o.camera(16 / 9)  # still renders
    o.pan(10, 5, 360)  # and still moves
    assert o.state() != before


def test_the_server_refuses_a_drag_that_would_make_the_camera_non_finite(server):
    before = server.orbit.state()
    with pytest.raises(ValueError):
        server.handle({"type": "drag", "dx": 1e300, "dy": 1e300, "pan": True})
    assert server.orbit.state() == before and not server.interacting
    for _ in range(3):  # the largest drags allowed, again and again: still a camera
        server.handle({"type": "drag", "dx": 1e6, "dy": -1e6, "pan": True})
        server.handle({"type": "zoom", "factor": 1e6})
        server.orbit.camera(16 / 9)


def test_a_refused_camera_changes_nothing():
    o = Orbit([0, 0, 0], [1, 1, 1])
    before = o.state()
    for fov in (500, 0, math.nan, "wide", [1]):
        with pytest.raises(ValueError, match="camera: fov must be in 1..170 degrees"):
            o.set([5, 5, 5], [0, 0, 0], fov)
        assert o.state() == before
    o.set([5, 5, 5], [0, 0, 0], 30)
    assert np.allclose(o.eye, 5) and o.fov_y == 30


def test_each_page_has_its_own_frame_size_and_camera(server):
    """Two pages of other sizes: each gets frames at its own size and aspect,
    and one page's drag turns its own camera only (they shared one size and
    one camera: the last page's size made the other's frames the wrong
    aspect, and a drag moved both)."""

    async def go():
        a, b = await Page.open(server), await Page.open(server)
        await a.send({"type": "size", "width": 320, "height": 180, "seq": 1})
        await a.frame("a's frame at its size", width=320, height=180, seq=1)
        await b.send({"type": "size", "width": 200, "height": 200, "seq": 1})
        still_b = await b.frame("b's frame at its size", width=200, height=200, seq=1)
        await a.send({"type": "drag", "dx": 40, "dy": 0, "seq": 2})
        moved_a = await a.frame("a's interaction frame", interactive=True, width=160, height=90, seq=2)
        await a.send({"type": "end", "seq": 3})
        await a.frame("a's still frame", interactive=False, width=320, height=180, seq=3)
        assert moved_a["camera"]["azimuth"] != still_b["camera"]["azimuth"]
        # b asks for a frame: its own size, its own camera, not a's
        await b.send({"type": "end", "seq": 2})
        h = await b.frame("b's frame after a's drag", seq=2)
        assert (h["width"], h["height"], h["interactive"]) == (200, 200, False)
        assert h["camera"] == still_b["camera"]
        a.ws.close()  # in the middle of nothing: b goes on
        await b.send({"type": "drag", "dx": 5, "dy": 0, "seq": 3})
        await b.frame("b's interaction frame", interactive=True, width=100, height=100, seq=3)
        b.ws.close()

    asyncio.run(go())
    # the server's own view (handle() without a page) is neither page's
    assert server.size == (320, 180) and not server.interacting


def test_settings_are_the_scenes_every_page_gets_them_and_a_frame(server):
    async def go():
        a, b = await Page.open(server), await Page.open(server)
        await b.send({"type": "size", "width": 200, "height": 100, "seq": 1})
        await b.frame("b's frame at its size", width=200, height=100)
        await a.send({"type": "set", "settings": {"point_size": 3}})
        got = await b.next(lambda k, m: k == "settings", "the settings a page changed")
        assert got["settings"]["point_size"] == 3
        await b.frame("b's frame of the new settings", width=200, height=100, interactive=False)
        a.ws.close()
        b.ws.close()

    asyncio.run(go())
    assert server.scene.settings["point_size"] == 3


def test_a_page_beyond_max_pages_is_told_and_closed():
    s = ViewServer(_Grey(), size=(64, 48), max_pages=2)

    async def go():
        a, b = await Page.open(s), await Page.open(s)
        await a.frame("a's first frame")
        await b.frame("b's first frame")
        c = await Page.open(s)
        assert "at most 2 pages at once" in await c.error()
        assert await c.ws.read_message() is None  # closed, "try again later"
        assert c.ws.close_code == 1013 and "at most 2 pages" in c.ws.close_reason
        assert s.pages == 2
        a.ws.close()
        for _ in range(100):  # the server hears of it
            if s.pages == 1:
                break
            await asyncio.sleep(0.05)
        d = await Page.open(s)  # room again
        await d.frame("d's first frame")
        await b.send({"type": "fit"})
        await b.frame("b still served")
        b.ws.close()
        d.ws.close()

    try:
        asyncio.run(go())
    finally:
        s.close()


class _Sized(_Grey):
    """_Grey that records what the server tells it of the pages' sizes."""

    def __init__(self):
        super().__init__()
        self.released: list = []

    def release(self, sizes=()):
        self.released.append(tuple(sizes))


def test_a_closed_page_gives_its_frame_sizes_back():
    s = ViewServer(_Sized(), size=(64, 48))

    async def go():
        a, b = await Page.open(s), await Page.open(s)
        await a.send({"type": "size", "width": 120, "height": 80, "seq": 1})
        await a.frame("a's frame", width=120, seq=1)
        await b.frame("b's first frame")
        assert s.scene.kept_sizes == 4  # a still and an interaction size a page
        views = list(s._views.values())
        a.ws.close()
        for _ in range(100):
            if s.scene.released:
                break
            await asyncio.sleep(0.05)
        assert s.scene.released == [((120, 80), (60, 40))]
        assert s.scene.kept_sizes == 2 and s.pages == 1
        # nothing of a's view is left in the render worker
        assert s.scheduler.wait_idle(WAIT)
        assert not s.scheduler._latest and not s.scheduler._ready
        assert views[0] not in s._views.values()
        b.ws.close()

    try:
        asyncio.run(go())
    finally:
        s.close()


class _Passes(_Grey):
    """A progressive mode: `n` passes a view, `seconds` each."""

    progressive = frozenset(("points",))

    def __init__(self, n: int, seconds: float):
        super().__init__()
        self.n, self.seconds = n, seconds

    def frames(self, camera, width, height, settings, superseded):
        import time

        for i in range(self.n):
            time.sleep(self.seconds)
            yield Frame(
                np.full((height, width, 3), 90, np.uint8), final=i == self.n - 1, info={"pass": i + 1}
            )
            if superseded():
                return


def test_a_pages_progressive_render_does_not_hold_another_pages_frames_back():
    s = ViewServer(_Passes(40, 0.05), size=(64, 48))  # 2 s a view

    async def go():
        a = await Page.open(s)
        await a.send({"type": "size", "width": 80, "height": 60, "seq": 1})
        await a.frame("a's first pass", seq=1, width=80)
        b = await Page.open(s)  # while a's passes run
        b_first = await b.frame("b's first frame")
        a_last = await a.frame("a's last pass", seq=1, final=True, width=80)
        await b.frame("b's last pass", final=True)
        # the pages took turns: b's first frame did not wait for a's 2 s of passes
        assert b_first["id"] < a_last["id"]
        a.ws.close()
        b.ws.close()

    try:
        asyncio.run(go())
    finally:
        s.close()


@pytest.mark.parametrize(
    "page, frame",
    [
        ((7680, 4320), MAX_SIZE),
        ((5000, 1000), (3840, 768)),
        ((1000, 5000), (432, 2160)),
        ((1280, 720), (1280, 720)),
        ((1e6, 1e6), (2160, 2160)),
        ((4, 4), (16, 16)),
    ],
)
def test_a_page_larger_than_the_largest_frame_keeps_its_aspect(server, page, frame):
    server.handle({"type": "size", "width": page[0], "height": page[1]})
    assert server.size == frame


def _get(url):
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status
    except urllib.error.HTTPError as e:
        return e.code


def test_the_log_lines_do_not_show_the_token(caplog, monkeypatch):
    for name in ("tornado.access", "tornado.application", "tornado.general"):
        caplog.set_level(logging.INFO, logger=name)  # distributed's config quiets tornado's
    s = ViewServer(_Grey(), token="s3cret-t0ken")
    try:
        base = f"http://127.0.0.1:{s.port}/"
        assert _get(s.url) == 200 and _get(base + "?token=wrong-t0ken") == 403
        assert _get(base + "ws?token=wrong-t0ken") == 403

        def fails(sock):
            raise RuntimeError("open failed")

        monkeypatch.setattr(s, "opened", fails)

        async def go():
            page = await Page.open(s, "s3cret-t0ken")
            assert await page.ws.read_message() is None  # tornado closes it

        asyncio.run(go())
    finally:
        s.close()
    lines = [r.getMessage() for r in caplog.records]
    assert any(line.startswith("200 GET / (127.0.0.1)") for line in lines), lines
    assert any(line.startswith("403 GET /ws (127.0.0.1)") for line in lines), lines
    assert "Uncaught exception GET /ws (127.0.0.1)" in lines, lines
    assert not [line for line in lines if "t0ken" in line], lines


@pytest.mark.parametrize(
    "query, first",
    [
        ("width=200&height=100", (200, 100)),  # the page's canvas
        ("width=9999&height=1000", (3840, 384)),  # one factor, as a size event's
        ("width=nan&height=100", (320, 180)),  # not a size: the server's until the page sends one
        ("width=200", (320, 180)),
    ],
)
def test_a_page_that_opens_with_its_size_gets_its_first_frame_at_that_size(server, query, first):
    """The page sends its canvas size with the socket's URL: its first frame
    is at that size (it was rendered at the server's default size, then
    thrown away when the page's size event came; 1280x720 for clvis view)."""

    async def go():
        page = await Page.open(server, query=query)
        h = await page.frame("the first frame")
        assert (h["width"], h["height"]) == first
        page.ws.close()

    asyncio.run(go())
    assert server.frames == 1


def test_an_openvdb_grid_too_large_for_its_iso_mode_is_an_error_in_the_page(monkeypatch):
    """clvis view FILE.vdb, mode iso, where the grid made dense would not fit
    in host memory: the page's status line gets the refusal (nothing made
    dense, the server goes on), and back in mode gaussians it gets frames."""
    from pathlib import Path

    import clvis
    from clvis import runtime
    from clvis.view import SparseScene

    path = Path(__file__).resolve().parents[1] / "data" / "openvdb_small.vdb"
    s = ViewServer(SparseScene(clvis.read_vdb(path), description="big.vdb"), size=(64, 48))
    monkeypatch.setattr(runtime, "host_available_bytes", lambda: 100_000)

    async def go():
        page = await Page.open(s)
        await page.frame("the first frame", mode="gaussians")
        await page.send({"type": "set", "settings": {"mode": "iso"}})
        error = await page.error()
        await page.send({"type": "set", "settings": {"mode": "gaussians"}})
        await page.frame("a frame after the error", mode="gaussians")
        page.ws.close()
        return error

    try:
        error = asyncio.run(go())
    finally:
        s.close()
    assert error.startswith("DeviceError: big.vdb: the grid made dense is 38x39x40 voxels")
    assert "mode gaussians" in error and len(error) <= 300 and s.scene._dense is None


def test_the_scene_is_told_which_frames_are_the_cameras_moving():
    """An interaction frame's settings say "interacting" (a gaussians mode
    then draws its budget, scenes.GAUSS_BUDGET), a still frame's do not; the
    page cannot set it (it is no setting of the scene's)."""

    class Told(_Grey):
        def frames(self, camera, width, height, settings, superseded):
            seen.append(settings.get("interacting"))
            yield from super().frames(camera, width, height, settings, superseded)

    seen: list = []
    s = ViewServer(Told(), size=(320, 180))

    async def go():
        a = await Page.open(s)
        await a.send({"type": "size", "width": 320, "height": 180, "seq": 1})
        await a.frame("a still frame", interactive=False, seq=1)
        await a.send({"type": "drag", "dx": 40, "dy": 0, "seq": 2})
        await a.frame("an interaction frame", interactive=True, seq=2)
        await a.send({"type": "set", "settings": {"interacting": True}})
        assert "unknown setting 'interacting'" in await a.error()
        a.ws.close()

    try:
        asyncio.run(go())
    finally:
        s.close()
    assert seen[-2:] == [False, True] and "interacting" not in s.scene.settings
