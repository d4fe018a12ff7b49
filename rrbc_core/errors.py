"""The one exception type for bad input.

Every check on user-supplied data (files, command-line values, point sets handed to the library) raises
`InputError` with a message a user can act on. The command line turns it into one stderr line and exit code 2.
"""


class InputError(ValueError):
    """Bad input: the message says what is wrong and, where it can, where and how to fix it."""


MESSAGE_LIMIT = 400  # characters of a message shown to a user (stderr line, app notification)


def one_line(text: str, limit: int = MESSAGE_LIMIT) -> str:
    """`text` as one safe line for a terminal or a page: whitespace runs collapsed, control characters (NUL, ANSI
    escapes, DEL, C1) shown as \\xNN instead of acting, at most `limit` characters (then "…")."""
    out = []
    for ch in " ".join(str(text).split()):
        o = ord(ch)
        out.append(f"\\x{o:02x}" if o < 0x20 or 0x7F <= o < 0xA0 else ch)
    s = "".join(out)
    return s if len(s) <= limit else s[: limit - 1] + "…"


def excerpt(text: str, limit: int = 40) -> str:
    """A short, safe quotation of file content for a message (`one_line`, at most `limit` characters)."""
    return one_line(text, limit)


def printable(text: str) -> str:
    """Output text for a terminal: control characters other than newline and tab (NUL, ANSI escapes, DEL, C1)
    shown as \\xNN, so an id or a name from a file cannot drive the terminal."""
    return "".join(
        ch if ch in "\n\t" or not (ord(ch) < 0x20 or 0x7F <= ord(ch) < 0xA0) else f"\\x{ord(ch):02x}" for ch in text
    )
