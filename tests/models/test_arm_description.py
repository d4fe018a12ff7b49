"""The robot the app draws from its URDF (models.arm_description, session.arm): the packaged UR descriptions follow
the DH arms joint for joint, a user's URDF is posed by its tool point, and scenes name a URDF (`robot.urdf`)."""

import shutil

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.io.scene import default_scene_path
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.models.arm_description import dh_arm_description, reach, urdf_arm_description
from rrbc_core.models.kinematics import ROBOT_DH, forward
from rrbc_core.models.urdf import bundled_urdf
from rrbc_core.session.arm import arm_description, arm_pose


@pytest.mark.parametrize("model", ["ur5", "ur10"])
def test_the_packaged_description_follows_the_dh_arm(model):
    d = dh_arm_description(model, 120.0)
    rng = np.random.default_rng(4)
    for q in rng.uniform(-np.pi, np.pi, (10, 6)):
        p, rot = forward(ROBOT_DH[model].with_tool(120.0), q)
        np.testing.assert_allclose(d.tool_point(q), p, atol=1e-6)
        tip = d.tip_frame(q)  # the flange's frame: the tool lies along its z axis
        np.testing.assert_allclose(tip[:3, 3] + 120.0 * tip[:3, 2], p, atol=1e-6)
        np.testing.assert_allclose(tip[:3, :3] @ tip[:3, :3].T, np.eye(3), atol=1e-9)
    assert set(d.joint_values_si(np.zeros(6))) == {
        "shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"
    }  # fmt: skip


def test_a_urdf_arm_reaches_by_its_tool_point_within_its_limits():
    d = urdf_arm_description("lift_arm", tool_mm=(0.0, 0.0, 50.0))
    rng = np.random.default_rng(2)
    q0 = np.array([0.5 * ((i.lower or 0) + (i.upper or 0)) for i in d.chain.inputs])
    for _ in range(5):  # points the arm does reach: those of random configurations
        q = q0 + rng.uniform(-0.5, 0.5, len(q0)) * np.array([400 if i.unit == "m" else 1.0 for i in d.chain.inputs])
        q = np.clip(q, [i.lower if i.lower is not None else -9 for i in d.chain.inputs],
                    [i.upper if i.upper is not None else 9 for i in d.chain.inputs])  # fmt: skip
        target = d.tool_point(q)
        got = reach(d, target)
        np.testing.assert_allclose(d.tool_point(got), target, atol=0.01)
        for v, i in zip(got, d.chain.inputs):
            assert (i.lower is None or v >= i.lower - 1e-9) and (i.upper is None or v <= i.upper + 1e-9)
    with pytest.raises(InputError, match="cannot put its tool on"):
        reach(d, [9000.0, 0.0, 0.0])


def _urdf_scene(tmp_path, robot_lines: str):
    src = default_scene_path()
    text = src.read_text()
    start = text.index("[robot]")
    end = text.index("[sensor]")
    text = text[:start] + "[robot]\n" + robot_lines + "\n\n" + text[end:]
    # a robot the kinematics do not model carries no kinematic or compliance error term
    text = text.replace('type = "kinematic"', 'type = "smooth_field"\nrms_mm = 0.3\nlength_mm = 300.0')
    for p in src.parent.glob("meshes/*"):
        (tmp_path / "meshes").mkdir(exist_ok=True)
        shutil.copy(p, tmp_path / "meshes" / p.name)
    shutil.copy(bundled_urdf("lift_arm"), tmp_path / "lift_arm.urdf")
    f = tmp_path / "cell.toml"
    f.write_text(text)
    return f


def test_a_scene_names_its_robots_urdf_and_the_arm_reaches_its_targets(tmp_path):
    f = _urdf_scene(tmp_path, 'model = "none"\ntool_mm = 40.0\nurdf = "panda"\ntip = "panda_link8"')
    scene = load_scene(f)
    assert scene.robot_urdf == "panda" and scene.robot_tip == "panda_link8"
    d = arm_description(scene)
    target = scene.targets[0].position
    pose = arm_pose(scene, target)
    np.testing.assert_allclose(d.tool_point(pose.joints), target, atol=0.05)
    assert pose.frames is None and np.allclose(pose.landed, target)


@pytest.mark.parametrize(
    "robot,message",
    [
        ('model = "ur5"\ntool_mm = 100.0\nurdf = "lift_arm.urdf"', 'set robot.model = "none"'),
        ('model = "none"\ntool_mm = 0.0\ntip = "flange"', "give robot.urdf too"),
        ('model = "none"\ntool_mm = 0.0\nurdf = "../elsewhere.urdf"', "leaves the scene's folder"),
        ('model = "none"\ntool_mm = 0.0\nurdf = "lift_arm.urdf"\ntip = "hand"', "no link 'hand'"),
    ],
)
def test_bad_robot_urdfs_are_refused_in_one_line(tmp_path, robot, message):
    f = _urdf_scene(tmp_path, robot)
    with pytest.raises(InputError, match=message) as err:
        load_scene(f)
    assert "\n" not in str(err.value) and "robot." in str(err.value)
