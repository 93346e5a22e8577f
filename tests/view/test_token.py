"""The viewer's access rules: loopback needs no token, any other host gets
one, and the page and the socket refuse requests without it."""

import json
import urllib.error
import urllib.request

import numpy as np
import pytest

pytest.importorskip("tornado", reason="the view extra (tornado) is not installed")

from clvis.view import PointScene, ViewServer, needs_token, token_ok  # noqa: E402
from clvis.view.server import access_token  # noqa: E402


def test_token_check():
    assert token_ok(None, None) and token_ok(None, "anything")
    assert token_ok("s3cret", "s3cret")
    for bad in (None, "", "s3cre", "s3cret ", "S3CRET", 123):
        assert not token_ok("s3cret", bad)
    assert not needs_token("127.0.0.1") and not needs_token("localhost") and not needs_token("::1")
    assert not needs_token("127.0.0.2") and not needs_token("[::1]")
    assert needs_token("0.0.0.0") and needs_token("192.168.1.10") and needs_token("myhost.example")


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(1)
    return PointScene(rng.random((1000, 3)).astype(np.float32), description="test points")


def _get(url):
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def test_loopback_serves_without_token(scene):
    s = ViewServer(scene)
    try:
        assert s.token is None and s.url == f"http://127.0.0.1:{s.port}/"
        status, body = _get(s.url)
        assert status == 200 and b"clvisView" in body
    finally:
        s.close()


def test_a_token_is_required_when_given(scene):
    # a token on loopback stands for the one another host gets (the test binds
    # loopback only: no port of this machine is opened to the network)
    s = ViewServer(scene, token="t0ken-for-test")
    try:
        assert s.url.endswith("/?token=t0ken-for-test")
        base = f"http://127.0.0.1:{s.port}/"
        assert _get(base)[0] == 403
        assert _get(base + "?token=wrong")[0] == 403
        assert _get(s.url)[0] == 200
        assert _get(base + "ws")[0] == 403  # the socket checks before the upgrade
    finally:
        s.close()


def test_socket_refuses_a_bad_token_and_accepts_the_right_one(scene):
    import asyncio

    import tornado.httpclient
    import tornado.websocket

    s = ViewServer(scene, token="abc")

    async def connect(query):
        return await tornado.websocket.websocket_connect(f"ws://127.0.0.1:{s.port}/ws{query}")

    try:
        with pytest.raises(tornado.httpclient.HTTPClientError) as e:
            asyncio.run(connect("?token=abd"))
        assert e.value.code == 403

        async def good():
            ws = await connect("?token=abc")
            msg = json.loads(await ws.read_message())
            ws.close()
            return msg

        msg = asyncio.run(good())
        assert msg["type"] == "config" and msg["kind"] == "points"
    finally:
        s.close()


def test_non_loopback_gets_a_random_token():
    a, b = access_token("0.0.0.0"), access_token("10.0.0.2")
    assert isinstance(a, str) and len(a) >= 20 and a != b
    assert access_token("127.0.0.1") is None and access_token("::1") is None
    assert access_token("0.0.0.0", "mine") == "mine"
