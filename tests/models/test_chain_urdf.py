"""The robot model (rrbc_core.models.chain) and its URDF reader (rrbc_core.models.urdf): the packaged UR5 and UR10
URDFs agree with our DH tables to the nanometre (up to the URDF's base rotation), the Jacobians agree with finite
differences, mimic joints follow their master (also off the chain), prismatic joints read metres as mm, the tip and
base are chosen as documented, and bad files or links are refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.models.chain import Chain
from rrbc_core.models.kinematics import UR5, UR10, forward
from rrbc_core.models.urdf import describe, load_urdf, packaged_urdf
from rrbc_core.registration import register
from tests.support.urdf_arms import LIFT_ARM, random_errors, random_poses


@pytest.mark.parametrize("name,dh", [("ur5", UR5), ("ur10", UR10)])
def test_the_packaged_ur_urdfs_are_our_dh_tables_up_to_the_base_rotation(name, dh):
    chain = load_urdf(name, tip="tool0")
    q = np.random.default_rng(0).uniform(-3, 3, (50, 6))
    p_urdf = chain.forward(q)
    p_dh, _ = forward(dh, q)
    reg = register("least-squares", p_dh, p_urdf)
    assert reg.fre_rms_mm < 1e-6
    np.testing.assert_allclose(reg.mapping.rotation, np.diag([-1.0, -1.0, 1.0]), atol=1e-9)  # base_link vs DH base
    np.testing.assert_allclose(Chain.from_dh(dh, name).forward(q), p_dh, atol=1e-9)


@pytest.mark.parametrize("arm", ["ur5-dh", "panda", "lift"])
@pytest.mark.parametrize("size", [0.0, 40.0])
def test_jacobians_agree_with_finite_differences(arm, size):
    """At the nominal chain and far from it (errors 40x a real arm's: 2° and 8 mm), where calibration steps."""
    chain = {
        "ur5-dh": lambda: Chain.from_dh(UR5, "ur5", tool_mm=[10.0, -5.0, 100.0]),
        "panda": lambda: load_urdf("panda", tip="panda_rightfinger"),
        "lift": lambda: load_urdf(LIFT_ARM, tool_mm=[5.0, 0.0, 50.0]),
    }[arm]()
    rng = np.random.default_rng(3)
    q = random_poses(chain, rng, 20)
    delta = random_errors(chain, rng, size)
    _, jp, jq = chain.kinematics(q, delta)
    h = 1e-6
    num = np.stack(
        [(chain.forward(q, delta + h * e) - chain.forward(q, delta - h * e)) / (2 * h) for e in np.eye(chain.n_params)],
        axis=2,
    )
    # the nominal directions the chain's Jacobian used before (exact only at size 0) fail this at size 40
    np.testing.assert_allclose(jp, num, atol=1e-6 * np.abs(num).max())
    numq = np.stack(
        [(chain.forward(q + h * e, delta) - chain.forward(q - h * e, delta)) / (2 * h) for e in np.eye(len(q[0]))], 2
    )
    np.testing.assert_allclose(jq, numq, atol=1e-6 * np.abs(numq).max())


def test_a_mimic_joint_follows_its_master_off_the_chain_and_a_prismatic_joint_reads_metres():
    chain = load_urdf(LIFT_ARM)
    assert chain.tip == "tcp" and chain.base == "world"  # the end of the longest chain, the root
    assert chain.columns[-1] == "belt_joint" and [i.unit for i in chain.inputs][:2] == ["m", "rad"]
    spindle = chain.joints[-1]
    assert spindle.name == "spindle_joint" and spindle.multiplier == 0.5 and spindle.offset == pytest.approx(0.2)
    q = random_poses(chain, np.random.default_rng(1), 5)
    q2 = q.copy()
    q2[:, -1] += 2 * np.pi  # the belt turns a full turn: the spindle half a turn
    tool = load_urdf(LIFT_ARM, tool_mm=[10.0, 0.0, 0.0])
    a, b = tool.forward(q), tool.forward(q2)
    # the tool point is 10 mm + 20 mm from the spindle's axis in x (tcp origin): half a turn moves it 2 x 30 mm
    np.testing.assert_allclose(np.linalg.norm(a - b, axis=1), 60.0, atol=1e-9)
    q3 = q.copy()
    q3[:, 0] += 100.0  # the lift: 100 mm up along the column's z (the column is upright)
    np.testing.assert_allclose(chain.forward(q3) - chain.forward(q), [[0.0, 0.0, 100.0]] * 5, atol=1e-9)


def test_tip_and_base_choose_the_chain_and_bad_choices_are_refused():
    chain = load_urdf(LIFT_ARM, tip="flange", base="column")
    assert [j.name for j in chain.joints][0] == "lift_joint" and len(chain.inputs) == 7
    assert "column → flange, 7 moving joints" in describe(chain)
    with pytest.raises(InputError, match="no link 'hand'"):
        load_urdf(LIFT_ARM, tip="hand")
    with pytest.raises(InputError, match="is not above"):
        load_urdf(LIFT_ARM, tip="belt_pulley", base="carriage")
    with pytest.raises(InputError, match="no moving joint"):
        load_urdf(LIFT_ARM, tip="column")


def test_unreadable_files_and_unknown_names_are_refused_in_one_line(tmp_path):
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><joint name='j' type='revolute'><parent link='a'/>")
    for arg, words in ((bad, "cannot read as a URDF"), (tmp_path / "none.urdf", "no such URDF file")):
        with pytest.raises(InputError, match=words) as exc:
            load_urdf(arg)
        assert "\n" not in str(exc.value)
    floating = tmp_path / "floating.urdf"
    floating.write_text(
        "<robot name='f'><link name='a'/><link name='b'/><joint name='j' type='floating'>"
        "<parent link='a'/><child link='b'/></joint></robot>"
    )
    with pytest.raises(InputError, match="floating"):
        load_urdf(floating)
    assert packaged_urdf("panda").exists()


def test_random_errors_move_the_tool_by_their_size():
    chain = load_urdf("panda", tip="panda_hand_tcp")
    rng = np.random.default_rng(2)
    q = random_poses(chain, rng, 200)
    d = np.linalg.norm(chain.forward(q, random_errors(chain, rng, 1.0)) - chain.forward(q), axis=1)
    assert 0.1 < np.sqrt(np.mean(d**2)) < 5.0  # mm: a calibration's worth, not a different robot
