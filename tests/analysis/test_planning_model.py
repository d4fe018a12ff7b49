"""The planner's registration sensitivities (`planning_model._Registration`): summed once over the registration
points, so `rrbc plan` grows linearly with their number (issue 16: 2000 registration points once asked for a
361 GiB array). Checked against a plain loop that differentiates the least-squares fit one reading at a time."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rrbc_core.analysis import planning_model
from rrbc_core.analysis.planning_model import _homogeneous, _Registration
from rrbc_core.registration.strategies import least_squares


def _cell(seed: int, n: int):
    rng = np.random.default_rng(seed)
    robot = rng.uniform(-400, 400, (n, 3)) + [500, 0, 300]
    rot = Rotation.random(random_state=rng).as_matrix()
    sensor = (robot - robot.mean(0)) @ rot + rng.normal(0, 0.3, (n, 3))  # bias: the fit is not exact
    a = rng.normal(size=(n, 3, 3)) * rng.uniform(0.01, 0.05)
    return sensor, robot, np.einsum("nab,ncb->nac", a, a) + 1e-4 * np.eye(3)


def _plain_jacobian(sensor, robot, x, h=1e-3):
    """∂(R̂ x + t̂)/∂b_jc for one point x, one least-squares fit per perturbed reading: (N, 3 c, 3 a)."""
    out = np.empty((len(robot), 3, 3))
    for j in range(len(robot)):
        for c in range(3):
            hi, lo = robot.copy(), robot.copy()
            hi[j, c] += h
            lo[j, c] -= h
            f1, f0 = least_squares(sensor, hi).mapping, least_squares(sensor, lo).mapping
            out[j, c] = (f1.apply(x[None])[0] - f0.apply(x[None])[0]) / (2 * h)
    return out


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_registration_variance_and_shared_term_match_a_plain_loop(seed):
    sensor, robot, cov = _cell(seed, 7)
    reg = _Registration.fit(sensor, robot, cov)
    rng = np.random.default_rng(seed + 10)
    for x in rng.uniform(-300, 300, (3, 3)):
        jac = _plain_jacobian(sensor, robot, x)  # [j, c, a]
        var = sum(np.trace(jac[j].T @ cov[j] @ jac[j]) for j in range(len(robot)))
        assert reg.variance(_homogeneous(x)) == pytest.approx(var, rel=1e-5)
        for j in range(len(robot)):
            assert _homogeneous(x) @ reg.shared[j] == pytest.approx(np.trace(jac[j].T @ cov[j]), rel=1e-5, abs=1e-12)


def test_the_chunked_differences_do_not_depend_on_the_chunk(monkeypatch):
    sensor, robot, cov = _cell(4, 40)
    whole = _Registration.fit(sensor, robot, cov)
    monkeypatch.setattr(planning_model, "_FD_CHUNK", 7)
    chunked = _Registration.fit(sensor, robot, cov)
    np.testing.assert_array_equal(whole.d_affine, chunked.d_affine)
    np.testing.assert_allclose(whole.reg_var, chunked.reg_var, rtol=1e-12)


def test_many_registration_points_stay_small():
    """2000 registration points: the arrays kept are (N, 3, 3, 4) and (4, 4), not (N x N) or (checks x N x 9)."""
    sensor, robot, cov = _cell(5, 2000)
    reg = _Registration.fit(sensor, robot, cov)
    assert reg.d_affine.shape == (2000, 3, 3, 4) and reg.reg_var.shape == (4, 4) and reg.shared.shape == (2000, 4)
    # the variance of the fit at its centroid falls like 1/N: with 2000 points it is below any single point's
    assert reg.variance(_homogeneous(sensor.mean(0))) < np.trace(cov, axis1=1, axis2=2).min()
