"""The viewer's server: the page over HTTP, frames and events over a WebSocket.

Tornado runs on its own thread with its own event loop (so a Jupyter kernel's
loop is never touched); renders run on the LatestWins worker thread. Every
event updates the shared view state at once and asks for a frame; the worker
renders the newest state when it gets to it, so a burst of mouse events
costs one frame, not one each. While the pointer drags, frames are rendered
at ``interactive_scale`` of the page's size and sent as lower-quality JPEG;
when it stops, at full size (a progressive mode's still view starts with its
first pass at the interaction size: scenes.view_frames). Each frame is one binary message: a 4-byte
big-endian header length, the header (JSON: camera, figures, seconds per
stage), then the JPEG.

Security: the server binds 127.0.0.1 by default. Any other host gets a token
(printed with the URL) that the page and the socket must present; tornado's
same-origin check refuses sockets opened by other sites' pages. The data are
the ones the server was started with: the page can change the view and the
settings, never name a file.
"""

from __future__ import annotations

import asyncio
import functools
import hmac
import io
import itertools
import json
import math
import secrets
import struct
import sys
import threading
import time
from importlib import resources
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from ..camera import hemisphere_cameras
from .orbit import Orbit
from .scenes import Frame, Scene, view_frames
from .schedule import LatestWins, Outbox

__all__ = ["LOOPBACK", "ViewServer", "access_token", "needs_token", "token_ok"]

LOOPBACK = ("127.0.0.1", "localhost", "::1")
MAX_SIZE = (3840, 2160)
MIN_SIDE = 16
MAX_NUMBER = 1e6  # the largest |number| an event takes (pixels of a drag, a page's side, a zoom factor)
_MAX_ERROR = 300  # characters of an error message sent back (the value it names may be long)
HEMISPHERE_VIEWS = 128  # clvis.hemisphere_cameras: 4 polar angles x 32 azimuths
_QUALITY = {True: 75, False: 92}  # JPEG quality while dragging, when still


def needs_token(host: str) -> bool:
    """Every host but the loopback interface (localhost, 127.0.0.0/8, ::1) needs a token."""
    import ipaddress

    if host in LOOPBACK:
        return False
    try:
        return not ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:  # a host name: it may resolve to any interface
        return True


def access_token(host: str, token: str | None = None) -> str | None:
    """The token a server on `host` asks for: `token` when given, else a new
    random one for any host but loopback (None: no token)."""
    if token is None and needs_token(host):
        return secrets.token_urlsafe(18)
    return token


def token_ok(expected: str | None, given: str | None) -> bool:
    """Whether `given` is the server's token (any value when it has none);
    compared in constant time."""
    if expected is None:
        return True
    if not isinstance(given, str) or not given:
        return False
    return hmac.compare_digest(expected.encode(), given.encode())


def _rgbx(image: np.ndarray) -> np.ndarray | None:
    """The C-contiguous (H, W, 4) array whose first three channels `image`
    (an (H, W, 3) uint8 view) is, or None (what scenes._over_background
    gives: PIL reads it as RGBX without a copy)."""
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        return None
    h, w = image.shape[:2]
    if image.strides != (4 * w, 4, 1):
        return None
    start = image.__array_interface__["data"][0]
    base = image.base
    while isinstance(base, np.ndarray):
        if (
            base.flags.c_contiguous
            and base.nbytes == 4 * h * w
            and base.__array_interface__["data"][0] == start
        ):
            return base
        base = base.base
    return None


def encode_jpeg(image: Any, quality: int) -> bytes:
    """`image` (H, W, 3) uint8 as JPEG: 4:2:0 below quality 90, else 4:4:4."""
    from PIL import Image

    buf = io.BytesIO()
    rgbx = _rgbx(image) if isinstance(image, np.ndarray) else None
    if rgbx is not None:
        h, w = image.shape[:2]
        pic = Image.frombuffer("RGB", (w, h), rgbx, "raw", "RGBX", 0, 1)
    else:
        pic = Image.fromarray(image)
    pic.save(buf, format="JPEG", quality=quality, subsampling=0 if quality >= 90 else 2)
    return buf.getvalue()


