"""Who may connect to the app (issue 16): only pages this server served, and only with the run's token.

A web page from any other site can open a websocket to a local port; without a check it could drive the app and
read what it shows. Two checks on every websocket handshake, before any message is sent:

- **Origin.** A browser names the page's origin in the handshake. It must be this server itself (the same host
  and port as the handshake's Host header). Non-browser clients send no Origin; they must present the token.
- **Token** (the Jupyter convention). `rrbc view` prints a URL carrying a random per-run token; the page opens its
  websocket at the path ``/rrbc-<token>`` (viser's client takes the websocket address from the ``websocket`` URL
  parameter). A connection without it is refused. `--no-token` turns this off for trusted setups (the Origin
  check stays).
- **Host allow-list** (as Jupyter keeps one, against DNS rebinding: a page from evil.example whose name is made to
  resolve to 127.0.0.1 sends ``Host: evil.example:PORT`` and its own matching Origin). The handshake's Host name must
  be a localhost name, an IP address literal (rebinding needs a name) or a name given with ``rrbc view
  --allow-host NAME``; checked with and without the token.
- A handshake with more than one Host or Origin header is refused (never read as either value).

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


#: Host names always allowed (besides IP address literals and `--allow-host` names)
LOCAL_NAMES = frozenset({"localhost", "localhost.localdomain", "ip6-localhost", "ip6-loopback"})


def host_name(host: str) -> str:
    """The name part of a Host header value (no port; an IPv6 literal without its brackets), lower case."""
    h = host.strip().lower()
    if h.startswith("["):
        return h[1 : h.find("]")] if "]" in h else h[1:]
    return h.rsplit(":", 1)[0] if h.count(":") == 1 else h


def host_allowed(host: str, extra: frozenset[str] = frozenset()) -> bool:
    """Whether a Host header names this machine in a way no other site can (module docstring): a localhost name, an
    IP address literal, or one of `extra` (lower case)."""
    import ipaddress

    name = host_name(host)
    if name in LOCAL_NAMES or name in extra:
        return True
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def allowed(
    origin: str | None, host: str | None, path: str, token: str | None, hosts: frozenset[str] = frozenset()
) -> tuple[bool, str]:
    """Whether a websocket handshake may proceed: (ok, reason when not). `origin`, `host`: the Origin and Host
    headers (None when absent); `path`: the request path; `token`: the run's token (None: no token required);
    `hosts`: names allowed besides localhost names and IP literals (`--allow-host`)."""
    if host is not None and not host_allowed(host, hosts):
        return False, "this server answers only to localhost, IP addresses and --allow-host names (Host refused)"
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


#: The page's render scale, given in the URL it opens (viser's client reads ``fixedDpr``): one canvas pixel per CSS
#: pixel. The server frames views beside the control panel, whose width is in CSS pixels, from the canvas's width in
#: its own pixels (`ClientHandle.camera.image_width`); viser's adaptive scale (0.75-1 of the screen's pixel ratio,
#: lowered while frames are slow) and high-density screens (2 canvas pixels per CSS pixel) would make that share
#: wrong: views squeezed to the left, or points under the panel. Drawing costs less for it; a high-density screen
#: shows the 3-D view at half its resolution.
RENDER_SCALE_PARAM = "fixedDpr=1"


def page_url(base_url: str, token: str | None) -> str:
    """The URL to open: `base_url` (http://host:port) with the websocket address carrying the token and the render
    scale (`RENDER_SCALE_PARAM`)."""
    base = base_url.rstrip("/")
    if token is None:
        return f"{base}/?{RENDER_SCALE_PARAM}"
    ws = "ws" + base[len("http") :] + TOKEN_PATH_PREFIX + token
    return f"{base}/?websocket={quote(ws, safe='')}&{RENDER_SCALE_PARAM}"


class AccessGuard:
    """Checks every websocket handshake of a viser server (module docstring). `refused`: the client ids closed."""

    def __init__(self, server: viser.ViserServer, token: str | None, hosts=()):
        self.token = token
        self.hosts = frozenset(str(h).strip().lower() for h in hosts)
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
        values = {name: req.headers.get_all(name) for name in ("Origin", "Host")}
        if any(len(v) > 1 for v in values.values()):
            ok, why = False, "a handshake with more than one Host or Origin header is refused"
        else:
            origin, host = (v[0] if v else None for v in values.values())
            ok, why = allowed(origin, host, req.path, self.token, self.hosts)
        if not ok:
            self.refused.add(int(conn.client_id))
            self.refusals += 1
            await ws.close(1008, why[:120])
