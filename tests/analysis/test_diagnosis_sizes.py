"""Honest sizes in `rrbc diagnose` (issue 36, item 3): the noise with an arm model is within 20 % of the truth and
never from a saturated fit; an arm effect's size is never more than the residual it explains.

Seeded arm files from the library's simulator (`simulation.arm_data.chain_measurements`: sensor and robot noise
`noise_mm` each, so √2·noise_mm per axis in the residual), on our lift-column arm and the packaged UR5, with and
without geometric errors. The tolerance: the pooled noise estimate over the three axes has about 3N − k ≈ 200
degrees of freedom here, a relative standard error near 1/√(2·200) = 5 %; 20 % is four of them.
"""

import numpy as np
import pytest

from rrbc_core.analysis.diagnosis import diagnose
from rrbc_core.models.urdf import load_urdf
from tests.support.urdf_arms import chain_measurements

NOISE = 0.05
TRUTH = np.sqrt(2.0) * NOISE


@pytest.mark.parametrize("robot", ["lift_arm", "ur5"])
@pytest.mark.parametrize("kin", [0.0, 1.0])
@pytest.mark.parametrize("seed", range(3))
def test_the_noise_beside_an_arm_is_within_20_percent(robot, kin, seed):
    m = chain_measurements(load_urdf(robot), 40 + seed, n_fid=70, n_chk=0, noise_mm=NOISE, kin_size=kin)
    d = diagnose(m, urdf=robot, seed=0)
    pooled = float(np.sqrt(np.mean(np.square(d.noise_sigma_mm))))
    assert abs(pooled / TRUTH - 1) < 0.2, (d.noise_sigma_mm, [e.name for e in d.effects])


@pytest.mark.parametrize("robot", ["lift_arm", "ur5"])
def test_a_small_station_does_not_saturate_the_noise_fit(robot):
    """14 points (42 numbers) against an arm with dozens of columns: the fit would leave nothing."""
    m = chain_measurements(load_urdf(robot), 7, n_reg=8, n_fid=6, n_chk=0, noise_mm=NOISE, kin_size=0.0)
    d = diagnose(m, urdf=robot, seed=0)
    pooled = float(np.sqrt(np.mean(np.square(d.noise_sigma_mm))))
    assert pooled > 0.5 * TRUTH, d.noise_sigma_mm


@pytest.mark.parametrize("robot", ["lift_arm", "ur5"])
@pytest.mark.parametrize("seed", range(3))
def test_an_arm_effect_is_never_larger_than_the_residual(robot, seed):
    m = chain_measurements(load_urdf(robot), 60 + seed, n_fid=40, n_chk=20, noise_mm=0.02, kin_size=1.5)
    d = diagnose(m, urdf=robot, seed=0)
    from rrbc_core.registration.strategies import least_squares

    ok = np.isfinite(m.robot[:, 0])
    fre = least_squares(m.sensor[ok], m.robot[ok]).fre_rms_mm
    for e in d.effects:
        if e.name in ("kinematic", "compliance"):
            assert 0 < e.parameters["rms_mm"] <= fre, (e.name, e.parameters["rms_mm"], fre)
