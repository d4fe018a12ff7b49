"""`rrbc check-model` (issue 36): a scene's error model held against a measured file.

Hidden effects of seeded random size and direction are planted in the demo cell's model (a UR5 with its kinematic
error, stereo noise), a file is simulated from the planted model, and the real pipeline runs against the scene
WITHOUT the effect: the misfit must be flagged, the effect named with a size within a tolerance derived from the
noise, the extended model must predict a second data set of the same points drawn with other noise, and the
out-of-sample gain must be positive. Clean files: nothing is added. Times are shuffled over the rows where a test is
about drift: in the scene's own file order time follows position, and a drift cannot be told from a linear map of
position (a test holds that the limit is said).
"""

import dataclasses

import numpy as np
import pytest
from scipy import stats

from rrbc_core.analysis.scene_check import Z95, _moments, _z, check_scene_model, outside_counts
from rrbc_core.analysis.scene_prediction import at_physical_points, file_stations, measured_figures, predict
from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.errors import InputError
from rrbc_core.io.scene import default_scene_path
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.models.errorterms import Drift, SampledField, Scale, SmoothField, error_model_from_dict
from rrbc_core.simulation.datasets import measured_data
from rrbc_core.simulation.montecarlo import work_cell_from_scene

TRIALS = 100
FOLDS = 3


@pytest.fixture(scope="module")
def scene():
    return load_scene(default_scene_path())


def _cell(scene, terms=(), cell_seed=0, shuffle_time=None):
    sc = dataclasses.replace(scene, error_model=scene.error_model.extended(robot=list(terms)))
    cell = work_cell_from_scene(sc, seed=cell_seed)
    if shuffle_time is not None:
        cell = dataclasses.replace(cell, time=np.random.default_rng(shuffle_time).permutation(cell.time))
    return cell


def _file(scene, terms=(), seed=1, cell_seed=0, shuffle_time=None):
    return measured_data(_cell(scene, terms, cell_seed, shuffle_time), seed)


def _noise_sigma(scene, mset):
    """Per-axis residual noise (mm) of the scene's model at the file's points: the theory behind the tolerances."""
    st = file_stations(mset, "ur5", scene.tool_yaw_deg)
    pred = predict(mset, st, scene.error_model, 200, 5)
    ok = np.isfinite(pred.residual[0, :, 0])
    return float(np.sqrt(np.mean(np.var(pred.residual[:, ok], axis=0))))


# ---------------------------------------------------------------------------------------------- one answer
def test_measured_figures_are_rrbc_corrects_own(scene):
    m = _file(scene, seed=2)
    st = file_stations(m, "ur5", scene.tool_yaw_deg)
    fig = measured_figures(m, st)
    res = correct_measurements(m)
    assert fig.rmst_rigid[0] == pytest.approx(res.summary()["rmst_rigid_mm"], abs=1e-9)
    assert fig.rmst_rrbc[0] == pytest.approx(res.summary()["rmst_rrbc_mm"], abs=1e-9)
    assert fig.fre[0] == pytest.approx(res.registration.fre_rms_mm, abs=1e-9)


# ---------------------------------------------------------------------------------------------- coverage
def test_predicted_intervals_cover_fresh_files_of_the_model(scene):
    """Files drawn from the scene's own model, each with its own noise: each figure's 95 % interval holds the
    measured value about 95 % of the time (lower bound: the binomial 0.1 % quantile of 95 % coverage), each row is
    inside its own region about 95 % of the time, and the count of rows outside stays under the trials' 97.5 %
    quantile of that count about 97.5 % of the time."""
    n = 30
    inside = {"fre_mm": 0, "rmst_rigid_mm": 0, "rmst_rrbc_mm": 0}
    rows_in, rows, count_ok = 0, 0, 0
    cell = _cell(scene)
    for k in range(n):
        m = measured_data(cell, 100 + k)
        st = at_physical_points(m, file_stations(m, "ur5", scene.tool_yaw_deg), scene.error_model)
        meas = measured_figures(m, st)
        pred = predict(m, st, scene.error_model, 200, k)
        for key, arr, mine in (
            ("fre_mm", pred.fre, meas.fre),
            ("rmst_rigid_mm", pred.rmst_rigid, meas.rmst_rigid),
            ("rmst_rrbc_mm", pred.rmst_rrbc, meas.rmst_rrbc),
        ):
            lo, hi = np.quantile(arr, [0.025, 0.975])
            inside[key] += int(lo <= mine[0] <= hi)
        mean, cov = _moments(pred)
        z = _z(meas.residual[0], mean, cov)
        ok = np.isfinite(z)
        rows_in += int(np.sum(z[ok] <= Z95))
        rows += int(ok.sum())
        count_hi = np.quantile(outside_counts(pred, mean, cov), 0.975)
        count_ok += int(np.sum(z[ok] > Z95) <= count_hi)
    floor = stats.binom.ppf(0.001, n, 0.95)
    assert all(v >= floor for v in inside.values()), inside
    assert count_ok >= stats.binom.ppf(0.001, n, 0.975), count_ok  # the count's one-sided 97.5 % bound
    # rows: pooled over files (rows of one file are correlated through its registration): 95 % within 2.5 points
    assert 0.925 <= rows_in / rows <= 0.975, rows_in / rows


