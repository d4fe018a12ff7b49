"""Tests for rrbc_core.io.measurements: reading, validation, aggregation and atomic writing of measurement files."""

from __future__ import annotations

import importlib.util
import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rrbc_core.io.measurements as meas
import rrbc_core.io.measurements_write as meas_write
from rrbc_core.errors import InputError
from rrbc_core.io.measurements import (
    ROLES,
    MeasurementSet,
    parse_measurements,
    read_measurements,
    validate,
)
from rrbc_core.io.measurements_write import write_measurements

DATA = Path(meas.__file__).parents[1] / "data"
EXAMPLE = DATA / "example_measurements.csv"

HEADER = "id,role,sensor_x,sensor_y,sensor_z,robot_x,robot_y,robot_z,time,label"
GOOD_ROWS = [
    "R1,registration,0,0,0,10,20,30,1.5,a",
    "R2,registration,100,0,0,110,20,30,2.5,b",
    "R3,both,0,100,0,10,120,30,,c",
    "F1,fiducial,50,50,0,60,70,30,4,d",
    "T1,target,20,20,0,,,,5,e",
    "C1,check,30,30,0,40,50,30,6,f",
]


def _text(*rows: str, header: str = HEADER, preamble: tuple[str, ...] = ()) -> str:
    return "\n".join([*preamble, header, *rows]) + "\n"


def _assert_one_line_error(exc: InputError, *parts: str) -> str:
    msg = str(exc)
    assert "\n" not in msg and "\r" not in msg, msg
    for part in parts:
        assert part in msg, f"{part!r} not in {msg!r}"
    return msg


def _same_set(a: MeasurementSet, b: MeasurementSet) -> None:
    assert a.ids == b.ids
    assert a.roles == b.roles
    for name in ("sensor", "robot", "time"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape, name
        np.testing.assert_array_equal(x, y, err_msg=name)  # exact, NaN == NaN
        assert np.array_equal(np.signbit(x), np.signbit(y)), name  # -0.0 survives too
    assert a.extra == b.extra


# --------------------------------------------------------------------------------------------- good input


def test_parse_good_file():
    m = parse_measurements(_text(*GOOD_ROWS, preamble=("# a comment", "", "   # indented comment")), "x.csv")
    assert m.source == "x.csv"
    assert m.ids == ("R1", "R2", "R3", "F1", "T1", "C1")
    assert m.roles == ("registration", "registration", "both", "fiducial", "target", "check")
    assert m.lines == (5, 6, 7, 8, 9, 10)
    np.testing.assert_array_equal(m.sensor[1], [100, 0, 0])
    np.testing.assert_array_equal(m.robot[5], [40, 50, 30])
    assert np.all(np.isnan(m.robot[4]))
    assert math.isnan(m.time[2]) and m.time[0] == 1.5
    assert m.extra == {"label": ("a", "b", "c", "d", "e", "f")}
    assert m.sensor.shape == (6, 3) and m.robot.shape == (6, 3) and m.time.shape == (6,)


def test_whitespace_bom_crlf_quotes_comments_between_rows_and_no_time_column():
    header = " id , role ,sensor_x,sensor_y,sensor_z,robot_x,robot_y,robot_z , note"
    text = "\ufeff" + "\r\n".join(
        [
            header,
            ' R1 , registration , 0 , 0 , 0 , 10 , 20 , 30 ,  "x, with comma"',
            "# comment between rows",
            "",
            'R2,registration,100,0,0,110,20,30,"multi',
            "# not a comment: inside a quoted cell",
            "",
            'line"',
            "R3,registration,0,1e2,0,10,1.2e2,+30,plain",
            "T1,target,1,1,0,garbage,ignored,,",
        ]
    )
    m = parse_measurements(text, "w.csv")
    assert m.ids == ("R1", "R2", "R3", "T1")
    assert m.lines == (2, 5, 9, 10)
    assert m.extra["note"][0] == "x, with comma"
    assert m.extra["note"][1] == "multi\r\n# not a comment: inside a quoted cell\r\n\r\nline"
    assert np.all(np.isnan(m.time))
    np.testing.assert_array_equal(m.robot[2], [10, 120, 30])
    assert np.all(np.isnan(m.robot[3]))  # robot values on target rows are ignored


def test_robot_values_on_target_rows_are_stored_as_nan_in_memory_too():
    m = MeasurementSet(
        ids=("a", "b", "c", "t"),
        roles=("registration", "registration", "registration", "target"),
        sensor=[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.5, 0.5, 0]],
        robot=[[0, 0, 0], [1, 0, 0], [0, 1, 0], [9, 9, 9]],
        time=[np.nan] * 4,
        lines=(0,) * 4,
    )
    assert np.all(np.isnan(m.robot[3]))
    validate(m)
    with pytest.raises(ValueError):
        m.sensor[0, 0] = 1.0  # stored read-only


