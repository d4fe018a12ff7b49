"""`rrbc diagnose` on files with stations and on checks far off the fiducials' plane (issue 28, items 1 and 4)."""

import json

import pytest

from rrbc_core.analysis.diagnosis import diagnose
from rrbc_core.analysis.diagnosis_stations import StationsDiagnosis, diagnose_stations
from rrbc_core.analysis.diagnosis_text import diagnosis_text
from rrbc_core.correction.stations import correct_stations
from rrbc_core.io.groups import split_groups
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.simulation.station_data import station_measurements
from tests.support.cli_run import rrbc


def test_each_station_is_diagnosed_on_its_own_at_the_split_alpha():
    mset = station_measurements(21, stations=3, eval_fiducials=0.5)
    dg = diagnose_stations(mset, alpha=0.03)
    assert isinstance(dg, StationsDiagnosis) and dg.groups == ("station1", "station2", "station3")
    for (_g, station), d in zip(split_groups(mset), dg.diagnoses):
        alone = diagnose(station, alpha=0.01)
        assert d.names == alone.names and d.alpha == pytest.approx(0.01)
        assert d.expected_rmst_change == pytest.approx(alone.expected_rmst_change)


def test_the_pooled_verdict_is_rrbc_corrects_pooled_figure():
    mset = station_measurements(22, stations=3, eval_fiducials=0.5)
    v = diagnose_stations(mset).rrbc()
    s = correct_stations(mset).summary()
    assert v["basis"] == "checks"
    assert v["rms_rigid_mm"] == pytest.approx(s["rmst_rigid_mm"]) and v["rms_rrbc_mm"] == pytest.approx(
        s["rmst_rrbc_mm"]
    )
    assert v["recommended"] == (s["rmst_rrbc_mm"] < s["rmst_rigid_mm"])


def test_the_field_planted_at_every_station_is_found_at_most_and_named_only_as_a_field():
    dg = diagnose_stations(station_measurements(23, stations=4, eval_fiducials=0.5, bias_mm=5.0))
    eff = dg.effects()
    assert len(eff.get("smooth_field", [])) >= 3
    assert "outliers" not in eff and "drift" not in eff


def test_the_command_line_reports_each_station(tmp_path):
    path = tmp_path / "st.csv"
    write_measurements(path, station_measurements(24, stations=2, eval_fiducials=0.5))
    out = rrbc("diagnose", path, "--json")
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert [g["group"] for g in data["groups"]] == ["station1", "station2"] and data["alpha_per_group"] == 0.005
    text = rrbc("diagnose", path).stdout
    assert "=== group 'station1' ===" in text and "=== all 2 groups" in text


def test_checks_off_the_fiducials_plane_are_said_on_their_own_line():
    """Fiducials on one plane (the stationing board), checks 160-420 mm above it: the text says how many checks are
    extrapolated and how far off the plane, on its own line, and the leave-one-out line says what it assumes."""
    dg = diagnose(station_measurements(25, stations=1, group_column=False))
    assert dg.basis == "checks" and dg.checks_extrapolation is not None
    lines = diagnosis_text(dg).splitlines()
    [extra] = [ln for ln in lines if ln.strip().startswith("extrapolated checks:")]
    assert "off the fiducials' plane by" in extra and "median" in extra
    [loo] = [ln for ln in lines if "leave-one-out over the paired points" in ln]
    assert "not the basis of the verdict" in loo and "which checks outside the fiducials' hull are not" in loo
    verdict = next(ln for ln in lines if ln.startswith("RRBC "))
    assert "at the file's check rows" in verdict and "leave-one-out" not in verdict
    assert dg.to_json()["rrbc"]["checks_extrapolation"] == dg.checks_extrapolation


def test_checks_inside_the_fiducials_say_nothing_of_extrapolation():
    from rrbc_core.io.measurements import read_measurements
    from tests.paths import EXAMPLE_CSV

    dg = diagnose(read_measurements(EXAMPLE_CSV))
    text = diagnosis_text(dg)
    assert (dg.checks_extrapolation is None) == ("extrapolated checks:" not in text)