def _finite(obj: Any) -> Any:
    """`obj` (JSON-ready) with each non-finite float as the string the page
    shows ("inf", "-inf", "nan": a split view's two identical halves have a
    PSNR of inf)."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return "nan" if obj != obj else ("inf" if obj > 0 else "-inf")
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def to_json(obj: Any) -> str:
    """Strict JSON, what the page's JSON.parse reads: json.dumps writes an
    infinite float as Infinity, which it refuses (the view froze); see _finite."""
    return json.dumps(_finite(obj), separators=(",", ":"), allow_nan=False)


def pack_message(header: dict, payload: bytes) -> bytes:
    h = to_json(header).encode()
    return struct.pack(">I", len(h)) + h + payload


class ViewServer:
    """Serve `scene` at http://host:port/ (port 0: a free one).

    ``url`` is the address to open (with the token when there is one).
    ``close()`` stops the server and the render worker.
    """

    def __init__(
        self,
        scene: Scene,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        token: str | None = None,
        interactive_scale: float = 0.5,
        size: tuple[int, int] = (1280, 720),
    ) -> None:
        try:
            import tornado  # noqa: F401
        except ImportError:
            from ..errors import ClvisError

            raise ClvisError("clvis view needs tornado: pip install 'clvis[view]'") from None
        if not 0 < interactive_scale <= 1:
            raise ValueError(f"interactive_scale: expected a fraction in (0, 1], got {interactive_scale!r}")
        self.scene, self.host, self.token = scene, host, access_token(host, token)
        self.interactive_scale = float(interactive_scale)
        self.orbit = Orbit(scene.lo, scene.hi, points=scene.fit_points)
        self.size = self._clamp_size(*size)
        self.orbit.fit(self.size[0] / self.size[1])
        self.interacting = False
        self.moved = False  # by the person: until then a resize frames the data again
        self.seq = 0  # the last event applied
        self.frames = 0
        self.last_send = 0.0
        self._lock = threading.Lock()
        self._sockets: set[Any] = set()
        self._error: str | None = None
        self.scheduler = LatestWins(on_error=self._report)
        self._ready = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: Any = None
        self._startup_error: BaseException | None = None
        self.thread = threading.Thread(target=self._serve, args=(port,), name="clvis-view-http", daemon=True)
        self.thread.start()
        self._ready.wait()
        if self._startup_error is not None:
            self.scheduler.close()
            raise self._startup_error

    # -- the event loop's thread ---------------------------------------------------

    def _serve(self, port: int) -> None:
        import tornado.httpserver
        import tornado.web

        loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        self._loop = loop
        try:
            page, socket = _handlers()
            app = tornado.web.Application(
                [(r"/", page, {"server": self}), (r"/ws", socket, {"server": self})],
                websocket_ping_interval=20,
                log_function=_log_request,
            )
            self._server = tornado.httpserver.HTTPServer(app, max_body_size=1 << 16)
            self._server.listen(port, address=self.host)
            sock = next(iter(self._server._sockets.values()))
            self.port = sock.getsockname()[1]
        except BaseException as e:  # noqa: BLE001  (re-raised on the caller's thread)
            self._startup_error = e
            self._ready.set()
            loop.close()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            loop.close()

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        if host in ("0.0.0.0", "[::]"):
            import socket

            host = socket.gethostname()
        return f"http://{host}:{self.port}/" + (f"?token={self.token}" if self.token else "")

    def _config(self) -> dict:
        s = self.scene
        return {
            "type": "config",
            "kind": s.kind,
            "modes": s.modes,
            "settings": s.settings,
            "choices": s.choices,
            "description": s.description,
            "device": s.device,
            "camera": self.orbit.state(self.scene.file_origin),
        }

    def opened(self, sock: Any) -> None:
        self._sockets.add(sock)
        with self._lock:  # a drag another page left unfinished ends here
            self.interacting = False
        sock.write_message(to_json(self._config()))
        self.request()

    def closed(self, sock: Any) -> None:
        """A page went away: a drag it did not end (no ``end`` before the
        socket closed) ends, or every page's frames stayed at the interaction size."""
        self._sockets.discard(sock)
        with self._lock:
            was, self.interacting = self.interacting, False
        if was and self._sockets:
            self.request()

    def handle(self, msg: dict) -> None:
        """An event from the page (on the loop's thread). ValueError for a
        malformed one (a wrong type, a number out of range, a camera that
        would not be finite); the view is then as it was."""
        kind = msg.get("type")
        interactive = False
        reply = None
        with self._lock:
            seq = msg.get("seq")
            if isinstance(seq, int) and not isinstance(seq, bool) and 0 <= seq < 2**53:
                self.seq = seq
            h = self.size[1]
            if kind == "size":
                self.size = self._clamp_size(msg.get("width"), msg.get("height"))
                if not self.moved:  # the page's own shape: frame the data for it
                    self.orbit.fit(self.size[0] / self.size[1])
            elif kind == "drag":
                dx, dy = _number(msg.get("dx"), "dx"), _number(msg.get("dy"), "dy")
                if msg.get("pan"):
                    self.orbit.pan(dx, dy, h)
                else:
                    self.orbit.orbit(dx, dy, h)
                self.interacting = interactive = self.moved = True
            elif kind == "zoom":
                self.orbit.zoom(min(max(_number(msg.get("factor"), "factor", 1.0), 0.2), 5.0))
                self.interacting = interactive = self.moved = True
            elif kind == "end":
                self.interacting = False
            elif kind == "fit":
                self.orbit.fit(self.size[0] / self.size[1])
                self.interacting = False
            elif kind == "camera":
                # the page's JSON as it came: Orbit.set rejects anything but two
                # finite 3-vectors (None included) with a ValueError
                eye, target = cast(npt.ArrayLike, msg.get("eye")), cast(npt.ArrayLike, msg.get("target"))
                self.orbit.set(*_local(self.scene.file_origin, eye, target), msg.get("fov"))
                self.interacting, self.moved = False, True
            elif kind == "preset":  # one of the NARVis samplers' 128 hemisphere views
                k = msg.get("hemisphere")
                if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < HEMISPHERE_VIEWS:
                    raise ValueError(f"hemisphere: expected a view 0..{HEMISPHERE_VIEWS - 1}, got {k!r}")
                lo, hi = self.orbit.lo, self.orbit.hi
                if (
                    float(np.linalg.norm(hi - lo)) / 2 < self.orbit.radius
                ):  # one point: the orbit's unit sphere
                    half = self.orbit.radius / np.sqrt(3.0)
                    lo, hi = (lo + hi) / 2 - half, (lo + hi) / 2 + half
                cam = next(itertools.islice(hemisphere_cameras(lo, hi), k, None))
                self.orbit.set(cam.eye, (lo + hi) / 2)
                self.interacting, self.moved = False, True
            elif kind == "set":
                self.scene.update(msg.get("settings", {}))
                reply = {"type": "settings", "settings": self.scene.settings}
            else:
                raise ValueError(f"unknown event {kind!r}")
        if reply is not None:
            self._send_text(to_json(reply))
        self.request(interactive)

    def _send_text(self, text: str) -> None:
        for sock in list(self._sockets):
            sock.write_message(text)

    def _broadcast(self, data: bytes) -> None:
        for sock in list(self._sockets):
            sock.outbox.put(data)

    def _report(self, e: BaseException) -> None:
        text = to_json({"type": "error", "message": f"{type(e).__name__}: {e}"[:_MAX_ERROR]})
        if self._loop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._send_text, text)

    # -- the render worker's thread ------------------------------------------------

    def request(self, interactive: bool = False) -> int:
        """Ask for a frame of the current state (the newest request wins)."""
        return self.scheduler.submit(self._render)

    def interaction_size(self, w: int, h: int) -> tuple[int, int]:
        """The size of an interaction frame for a page of w x h."""
        s = self.interactive_scale
        return max(MIN_SIDE, round(w * s)), max(MIN_SIDE, round(h * s))

    def _render(self, superseded) -> None:
        with self._lock:
            interactive = self.interacting
            w, h = self.size
            preview = None
            if interactive:
                w, h = self.interaction_size(w, h)
            else:  # a progressive mode's still view starts with its first pass at the interaction size
                pw, ph = self.interaction_size(w, h)
                preview = (self.orbit.camera(pw / ph), pw, ph)
            camera = self.orbit.camera(w / h)
            state = self.orbit.state(self.scene.file_origin)
            settings = dict(self.scene.settings)
            seq = self.seq
        for frame in view_frames(self.scene, camera, w, h, settings, superseded, preview):
            self._emit(frame, interactive, settings, state, seq)
            if superseded():
                return

    def _emit(self, frame: Frame, interactive: bool, settings: dict, state: dict, seq: int) -> None:
        t0 = time.perf_counter()
        jpeg = encode_jpeg(frame.image, _QUALITY[interactive or "preview" in frame.info])
        times = {k: round(v * 1000, 2) for k, v in frame.times.items()}
        times["encode"] = round((time.perf_counter() - t0) * 1000, 2)
        times["send"] = round(self.last_send * 1000, 2)  # the previous frame's
        self.frames += 1
        header = {
            "type": "frame",
            "id": self.frames,
            "seq": seq,
            "width": int(frame.image.shape[1]),
            "height": int(frame.image.shape[0]),
            "interactive": interactive,
            "final": frame.final,
            "mode": settings.get("mode"),
            "info": frame.info,
            "ms": times,
            "bytes": len(jpeg),
            "camera": state,
            "device": self.scene.device,
        }
        data = pack_message(header, jpeg)
        loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._broadcast, data)

    # -----------------------------------------------------------------------------

    def _clamp_size(self, w: Any, h: Any) -> tuple[int, int]:
        """The frame size for a page of w x h: at least MIN_SIDE, and a page
        larger than MAX_SIZE scaled down by one factor (its aspect kept: the
        page draws the frame over its whole canvas)."""
        w = max(_number(w, "width", 960), MIN_SIDE)
        h = max(_number(h, "height", 540), MIN_SIDE)
        k = min(1.0, MAX_SIZE[0] / w, MAX_SIZE[1] / h)
        return (
            min(max(round(w * k), MIN_SIDE), MAX_SIZE[0]),
            min(max(round(h * k), MIN_SIDE), MAX_SIZE[1]),
        )

    def close(self) -> None:
        """Stop the render worker, the scene's cluster (a Dask scene) and the server."""
        self.scheduler.close()
        try:
            self.scene.close()
        except Exception as e:  # noqa: BLE001  (closing goes on: the server still stops)
            print(f"clvis view: closing the scene: {type(e).__name__}: {e}", file=sys.stderr)
        loop = self._loop
        if loop is not None and not loop.is_closed():

            def stop():
                if self._server is not None:
                    self._server.stop()
                for sock in list(self._sockets):
                    sock.close()
                loop.stop()

            loop.call_soon_threadsafe(stop)
            self.thread.join(5)