def test_example_file_parses_validates_and_aggregates():
    m = read_measurements(EXAMPLE)
    validate(m)
    assert m.source == str(EXAMPLE)
    assert "label" in m.extra
    reg = m.points("registration")
    assert reg.ids == ("F11", "F14", "F41", "F44")
    assert list(reg.count) == [2, 2, 2, 2]
    fid = m.points("fiducial")
    assert len(fid.ids) == 16 and fid.ids[0] == "F11"
    assert sum(r == "both" for r in m.roles) == 8 and sum(r == "fiducial" for r in m.roles) == 12
    # the averaged corner is the mean of its two rows
    rows = [i for i, k in enumerate(m.ids) if k == "F44"]
    np.testing.assert_allclose(reg.sensor[3], m.sensor[rows].mean(axis=0), rtol=0, atol=0)
    np.testing.assert_allclose(reg.robot[3], m.robot[rows].mean(axis=0), rtol=0, atol=0)
    assert reg.first_line[3] == m.lines[rows[0]]
    tgt = m.points("target")
    assert len(tgt.ids) == 6 and np.all(np.isnan(tgt.robot)) and np.all(np.isfinite(tgt.sensor))
    chk = m.points("check")
    assert len(chk.ids) == 10 and np.all(np.isfinite(chk.robot))
    # targets and checks lie inside the grid (sensor frame)
    lo, hi = fid.sensor.min(axis=0), fid.sensor.max(axis=0)
    for pts in (tgt.sensor, chk.sensor):
        assert np.all(pts[:, :2] > lo[:2]) and np.all(pts[:, :2] < hi[:2])
    # every row has a time
    assert np.all(np.isfinite(m.time))


