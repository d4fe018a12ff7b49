"""`rrbc report` (issue 40, item 1): the JSON contract, the verdict flipping at the right tolerance, its figures
equal to `rrbc correct`'s and `rrbc calibrate`'s, stations and joints, and a self-contained HTML page that lists
every check (the page opened in Chromium: tests/browser/test_report_browser.py)."""

import json
import re

import pytest

from rrbc_core.analysis.acceptance import verdict_of
from rrbc_core.analysis.vec_compare import compare
from rrbc_core.correction.stations import correct_stations
from rrbc_core.io.measurements import read_measurements
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.simulation.station_data import station_measurements
from rrbc_core.studies.vec_study import joint_measurements
from tests.paths import ROOT
from tests.support.cli_run import rrbc

EXAMPLE = ROOT / "rrbc_core" / "data" / "example_measurements.csv"


def run(*args, timeout=300):
    return rrbc(*args, timeout=timeout)  # in this process (tests/support/cli_run.py)


def _report(*args) -> dict:
    r = run("report", *args, "--json")
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def _worst(acc: dict) -> tuple[float, str]:
    """The largest figure the verdict holds against the tolerance, and its point's id."""
    m = acc["recommended"]
    figs = [
        ((p["error_mm"] or {}).get(m) if p["role"] == "check" else (p["bound95_mm"] or {}).get(m), p["id"])
        for p in acc["points"]
    ]
    return max((v, i) for v, i in figs if v is not None)


def test_the_verdict_flips_at_the_worst_point_and_its_figures_are_rrbc_corrects(tmp_path):
    out = tmp_path / "report.html"
    r = run("report", EXAMPLE, "--json", "--out", out)
    assert r.returncode == 0, r.stderr
    acc = json.loads(r.stdout)
    assert {"verdict", "tolerance_mm", "criterion", "failing", "methods", "points"} <= set(acc)
    assert acc["verdict"] == "UNDECIDED" and acc["tolerance_mm"] is None  # no tolerance: no verdict
    worst, wid = _worst(acc)
    v, failing, _ = verdict_of(acc["points"], acc["recommended"], worst * 1.001)
    assert v == "PASS" and failing == []
    v, failing, _ = verdict_of(acc["points"], acc["recommended"], worst * 0.999)
    assert v == "FAIL" and [f["id"] for f in failing] == [wid]
    # through the command, with the tolerance given: the same verdict, in words
    text = run("report", EXAMPLE, "--tolerance", worst * 0.999).stdout
    assert text.startswith("verdict: FAIL") and "beyond: " in text and wid in text
    # one answer: the points' figures are rrbc correct's own
    cj = correct_stations(read_measurements(EXAMPLE)).to_json()
    by_id = {p["id"]: p for p in acc["points"]}
    assert len(by_id) == len(cj["targets"]) + len(cj["checks"])
    for tg in cj["targets"]:
        assert by_id[tg["id"]]["bound95_mm"]["rrbc"] == tg["bound95_mm"]
        assert by_id[tg["id"]]["robot"]["rrbc"] == tg["robot_rrbc"]
    for c in cj["checks"]:
        assert by_id[c["id"]]["error_mm"] == {"rigid": c["error_rigid_mm"], "rrbc": c["error_rrbc_mm"]}
    assert acc["methods"]["rrbc"]["rmst_mm"] == cj["summary"]["rmst_rrbc_mm"]
    # the page: self-contained, both figures, every point listed, the verdict shown
    html = out.read_text()
    assert not re.search(r"""(src|href)\s*=\s*['"](https?:)?//""", html)  # nothing fetched from anywhere
    assert html.count("src='data:image/png;base64,") == 2  # the histogram and the error-against-distance plot
    for p in acc["points"]:
        assert f'<td class="l">{p["id"]}</td>' in html
    assert f">{acc['verdict']}</span>" in html
    assert "RRBC (idw, neighbors 4, power 2)" in html  # the chosen interpolation, named on the page
    # a failing figure is printed with the decimals it takes to read it beyond the tolerance
    tight, tol = tmp_path / "tight.html", worst - 1e-5  # only the worst point beyond, by 0.00001 mm
    assert run("report", EXAMPLE, "--tolerance", tol, "--out", tight).returncode == 0
    beyond = tight.read_text().split("<h2>Points beyond the tolerance</h2>")[1].split("</table>")[0]
    cells = re.findall(r'<td class="">([0-9.]+)</td></tr>', beyond)
    assert len(cells) == 1 and float(cells[0]) > tol, (tol, cells)


