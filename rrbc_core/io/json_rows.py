"""JSON rows written from columns (issue 41, item 3): the text of many JSON objects of one shape (a corrected
point's row of `rrbc correct --json`) made from whole arrays, not from one dict per row.

A row is a list of `Field`s: a key and a value per row, taken from a column. Number columns (M,) or (M, ...) are
encoded by orjson in one call per column and cut into rows (a float is written as its shortest repr, NaN as
null); strings are escaped as `json.dumps` does (ASCII only: a non-ASCII character or DEL as \\uXXXX), so the text
is plain printable ASCII; booleans are `true` / `false`. A field can be left out of some rows (`present`) or be
null in some (`null`). `rows_text` gives `json.loads`-equal text to `json.dumps` of the same rows built as dicts
(tests/io/test_json_rows.py), about ten times faster.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import orjson

__all__ = ["Field", "rows_text", "number_texts", "string_texts"]


@dataclass(frozen=True)
class Field:
    """One key of every row: its values for M rows, `kind` "num" (a float array (M,) or (M, ...)), "bool" ((M,)),
    "str" (M strings) or "obj" ({name: (M,) floats}: a JSON object per row); `present` (M,) bool: the key only in
    those rows (default all); `null` (M,) bool: null in those rows (default none)."""

    key: str
    values: Any
    kind: str = "num"
    present: np.ndarray | None = None
    null: np.ndarray | None = None


def _number_parts(values: np.ndarray) -> tuple[list[bytes], bytes, bytes]:
    """Each row of a float array (M,) or (M, ...) as JSON text less its outer brackets, and those brackets (the
    opening and the closing ones; empty for (M,))."""
    a = np.ascontiguousarray(values, dtype=float)
    if len(a) == 0:
        return [], b"", b""
    text = orjson.dumps(a, option=orjson.OPT_SERIALIZE_NUMPY)[1:-1]  # the rows, joined by commas
    depth = a.ndim - 1
    if depth == 0:
        return text.split(b","), b"", b""
    # a row of depth d opens with d brackets and closes with d; between rows: d closing, a comma, d opening
    inner = text[depth:-depth].split(b"]" * depth + b"," + b"[" * depth)
    return inner, b"[" * depth, b"]" * depth


def number_texts(values: np.ndarray) -> list[bytes]:
    """Each row of a float array (M,) or (M, ...) as JSON text (nested lists for more dimensions; NaN null)."""
    inner, opening, closing = _number_parts(values)
    return [opening + row + closing for row in inner] if opening else inner


#: what a string may hold to be written as it is between quotes: printable ASCII but the quote and the backslash
_PLAIN = re.compile(r"[^ !#-\[\]-~]")


def _string_parts(values: Sequence[str]) -> tuple[list[bytes], bytes, bytes]:
    """Each string's JSON literal less its quotes, and the quotes (`string_texts`)."""
    values = list(values)
    joined = "\n".join(values)
    plain = joined.count("\n") == len(values) - 1 and not _PLAIN.search(joined.replace("\n", " "))
    if plain:  # printable ASCII without a quote or a backslash: the string itself
        return (joined.encode("ascii").split(b"\n") if values else []), b'"', b'"'
    return string_texts(values), b"", b""


def string_texts(values: Sequence[str]) -> list[bytes]:
    """Each string as a JSON string literal in printable ASCII (`json.dumps`'s escaping)."""
    out = [orjson.dumps(v) for v in values]
    joined = b"".join(out)
    if joined.isascii() and b"\x7f" not in joined:
        return out
    return [json.dumps(v).encode("ascii") for v in values]  # non-ASCII or DEL: escaped as \uXXXX


def _literal(key: str) -> bytes:
    """A key as a JSON string in a %-template (a % doubled)."""
    return string_texts([key])[0].replace(b"%", b"%%")


_TRUE_FALSE = np.array([b"false", b"true"], dtype=object)


def _parts(field: Field, n: int) -> tuple[list[bytes], bytes, bytes]:
    """The field's values as JSON texts less what every one of them opens and closes with, and that."""
    if field.kind == "num":
        return _number_parts(field.values)
    if field.kind == "bool":
        return _TRUE_FALSE[np.asarray(field.values, bool).astype(np.intp)].tolist(), b"", b""
    if field.kind == "str":
        return _string_parts(field.values)
    if field.kind == "obj":
        obj: Mapping[str, np.ndarray] = field.values
        if not obj:
            return [b""] * n, b"{", b"}"
        template = b",".join(_literal(k) + b":%b" for k in obj)
        return [template % t for t in zip(*(number_texts(v) for v in obj.values()))], b"{", b"}"
    raise ValueError(f"unknown field kind {field.kind!r}")


def rows_text(fields: Sequence[Field], n: int) -> bytes:
    """The n rows as JSON objects joined by commas (no brackets; empty for none), keys in the fields' order:
    printable ASCII bytes."""
    if n == 0:
        return b""
    template = [b"{"]
    columns: list[list[bytes]] = []
    first = True
    for f in fields:
        present = None if f.present is None else np.asarray(f.present, bool)
        if present is not None and not present.any():
            continue  # in no row
        texts, opening, closing = _parts(f, n)
        if len(texts) != n:
            raise ValueError(f"field {f.key!r} has {len(texts)} values for {n} rows")
        key = _literal(f.key) + b":"
        lead = b"" if first else b","
        null = None if f.null is None else np.asarray(f.null, bool)
        if null is not None and null.any():  # the value whole, or null (elementwise on an object array: in C)
            valued = np.empty(len(texts), dtype=object)
            valued[:] = texts
            if opening or closing:
                valued = opening + valued + closing
            valued[null] = b"null"
            texts = valued.tolist()
            opening = closing = b""
        if present is None or present.all():
            template.append(lead + key + opening.replace(b"%", b"%%") + b"%b" + closing.replace(b"%", b"%%"))
            first = False
        else:  # the key and its comma only where present (a field that may be absent is never the first)
            if first:
                raise ValueError("the first field of a row cannot be optional")
            whole = lead + key + opening
            texts = [whole + t + closing if p else b"" for t, p in zip(texts, present.tolist())]
            template.append(b"%b")
        columns.append(texts)
    template.append(b"}")
    row = b"".join(template)
    return b",".join([row % t for t in zip(*columns)])