def test_example_file_matches_its_generator(tmp_path):
    spec = importlib.util.spec_from_file_location("make_example", DATA / "make_example.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "regenerated.csv"
    assert mod.main([str(out)]) == 0
    a, b = read_measurements(EXAMPLE), read_measurements(out)
    assert a.ids == b.ids and a.roles == b.roles and a.extra == b.extra
    for name in ("sensor", "robot", "time"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=2e-4)
    assert "generated by: python rrbc_core/data/make_example.py" in EXAMPLE.read_text()


def test_points_aggregation_with_repeats():
    rows = [
        "A,registration,0,0,0,10,10,10,,",
        "B,both,100,0,0,110,10,10,,",
        "A,registration,2,0,0,12,10,10,,",
        "C,registration,0,100,0,10,110,10,,",
        "F,fiducial,5,5,0,15,15,10,,",
        "B,both,102,2,0,114,10,10,,",
        "F,fiducial,7,5,0,17,15,10,,",
        "A,registration,4,3,0,14,13,10,,",
    ]
    m = parse_measurements(_text(*rows), "agg.csv")
    reg = m.points("registration")
    assert reg.ids == ("A", "B", "C")
    assert list(reg.count) == [3, 2, 1]
    assert reg.first_line == (2, 3, 5)
    np.testing.assert_allclose(reg.sensor[0], [2, 1, 0])
    np.testing.assert_allclose(reg.robot[0], [12, 11, 10])
    np.testing.assert_allclose(reg.sensor[1], [101, 1, 0])
    fid = m.points("fiducial")
    assert fid.ids == ("B", "F")
    assert list(fid.count) == [2, 2]
    np.testing.assert_allclose(fid.sensor[1], [6, 5, 0])
    both = m.points("both")
    assert both.ids == ("B",)
    empty = m.points("check")
    assert empty.ids == () and empty.sensor.shape == (0, 3) and empty.robot.shape == (0, 3)
    with pytest.raises(InputError, match="valid roles"):
        m.points("registrations")


# ------------------------------------------------------------------------------------------- round trip


def test_round_trip_file(tmp_path):
    m = parse_measurements(_text(*GOOD_ROWS), "in.csv")
    out = tmp_path / "out.csv"
    write_measurements(out, m, comments=["first comment", "two\nlines", ""])
    text = out.read_text(encoding="utf-8")
    assert text.startswith("# first comment\n# two\n# lines\n#\nid,role,sensor_x,")
    assert text.splitlines()[4] == HEADER
    back = read_measurements(out)
    _same_set(m, back)
    assert back.lines == (6, 7, 8, 9, 10, 11)


def test_writer_omits_time_column_when_no_time_and_writes_empty_cells_for_nan(tmp_path):
    m = parse_measurements(_text(*[r.rsplit(",", 2)[0] + ",," + r.rsplit(",", 1)[1] for r in GOOD_ROWS]), "x")
    assert np.all(np.isnan(m.time))
    out = tmp_path / "o.csv"
    write_measurements(out, m)
    lines = out.read_text().splitlines()
    assert lines[0] == "id,role,sensor_x,sensor_y,sensor_z,robot_x,robot_y,robot_z,label"
    assert lines[5] == "T1,target,20.0,20.0,0.0,,,,e"
    _same_set(m, read_measurements(out))


def test_round_trip_example_exact(tmp_path):
    m = read_measurements(EXAMPLE)
    out = tmp_path / "ex.csv"
    write_measurements(out, m)
    _same_set(m, read_measurements(out))


_floats = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False, allow_infinity=False)
_coords = st.tuples(_floats, _floats, _floats)
_small = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False, allow_infinity=False)
_text_cell = st.text(max_size=12).map(str.strip)
_id_text = st.one_of(_text_cell, st.sampled_from(["#x", '"q"', "a,b", "é ü", "T\nN"]))
_BASE = np.array([[0.0, 0.0, 0.0], [1000.0, 0.0, 0.0], [0.0, 1000.0, 0.0]])


@st.composite
def measurement_sets(draw):
    rows = []  # (id, role, sensor, robot, time)
    time_values = st.one_of(st.just(math.nan), _floats)
    # three well-separated registration points (possibly repeated: repeats stay within 1 mm of the base)
    for k in range(3):
        role = draw(st.sampled_from(["registration", "both"]))
        ident = draw(_id_text) + f"~R{k}"
        for _ in range(draw(st.integers(1, 3))):
            d1 = np.array(draw(st.tuples(_small, _small, _small)))
            d2 = np.array(draw(st.tuples(_small, _small, _small)))
            rows.append((ident, role, _BASE[k] + d1, _BASE[k] * 1.5 + 7.0 + d2, draw(time_values)))
    # other points, any position
    for k in range(draw(st.integers(0, 6))):
        role = draw(st.sampled_from(["fiducial", "target", "check"]))
        ident = draw(_id_text) + f"~P{k}"
        for _ in range(draw(st.integers(1, 2))):
            s = np.array(draw(_coords))
            b = np.full(3, np.nan) if role == "target" else np.array(draw(_coords))
            rows.append((ident, role, s, b, draw(time_values)))
    order = draw(st.permutations(range(len(rows))))
    rows = [rows[i] for i in order]
    n = len(rows)
    extra_names = draw(st.lists(st.sampled_from(["label", "note", "q1"]), unique=True, max_size=3))
    extra = {name: tuple(draw(_text_cell) for _ in range(n)) for name in extra_names}
    return MeasurementSet(
        ids=tuple(r[0] for r in rows),
        roles=tuple(r[1] for r in rows),
        sensor=np.array([r[2] for r in rows]),
        robot=np.array([r[3] for r in rows]),
        time=np.array([r[4] for r in rows]),
        lines=(0,) * n,
        extra=extra,
    )


