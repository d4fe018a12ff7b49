"""Gravity loads and load terms (`rrbc_core.models.loads`): the torques are the gravity's generalised forces (the
negative gradient of the potential energy, by finite differences), the term Jacobians are the derivatives of the
deflected kinematics, and terms the data cannot see are not candidates."""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.models.chain import Chain
from rrbc_core.models.kinematics import ROBOT_DH
from rrbc_core.models.loads import (
    GRAVITY,
    candidate_terms,
    deflections,
    gravity_loads,
    named_terms,
    term_jacobian,
)
from rrbc_core.models.urdf import load_urdf
from rrbc_core.simulation.arm_data import random_poses


def _potential(chain, q) -> np.ndarray:
    """−Σ m g·c (J) per pose: the potential energy of the chain's segments."""
    _, _, f_rot, f_pos = chain.frames(q)
    centre = f_pos + np.einsum("nkij,kj->nki", f_rot, chain.inertia[:, 1:])
    return -np.sum(chain.inertia[:, 0] * (centre @ np.array(GRAVITY)), axis=1) / 1000.0


@pytest.mark.parametrize("robot", ["lift_arm", "ur5", "panda"])
def test_torques_are_the_gradient_of_the_potential(robot):
    chain = load_urdf(robot)
    q = random_poses(chain, np.random.default_rng(3), 7)
    loads = gravity_loads(chain, q)
    for k, j in enumerate(chain.joints):
        if j.prismatic or j.multiplier != 1.0:
            continue
        e = np.zeros(q.shape[1])
        e[j.driver] = 1e-6
        expected = -(_potential(chain, q + e) - _potential(chain, q - e)) / 2e-6
        np.testing.assert_allclose(loads.torque[:, k], expected, atol=1e-5 * (1 + np.abs(expected).max()))


def test_a_column_carries_the_moment_of_the_arm_above_it():
    """The lift column's perpendicular moment is the arm's weight times its horizontal lever about the column."""
    chain = load_urdf("lift_arm")
    q = random_poses(chain, np.random.default_rng(4), 5)
    loads = gravity_loads(chain, q)
    g_rot, g_pos, f_rot, f_pos = chain.frames(q)
    centre = f_pos + np.einsum("nkij,kj->nki", f_rot, chain.inertia[:, 1:])
    force = chain.inertia[:, 0, None] * np.array(GRAVITY)
    moment = np.sum(np.cross(centre - g_pos[:, :1], force[None]), axis=1) / 1000.0  # about the column's origin
    local = np.einsum("nji,nj->ni", g_rot[:, 0], moment)
    local[:, 2] = 0.0  # the column's axis is z
    np.testing.assert_allclose(loads.moment_perp[:, 0], local, atol=1e-9)
    assert np.all(np.linalg.norm(local, axis=1) > 10.0)  # tens of N·m: the arm leans out


@pytest.mark.parametrize("robot", ["lift_arm", "ur5"])
def test_term_jacobian_is_the_derivative_of_the_deflected_arm(robot):
    chain = load_urdf(robot)
    q = random_poses(chain, np.random.default_rng(5), 6)
    loads = gravity_loads(chain, q)
    terms = candidate_terms(chain, gravity_loads(chain, random_poses(chain, np.random.default_rng(6), 200)), True)
    assert terms
    coef = np.full(len(terms), 1e-5)
    _, jp, _ = chain.kinematics(
        q, dv=deflections(chain, terms, coef, loads)[0], drot=deflections(chain, terms, coef, loads)[1]
    )
    jt = term_jacobian(terms, loads, jp)
    for t in range(len(terms)):
        h = np.zeros(len(terms))
        h[t] = 1e-7
        plus = chain.kinematics(q, jacobians=False, dv=(d := deflections(chain, terms, coef + h, loads))[0], drot=d[1])[
            0
        ]
        minus = chain.kinematics(
            q, jacobians=False, dv=(d := deflections(chain, terms, coef - h, loads))[0], drot=d[1]
        )[0]
        np.testing.assert_allclose(jt[:, :, t], (plus - minus) / 2e-7, rtol=1e-3, atol=1e-3)


def test_candidates_are_the_terms_the_data_see():
    chain = load_urdf("lift_arm")
    loads = gravity_loads(chain, random_poses(chain, np.random.default_rng(7), 100))
    names = [t.name for t in candidate_terms(chain, loads)]
    assert "lift_joint.bending" in names and "upper_arm_joint.compliance" in names
    assert "shoulder_joint.compliance" not in names  # a vertical axis carries no gravity torque
    assert "spindle_joint.compliance" not in names  # nothing hangs on the tool spindle
    assert not any(n.endswith("backlash") for n in names)


def test_a_model_without_masses_is_refused_by_name():
    with pytest.raises(InputError, match="no link masses"):
        gravity_loads(Chain.from_dh(ROBOT_DH["ur5"], "ur5"), np.zeros((2, 6)))
    with pytest.raises(InputError, match="no load term"):
        named_terms(load_urdf("lift_arm"), ["elbow.compliance"])
    with pytest.raises(InputError, match="bending is a prismatic"):
        named_terms(load_urdf("lift_arm"), ["forearm_joint.bending"])