def _local(origin: np.ndarray, eye: Any, target: Any) -> tuple[Any, Any]:
    """A typed camera (the file's coordinates) in the scene's: `origin`
    subtracted; anything but two finite 3-vectors passes unchanged for
    Orbit.set to refuse."""
    out = []
    for v in (eye, target):
        try:
            a = np.asarray(v, np.float64)
        except (TypeError, ValueError):
            return eye, target
        if a.shape != (3,):
            return eye, target
        out.append(a - origin)
    return out[0], out[1]


def _short(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


def _number(v: Any, name: str, default: float = 0.0) -> float:
    """An event's number `v` (absent: `default`); ValueError naming `name`
    for anything but a finite number within ±MAX_NUMBER (a bool, a string,
    an integer too large for a float)."""
    if v is None:
        return default
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"{name}: expected a number, got {_short(v)}")
    try:
        f = float(v)
    except OverflowError:
        f = math.inf
    if not (math.isfinite(f) and abs(f) <= MAX_NUMBER):
        raise ValueError(f"{name}: expected a finite number within ±{MAX_NUMBER:g}, got {_short(v)}")
    return f


def _no_constant(name: str) -> Any:
    raise ValueError(f"message: {name} is not a JSON number")


def _summary(request: Any) -> str:
    """A request as the log shows it: the path without the query (the token)."""
    return f"{request.method} {request.path} ({request.remote_ip})"


