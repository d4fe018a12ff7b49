"""Measurement files read by columns (issue 41, item 3): pyarrow's CSV reader splits the rows, and every check is
one vectorised test over a column, so a million-row file is read in seconds instead of minutes of Python
text handling.

`parse_columnar(data, source, check_header)` gives exactly the rows the row-by-row reader
(`io.measurements.parse_measurements`) gives for the same file, or None where it does not decide:

- files it leaves to the row-by-row reader: quoted cells (a `"` anywhere), characters outside ASCII, a carriage
  return not followed by a line feed, control characters in an id or a kept column (cells are stripped of spaces
  and tabs only);
- any problem a check finds (a row with too few or too many cells, a cell that is not a number, a missing robot
  value, an unknown role, an id with two roles, ...): the row-by-row reader then reads the file and raises the one
  message naming the file, the line and the field of the first problem. A file is never refused here, so the
  messages have one source.

The rules are the row-by-row reader's (docs/formats/measurement-file.md): `#` lines, blank lines and rows of empty
cells are skipped, line numbers count physical lines, cells are stripped (with no quotes and no other control
characters where text is kept, spaces and tabs are what `str.strip` removes), robot cells of targets are not read,
numbers are plain decimals within the format's limits. A number cell is taken when pyarrow's float parser reads all
of it as a finite number: on every string tried (all strings of up to four characters of digits, signs, points,
exponents, the letters of nan and inf, spaces; 700 000 longer ones) those are exactly the cells the plain decimal
pattern takes, and the values are the same floats. Tests hold the two readers equal on generated files, good and
bad (tests/io/test_measurements_columnar.py).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rrbc_core.io.measurement_format import (
    COORDINATE_LIMIT_MM,
    ROBOT_COLUMNS,
    ROLES,
    SENSOR_COLUMNS,
    STANDARD_COLUMNS,
    TIME_LIMIT_S,
)

# control characters other than tab (Python's strip removes some of them from a cell's ends; pyarrow's does not)
_CONTROL = r"[\x00-\x08\x0a-\x1f\x7f]"
_SPACE = " \t"
#: the columns a file's numbers are in (read as numbers when every cell of them is one)
NUMERIC_COLUMNS = frozenset((*SENSOR_COLUMNS, *ROBOT_COLUMNS, "time"))
#: rows after the header longer than this (bytes) are parsed by pyarrow's threads first (`_parse`)
THREADED_MIN_BYTES = 8 << 20
#: the blocks they parse (pyarrow's default size)
THREADED_BLOCK_BYTES = 1 << 20


class _NotDecided(Exception):
    """The columnar reader leaves the text to the row-by-row reader."""


@dataclass(frozen=True, eq=False)
class ColumnarRows:
    """What the columnar reader read: the header's line and each row's id, role, sensor (R, 3), robot (R, 3; NaN
    for targets), time (R,; NaN where empty), physical line and kept columns, as `io.measurements.MeasurementSet`
    holds them."""

    header_line: int
    ids: tuple[str, ...]
    roles: tuple[str, ...]
    sensor: np.ndarray
    robot: np.ndarray
    time: np.ndarray
    lines: tuple[int, ...]
    extra: dict[str, tuple[str, ...]]
    role_codes: np.ndarray  # (R,) each row's role as its index in ROLES
    ids_distinct: bool  # no id on two rows


def parse_columnar(
    data: str | bytes, source: str, check_header: Callable[[list[str], int, str], object]
) -> ColumnarRows | None:
    """The file's rows read by columns, or None (module docstring). The header is checked by `check_header(cells,
    line, source)` (the row-by-row reader's own check, raising its message); the rows are not yet validated as a
    set (`io.measurements` does that).

    Parameters
    ----------
    data : str or bytes
        The file's content: text (a byte-order mark already removed) or the file's bytes (ASCII only is read here;
        a byte-order mark is not ASCII).
    source : str
        The name used in messages.
    """
    if not data.isascii():
        return None
    body = data.encode("ascii") if isinstance(data, str) else data
    del data
    if b'"' in body:
        return None
    if b"\r" in body:
        if body.count(b"\r") != body.count(b"\r\n"):
            return None
        body = body.replace(b"\r\n", b"\n")
    found = _header(body)
    if found is None:
        return None
    header_line, header, start = found
    check_header(header, header_line, source)
    try:
        with system_memory_pool():
            return _parse(body, start, header_line, header)
    except _NotDecided:
        return None


_POOL_LOCK = threading.Lock()
_POOL_USERS = 0  # readers inside `system_memory_pool`
_POOL_BEFORE: list = []  # the default pool they replaced (while there are any)


@contextlib.contextmanager
def system_memory_pool():
    """pyarrow's default memory pool set to the C library's allocator while a file is read, and set back after.

    pyarrow's own default (mimalloc) gives memory back to the system eagerly and takes fresh pages again for every
    large column; on a virtual machine those page faults cost most of a million-row file's system time
    (benchmarks/big_inputs.py's `read_1000000_rows`). Buffers keep the pool they came from, so arrays read here are
    freed correctly after the switch back; concurrent readers (two tabs uploading) share one switch."""
    import pyarrow as pa

    global _POOL_USERS
    with _POOL_LOCK:
        if _POOL_USERS == 0:
            _POOL_BEFORE.append(pa.default_memory_pool())
            pa.set_memory_pool(pa.system_memory_pool())
        _POOL_USERS += 1
    try:
        yield
    finally:
        with _POOL_LOCK:
            _POOL_USERS -= 1
            if _POOL_USERS == 0:
                pa.set_memory_pool(_POOL_BEFORE.pop())


def _header(body: bytes) -> tuple[int, list[str], int] | None:
    """(its line, its stripped cells, where the next line starts) of the first record that is not a comment, blank
    or empty cells (the row-by-row reader's header, in ASCII text without quotes and lone CRs); None without one."""
    start, line = 0, 0
    while start < len(body):
        end = body.find(b"\n", start)
        end = len(body) if end < 0 else end
        line += 1
        raw = body[start:end].decode("ascii")
        start = end + 1
        stripped = raw.strip()
        if not stripped or stripped.startswith("#"):
            continue
        cells = [cell.strip() for cell in raw.split(",")]
        if any(cells):
            return line, cells, min(start, len(body))
    return None


def cast_numbers(cells, limit: float) -> np.ndarray:
    """(M,) floats of pyarrow string cells, each a plain decimal whose value is finite and at most `limit` in size;
    raises `_NotDecided` for any other cell (module docstring)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    try:
        v = np.asarray(pc.cast(cells, pa.float64()), dtype=float)
    except (pa.ArrowInvalid, ValueError):
        raise _NotDecided from None
    if not (np.all(np.isfinite(v)) and np.all(np.abs(v) <= limit)):
        raise _NotDecided
    return v


def _parse(body: bytes, start: int, header_line: int, header: list[str]) -> ColumnarRows:
    """The rows of `body[start:]` (the lines after the header's) as a set; raises `_NotDecided`."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.csv as pcsv

    n_col = len(header)
    names = [f"c{k}" for k in range(n_col)]
    skipped: list[int] = []  # body lines (1-based) that are not rows: blank, comment, empty cells
    unplaced: list[bool] = []  # per line refused: whether it had no line number to decide by

    def other_count(row) -> str:  # a line whose cell count is not the header's: skipped only where it is no row
        stripped = row.text.strip()
        if row.number is not None and (
            stripped == "" or stripped.startswith("#") or all(c.strip() == "" for c in row.text.split(","))
        ):
            skipped.append(row.number)
            return "skip"
        unplaced.append(row.number is None)  # (by threads pyarrow gives no line number: read again by one)
        return "error"

    numeric = {f"c{k}" for k, name in enumerate(header) if name in NUMERIC_COLUMNS}

    def read(typed: bool, threads: bool = False):
        skipped.clear()
        unplaced.clear()
        # by threads: blocks parsed in pyarrow's own pool (on a million rows about half the time of one block on
        # one thread); else one block, whose rows carry their line numbers (the file is at most `FILE_LIMIT_BYTES`,
        # far below a block's limit)
        block = THREADED_BLOCK_BYTES if threads else len(body) - start + 1
        return pcsv.read_csv(
            pa.BufferReader(pa.py_buffer(body)[start:]),  # no copy
            read_options=pcsv.ReadOptions(column_names=names, use_threads=threads, block_size=block),
            parse_options=pcsv.ParseOptions(
                quote_char=False,
                double_quote=False,
                escape_char=False,
                newlines_in_values=False,
                ignore_empty_lines=False,
                invalid_row_handler=other_count,
            ),
            convert_options=pcsv.ConvertOptions(
                column_types={n: pa.float64() if typed and n in numeric else pa.string() for n in names},
                null_values=[""],  # (only an empty cell is "no value"; strings are never null)
                strings_can_be_null=False,
                check_utf8=False,
            ),
        )

    # the number columns parsed as numbers while the file is read (pyarrow's float parser is the cast's: module
    # docstring); where one cell is not a number (a comment line, a target's junk robot cell, a padded file)
    # every column is read as text and checked below, as before
    typed = True
    try:
        try:  # a large file by threads first; a line they cannot place (no line number) is read again by one
            table = read(True, threads=len(body) - start > THREADED_MIN_BYTES)
        except (pa.ArrowInvalid, ValueError):
            if not any(unplaced):
                raise
            table = read(True)
    except (pa.ArrowInvalid, ValueError):
        typed = False
        try:
            table = read(False)
        except (pa.ArrowInvalid, ValueError):
            raise _NotDecided from None
    if table.num_rows == 0:  # no rows: the row-by-row reader says what is missing
        raise _NotDecided
    padded = body.find(b" ", start) >= 0 or body.find(b"\t", start) >= 0
    if typed and padded:  # (whether the float parser trims a cell is pyarrow's business: read as text)
        typed = False
        table = read(False)
    columns = [table.column(k).combine_chunks() for k in range(n_col)]
    if padded:
        columns = [pc.utf8_trim(col, _SPACE) for col in columns]

    def blank(col):  # a cell without a value: an empty string, or a null number
        return pc.is_null(col) if pa.types.is_floating(col.type) else pc.equal(col, "")

    # rows the row-by-row reader skips although they have the header's cell count: comments and empty cells
    drop = np.asarray(pc.starts_with(columns[0], "#"), dtype=bool)
    if padded or any(pc.any(blank(col)).as_py() for col in columns):
        empty = blank(columns[0])
        for col in columns[1:]:
            empty = pc.and_(empty, blank(col))
        drop |= np.asarray(empty, dtype=bool)
    n_lines = body.count(b"\n", start) + (0 if body.endswith(b"\n") or start >= len(body) else 1)
    if skipped:
        body_lines = np.setdiff1d(np.arange(1, n_lines + 1), np.asarray(skipped, int), assume_unique=True)
    else:
        body_lines = np.arange(1, n_lines + 1)
    if len(body_lines) != table.num_rows:  # how pyarrow counted lines is not ours: leave it
        raise _NotDecided
    keep = ~drop
    if not keep.any():
        raise _NotDecided
    if not keep.all():
        mask = pa.array(keep)
        columns = [col.filter(mask) for col in columns]
    lines = body_lines[keep] + header_line
    n = int(keep.sum())
    cells = dict(zip(header, columns))

    ids, roles = cells["id"], cells["role"]
    kept = [ids] + [cells[name] for name in header if name not in STANDARD_COLUMNS]
    if any(pc.any(pc.match_substring_regex(col, _CONTROL)).as_py() for col in kept):
        raise _NotDecided
    role_set = pa.array(ROLES)
    if not pc.all(pc.is_in(roles, value_set=role_set)).as_py() or pc.any(pc.equal(ids, "")).as_py():
        raise _NotDecided
    role_code = np.asarray(pc.index_in(roles, value_set=role_set), dtype=int)
    needs_robot = role_code != ROLES.index("target")

    def numbers(col, wanted: np.ndarray, limit: float) -> np.ndarray:
        """The column's numbers where `wanted` (NaN elsewhere)."""
        if pa.types.is_floating(col.type):  # parsed while read: the same checks of value and size
            v = np.asarray(col.fill_null(np.nan), dtype=float)
            w = v[wanted]
            if not (np.all(np.isfinite(w)) and np.all(np.abs(w) <= limit)):
                raise _NotDecided
            return np.where(wanted, v, np.nan)
        if wanted.all():
            return cast_numbers(col, limit)
        out = np.full(n, np.nan)
        if wanted.any():
            out[wanted] = cast_numbers(col.filter(pa.array(wanted)), limit)
        return out

    def given(col) -> np.ndarray:
        return ~np.asarray(blank(col), dtype=bool)

    every = np.ones(n, bool)
    sensor = np.empty((n, 3))
    for k, name in enumerate(SENSOR_COLUMNS):
        if not given(cells[name]).all():
            raise _NotDecided
        sensor[:, k] = numbers(cells[name], every, COORDINATE_LIMIT_MM)
    robot = np.empty((n, 3))
    for k, name in enumerate(ROBOT_COLUMNS):
        present = given(cells[name])
        if np.any(needs_robot & ~present):  # a registration, fiducial or check row without it
            raise _NotDecided
        robot[:, k] = numbers(cells[name], needs_robot & present, COORDINATE_LIMIT_MM)
    time = numbers(cells["time"], given(cells["time"]), TIME_LIMIT_S) if "time" in cells else np.full(n, np.nan)
    id_list = ids.to_pylist()
    distinct = len(set(id_list)) == n  # (a Python set: faster here than pyarrow's count_distinct)
    if not distinct:  # repeated ids: one role each
        id_code = np.asarray(pc.dictionary_encode(ids).indices, dtype=int)
        lo = np.full(int(id_code.max()) + 1, len(ROLES))
        hi = np.full(len(lo), -1)
        np.minimum.at(lo, id_code, role_code)
        np.maximum.at(hi, id_code, role_code)
        if np.any(lo != hi):
            raise _NotDecided
    extra = {name: tuple(cells[name].to_pylist()) for name in header if name not in STANDARD_COLUMNS}
    return ColumnarRows(
        header_line,
        tuple(id_list),
        tuple(np.asarray(ROLES, dtype=object)[role_code].tolist()),
        sensor,
        robot,
        time,
        tuple(lines.tolist()),
        extra,
        role_code,
        distinct,
    )
