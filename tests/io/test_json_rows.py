"""Rows written from columns (`io.json_rows`, issue 41 item 3) are the rows `rrbc correct --json` builds as dicts:
`json.loads` gives the same values for every kind of row (targets and checks, stations, points off coplanar
fiducials, points without a bound, a Gaussian process's standard deviations), and the text is printable ASCII
whatever the ids hold."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.correction.stations import correct_stations
from rrbc_core.io.json_rows import Field, number_texts, rows_text, string_texts
from rrbc_core.io.json_stream import json_chunks
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.methods import MethodOptions
from rrbc_core.simulation.field_data import field_measurements
from rrbc_core.simulation.station_data import drawn_stations


def _same_document(result) -> None:
    streamed = "".join(json_chunks(result.to_json(lazy=True)))
    assert streamed.isascii() and streamed.isprintable()
    assert json.loads(streamed) == json.loads(json.dumps(result.to_json(), allow_nan=False))


def _board_below(seed: int) -> MeasurementSet:
    """Coplanar fiducials (z = 0) with checks and targets far above and beside them: off-plane rows, rows beyond
    what the folds tested (no bound: null)."""
    m = field_measurements(seed, n_fiducials=30, n_checks=40)
    sensor = np.array(m.sensor)
    fid = np.array([r in ("fiducial", "both") for r in m.roles])
    sensor[fid, 2] = 0.0
    far = np.flatnonzero(~fid)[:10]
    sensor[far] += np.array([0.0, 0.0, 900.0])
    sensor[np.flatnonzero(~fid)[10::4], 2] = 0.0  # some on the board's plane
    roles = tuple("target" if k % 3 == 0 and r == "check" else r for k, r in enumerate(m.roles))
    robot = np.array(m.robot)
    robot[fid] = np.array(m.robot)[fid] + (sensor[fid] - np.array(m.sensor)[fid])
    return MeasurementSet(m.ids, roles, sensor, robot, m.time, m.lines, m.source)


@pytest.mark.parametrize("case", ["volume", "board below", "gp", "stations", "no interpolation"])
def test_rows_from_columns_are_the_dict_rows(case):
    if case == "volume":
        res = correct_measurements(field_measurements(1, n_fiducials=40, n_checks=30))
    elif case == "board below":
        res = correct_measurements(_board_below(2))
    elif case == "gp":
        res = correct_measurements(
            field_measurements(3, n_fiducials=25, n_checks=20), MethodOptions.named("least-squares", "gp")
        )
    elif case == "stations":
        res = correct_stations(drawn_stations(3))
    else:
        res = correct_measurements(
            field_measurements(4, n_fiducials=20, n_checks=10), MethodOptions.named("least-squares", "none")
        )
    _same_document(res)


def test_the_board_case_has_what_it_claims():
    """The board file holds rows off the plane and rows without a bound, so the test above covers them."""
    j = correct_measurements(_board_below(2)).to_json()
    rows = j["checks"] + j["targets"]
    assert any("off_plane_mm" in r for r in rows) and any("off_plane_mm" not in r for r in rows)
    assert any(r["bound95_mm"] is None for r in rows) and any(r["bound95_mm"] is not None for r in rows)


@pytest.mark.parametrize("plain", [False, True], ids=["hostile ids", "plain ids"])
def test_strings_and_numbers_are_escaped_as_json_dumps_does(plain):
    ids = [
        "plain",
        'q"uote',
        "back\\slash",
        "tab\t",
        "esc\x1b[31m",
        "del\x7f",
        "é",
        "\u0085c1",
        "%d %s",
        "𝔘",
        "new\nline",
        "tab\there",
    ]
    if plain:
        ids = [f"P{k} x-y_z.{k}" for k in range(12)]
    texts = string_texts(ids)
    assert all(t.isascii() and t.decode().isprintable() for t in texts)
    assert [json.loads(t) for t in texts] == ids
    a = np.array([[1.0, np.nan, -0.0], [1e-7, 1e300, 5e-324]])
    assert [json.loads(t) for t in number_texts(a)] == [[1.0, None, -0.0], [1e-7, 1e300, 5e-324]]
    c = np.arange(18.0).reshape(2, 3, 3)
    assert [json.loads(t) for t in number_texts(c)] == c.tolist()
    assert number_texts(np.zeros((0, 3))) == [] and json.loads(number_texts(np.array([2.5]))[0]) == 2.5
    n = len(ids)
    fields = [
        Field("id", ids, "str"),
        Field("v", np.arange(n * 3.0).reshape(n, 3)),
        Field("maybe", np.arange(n * 1.0), present=np.arange(n) % 2 == 0),
        Field("flag", np.arange(n) % 3 == 0, "bool"),
        Field("obj", {"a%": np.arange(n * 1.0), "b": -np.arange(n * 1.0)}, "obj", null=np.arange(n) == 1),
    ]
    rows = json.loads(b"[" + rows_text(fields, n) + b"]")
    want = []
    for k in range(n):
        r = {"id": ids[k], "v": [3.0 * k, 3.0 * k + 1, 3.0 * k + 2]}
        if k % 2 == 0:
            r["maybe"] = float(k)
        r["flag"] = k % 3 == 0
        r["obj"] = None if k == 1 else {"a%": float(k), "b": -float(k)}
        want.append(r)
    assert rows == want
    assert [list(r) for r in rows] == [list(r) for r in want]  # the keys in the fields' order
    assert rows_text(fields, 0) == b""
