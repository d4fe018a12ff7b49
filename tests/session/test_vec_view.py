"""VEC beside rigid and RRBC in the session (issue 15, item 4): tool orientations, and why position-only RRBC cannot
follow an arm error that depends on the configuration while a calibrated arm model can."""

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import read_measurements
from rrbc_core.io.scene import default_scene_path
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.session import vec_view
from rrbc_core.session.explorer import ExplorerSession
from rrbc_core.session.tools import TILT_MAX_DEG, tool_rotation
from tests.paths import ROOT


@pytest.fixture()
def session():
    return ExplorerSession.from_scene(load_scene(default_scene_path()))


@pytest.mark.parametrize("tilt, az", [(0, 0), (30, 0), (30, 90), (45, -135)])
def test_tool_rotation_leans_the_tool_axis_towards_the_azimuth(tilt, az):
    r = tool_rotation(0.0, tilt, az)
    t, a = np.radians(tilt), np.radians(az)
    assert np.allclose(r[:, 2], [np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), -np.cos(t)], atol=1e-12)
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(r), 1.0)


def test_rrbc_cannot_follow_a_tilted_tool_and_vec_calibrated_in_varied_poses_can(session):
    vec_view.set_varied_registration(session, True)
    pid = session.layout["targets"].ids[0]
    ev0, v0 = session.evaluate(), vec_view.vec_view(session)
    vec_view.set_target_tool(session, pid, 40.0, 0.0)
    ev1, v1 = session.evaluate(), vec_view.vec_view(session)
    # the physical point and its noise are the same: RRBC's command (position only) does not move at all...
    assert np.array_equal(ev0.targets.robot_rrbc[0], ev1.targets.robot_rrbc[0])
    # ... while the command that truly reaches the point moves with the arm's configuration
    shift = ev1.targets.truth[0] - ev0.targets.truth[0]
    assert np.linalg.norm(shift) > 0.1
    assert ev1.targets.error_rrbc[0] > ev0.targets.error_rrbc[0] + 0.5 * np.linalg.norm(shift)
    # VEC's command follows the shift (within a quarter of it: the identified arm is close to the true one)
    vec_shift = v1.robot_vec[0] - v0.robot_vec[0]
    assert np.linalg.norm(vec_shift - shift) < 0.25 * np.linalg.norm(shift)
    assert v1.error_vec[0] < v1.error_rrbc[0]
    assert tuple(v1.tools[0]) == (40.0, 0.0)


def test_vec_from_tool_down_poses_alone_identifies_less(session):
    down = vec_view.vec_view(session)
    vec_view.set_varied_registration(session, True)
    varied = vec_view.vec_view(session)
    assert varied.rank > down.rank  # orientation-dependent combinations become identifiable
    assert down.poses == varied.poses == len(session.layout["registration"].ids) + len(session.layout["fiducials"].ids)


def test_bad_tool_orientations_are_refused_and_leave_the_session_unchanged(session):
    pid = session.layout["targets"].ids[0]
    before = session.evaluate().targets.truth.copy()
    for tilt, az in [(TILT_MAX_DEG + 1, 0), (-1, 0), (float("nan"), 0), (10, 400)]:
        with pytest.raises(InputError):
            vec_view.set_target_tool(session, pid, tilt, az)
    with pytest.raises(InputError):
        vec_view.set_target_tool(session, "no-such-target", 10, 0)
    assert session.target_tools == {}
    assert np.array_equal(session.evaluate().targets.truth, before)


def test_no_vec_without_a_kinematic_arm(tmp_path):
    mset = read_measurements(ROOT / "rrbc_core" / "data" / "example_measurements.csv")
    measured = ExplorerSession.from_measurements(mset)
    assert vec_view.vec_view(measured) is None and not measured.has_arm
    with pytest.raises(InputError):
        vec_view.set_target_tool(measured, measured.layout["targets"].ids[0], 10, 0)
