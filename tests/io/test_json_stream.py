"""`rrbc correct --json` written as it is made (issue 41, item 3: a streamed JSON writer): the same document as one
`json.dumps` of the whole object (compact), rows readable twice (the file and stdout), and the memory of a long
file's rows not held at once."""

from __future__ import annotations

import json
import tracemalloc

import pytest

from rrbc_core.correction.stations import correct_stations
from rrbc_core.errors import printable_bytes
from rrbc_core.io.json_stream import LazyRows, PrintableAscii, json_bytes, json_chunks, to_plain
from rrbc_core.io.measurements import read_measurements
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.simulation.field_data import field_measurements
from rrbc_core.simulation.station_data import drawn_stations
from tests.paths import EXAMPLE_CSV
from tests.support.cli_run import rrbc


def test_the_streamed_text_is_json_dumps_of_the_whole_object():
    rows = LazyRows(3, lambda: ({"id": f"T{i}", "x": [i, 0.5, None]} for i in range(3)))
    obj = {"a": 1, "groups": [{"group": "g", "targets": rows, "n": 2.5}], "rows": rows, "empty": LazyRows(0, list)}
    text = "".join(json_chunks(obj))
    assert text == json.dumps(to_plain(obj), allow_nan=False, separators=(",", ":"))
    assert list(rows) == list(rows) and len(rows) == 3  # made afresh each time it is read
    with pytest.raises(ValueError):  # NaN refused, as json.dumps(allow_nan=False) does
        "".join(json_chunks({"x": LazyRows(1, lambda: [{"v": float("nan")}])}))


def test_the_streamed_bytes_are_printable_ascii_whatever_the_strings_hold():
    """The CLI writes `json_bytes`' pieces without checking them for a terminal (`PrintableAscii`): a NUL, an escape,
    DEL, a C1 control and non-ASCII in ids and keys are escaped, and the document reads back the same."""
    odd = "a\x00b\x1b[31mc\x7fd\x9fé€"
    rows = LazyRows(2, lambda: ({"id": odd + str(i), odd: [i]} for i in range(2)))
    obj = {"warning": odd, "rows": rows, odd: {"k": [odd]}}
    pieces = list(json_bytes(obj))
    assert pieces and all(isinstance(p, PrintableAscii) for p in pieces)
    data = b"".join(pieces)
    assert data.isascii() and printable_bytes(data) == data
    assert json.loads(data) == to_plain(obj)


@pytest.mark.parametrize("grouped", [False, True], ids=["one station", "stations"])
def test_rrbc_correct_json_is_the_whole_objects_text(tmp_path, grouped):
    path = EXAMPLE_CSV
    if grouped:
        path = tmp_path / "stations.csv"
        write_measurements(path, drawn_stations(3))
    out = rrbc("correct", path, "--json", "--out", tmp_path / "corrected.csv")
    assert out.returncode == 0, out.stderr
    whole = correct_stations(read_measurements(path)).to_json()
    assert out.stdout.endswith("\n") and out.stdout.isascii()
    assert json.loads(out.stdout) == json.loads(json.dumps(whole, allow_nan=False))
    assert (tmp_path / "corrected.csv").read_text().count("\n") > 1  # the rows were read for the file too


def test_a_long_files_rows_are_not_held_at_once(monkeypatch):
    """20 000 checks made 2000 at a time: the streamed text's peak Python memory is under a quarter of the whole
    object's and its text (ten chunks: a tenth of the rows at once, and pieces of text of about 1 MB)."""
    from rrbc_core.correction import pipeline

    monkeypatch.setattr(pipeline, "ROWS_PER_CHUNK", 2000)
    m = field_measurements(3, n_fiducials=200, n_checks=20_000)
    res = correct_stations(m)
    res.to_json()  # the bounds and everything cached, outside the measurement

    def peak(fn) -> int:
        tracemalloc.start()
        fn()
        _, top = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        return top

    def streamed():
        for _ in json_chunks(res.to_json(lazy=True)):
            pass

    eager = peak(lambda: json.dumps(res.to_json(), allow_nan=False))
    lazy = peak(streamed)
    assert lazy < 0.25 * eager, (lazy, eager)
