"""The columnar reader (issue 41, item 3) reads every file exactly as the row-by-row reader does: the same set for
a good file, the same one-line message for a bad one (it leaves bad files to the row-by-row reader), on seeded
files mutated in the ways real and hostile files differ."""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.io import measurements as reader
from rrbc_core.io import measurements_columnar as columnar
from rrbc_core.io.measurements import _check_header, parse_measurements
from rrbc_core.io.measurements_columnar import parse_columnar
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.simulation.field_data import field_measurements
from rrbc_core.simulation.station_data import drawn_stations


def _read(text: str, monkeypatch, columnar: bool):
    """(set, None) or (None, message) of `parse_measurements`, by columns where it decides or row by row."""
    monkeypatch.setattr(reader, "COLUMNAR_MIN_CHARS", 0 if columnar else 1 << 62)
    try:
        return parse_measurements(text, "f.csv"), None
    except InputError as exc:
        return None, str(exc)


def _same(a, b) -> bool:
    return (
        a.ids == b.ids
        and a.roles == b.roles
        and a.lines == b.lines
        and a.extra == b.extra
        and a.source == b.source
        and all(np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True) for f in ("sensor", "robot", "time"))
        # what the columnar reader hands the set ready-made (role codes, whether an id repeats) is what it computes
        and np.array_equal(a._role_codes(), b._role_codes())
        and a._ids_distinct() == b._ids_distinct() == (len(set(a.ids)) == len(a.ids))
        and all(_same_points(a.points(role), b.points(role)) for role in ("registration", "fiducial", "check"))
    )


def _same_points(p, q) -> bool:
    return (
        p.ids == q.ids
        and p.first_line == q.first_line
        and np.array_equal(p.count, q.count)
        and all(np.array_equal(getattr(p, f), getattr(q, f), equal_nan=True) for f in ("sensor", "robot"))
    )


def _decides(text: str) -> bool:
    return parse_columnar(text, "f.csv", _check_header) is not None


def _base_text(tmp_path, grouped: bool) -> str:
    m = drawn_stations(2) if grouped else field_measurements(3, n_fiducials=12, n_checks=10)
    if not grouped:  # a time column and a kept extra column
        from rrbc_core.io.measurements import MeasurementSet

        n = len(m.ids)
        m = MeasurementSet(m.ids, m.roles, m.sensor, m.robot, np.arange(n) * 1.5, m.lines, extra={"note": ("x",) * n})
    path = tmp_path / "base.csv"
    write_measurements(path, m)
    return path.read_text()


#: ways a line is changed: (name, function of (cells, rng) -> replacement lines); cells are the row's cells
def _mutations():
    bad_numbers = ["1_0", "nan", "inf", "1e400", "abc", "", " ", "0x10", "1e9.5", "2e9", "١", "--1", "1e"]
    good_numbers = ["+1.5", ".5", "-0.", "1E3", " 12 ", "\t7\t", "00012", "1e-5"]
    return [
        ("comment", lambda c, r: ["# note", ",".join(c)]),
        ("indented comment with the header's commas", lambda c, r: ["  #" + ",".join("x" * len(c)), ",".join(c)]),
        ("blank and spaces", lambda c, r: ["", "   \t", ",".join(c)]),
        ("empty cells", lambda c, r: [",".join([" "] * len(c)), ",".join(c)]),
        ("short empty cells", lambda c, r: [",,", ",".join(c)]),
        ("padded cells", lambda c, r: [",".join(f" {x}\t" for x in c)]),
        ("good number", lambda c, r: [",".join(_set(c, r.integers(2, 8), r.choice(good_numbers)))]),
        ("bad number", lambda c, r: [",".join(_set(c, r.integers(2, 8), r.choice(bad_numbers)))]),
        ("cell missing", lambda c, r: [",".join(c[:-1])]),
        ("cell too many", lambda c, r: [",".join(c + ["9"])]),
        ("unknown role", lambda c, r: [",".join(_set(c, 1, "fiducal"))]),
        ("target", lambda c, r: [",".join(_set(_set(c, 1, "target"), 5, r.choice(["", "junk", "1"])))]),
        ("empty id", lambda c, r: [",".join(_set(c, 0, " "))]),
        (
            "id with two roles",
            lambda c, r: [",".join(c), ",".join(_set(c, 1, "check" if c[1] != "check" else "fiducial"))],
        ),
        ("quoted", lambda c, r: [",".join(_set(c, 0, '"' + c[0] + '"'))]),
        ("non-ascii id", lambda c, r: [",".join(_set(c, 0, c[0] + "é"))]),
        ("control character", lambda c, r: [",".join(_set(c, 0, c[0] + "\x0b"))]),
        ("time too large", lambda c, r: [",".join(_set(c, len(c) - 1, "1e13"))]),
        ("repeat", lambda c, r: [",".join(c), ",".join(c)]),
    ]


def _set(cells: list[str], k, value: str) -> list[str]:
    out = list(cells)
    out[int(k) % len(out)] = value
    return out


