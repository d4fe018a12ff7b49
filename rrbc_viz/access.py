"""Who may connect to the app (issue 16): only pages this server served, and only with the run's token.

A web page from any other site can open a websocket to a local port; without a check it could drive the app and
read what it shows. Two checks on every websocket handshake, before any message is sent:

- **Origin.** A browser names the page's origin in the handshake. It must be this server itself (the same host
  and port as the handshake's Host header). Non-browser clients send no Origin; they must present the token.
- **Token** (the Jupyter convention). `rrbc view` prints a URL carrying a random per-run token; the page opens its
  websocket at the path ``/rrbc-<token>`` (viser's client takes the websocket address from the ``websocket`` URL
  parameter). A connection without it is refused. `--no-token` turns this off for trusted setups (the Origin
  check stays).

A refused connection is closed with code 1008 (policy violation) before viser sends it anything; its client id is
remembered so the app's per-client callbacks skip it. viser 1.1.1 has no public hook for the handshake: the check
is the first of its websocket server's connect callbacks (`ViserServer._websock_server`, pinned version; the
tests drive a real server with raw websocket clients so a change there fails loudly).
"""

from __future__ import annotations

import secrets
from urllib.parse import quote, urlsplit

import viser

TOKEN_PATH_PREFIX = "/rrbc-"


def new_token() -> str:
    """A fresh random token (32 URL-safe characters, 192 bits)."""
    return secrets.token_urlsafe(24)


def allowed(origin: str | None, host: str | None, path: str, token: str | None) -> tuple[bool, str]:
    """Whether a websocket handshake may proceed: (ok, reason when not). `origin`, `host`: the Origin and Host
    headers (None when absent); `path`: the request path; `token`: the run's token (None: no token required)."""
    if origin is not None:
        o = urlsplit(origin)
        if o.scheme not in ("http", "https") or not host or o.netloc.lower() != host.strip().lower():
            return False, "connections are accepted only from pages this server served (Origin mismatch)"
    if token is not None:
        wanted = TOKEN_PATH_PREFIX + token
        given = path.partition("?")[0].rstrip("/")
        if not secrets.compare_digest(given.encode(), wanted.encode()):
            return False, "a valid token is required: open the URL `rrbc view` printed"
    elif origin is None and host is None:
        return False, "no Host header"
    return True, ""


def page_url(base_url: str, token: str | None) -> str:
    """The URL to open: `base_url` (http://host:port) with the websocket address carrying the token."""
    base = base_url.rstrip("/")
    if token is None:
        return base
    ws = "ws" + base[len("http") :] + TOKEN_PATH_PREFIX + token
    return f"{base}/?websocket={quote(ws, safe='')}"


class AccessGuard:
    """Checks every websocket handshake of a viser server (module docstring). `refused`: the client ids closed."""

    def __init__(self, server: viser.ViserServer, token: str | None):
        self.token = token
        self.refused: set[int] = set()
        self.refusals = 0
        self._infra = server._websock_server  # viser 1.1.1: its websocket server (no public handshake hook)
        self._infra._client_connect_cb.insert(0, self._check)

    def is_refused(self, client_id: int) -> bool:
        return int(client_id) in self.refused

    async def _check(self, conn) -> None:
        ws = self._infra._live_connections.get(conn.client_id)
        if ws is None:
            return
        req = ws.request
        if req is None:
            return
        ok, why = allowed(req.headers.get("Origin"), req.headers.get("Host"), req.path, self.token)
        if not ok:
            self.refused.add(int(conn.client_id))
            self.refusals += 1
            await ws.close(1008, why[:120])
