"""A real dask.distributed LocalCluster for the distributed tests (and the
CLI's): two worker processes of one thread each, dashboards on free ports, a bound on
every wait."""

import contextlib
import socket

import pytest

distributed = pytest.importorskip("distributed")  # the `distributed` extra; ./dev.sh test installs it

TIMEOUT = 60  # seconds any wait of these tests may take


def local_cluster(**kw):
    """A LocalCluster of two one-thread worker processes."""
    kw.setdefault("n_workers", 2)
    return distributed.LocalCluster(
        threads_per_worker=1, processes=True, dashboard_address=":0", worker_dashboard_address=":0", **kw
    )


@contextlib.contextmanager
def silent_scheduler():
    """A tcp:// address on this machine that accepts connections and never
    speaks Dask (a scheduler that hangs); closed after."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    try:
        yield f"tcp://127.0.0.1:{srv.getsockname()[1]}"
    finally:
        srv.close()


@contextlib.contextmanager
def _served(answer):
    """A "host:port" on this machine whose connections a thread hands to
    `answer(conn)` as they come (each kept open until the server closes,
    its OSErrors ignored); closed after."""
    import threading

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    srv.settimeout(0.2)
    stop = threading.Event()

    def serve():
        conns = []
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except OSError:
                continue
            conns.append(conn)
            with contextlib.suppress(OSError):
                answer(conn)
        for c in conns:
            c.close()

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    try:
        yield f"127.0.0.1:{srv.getsockname()[1]}"
    finally:
        stop.set()
        t.join(5)
        srv.close()


@contextlib.contextmanager
def http_like_server():
    """A tcp:// address on this machine where something that is not Dask
    answers, as a web server does: a 400 reply to whatever it is sent
    (read as a Dask message, its first bytes are a length of exabytes);
    closed after."""

    def answer(conn):
        conn.settimeout(5)
        conn.recv(4096)
        conn.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 11\r\n\r\nBad Request")
        conn.close()

    with _served(answer) as address:
        yield address


@contextlib.contextmanager
def web_server(directory):
    """Python's own web server (``python -m http.server``) on a free port of
    this machine, in a thread: it answers only a whole HTTP request, and
    stays silent until then; its "host:port", closed after."""
    import functools
    import http.server
    import threading

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):  # no line on stderr per request
            pass

    srv = http.server.ThreadingHTTPServer(
        ("127.0.0.1", 0), functools.partial(Quiet, directory=str(directory))
    )
    t = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True)
    t.start()
    try:
        yield f"127.0.0.1:{srv.server_address[1]}"
    finally:
        srv.shutdown()
        srv.server_close()
        t.join(5)


@contextlib.contextmanager
def banner_server(banner=b"SSH-2.0-OpenSSH_9.6\r\n"):
    """A tcp:// "host:port" on this machine where something that is not Dask
    speaks first, as an SSH server does (its banner, then silence until it
    is closed); closed after."""
    with _served(lambda conn: conn.sendall(banner)) as address:
        yield address
