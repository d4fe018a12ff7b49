"""Measurement files: the CSV interchange format for measured points (spec: docs/formats/measurement-file.md).

A measurement file holds, per row, a point `id`, its `role` (registration, fiducial, both, target, check), the
point as measured in the sensor frame (`sensor_x`, `sensor_y`, `sensor_z`, mm), as measured by the robot or, for
check rows, its robot-frame ground truth (`robot_x`, `robot_y`, `robot_z`, mm; empty for targets) and optionally
the time of measurement (`time`, s). Other columns are kept verbatim and written back.

Reading:
- `read_measurements(path)` / `parse_measurements(text, source)` return a `MeasurementSet` (rows in file order)
  and raise `InputError` with a one-line message `<file>: line <n>: field <name>: <what is wrong>` on any bad
  input (the `line` and `field` parts are left out where they do not apply).
- `#` lines (possibly indented), blank lines and rows of empty cells only are skipped; line numbers count
  physical lines of the file. A quoted cell may span lines.
- Cells are stripped of surrounding whitespace; column names are case-sensitive.
- Robot values on `target` rows are ignored (stored as NaN); an empty `time` cell is NaN.

Writing: `write_measurements(path, mset, comments)` validates the set, then writes it atomically (temporary file
in the same directory, then `os.replace`): a failure never leaves a partial or modified destination. Floats are
written with `repr`, so writing then reading gives back the very same floats.

`validate(mset)` runs the set-level checks (also run by the readers): per-row consistency, one role per id, at
least 3 distinct registration points (roles registration and both), not coincident and not (nearly) collinear in
either frame (`geometry.check_registration_points`, thresholds `COINCIDENT_MM`, `COLLINEAR_RATIO`).
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
from array import array
from collections.abc import Iterator
from dataclasses import replace
from os import PathLike

import numpy as np

from rrbc_core.errors import InputError, excerpt
from rrbc_core.geometry.points import check_registration_points
from rrbc_core.io.measurement_format import (
    COLUMNAR_MIN_CHARS,
    COORDINATE_LIMIT_MM,
    FIDUCIAL_ROLES,
    FILE_LIMIT_BYTES,
    GROUP_COLUMN,
    NUMBER_PATTERN,
    REGISTRATION_ROLES,
    REQUIRED_COLUMNS,
    ROBOT_COLUMNS,
    ROBOT_REQUIRED_ROLES,
    ROLES,
    SENSOR_COLUMNS,
    STANDARD_COLUMNS,
    TIME_LIMIT_S,
)
from rrbc_core.io.measurement_messages import MAX_LISTED
from rrbc_core.io.measurement_messages import error as _error
from rrbc_core.io.measurement_messages import listed as _listed
from rrbc_core.io.measurement_messages import registration_error as _registration_error
from rrbc_core.io.measurement_set import MeasurementSet, PointGroup, select_rows

__all__ = [
    "ROLES",
    "REGISTRATION_ROLES",
    "FIDUCIAL_ROLES",
    "ROBOT_REQUIRED_ROLES",
    "SENSOR_COLUMNS",
    "ROBOT_COLUMNS",
    "STANDARD_COLUMNS",
    "MeasurementSet",
    "PointGroup",
    "read_measurements",
    "parse_measurements",
    "validate",
]

_NUMBER = re.compile(NUMBER_PATTERN, re.ASCII)  # ASCII digits only


# --------------------------------------------------------------------------------------------------- reading


def read_measurements(path: str | PathLike) -> MeasurementSet:
    """Read and validate a measurement file (UTF-8 CSV; format: docs/formats/measurement-file.md).

    Parameters
    ----------
    path : str or Path
        The file.

    Returns
    -------
    MeasurementSet
        Its rows in file order: ids, roles, sensor (N, 3) sensor frame, robot (N, 3) robot frame, mm, time (s).

    Raises
    ------
    InputError
        One line naming the file, the line and the field of the first problem.
    """
    source = os.fspath(path)
    if isinstance(source, bytes):
        source = os.fsdecode(source)
    if os.path.exists(source) and not os.path.isfile(source):
        raise _error(source, None, None, "cannot read the file: not a regular file (a device, FIFO or directory)")
    try:
        with open(path, "rb") as fh:
            data = fh.read(FILE_LIMIT_BYTES + 1)
    except OSError as exc:
        reason = exc.strerror or exc.__class__.__name__
        raise _error(source, None, None, f"cannot read the file: {reason}") from None
    if len(data) > FILE_LIMIT_BYTES:
        raise _error(
            source, None, None, f"larger than {FILE_LIMIT_BYTES // 2**20} MiB, the limit of a measurement file"
        )
    if len(data) >= COLUMNAR_MIN_CHARS:  # a long file: read by columns where that reader decides (the same set)
        read = _read_columnar(data, source)
        if read is not None:
            return read
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise _error(
            source,
            line,
            None,
            f"not UTF-8 text (byte 0x{data[exc.start]:02x} at column {column}); save the file as UTF-8",
        ) from None
    return parse_measurements(text, source)


def _read_columnar(data: str | bytes, source: str) -> MeasurementSet | None:
    """The validated set `io.measurements_columnar` reads, or None where it leaves the file to the row reader."""
    from rrbc_core.io.measurements_columnar import parse_columnar

    read = parse_columnar(data, source, _check_header)
    if read is None:
        return None
    mset = MeasurementSet(read.ids, read.roles, read.sensor, read.robot, read.time, read.lines, source, read.extra)
    mset._known(read.role_codes, read.ids_distinct)
    _validate(mset, header_line=read.header_line, rows_checked=True)
    return mset


class _LineFeed:
    """Feeds physical lines to csv.reader, skipping comment and blank lines between records (not inside a quoted
    multi-line cell) and remembering the physical line number where each record starts."""

    def __init__(self, text: str) -> None:
        self._lines = io.StringIO(text, newline="")
        self.number = 0  # physical lines consumed so far
        self.record_start = 0
        self.at_record_start = True

    def __iter__(self) -> Iterator[str]:
        return self

    def __next__(self) -> str:
        while True:
            raw = self._lines.readline()
            if raw == "":
                raise StopIteration
            self.number += 1
            if self.at_record_start:
                stripped = raw.strip()
                if not stripped or stripped.startswith("#"):
                    continue
                self.record_start = self.number
                self.at_record_start = False
            return raw


def _records(text: str, source: str) -> Iterator[tuple[int, list[str]]]:
    """(line number, stripped cells) for every non-comment record of the text."""
    feed = _LineFeed(text)
    reader = csv.reader(feed, strict=True, skipinitialspace=True)
    while True:
        feed.at_record_start = True
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            hint = "; is a quote left open?" if "end of data" in str(exc) else ""
            raise _error(source, feed.record_start or None, None, f"malformed CSV ({exc}){hint}") from None
        cells = [cell.strip() for cell in row]
        if any(cells):  # rows of empty cells only (",,,,", left by spreadsheets) are skipped like blank lines
            yield feed.record_start, cells


def _number(cell: str, source: str, line: int, column: str, limit: float = COORDINATE_LIMIT_MM) -> float:
    if _NUMBER.fullmatch(cell):
        number = float(cell)
        if math.isfinite(number) and abs(number) <= limit:
            return number
        if not math.isfinite(number):
            raise _error(source, line, column, f"{excerpt(cell)!r} is out of range (not a finite number)")
        raise _error(source, line, column, f"{excerpt(cell)!r} is out of range (at most {limit:g} in size)")
    value: float | None
    try:
        value = float(cell)
    except ValueError:
        value = None
    if value is not None and not math.isfinite(value):
        raise _error(
            source, line, column, f"{excerpt(cell)!r} is not a finite number (NaN and infinity are not allowed)"
        )
    raise _error(source, line, column, f"{excerpt(cell)!r} is not a number")


def parse_measurements(text: str, source: str = "<text>") -> MeasurementSet:
    """Parse and validate the text of a measurement file (as `read_measurements` does for a file).

    Parameters
    ----------
    text : str
        The file's content.
    source : str
        The name used in messages.

    Returns
    -------
    MeasurementSet

    Raises
    ------
    InputError
        One line naming the source, the line and the field of the first problem.
    """
    source = str(source)
    if text.startswith("\ufeff"):
        text = text[1:]
    if len(text) >= COLUMNAR_MIN_CHARS:  # a long file: read by columns where that reader decides (the same set)
        read = _read_columnar(text, source)
        if read is not None:
            return read
    records = _records(text, source)
    try:
        header_line, header = next(records)
    except StopIteration:
        raise _error(source, None, None, "no header row: the file is empty or holds only comments") from None
    columns = _check_header(header, header_line, source)
    position = {name: k for k, name in enumerate(header)}
    extra_names = [name for name in header if name not in STANDARD_COLUMNS]
    has_time = "time" in position

    ids: list[str] = []
    roles: list[str] = []
    sensor = array("d")  # flat x, y, z per row: 24 bytes a row, not a list of float objects
    robot = array("d")
    times = array("d")
    lines = array("q")
    extra: dict[str, list[str]] = {name: [] for name in extra_names}
    seen: dict[str, tuple[str, int]] = {}  # id -> (role, first line)

    for line, cells in records:
        if len(cells) != columns:
            if len(cells) < columns:
                missing = header[len(cells)]
                raise _error(
                    source, line, missing, f"cell missing: the row has {len(cells)} cells, the header has {columns}"
                )
            raise _error(
                source,
                line,
                None,
                f"the row has {len(cells)} cells, the header has {columns} (extra cells after {header[-1]!r}; "
                "quote cells that contain commas)",
            )
        ident = cells[position["id"]]
        role = cells[position["role"]]
        s = []
        for name in SENSOR_COLUMNS:
            cell = cells[position[name]]
            if cell == "":
                raise _error(source, line, name, "empty: every row needs its sensor-frame coordinates")
            s.append(_number(cell, source, line, name))
        b = [math.nan] * 3
        if role != "target":
            for k, name in enumerate(ROBOT_COLUMNS):
                cell = cells[position[name]]
                if cell != "":
                    b[k] = _number(cell, source, line, name)
        t = math.nan
        if has_time:
            cell = cells[position["time"]]
            if cell != "":
                t = _number(cell, source, line, "time", TIME_LIMIT_S)
        _check_row(source, line, ident, role, s, b, t)
        _check_same_role(source, line, ident, role, seen)
        ids.append(ident)
        roles.append(role)
        sensor.extend(s)
        robot.extend(b)
        times.append(t)
        lines.append(line)
        for name in extra_names:
            extra[name].append(cells[position[name]])

    mset = MeasurementSet(
        ids=tuple(ids),
        roles=tuple(roles),
        sensor=np.frombuffer(sensor, dtype=float).reshape(-1, 3),
        robot=np.frombuffer(robot, dtype=float).reshape(-1, 3),
        time=np.frombuffer(times, dtype=float),
        lines=tuple(lines.tolist()),
        source=source,
        extra={name: tuple(values) for name, values in extra.items()},
    )
    _validate(mset, header_line=header_line, rows_checked=True)
    return mset


def _check_header(header: list[str], line: int, source: str) -> int:
    for k, name in enumerate(header):
        if name == "":
            raise _error(source, line, None, f"column {k + 1} of the header has no name")
    seen: dict[str, int] = {}
    for k, name in enumerate(header):
        if name in seen:
            raise _error(source, line, name, f"column named twice in the header (columns {seen[name] + 1} and {k + 1})")
        seen[name] = k
    for name in REQUIRED_COLUMNS:
        if name not in seen:
            hint = ""
            near = [h for h in header if h.lower() == name.lower()]
            if near:
                hint = f" (found {excerpt(near[0])!r}: column names are case-sensitive)"
            elif name in ROBOT_COLUMNS:
                hint = " (needed for roles registration, fiducial, both, check)"
            shown = excerpt(", ".join(h[:20] for h in header[:MAX_LISTED]), 80)
            raise _error(source, line, name, f"required column missing{hint}; the header is: {shown}")
    return len(header)


# ------------------------------------------------------------------------------------------------ validation


def _check_row(source: str, line: int, ident, role, s, b, t) -> None:
    """Row-level checks shared by the parser (file order) and `validate` (in-memory sets)."""
    if not isinstance(ident, str):
        raise _error(source, line, "id", f"{ident!r} is not a string")
    if ident == "":
        raise _error(source, line, "id", "empty: every row needs the id of its point")
    if ident != ident.strip():
        raise _error(source, line, "id", f"{ident!r} has leading or trailing whitespace")
    if role not in ROLES:
        raise _error(source, line, "role", f"{role!r} is not a valid role; valid roles: {', '.join(ROLES)}")
    for name, v in zip(SENSOR_COLUMNS, s):
        if not math.isfinite(v):
            raise _error(source, line, name, f"{v!r} is not a finite number")
    if role in ROBOT_REQUIRED_ROLES:
        given = [name for name, v in zip(ROBOT_COLUMNS, b) if not math.isnan(v)]
        for name, v in zip(ROBOT_COLUMNS, b):
            if math.isnan(v):
                what = "robot-frame ground truth" if role == "check" else "robot measurement"
                part = f" (only {', '.join(given)} given)" if given else ""
                raise _error(
                    source,
                    line,
                    name,
                    f"missing{part}: role {role!r} needs the {what} in robot_x, robot_y, robot_z",
                )
            if not math.isfinite(v):
                raise _error(source, line, name, f"{v!r} is not a finite number")
    if not (math.isnan(t) or math.isfinite(t)):
        raise _error(source, line, "time", f"{t!r} is not a finite number")


def _check_same_role(source: str, line: int, ident: str, role: str, seen: dict[str, tuple[str, int]]) -> None:
    if ident in seen:
        first_role, first_line = seen[ident]
        if first_role != role:
            where = f"line {first_line}" if first_line else "an earlier row"
            raise _error(
                source,
                line,
                "role",
                f"id {ident!r} has role {role!r} here but {first_role!r} on {where}; "
                "all rows of one point must carry the same role",
            )
    else:
        seen[ident] = (role, line)


def validate(mset: MeasurementSet) -> None:
    """Check a measurement set (also run by the readers and the writer); raise InputError with a one-line message.

    Checks: consistent shapes; per row a non-empty id, a valid role, finite sensor values, complete finite robot
    values for roles registration, fiducial, both, check, finite or absent time; one role per id; at least 3
    distinct registration points (registration + both), neither coincident nor (nearly) collinear in the sensor
    frame nor in the robot frame.
    """
    _validate(mset, header_line=0)


def _validate(mset: MeasurementSet, header_line: int, rows_checked: bool = False) -> None:
    """`validate`'s checks; `rows_checked`: the per-row ones were made while the rows were read (not again)."""
    source = mset.source
    n = len(mset.ids)
    shapes = {
        "roles": (len(mset.roles), (n,)),
        "sensor": (mset.sensor.shape, (n, 3)),
        "robot": (mset.robot.shape, (n, 3)),
        "time": (mset.time.shape, (n,)),
        "lines": (len(mset.lines), (n,)),
    }
    for name, (got, want) in shapes.items():
        got_shape = got if isinstance(got, tuple) else (got,)
        if got_shape != want:
            raise _error(source, None, name, f"has shape {got_shape}, expected {want} ({n} rows)")
    for name, values in mset.extra.items():
        if name == "" or name != name.strip():
            raise _error(source, None, None, f"extra column name {name!r} is empty or has surrounding whitespace")
        if name in STANDARD_COLUMNS:
            raise _error(source, None, name, "an extra column cannot use the name of a standard column")
        if len(values) != n:
            raise _error(source, None, name, f"extra column has {len(values)} values, expected {n} (one per row)")

    if GROUP_COLUMN in mset.extra:  # stations (io.groups): each is validated as a file of its own, named in messages
        _validate_groups(mset, header_line, rows_checked)
        return
    seen: dict[str, tuple[str, int]] = {}
    for i in range(0 if rows_checked else n):
        line = mset.lines[i]
        _check_row(
            source,
            line,
            mset.ids[i],
            mset.roles[i],
            mset.sensor[i].tolist(),
            mset.robot[i].tolist(),
            float(mset.time[i]),
        )
        _check_same_role(source, line, mset.ids[i], mset.roles[i], seen)

    reg_rows = mset.rows("registration")
    reg = mset.points("registration")
    last_line = max(map(mset.lines.__getitem__, reg_rows.tolist()), default=0) or header_line
    if len(reg) < 3:
        listed = f" ({_listed(reg.ids)})" if len(reg) else ""
        raise _error(
            source,
            last_line,
            "role",
            f"{len(reg)} distinct registration point{'s' if len(reg) != 1 else ''}{listed}; at least 3 are needed "
            "(rows with role registration or both), well spread and not on one line",
        )
    for frame, pts in (("sensor", reg.sensor), ("robot", reg.robot)):
        try:
            check_registration_points(pts, what=f"registration points ({frame} frame)")
        except InputError as exc:
            raise _registration_error(source, frame, reg, pts, last_line, exc) from None


def _validate_groups(mset: MeasurementSet, header_line: int, rows_checked: bool) -> None:
    for i, value in enumerate(mset.extra[GROUP_COLUMN]):
        if value.strip() == "":
            raise _error(
                mset.source,
                mset.lines[i],
                GROUP_COLUMN,
                "empty group; with a group column every row names its station (docs/formats/measurement-file.md)",
            )
    values = mset.extra[GROUP_COLUMN]
    index: dict[str, int] = {}
    code = np.fromiter((index.setdefault(v, len(index)) for v in values), dtype=int, count=len(values))
    order = np.argsort(code, kind="stable")  # each station's rows in file order
    ends = np.cumsum(np.bincount(code, minlength=len(index)))
    for g, name in enumerate(index):
        rows = order[(ends[g - 1] if g else 0) : ends[g]]
        station = select_rows(mset, rows, f"{mset.source}, group {name!r}")  # as io.groups.group_label names it
        station = replace(station, extra={k: v for k, v in station.extra.items() if k != GROUP_COLUMN})
        _validate(station, header_line, rows_checked)
