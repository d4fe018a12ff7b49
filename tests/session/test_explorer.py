"""The session behind the browser app (rrbc_core.session.explorer), tested without a browser."""

import numpy as np
import pytest

from rrbc_core import interpolation, registration
from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.correction.rrbc import correct_points, fiducial_corrections
from rrbc_core.errors import InputError
from rrbc_core.io.measurements import read_measurements
from rrbc_core.io.scene import default_scene_path
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.methods import MethodOptions
from rrbc_core.session import figures
from rrbc_core.session.evaluation import Settings, hull_edges
from rrbc_core.session.explorer import ExplorerSession

EXAMPLE = default_scene_path().parents[1] / "rrbc_core" / "data" / "example_measurements.csv"


@pytest.fixture(scope="module")
def scene():
    return load_scene(default_scene_path())


def test_evaluation_is_the_nine_steps_on_the_sessions_readings(scene):
    """Recompute registration, corrections and targets from the session's readings with the core functions."""
    ses = ExplorerSession.from_scene(scene)
    ev = ses.evaluate()
    reg = registration.least_squares(ev.registration_readings.sensor, ev.registration_readings.robot)
    np.testing.assert_allclose(ev.registration.mapping.rotation, reg.mapping.rotation, atol=1e-12)
    e = fiducial_corrections(reg.mapping, ev.fiducial_readings.sensor, ev.fiducial_readings.robot)
    np.testing.assert_allclose(ev.corrections, e, atol=1e-12)
    cp = correct_points(reg.mapping, interpolation.IDW().fit(ev.fiducial_readings.sensor, e), ev.targets.sensor)
    np.testing.assert_allclose(ev.targets.robot_rrbc, cp.robot_rrbc, atol=1e-12)
    np.testing.assert_allclose(ev.targets.error_rrbc, np.linalg.norm(cp.robot_rrbc - ev.targets.truth, axis=1))
    # the default scene is bias-dominated: RRBC visibly helps at its targets
    assert ev.summary["rmst_rrbc_mm"] < 0.5 * ev.summary["rmst_rigid_mm"]


def test_export_reproduces_the_sessions_numbers_through_rrbc_correct(scene, tmp_path):
    """The export is the scene's data set as `rrbc simulate --out` writes it (targets as target rows, check points in
    their regions with their truth): `rrbc correct` on it lands every target where the session does, and the JSON
    download is `rrbc correct` on it."""
    from rrbc_core.io.measurements_write import write_measurements

    ses = ExplorerSession.from_scene(scene, Settings(interpolation="tps"))
    ev = ses.move("targets", "H1", ses.layout["targets"].positions[0] + [3.0, -2.0, 0.0])
    f = tmp_path / "export.csv"
    write_measurements(f, figures.export_measurements(ses))
    out = correct_measurements(read_measurements(f), MethodOptions(interpolation="tps")).to_json()
    by_id = {c["id"]: c for c in out["targets"]}
    for i, pid in enumerate(ev.targets.ids):
        np.testing.assert_allclose(by_id[pid]["robot_rrbc"], ev.targets.robot_rrbc[i], atol=1e-9)
    assert len(out["checks"]) == scene.check_points_per_target * len(ev.targets.ids)
    assert all(c["id"].split(".c")[0] in ev.targets.ids for c in out["checks"])
    js = figures.export_json(ses)
    assert js["summary"] == pytest.approx(out["summary"], abs=1e-9)
    assert js["settings"]["interpolation"] == "tps"


