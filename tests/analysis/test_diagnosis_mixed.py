"""`rrbc diagnose` with the arm and with two effects at once (issue 15, item 5).

Hidden effects of seeded random size and geometry, run through the real `diagnose`:
- joint columns present (the library's own simulator of a UR5 with a 100 mm tool, `studies.vec_study`): DH errors
  are named `kinematic` and nothing else; a sensor field with a perfect arm is a `smooth_field`, never `kinematic`;
  clean data give nothing;
- DH errors with a sensor field: `kinematic` and the field as a position effect (its linear part beside the arm);
- a smooth field with drift: exactly those two names, no noise effect, the noise and the field's size estimated
  beside each other (the field's RMS must not absorb the drift);
- a smooth field with outliers, scale with outliers: exactly the planted names and ids;
- outliers in the file: `expected_rmst_change` predicts the harm `rrbc correct` does on that file.
Allowances are stated per test; none was tuned on these seeds beyond what the comment says.
"""

import dataclasses

import numpy as np
import pytest

from rrbc_core.analysis.diagnosis import diagnose
from rrbc_core.cli import main
from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.methods import MethodOptions
from rrbc_core.models.errorterms import Drift, Scale, SmoothField
from rrbc_core.registration.strategies import least_squares
from rrbc_core.studies.vec_study import TOOL_MM, joint_measurements
from tests.analysis.test_diagnosis import synth
from tests.analysis.test_diagnosis_validation import _data_set


def _joints(seed, **kw):
    rng = np.random.default_rng(9000 + seed)
    return joint_measurements(seed, noise_mm=float(rng.uniform(0.01, 0.03)), **kw), rng


# -------------------------------------------------------------------------------------------------- the arm
@pytest.mark.parametrize("seed", range(8))
def test_dh_errors_with_joints_are_named_kinematic_and_nothing_else(seed):
    rng = np.random.default_rng(9100 + seed)
    m, _ = _joints(seed, dh_size=float(rng.uniform(0.7, 1.5)))
    dg = diagnose(m, tool_mm=TOOL_MM)
    assert dg.names == ["kinematic"], dg.tests
    assert "outliers" not in dg.names and "anisotropic_noise" not in dg.names
    assert dg.effects[0].parameters["combinations"] >= 10  # a UR5 moved in all six joints shows many combinations


@pytest.mark.parametrize("seed", range(8))
def test_a_sensor_field_with_a_perfect_arm_is_a_field_not_kinematic(seed):
    rng = np.random.default_rng(9200 + seed)
    m, _ = _joints(seed, dh_size=0.0, field_mm=float(rng.uniform(0.2, 0.4)))
    dg = diagnose(m, tool_mm=TOOL_MM)
    assert "kinematic" not in dg.names, dg.tests
    assert "smooth_field" in dg.names or "affine" in dg.names  # found as a position effect


@pytest.mark.parametrize("seed", range(8))
def test_dh_errors_with_a_sensor_field_are_kinematic_plus_a_position_effect(seed):
    """DH errors of random size with a sensor field of random size (length 300 mm): `kinematic` and the field as a
    position effect - `smooth_field`, or its linear part `affine`/`scale` (the same standard as a field alone,
    above: beside the arm's ~20 columns the rest of a long field is not identifiable) - with the limit saying so;
    never outliers or a noise effect."""
    rng = np.random.default_rng(9300 + seed)
    m, _ = _joints(seed, dh_size=float(rng.uniform(0.7, 1.5)), field_mm=float(rng.uniform(0.2, 0.4)))
    dg = diagnose(m, tool_mm=TOOL_MM)
    names = set(dg.names)
    assert "kinematic" in names and names & {"smooth_field", "affine", "scale"}, dg.tests
    assert names <= {"kinematic", "smooth_field", "affine", "scale"}, dg.names
    if names & {"affine", "scale"}:
        assert any("linear part is reported as affine" in t for t in dg.limits)


def test_clean_data_with_joints_report_nothing_over_20_seeds():
    # family-wise alpha 0.01 over the 7 tests: P(2 or more false alarms in 20 sets) < 0.02
    alarms = [diagnose(_joints(seed, dh_size=0.0)[0], tool_mm=TOOL_MM).names for seed in range(20)]
    assert sum(bool(a) for a in alarms) <= 1, alarms


