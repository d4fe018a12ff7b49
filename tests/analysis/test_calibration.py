"""Model-based calibration (rrbc_core.analysis.calibration) on planted kinematic errors of random size (seeded), on
the UR5's DH chain and on URDF arms (a packaged Panda, our lift-column arm with a mimic joint): the identifiable
parameters come back within their stated uncertainty, the unidentifiable ones are said to be so, and predictions at
new poses reach the noise floor."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rrbc_core.analysis import calibration
from rrbc_core.analysis.calibration import calibrate, vec_commands
from rrbc_core.analysis.vec_compare import compare
from rrbc_core.errors import InputError
from rrbc_core.io.joints import joint_values
from rrbc_core.models.chain import Chain
from rrbc_core.models.kinematics import UR5, UR5_TOOL_DOWN_SEED
from rrbc_core.models.urdf import load_urdf
from tests.support.urdf_arms import LIFT_ARM, chain_measurements, random_errors, random_poses


def _ur5_poses(rng, n):
    return UR5_TOOL_DOWN_SEED + rng.uniform(-0.8, 0.8, (n, 6))


def _chains():
    from rrbc_core.models.urdf import load_urdf

    return {
        "ur5-dh": (Chain.from_dh(UR5, "ur5", tool_mm=[0.0, 0.0, 100.0]), _ur5_poses),
        "panda": (load_urdf("panda", tip="panda_hand_tcp"), None),
        "lift": (load_urdf(LIFT_ARM, tool_mm=[0.0, 0.0, 80.0]), None),
    }


@pytest.mark.parametrize("arm,seed", [("ur5-dh", 11), ("ur5-dh", 12), ("panda", 13), ("lift", 14)])
def test_planted_errors_are_recovered_within_their_uncertainty_and_predictions_reach_the_noise_floor(arm, seed):
    chain, poses = _chains()[arm]
    rng = np.random.default_rng(seed)
    draw = poses or (lambda r, n: random_poses(chain, r, n))
    truth = random_errors(chain, rng, size=rng.uniform(0.5, 2.0))
    sigma = rng.uniform(0.01, 0.04)  # sensor noise per axis, mm
    rot = Rotation.from_rotvec(rng.normal(size=3) * 0.5).as_matrix()
    t = rng.uniform(-1500, 1500, 3)
    q = draw(rng, 80)
    p = chain.forward(q, truth)
    s = (p - t) @ rot + rng.normal(0, sigma, p.shape)
    cal = calibrate(chain, q, s)
    ok = cal.identifiable
    # from positions alone some parameters (and combinations with the base) cannot be separated
    assert 0 < ok.sum() < chain.n_params and cal.rank < chain.n_params + 6
    z = (cal.delta[ok] - truth[ok]) / cal.delta_se[ok]
    assert np.all(np.abs(z) < 4.5), dict(zip(np.array(chain.param_names)[ok], np.round(z, 2)))
    assert 0.2 < np.mean(z**2) < 3.0  # the stated uncertainties are of the right size (chi-square per parameter ~ 1)
    assert abs(cal.sigma_mm / sigma - 1) < 0.35  # the residual noise estimate
    # new poses, noise-free: the identified arm predicts where the real one goes to within the noise floor
    qc = draw(rng, 40)
    pc = chain.forward(qc, truth)
    sc = (pc - t) @ rot
    err = np.sqrt(np.mean(np.sum((cal.sensor_to_robot(sc) - cal.forward(qc)) ** 2, axis=1)))
    nominal_err = np.sqrt(np.mean(np.sum((pc - chain.forward(qc)) ** 2, axis=1)))
    assert err < np.sqrt(3) * sigma and err < 0.1 * nominal_err
    # VEC's command: the nominal controller, sent it, puts the real arm's tool on the point
    cmd = vec_commands(cal, sc, qc)
    reached = _reached_by_command(chain, truth, cmd, qc)
    assert np.sqrt(np.mean(np.sum((reached - pc) ** 2, axis=1))) < np.sqrt(3) * sigma


def _reached_by_command(chain, truth, cmd, q0):
    """Where the true arm goes when the nominal controller is sent `cmd`: the nominal IK of cmd near q0 (Gauss–Newton,
    position only), then the true forward kinematics."""
    q = q0.copy()
    for _ in range(20):
        p, _, jq = chain.kinematics(q)
        q = q + np.einsum("nij,nj->ni", np.linalg.pinv(jq), cmd - p)
    return chain.forward(q, truth)


def test_too_few_poses_are_refused():
    chain = Chain.from_dh(UR5, "ur5")
    with pytest.raises(InputError, match="at least 6 poses"):
        calibrate(chain, np.zeros((3, 6)), np.zeros((3, 3)))


def test_a_misspecified_arm_is_fitted_to_its_least_squares_minimum_and_a_fit_cut_short_says_so(monkeypatch):
    """A lift arm that bends under load, fitted with geometric terms alone (the model cannot hold the error): the
    iteration ends at a minimum of the sum of squares (no small step along any identified direction lowers it),
    and `rrbc calibrate` warns only when the fit stopped at its step limit still lowering the residuals."""
    chain = load_urdf("lift_arm")
    plant = {"lift_joint.bending": 6e-6, "upper_arm_joint.compliance": 3.5e-5, "forearm_joint.compliance": 2.5e-5}
    m = chain_measurements(chain, 2, n_fid=60, n_chk=20, noise_mm=0.05, kin_size=1.0, compliance=plant)
    rows = [i for i, r in enumerate(m.roles) if r in ("registration", "fiducial")]
    q, s = joint_values(m, chain)[rows], np.asarray(m.sensor)[rows]
    cal = calibration.calibrate(chain, q, s)
    assert cal.converged
    cost = float(np.sum(cal.residuals**2))
    res, j = calibration._system(
        chain, q, s, cal.delta, cal.rotation[None], cal.translation[None], np.zeros(len(q), int)
    )
    assert float(res @ res) == pytest.approx(cost)
    # the gradient within the identified combinations vanishes at the end (relative to its size at the start)
    sc = calibration._scales(chain)
    _, sv, vt = np.linalg.svd(j / sc, full_matrices=False)
    basis = vt[: cal.rank].T
    start, j0 = calibration._system(
        chain, q, s, np.zeros(chain.n_params), cal.rotation[None], cal.translation[None], np.zeros(len(q), int)
    )
    assert np.linalg.norm(basis.T @ (j / sc).T @ res) < 1e-4 * np.linalg.norm(basis.T @ (j0 / sc).T @ start)
    assert calibration.NOT_CONVERGED not in compare(m, urdf="lift_arm")["warnings"]
    monkeypatch.setattr(calibration, "MAX_STEPS", 1)
    assert not calibration.calibrate(chain, q, s).converged
    assert calibration.NOT_CONVERGED in compare(m, urdf="lift_arm")["warnings"]