# ---------------------------------------------------------------------------------------------- clean files
@pytest.mark.parametrize("seed", range(3))
def test_a_clean_file_fits_and_nothing_is_added(scene, seed):
    m = _file(scene, seed=10 + seed, cell_seed=seed)
    r = check_scene_model(m, scene, trials=TRIALS, folds=FOLDS, seed=seed)
    assert r.unexplained == () and r.added == (), [e.name for e in r.unexplained]
    assert r.gain["prediction_error_after_mm"] == r.gain["prediction_error_before_mm"]


# ---------------------------------------------------------------------------------------------- hidden effects
def _second_files_inside(scene, result, terms, cell_seed, shuffle_time=None):
    """Second data sets of the same points from the planted model, each with other noise: the extended model's
    95 % intervals of the FRE and the rigid RMST hold them about 95 % of the time (at least the binomial 0.1 %
    quantile of 95 % coverage over the files)."""
    n = 12
    cell = _cell(scene, terms, cell_seed, shuffle_time)
    ext = result.extended_model
    inside = np.zeros(2, int)
    for k in range(n):
        m2 = measured_data(cell, 900 + k)
        st = at_physical_points(m2, file_stations(m2, "ur5", scene.tool_yaw_deg), ext)
        meas = measured_figures(m2, st)
        pred = predict(m2, st, ext, 200, k)
        for j, (arr, mine) in enumerate(((pred.fre, meas.fre), (pred.rmst_rigid, meas.rmst_rigid))):
            lo, hi = np.quantile(arr, [0.025, 0.975])
            inside[j] += int(lo <= mine[0] <= hi)
    assert np.all(inside >= stats.binom.ppf(0.001, n, 0.95)), inside


def _flagged_and_gain(r):
    assert r.figures_outside or len(r.outside) > 0.2 * r.n_rows
    assert not r.model_fits
    g = r.gain
    assert g["prediction_error_after_mm"] < g["prediction_error_before_mm"], g
    assert g["coverage_after"] > g["coverage_before"], g
    # one isotropic_noise: the named size is the size written (the spread step's in quadrature with diagnose's)
    named = [e.parameters["sigma_mm"] for e in r.unexplained if e.name == "isotropic_noise"]
    written = [t.table["sigma_mm"] for t in r.added if t.table["type"] == "isotropic_noise"]
    assert len(named) == len(written) <= 1 and np.allclose(named, written, atol=1e-6), (named, written)


