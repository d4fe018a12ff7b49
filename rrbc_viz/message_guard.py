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
"""

from __future__ import annotations

import dataclasses
import sys
import threading
import time
import typing
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
    times: list = dataclasses.field(default_factory=list)  # when its malformed messages came (time.monotonic)
    unlogged: int = 0
    first_reason: str = ""
    last_log: float = -1e18


_clients: dict[int, _Client] = {}
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


def note_bad(client_key: int, why: str, log: Callable[[str], object] | None = None) -> bool:
    """Count a malformed message of a client; log at most once per LOG_INTERVAL_S. True when the client has sent
    too many (disconnect it)."""
    now = time.monotonic()
    with _lock:
        c = _clients.setdefault(client_key, _Client())
        c.times = [t for t in c.times if now - t < WINDOW_S] + [now]
        c.unlogged += 1
        c.first_reason = c.first_reason or why
        stats["dropped"] += 1
        line = None
        if now - c.last_log >= LOG_INTERVAL_S:
            line = f"rrbc view: dropped {c.unlogged} malformed message(s) from a client ({c.first_reason})"
            c.last_log, c.unlogged, c.first_reason = now, 0, ""
            stats["logged"] += 1
        too_many = len(c.times) > MAX_BAD
        if too_many:
            stats["disconnected"] += 1
    if line is not None:
        (log or (lambda s: print(s, file=sys.stderr, flush=True)))(line)
    return too_many


def forget(client_key: int) -> None:
    with _lock:
        _clients.pop(client_key, None)


async def _guarded_consumer(websocket, handle_message, message_class) -> None:
    """viser's message consumer with the check (module docstring)."""
    key = id(websocket)
    try:
        while True:
            raw = await websocket.recv()
            message, why = check(raw, message_class)
            if message is None:
                if note_bad(key, why):
                    await websocket.close(1008, "too many malformed messages")
                    return
                continue
            handle_message(message)
    finally:
        forget(key)


def install() -> None:
    """Replace viser's message consumer by the guarded one (once per process)."""
    global _installed
    with _lock:
        if _installed:
            return
        from viser.infra import _infra

        _infra._message_consumer = _guarded_consumer
        _installed = True
