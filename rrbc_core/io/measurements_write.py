"""Writing a measurement file (`write_measurements`): the format of docs/formats/measurement-file.md, numbers written so
they read back exactly, the file replaced atomically (a failed write leaves the old file as it was)."""

from __future__ import annotations

import csv
import io
import math
import os
import secrets
from collections.abc import Sequence
from os import PathLike
from pathlib import Path

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.io.measurement_messages import error as _error
from rrbc_core.io.measurements import ROBOT_COLUMNS, SENSOR_COLUMNS, MeasurementSet, validate


def _cell(value: float) -> str:
    v = float(value)
    return "" if math.isnan(v) else repr(v)


def write_measurements(path: str | PathLike, mset: MeasurementSet, comments: Sequence[str] = ()) -> None:
    """Validate a measurement set and write it as a measurement file, atomically.

    Columns: the standard ones, plus ``time`` when any row has a time. Numbers are written with ``repr`` so they read
    back exactly; a missing value is an empty cell. The file is written beside `path` and moved into place with
    ``os.replace``, so a failure leaves an existing file as it was.

    Parameters
    ----------
    path : str or Path
        Where to write.
    mset : MeasurementSet
        The rows (validated first, as `read_measurements` would).
    comments : sequence of str
        Lines written first, each as a ``#`` comment.

    Raises
    ------
    InputError
        The set is invalid or the file cannot be written (one line).
    """
    if not isinstance(mset, MeasurementSet):
        raise InputError(
            f"write_measurements(path, mset) needs a MeasurementSet as its second argument, got {type(mset).__name__}"
        )
    validate(mset)
    write_time = bool(np.any(np.isfinite(mset.time)))
    header = ["id", "role", *SENSOR_COLUMNS, *ROBOT_COLUMNS] + (["time"] if write_time else []) + list(mset.extra)
    fh = io.StringIO()
    for comment in comments:
        for text in str(comment).splitlines() or [""]:
            fh.write(f"# {text}\n" if text else "#\n")
    plain = csv.writer(fh, lineterminator="\n")
    quoted = csv.writer(fh, lineterminator="\n", quoting=csv.QUOTE_ALL)
    plain.writerow(header)
    extra_values = list(mset.extra.values())
    for i in range(len(mset.ids)):
        row = [mset.ids[i], mset.roles[i]]
        row += [_cell(v) for v in mset.sensor[i]]
        row += [_cell(v) for v in mset.robot[i]]
        if write_time:
            row.append(_cell(mset.time[i]))
        row += [str(values[i]) for values in extra_values]
        # A row whose id starts with '#' would read as a comment unless its first cell is quoted; csv
        # quotes '\n' (the line terminator) but not a lone '\r', which readers take as a line break.
        needs_quotes = row[0].lstrip().startswith("#") or any("\r" in cell for cell in row)
        (quoted if needs_quotes else plain).writerow(row)
    atomic_write_text(path, fh.getvalue())


def output_path(path: str | PathLike) -> str:
    """Where `path` is written (issue 16): an empty path, a directory or a special file (a device, a FIFO) is
    refused (InputError, one line); a symbolic link is written through (its target is replaced, the link stays);
    the folder must exist. Call it before long work, so a bad `--out` is said at once, not after the run."""
    dest = os.fspath(path)
    if isinstance(dest, bytes):
        dest = os.fsdecode(dest)
    if not str(dest).strip():
        raise InputError("an empty output path: give a file name")
    if os.path.islink(dest):
        dest = os.path.realpath(dest)
    if os.path.exists(dest) and not os.path.isfile(dest):
        raise _error(dest, None, None, "not a regular file (a directory, device or FIFO): refusing to replace it")
    directory = os.path.dirname(os.path.abspath(dest))
    if not os.path.isdir(directory):
        raise _error(dest, None, None, f"cannot write the file: no such folder {directory}")
    if not os.access(directory, os.W_OK):
        raise _error(dest, None, None, f"cannot write the file: the folder {directory} is not writable")
    return dest


def output_dir(path: str | PathLike, flag: str = "--out") -> Path:
    """Where a folder of outputs goes (`flag` names it in messages): refused (InputError, one line) when empty, when
    it exists and is not a folder, or when its nearest existing ancestor is not a folder one can write in; it need
    not exist yet (`make_output_dir` creates it, with any missing parents). Call it before long work."""
    text = os.fsdecode(os.fspath(path))
    if not text.strip():
        raise InputError(f"{flag}: an empty path; give a folder")
    p = Path(text)
    if p.exists() and not p.is_dir():
        raise InputError(f"{flag} {p}: exists and is not a folder")
    ancestor = p.resolve()
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir() or not os.access(ancestor, os.W_OK | os.X_OK):
        raise InputError(f"{flag} {p}: cannot create or write it ({ancestor} is not a folder one can write in)")
    return p


def make_output_dir(path: str | PathLike, flag: str = "--out") -> Path:
    """`output_dir`, created if it does not exist yet (with its missing parents)."""
    p = output_dir(path, flag)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{flag} {p}: cannot create the folder: {exc.strerror or exc}") from None
    return p


def atomic_write_text(path: str | PathLike, text: str) -> None:
    """Write `text` (UTF-8) to `path` atomically: a temporary file beside it, fsync'd, then ``os.replace``; an
    existing file keeps its permissions, and a failure leaves it as it was; a link is written through and special
    files are refused (`output_path`). InputError (one line) if it cannot be written."""
    dest = output_path(path)
    directory = os.path.dirname(os.path.abspath(dest))
    base = os.path.basename(dest)
    tmp = os.path.join(directory, f".{base}.{secrets.token_hex(6)}.tmp")
    try:
        mode = os.stat(dest).st_mode & 0o7777 if os.path.exists(dest) else None
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as exc:
        raise _error(dest, None, None, f"cannot write the file: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as out:
            out.write(text)
            out.flush()
            os.fsync(out.fileno())
        if mode is not None:
            os.chmod(tmp, mode)
        os.replace(tmp, dest)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise _error(dest, None, None, f"cannot write the file: {exc.strerror or exc}") from None
        raise