def test_a_moved_fiducial_is_remeasured_at_its_new_place_but_keeps_its_noise_draw(scene):
    ses = ExplorerSession.from_scene(scene, Settings(bias_scale=0.0))  # noise only: isotropic/anisotropic
    ev0 = ses.evaluate()
    i = 3
    pid = ev0.fiducial_ids[i]
    p0 = ev0.fiducial_positions[i]
    robot_noise0 = ev0.fiducial_readings.robot[i] - p0
    ev1 = ses.move("fiducials", pid, p0 + [20.0, 10.0, 0.0])
    robot_noise1 = ev1.fiducial_readings.robot[i] - ev1.fiducial_positions[i]
    np.testing.assert_allclose(robot_noise1, robot_noise0, atol=1e-12)  # robot noise is isotropic: same draw
    assert not np.allclose(ev1.fiducial_readings.sensor[i], ev0.fiducial_readings.sensor[i])
    # with bias on, the robot reading at the new place carries the kinematic bias evaluated there
    ses_b = ExplorerSession.from_scene(scene, Settings(noise_scale=0.0))
    b0 = ses_b.evaluate()
    b1 = ses_b.move("fiducials", pid, p0 + [80.0, 0.0, 0.0])
    bias0 = b0.fiducial_readings.robot[i] - p0
    bias1 = b1.fiducial_readings.robot[i] - b1.fiducial_positions[i]
    assert np.linalg.norm(bias0) > 0.05 and not np.allclose(bias0, bias1, atol=1e-4)
    # a new seed redraws every point's noise
    n0 = ses.evaluate().fiducial_readings.robot.copy()
    n1 = ses.update(seed=12345).fiducial_readings.robot
    assert not np.allclose(n0, n1)


def test_excluding_a_fiducial_removes_it_from_the_interpolation(scene):
    ses = ExplorerSession.from_scene(scene)
    ev = ses.evaluate()
    pid = ev.fiducial_ids[0]
    ev2 = ses.set_excluded(pid, True)
    assert ev2.summary["fiducials_used"] == ev.summary["fiducials_used"] - 1
    assert np.all(np.isnan(ev2.corrections[0])) and not ev2.included[0]
    assert not np.allclose(ev2.targets.robot_rrbc, ev.targets.robot_rrbc)
    ev3 = ses.set_excluded(pid, False)
    np.testing.assert_allclose(ev3.targets.robot_rrbc, ev.targets.robot_rrbc, atol=1e-12)


def test_target_dragged_outside_the_hull_is_extrapolated(scene):
    ses = ExplorerSession.from_scene(scene)
    ev = ses.evaluate()
    assert not ev.targets.extrapolated.any()
    ev = ses.move("targets", ev.targets.ids[0], [350.0, 330.0, 120.0])  # reachable, beyond the fiducials
    assert ev.targets.extrapolated[0] and ev.targets.ids[0] in ev.summary["extrapolated"]


def test_bad_settings_leave_the_session_unchanged(scene):
    ses = ExplorerSession.from_scene(scene)
    before = ses.settings
    with pytest.raises(InputError):
        ses.update(interpolation="cubic")
    with pytest.raises(InputError):
        ses.update(noise_scale=-1.0)
    assert ses.settings == before


def test_measurement_mode_moves_targets_and_refuses_to_move_measured_fiducials():
    ses = ExplorerSession.from_measurements(read_measurements(EXAMPLE), settings=Settings(interpolation="gp"))
    ev = ses.evaluate()
    assert ev.targets.correction_std is not None
    t0 = ev.targets.ids[0]
    c0, s0 = ev.targets.correction[0].copy(), ev.targets.correction_std[0].copy()
    ev2 = ses.move("targets", t0, ev.targets.positions[0] + [60.0, 40.0, 0.0])
    assert not np.allclose(ev2.targets.correction[0], c0)
    assert not np.allclose(ev2.targets.correction_std[0], s0)
    # the new sensor position maps back to where the target was dragged (rigid part)
    np.testing.assert_allclose(ev2.targets.robot_rigid[0], ev.targets.positions[0] + [60.0, 40.0, 0.0], atol=1e-9)
    with pytest.raises(InputError, match="cannot be moved"):
        ses.move("fiducials", ev.fiducial_ids[0], ev.fiducial_positions[0] + 1.0)
    # a hostile position (issue 42): beyond the measurement reader's coordinate limit, refused, the session as it was
    for bad in ([1e12, 0.0, 0.0], [np.nan, 0.0, 0.0], [np.inf, 1.0, 1.0]):
        with pytest.raises(InputError):
            ses.move("targets", t0, bad)
    np.testing.assert_array_equal(ses.layout["targets"].positions[0], ev2.targets.positions[0])
    with pytest.raises(InputError):
        ses.update(noise_scale=2.0)
    hm = figures.heat_map(ses, samples_per_target=20)
    assert np.all(np.isnan(hm.error_rigid)) and hm.std_mm is not None


