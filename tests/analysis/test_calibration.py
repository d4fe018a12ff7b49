"""Model-based calibration (rrbc_core.analysis.calibration) on planted DH errors of random size (seeded): the
identifiable parameters come back within their stated uncertainty, the unidentifiable ones are said to be so, and
predictions at new poses reach the noise floor."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rrbc_core.analysis.calibration import PARAM_NAMES, calibrate, dh_vector
from rrbc_core.errors import InputError
from rrbc_core.models.kinematics import UR5, UR5_TOOL_DOWN_SEED, forward, perturbed


def _poses(rng, n):
    return UR5_TOOL_DOWN_SEED + rng.uniform(-0.8, 0.8, (n, 6))


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_pure_dh_errors_are_recovered_within_their_uncertainty_and_predictions_reach_the_noise_floor(seed):
    rng = np.random.default_rng(seed)
    nominal = UR5.with_tool(100.0)
    size = rng.uniform(0.5, 2.0)
    true = perturbed(nominal, rng, 0.1 * size, 0.2 * size, 0.05 * size)
    sigma = rng.uniform(0.01, 0.04)  # sensor noise per axis, mm
    rot = Rotation.from_rotvec(rng.normal(size=3) * 0.5).as_matrix()
    t = rng.uniform(-1500, 1500, 3)
    q = _poses(rng, 60)
    p, _ = forward(true, q)
    s = (p - t) @ rot + rng.normal(0, sigma, p.shape)
    cal = calibrate(q, s, nominal, rot, t)
    truth = dh_vector(true) - dh_vector(nominal)
    ok = cal.identifiable
    # sanity, not theory: from positions alone some parameters (and combinations with the base) cannot be separated
    assert 0 < ok.sum() < len(PARAM_NAMES) and cal.rank < len(PARAM_NAMES) + 6
    z = (cal.delta[ok] - truth[ok]) / cal.delta_se[ok]
    assert np.all(np.abs(z) < 4.5), dict(zip(np.array(PARAM_NAMES)[ok], np.round(z, 2)))
    assert 0.2 < np.mean(z**2) < 3.0  # the stated uncertainties are of the right size (chi-square per parameter ~ 1)
    assert abs(cal.sigma_mm / sigma - 1) < 0.35  # the residual noise estimate
    # new poses, noise-free: the identified arm predicts where the real one goes to within the noise floor
    qc = _poses(rng, 40)
    pc, _ = forward(true, qc)
    sc = (pc - t) @ rot
    pred, _ = forward(cal.identified, qc)
    err = np.sqrt(np.mean(np.sum((cal.sensor_to_robot(sc) - pred) ** 2, axis=1)))
    nominal_err = np.sqrt(np.mean(np.sum((pc - forward(nominal, qc)[0]) ** 2, axis=1)))
    assert err < np.sqrt(3) * sigma and err < 0.1 * nominal_err


def test_too_few_poses_are_refused():
    with pytest.raises(InputError, match="at least 6 poses"):
        calibrate(np.zeros((3, 6)), np.zeros((3, 3)), UR5)
