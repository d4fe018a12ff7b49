"""`rrbc correct`'s per-point bounds through the console script (issue 37, item 1; contract in docs/cli.md): the JSON
keys on every target and check, the text's bound column equal to the JSON, the instrument flags and their refusals."""

import json

import numpy as np
import pytest

from rrbc_core.correction.bound_radius import bound95
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.simulation.field_data import field_measurements
from rrbc_core.simulation.station_data import station_measurements
from tests.paths import ROOT
from tests.support.cli_run import rrbc

EXAMPLE = ROOT / "rrbc_core" / "data" / "example_measurements.csv"


def run(*args, timeout=300):
    return rrbc(*args, timeout=timeout)  # in this process (tests/support/cli_run.py)


def _check_row(row: dict, suffix: str = "") -> None:
    b = row[f"bound95{suffix}_mm"]
    if b is None:
        assert row[f"budget{suffix}_mm"] is None and row.get(f"cov{suffix}_mm2") is None
        return
    budget = row[f"budget{suffix}_mm"]
    if suffix:  # rigid's: its bound and budget (no covariance)
        assert f"cov{suffix}_mm2" not in row and b >= max(budget.values())
        return
    cov = np.array(row[f"cov{suffix}_mm2"])
    assert cov.shape == (3, 3) and np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) >= -1e-12)
    assert b == pytest.approx(bound95(cov[None])[0], rel=1e-9)
    assert set(budget) <= {"instrument", "registration", "interpolation", "arm"} and "instrument" in budget
    # the budget's parts are RMS contributions of covariances that sum to cov
    assert sum(v**2 for v in budget.values()) == pytest.approx(np.trace(cov), rel=1e-9)


def test_every_target_and_check_has_its_bound_and_the_text_shows_the_same_numbers():
    out = run("correct", EXAMPLE, "--json")
    assert out.returncode == 0, out.stderr
    j = json.loads(out.stdout)
    assert j["bounds"]["level"] == 0.95 and j["bounds"]["instrument"]["source"]
    for kind in ("targets", "checks"):
        assert j[kind]
        for row in j[kind]:
            _check_row(row)
            _check_row(row, "_rigid")
    text = run("correct", EXAMPLE).stdout
    assert "bound95" in text and "instrument:" in text
    for row in j["targets"] + j["checks"]:
        line = next(ln for ln in text.splitlines() if ln.split() and ln.split()[0] == row["id"])
        assert float(line.split()[7]) == round(row["bound95_mm"], 4)


def test_the_instrument_flags_reach_the_bounds_and_say_where_their_figures_came_from():
    j = json.loads(run("correct", EXAMPLE, "--json", "--instrument", "tracker", "--robot-noise-mm", "0.03").stdout)
    inst = j["bounds"]["instrument"]
    assert inst["name"] == "tracker" and inst["kind"] == "polar" and inst["robot_mm"] == 0.03
    j2 = json.loads(run("correct", EXAMPLE, "--json", "--sensor-noise-mm", "0.2").stdout)
    assert j2["bounds"]["instrument"]["sigma_mm"] == 0.2 and "given" in j2["bounds"]["instrument"]["source"]
    # a noisier instrument widens every check's instrument share
    a = [r["budget_mm"]["instrument"] for r in j["checks"]]
    b = [r["budget_mm"]["instrument"] for r in j2["checks"]]
    assert min(b) > max(a)


@pytest.mark.parametrize(
    "flags",
    [
        ("--instrument", "laser"),
        ("--sensor-noise-mm", "-1"),
        ("--sensor-noise-mm", "nan"),
        ("--robot-noise-mm", "1e9"),
        ("--instrument", "total-station", "--sensor-noise-mm", "0.1"),
        ("--sensor-noise-mm", "0.1", "--angle-noise-urad", "3"),
        ("--angle-noise-urad", "abc"),
    ],
)
def test_noise_figures_that_cannot_be_are_refused_in_one_line(flags):
    out = run("correct", EXAMPLE, *flags)
    assert out.returncode == 2 and out.stdout == ""
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr


def test_stations_are_bounded_each_from_its_own_rows(tmp_path):
    f = tmp_path / "stations.csv"
    write_measurements(f, station_measurements(3, stations=3, eval_fiducials=0.5))
    j = json.loads(run("correct", f, "--json").stdout)
    assert len(j["groups"]) == 3
    for g in j["groups"]:
        assert g["bounds"]["interpolation_profile"]["fiducials"] > 0
        assert any(r["bound95_mm"] is not None for r in g["checks"])


def test_a_check_without_a_bound_is_null_and_warned_about(tmp_path):
    f = tmp_path / "plane.csv"
    write_measurements(f, field_measurements(5, layout="plane"))
    j = json.loads(run("correct", f, "--json").stdout)
    nulls = [r for r in j["checks"] if r["bound95_mm"] is None]
    assert nulls and any("no bound for" in w for w in j["warnings"])
    text = run("correct", f).stdout
    assert any(ln.split()[0] == nulls[0]["id"] and " - " in ln for ln in text.splitlines() if ln.split())
