"""Who may connect (issue 16, item 1; rrbc_viz.access): a real app server and raw websocket clients, as a hostile
page or script would connect. A refused connection is closed with 1008 before the server sends it anything."""

import asyncio
import concurrent.futures

import pytest
import websockets

from rrbc_viz.access import TOKEN_PATH_PREFIX, allowed, page_url
from rrbc_viz.serve import serve

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

    # in a thread of its own: another test's event loop (Playwright's sync API) may be running in this one
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, go()).result(timeout=30)


@pytest.fixture
def tokened(app):
    """The default app (conftest's `app`: serve(port=0) carries a fresh token)."""
    return app


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
        assert a.url == f"http://127.0.0.1:{a.port}/?fixedDpr=1"
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
        # DNS rebinding: a page from a name made to resolve here, its Origin matching its Host (issue 42, item 3)
        ("http://evil.example:8080", "evil.example:8080", "/rrbc-abc", "abc", False),
        ("http://evil.example:8080", "evil.example:8080", "/", None, False),
        (None, "evil.example:8080", "/", None, False),
        ("http://[::1]:8080", "[::1]:8080", "/", None, True),  # IP literals cannot be rebound
        ("http://192.168.1.20:8080", "192.168.1.20:8080", "/", None, True),
        ("http://LOCALHOST:8080", "LOCALHOST:8080", "/", None, True),
    ],
)
def test_the_rule(origin, host, path, token, ok):
    assert allowed(origin, host, path, token)[0] is ok


def test_an_allowed_name_is_accepted_and_only_it():
    assert allowed("http://lab-pc:8080", "lab-pc:8080", "/", None, frozenset({"lab-pc"}))[0]
    assert not allowed("http://lab-pc2:8080", "lab-pc2:8080", "/", None, frozenset({"lab-pc"}))[0]


def _raw_handshake(port: int, path: str, headers: list[tuple[str, str]]) -> bytes:
    """A websocket handshake written by hand (a client library would not send a header twice): the reply's start."""
    import socket

    base = [
        ("Upgrade", "websocket"),
        ("Connection", "Upgrade"),
        ("Sec-WebSocket-Key", "dGhlIHNhbXBsZSBub25jZQ=="),
        ("Sec-WebSocket-Version", "13"),
        ("Sec-WebSocket-Protocol", PROTOCOL),
    ]
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall((f"GET {path} HTTP/1.1\r\n" + "".join(f"{k}: {v}\r\n" for k, v in headers + base) + "\r\n").encode())
        data = b""
        while b"\r\n\r\n" not in data:
            chunk = s.recv(4096)
            if not chunk:
                break
            data += chunk
        try:  # what follows the upgrade: the close frame of a refused connection (or the app's first message)
            s.settimeout(5)
            data += s.recv(4096)
        except OSError:
            pass
        return data


@pytest.mark.parametrize("twice", ["Host", "Origin"])
def test_a_handshake_with_a_header_twice_is_refused_without_a_traceback(tokened, twice, caplog):
    """Issue 42, item 2: two Host (or Origin) headers, one of them this server's: refused (400, or closed with 1008
    before anything is sent), never read as either value, and nothing is logged with a traceback."""
    import logging
    import struct

    caplog.set_level(logging.INFO)
    own_host, own_origin = f"127.0.0.1:{tokened.port}", f"http://127.0.0.1:{tokened.port}"
    headers = [("Host", own_host), ("Origin", own_origin)]
    headers.append(("Host", "evil.example") if twice == "Host" else ("Origin", "http://evil.example"))
    reply = _raw_handshake(tokened.port, TOKEN_PATH_PREFIX + tokened.guard.token, headers)
    status = reply.split(b"\r\n", 1)[0]
    if b" 101 " in status:  # upgraded, then closed by the guard with 1008 as its first frame
        frame = reply.split(b"\r\n\r\n", 1)[1]
        assert frame[:1] == b"\x88" and struct.unpack(">H", frame[2:4])[0] == 1008, reply
    else:
        assert b" 400 " in status, reply
    assert not any(r.exc_info for r in caplog.records), [r.getMessage() for r in caplog.records if r.exc_info]
    ok = _try(tokened.port, TOKEN_PATH_PREFIX + tokened.guard.token, own_origin)  # the app still answers its page
    assert ok == ("message", None)


def test_page_url_carries_the_websocket_address_with_the_token_and_one_canvas_pixel_per_css_pixel():
    assert page_url("http://127.0.0.1:8080", "tok") == (
        "http://127.0.0.1:8080/?websocket=ws%3A%2F%2F127.0.0.1%3A8080%2Frrbc-tok&fixedDpr=1"
    )
    assert page_url("http://127.0.0.1:8080", None) == "http://127.0.0.1:8080/?fixedDpr=1"


# ------------------------------------------------------------------------- files: no free-text server path
def test_the_file_tab_offers_only_the_offered_folders_and_opens_by_label(tmp_path):
    import os

    from tests.paths import EXAMPLE_CSV

    data = tmp_path / "data"
    data.mkdir()
    (data / "mine.csv").write_bytes(EXAMPLE_CSV.read_bytes())
    (data / "notes.txt").write_text("not offered", encoding="utf-8")
    outside = tmp_path / "secret.csv"
    outside.write_bytes(EXAMPLE_CSV.read_bytes())
    os.symlink(outside, data / "link.csv")  # a link out of the folder is not offered
    a = serve(port=0, data_dirs=[data])
    try:
        offered = a.controls.file.path.options
        assert "scenes/demo_workcell.toml" in offered and "data/mine.csv" in offered
        assert not any("secret" in o or "link" in o or "notes" in o for o in offered)
        assert "scenes/meshes/demo_workcell.glb" in a.controls.file.mesh_path.options
        assert a.files.load_offered("data/mine.csv") is True and a.session.kind == "measurements"
        assert a.files.load_offered(str(outside)) is False and "not one of the files offered" in a.last_message
        assert a.files.load_offered("data/../secret.csv") is False
        # a file added later shows after a rescan
        (data / "later.csv").write_bytes(EXAMPLE_CSV.read_bytes())
        a.files.rescan_files()
        assert "data/later.csv" in a.controls.file.path.options
    finally:
        a.stop()


def test_a_data_folder_that_is_not_a_directory_is_refused_before_serving(tmp_path):
    from rrbc_core.errors import InputError

    with pytest.raises(InputError, match="not a directory"):
        serve(port=0, data_dirs=[tmp_path / "missing"])