@pytest.mark.parametrize("seed", range(3))
def test_a_drift_the_scene_lacks_is_named_sized_written_and_predicts(scene, seed):
    rng = np.random.default_rng(3600 + seed)
    cell = _cell(scene)
    span = float(np.ptp(cell.time))
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    size_mm = rng.uniform(0.4, 0.8)  # over the session: 5-10 times the noise
    rate = direction * size_mm / span
    terms = [Drift(rate_mm_per_s=tuple(rate))]
    m = _file(scene, terms, seed=20 + seed, shuffle_time=seed)
    r = check_scene_model(m, scene, trials=TRIALS, folds=FOLDS, seed=seed)
    _flagged_and_gain(r)
    names = [e.name for e in r.unexplained]
    assert "drift" in names and "time" in r.follows, names
    est = np.array(next(e for e in r.unexplained if e.name == "drift").parameters["rate_mm_per_s"])
    t = np.asarray(m.time)[np.isfinite(m.robot[:, 0])]
    se = _noise_sigma(scene, m) / np.sqrt(np.sum((t - t.mean()) ** 2))  # LS slope's standard error per axis
    assert np.all(np.abs(est - rate) <= 4 * se + 1e-12), (est, rate, se)
    drift = [t for t in r.added if t.table["type"] == "drift"]
    assert len(drift) == 1 and np.allclose(drift[0].table["rate_mm_per_s"], est)
    _second_files_inside(scene, r, terms, 0, seed)


@pytest.mark.parametrize("seed", range(3))
def test_a_scale_the_scene_lacks_is_named_sized_and_written(scene, seed):
    rng = np.random.default_rng(3610 + seed)
    ppm = float(rng.choice([-1, 1]) * rng.uniform(400, 700))  # 0.1-0.2 mm over the cell's ±300 mm
    terms = [Scale(ppm=ppm)]
    m = _file(scene, terms, seed=30 + seed)
    r = check_scene_model(m, scene, trials=TRIALS, folds=FOLDS, seed=seed)
    _flagged_and_gain(r)
    eff = {e.name: e for e in r.unexplained}
    assert "scale" in eff and "affine" not in eff, list(eff)
    est, se = eff["scale"].parameters["ppm"], eff["scale"].parameters["ppm_standard_error"]
    assert abs(est - ppm) <= 4 * se, (est, ppm, se)
    _second_files_inside(scene, r, terms, 0)


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)])
def test_a_smooth_field_the_scene_lacks_is_named_written_as_a_sampled_field_and_predicts(scene, seed):
    rng = np.random.default_rng(3620 + seed)
    terms = [SmoothField(rms_mm=float(rng.uniform(0.3, 0.5)), length_mm=float(rng.uniform(200, 300)), seed=seed)]
    m = _file(scene, terms, seed=40 + seed)
    r = check_scene_model(m, scene, trials=TRIALS, folds=FOLDS, seed=seed)
    _flagged_and_gain(r)
    eff = {e.name: e for e in r.unexplained}
    assert "smooth_field" in eff, list(eff)
    assert "position" in r.follows
    # an honest size: no more than the rigid residual the file holds (its RMS at the rows with both readings)
    rigid_rms = np.sqrt(np.nanmean(np.sum(measured_figures(m, file_stations(m, "ur5", 0.0)).residual[0] ** 2, 1)))
    assert eff["smooth_field"].parameters["rms_mm"] <= rigid_rms
    assert any(t.table["type"] == "sampled_field" for t in r.added)
    _second_files_inside(scene, r, terms, 0)


def test_two_effects_at_once_are_both_named(scene):
    rng = np.random.default_rng(3630)
    cell = _cell(scene)
    rate = rng.normal(size=3)
    rate *= 0.6 / np.linalg.norm(rate) / float(np.ptp(cell.time))
    terms = [Drift(rate_mm_per_s=tuple(rate)), Scale(ppm=600.0)]
    m = _file(scene, terms, seed=50, shuffle_time=7)
    r = check_scene_model(m, scene, trials=TRIALS, folds=FOLDS, seed=0)
    _flagged_and_gain(r)
    names = {e.name for e in r.unexplained}
    assert "drift" in names and names & {"scale", "affine"}, names


def test_time_that_follows_position_is_said(scene):
    cell = _cell(scene)
    rate = np.array([0.5, 0.0, 0.0]) / float(np.ptp(cell.time))
    terms = [Drift(rate_mm_per_s=tuple(rate))]
    m = _file(scene, terms, seed=60)
    r = check_scene_model(m, scene, trials=TRIALS, folds=FOLDS, seed=0)
    assert r.unexplained
    if {"drift", "affine", "scale"} & {e.name for e in r.unexplained}:
        assert any("time follows position" in s for s in r.limits), r.limits
    # the sum of the confounded terms still predicts, their fit's uncertainty included (`linear_uncertainty`)
    assert "linear_uncertainty" in [t.table["type"] for t in r.added]
    _second_files_inside(scene, r, terms, 0)
    # diagnose does not test a scale that changes with time where time follows position, and says so
    from rrbc_core.analysis.diagnosis import diagnose

    d = diagnose(m, robot="ur5", tool_mm=scene.tool_mm)
    assert "scale_rate" not in d.tests
    assert any("scale that changes with time cannot be told" in s for s in d.limits), d.limits