def test_cli_diagnose_with_joints_names_kinematic_and_refuses_bad_tool(tmp_path, capsys):
    path = tmp_path / "m.csv"
    write_measurements(path, joint_measurements(3))
    assert main(["diagnose", str(path), "--tool", "100", "--json"]) == 0
    import json

    out = json.loads(capsys.readouterr().out)
    assert [e["name"] for e in out["effects"]] == ["kinematic"]
    assert main(["diagnose", str(path), "--tool", "nan"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "tool" in err[0]


def test_partial_joint_columns_are_refused_in_one_line(tmp_path, capsys):
    m = joint_measurements(1)
    extra = {k: v for k, v in m.extra.items() if k != "q6"}
    path = tmp_path / "m.csv"
    write_measurements(path, dataclasses.replace(m, extra=extra))
    assert main(["diagnose", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "q6" in err[0]


# ----------------------------------------------------------------------------------------- two effects at once
@pytest.mark.parametrize("seed", range(8))
def test_smooth_field_with_drift_gives_exactly_both_and_honest_sizes(seed):
    rng = np.random.default_rng(9300 + seed)
    sigma, n = float(rng.uniform(0.005, 0.05)), int(rng.integers(80, 201))
    _, info = synth(seed, n=n, sigma=sigma)
    field = SmoothField(rms_mm=sigma * rng.uniform(5, 10), length_mm=0.3 * info["ext"], seed=seed)
    v = rng.normal(size=3)
    total = sigma * rng.uniform(5, 10)  # drift over the whole run, mm
    drift = Drift((v / np.linalg.norm(v) * total / (n * 10.0)).tolist())
    m, info = synth(seed, n=n, sigma=sigma, terms=[field, drift])
    dg = diagnose(m)
    assert sorted(dg.names) == ["drift", "smooth_field"], dg.tests
    # the noise beside the field: within 4 standard errors of sigma (about n/2 effective dof per axis)
    se = sigma * np.sqrt(2 / n) * 4
    assert np.all(np.abs(np.array(dg.noise_sigma_mm) - sigma) < se + 0.25 * sigma), dg.noise_sigma_mm
    # the field's RMS is the field's, not the drift's: the realised field's non-rigid RMS at the points
    only_field, _ = synth(seed, n=n, sigma=sigma, terms=[field])
    truth = float(
        np.sqrt(np.mean(np.sum(least_squares(info["robot"], np.asarray(only_field.robot)[:n]).residuals ** 2, 1)))
    )
    est = dg.effects[dg.names.index("smooth_field")].parameters["rms_mm"]
    assert abs(est - truth) < 0.3 * truth + 2 * sigma, (est, truth)


@pytest.mark.parametrize("seed", range(8))
def test_a_smooth_field_alone_reports_no_noise_effect_and_no_outliers(seed):
    rng = np.random.default_rng(9400 + seed)
    sigma, n = float(rng.uniform(0.005, 0.05)), int(rng.integers(60, 201))
    _, info = synth(seed, n=n, sigma=sigma)
    field = SmoothField(rms_mm=sigma * rng.uniform(5, 15), length_mm=info["ext"] * rng.uniform(0.25, 0.5), seed=seed)
    m, _ = synth(seed, n=n, sigma=sigma, terms=[field], repeats=int(rng.integers(1, 3)))
    assert diagnose(m).names == ["smooth_field"]


def _with_outliers(rng, m, n, most, lo_mm, hi_mm):
    """1..most of the first n points displaced by lo..hi mm in random directions: (new set, their indices)."""
    robot = np.array(m.robot)
    idx = rng.choice(n, int(rng.integers(1, most + 1)), replace=False)
    for i in idx:
        v = rng.normal(size=3)
        robot[i] += v / np.linalg.norm(v) * rng.uniform(lo_mm, hi_mm)
    return MeasurementSet(m.ids, m.roles, m.sensor, robot, m.time, m.lines), idx


@pytest.mark.parametrize("seed", range(6))
def test_smooth_field_with_outliers_names_both_and_only_the_planted_ids(seed):
    rng = np.random.default_rng(9500 + seed)
    sigma, n = float(rng.uniform(0.01, 0.05)), int(rng.integers(100, 201))
    _, info = synth(seed, n=n, sigma=sigma, planar=False)
    field = SmoothField(rms_mm=sigma * rng.uniform(5, 10), length_mm=0.3 * info["ext"], seed=seed)
    m, _ = synth(seed, n=n, sigma=sigma, terms=[field], planar=False)
    m, idx = _with_outliers(rng, m, n, 3, sigma * 30, sigma * 60)
    dg = diagnose(m)
    assert sorted(dg.names) == ["outliers", "smooth_field"], dg.tests
    assert sorted(dg.effects[dg.names.index("outliers")].parameters["ids"]) == sorted(f"P{i}" for i in idx)


@pytest.mark.parametrize("seed", range(6))
def test_scale_with_outliers_names_both(seed):
    rng = np.random.default_rng(9600 + seed)
    sigma, n = float(rng.uniform(0.005, 0.05)), int(rng.integers(40, 201))
    _, info = synth(seed, n=n, sigma=sigma)
    spread = float(np.sum((info["robot"] - info["robot"].mean(0)) ** 2))
    ppm = float(rng.choice([-1, 1]) * rng.uniform(20, 40)) * sigma / np.sqrt(spread) * 1e6
    m, _ = synth(seed, n=n, sigma=sigma, terms=[Scale(ppm)])
    m, idx = _with_outliers(rng, m, n, 2, sigma * 15, sigma * 30)
    dg = diagnose(m)
    assert sorted(dg.names) == ["outliers", "scale"], dg.tests
    assert sorted(dg.effects[dg.names.index("outliers")].parameters["ids"]) == sorted(f"P{i}" for i in idx)


# -------------------------------------------------------------------------------- what rrbc correct will do
def test_with_outliers_in_the_file_the_prediction_is_for_the_file_as_given():
    """Two gross outliers (2-5 mm) among the fiducials of 10 seeded sets (half with a field): `rrbc correct` on
    the file then makes the check RMST worse; the prediction must say so (RRBC not recommended) in at least 8 of
    10 (measured: 9 of 10; the exception is a set where the checks fall far from both outliers), and removing the
    outliers must be predicted to do better than keeping them in every set."""
    agree = 0
    for k in range(10):
        full, paired = _data_set(63000 + k, bool(k % 2))
        rng = np.random.default_rng(k)
        n = len(paired.ids)
        robot = np.array(full.robot)
        for i in rng.choice(n, 2, replace=False):
            v = rng.normal(size=3)
            robot[i] += v / np.linalg.norm(v) * rng.uniform(2, 5)
        full = dataclasses.replace(full, robot=robot)
        dg = diagnose(dataclasses.replace(paired, robot=robot[:n]))
        summ = correct_measurements(full, MethodOptions()).summary()
        helped = summ["rmst_rrbc_mm"] < summ["rmst_rigid_mm"]
        agree += dg.rrbc_recommended == helped
        assert "outliers" in dg.names
        assert dg.expected_change_without_outliers < dg.expected_rmst_change
        assert "as given" in dg.assumes
    assert agree >= 8


def large_field_case(seed: int, drift: bool) -> MeasurementSet:
    """A smooth field of 5-30 noise levels (length 0.2-0.5 of the extent), with drift of 5-20 noise levels over the
    run (seeds from 7700) or without (seeds from 8800); 40-200 points, planar or not, with or without repeats.
    Also used by scripts/real_data_checks.py."""
    rng = np.random.default_rng((7700 if drift else 8800) + seed)
    sigma, n = float(rng.uniform(0.005, 0.05)), int(rng.integers(40, 201))
    planar, reps = bool(rng.integers(2)), int(rng.integers(1, 3))
    _, info = synth(seed, n=n, sigma=sigma, planar=planar)
    terms: list = [
        SmoothField(rms_mm=sigma * rng.uniform(5, 30), length_mm=rng.uniform(0.2, 0.5) * info["ext"], seed=seed)
    ]
    if drift:
        v = rng.normal(size=3)
        terms.append(Drift((v / np.linalg.norm(v) * sigma * rng.uniform(5, 20) / (n * 10.0)).tolist()))
    return synth(seed, n=n, sigma=sigma, terms=terms, planar=planar, repeats=reps)[0]


@pytest.mark.parametrize("seed", range(24))
def test_a_large_field_beside_drift_does_not_hide_the_drift_nor_become_anisotropic_noise(seed):
    """Issue 28, item 5: the hidden cases named `anisotropic_noise` beside a smooth field and drift (2 of 6) and
    missed the drift (1 of 6). A field many times the noise swamps the ordinary drift test; the drift is looked for
    again beside the field (generalised least squares), and the noise is judged on what field and drift leave.
    Sizes wider than the test above: fields of 5-30 noise levels, drift of 5-20 over the run, 40-200 points, planar
    or not, with or without repeats."""
    names = set(diagnose(large_field_case(seed, drift=True)).names)
    assert {"drift", "smooth_field"} <= names and "anisotropic_noise" not in names and "outliers" not in names, names


@pytest.mark.parametrize("seed", range(24))
def test_a_large_field_alone_gains_no_drift_from_the_second_look(seed):
    """The second look at drift beside a field must not find drift where there is none (same sizes, no drift)."""
    dg = diagnose(large_field_case(seed, drift=False))
    assert "drift" not in dg.names, dg.tests
