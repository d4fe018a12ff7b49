"""What an integrator hands on (issue 40, item 2): `rrbc correct --out` writes the corrected targets and checks as a
CSV equal to `--json`'s numbers, with stations too, nothing on a bad path; the sensor-to-robot transform in the forms
controllers and ROS take (4x4, xyz, rpy), in `correct` and `calibrate`."""

import csv
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rrbc_core.geometry.transforms import RigidTransform
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.simulation.station_data import station_measurements
from tests.paths import ROOT
from tests.support.cli_run import rrbc

EXAMPLE = ROOT / "rrbc_core" / "data" / "example_measurements.csv"


def run(*args, timeout=300):
    return rrbc(*args, timeout=timeout)  # in this process (tests/support/cli_run.py)


def _read(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _same_rows(rows, parts):
    """The CSV rows hold each JSON target's and check's corrected position, bound and flag, in order."""
    expect = [
        (p.get("group"), role, q)
        for p in parts
        for role, key in (("target", "targets"), ("check", "checks"))
        for q in p[key]
    ]
    assert len(rows) == len(expect) > 0
    for row, (group, role, q) in zip(rows, expect):
        assert row["id"] == q["id"] and row["role"] == role
        if group is not None:
            assert row["group"] == group
        assert [float(row[c]) for c in ("robot_x", "robot_y", "robot_z")] == q["robot_rrbc"]  # repr: exact
        b = q.get("bound95_mm")
        assert (row["bound95_mm"] == "") if b is None else float(row["bound95_mm"]) == b
        assert row["extrapolated"] == ("true" if q["extrapolated"] else "false")


def test_correct_out_writes_the_json_numbers_as_a_csv(tmp_path):
    out = tmp_path / "corrected.csv"
    r = run("correct", EXAMPLE, "--out", out)
    assert r.returncode == 0, r.stderr
    assert f"corrected targets and checks to {out}" in r.stdout
    # --json with --out: stdout stays one JSON object, the file the same as the text run's
    r2 = run("correct", EXAMPLE, "--json", "--out", tmp_path / "again.csv")
    j = json.loads(r2.stdout)
    assert (tmp_path / "again.csv").read_text() == out.read_text()
    rows = _read(out)
    assert list(rows[0]) == ["id", "role", "robot_x", "robot_y", "robot_z", "bound95_mm", "extrapolated"]
    _same_rows(rows, [j])


def test_correct_out_with_stations_names_each_rows_station(tmp_path):
    data = tmp_path / "stations.csv"
    write_measurements(data, station_measurements(3, stations=3))
    out = tmp_path / "corrected.csv"
    r = run("correct", data, "--json", "--out", out)
    assert r.returncode == 0, r.stderr
    rows = _read(out)
    assert list(rows[0])[:3] == ["id", "role", "group"]
    _same_rows(rows, json.loads(r.stdout)["groups"])


def test_a_bad_out_path_is_refused_first_and_nothing_is_written(tmp_path):
    for bad in (tmp_path / "no" / "such" / "x.csv", tmp_path):
        r = run("correct", EXAMPLE, "--out", bad)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.parametrize("seed", range(6))
def test_rpy_is_the_urdf_convention_and_the_forms_agree(seed):
    rng = np.random.default_rng(seed)
    rpy = rng.uniform([-np.pi, -np.pi / 2, -np.pi], [np.pi, np.pi / 2, np.pi])
    if seed == 5:
        rpy[1] = np.pi / 2  # gimbal lock: the rotation is still reproduced
    rot = Rotation.from_euler("xyz", rpy).as_matrix()  # fixed axes x, y, z: URDF's rpy
    tr = RigidTransform(rot, rng.uniform(-2000, 2000, 3))
    forms = tr.export_forms()
    back = Rotation.from_euler("xyz", forms["rpy_rad"]).as_matrix()
    assert np.allclose(back, rot, atol=1e-9)
    if seed != 5:
        assert np.allclose(forms["rpy_rad"], rpy, atol=1e-9)
    m = np.array(forms["matrix_4x4"])
    assert np.allclose(m[:3, :3], rot) and np.allclose(m[:3, 3], forms["xyz_mm"]) and m[3].tolist() == [0, 0, 0, 1]
    assert np.allclose(np.array(forms["xyz_m"]) * 1000.0, forms["xyz_mm"])


def test_correct_and_calibrate_give_the_transform_in_every_form(tmp_path):
    j = json.loads(run("correct", EXAMPLE, "--json").stdout)["registration"]
    tr = RigidTransform(j["rotation"], j["translation"])
    assert j["matrix_4x4"] == tr.as_matrix().tolist() and j["rpy_rad"] == tr.rpy().tolist()
    from rrbc_core.studies.vec_study import joint_measurements

    data = tmp_path / "arm.csv"
    write_measurements(data, joint_measurements(1, n_fid=20, n_chk=10))
    r = run("calibrate", data, "--robot", "ur5", "--tool", "100", "--json")
    assert r.returncode == 0, r.stderr
    s2r = json.loads(r.stdout)["sensor_to_robot"]
    tr = RigidTransform(s2r["rotation"], s2r["translation"])
    assert s2r["matrix_4x4"] == tr.as_matrix().tolist() and s2r["rpy_rad"] == tr.rpy().tolist()
