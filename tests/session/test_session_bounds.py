"""One answer everywhere (issue 37, item 3): the bounds the app shows for a measured file's targets and checks are
`rrbc correct`'s, computed by the same core function; a drag changes them."""

import numpy as np
import pytest

from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.io.groups import split_groups
from rrbc_core.session.explorer import ExplorerSession
from rrbc_core.simulation.field_data import field_measurements
from rrbc_core.simulation.station_data import station_measurements


def _by_id(res):
    out = {}
    for group, pb, pr in (
        (res.targets, res.bounds.targets, res.bounds.targets_rigid),
        (res.checks, res.bounds.checks, res.bounds.checks_rigid),
    ):
        if pb is None:
            continue
        for k, pid in enumerate(group.ids):
            out[pid] = (pb.bound95_mm[k], pr.bound95_mm[k], {n: v[k] for n, v in pb.budget_mm.items()})
    return out


@pytest.mark.parametrize("repeats", [False, True])
def test_the_sessions_bounds_are_rrbc_corrects(repeats):
    mset = field_measurements(21, repeats=repeats, n_checks=30)
    session = ExplorerSession.from_measurements(mset)
    ev = session.evaluate()
    expected = _by_id(correct_measurements(mset, session.settings.method))
    assert ev.bounds is not None and len(ev.targets.ids) == len(expected)
    for k, pid in enumerate(ev.targets.ids):
        b, br, budget = expected[pid]
        got = ev.bounds.rrbc.bound95_mm[k]
        assert (np.isnan(b) and np.isnan(got)) or got == pytest.approx(b, rel=1e-9)
        assert ev.bounds.rigid.bound95_mm[k] == pytest.approx(br, rel=1e-9, nan_ok=True)
        if np.isfinite(b):
            assert {n: ev.bounds.rrbc.budget_mm[n][k] for n in budget} == pytest.approx(budget, rel=1e-9)
    assert ev.warnings == correct_measurements(mset, session.settings.method).warnings()


def test_a_station_and_a_dragged_fiducial():
    mset = station_measurements(41, stations=2, eval_fiducials=0.5)
    session = ExplorerSession.from_measurements(mset, station="station2")
    ev = session.evaluate()
    alone = correct_measurements(dict(split_groups(mset))["station2"], session.settings.method)
    exp = _by_id(alone)
    assert [ev.bounds.rrbc.bound95_mm[k] for k, pid in enumerate(ev.targets.ids)] == pytest.approx(
        [exp[pid][0] for pid in ev.targets.ids], nan_ok=True
    )
    # a target moved away from the fiducials: its bound widens or, beyond what they test, is withheld
    pid = ev.targets.ids[0]
    moved = session.move("targets", pid, session.layout["targets"].positions[0] + np.array([0.0, 0.0, 250.0]))
    k = moved.targets.ids.index(pid)
    b0, b1 = ev.bounds.rrbc.bound95_mm[0], moved.bounds.rrbc.bound95_mm[k]
    assert np.isnan(b1) or b1 > b0


def test_dragging_a_fiducial_in_a_scene_changes_the_targets_bounds():
    from rrbc_core.io.scene import default_scene_path
    from rrbc_core.io.scene_toml import load_scene

    session = ExplorerSession.from_scene(load_scene(default_scene_path()))
    ev = session.evaluate()
    assert ev.bounds is not None and np.any(np.isfinite(ev.bounds.rrbc.bound95_mm))
    fid = session.layout["fiducials"].ids[0]
    pos = session.layout["fiducials"].positions[0] + np.array([60.0, -40.0, 0.0])
    after = session.move("fiducials", fid, pos).bounds.rrbc
    assert not np.allclose(np.nan_to_num(after.bound95_mm), np.nan_to_num(ev.bounds.rrbc.bound95_mm))


def test_a_fiducials_live_drag_keeps_the_folds_profile_and_its_end_is_exact():
    """A drag's update (`move(..., live=True)`) keeps the fiducials' cross-validation profile from before the drag
    (a statistic of all the fiducials) and computes the rest for the layout as it is: the moved fiducial's own
    geometry changes the bounds at once. The drag's end (`live` False) gives exactly what a fresh session of the same
    layout gives, as `rrbc correct` would."""
    from rrbc_core.io.scene import default_scene_path
    from rrbc_core.io.scene_toml import load_scene

    scene = load_scene(default_scene_path())
    session = ExplorerSession.from_scene(scene)
    first = session.evaluate().bounds
    fid = session.layout["fiducials"].ids[0]
    start = session.layout["fiducials"].positions[0].copy()
    goal = start + np.array([60.0, -30.0, 0.0])
    for k in (1, 2, 3):
        live = session.move("fiducials", fid, start + (goal - start) * k / 3, live=True).bounds
        assert live.source.profile is first.source.profile  # kept for the drag
    assert not np.array_equal(live.rrbc.bound95_mm, first.rrbc.bound95_mm, equal_nan=True)  # followed the fiducial
    end = session.move("fiducials", fid, goal).bounds
    assert end.source.profile is not first.source.profile
    fresh = ExplorerSession.from_scene(scene)
    exact = fresh.move("fiducials", fid, goal).bounds
    # (a drag's path and one move differ in rounding only: 1e-14 here, with or without the live updates)
    np.testing.assert_allclose(end.rrbc.bound95_mm, exact.rrbc.bound95_mm, rtol=1e-12)
    np.testing.assert_allclose(end.rrbc.cov_mm2, exact.rrbc.cov_mm2, rtol=1e-12, atol=1e-18)


def test_the_error_slice_shows_at_a_target_the_bound_the_target_has():
    """The slice's `bound95` at a grid point placed on a target is that target's own 95 % bound (the same basis,
    `correction.bounds.bound_points`; the slice's reading is noise-free, the target's is not: a few µm apart), and the
    slice has no bound where the fiducials' cross-validation did not reach."""
    from rrbc_core.io.scene import default_scene_path
    from rrbc_core.io.scene_toml import load_scene
    from rrbc_core.session.figures import error_slice
    from rrbc_core.session.slices import SlicePlane

    session = ExplorerSession.from_scene(load_scene(default_scene_path()))
    ev = session.evaluate()
    assert ev.bounds is not None
    for k, (pid, p) in enumerate(zip(ev.targets.ids, ev.targets.positions)):
        want = ev.bounds.rrbc.bound95_mm[k]
        assert np.isfinite(want), pid
        # a 3 x 3 grid whose centre is the target
        plane = SlicePlane("z", float(p[2]), (p[0] - 10.0, p[1] - 10.0), (p[0] + 10.0, p[1] + 10.0), n=3)
        assert error_slice(session, plane).values["bound95"][1, 1] == pytest.approx(want, rel=1e-2), pid
    # over the arm's reach (finite errors), bounds near the fiducials and none far beyond what they tested
    z = float(np.mean(ev.targets.positions[:, 2]))
    sl = error_slice(session, SlicePlane("z", z, (-1500.0, -1500.0), (1500.0, 1500.0), n=24))
    reach = np.isfinite(sl.values["rrbc"])
    bound = np.isfinite(sl.values["bound95"])
    assert np.any(bound & reach) and np.any(~bound & reach) and not np.any(bound & ~reach)
