"""Planning in the explorer session (rrbc_core.session.explorer over rrbc_core.analysis.planning), without a browser: coverage and
predicted RMST for the fiducials as the session has them (dragged, excluded, accepted), suggestions, accepting
them, and the message measured data get instead."""

import numpy as np
import pytest

from rrbc_core.analysis import planning
from rrbc_core.errors import InputError
from rrbc_core.io.measurements import read_measurements
from rrbc_core.io.scene import default_scene_path
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.session import planning_view
from rrbc_core.session.evaluation import Settings
from rrbc_core.session.explorer import ExplorerSession
from tests.paths import ROOT

EXAMPLE = ROOT / "rrbc_core" / "data" / "example_measurements.csv"
SCENES = sorted((ROOT / "scenes").glob("*.toml"))
# F1 (a hull corner on the table, next to H1) slid in under the plate: H1's region leaves the hull, and the
# candidates (a grid over the plate) can cover it again
F1_AWAY = [400.0, -60.0, 0.0]


@pytest.fixture(scope="module")
def scene():
    return load_scene(default_scene_path())


def _included(ses):
    fid = ses.layout["fiducials"]
    keep = [i for i, pid in enumerate(fid.ids) if pid not in ses.settings.excluded]
    return fid.positions[keep]


def _regions(ses):
    return [
        ses.regions[pid].__class__(ses.regions[pid].kind, p, ses.regions[pid].size)
        for pid, p in zip(ses.layout["targets"].ids, ses.layout["targets"].positions)
    ]


def test_planning_state_is_the_planners_numbers_for_the_fiducials_as_they_are(scene):
    ses = ExplorerSession.from_scene(scene)
    st0 = planning_view.planning_state(ses)
    assert st0.target_ids == scene.target_ids and st0.fiducials_used == len(scene.fiducials)
    # the shipped scene's fiducials hold every target region (its file says so)
    np.testing.assert_array_equal(st0.coverage, np.ones(len(scene.targets)))
    np.testing.assert_array_equal(
        st0.coverage, planning.coverage(scene.fiducials.positions, [t.region for t in scene.targets])
    )
    direct = planning.predict_rmst(scene, scene.fiducials.positions, registration_mm=scene.registration.positions)
    assert st0.predicted == direct
    assert planning_view.planning_state(ses) is st0  # cached while nothing changes

    # a dragged fiducial: H1's region leaves the hull; numbers are the planner's for the new positions
    ses.move("fiducials", "F1", F1_AWAY)
    st1 = planning_view.planning_state(ses)
    assert st1 is not st0
    assert st1.coverage_of("H1") < 1.0
    np.testing.assert_array_equal(st1.coverage, planning.coverage(_included(ses), _regions(ses)))
    assert st1.predicted == planning.predict_rmst(
        planning_view.planning_scene(ses), _included(ses), registration_mm=ses.layout["registration"].positions
    )
    assert st1.predicted != st0.predicted

    # excluded fiducials do not count
    ses.set_excluded("F3", True)
    st2 = planning_view.planning_state(ses)
    assert st2.fiducials_used == len(scene.fiducials) - 1
    np.testing.assert_array_equal(st2.coverage, planning.coverage(_included(ses), _regions(ses)))
    ses.set_excluded("F3", False)

    # back where it was: the first numbers again
    ses.move("fiducials", "F1", scene.fiducials.position("F1"))
    st3 = planning_view.planning_state(ses)
    np.testing.assert_array_equal(st3.coverage, st0.coverage)
    assert st3.predicted == st0.predicted


def test_a_dragged_target_carries_its_region(scene):
    ses = ExplorerSession.from_scene(scene)
    ses.move("targets", "H1", [150.0, -150.0, 300.0])  # far outside the fiducials' hull
    st = planning_view.planning_state(ses)
    assert st.coverage_of("H1") == 0.0 and st.coverage_of("H2") == 1.0
    moved = planning_view.planning_scene(ses).target("H1")
    np.testing.assert_array_equal(moved.region.center, [150.0, -150.0, 300.0])


def test_noise_and_bias_sizes_reach_the_prediction(scene):
    ses = ExplorerSession.from_scene(scene)
    p1 = planning_view.planning_state(ses).predicted
    ses.update(bias_scale=0.0)
    p0 = planning_view.planning_state(ses).predicted
    assert p0.rigid_mm < p1.rigid_mm  # the bias (kinematic error) is the scene's larger error
    ses.update(bias_scale=1.0, noise_scale=2.0)
    p2 = planning_view.planning_state(ses).predicted
    assert p2.rrbc_mm > p1.rrbc_mm  # RRBC carries fiducial noise into the targets


