"""JSON written as it is made: a result's long lists of rows (`LazyRows`) are encoded a batch at a time, so that
`rrbc correct --json` on a million rows never holds every row's object, nor the whole text, at once.

`json_chunks(obj)` yields compact JSON text of `obj` (no spaces after `,` and `:`; the same document as
`json.dumps(obj, allow_nan=False)`: `json.loads` gives equal values) in pieces of about `CHUNK_CHARS`
characters; a `LazyRows` inside it is a list whose rows are made while they are written, from columns where it
has its own encoder (`io.json_rows`). Anything else is encoded by `json.dumps` as it is.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Iterator
from typing import Any

CHUNK_CHARS = 1 << 20  # about 1 MB of text per piece written


class LazyRows:
    """A JSON list of `n` rows made by `make()` (a fresh iterator each time: the rows can be read more than once,
    as `rrbc correct --out` and `--json` both do). Iterating it makes the rows; `len` is known without them.
    `encoded()`, when given, yields the same rows' JSON text a batch at a time (ASCII bytes, rows joined by commas,
    no brackets; `io.json_rows`): what `json_bytes` writes instead of encoding the rows one by one."""

    def __init__(self, n: int, make: Callable[[], Iterable[Any]], encoded: Callable[[], Iterable[bytes]] | None = None):
        self.n = int(n)
        self._make = make
        self.encoded = encoded

    def __len__(self) -> int:
        return self.n

    def __iter__(self) -> Iterator[Any]:
        return iter(self._make())

    def __eq__(self, other: object) -> bool:  # compared as the list it stands for (tests)
        return list(self) == (list(other) if isinstance(other, (list, tuple, LazyRows)) else other)

    __hash__ = None  # type: ignore[assignment]


def _has_lazy(value: Any) -> bool:
    if isinstance(value, LazyRows):
        return True
    if isinstance(value, dict):
        return any(_has_lazy(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(isinstance(v, (dict, list, tuple, LazyRows)) and _has_lazy(v) for v in value)
    return False


ROWS_PER_DUMP = 1000  # rows encoded by one json.dumps call


class PrintableAscii(bytes):
    """Bytes known to hold printable ASCII only (what `json_bytes` yields): a terminal needs no check of them."""


def _dumps(value: Any) -> bytes:
    # ensure_ascii: ASCII, control characters escaped; DEL (ASCII, not escaped by json) too, as json_rows does
    return json.dumps(value, allow_nan=False, separators=(",", ":")).encode("ascii").replace(b"\x7f", b"\\u007f")


def _batches(rows: Iterable[Any]) -> Iterator[list]:
    """`rows` in lists of `ROWS_PER_DUMP` (none empty)."""
    batch: list = []
    for row in rows:
        batch.append(row)
        if len(batch) == ROWS_PER_DUMP:
            yield batch
            batch = []
    if batch:
        yield batch


def _pieces(value: Any) -> Iterator[bytes]:
    if isinstance(value, LazyRows):
        yield b"["
        first = True
        if value.encoded is not None:
            texts: Iterable[bytes] = value.encoded()
        else:
            texts = (_dumps(b)[1:-1] for b in _batches(value))
        for text in texts:  # a batch of rows at a time, without the list's brackets
            if text:
                yield (b"" if first else b",") + text
                first = False
        yield b"]"
    elif isinstance(value, dict) and _has_lazy(value):
        yield b"{"
        for i, (k, v) in enumerate(value.items()):
            yield (b"" if i == 0 else b",") + json.dumps(str(k)).encode("ascii") + b":"
            yield from _pieces(v)
        yield b"}"
    elif isinstance(value, (list, tuple)) and _has_lazy(value):
        yield b"["
        for i, v in enumerate(value):
            if i:
                yield b","
            yield from _pieces(v)
        yield b"]"
    else:
        yield _dumps(value)


def json_bytes(obj: Any) -> Iterator[PrintableAscii]:
    """The JSON text of `obj` (module docstring) as printable ASCII bytes, in pieces of about `CHUNK_CHARS`."""
    buf: list[bytes] = []
    size = 0
    for piece in _pieces(obj):
        buf.append(piece)
        size += len(piece)
        if size >= CHUNK_CHARS:
            yield PrintableAscii(b"".join(buf))
            buf, size = [], 0
    if buf:
        yield PrintableAscii(b"".join(buf))


def json_chunks(obj: Any) -> Iterator[str]:
    """The JSON text of `obj` (module docstring) in pieces of about `CHUNK_CHARS` characters (`json_bytes`)."""
    for piece in json_bytes(obj):
        yield piece.decode("ascii")


def to_plain(obj: Any) -> Any:
    """`obj` with every `LazyRows` made into the list it stands for (for callers that want plain JSON values)."""
    if isinstance(obj, LazyRows):
        return [to_plain(r) for r in obj]
    if isinstance(obj, dict):
        return {k: to_plain(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [to_plain(v) for v in obj]
    return obj