@pytest.mark.parametrize(
    ("grouped", "threads"),
    [(False, False), (True, False), (False, True)],
    ids=["one station", "stations", "by threads in small blocks"],
)
def test_the_columnar_reader_reads_every_file_as_the_row_reader_does(tmp_path, monkeypatch, grouped, threads):
    """`threads`: every file parsed by pyarrow's threads first, in blocks of 512 bytes (a long file's way: lines
    they cannot place are read again by one thread)."""
    if threads:
        monkeypatch.setattr(columnar, "THREADED_MIN_BYTES", 0)
        monkeypatch.setattr(columnar, "THREADED_BLOCK_BYTES", 512)
    base = _base_text(tmp_path, grouped)
    lines = base.split("\n")
    header = next(i for i, line in enumerate(lines) if line and not line.startswith("#"))
    mutations = _mutations()
    rng = np.random.default_rng(41)
    decided = {name: 0 for name, _ in mutations}
    for trial in range(260):
        out = list(lines)
        names = []
        for _ in range(int(rng.integers(1, 3))):
            k = int(rng.integers(header + 1, len(out) - 1))
            if not out[k] or out[k].lstrip().startswith("#") or out[k].count(",") < 7:
                continue
            name, mutate = mutations[int(rng.integers(len(mutations)))]
            out[k : k + 1] = mutate(out[k].split(","), rng)
            names.append(name)
        text = "\n".join(out)
        if trial % 3 == 1:
            text = text.replace("\n", "\r\n")
        if trial % 5 == 2:
            text = text.rstrip("\n")
        by_rows, msg_rows = _read(text, monkeypatch, columnar=False)
        by_columns, msg_columns = _read(text, monkeypatch, columnar=True)
        assert msg_columns == msg_rows, (names, msg_rows, msg_columns)
        if by_rows is not None:
            assert by_columns is not None and _same(by_columns, by_rows), names
        if _decides(text):
            for name in names:
                decided[name] += 1
    # the rules it shares with the row reader are its own, not left to it
    for name in (
        "comment",
        "indented comment with the header's commas",
        "blank and spaces",
        "empty cells",
        "short empty cells",
        "padded cells",
        "good number",
        "target",
        "repeat",
    ):
        assert decided[name] > 0, (name, decided)


def test_a_long_file_is_read_by_columns_and_the_same(tmp_path, monkeypatch):
    """Above `COLUMNAR_MIN_CHARS` the reader reads by columns (it decides on a plain written file) and gives the row
    reader's set; a bad cell far down is named by the row reader's message."""
    m = field_measurements(4, n_fiducials=60, n_checks=24_000)
    path = tmp_path / "long.csv"
    write_measurements(path, m)
    text = path.read_text()
    assert len(text) >= reader.COLUMNAR_MIN_CHARS and _decides(text)
    by_columns, _ = _read(text, monkeypatch, columnar=True)
    by_rows, _ = _read(text, monkeypatch, columnar=False)
    assert _same(by_columns, by_rows)
    monkeypatch.setattr(reader, "COLUMNAR_MIN_CHARS", 0)
    from_bytes = reader.read_measurements(path)  # the file's bytes read by columns, as `read_measurements` does
    monkeypatch.setattr(reader, "COLUMNAR_MIN_CHARS", 1 << 62)
    assert _same(from_bytes, reader.read_measurements(path))
    bad = text.rsplit("\n", 3)
    cells = bad[1].split(",")
    cells[2] = "1,5"
    text_bad = "\n".join([bad[0], ",".join(cells), *bad[2:]])
    assert _read(text_bad, monkeypatch, columnar=True)[1] == _read(text_bad, monkeypatch, columnar=False)[1]
    assert "cells, the header has" in _read(text_bad, monkeypatch, columnar=True)[1]


def test_a_number_cell_is_taken_exactly_when_the_plain_decimal_pattern_takes_it():
    """Every string of up to three characters from digits, signs, points, exponents, the letters of nan and inf,
    spaces and underscores, and 20 000 longer seeded ones: pyarrow's parser (`cast_numbers`) takes exactly those the
    row reader's pattern takes as finite numbers, and gives the same floats."""
    import itertools
    import math
    import re

    import pyarrow as pa

    from rrbc_core.io.measurement_format import NUMBER_PATTERN
    from rrbc_core.io.measurements_columnar import _NotDecided, cast_numbers

    pattern = re.compile(NUMBER_PATTERN, re.ASCII)
    alphabet = "01.eE+-naifIN _x"
    strings = ["".join(t) for n in (1, 2, 3) for t in itertools.product(alphabet, repeat=n)]
    rng = np.random.default_rng(7)
    letters = np.array(list("0123456789.eE+-naif"))
    strings += ["".join(c) for c in letters[rng.integers(0, len(letters), (20_000, 7))]]
    strings += [repr(float(x)) for x in rng.normal(size=2000) * 10.0 ** rng.integers(-30, 30, 2000)]
    strings += ["".join(map(str, rng.integers(0, 10, 25))) + "e-" + str(k) for k in range(40)]
    for s in strings:
        want = float(s) if pattern.fullmatch(s) and math.isfinite(float(s)) else None
        try:
            got = float(cast_numbers(pa.array([s]), math.inf)[0])
        except _NotDecided:
            got = None
        assert got == want, (s, got, want)


