"""Who may connect (issue 16, item 1; rrbc_viz.access): a real app server and raw websocket clients, as a hostile
page or script would connect. A refused connection is closed with 1008 before the server sends it anything."""

import asyncio

import pytest
import websockets

from rrbc_viz.access import TOKEN_PATH_PREFIX, allowed, page_url
from rrbc_viz.app import serve

PROTOCOL = "viser-v1.1.1"


def _try(port: int, path: str, origin: str | None, host: str | None = None):
    """Connect, wait for the first message or the close. Returns ("message", None) or ("closed", code)."""

    async def go():
        headers = {}
        if origin is not None:
            headers["Origin"] = origin
        async with websockets.connect(
            f"ws://127.0.0.1:{port}{path}",
            subprotocols=[PROTOCOL],
            additional_headers=headers,
            origin=None,
            open_timeout=10,
        ) as ws:
            try:
                await asyncio.wait_for(ws.recv(), timeout=10)
                return "message", None
            except websockets.exceptions.ConnectionClosed as e:
                return "closed", e.rcvd.code if e.rcvd else None

    return asyncio.run(go())


@pytest.fixture
def tokened():
    a = serve(port=0)
    try:
        yield a
    finally:
        a.stop()


def test_a_foreign_page_is_refused_even_with_the_token(tokened):
    path = TOKEN_PATH_PREFIX + tokened.guard.token
    assert _try(tokened.port, path, "http://evil.example") == ("closed", 1008)
    assert tokened.guard.refusals == 1


def test_no_token_or_a_wrong_one_is_refused(tokened):
    own = f"http://127.0.0.1:{tokened.port}"
    assert _try(tokened.port, "/", own) == ("closed", 1008)
    assert _try(tokened.port, TOKEN_PATH_PREFIX + "x" * len(tokened.guard.token), own) == ("closed", 1008)
    assert _try(tokened.port, "/", None) == ("closed", 1008)  # a script without Origin


def test_the_served_page_with_the_token_gets_the_app(tokened):
    own = f"http://127.0.0.1:{tokened.port}"
    assert _try(tokened.port, TOKEN_PATH_PREFIX + tokened.guard.token, own) == ("message", None)
    assert tokened.guard.refusals == 0


def test_no_token_mode_still_refuses_foreign_pages():
    a = serve(port=0, token=None)
    try:
        assert a.url == f"http://127.0.0.1:{a.port}"
        assert _try(a.port, "/", "http://evil.example") == ("closed", 1008)
        assert _try(a.port, "/", f"http://127.0.0.1:{a.port}") == ("message", None)
    finally:
        a.stop()


@pytest.mark.parametrize(
    "origin, host, path, token, ok",
    [
        ("http://127.0.0.1:8080", "127.0.0.1:8080", "/rrbc-abc", "abc", True),
        ("http://localhost:8080", "localhost:8080", "/rrbc-abc/", "abc", True),
        ("http://127.0.0.1:8081", "127.0.0.1:8080", "/rrbc-abc", "abc", False),  # another local port
        ("null", "127.0.0.1:8080", "/rrbc-abc", "abc", False),  # sandboxed iframe / file://
        ("file://", "127.0.0.1:8080", "/rrbc-abc", "abc", False),
        (None, "127.0.0.1:8080", "/rrbc-abd", "abc", False),
        (None, "127.0.0.1:8080", "/rrbc-abc", "abc", True),
        ("http://127.0.0.1:8080", "127.0.0.1:8080", "/", None, True),
    ],
)
def test_the_rule(origin, host, path, token, ok):
    assert allowed(origin, host, path, token)[0] is ok


def test_page_url_carries_the_websocket_address_with_the_token():
    assert page_url("http://127.0.0.1:8080", "tok") == (
        "http://127.0.0.1:8080/?websocket=ws%3A%2F%2F127.0.0.1%3A8080%2Frrbc-tok"
    )
    assert page_url("http://127.0.0.1:8080", None) == "http://127.0.0.1:8080"
