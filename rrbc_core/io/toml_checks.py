"""Reading a TOML document with one-line errors that name the file, the key and the line (`Checker`,
`read_toml`): what the scene reader (`scene_toml`) reports a bad scene file with."""

from __future__ import annotations

import math
import os
import re
import tomllib

import numpy as np

from rrbc_core.errors import InputError


def fmt_value(v, limit: int = 80) -> str:
    """A TOML-like rendering of a value for error messages."""

    def r(x):
        if isinstance(x, bool):
            return "true" if x else "false"
        if isinstance(x, str):
            return '"' + x.replace('"', '\\"') + '"'
        if isinstance(x, float):
            if math.isnan(x):
                return "nan"
            if math.isinf(x):
                return "inf" if x > 0 else "-inf"
            return repr(x)
        if isinstance(x, (list, tuple)):
            return "[" + ", ".join(r(e) for e in x) + "]"
        if isinstance(x, dict):
            return "{" + ", ".join(f"{k} = {r(e)}" for k, e in x.items()) + "}"
        return str(x)

    s = r(v)
    return s if len(s) <= limit else s[: limit - 3] + "..."


def is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


class Checker:
    """Builds one-line errors `<file>: <key>: <what>` and validates TOML values."""

    def __init__(self, source: str):
        self.source = source

    def error(self, key: str, what: str) -> InputError:
        what = " ".join(str(what).split())  # one line, whatever the cause said
        return InputError(f"{self.source}: {key}: {what}" if key else f"{self.source}: {what}")

    def table(self, v, key: str) -> dict:
        if not isinstance(v, dict):
            raise self.error(key, f"must be a table, got {fmt_value(v)}")
        return v

    def keys(self, d: dict, key: str, allowed, required=(), where: str | None = None) -> None:
        allowed = tuple(allowed)
        for k in d:
            if k not in allowed:
                where = where or (f"[{key}]" if key else "the top level")
                raise self.error(
                    f"{key}.{k}" if key else k,
                    f"unknown key; valid keys in {where}: {', '.join(allowed)}",
                )
        for k in required:
            if k not in d:
                raise self.error(f"{key}.{k}" if key else k, "missing required key")

    def string(self, v, key: str, choices=None, nonempty: bool = True) -> str:
        if not isinstance(v, str):
            raise self.error(key, f"must be a string, got {fmt_value(v)}")
        if nonempty and not v.strip():
            raise self.error(key, "must not be empty")
        if choices is not None and v not in choices:
            raise self.error(key, f"must be one of {', '.join(repr(c) for c in choices)}, got {fmt_value(v)}")
        return v

    def number(self, v, key: str, *, positive=False, nonneg=False) -> float:
        if not is_number(v):
            raise self.error(key, f"must be a number, got {fmt_value(v)}")
        x = float(v)
        if not math.isfinite(x) or abs(x) > VALUE_LIMIT:
            raise self.error(key, f"must be a finite number at most {VALUE_LIMIT:g} in size, got {fmt_value(v)}")
        if positive and not x > 0:
            raise self.error(key, f"must be a positive number, got {fmt_value(v)}")
        if nonneg and not x >= 0:
            raise self.error(key, f"must be a number >= 0, got {fmt_value(v)}")
        return x

    def integer(self, v, key: str, minimum=None, maximum=None) -> int:
        if isinstance(v, bool) or not (isinstance(v, int) or (isinstance(v, float) and v.is_integer())):
            raise self.error(key, f"must be an integer, got {fmt_value(v)}")
        i = int(v)
        if minimum is not None and i < minimum:
            raise self.error(key, f"must be an integer >= {minimum}, got {fmt_value(v)}")
        if maximum is not None and i > maximum:
            raise self.error(key, f"must be at most {maximum}, got {fmt_value(v)}")
        return i

    def vector(self, v, key: str, n: int = 3, *, positive=False, what=None) -> np.ndarray:
        desc = what or (f"{n} positive numbers" if positive else f"{n} finite numbers")
        ok = isinstance(v, list) and len(v) == n and all(is_number(e) for e in v)
        if ok:
            a = np.array([float(e) for e in v])
            ok = bool(np.all(np.isfinite(a)) and np.all(np.abs(a) <= VALUE_LIMIT)) and (
                not positive or bool(np.all(a > 0))
            )
        if not ok:
            raise self.error(key, f"must be {desc}, got {fmt_value(v)} (each at most {VALUE_LIMIT:g} in size)")
        return a

    def array_of_tables(self, v, key: str) -> list:
        if isinstance(v, dict):
            raise self.error(key, f"must be an array of tables ([[{key}]] blocks), got a single table [{key}]")
        if not isinstance(v, list) or not all(isinstance(e, dict) for e in v):
            raise self.error(key, f"must be an array of tables ([[{key}]] blocks), got {fmt_value(v)}")
        return v


# ------------------------------------------------------------------------------------------------------
# The loader
# ------------------------------------------------------------------------------------------------------
TOML_POS = re.compile(r"\s*\(at line (\d+), column (\d+)\)\s*$")


TOML_EOF = re.compile(r"\s*\(at end of document\)\s*$")


VALUE_LIMIT = 1e9  # every number in a scene is at most this in size (mm, degrees, s): larger is a slip
SCENE_FILE_LIMIT = 16 * 1024 * 1024  # bytes: a scene file larger than this is refused (shipped scenes: < 20 kB)


def read_toml(path, source: str, c: Checker) -> dict:
    try:
        if os.path.exists(path) and not os.path.isfile(path):
            raise c.error("", "not a regular file (a scene is a .toml file)")
        with open(path, "rb") as fh:
            data = fh.read(SCENE_FILE_LIMIT + 1)
    except OSError as exc:
        raise c.error("", f"cannot read the scene file: {exc.strerror or exc.__class__.__name__}") from None
    if len(data) > SCENE_FILE_LIMIT:
        raise c.error("", f"larger than {SCENE_FILE_LIMIT // (1024 * 1024)} MiB: not a scene file")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise c.error(f"line {line}", "not UTF-8 text; save the scene file as UTF-8") from None
    text = text.removeprefix("\ufeff")  # a byte-order mark (some editors write one) is not part of the TOML
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise c.error("", "TOML nested too deeply to read") from None
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = TOML_POS.search(msg)
        if m:
            raise c.error(f"line {m.group(1)}, column {m.group(2)}", f"TOML syntax error: {msg[: m.start()]}") from None
        m = TOML_EOF.search(msg)
        if m:
            raise c.error("end of file", f"TOML syntax error: {msg[: m.start()]}") from None
        raise c.error("", f"TOML syntax error: {msg}") from None