def test_stations_and_joints(tmp_path):
    data = tmp_path / "stations.csv"
    write_measurements(data, station_measurements(5, stations=3))
    acc = _report(data, "--tolerance", "1.0")
    assert len(acc["measured"]["stations"]) == 3 and len(acc["registration"]) == 3
    assert all(p["group"] is not None for p in acc["points"])
    assert all(f["group"] is not None for f in acc["failing"])
    arm = tmp_path / "arm.csv"
    write_measurements(arm, joint_measurements(2, n_fid=40, n_chk=30))
    acc = _report(arm, "--robot", "ur5", "--tool", "100", "--tolerance", "0.5")
    cal = compare(read_measurements(arm), robot="ur5", tool=100.0)  # rrbc calibrate's function
    assert set(acc["methods"]) == {"rigid", "rrbc", "vec", "vec_rrbc"}
    assert acc["recommended"] == cal["recommended"]
    assert acc["arm_transform"] == cal["sensor_to_robot"] and "matrix_4x4" in acc["arm_transform"]
    page = tmp_path / "arm.html"
    assert run("report", arm, "--robot", "ur5", "--tool", "100", "--out", page).returncode == 0
    assert "VEC: identified with the arm" in page.read_text()
    checks = {c["id"]: c for c in cal["check_points"]}
    for p in acc["points"]:
        if p["role"] == "check":
            assert p["error_mm"] == checks[p["id"]]["error_mm"]
            assert p["bound95_mm"] == checks[p["id"]]["bound95_mm"]


def test_a_report_with_an_arm_runs_diagnose_once_and_calibrate_judges_the_arm_the_same(tmp_path, monkeypatch):
    """The report's diagnosis is the call calibrate's arm verdict makes (same model, level and seed): reused, not
    run twice, and the verdict is the one `compare` reaches on its own."""
    from rrbc_core.analysis import acceptance, diagnosis_stations

    arm = tmp_path / "arm.csv"
    write_measurements(arm, joint_measurements(3, dh_size=1.0, n_fid=40, n_chk=30))
    mset = read_measurements(arm)
    alone = compare(mset, robot="ur5", tool=100.0)["kinematic_error"]["verdict"]
    calls, real = [], diagnosis_stations.diagnose_stations
    monkeypatch.setattr(diagnosis_stations, "diagnose_stations", lambda *a, **k: calls.append(1) or real(*a, **k))
    seen = {}
    original = acceptance._with_calibration
    monkeypatch.setattr(acceptance, "_with_calibration", lambda pts, cal: seen.update(cal) or original(pts, cal))
    acceptance.acceptance(mset, robot="ur5", tool=100.0)
    assert len(calls) == 1
    assert seen["kinematic_error"]["verdict"] == alone


def test_bad_input_is_one_line_and_writes_nothing(tmp_path):
    for args in (
        ("--tolerance", "-1"),
        ("--tolerance", "nan"),
        ("--out", tmp_path / "missing" / "r.html"),
        ("--robot", "ur5", "--urdf", "ur5"),
    ):
        r = run("report", EXAMPLE, *args)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, (args, r.stderr)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "points, expect",
    [
        ([], "UNDECIDED"),
        ([{"id": "T", "role": "target", "group": None, "bound95_mm": {"rrbc": None}}], "UNDECIDED"),
        ([{"id": "T", "role": "target", "group": None, "bound95_mm": {"rrbc": 0.2}}], "PASS"),
        (
            [
                {"id": "T", "role": "target", "group": None, "bound95_mm": {"rrbc": None}},
                {"id": "C", "role": "check", "group": None, "error_mm": {"rrbc": 0.7}, "bound95_mm": {}},
            ],
            "FAIL",
        ),
    ],
)
def test_verdict_cases(points, expect):
    v, failing, reason = verdict_of(points, "rrbc", 0.5)
    assert v == expect and reason
    assert [f["id"] for f in failing] == (["C"] if expect == "FAIL" else [])