def test_a_number_column_read_as_numbers_takes_the_same_cells_as_the_cast():
    """The reader parses the number columns as numbers while reading (`NUMERIC_COLUMNS`) and reads the file as text
    where a cell is not one: pyarrow's CSV float conversion takes exactly the cells `cast_numbers` takes (every
    string of up to three characters from digits, signs, points, exponents and the letters of nan and inf, and
    3000 longer seeded ones; cells with spaces go the text way) with the same floats."""
    import io
    import itertools
    import math

    import pyarrow as pa
    import pyarrow.csv as pcsv

    from rrbc_core.io.measurements_columnar import _NotDecided, cast_numbers

    alphabet = "01.eE+-naifIN_x"
    strings = ["".join(t) for n in (1, 2, 3) for t in itertools.product(alphabet, repeat=n)]
    rng = np.random.default_rng(8)
    letters = np.array(list("0123456789.eE+-naif"))
    strings += ["".join(c) for c in letters[rng.integers(0, len(letters), (2000, 7))]]
    strings += [repr(float(x)) for x in rng.normal(size=1000) * 10.0 ** rng.integers(-30, 30, 1000)]
    options = pcsv.ConvertOptions(column_types={"x": pa.float64()}, null_values=[""], strings_can_be_null=False)
    for s in strings:
        try:
            cast = float(cast_numbers(pa.array([s]), math.inf)[0])
        except _NotDecided:
            cast = None
        try:
            v = pcsv.read_csv(io.BytesIO(b"x\n" + s.encode()), convert_options=options).column(0)[0].as_py()
            typed = v if v is not None and math.isfinite(v) else None
        except pa.ArrowInvalid:
            typed = None
        assert typed == cast, (s, typed, cast)


def test_a_read_sets_pyarrows_default_pool_back_also_when_readers_overlap_or_fail(tmp_path):
    """The columnar reader reads with the C allocator as pyarrow's default pool (`system_memory_pool`) and sets the
    caller's pool back: after one read, after reads in threads that overlap, and after a file it leaves undecided.
    What was read stays valid after the switch back."""
    import threading

    import pyarrow as pa

    from rrbc_core.io.measurements_columnar import system_memory_pool

    before = pa.default_memory_pool().backend_name
    path = tmp_path / "m.csv"
    write_measurements(path, field_measurements(5, n_fiducials=20, n_checks=3000))
    text = path.read_text()
    got = parse_columnar(text, "f.csv", _check_header)
    assert got is not None and pa.default_memory_pool().backend_name == before
    inside = []
    gate = threading.Barrier(4)

    def overlap():
        with system_memory_pool():
            gate.wait(timeout=30)  # all four inside at once
            inside.append(pa.default_memory_pool().backend_name)
            gate.wait(timeout=30)
        parse_columnar(text, "f.csv", _check_header)

    threads = [threading.Thread(target=overlap) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert inside == ["system"] * 4
    assert pa.default_memory_pool().backend_name == before
    assert parse_columnar(text.replace("\n", "\n1,5\n", 1), "f.csv", _check_header) is None  # undecided
    assert pa.default_memory_pool().backend_name == before
    np.testing.assert_array_equal(got.sensor, parse_columnar(text, "f.csv", _check_header).sensor)


def test_a_long_file_with_a_comment_line_is_read_by_threads_then_once_by_one(tmp_path, monkeypatch):
    """By threads pyarrow gives a refused line no number, so a comment line far down cannot be skipped there: the
    file is read once more by one thread with its numbers still parsed as numbers (not as text), and the set is the
    row reader's. (The comment has no space: a space anywhere in the rows has every cell read as text.)"""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    monkeypatch.setattr(columnar, "THREADED_MIN_BYTES", 0)
    monkeypatch.setattr(columnar, "THREADED_BLOCK_BYTES", 4096)
    lines = _base_text(tmp_path, False).split("\n")
    lines.insert(len(lines) // 2, "#a-note-far-down")
    text = "\n".join(lines)
    reads = []
    real = pcsv.read_csv

    def spy(source, read_options=None, parse_options=None, convert_options=None, **kw):
        typed = any(pa.types.is_floating(t) for t in convert_options.column_types.values())
        reads.append((read_options.use_threads, typed))
        return real(source, read_options=read_options, parse_options=parse_options, convert_options=convert_options)

    monkeypatch.setattr(pcsv, "read_csv", spy)
    by_columns, _ = _read(text, monkeypatch, columnar=True)
    assert reads == [(True, True), (False, True)]
    assert _same(by_columns, _read(text, monkeypatch, columnar=False)[0])
