"""Malformed or hostile messages from a browser tab, dropped at the door (issue 31, item 4).

viser 1.1.1 decodes each websocket message a client sends and hands it on; a message that does not decode ends the
connection with a traceback in the log, and one that decodes with wrongly typed fields fails later in a task, with
another traceback. A script sending garbage in a loop filled the log (525 tracebacks) and the memory. Here every
incoming message is checked before viser sees it: it must decode, name a message type the client may send, and
carry fields of that type's declared types (`msgspec.convert` against viser's own message dataclass). A message
that fails is dropped without a traceback; a client's drops are logged at most once per `LOG_INTERVAL_S` (one line,
with how many were dropped and the first reason), and a client that sends more than `MAX_BAD` of them within
`WINDOW_S` is disconnected (close code 1008). The check replaces viser's message consumer
(`viser.infra._infra._message_consumer`, pinned version; the tests drive a real server with raw websocket clients,
so a change there fails loudly), installed once per process by `install`.

Well-formed messages can still carry hostile values: a GUI update naming a property the widget does not have, or a
value of another type ("abc" for a slider), a NaN or infinity, a number outside the widget's range, a dropdown
choice it does not offer. viser 1.1.1 casts such values with an assertion or `float("abc")` (a traceback per
message) or passes them on to the app's callbacks. `check_gui_update` checks each against the widget's own state
first (`GuiApi._handle_gui_updates` is wrapped by `install`); a refused update is dropped and counted like a
malformed message. Clients are counted by their address, not per connection, so a reconnecting client's drops are
logged once per `LOG_INTERVAL_S` too.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import threading
import time
import typing
import warnings
from collections.abc import Callable

import msgspec

#: A client's malformed messages are logged at most once in this many seconds.
LOG_INTERVAL_S = 60.0
#: More than this many malformed messages within `WINDOW_S` seconds and the client is disconnected.
MAX_BAD = 20
WINDOW_S = 60.0

_lock = threading.Lock()
_installed = False
_validators: dict[type, type] = {}


@dataclasses.dataclass
class _Client:
    unlogged: int = 0
    first_reason: str = ""
    last_log: float = -1e18


_clients: dict[object, _Client] = {}  # per client address: its drops not yet logged and when it was last logged
_floods: dict[object, list] = {}  # per connection: when its malformed messages came (time.monotonic), last WINDOW_S
stats = {"dropped": 0, "disconnected": 0, "logged": 0}


def _validator(cls: type) -> type:
    """A plain dataclass with the init fields of viser message class `cls` and their types, for msgspec.convert
    (viser's own classes carry non-init fields msgspec would refuse)."""
    v = _validators.get(cls)
    if v is None:
        hints = typing.get_type_hints(cls)
        fields = [
            (f.name, hints[f.name], dataclasses.field(default=f.default))
            if f.default is not dataclasses.MISSING
            else (f.name, hints[f.name])
            for f in dataclasses.fields(cls)
            if f.init
        ]
        v = dataclasses.make_dataclass(f"Check{cls.__name__}", fields)
        _validators[cls] = v
    return v


def check(raw, message_class) -> tuple[object | None, str]:
    """(the message, "") if `raw` is a well-formed client message of viser's protocol, else (None, why)."""
    if not isinstance(raw, bytes):
        return None, "a text frame"
    try:
        mapping = msgspec.msgpack.decode(raw)
    except Exception as exc:  # noqa: BLE001 - any decode failure is a malformed message
        return None, f"not MessagePack ({type(exc).__name__})"
    if not isinstance(mapping, dict) or not isinstance(mapping.get("type"), str):
        return None, "no message type"
    cls = message_class._subclass_from_type_string().get(mapping["type"])
    if cls is None:
        return None, f"unknown message type {mapping['type'][:40]!r}"
    body = {k: v for k, v in mapping.items() if k != "type"}
    try:
        msgspec.convert(body, type=_validator(cls), strict=False)
        return message_class.deserialize(raw), ""
    except Exception as exc:  # noqa: BLE001 - wrongly typed or missing fields
        return None, f"{mapping['type'][:40]}: {' '.join(str(exc).split())[:120]}"


#: The longest text a GUI update may carry (a text field; file names come by other messages).
MAX_TEXT = 10_000


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(float(x))


def check_gui_update(state, updates: dict) -> str:
    """Why the GUI `updates` {property: value} a client sent for a widget whose state (viser's props) is `state`
    must be refused ("" when they may go on): only `value` may be sent; its type is the widget's (numbers finite,
    within `min`/`max` where the widget has them; a dropdown's value one of its options; text at most MAX_TEXT
    characters)."""
    props = getattr(state, "props", state)  # viser keeps min, max and options in the widget's props
    for name, value in updates.items():
        if name != "value" or not hasattr(state, "value"):
            return f"GUI update of a property a client may not set ({str(name)[:40]!r})"
        current = state.value
        # a button's value is true/false; a button group's (also a "button" to viser) is the text of one of its
        # options, checked below with the other texts
        if isinstance(current, bool) or (getattr(state, "is_button", False) and not isinstance(current, str)):
            if not isinstance(value, bool):
                return "GUI update: not a true/false value"
        elif isinstance(current, (int, float)):
            if not _finite(value):
                return f"GUI update: not a finite number ({str(value)[:40]!r})"
            lo, hi = getattr(props, "min", None), getattr(props, "max", None)
            tol = abs(float(getattr(props, "step", None) or 0.0)) + 1e-9 * (abs(lo or 0.0) + abs(hi or 0.0) + 1.0)
            if (lo is not None and value < lo - tol) or (hi is not None and value > hi + tol):  # a step's rounding
                return f"GUI update: {value!r} outside the widget's range"
        elif isinstance(current, tuple):
            if not isinstance(value, (list, tuple)) or len(value) != len(current):
                return "GUI update: not a list of the widget's length"
            if current and not isinstance(current[0], str) and not all(_finite(v) for v in value):
                return "GUI update: not finite numbers"
            if current and isinstance(current[0], str) and not all(isinstance(v, str) for v in value):
                return "GUI update: not texts"
        elif isinstance(current, str):
            if not isinstance(value, str) or len(value) > MAX_TEXT:
                return "GUI update: not a text of at most 10,000 characters"
            options = getattr(props, "options", None)
            if options is not None and value not in options:
                return f"GUI update: {value[:40]!r} is not one of the widget's options"
    return ""


def note_bad(client_key: object, why: str, log: Callable[[str], object] | None = None, connection=None) -> bool:
    """Count a malformed message of a client (`client_key`: its address); log at most once per LOG_INTERVAL_S per
    address. True when the `connection` (default: the client) has sent too many within WINDOW_S (disconnect it: a
    tab's flood never closes another tab from the same address)."""
    now = time.monotonic()
    conn = client_key if connection is None else connection
    with _lock:
        if len(_clients) > 1000:  # forget addresses quiet for longer than both intervals (a bounded table)
            for k in [k for k, v in _clients.items() if now - v.last_log > 2 * max(WINDOW_S, LOG_INTERVAL_S)]:
                del _clients[k]
        c = _clients.setdefault(client_key, _Client())
        times = [t for t in _floods.get(conn, []) if now - t < WINDOW_S] + [now]
        _floods[conn] = times
        c.unlogged += 1
        c.first_reason = c.first_reason or why
        stats["dropped"] += 1
        line = None
        if now - c.last_log >= LOG_INTERVAL_S:
            line = f"rrbc view: dropped {c.unlogged} malformed message(s) from a client ({c.first_reason})"
            c.last_log, c.unlogged, c.first_reason = now, 0, ""
            stats["logged"] += 1
        too_many = len(times) > MAX_BAD
        if too_many:
            stats["disconnected"] += 1
    if line is not None:
        (log or (lambda s: print(s, file=sys.stderr, flush=True)))(line)
    return too_many


def forget(key: object) -> None:
    """Forget a connection's (or a client's) counts."""
    with _lock:
        _clients.pop(key, None)
        _floods.pop(key, None)


def _client_key(websocket) -> object:
    """A client's address (its drops counted across reconnections), the connection itself when it has none."""
    try:
        return str(websocket.remote_address[0])
    except Exception:  # noqa: BLE001 - any transport without an address
        return id(websocket)


async def _guarded_consumer(websocket, handle_message, message_class) -> None:
    """viser's message consumer with the check (module docstring)."""
    key = _client_key(websocket)
    try:
        while True:
            raw = await websocket.recv()
            message, why = check(raw, message_class)
            if message is None:
                if note_bad(key, why, connection=id(websocket)):
                    await websocket.close(1008, "too many malformed messages")
                    return
                continue
            handle_message(message)
    finally:
        with _lock:  # the connection's flood count goes with it; its address's log line outlives it
            _floods.pop(id(websocket), None)


def install() -> None:
    """Replace viser's message consumer by the guarded one (once per process)."""
    global _installed
    with _lock:
        if _installed:
            return
        from viser import _gui_api
        from viser.infra import _infra

        _infra._message_consumer = _guarded_consumer
        handle_updates = _gui_api.GuiApi._handle_gui_updates

        async def _checked_updates(self, client_id, message) -> None:  # registered by each GuiApi made after this
            handle = self._gui_input_handle_from_uuid.get(message.uuid, None)
            if handle is not None and not handle._impl.removed:
                why = check_gui_update(handle._impl, dict(message.updates))
                if why:
                    note_bad("gui", why)  # counted and logged, never a reason to close a tab
                    return
            await handle_updates(self, client_id, message)

        _gui_api.GuiApi._handle_gui_updates = _checked_updates  # type: ignore[method-assign]
        # viser warns (once per tab) when a message is queued for a tab that has gone or after the server stopped: a
        # drag or an update in flight when a tab closes or Ctrl+C comes. The message is dropped either way, and what
        # a tab does must not write to the log (issue 42)
        warnings.filterwarnings("ignore", message=r"Queued a \w+ on a closed connection", category=UserWarning)
        _installed = True