def test_heat_map_rrbc_beats_rigid_over_the_regions_and_is_cached(scene):
    ses = ExplorerSession.from_scene(scene)
    hm = figures.heat_map(ses, samples_per_target=100)
    assert hm.positions.shape == (100 * len(scene.targets), 3)
    assert np.sqrt(np.mean(hm.error_rrbc**2)) < 0.5 * np.sqrt(np.mean(hm.error_rigid**2))
    for t in scene.targets:  # samples lie inside each region
        sel = np.array(hm.target) == t.id
        assert t.region.contains(hm.positions[sel]).all()
    hm2 = figures.heat_map(ses, samples_per_target=100)
    np.testing.assert_array_equal(hm.error_rrbc, hm2.error_rrbc)


def test_monte_carlo_plots(scene):
    ses = ExplorerSession.from_scene(scene)
    mc = figures.monte_carlo(ses, trials=50, checks_per_target=5)
    centres, a, b = mc.histogram(bins=20)
    assert a.sum() == pytest.approx(1.0) and b.sum() == pytest.approx(1.0)
    assert np.sqrt(np.mean(mc.rrbc**2)) < np.sqrt(np.mean(mc.rigid**2))
    d, r, q, hr, hq = mc.by_distance(bins=4)
    assert len(d) == 4 and np.all(np.diff(d) > 0) and np.all(hr >= 0) and np.all(hq >= 0)
    # each bin's mean is the mean of its check points' mean errors (equal-count bins by distance)
    order = np.argsort(mc.distance)
    first = order[: len(order) // 4 + (len(order) % 4 > 0)]
    assert r[0] == pytest.approx(mc.rigid.mean(axis=0)[first].mean())
    assert d[0] == pytest.approx(mc.distance[first].mean())
    # more noise and no bias: RRBC no longer helps (docs/theory.md §0)
    ses.update(bias_scale=0.0, noise_scale=3.0)
    mc2 = figures.monte_carlo(ses, trials=50, checks_per_target=5)
    assert np.sqrt(np.mean(mc2.rrbc**2)) > np.sqrt(np.mean(mc2.rigid**2))


def test_monte_carlo_in_chunks_gives_one_batchs_numbers_and_stops_when_asked(scene, monkeypatch):
    """The app's Monte Carlo runs its trials in chunks, asking `should_stop` before each: the numbers are those of
    one batch (the noise and the seeds are drawn first), and a True answer stops it with `Cancelled` at once."""
    from rrbc_core.errors import Cancelled
    from rrbc_core.session import figures

    ses = ExplorerSession.from_scene(scene)
    chunked = figures.monte_carlo(ses, trials=120, checks_per_target=3)  # 50 + 50 + 20
    monkeypatch.setattr(figures, "MC_CHUNK_TRIALS", 10_000)
    whole = figures.monte_carlo(ses, trials=120, checks_per_target=3)
    # the same numbers up to the rounding of batched sums (the compiled kernels group trials differently)
    np.testing.assert_allclose(chunked.rigid, whole.rigid, rtol=0, atol=1e-9)
    np.testing.assert_allclose(chunked.rrbc, whole.rrbc, rtol=0, atol=1e-9)
    monkeypatch.setattr(figures, "MC_CHUNK_TRIALS", 10)
    asked = []

    def stop_at_third() -> bool:
        asked.append(1)
        return len(asked) >= 3

    with pytest.raises(Cancelled, match="stopped after 20 of 120 trials"):
        figures.monte_carlo(ses, trials=120, checks_per_target=3, should_stop=stop_at_third)
    assert len(asked) == 3


def test_hull_edges_of_a_cube_a_square_and_a_segment():
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) * 100
    assert hull_edges(cube).shape == (12, 2, 3)
    square = np.array([[0, 0, 0], [100, 0, 0], [100, 100, 0], [0, 100, 0], [50, 50, 0.0]])
    assert hull_edges(square).shape == (4, 2, 3)
    seg = np.array([[0, 0, 0], [50, 0, 0], [100, 0, 0.0]])
    np.testing.assert_allclose(np.sort(hull_edges(seg)[0][:, 0]), [0, 100])


def test_an_unreachable_place_is_refused_and_the_layout_kept(scene):
    ses = ExplorerSession.from_scene(scene)
    before = ses.layout["targets"].positions.copy()
    with pytest.raises(InputError, match="reach"):
        ses.move("targets", "H1", [900.0, 300.0, 400.0])
    np.testing.assert_array_equal(ses.layout["targets"].positions, before)
    ses.evaluate()