def test_suggest_then_accept_covers_the_regions_and_lowers_the_prediction(scene):
    ses = ExplorerSession.from_scene(scene)
    ses.move("fiducials", "F1", F1_AWAY)
    before = planning_view.planning_state(ses)
    assert before.coverage_of("H1") < 1.0
    result = planning_view.suggest_fiducials(ses, 4, seed=0)
    assert ses.suggestion is result and planning_view.suggestion_current(ses)
    assert len(result.suggested_ids) == 4 and np.asarray(result.suggested).shape == (4, 3)
    # suggested places are usable candidates of the scene, at their candidate positions
    mask, _ = planning.usable_candidates(planning_view.planning_scene(ses))
    usable = {cid for cid, ok in zip(scene.candidates.ids, mask) if ok}
    assert set(result.suggested_ids) <= usable
    for cid, p in zip(result.suggested_ids, result.suggested):
        np.testing.assert_allclose(p, scene.candidates.position(cid))
    np.testing.assert_array_equal(result.coverage, before.coverage)  # the planner saw the dragged layout
    assert result.predicted_after.rrbc_mm < result.predicted.rrbc_mm

    ev = planning_view.accept_suggestions(ses)
    assert ev.fiducial_ids[-4:] == tuple(result.suggested_ids) and ses.accepted == tuple(result.suggested_ids)
    np.testing.assert_allclose(ev.fiducial_positions[-4:], result.suggested)
    assert ev.included[-4:].all() and ev.summary["fiducials_used"] == len(scene.fiducials) + 4
    assert ses.suggestion is None
    after = planning_view.planning_state(ses)
    assert after.fiducials_used == len(scene.fiducials) + 4
    # coverage where the plan said: 1 where it predicted 1, and the predicted RMST went down
    np.testing.assert_array_equal(after.coverage, np.asarray(result.coverage_after))
    assert result.coverage_after[0] == 1.0 and after.coverage_of("H1") == 1.0  # H1 covered again
    np.testing.assert_array_equal(after.coverage, np.ones(len(scene.targets)))
    assert after.predicted.rrbc_mm < before.predicted.rrbc_mm
    assert after.predicted.rrbc_mm == pytest.approx(result.predicted_after.rrbc_mm)

    # the new fiducials are measured from the error model, noise seeded by their id (stable over re-evaluation)
    i = ev.fiducial_ids.index(result.suggested_ids[0])
    p = ev.fiducial_positions[i]
    fresh = ses.measure_points("fiducials", [result.suggested_ids[0]], p[None])
    np.testing.assert_allclose(ev.fiducial_readings.robot[i], fresh.robot[0], atol=1e-9)
    np.testing.assert_allclose(ev.fiducial_readings.sensor[i], fresh.sensor[0], atol=1e-9)
    assert np.linalg.norm(ev.fiducial_readings.robot[i] - p) > 0  # bias and noise, not the ideal point
    np.testing.assert_array_equal(ses.evaluate().corrections[i], ev.corrections[i])
    # and they can be dragged and excluded like any fiducial
    ses.move("fiducials", result.suggested_ids[0], p + [0.0, 0.0, 5.0])
    ses.set_excluded(result.suggested_ids[1], True)
    assert planning_view.planning_state(ses).fiducials_used == len(scene.fiducials) + 3


def test_accept_explicit_ids_positions_and_bad_input(scene):
    ses = ExplorerSession.from_scene(scene)
    with pytest.raises(InputError, match="Suggest"):
        planning_view.accept_suggestions(ses)  # nothing suggested yet
    for bad in (0, -2, "four"):
        with pytest.raises(InputError, match="number of fiducials"):
            planning_view.suggest_fiducials(ses, bad)
    n = len(ses.layout["fiducials"].ids)
    with pytest.raises(InputError, match="not a candidate"):
        planning_view.accept_suggestions(ses, ["grid-0001", "nowhere"])
    with pytest.raises(InputError, match="finite"):
        planning_view.accept_suggestions(ses, [[1.0, np.nan, 2.0]])
    assert len(ses.layout["fiducials"].ids) == n  # refused: unchanged
    ev = planning_view.accept_suggestions(ses, ["grid-0001"])
    assert ev.fiducial_ids[-1] == "grid-0001"
    ev = planning_view.accept_suggestions(ses, [[500.0, 0.0, 40.0], [450.0, 0.0, 40.0]])
    assert ev.fiducial_ids[-2:] == ("P1", "P2")
    ev = planning_view.accept_suggestions(ses, ["grid-0001"])  # the same place again gets an id of its own
    assert ev.fiducial_ids[-1] == "grid-0001-2" and len(set(ev.fiducial_ids)) == len(ev.fiducial_ids)
    # a place the arm cannot reach is refused and the session keeps its layout
    with pytest.raises(InputError):
        planning_view.accept_suggestions(ses, [[5000.0, 0.0, 0.0]])
    assert ses.layout["fiducials"].ids == ev.fiducial_ids


def test_measured_data_say_why_they_cannot_plan():
    ses = ExplorerSession.from_measurements(read_measurements(EXAMPLE))
    for call in (
        lambda: planning_view.planning_state(ses),
        lambda: planning_view.suggest_fiducials(ses, 2),
        lambda: planning_view.accept_suggestions(ses),
        lambda: planning_view.planning_scene(ses),
    ):
        with pytest.raises(InputError, match="planning needs a scene"):
            call()


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_every_shipped_scene_plans(path):
    sc = load_scene(path)
    ses = ExplorerSession.from_scene(sc, Settings(seed=sc.seed))
    st = planning_view.planning_state(ses)
    assert len(st.coverage) == len(sc.targets) and np.all((st.coverage >= 0) & (st.coverage <= 1))
    p = st.predicted
    assert all(np.isfinite([p.rigid_mm, p.rigid_std_mm, p.rrbc_mm, p.rrbc_std_mm])) and p.rigid_mm > 0
