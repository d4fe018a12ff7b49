"""Files with stations, the `group` column (issue 28): each station registered and corrected on its own."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rrbc_core.correction import metrics
from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.correction.stations import StationsResult, correct_stations
from rrbc_core.errors import InputError
from rrbc_core.io.groups import split_groups
from rrbc_core.io.measurements import parse_measurements, read_measurements
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.methods import MethodOptions
from rrbc_core.simulation.station_data import station_measurements

RRBC = str(Path(sys.executable).with_name("rrbc"))


def test_each_station_is_the_file_of_its_rows(tmp_path):
    """A station's result is exactly that of a file holding only its rows (split by hand, no group column)."""
    mset = station_measurements(11, stations=3, eval_fiducials=0.5)
    result = correct_stations(mset, MethodOptions.named("least-squares", "tps"))
    assert isinstance(result, StationsResult) and result.groups == ("station1", "station2", "station3")
    values = mset.extra["group"]
    for g, station in zip(result.groups, result.stations):
        rows = [i for i, v in enumerate(values) if v == g]
        alone = station_measurements(11, stations=3, eval_fiducials=0.5, group_column=False)
        path = tmp_path / f"{g}.csv"
        from rrbc_core.io.groups import select_rows

        write_measurements(path, select_rows(alone, rows))
        by_hand = correct_measurements(read_measurements(path), MethodOptions.named("least-squares", "tps"))
        np.testing.assert_allclose(station.error_rrbc, by_hand.error_rrbc, atol=1e-9)
        assert station.registration.fre_rms_mm == pytest.approx(by_hand.registration.fre_rms_mm, abs=1e-9)


def test_pooled_figures_are_over_all_stations_checks():
    result = correct_stations(station_measurements(12, stations=4))
    rigid = np.concatenate([r.error_rigid for r in result.stations])
    rrbc = np.concatenate([r.error_rrbc for r in result.stations])
    s = result.summary()
    assert s["checks"] == len(rigid) == result.statistics().n
    assert s["rmst_rigid_mm"] == pytest.approx(metrics.rmst(rigid)) and s["rmst_rrbc_mm"] == pytest.approx(
        metrics.rmst(rrbc)
    )
    assert result.statistics().rigid["rms"] == pytest.approx(s["rmst_rigid_mm"])


@pytest.mark.parametrize("seed", range(5))
def test_stations_registered_apart_fit_better_than_one_registration_over_all(seed):
    """What real files show (4.2-5.3 mm FRE pooled against 1.0-2.7 mm per station): each station's FRE is below
    the pooled registration's; and with fiducials around the checks, RRBC per station beats RRBC on the pool (whose
    fiducials carry other stations' corrections)."""
    grouped = correct_stations(station_measurements(seed, eval_fiducials=0.5))
    pooled = correct_measurements(station_measurements(seed, eval_fiducials=0.5, group_column=False))
    assert max(r.registration.fre_rms_mm for r in grouped.stations) < pooled.registration.fre_rms_mm
    assert grouped.summary()["rmst_rrbc_mm"] < pooled.summary()["rmst_rrbc_mm"]


def _csv(rows):
    head = "id,role,sensor_x,sensor_y,sensor_z,robot_x,robot_y,robot_z,group\n"
    return head + "\n".join(rows) + "\n"


def test_a_station_without_three_registration_points_is_refused_by_name():
    rows = [f"R{i},both,{x},{y},0,{x},{y},0,A" for i, (x, y) in enumerate([(0, 0), (100, 0), (0, 100), (100, 100)])]
    rows += [f"Q{i},both,{x},{y},0,{x},{y},0,B" for i, (x, y) in enumerate([(0, 0), (100, 0)])]
    with pytest.raises(InputError, match=r"group 'B'.*2 distinct registration points"):
        parse_measurements(_csv(rows), "f.csv")


def test_the_same_id_in_two_stations_is_two_points():
    rows = []
    for g, dz in (("A", 0.0), ("B", 50.0)):
        rows += [
            f"R{i},both,{x},{y},{dz},{x + 1},{y},{dz}," + g
            for i, (x, y) in enumerate([(0, 0), (100, 0), (0, 100), (90, 90)])
        ]
        rows.append(f"C1,check,50,50,{dz + 10},51,50,{dz + 10},{g}")
    mset = parse_measurements(_csv(rows), "f.csv")
    assert [len(m.points("registration")) for _, m in split_groups(mset)] == [4, 4]


def test_an_empty_group_value_is_refused():
    rows = [f"R{i},both,{x},{y},0,{x},{y},0,A" for i, (x, y) in enumerate([(0, 0), (100, 0), (0, 100)])]
    rows.append("C1,check,5,5,5,5,5,5,")
    with pytest.raises(InputError, match="empty group"):
        parse_measurements(_csv(rows), "f.csv")


def test_the_command_line_reports_each_station_and_the_pool(tmp_path):
    path = tmp_path / "stations.csv"
    write_measurements(path, station_measurements(13, stations=3, eval_fiducials=0.5))
    out = subprocess.run([RRBC, "correct", str(path), "--json"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert [g["group"] for g in data["groups"]] == ["station1", "station2", "station3"]
    expected = correct_stations(read_measurements(path)).to_json()
    assert data["summary"]["rmst_rrbc_mm"] == pytest.approx(expected["summary"]["rmst_rrbc_mm"])
    assert data["warnings"] == expected["warnings"]
    text = subprocess.run([RRBC, "correct", str(path)], capture_output=True, text=True, timeout=120).stdout
    assert "=== group 'station2' ===" in text and "=== all 3 groups" in text
    rmst = data["summary"]["rmst_rrbc_mm"]
    assert f"RRBC {rmst:.4f} mm" in text