# ---------------------------------------------------------------------------------------------- the term
def test_the_sampled_field_passes_through_its_points_and_fades_far_away():
    rng = np.random.default_rng(1)
    pts = rng.uniform(0, 500, (30, 3))
    vec = rng.normal(0, 0.2, (30, 3))
    f = SampledField(points_mm=pts.tolist(), vectors_mm=vec.tolist(), length_mm=60.0)
    assert np.allclose(f.field(pts), vec, atol=1e-3)
    assert np.all(np.abs(f.field(np.array([[1e5, 0, 0]]))) < 1e-12)
    table = {"type": "sampled_field", "points_mm": pts.tolist(), "vectors_mm": vec.tolist(), "length_mm": 60.0}
    assert error_model_from_dict({"robot": [table]}).robot[0].points_mm == f.points_mm


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"vectors_mm": [[0, 0, 0]]}, "one per point"),
        ({"points_mm": [[0, 0]]}, "triples"),
        ({"points_mm": [[0, 0, float("nan")]], "vectors_mm": [[0, 0, 0]]}, "finite"),
        ({"points_mm": [[0, 0, 0]] * 2001, "vectors_mm": [[0, 0, 0]] * 2001}, "2000"),
        ({"length_mm": 0}, "length_mm"),
    ],
)
def test_a_bad_sampled_field_is_refused_with_its_reason(change, words):
    table = {"type": "sampled_field", "points_mm": [[0, 0, 0], [1, 0, 0]], "vectors_mm": [[0, 0, 0]] * 2}
    table["length_mm"] = 10.0
    table.update(change)
    with pytest.raises(InputError, match=words):
        error_model_from_dict({"robot": [table]})


def test_bad_arguments_are_refused(scene):
    m = _file(scene, seed=2)
    with pytest.raises(InputError, match="trials"):
        check_scene_model(m, scene, trials=5)
    with pytest.raises(InputError, match="folds"):
        check_scene_model(m, scene, folds=1)


def test_repeated_rows_are_one_point_as_rrbc_correct_has_them(scene):
    """Registration points and fiducials measured twice (repeated ids): the figures are still rrbc correct's own, and
    a station with fewer than 3 distinct registration points is refused in one line."""
    from rrbc_core.io.measurements import MeasurementSet

    m = _file(scene, seed=4)
    again = [i for i, r in enumerate(m.roles) if r in ("registration", "fiducial")]
    rows = list(range(len(m))) + again
    noise = np.random.default_rng(4).normal(0, 0.02, (len(rows), 3))
    rep = MeasurementSet(
        tuple(m.ids[i] for i in rows),
        tuple(m.roles[i] for i in rows),
        m.sensor[rows] + noise,
        m.robot[rows],
        m.time[rows],
        tuple(0 for _ in rows),
        "repeats",
        {k: tuple(v[i] for i in rows) for k, v in m.extra.items()},
    )
    fig = measured_figures(rep, file_stations(rep, "ur5", scene.tool_yaw_deg))
    res = correct_measurements(rep)
    assert fig.rmst_rigid[0] == pytest.approx(res.summary()["rmst_rigid_mm"], abs=1e-9)
    assert fig.rmst_rrbc[0] == pytest.approx(res.summary()["rmst_rrbc_mm"], abs=1e-9)
    assert fig.fre[0] == pytest.approx(res.registration.fre_rms_mm, abs=1e-9)
    two = [i for i, r in enumerate(m.roles) if r != "registration"] + [0, 1]
    few = MeasurementSet(
        tuple(m.ids[i] for i in two),
        tuple(m.roles[i] for i in two),
        m.sensor[two],
        m.robot[two],
        m.time[two],
        tuple(0 for _ in two),
        "few",
        {k: tuple(v[i] for i in two) for k, v in m.extra.items()},
    )
    with pytest.raises(InputError, match="2 registration points"):
        file_stations(few, "ur5", scene.tool_yaw_deg)


