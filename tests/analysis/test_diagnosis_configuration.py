"""`rrbc diagnose` names the arm without its model (issue 38, item 3: "the sensor blamed for the arm"): on a file with
joint-like columns and no arm model, residuals that follow the joint configuration are named `kinematic` (model
"none": the arm's error, not identified), and the sensor effects the arm explains are not named beside it; a sensor
scale or a sensor field with the arm clean is still the sensor's, and a clean file names nothing of the arm.

Seeded UR5 files (`vec_study.joint_measurements`: hundreds of poses, the joints in degrees) whose q1..q6 columns are
renamed joint_1..joint_6, so that the default UR5 test cannot read them: the model-free test
(`diagnosis_arm.configuration_columns`) is what runs."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rrbc_core.analysis.diagnosis import diagnose
from rrbc_core.analysis.diagnosis_arm import configuration_columns
from rrbc_core.studies.vec_study import TOOL_MM, joint_measurements

ALPHA = 0.01


def _renamed(mset):
    extra = {(f"joint_{k[1:]}" if k.startswith("q") else k): v for k, v in mset.extra.items()}
    return dataclasses.replace(mset, extra=extra)


def _scaled(mset, ppm: float):
    """The sensor's readings scaled about their centroid (a sensor scale error of `ppm`)."""
    s = np.asarray(mset.sensor, float)
    ok = np.all(np.isfinite(s), axis=1)
    c = s[ok].mean(axis=0)
    return dataclasses.replace(mset, sensor=c + (1.0 + ppm * 1e-6) * (s - c))


def _rigid_rms(mset) -> float:
    from rrbc_core.registration.strategies import least_squares

    s, b = np.asarray(mset.sensor, float), np.asarray(mset.robot, float)
    ok = np.all(np.isfinite(s), axis=1) & np.all(np.isfinite(b), axis=1)
    reg = least_squares(s[ok], b[ok])
    return float(np.sqrt(np.mean(np.sum((b[ok] - reg.mapping.apply(s[ok])) ** 2, axis=1))))


@pytest.mark.parametrize("seed", [2, 5, 8])
def test_an_arm_error_is_named_as_the_arm_without_a_model(seed):
    m = _renamed(joint_measurements(seed, dh_size=3.0, n_fid=200, n_chk=60))
    res = diagnose(m, alpha=ALPHA, seed=0)
    by = {e.name: e for e in res.effects}
    assert "kinematic" in by, [e.name for e in res.effects]
    k = by["kinematic"]
    assert k.parameters["model"] == "none" and k.parameters["robot"] is None
    assert k.parameters["joint_columns"] == [f"joint_{i}" for i in range(1, 7)]
    assert "--urdf ROBOT.urdf --tip LINK" in k.evidence
    # an honest size: never more than what the rigid fit leaves
    assert 0 < k.magnitude_mm <= _rigid_rms(m) + 3 * 0.02  # (the files' noise: 0.02 mm per axis)
    # the same file with its model: the arm tested and identified, as before
    tested = diagnose(joint_measurements(seed, dh_size=3.0, n_fid=200, n_chk=60), robot="ur5", tool_mm=TOOL_MM)
    by_model = {e.name: e for e in tested.effects}
    assert "kinematic" in by_model
    # and the size without the model is the arm's: within 10 % of the size the model gives
    assert abs(k.magnitude_mm / by_model["kinematic"].magnitude_mm - 1) < 0.10


def test_a_clean_arm_names_nothing_of_the_arm():
    """Noise only, 10 seeds: the model-free test is one more F-test at alpha / m; `kinematic` named on at most 2
    (binomial: P(>= 3 of 10) < 1e-4 at the family's alpha 0.01)."""
    named = 0
    for seed in range(10):
        m = _renamed(joint_measurements(100 + seed, dh_size=0.0, n_fid=200, n_chk=20))
        named += "kinematic" in {e.name for e in diagnose(m, alpha=ALPHA, seed=0).effects}
    assert named <= 2, named


def test_a_sensor_scale_with_a_clean_arm_is_the_sensors():
    m = _scaled(_renamed(joint_measurements(11, dh_size=0.0, n_fid=200, n_chk=20)), 300.0)
    names = {e.name for e in diagnose(m, alpha=ALPHA, seed=0).effects}
    assert "scale" in names and "kinematic" not in names, names


def test_a_sensor_field_with_a_clean_arm_is_not_named_the_arms():
    m = _renamed(joint_measurements(12, dh_size=0.0, field_mm=0.3, n_fid=200, n_chk=20))
    names = {e.name for e in diagnose(m, alpha=ALPHA, seed=0).effects}
    assert "kinematic" not in names, names


def test_too_few_points_for_the_harmonics_say_so():
    m = _renamed(joint_measurements(3, dh_size=3.0, n_fid=20, n_chk=10))
    limits: list[str] = []
    from rrbc_core.analysis.diagnosis_stats import paired

    d = paired(m)
    assert configuration_columns(m, d.rows, d.row_point, len(d.ids), limits) is None
    assert any("needs" in x and "harmonics" in x for x in limits), limits
    res = diagnose(m, alpha=ALPHA, seed=0)
    assert "kinematic" not in {e.name for e in res.effects}
    assert any("harmonics of the joint values" in x for x in res.limits)


