"""The arm the app draws (rrbc_core.session.arm): posed by the nominal controller to reach a place; the real arm's
tool lands where the scene's kinematic error puts it, which agrees with the measurement model's truth."""

from dataclasses import replace

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import read_measurements
from rrbc_core.io.scene import default_scene_path
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.models.kinematics import forward, tool_down
from rrbc_core.models.measurement import MeasurementModel
from rrbc_core.session.arm import arm_pose
from rrbc_core.session.explorer import ExplorerSession


@pytest.fixture(scope="module")
def scene():
    return load_scene(default_scene_path())


def test_the_nominal_arm_reaches_the_commanded_place_and_its_frames_chain_up(scene):
    p = np.array([400.0, -150.0, 15.0])
    pose = arm_pose(scene, p)
    np.testing.assert_allclose(pose.frames[-1, :3, 3], p, atol=1e-6)
    np.testing.assert_allclose(pose.frames[0], np.eye(4))
    assert pose.frames.shape == (8, 4, 4)
    for f in pose.frames:  # proper rigid frames
        np.testing.assert_allclose(f[:3, :3] @ f[:3, :3].T, np.eye(3), atol=1e-9)
    np.testing.assert_allclose(pose.frames[-1, :3, 2], [0, 0, -1], atol=1e-6)  # the tool points down


def test_the_real_arm_lands_where_the_measurement_models_truth_says(scene):
    """The truth c of a physical point p is the command that really reaches p (models.measurement). Sending
    the arm to c must therefore land it at p, up to the second-order change of the error over |c - p| ~ 1 mm."""
    model = MeasurementModel(scene.sensor_to_robot, scene.error_model, scene.joint_seed)
    rng = np.random.default_rng(11)
    for p in rng.uniform([350, -200, 10], [600, 200, 120], (5, 3)):
        pts = model.points(p[None], tool_down(scene.tool_yaw_deg))
        c = model.read(pts).truth[0]
        assert np.linalg.norm(c - p) > 0.2  # the arm's error is there to see
        pose = arm_pose(scene, c)
        np.testing.assert_allclose(pose.landed, p, atol=0.02)


def test_bias_size_scales_the_landing_and_bad_input_is_refused(scene):
    p = np.array([450.0, 50.0, 15.0])
    full = arm_pose(scene, p, 1.0)
    half = arm_pose(scene, p, 0.5)
    none = arm_pose(scene, p, 0.0)
    np.testing.assert_allclose(half.landed - p, 0.5 * (full.landed - p), atol=1e-9)
    np.testing.assert_allclose(none.landed, p)
    term = next(t for t in scene.error_model.terms("robot") if hasattr(t, "true_robot"))
    real, _ = forward(term.true_robot(), full.joints)
    np.testing.assert_allclose(full.landed, real)
    with pytest.raises(InputError, match="reach"):
        arm_pose(scene, [3000.0, 0.0, 0.0])
    example = default_scene_path().parents[1] / "rrbc_core" / "data" / "example_measurements.csv"
    measured = ExplorerSession.from_measurements(read_measurements(example))
    with pytest.raises(InputError, match="no arm model"):
        arm_pose(measured.scene, p)


def test_measured_data_pose_their_robot_from_the_joint_columns(tmp_path):
    """`rrbc view data.csv --urdf`: the robot at each point's joint values, its tool on the point's robot reading;
    a URDF that is not the file's robot, or a scene, is refused in one line."""
    from rrbc_core.io.measurements_write import write_measurements
    from rrbc_core.models.urdf import load_urdf
    from rrbc_core.session.arm import attach_arm, measured_arm_pose
    from rrbc_core.simulation.arm_data import chain_measurements

    mset = chain_measurements(load_urdf("ur5", tip="tool0"), 3, n_fid=12, n_chk=6, n_tgt=2, noise_mm=0.05)
    write_measurements(tmp_path / "d.csv", mset)
    session = ExplorerSession.from_measurements(read_measurements(tmp_path / "d.csv"))
    attach_arm(session, "ur5", tip="tool0")
    for kind in ("registration", "fiducials"):
        g = session.layout[kind]
        for pid, p in zip(g.ids, g.positions):
            np.testing.assert_allclose(measured_arm_pose(session, kind, pid).commanded, p, atol=0.5)  # noise 0.05
    assert len(session.arm_joints) == len(set(zip(mset.roles, mset.ids)))
    with pytest.raises(InputError, match="not this robot"):
        attach_arm(ExplorerSession.from_measurements(read_measurements(tmp_path / "d.csv")), "ur10", tip="tool0")
    with pytest.raises(InputError, match="no joint columns"):
        attach_arm(ExplorerSession.from_measurements(read_measurements(tmp_path / "d.csv")), "panda")
    with pytest.raises(InputError, match="a scene names its own"):
        attach_arm(ExplorerSession.from_scene(load_scene(default_scene_path())), "ur5")


def test_rrbc_view_refuses_a_urdf_that_cannot_pose_the_files_robot(tmp_path):
    import subprocess

    from tests.paths import EXAMPLE_CSV, RRBC

    for args, words in (
        ([str(EXAMPLE_CSV), "--urdf", "panda"], "no joint columns"),
        ([str(EXAMPLE_CSV), "--tip", "tool0"], "give --urdf"),
        ([str(default_scene_path()), "--urdf", "ur5"], "a scene names its own"),
    ):
        r = subprocess.run([*RRBC, "view", *args, "--port", "0"], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and words in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert r.stdout == ""


def test_a_probe_is_given_with_tool_and_a_missing_one_is_named(tmp_path):
    """Issue 39: `rrbc view data.csv --urdf ... --tool X,Y,Z` (a 109 mm probe); without it the refusal says which
    tool would make the model fit, instead of blaming --tip."""
    from rrbc_core.io.measurements_write import write_measurements
    from rrbc_core.models.urdf import load_urdf
    from rrbc_core.session.arm import attach_arm
    from rrbc_core.simulation.arm_data import chain_measurements

    probe = load_urdf("ur5", tip="tool0", tool_mm=[0.0, 0.0, 109.0])
    mset = chain_measurements(probe, 5, n_fid=12, n_chk=6, n_tgt=2, noise_mm=0.05)
    mset = replace(mset, extra={k: v for k, v in mset.extra.items() if not k.startswith("tool_")})
    write_measurements(tmp_path / "d.csv", mset)

    def fresh():
        return ExplorerSession.from_measurements(read_measurements(tmp_path / "d.csv"))

    with pytest.raises(InputError, match=r"give --tool -?0\.0,-?0\.0,109\.0"):
        attach_arm(fresh(), "ur5", tip="tool0")
    for tool in ((0.0, 0.0, 109.0), 109.0):
        s = fresh()
        attach_arm(s, "ur5", tip="tool0", tool=tool)
        assert s.arm_spec == ("ur5", "tool0", None, s.arm_spec[3]) and np.allclose(s.arm_spec[3], [0, 0, 109])