def test_a_station_whose_sensor_moved_is_the_one_named(scene):
    """Two stations of the demo cell (the sensor placed twice); in the second, the sensor is bumped after its
    registration points were measured (a random small rotation and shift, seeded): that station's rows miss, the
    other's do not, and the misfit is said to follow the station; folds are the stations."""
    from scipy.spatial.transform import Rotation

    from rrbc_core.geometry.transforms import RigidTransform
    from rrbc_core.io.measurements import MeasurementSet

    rng = np.random.default_rng(3640)
    turn = Rotation.from_rotvec([0.0, 0.0, 0.35]).as_matrix()
    centre = np.array([475.0, 0.0, 0.0])
    pose = scene.sensor_to_robot
    moved_pose = RigidTransform(turn @ pose.rotation, turn @ (pose.translation - centre) + centre)
    parts = []
    for k, sc in enumerate((scene, dataclasses.replace(scene, sensor_to_robot=moved_pose))):
        m = measured_data(work_cell_from_scene(sc, seed=k), 70 + k)
        if k == 1:  # bumped once its registration rows were read
            bump = Rotation.from_rotvec(rng.normal(0, 1, 3) * 2e-4).as_matrix()
            late = np.array([r != "registration" for r in m.roles])
            s = m.sensor.copy()
            s[late] = s[late] @ bump.T + rng.normal(0, 1, 3) * 0.15
            m = dataclasses.replace(m, sensor=s)
        parts.append((m, f"s{k + 1}"))
    cat = lambda f: np.concatenate([f(m) for m, _ in parts])
    extra = {key: sum((m.extra[key] for m, _ in parts), ()) for key in parts[0][0].extra}
    extra["group"] = sum(((g,) * len(m) for m, g in parts), ())
    both = MeasurementSet(
        sum((m.ids for m, _ in parts), ()),
        sum((m.roles for m, _ in parts), ()),
        cat(lambda m: m.sensor),
        cat(lambda m: m.robot),
        cat(lambda m: m.time),
        tuple(0 for _ in range(sum(len(m) for m, _ in parts))),
        "two stations",
        extra,
    )
    r = check_scene_model(both, scene, trials=TRIALS, folds=FOLDS, seed=0)
    assert r.stations_off == ("s2",), r.stations_off
    assert "station" in r.follows
    assert r.gain["fold_by"] == "station" and r.gain["folds"] == 2
    assert all(p.group == "s2" for p in r.outside[: len(r.outside) // 2])  # the worst rows are the bumped station's


@pytest.mark.parametrize("seed", range(3))
def test_a_scale_that_changes_with_time_is_named_with_its_rate_and_written(scene, seed):
    """A thermal ramp: the scale grows by 800-1200 ppm over the session (random sign), times shuffled. diagnose names
    `scale` with `ppm_per_s` within four of its standard errors; check-model writes a scale term with that rate."""
    from rrbc_core.analysis.diagnosis import diagnose

    rng = np.random.default_rng(3650 + seed)
    t = _cell(scene).time
    rate = float(rng.choice([-1, 1]) * rng.uniform(800, 1200) / np.ptp(t))
    terms = [Scale(ppm=0.0, ppm_per_s=rate, t0_s=float(t.mean()))]
    m = _file(scene, terms, seed=80 + seed, shuffle_time=seed)
    d = diagnose(m, robot="ur5", tool_mm=scene.tool_mm)
    sc = next(e for e in d.effects if e.name == "scale").parameters
    assert abs(sc["ppm_per_s"] - rate) <= 4 * sc["ppm_per_s_standard_error"], (sc, rate)
    r = check_scene_model(m, scene, trials=TRIALS, folds=FOLDS, seed=seed)
    _flagged_and_gain(r)
    written = [t.table for t in r.added if t.table["type"] == "scale"]
    assert len(written) == 1 and np.sign(written[0]["ppm_per_s"]) == np.sign(rate), written
    _second_files_inside(scene, r, terms, 0, seed)