def _log_request(handler: Any) -> None:
    """tornado's access log line, with the path only (its own writes the
    URI, and with it the token: a secret in the logs)."""
    from tornado.log import access_log

    status = handler.get_status()
    log = access_log.info if status < 400 else access_log.warning if status < 500 else access_log.error
    log("%d %s %.2fms", status, _summary(handler.request), 1000.0 * handler.request.request_time())


def _page() -> bytes:
    return resources.files(__package__).joinpath("static/index.html").read_bytes()


@functools.cache
def _handlers():
    import tornado.web
    import tornado.websocket
    from tornado.log import app_log

    class Redacted(tornado.web.RequestHandler):
        """tornado's log lines without the query (the token): its own name the URI."""

        def _request_summary(self) -> str:
            return _summary(self.request)

        def log_exception(self, typ, value, tb) -> None:
            if isinstance(value, tornado.web.HTTPError):
                super().log_exception(typ, value, tb)  # one line, through _request_summary
            else:  # tornado's adds repr(request), the URI in it
                app_log.error("Uncaught exception %s", _summary(self.request), exc_info=(typ, value, tb))

    class PageHandler(Redacted):
        def initialize(self, server: ViewServer) -> None:
            self.server = server

        def get(self) -> None:
            if not token_ok(self.server.token, self.get_query_argument("token", None)):
                self.set_status(403)
                self.finish("clvis view: open the URL the server printed (with its token)\n")
                return
            self.set_header("Content-Type", "text/html; charset=utf-8")
            self.set_header("Cache-Control", "no-store")
            self.finish(_page())

    class SocketHandler(tornado.websocket.WebSocketHandler, Redacted):
        def initialize(self, server: ViewServer) -> None:
            self.server = server
            self.outbox = Outbox(self._send)

        def prepare(self) -> None:
            if not token_ok(self.server.token, self.get_query_argument("token", None)):
                raise tornado.web.HTTPError(403)

        def open(self) -> None:
            self.server.opened(self)

        def on_message(self, message) -> None:
            """One event; whatever goes wrong with it is an error message to
            this page, and the connection stays open."""
            msg: Any = None
            try:
                try:
                    msg = json.loads(message, parse_constant=_no_constant)
                except RecursionError:
                    raise ValueError("message: nested too deeply") from None
                if not isinstance(msg, dict):
                    raise ValueError("expected a JSON object")
                self.server.handle(msg)
            except (ValueError, TypeError) as e:
                self._error(str(e))
            except Exception as e:  # noqa: BLE001  (a bug: the page hears of it, the socket lives)
                kind = msg.get("type") if isinstance(msg, dict) else None
                text = f"{type(e).__name__}: {e}"[:_MAX_ERROR]
                print(f"clvis view: event {_short(kind)}: {text}", file=sys.stderr)
                self._error(text)

        def _error(self, message: str) -> None:
            try:
                self.write_message(to_json({"type": "error", "message": message[:_MAX_ERROR]}))
            except tornado.websocket.WebSocketClosedError:
                pass

        def on_close(self) -> None:
            self.server.closed(self)

        def _send(self, data: bytes) -> None:
            t0 = time.perf_counter()
            try:
                fut = self.write_message(data, binary=True)
            except tornado.websocket.WebSocketClosedError:
                return

            def done(_f) -> None:
                self.server.last_send = time.perf_counter() - t0
                self.outbox.done()

            fut.add_done_callback(done)

    return PageHandler, SocketHandler
