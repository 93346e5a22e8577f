"""The viewer's server: the page over HTTP, frames and events over a WebSocket.

Tornado runs on its own thread with its own event loop (so a Jupyter kernel's
loop is never touched); renders run on the LatestWins worker thread. Each
page has its own view (:class:`View`: camera, frame size, drag state); the
settings are the scene's, one set for every page. Every event updates its
page's view (or the settings) at once and asks for a frame; the worker
renders the newest state of each view when it gets to it, so a burst of mouse
events costs one frame, not one each. While the pointer drags, frames are rendered
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
from collections.abc import Iterator
from importlib import resources
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from ..camera import hemisphere_cameras
from .orbit import Orbit
from .scenes import Frame, Scene, view_frames
from .schedule import LatestWins, Outbox

__all__ = ["LOOPBACK", "MAX_PAGES", "View", "ViewServer", "access_token", "needs_token", "token_ok"]

LOOPBACK = ("127.0.0.1", "localhost", "::1")
MAX_SIZE = (3840, 2160)
MIN_SIDE = 16
MAX_NUMBER = 1e6  # the largest |number| an event takes (pixels of a drag, a page's side, a zoom factor)
_MAX_ERROR = 300  # characters of an error message sent back (the value it names may be long)
HEMISPHERE_VIEWS = 128  # clvis.hemisphere_cameras: 4 polar angles x 32 azimuths
_QUALITY = {True: 75, False: 92}  # JPEG quality while dragging, when still
MAX_PAGES = 8  # pages (sockets) a server shows at once, each its own view
_FULL = 1013  # the WebSocket close code "try again later": a page beyond max_pages


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


class View:
    """One page's view: its camera (an orbit), frame size, drag state and the
    last event it reflects; `sock` the page's socket (None: the server's own
    view, the one ``ViewServer.handle`` without a page changes)."""

    def __init__(self, scene: Scene, size: tuple[int, int], sock: Any = None) -> None:
        self.orbit = Orbit(scene.lo, scene.hi, azimuth=scene.home_azimuth, points=scene.fit_points)
        self.size = size
        self.orbit.fit(size[0] / size[1])
        self.interacting = False
        self.moved = False  # by the person: until then a resize frames the data again
        self.seq = 0  # the last event applied
        self.sock = sock
        self.last_send = 0.0  # seconds the page's previous frame took to send


class ViewServer:
    """Serve `scene` at http://host:port/ (port 0: a free one).

    ``url`` is the address to open (with the token when there is one).
    ``close()`` stops the server and the render worker. Each page (socket)
    gets its own :class:`View`; at most `max_pages` at once (one more is
    told so and closed). ``view`` is the server's own view (``handle(msg)``
    without a page; ``orbit``, ``size`` and ``interacting`` are its).
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
        max_pages: int = MAX_PAGES,
    ) -> None:
        try:
            import tornado  # noqa: F401
        except ImportError:
            from ..errors import ClvisError

            raise ClvisError("clvis view needs tornado: pip install 'clvis[view]'") from None
        if not 0 < interactive_scale <= 1:
            raise ValueError(f"interactive_scale: expected a fraction in (0, 1], got {interactive_scale!r}")
        if isinstance(max_pages, bool) or not isinstance(max_pages, int) or max_pages < 1:
            raise ValueError(f"max_pages: expected a positive integer, got {max_pages!r}")
        # the socket layer would take 70000 as 70000 % 65536 = 4464, and "8080" as is
        if isinstance(port, bool) or not isinstance(port, (int, np.integer)):
            raise TypeError(f"port: expected an int in [0, 65535], got {type(port).__name__}")
        if not 0 <= port <= 65535:
            raise ValueError(f"port: expected an int in [0, 65535] (0: a free one), got {port}")
        port = int(port)
        self.scene, self.host, self.token = scene, host, access_token(host, token)
        self.interactive_scale = float(interactive_scale)
        self.max_pages = max_pages
        self.size0 = self._clamp_size(*size)  # a page's frame size until it sends its own
        self.view = View(scene, self.size0)
        self.frames = 0
        self._lock = threading.Lock()
        self._views: dict[Any, View] = {}  # the open pages' views by socket (the loop's thread)
        self.scheduler = LatestWins()
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

    # the server's own view (what tests and Python callers of handle() read)
    @property
    def orbit(self) -> Orbit:
        return self.view.orbit

    @property
    def size(self) -> tuple[int, int]:
        return self.view.size

    @property
    def interacting(self) -> bool:
        return self.view.interacting

    @property
    def pages(self) -> int:
        """The pages open now."""
        return len(self._views)

    def _config(self, view: View) -> dict:
        s = self.scene
        return {
            "type": "config",
            "kind": s.kind,
            "modes": s.modes,
            "settings": s.settings,
            "choices": s.choices,
            "description": s.description,
            "device": s.device,
            "camera": view.orbit.state(self.scene.file_origin),
        }

    def opened(self, sock: Any, size: tuple[Any, Any] | None = None) -> bool:
        """A page opened its socket: its own view, at the start camera, and
        its first frame, at `size` (the page's canvas, sent with the socket's
        URL: the first frame is not one of the default size, thrown away when
        the page's ``size`` event comes; None: the server's size); False (the
        page told why, its socket closed) when `max_pages` are open already.
        ValueError for a size that is not two finite numbers."""
        if len(self._views) >= self.max_pages:
            message = (
                f"this viewer shows at most {self.max_pages} pages at once, each its own view: "
                "close one and reload this page"
            )
            sock.write_message(to_json({"type": "error", "message": message}))
            sock.close(_FULL, f"at most {self.max_pages} pages at once: close one and reload")
            return False
        first = self.size0 if size is None else self._clamp_size(*size)
        view = self._views[sock] = View(self.scene, first, sock)
        self._keep_sizes()
        sock.write_message(to_json(self._config(view)))
        self.request(view)
        return True

    def closed(self, sock: Any) -> None:
        """A page went away: its view's frames stop (one in progress too) and,
        on the render thread, the memory pool gives back the blocks held for
        its frame sizes."""
        view = self._views.pop(sock, None)
        if view is None:
            return
        self.scheduler.cancel(view)
        self._keep_sizes()
        with self._lock:
            sizes = (view.size, self.interaction_size(*view.size))
        try:
            self.scheduler.submit(lambda _superseded: self.scene.release(sizes), key=("closed", view))
        except RuntimeError:  # the server is closing: nothing renders any more
            pass

    def _keep_sizes(self) -> None:
        # the pool keeps its blocks for a still and an interaction size a page
        self.scene.kept_sizes = 2 * max(1, len(self._views))

    def handle(self, msg: dict, sock: Any = None) -> None:
        """An event from the page of socket `sock` (None: the server's own
        view), on the loop's thread. ValueError for a malformed one (a wrong
        type, a number out of range, a camera that would not be finite); the
        view is then as it was. A view event changes that page's view only;
        ``set`` changes the scene's settings, and every page gets them and a
        new frame."""
        view = self.view if sock is None else self._views.get(sock)
        if view is None:  # a message after the page was refused or closed
            return
        kind = msg.get("type")
        reply = None
        with self._lock:
            seq = msg.get("seq")
            if isinstance(seq, int) and not isinstance(seq, bool) and 0 <= seq < 2**53:
                view.seq = seq
            orbit, h = view.orbit, view.size[1]
            if kind == "size":
                view.size = self._clamp_size(msg.get("width"), msg.get("height"))
                if not view.moved:  # the page's own shape: frame the data for it
                    orbit.fit(view.size[0] / view.size[1])
            elif kind == "drag":
                dx, dy = _number(msg.get("dx"), "dx"), _number(msg.get("dy"), "dy")
                if msg.get("pan"):
                    orbit.pan(dx, dy, h)
                else:
                    orbit.orbit(dx, dy, h)
                view.interacting = view.moved = True
            elif kind == "zoom":
                orbit.zoom(min(max(_number(msg.get("factor"), "factor", 1.0), 0.2), 5.0))
                view.interacting = view.moved = True
            elif kind == "end":
                view.interacting = False
            elif kind == "fit":
                orbit.fit(view.size[0] / view.size[1])
                view.interacting = False
            elif kind == "camera":
                # the page's JSON as it came: Orbit.set rejects anything but two
                # finite 3-vectors (None included) with a ValueError
                eye, target = cast(npt.ArrayLike, msg.get("eye")), cast(npt.ArrayLike, msg.get("target"))
                orbit.set(*_local(self.scene.file_origin, eye, target), msg.get("fov"))
                view.interacting, view.moved = False, True
            elif kind == "preset":  # one of the NARVis samplers' 128 hemisphere views
                k = msg.get("hemisphere")
                if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < HEMISPHERE_VIEWS:
                    raise ValueError(f"hemisphere: expected a view 0..{HEMISPHERE_VIEWS - 1}, got {k!r}")
                lo, hi = orbit.lo, orbit.hi
                if float(np.linalg.norm(hi - lo)) / 2 < orbit.radius:  # one point: the orbit's unit sphere
                    half = orbit.radius / np.sqrt(3.0)
                    lo, hi = (lo + hi) / 2 - half, (lo + hi) / 2 + half
                cam = next(itertools.islice(hemisphere_cameras(lo, hi), k, None))
                orbit.set(cam.eye, (lo + hi) / 2)
                view.interacting, view.moved = False, True
            elif kind == "set":
                self.scene.update(msg.get("settings", {}))
                reply = {"type": "settings", "settings": self.scene.settings}
            else:
                raise ValueError(f"unknown event {kind!r}")
        if reply is None:
            self.request(view)
            return
        # the settings are the scene's: every page shows them
        self._send_text(to_json(reply))
        for other in list(self._views.values()) or [self.view]:
            self.request(other)

    def _send_text(self, text: str) -> None:
        """`text` to every page."""
        for sock in list(self._views):
            sock.write_message(text)

    def _deliver(self, view: View, data: bytes) -> None:
        """A frame to its page (on the loop's thread), unless the page went away."""
        if view.sock is not None and self._views.get(view.sock) is view:
            view.sock.outbox.put(data)

    def _report(self, e: BaseException, view: View) -> None:
        """A frame of `view` failed: the error to its page (the server's own
        view: to every page)."""
        text = to_json({"type": "error", "message": f"{type(e).__name__}: {e}"[:_MAX_ERROR]})
        loop = self._loop
        if loop is None or loop.is_closed():
            return

        def send() -> None:
            if view.sock is None:
                self._send_text(text)
            elif self._views.get(view.sock) is view:
                view.sock.write_message(text)

        loop.call_soon_threadsafe(send)

    # -- the render worker's thread ------------------------------------------------

    def request(self, view: View | None = None) -> int:
        """Ask for a frame of `view`'s current state (None: the server's own
        view); the newest request of each view wins."""
        view = self.view if view is None else view
        return self.scheduler.submit(functools.partial(self._frames, view), key=view)

    def _frames(self, view: View, superseded) -> Iterator[None]:
        """`view`'s frames, one step of the worker each (the pages take turns
        between frames); an error is that page's message."""
        try:
            yield from self._render(view, superseded)
        except Exception as e:
            self._report(e, view)
            raise

    def interaction_size(self, w: int, h: int) -> tuple[int, int]:
        """The size of an interaction frame for a page of w x h."""
        s = self.interactive_scale
        return max(MIN_SIDE, round(w * s)), max(MIN_SIDE, round(h * s))

    def _render(self, view: View, superseded) -> Iterator[None]:
        with self._lock:
            interactive = view.interacting
            w, h = view.size
            preview = None
            if interactive:
                w, h = self.interaction_size(w, h)
            else:  # a progressive mode's still view starts with its first pass at the interaction size
                pw, ph = self.interaction_size(w, h)
                preview = (view.orbit.camera(pw / ph), pw, ph)
            camera = view.orbit.camera(w / h)
            state = view.orbit.state(self.scene.file_origin)
            # the camera moving: a gaussians mode draws its budget (scenes.GAUSS_BUDGET)
            settings = {**self.scene.settings, "interacting": interactive}
            seq = view.seq
        for frame in view_frames(self.scene, camera, w, h, settings, superseded, preview):
            self._emit(view, frame, interactive, settings, state, seq)
            if superseded():
                return
            yield

    def _emit(
        self, view: View, frame: Frame, interactive: bool, settings: dict, state: dict, seq: int
    ) -> None:
        t0 = time.perf_counter()
        jpeg = encode_jpeg(frame.image, _QUALITY[interactive or "preview" in frame.info])
        times = {k: round(v * 1000, 2) for k, v in frame.times.items()}
        times["encode"] = round((time.perf_counter() - t0) * 1000, 2)
        times["send"] = round(view.last_send * 1000, 2)  # the page's previous frame's
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
            loop.call_soon_threadsafe(self._deliver, view, data)

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
                for sock in list(self._views):
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
            # the page's canvas size, in the URL (?width=W&height=H): its
            # first frame at that size; none, or not two numbers: the
            # server's size until a size event
            w, h = self.get_query_argument("width", None), self.get_query_argument("height", None)
            size = None
            if w is not None and h is not None:
                try:
                    size = self.server._clamp_size(float(w), float(h))
                except ValueError:
                    size = None
            self.server.opened(self, size)

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
                self.server.handle(msg, self)
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
                view = self.server._views.get(self)
                if view is not None:
                    view.last_send = time.perf_counter() - t0
                self.outbox.done()

            fut.add_done_callback(done)

    return PageHandler, SocketHandler