def test_a_scale_beyond_what_the_instrument_plausibly_has_is_called_implausible(tmp_path):
    """`--instrument`: 300 ppm is more than a tracker has (10 ppm), not more than a stereo camera's (5000 ppm)."""
    from rrbc_core.io.measurements_write import write_measurements
    from tests.support.cli_run import rrbc

    m = _scaled(_renamed(joint_measurements(11, dh_size=0.0, n_fid=200, n_chk=20)), 300.0)
    tracker = diagnose(m, alpha=ALPHA, seed=0, instrument="tracker")
    assert "scale" in {e.name for e in tracker.effects}
    [line] = [x for x in tracker.limits if "plausibly has" in x]
    assert "more than a tracker plausibly has (at most 10 ppm" in line and "the arm" in line
    stereo = diagnose(m, alpha=ALPHA, seed=0, instrument="stereo")
    assert not [x for x in stereo.limits if "plausibly has" in x]
    path = tmp_path / "scaled.csv"
    write_measurements(path, m)
    out = rrbc("diagnose", path, "--instrument", "tracker")
    assert out.returncode == 0 and "more than a tracker plausibly has" in out.stdout
    bad = rrbc("diagnose", path, "--instrument", "ruler")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr


def test_a_field_shorter_than_the_points_spacing_is_called_no_sensors_distortion():
    from rrbc_core.analysis.diagnosis_arm import short_field
    from rrbc_core.analysis.diagnosis_systematic import Effect

    grid = np.stack(np.meshgrid(*[np.arange(0.0, 500.0, 100.0)] * 3), -1).reshape(-1, 3)  # 100 mm apart

    def field(length_mm: float) -> dict:
        return {"smooth_field": Effect("smooth_field", {"rms_mm": 1.0, "length_scale_mm": length_mm}, 1e-9, "")}

    short = short_field(field(5.0), grid)
    assert short is not None and "(5 mm) is shorter than half the points' typical spacing (100 mm)" in short
    assert short_field(field(300.0), grid) is None
    assert short_field({}, grid) is None
    # the spacing the diagnosis takes from Moran's neighbour search: the same answer
    from rrbc_core.analysis.diagnosis_moran import neighbours

    rng = np.random.default_rng(3)
    cloud = rng.uniform(0, 800, (300, 3))
    assert neighbours(grid)[1] == 100.0
    for length in (5.0, 30.0, 300.0):
        assert short_field(field(length), cloud, neighbours(cloud)[1]) == short_field(field(length), cloud)


def test_fewer_poses_use_the_harmonics_without_the_base_joints_products():
    """148 paired points: too few for the 74 harmonics with products (222 needed), enough for the 26 without."""
    m = _renamed(joint_measurements(2, dh_size=3.0, n_fid=120, n_chk=20))
    from rrbc_core.analysis.diagnosis_stats import paired

    d = paired(m)
    cols = configuration_columns(m, d.rows, d.row_point, len(d.ids), [])
    assert cols is not None and cols.fields.shape[0] == 3 * 26
    k = {e.name: e for e in diagnose(m, alpha=ALPHA, seed=0).effects}.get("kinematic")
    assert k is not None and k.parameters["model"] == "none"


def test_the_model_free_columns_stay_bounded_on_a_big_file(monkeypatch):
    """Past the element bound the smaller basis is used, and past that none, with a limit: never unbounded memory."""
    from rrbc_core.analysis import diagnosis_arm
    from rrbc_core.analysis.diagnosis_stats import paired

    m = _renamed(joint_measurements(2, dh_size=3.0, n_fid=200, n_chk=60))
    d = paired(m)
    n = len(d.ids)
    args = (m, d.rows, d.row_point, n)
    assert configuration_columns(*args, []).fields.shape[0] == 3 * 74
    monkeypatch.setattr(diagnosis_arm, "CONFIGURATION_MAX_ELEMENTS", 9 * n * 26)
    assert configuration_columns(*args, []).fields.shape[0] == 3 * 26
    monkeypatch.setattr(diagnosis_arm, "CONFIGURATION_MAX_ELEMENTS", 9 * n * 26 - 1)
    limits: list[str] = []
    assert configuration_columns(*args, limits) is None
    assert any("was left out" in x for x in limits), limits


def test_a_column_named_like_a_lift_is_a_linear_axis_not_an_angle():
    """A lift column in metres (values within 2π) is taken as a linear axis by its name: its value and its square,
    not sin and cos, and not the 'first joint' whose turn the others' harmonics are multiplied by."""
    from rrbc_core.analysis.diagnosis_stats import paired

    m = _renamed(joint_measurements(2, dh_size=3.0, n_fid=200, n_chk=60))
    lift = np.random.default_rng(0).uniform(0.0, 1.5, len(m.ids))
    m = dataclasses.replace(m, extra={"lift_joint": tuple(f"{v:.4f}" for v in lift), **m.extra})
    d = paired(m)
    cols = configuration_columns(m, d.rows, d.row_point, len(d.ids), [])
    assert cols is not None and cols.fields.shape[0] == 3 * (2 + 74)
    assert cols.model_free[0] == "lift_joint"
