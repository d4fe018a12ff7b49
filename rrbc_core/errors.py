"""The one exception type for bad input.

Every check on user-supplied data (files, command-line values, point sets handed to the library) raises
`InputError` with a message a user can act on. The command line turns it into one stderr line and exit code 2.
"""

import re


class InputError(ValueError):
    """Bad input: the message says what is wrong and, where it can, where and how to fix it."""


class Cancelled(Exception):
    """Work stopped before it finished because its caller said it was no longer wanted (a `should_stop` callable
    returned True between chunks). Not an error of the input: nothing is reported to the user as a failure."""


MESSAGE_LIMIT = 400  # characters of a message shown to a user (stderr line, app notification)


_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f]")
_CONTROL_BUT_LAYOUT = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def _hex(match: re.Match) -> str:
    return f"\\x{ord(match.group()):02x}"


def one_line(text: str, limit: int = MESSAGE_LIMIT) -> str:
    """`text` as one safe line for a terminal or a page: whitespace runs collapsed, control characters (NUL, ANSI
    escapes, DEL, C1) shown as \\xNN instead of acting, at most `limit` characters (then "…")."""
    s = _CONTROL.sub(_hex, " ".join(str(text).split()))
    return s if len(s) <= limit else s[: limit - 1] + "…"


def excerpt(text: str, limit: int = 40) -> str:
    """A short, safe quotation of file content for a message (`one_line`, at most `limit` characters)."""
    return one_line(text, limit)


#: the bytes ASCII text may hold as they are: the printable ones, newline and tab
_LAYOUT_AND_PRINTABLE = bytes(range(0x20, 0x7F)) + b"\n\t"


def printable(text: str) -> str:
    """Output text for a terminal: control characters other than newline and tab (NUL, ANSI escapes, DEL, C1)
    shown as \\xNN, so an id or a name from a file cannot drive the terminal. Linear in the text, in C: ASCII text
    with nothing to show otherwise is returned as it is after one pass deleting the bytes it may hold (a gigabyte of
    JSON in about a quarter of a second), anything else through a regular expression."""
    if text.isascii() and not text.encode("ascii").translate(None, _LAYOUT_AND_PRINTABLE):
        return text
    return _CONTROL_BUT_LAYOUT.sub(_hex, text)


def printable_bytes(data: bytes) -> bytes:
    """`printable` for UTF-8 output bytes: returned as they are when they hold nothing else than printable ASCII,
    newline and tab (one pass)."""
    if not data.translate(None, _LAYOUT_AND_PRINTABLE):
        return data
    return printable(data.decode("utf-8", errors="replace")).encode("utf-8")
