"""Simulation against theory: noise-only Monte Carlo vs Fitzpatrick and the first-order covariance."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rrbc_core.correction import metrics
from rrbc_core.geometry.transforms import RigidTransform
from rrbc_core.models.errormodels import ErrorModel
from rrbc_core.models.errorterms import AnisotropicNoise, IsotropicNoise
from rrbc_core.simulation import batch
from rrbc_core.simulation.datasets import measurement_set
from rrbc_core.simulation.montecarlo import WorkCell, measure, monte_carlo, trial_errors

Z = 4.0  # z-score of the statistical tolerances


def _cell(model, reg, checks, fids=None, rot=None):
    """A hand-built cell: sensor 1.5 m away looking at the points (robot frame, mm)."""
    fids = np.zeros((0, 3)) if fids is None else fids
    pts = np.vstack([reg, fids, checks])
    roles = ["registration"] * len(reg) + ["fiducial"] * len(fids) + ["check"] * len(checks)
    ids = [f"P{i}" for i in range(len(pts))]
    r = Rotation.from_rotvec([2.6, 0.4, -0.3]).as_matrix() if rot is None else rot
    sensor_to_robot = RigidTransform(
        r, -r @ np.array([0.0, 0.0, 1500.0])
    )  # sensor frame point (0,0,1500) ↦ robot origin
    return WorkCell(
        name="test",
        sensor_to_robot=sensor_to_robot,
        ids=tuple(ids),
        roles=tuple(roles),
        robot=pts,
        time=np.arange(len(pts), dtype=float),
        tool_rotation=np.broadcast_to(np.eye(3), (len(pts), 3, 3)).copy(),
        error_model=model,
        check_target=tuple("" for _ in ids),
    )


REG3D = np.array([[-300, -250, 0], [320, -260, 40], [300, 280, -30], [-280, 300, 60], [0, 0, 250], [50, -40, -200.0]])
PLATE = np.array([[x, y, 0.0] for x in np.linspace(-375, 375, 4) for y in np.linspace(-262.5, 262.5, 4)])
CHECKS = np.array([[0, 0, 0], [200, 100, 50], [-350, 300, 0], [600, -500, 100], [0, 0, 400.0]])


@pytest.mark.parametrize("reg", [REG3D, PLATE, PLATE[[0, 3, 12]]], ids=["3d", "plate", "3pt"])
def test_noise_only_monte_carlo_matches_fitzpatrick(reg):
    """Isotropic noise σ on both sides: <TRE²> at a check = FLE²/N (1 + Σ d²/3f²) + 3σ_s² (the check itself is
    measured by the sensor), FLE² = 3σ_s² + 3σ_r². Tolerance: Z standard errors of the Monte Carlo mean of TRE²
    plus the neglected second-order term, bounded by 10 (FLE/f_min)² relative (see tests/correction/test_metrics.py)."""
    sigma_s, sigma_r = 0.05, 0.08
    cell = _cell(ErrorModel(robot=(IsotropicNoise(sigma_r),), sensor=(IsotropicNoise(sigma_s),)), reg, CHECKS)
    measured = measure(cell, np.random.default_rng(11), 4000)
    e = trial_errors(cell, measured, "least-squares", "none")
    tre2 = e.rigid**2
    fle = np.sqrt(3 * sigma_s**2 + 3 * sigma_r**2)
    pred = metrics.expected_tre_fitzpatrick(reg, CHECKS, fle) ** 2 + 3 * sigma_s**2
    se = tre2.std(axis=0, ddof=1) / np.sqrt(len(tre2))
    f_min = np.sqrt(np.sort(np.linalg.svd(reg - reg.mean(0), compute_uv=False) ** 2)[-2] / len(reg))
    tol = Z * se + 10 * (fle / f_min) ** 2 * pred
    np.testing.assert_array_less(np.abs(tre2.mean(0) - pred), tol)


def test_anisotropic_noise_matches_first_order_covariance_per_axis():
    """Sensor noise 3x larger along the line of sight; per-axis variance of the check-point error (robot frame)
    against tre_covariance_first_order with Σ_i = R Σ_s,i Rᵀ + σ_r² I and the check's own sensor noise as
    target covariance. Tolerance: Z standard errors of a Gaussian sample variance, v·sqrt(2/(K−1))."""
    sens = AnisotropicNoise(sigma_perp_mm=0.03, sigma_along_mm=0.09)
    sigma_r = 0.02
    cell = _cell(ErrorModel(robot=(IsotropicNoise(sigma_r),), sensor=(sens,)), REG3D, CHECKS)
    k = 6000
    m = measure(cell, np.random.default_rng(12), k)
    reg = cell.index("registration")
    chk = cell.index("check")
    out = batch.rrbc_batch(
        "least-squares", "none", m.sensor[:, reg], m.robot[:, reg], m.sensor[:, reg], m.robot[:, reg], m.sensor[:, chk]
    )
    err = out["robot_rigid"] - m.truth[chk][None]
    rot = cell.sensor_to_robot.rotation
    cov_s = sens.covariance(cell.sensor_truth)
    cov_robot = np.einsum("ij,pjk,lk->pil", rot, cov_s, rot)
    fle_cov = cov_robot[reg] + sigma_r**2 * np.eye(3)
    pred = metrics.tre_covariance_first_order(REG3D, CHECKS, fle_cov, target_cov=cov_robot[chk])
    pred_var = np.diagonal(pred, axis1=1, axis2=2)
    mc_var = err.var(axis=0, ddof=1)
    tol = Z * pred_var * np.sqrt(2 / (k - 1)) + 1e-4 * pred_var
    np.testing.assert_array_less(np.abs(mc_var - pred_var), tol)
    # the anisotropy is visible: the predicted covariance is far from isotropic at the checks
    assert (pred_var.max(axis=1) / pred_var.min(axis=1)).max() > 1.5


def test_measurement_set_of_a_simulation_has_truth_on_checks_and_no_robot_on_targets():
    cell = _cell(ErrorModel(robot=(IsotropicNoise(0.05),)), REG3D, CHECKS, fids=REG3D[:4] + 10)
    m = measure(cell, np.random.default_rng(0), 2)
    ms = measurement_set(cell, m, trial=1)
    chk = cell.index("check")
    np.testing.assert_array_equal(ms.robot[chk], m.truth[chk])
    np.testing.assert_array_equal(ms.sensor, m.sensor[1])


def test_monte_carlo_is_seeded_and_reports_every_strategy():
    cell = _cell(
        ErrorModel(robot=(IsotropicNoise(0.05),), sensor=(IsotropicNoise(0.02),)),
        REG3D,
        CHECKS,
        fids=np.vstack([REG3D, [[0, 0, 0]]]) + 5,
    )
    a = monte_carlo(cell, 40, seed=3, interpolations=("idw", "none"))
    b = monte_carlo(cell, 40, seed=3, interpolations=("idw", "none"))
    assert [s.__dict__ for s in a.strategies] == [s.__dict__ for s in b.strategies]
    assert [s.name for s in a.strategies] == [
        "least-squares",
        "three-point",
        "combinatorial",
        "annealing",
        "clustering",
    ]
    ls = a.strategies[0]
    assert ls.tre_mean_mm <= ls.tre_rms_mm <= ls.tre_max_mm
    # without RRBC (none) the RMST equals the rigid RMS of the same trials
    none = [i for i in a.interpolations if i.name == "none"][0]
    assert none.rmst_mm == pytest.approx(ls.tre_rms_mm, rel=1e-12)