@settings(
    max_examples=100,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(mset=measurement_sets(), comments=st.lists(st.text(max_size=20), max_size=3))
def test_round_trip_property(tmp_path, mset, comments):
    validate(mset)
    out = tmp_path / "prop.csv"
    write_measurements(out, mset, comments)
    back = read_measurements(out)
    _same_set(mset, back)
    # and the text form parses to the same set as well
    _same_set(mset, parse_measurements(out.read_bytes().decode("utf-8"), "prop.csv"))


# ------------------------------------------------------------------------------------------- bad input

# (case name, file text, expected line number or None, expected field or None, extra substrings)
_REG3 = GOOD_ROWS[:3]
BAD_CASES = [
    ("empty file", "", None, None, ["no header"]),
    ("only comments", "# just a comment\n\n   \n# another\n", None, None, ["no header"]),
    ("missing required column", _text(*_REG3, header=HEADER.replace("sensor_y", "sy")), 1, "sensor_y", ["missing"]),
    (
        "missing robot column",
        "# c\n"
        + _text(*[r.rsplit(",", 4)[0] for r in _REG3], header="id,role,sensor_x,sensor_y,sensor_z,robot_x,robot_y"),
        2,
        "robot_z",
        ["missing"],
    ),
    ("column name case", _text(*_REG3, header=HEADER.replace("role", "Role")), 1, "role", ["case-sensitive"]),
    ("duplicate column", _text(*[r + ",x" for r in _REG3], header=HEADER + ",label"), 1, "label", ["twice"]),
    ("unnamed column", _text(*[r + ",x" for r in _REG3], header=HEADER + ","), 1, None, ["column 11", "no name"]),
    ("non-numeric sensor", _text(*_REG3, "F1,fiducial,1,abc,0,1,2,3,,"), 5, "sensor_y", ["'abc' is not a number"]),
    ("non-numeric robot", _text(*_REG3, "F1,fiducial,1,2,0,1,2,3 mm,,"), 5, "robot_z", ["'3 mm' is not a number"]),
    ("non-numeric time", _text(*_REG3, "F1,fiducial,1,2,0,1,2,3,12:00,"), 5, "time", ["'12:00' is not a number"]),
    ("nan value", _text(*_REG3, "F1,fiducial,1,2,0,nan,2,3,,"), 5, "robot_x", ["not a finite number"]),
    ("inf value", _text(*_REG3, "F1,fiducial,-inf,2,0,1,2,3,,"), 5, "sensor_x", ["not a finite number"]),
    ("infinity time", _text(*_REG3, "F1,fiducial,1,2,0,1,2,3,Infinity,"), 5, "time", ["not a finite number"]),
    ("overflow value", _text(*_REG3, "F1,fiducial,1e999,2,0,1,2,3,,"), 5, "sensor_x", ["not a finite number"]),
    ("empty sensor value", _text(*_REG3, "T1,target,1,,0,,,,,"), 5, "sensor_y", ["empty"]),
    ("too few cells", _text(*_REG3, "F1,fiducial,1,2,0,1,2,3"), 5, "time", ["8 cells", "header has 10"]),
    ("too many cells", _text(*_REG3, "F1,fiducial,1,2,0,1,2,3,,x,y"), 5, None, ["11 cells", "header has 10"]),
    ("bad quoting", _text(*_REG3, 'F1,"fid"x,1,2,0,1,2,3,,'), 5, None, ["malformed CSV"]),
    ("unterminated quote", _text(*_REG3, 'F1,fiducial,1,2,0,1,2,3,,"open', "# x"), 5, None, ["quote left open"]),
    (
        "unknown role",
        _text(*_REG3, "F1,fiducal,1,2,0,1,2,3,,"),
        5,
        "role",
        ["'fiducal' is not a valid role", "registration, fiducial, both, target, check"],
    ),
    ("role case", _text(*_REG3, "F1,Fiducial,1,2,0,1,2,3,,"), 5, "role", ["valid roles"]),
    ("empty id", _text(*_REG3, ",fiducial,1,2,0,1,2,3,,"), 5, "id", ["empty"]),
    ("blank id", _text(*_REG3, "   ,fiducial,1,2,0,1,2,3,,"), 5, "id", ["empty"]),
    (
        "robot missing registration",
        _text(GOOD_ROWS[0], "R2,registration,100,0,0,,,,,", GOOD_ROWS[2]),
        3,
        "robot_x",
        ["missing", "'registration'"],
    ),
    ("robot missing fiducial", _text(*_REG3, "F1,fiducial,1,2,0,,,,,"), 5, "robot_x", ["missing", "'fiducial'"]),
    ("robot missing both", _text(*_REG3[:2], "R3,both,0,100,0,,,,,"), 4, "robot_x", ["missing", "'both'"]),
    ("robot missing check", _text(*_REG3, "C1,check,1,2,0,,,,,"), 5, "robot_x", ["missing", "'check'", "truth"]),
    (
        "robot partial triple",
        _text(*_REG3, "F1,fiducial,1,2,0,1,,3,,"),
        5,
        "robot_y",
        ["missing", "only robot_x, robot_z given"],
    ),
    ("robot partial triple check", _text(*_REG3, "C1,check,1,2,0,1,2,,,"), 5, "robot_z", ["missing"]),
    ("no data rows", _text(), 1, "role", ["0 distinct registration points", "at least 3"]),
    (
        "no registration rows",
        "# c\n" + _text("F1,fiducial,1,2,0,1,2,3,,", "T1,target,1,1,0,,,,,"),
        2,
        "role",
        ["0 distinct registration points"],
    ),
    (
        "two registration points",
        _text(GOOD_ROWS[0], "F1,fiducial,1,2,0,1,2,3,,", GOOD_ROWS[1], GOOD_ROWS[4]),
        4,
        "role",
        ["2 distinct registration points", "'R1', 'R2'", "at least 3"],
    ),
    (
        "repeated registration id",
        _text(GOOD_ROWS[0], GOOD_ROWS[1], "R1,registration,0.1,0,0,10,20,30,,"),
        4,
        "role",
        ["2 distinct registration points"],
    ),
    (
        "coincident sensor",
        _text(*_REG3, "R4,registration,0.0004,0,0,50,60,70,,"),
        5,
        "sensor_x/y/z",
        ["'R4' (line 5)", "'R1' (line 2)", "coincide", "sensor frame"],
    ),
    (
        "coincident robot",
        _text(*_REG3, "R4,both,50,60,0,110,20,30.0001,,"),
        5,
        "robot_x/y/z",
        ["'R4' (line 5)", "'R2' (line 3)", "coincide", "robot frame"],
    ),
    (
        "collinear sensor",
        _text(
            "A,registration,0,0,0,0,0,0,,",
            "B,registration,100,0,0,100,0,0,,",
            "C,registration,200,0.5,0,200,100,0,,",
            "F1,fiducial,1,2,0,1,2,3,,",
        ),
        4,
        "sensor_x/y/z",
        ["collinear", "sensor frame", "'A', 'B', 'C'"],
    ),
    (
        "collinear robot",
        _text(
            "A,registration,0,0,0,0,0,0,,",
            "B,both,100,0,0,100,0,0,,",
            "C,registration,0,100,0,200,0,0,,",
            "T1,target,1,1,0,,,,,",
        ),
        4,
        "robot_x/y/z",
        ["collinear", "robot frame"],
    ),
    (
        "different roles",
        _text(*_REG3, "F1,fiducial,1,2,0,1,2,3,,", "F1,check,1,2,0,1,2,3,,"),
        6,
        "role",
        ["'F1'", "'check' here", "'fiducial' on line 5"],
    ),
    (
        "registration id reused as fiducial",
        _text(*_REG3, "R1,fiducial,0,0,0,10,20,30,,"),
        5,
        "role",
        ["'R1'", "line 2"],
    ),
]


@pytest.mark.parametrize("name,text,line,field,parts", BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_bad_input_parse(name, text, line, field, parts):
    with pytest.raises(InputError) as info:
        parse_measurements(text, "data.csv")
    expected = ["data.csv: "] + list(parts)
    if line is not None:
        expected.append(f"line {line}: ")
    else:
        assert "line " not in str(info.value).split(": ")[1]
    if field is not None:
        expected.append(f"field {field}: ")
    msg = _assert_one_line_error(info.value, *expected)
    assert msg.startswith("data.csv: ")


@pytest.mark.parametrize("name,text,line,field,parts", BAD_CASES[:12], ids=[c[0] for c in BAD_CASES[:12]])
def test_bad_input_read_file_names_the_path(tmp_path, name, text, line, field, parts):
    path = tmp_path / "data.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError) as info:
        read_measurements(path)
    _assert_one_line_error(info.value, f"{path}: ", *parts, *([f"line {line}: "] if line else []))


def test_example_message_format():
    with pytest.raises(InputError) as info:
        parse_measurements(_text(*_REG3, "X,fiducial,1,2,0,1,2,3,,", "F1,fiducial,1,abc,0,1,2,3,,"), "data.csv")
    assert str(info.value) == "data.csv: line 6: field sensor_y: 'abc' is not a number"


def test_missing_file(tmp_path):
    path = tmp_path / "nope.csv"
    with pytest.raises(InputError) as info:
        read_measurements(path)
    _assert_one_line_error(info.value, str(path), "cannot read")


def test_directory_is_not_a_file(tmp_path):
    with pytest.raises(InputError) as info:
        read_measurements(tmp_path)
    _assert_one_line_error(info.value, str(tmp_path), "cannot read")


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="needs a non-root POSIX user")
def test_unreadable_file(tmp_path):
    path = tmp_path / "locked.csv"
    path.write_text(_text(*GOOD_ROWS))
    path.chmod(0)
    try:
        with pytest.raises(InputError) as info:
            read_measurements(path)
        _assert_one_line_error(info.value, str(path), "cannot read")
    finally:
        path.chmod(0o644)


def test_unreadable_file_simulated(tmp_path, monkeypatch):
    path = tmp_path / "locked.csv"
    path.write_text(_text(*GOOD_ROWS))

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(meas, "open", denied, raising=False)
    with pytest.raises(InputError) as info:
        read_measurements(path)
    msg = _assert_one_line_error(info.value, str(path), "cannot read the file: Permission denied")
    assert msg == f"{path}: cannot read the file: Permission denied"


def test_rows_of_empty_cells_are_skipped():
    m = parse_measurements(_text(*GOOD_ROWS[:3], ",,,,,,,,,", " , ,,,,,,,,", GOOD_ROWS[3]), "e.csv")
    assert m.ids == ("R1", "R2", "R3", "F1") and m.lines == (2, 3, 4, 7)


def test_not_utf8(tmp_path):
    path = tmp_path / "latin1.csv"
    path.write_bytes(_text(*GOOD_ROWS[:2], "R3,both,0,100,0,10,120,30,,caf\xe9").encode("latin-1"))
    with pytest.raises(InputError) as info:
        read_measurements(path)
    _assert_one_line_error(info.value, f"{path}: line 4: ", "UTF-8", "0xe9")


def test_validate_in_memory_sets():
    good = parse_measurements(_text(*GOOD_ROWS), "g.csv")
    base = dict(
        ids=good.ids,
        roles=good.roles,
        sensor=good.sensor,
        robot=good.robot,
        time=good.time,
        lines=(0,) * len(good.ids),
        extra=good.extra,
    )
    validate(MeasurementSet(**base))

    def bad(fragment, **changes):
        with pytest.raises(InputError) as info:
            validate(MeasurementSet(**{**base, **changes}))
        msg = _assert_one_line_error(info.value, "<memory>: ", fragment)
        assert "line 0" not in msg
        return msg

    bad("field sensor: has shape (6, 2)", sensor=good.sensor[:, :2])
    bad("field roles", roles=good.roles[:-1])
    bad("field label: extra column has 5 values", extra={"label": good.extra["label"][:5]})
    bad("field time: an extra column cannot use", extra={"time": good.extra["label"]})
    bad("field role: 'bogus' is not a valid role", roles=("bogus",) + good.roles[1:])
    bad("field id: empty", ids=("",) + good.ids[1:])
    bad("field id: ' R1' has leading or trailing whitespace", ids=(" R1",) + good.ids[1:])
    s = good.sensor.copy()
    s[3, 2] = np.nan
    bad("field sensor_z: nan is not a finite number", sensor=s)
    r = good.robot.copy()
    r[5, 1] = np.nan
    bad("field robot_y: missing", robot=r)
    r = good.robot.copy()
    r[0, 0] = np.inf
    bad("field robot_x: inf is not a finite number", robot=r)
    t = good.time.copy()
    t[1] = -np.inf
    bad("field time: -inf", time=t)
    bad(
        "field role: id 'R1' has role 'fiducial' here but 'registration' on an earlier row",
        ids=("R1",) + good.ids[1:3] + ("R1",) + good.ids[4:],
    )
    r = good.robot.copy()
    r[2] = r[0]
    bad("coincide in the robot frame", robot=r)
    # with line numbers, messages carry them
    msg = bad(
        "line 3: field role",
        lines=(2, 3, 4, 5, 6, 7),
        roles=("registration", "registration", "check") + good.roles[3:],
        ids=good.ids,
    )
    assert "2 distinct registration points" in msg


# -------------------------------------------------------------------------------------- atomic writing


def _write_existing(path: Path) -> bytes:
    write_measurements(path, parse_measurements(_text(*GOOD_ROWS), "old"), ["old content"])
    return path.read_bytes()


@pytest.mark.parametrize("existing", [False, True])
def test_writer_is_atomic_when_a_row_fails(tmp_path, monkeypatch, existing):
    dest = tmp_path / "out.csv"
    before = _write_existing(dest) if existing else None
    m = read_measurements(EXAMPLE)
    calls = {"n": 0}
    real = meas_write._cell

    def failing(value):
        calls["n"] += 1
        if calls["n"] > 40:  # a few rows in
            raise RuntimeError("disk on fire")
        return real(value)

    monkeypatch.setattr(meas_write, "_cell", failing)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_measurements(dest, m)
    assert calls["n"] > 40
    if existing:
        assert dest.read_bytes() == before
    else:
        assert not dest.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == (["out.csv"] if existing else [])


def test_writer_is_atomic_when_replace_fails(tmp_path, monkeypatch):
    dest = tmp_path / "out.csv"
    before = _write_existing(dest)

    def no_replace(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(meas_write.os, "replace", no_replace)
    with pytest.raises(InputError) as info:
        write_measurements(dest, read_measurements(EXAMPLE))
    _assert_one_line_error(info.value, str(dest), "cannot write", "No space left")
    assert dest.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]


def test_writer_refuses_invalid_sets_and_writes_nothing(tmp_path):
    good = parse_measurements(_text(*GOOD_ROWS), "g.csv")
    bad = MeasurementSet(
        ids=good.ids,
        roles=("fiducial",) * 4 + ("target", "check"),
        sensor=good.sensor,
        robot=good.robot,
        time=good.time,
        lines=(0,) * 6,
    )
    with pytest.raises(InputError, match="registration points"):
        write_measurements(tmp_path / "x.csv", bad)
    assert list(tmp_path.iterdir()) == []


def test_writer_missing_directory_is_input_error(tmp_path):
    good = parse_measurements(_text(*GOOD_ROWS), "g.csv")
    target = tmp_path / "no" / "such" / "dir.csv"
    with pytest.raises(InputError) as info:
        write_measurements(target, good)
    _assert_one_line_error(info.value, str(target), "cannot write")


def test_writer_keeps_mode_of_existing_file(tmp_path):
    dest = tmp_path / "m.csv"
    _write_existing(dest)
    dest.chmod(0o640)
    write_measurements(dest, read_measurements(EXAMPLE))
    assert (dest.stat().st_mode & 0o777) == 0o640


def test_roles_constant():
    assert ROLES == ("registration", "fiducial", "both", "target", "check")


# ----------------------------------------------------------------------------- bounds (issue 16, item 4)
_HEAD = "id,role,sensor_x,sensor_y,sensor_z,robot_x,robot_y,robot_z,time\n"


@pytest.mark.parametrize(
    "cell, column, says",
    [
        ("\u0661\u0662", "sensor_x", "is not a number"),  # Arabic-Indic digits: the docs say ASCII only
        ("\uff11", "sensor_x", "is not a number"),  # a full-width digit
        ("1e200", "sensor_x", "out of range"),
        ("-2e9", "robot_z", "out of range"),
        ("1e300", "time", "out of range"),
    ],
)
def test_non_ascii_digits_and_huge_values_are_refused_naming_line_and_field(cell, column, says):
    cells = {"sensor_x": "1", "robot_z": "3", "time": "0"}
    cells[column] = cell
    text = _HEAD + f"A,fiducial,{cells['sensor_x']},2,3,1,2,{cells['robot_z']},{cells['time']}\n"
    with pytest.raises(meas.InputError) as e:
        meas.parse_measurements(text, "f.csv")
    msg = str(e.value)
    assert "line 2" in msg and column in msg and says in msg


def test_the_bounds_themselves_are_accepted():
    rows = [
        "A,both,0,0,0,0,0,0,1e12",
        "B,both,100,0,0,100,0,0,1",
        "C,both,0,100,0,0,100,0,2",
        "T,target,1e9,-1e9,3,,,,3",
    ]
    m = meas.parse_measurements(_HEAD + "\n".join(rows) + "\n", "f.csv")
    assert m.sensor[3, 0] == 1e9 and m.sensor[3, 1] == -1e9 and m.time[0] == 1e12


def test_member_of_is_numpys_isin_for_ids():
    """`io.id_sets.member_of` answers as `np.isin` does, for ids of any length, repeats and empty sets."""
    from rrbc_core.io.id_sets import member_of

    rng = np.random.default_rng(3)
    ids = np.array([f"P{k}" * (1 + k % 3) for k in rng.integers(0, 50, 200)], dtype=object)
    members = np.array([f"P{k}" * (1 + k % 3) for k in rng.integers(0, 80, 40)], dtype=object)
    np.testing.assert_array_equal(member_of(ids, members), np.isin(ids, members))
    np.testing.assert_array_equal(member_of(tuple(ids), list(members)), np.isin(ids, members))
    assert member_of((), ("a",)).shape == (0,) and not member_of(("a", "b"), ()).any()
