"""Tests for rrbc_core.correction.metrics.

Monte Carlo checks use the project's own least-squares registration (rrbc_core.registration.least_squares)
on seeded noise applied to BOTH frames, with a non-identity sensor→robot rotation, so the net FLE in the robot
frame is δ_i = R ε_i − η_i (docs/theory.md §0).

How the Monte Carlo tolerances are derived (never tuned):

* Statistical part: z · SE with z = 4 (two-sided p ≈ 6e-5 per comparison; with < 60 comparisons in the file
  the chance of any false alarm is < 0.5 %, and every seed is fixed so the outcome is deterministic).
  - mean of TRE² or FRE²: SE = std(sample, ddof=1) / sqrt(K), from the same Monte Carlo.
  - a variance (per-axis TRE variance): SE = var · sqrt(2 / (K − 1)), the standard error of a sample
    variance of Gaussian data (TRE is Gaussian to first order), evaluated at the predicted variance (the
    value under test).
* First-order (model) part: the formulas are the first term of an expansion in FLE / f (f = fiducial spread).
  For zero-mean Gaussian noise the product of the linear and quadratic terms has zero mean, so the first
  neglected term of a second moment is relatively O((FLE / f_min)²), f_min the smallest principal spread
  f_k of docs/theory.md §2.1. We allow REL_FIRST_ORDER = 10 · (FLE_rms / f_min)² relative (constant 10 as a
  generous bound on the O(1) coefficient). For the layouts here that is ≤ 1e-4, i.e. the tolerances are
  essentially statistical: the formulas must agree with the simulation to within its own noise.
"""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_core.correction.metrics import (
    bias_tre,
    expected_fre_squared,
    expected_tre_fitzpatrick,
    fre_rms,
    max_error,
    rmst,
    tre,
    tre_covariance_first_order,
)
from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform, rotation_from_euler_zyx

Z = 4.0

# Sensor -> robot truth used in every simulation: a large, non-identity rotation.
TRUTH = RigidTransform(rotation_from_euler_zyx(0.7, -0.4, 2.1), [400.0, -250.0, 80.0])

# ---- fiducial layouts (sensor frame, mm) ----------------------------------------------------------------
GRID = np.array([[x, y, 0.0] for x in np.linspace(0.0, 750.0, 4) for y in np.linspace(0.0, 525.0, 4)])
THREE_SMALL = np.array([[0.0, 0.0, 0.0], [250.0, 0.0, 0.0], [0.0, 175.0, 0.0]])  # adjacent corner sites
SPREAD_3D = np.array(
    [
        [0.0, 0.0, 0.0],
        [420.0, 30.0, 60.0],
        [80.0, 350.0, 150.0],
        [390.0, 310.0, -40.0],
        [200.0, 150.0, 280.0],
        [-60.0, 200.0, 120.0],
    ]
)
PLATE_TARGETS = np.array(
    [
        [375.0, 262.5, 0.0],  # centroid of the grid
        [0.0, 0.0, 0.0],  # a corner site
        [750.0, 525.0, 0.0],  # the far corner
        [375.0, 262.5, 150.0],  # above the plate
        [-200.0, 700.0, 50.0],  # outside
    ]
)
LAYOUTS = {
    "3d-spread": (SPREAD_3D, np.vstack([SPREAD_3D.mean(0), [600.0, -100.0, 300.0], [150.0, 150.0, 100.0]])),
    "plate-4x4": (GRID, PLATE_TARGETS),
    "three-points": (THREE_SMALL, PLATE_TARGETS),
}


def f_min(points) -> float:
    """Smallest principal spread f_k (docs/theory.md §2.1), mm."""
    c = points - points.mean(0)
    lam2 = np.linalg.svd(c, compute_uv=False) ** 2
    return float(np.sqrt(np.min(lam2.sum() - lam2) / len(points)))


def rel_first_order(fle_rms_mm, points) -> float:
    return 10.0 * (fle_rms_mm / f_min(points)) ** 2


def simulate(sensor_true, targets_sensor, sensor_chol, robot_chol, trials, seed, weights=None, target_chol=None):
    """Seeded Monte Carlo of the project's least-squares registration.

    sensor_chol (N,3,3): Cholesky factors of the sensor noise (sensor frame); robot_chol (N,3,3): robot noise
    (robot frame); target_chol (M,3,3) optional: sensor noise on the measured targets.
    Returns (TRE vectors (K,M,3) in the robot frame = predicted − true, FRE² (K,)).
    """
    from rrbc_core.registration.strategies import least_squares

    rng = np.random.default_rng(seed)
    n, m = len(sensor_true), len(targets_sensor)
    robot_true = TRUTH.apply(sensor_true)
    targets_robot = TRUTH.apply(targets_sensor)
    eps = np.einsum("nab,knb->kna", sensor_chol, rng.standard_normal((trials, n, 3)))
    eta = np.einsum("nab,knb->kna", robot_chol, rng.standard_normal((trials, n, 3)))
    if target_chol is None:
        tle = np.zeros((trials, m, 3))
    else:
        tle = np.einsum("mab,kmb->kma", target_chol, rng.standard_normal((trials, m, 3)))
    err = np.empty((trials, m, 3))
    fre2 = np.empty(trials)
    for k in range(trials):
        reg = least_squares(sensor_true + eps[k], robot_true + eta[k], weights=weights)
        err[k] = reg.mapping.apply(targets_sensor + tle[k]) - targets_robot
        fre2[k] = fre_rms(reg.residuals) ** 2
    return err, fre2


def iso_chol(n, sigma):
    return np.broadcast_to(sigma * np.eye(3), (n, 3, 3))


# =========================================================================================================
# Fitzpatrick–West–Maurer vs Monte Carlo
# =========================================================================================================
SIGMA = 0.1  # mm per axis, each side
FLE_RMS = float(np.sqrt(3 * SIGMA**2 + 3 * SIGMA**2))  # net two-frame FLE, 0.245 mm
K_ISO = 4000


@pytest.fixture(scope="module")
def iso_runs():
    out = {}
    for i, (name, (fid, tgt)) in enumerate(LAYOUTS.items()):
        n = len(fid)
        err, fre2 = simulate(fid, tgt, iso_chol(n, SIGMA), iso_chol(n, SIGMA), K_ISO, seed=1000 + i)
        out[name] = (fid, tgt, err, fre2)
    return out


@pytest.mark.parametrize("name", list(LAYOUTS))
def test_fitzpatrick_matches_monte_carlo(iso_runs, name):
    """mean TRE²(r) over K = 4000 trials vs FLE²/N (1 + Σ d_k²/(3 f_k²)).

    Tolerance: 4 · std(TRE²)/sqrt(K) (Monte Carlo standard error) + 10 (FLE/f_min)² · prediction (first-order
    term, ≤ 1e-4 relative here; see module docstring). Fiducials and targets handed to the formula are in the
    robot frame (the frame the fit maps into).
    """
    fid, tgt, err, _ = iso_runs[name]
    tre2 = np.sum(err**2, axis=2)  # (K, M)
    mc = tre2.mean(axis=0)
    se = tre2.std(axis=0, ddof=1) / np.sqrt(len(tre2))
    pred = expected_tre_fitzpatrick(TRUTH.apply(fid), TRUTH.apply(tgt), FLE_RMS) ** 2
    tol = Z * se + rel_first_order(FLE_RMS, fid) * pred
    assert np.all(np.abs(mc - pred) <= tol), f"{name}: MC {mc} vs formula {pred}, tol {tol}"
    # the test can tell a factor-of-two error in FLE² (e.g. noise on one side only) from the truth
    assert np.all(np.abs(mc - pred / 2) > tol)
    # the formula is invariant to the rigid motion of the frame: sensor-frame inputs give the same numbers
    np.testing.assert_allclose(expected_tre_fitzpatrick(fid, tgt, FLE_RMS) ** 2, pred, rtol=1e-9)


@pytest.mark.parametrize("name", list(LAYOUTS))
def test_expected_fre_matches_monte_carlo(iso_runs, name):
    """mean FRE² vs (1 − 2/N) FLE²; tolerance 4 · std(FRE²)/sqrt(K) + first-order term (module docstring)."""
    fid, _, _, fre2 = iso_runs[name]
    pred = expected_fre_squared(len(fid), FLE_RMS)
    tol = Z * fre2.std(ddof=1) / np.sqrt(len(fre2)) + rel_first_order(FLE_RMS, fid) * pred
    assert abs(fre2.mean() - pred) <= tol, f"{name}: MC {fre2.mean()} vs {pred}, tol {tol}"
    # FLE² itself (no 1 − 2/N) would be rejected: the check has the power to see the 6 fitted parameters
    assert abs(fre2.mean() - FLE_RMS**2) > tol


# =========================================================================================================
# First-order covariance: anisotropic, inhomogeneous FLE vs Monte Carlo
# =========================================================================================================
# A stereo-like sensor at the sensor-frame origin looks along +z at a workspace ~2 m away. Depth noise (along
# each point's own line of sight) is 3x the lateral noise at 2 m and grows as range² (lateral as range), so
# every fiducial has a different, anisotropic covariance. The robot adds isotropic noise that grows with reach.
CAM_FIDUCIALS = np.array(
    [
        [-300.0, -250.0, 1850.0],
        [320.0, -220.0, 1900.0],
        [280.0, 260.0, 2150.0],
        [-260.0, 240.0, 2200.0],
        [0.0, 0.0, 2000.0],
        [120.0, -40.0, 2350.0],
        [-150.0, 80.0, 1700.0],
    ]
)
CAM_TARGETS = np.array([[0.0, 0.0, 2000.0], [400.0, 350.0, 2300.0], [-500.0, 0.0, 1800.0], [50.0, -400.0, 2600.0]])
K_ANISO = 10000


def camera_cov(points):
    """Sensor-frame covariance per point (mm²): σ_⊥ = 0.03 (ρ/2 m), σ_∥ = 3 σ_⊥ (ρ/2 m) along the sight line."""
    rho = np.linalg.norm(points, axis=1)
    u = points / rho[:, None]
    s_perp = 0.03 * rho / 2000.0
    s_par = 3.0 * s_perp * rho / 2000.0
    uu = u[:, :, None] * u[:, None, :]
    return s_perp[:, None, None] ** 2 * (np.eye(3) - uu) + s_par[:, None, None] ** 2 * uu


def robot_cov(robot_points):
    """Robot-frame isotropic repeatability growing with reach: σ_b = 0.01 + 0.01 (‖x‖ / 1 m) mm."""
    s = 0.01 + 0.01 * np.linalg.norm(robot_points, axis=1) / 1000.0
    return s[:, None, None] ** 2 * np.eye(3)


def rotate_cov(r, cov):
    return np.einsum("ab,nbc,dc->nad", r, cov, r)


ANISO_CASES = {
    "uniform-weights-with-target-noise": (False, True),
    "inverse-trace-weights": (True, False),
}


@pytest.fixture(scope="module")
def aniso_runs():
    r = TRUTH.rotation
    sig_s = camera_cov(CAM_FIDUCIALS)
    sig_b = robot_cov(TRUTH.apply(CAM_FIDUCIALS))
    sig_net = rotate_cov(r, sig_s) + sig_b  # Σ_i = R Σ_s,i Rᵀ + Σ_b,i  (robot frame)
    out = {}
    for i, (name, (weighted, target_noise)) in enumerate(ANISO_CASES.items()):
        w = 1.0 / np.trace(sig_net, axis1=1, axis2=2) if weighted else None
        tcov_s = camera_cov(CAM_TARGETS)
        err, _ = simulate(
            CAM_FIDUCIALS,
            CAM_TARGETS,
            np.linalg.cholesky(sig_s),
            np.linalg.cholesky(sig_b),
            K_ANISO,
            seed=2000 + i,
            weights=w,
            target_chol=np.linalg.cholesky(tcov_s) if target_noise else None,
        )
        out[name] = dict(err=err, w=w, sig_s=sig_s, sig_b=sig_b, sig_net=sig_net, tcov_s=tcov_s, tn=target_noise)
    return out


@pytest.mark.parametrize("name", list(ANISO_CASES))
def test_first_order_covariance_matches_monte_carlo(aniso_runs, name):
    """Per-axis TRE variance (robot frame) over K = 10000 trials vs diag of the first-order covariance.

    Tolerance per entry: 4 · v · sqrt(2/(K−1)) (standard error of a Gaussian sample variance at the predicted
    v) + 10 (FLE/f_min)² · v (first-order term, ~1e-6 relative here). The same for the trace (a sum of
    correlated variances; its SE is bounded by the sum of the per-axis SEs, which is what we use).
    """
    run = aniso_runs[name]
    r = TRUTH.rotation
    fid_b, tgt_b = TRUTH.apply(CAM_FIDUCIALS), TRUTH.apply(CAM_TARGETS)
    tcov = rotate_cov(r, run["tcov_s"]) if run["tn"] else None
    pred = tre_covariance_first_order(fid_b, tgt_b, run["sig_net"], weights=run["w"], target_cov=tcov)
    v_pred = np.diagonal(pred, axis1=1, axis2=2)  # (M,3)
    err = run["err"]
    k = len(err)
    v_mc = err.var(axis=0, ddof=1)  # (M,3)
    fle = float(np.sqrt(np.trace(run["sig_net"], axis1=1, axis2=2).mean()))
    rel = rel_first_order(fle, CAM_FIDUCIALS)
    tol = Z * v_pred * np.sqrt(2.0 / (k - 1)) + rel * v_pred
    assert np.all(np.abs(v_mc - v_pred) <= tol), f"{name}: MC {v_mc} vs predicted {v_pred}, tol {tol}"
    tr_pred = v_pred.sum(axis=1)
    assert np.all(np.abs(v_mc.sum(axis=1) - tr_pred) <= tol.sum(axis=1))

    # Power: forgetting to rotate the sensor covariance into the robot frame (or rotating it the wrong way)
    # must be visible to this test on at least one axis of one target.
    for wrong_rotation in (np.eye(3), r.T):
        wrong_tcov = None if tcov is None else rotate_cov(wrong_rotation, run["tcov_s"])
        wrong = tre_covariance_first_order(
            fid_b,
            tgt_b,
            rotate_cov(wrong_rotation, run["sig_s"]) + run["sig_b"],
            weights=run["w"],
            target_cov=wrong_tcov,
        )
        v_wrong = np.diagonal(wrong, axis1=1, axis2=2)
        assert np.any(np.abs(v_mc - v_wrong) > 3 * tol)


# =========================================================================================================
# Exact algebraic properties of the first-order covariance
# =========================================================================================================
@pytest.mark.parametrize("name", list(LAYOUTS))
def test_isotropic_trace_equals_fitzpatrick(name):
    """Isotropic Σ = (FLE²/3) I, uniform weights: tr Cov(TRE(r)) = Fitzpatrick² exactly (to 1e-9)."""
    fid, _ = LAYOUTS[name]
    rng = np.random.default_rng(7)
    fid_b = TRUTH.apply(fid)
    targets = TRUTH.apply(np.vstack([fid, rng.uniform(-800, 1500, size=(50, 3))]))
    fle = 0.37
    fitz2 = expected_tre_fitzpatrick(fid_b, targets, fle) ** 2
    for weights in (None, np.full(len(fid), 2.5), np.broadcast_to(4.0 * np.eye(3), (len(fid), 3, 3))):
        cov = tre_covariance_first_order(fid_b, targets, fle**2 / 3 * np.eye(3), weights=weights)
        np.testing.assert_allclose(np.trace(cov, axis1=1, axis2=2), fitz2, rtol=1e-9)


def test_covariance_at_centroid_is_sigma_over_n():
    """Uniform weights, shared Σ: at the fiducial centroid Cov(TRE) = Σ/N exactly (rotation decouples)."""
    fid = TRUTH.apply(SPREAD_3D)
    a = np.array([[0.04, 0.01, -0.005], [0.01, 0.02, 0.003], [-0.005, 0.003, 0.09]])
    cov = tre_covariance_first_order(fid, fid.mean(0, keepdims=True), a)
    np.testing.assert_allclose(cov[0], a / len(fid), rtol=1e-10, atol=1e-15)


def test_covariance_is_frame_covariant_and_well_conditioned():
    """Rotating/translating every input by (Q, u) gives Q Cov Qᵀ, also 1e6 mm from the origin."""
    fid = CAM_FIDUCIALS
    tgt = CAM_TARGETS
    sig = camera_cov(fid)
    w = np.linalg.inv(sig)
    base = tre_covariance_first_order(fid, tgt, sig, weights=w, target_cov=camera_cov(tgt))
    q = rotation_from_euler_zyx(-1.1, 0.3, 0.9)
    move = RigidTransform(q, [1e6, -2e6, 5e5])
    moved = tre_covariance_first_order(
        move.apply(fid),
        move.apply(tgt),
        rotate_cov(q, sig),
        weights=rotate_cov(q, w),
        target_cov=rotate_cov(q, camera_cov(tgt)),
    )
    np.testing.assert_allclose(moved, rotate_cov(q, base), rtol=1e-7, atol=1e-12)


def test_ideal_weights_are_optimal_and_scalar_weights_match_matrix_weights():
    """Ideal weights M_i = Σ_i⁻¹ give the smallest covariance (Loewner order) among weightings, and scalar
    weights w_i equal matrix weights w_i I; only relative weights matter."""
    fid = TRUTH.apply(CAM_FIDUCIALS)
    tgt = TRUTH.apply(CAM_TARGETS)
    sig = rotate_cov(TRUTH.rotation, camera_cov(CAM_FIDUCIALS)) + robot_cov(fid)
    ideal = tre_covariance_first_order(fid, tgt, sig, weights=np.linalg.inv(sig))
    w = 1.0 / np.trace(sig, axis1=1, axis2=2)
    for other in (None, w):
        c = tre_covariance_first_order(fid, tgt, sig, weights=other)
        assert np.all(np.linalg.eigvalsh(c - ideal) >= -1e-12 * np.abs(c).max())
    a = tre_covariance_first_order(fid, tgt, sig, weights=w)
    b = tre_covariance_first_order(fid, tgt, sig, weights=1e3 * w[:, None, None] * np.eye(3))
    np.testing.assert_allclose(a, b, rtol=1e-10)


def test_target_cov_is_added():
    fid = TRUTH.apply(GRID)
    tgt = TRUTH.apply(PLATE_TARGETS)
    base = tre_covariance_first_order(fid, tgt, 0.01 * np.eye(3))
    tc = np.diag([0.001, 0.002, 0.003])
    np.testing.assert_allclose(
        tre_covariance_first_order(fid, tgt, 0.01 * np.eye(3), target_cov=tc) - base,
        np.broadcast_to(tc, base.shape),
        atol=1e-15,
    )
    per = np.stack([k * tc for k in range(1, len(tgt) + 1)])
    np.testing.assert_allclose(
        tre_covariance_first_order(fid, tgt, 0.01 * np.eye(3), target_cov=per) - base, per, atol=1e-15
    )


# =========================================================================================================
# Fitzpatrick formula: hand-computed values
# =========================================================================================================
def test_fitzpatrick_plate_by_hand():
    """Coplanar plate, centred coordinates: f_x² = mean(y'²), f_y² = mean(x'²), f_z² = mean(x'²+y'²) (§2.1).

    Target at height h above the centroid: d_x² = d_y² = h², d_z² = 0, so
    <TRE²> = FLE²/N (1 + h²/3 (1/f_x² + 1/f_y²)). Target in the plane at (a, b) from the centroid:
    d_x² = b², d_y² = a², d_z² = a² + b².
    """
    c = GRID.mean(0)
    xc = GRID - c
    fx2, fy2 = np.mean(xc[:, 1] ** 2), np.mean(xc[:, 0] ** 2)
    fz2 = fx2 + fy2
    n, fle, h, a, b = 16, 0.3, 120.0, 500.0, -100.0
    want_up = fle**2 / n * (1 + h**2 / 3 * (1 / fx2 + 1 / fy2))
    want_in = fle**2 / n * (1 + (b**2 / fx2 + a**2 / fy2 + (a**2 + b**2) / fz2) / 3)
    got = expected_tre_fitzpatrick(GRID, c + np.array([[0, 0, h], [a, b, 0], [0, 0, 0]]), fle) ** 2
    np.testing.assert_allclose(got, [want_up, want_in, fle**2 / n], rtol=1e-12)


def test_fitzpatrick_plate_reference_numbers():
    """Theory notes §2.6 table (σ = 0.1 mm net per axis, FLE = 0.173 mm): mean RMS TRE over the 16 sites."""
    fle = np.sqrt(3) * 0.1
    three_large = GRID[[0, 3, 12]]
    for fid, want in ((THREE_SMALL, 0.387), (three_large, 0.138), (GRID[[0, 3, 12, 15]], 0.107), (GRID, 0.061)):
        got = expected_tre_fitzpatrick(fid, GRID, fle).mean()
        assert abs(got - want) < 0.0015, (got, want)


# =========================================================================================================
# Bias propagation
# =========================================================================================================
def skew(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


@pytest.mark.parametrize("weights", ["none", "scalar", "matrix"])
def test_rigid_bias_is_absorbed(weights):
    """β(x) = ω × x + τ (an infinitesimal rigid motion) lies in the span of A: TRE_bias = 0 to rounding."""
    fid = TRUTH.apply(SPREAD_3D)
    tgt = TRUTH.apply(np.vstack([SPREAD_3D, [[900.0, -300.0, 500.0]]]))
    omega, tau = np.array([2e-4, -1e-4, 3e-4]), np.array([0.3, -0.2, 0.5])
    beta = lambda x: x @ skew(omega).T + tau
    w = {"none": None, "scalar": np.arange(1.0, 7.0), "matrix": np.linalg.inv(camera_cov(CAM_FIDUCIALS[:6]))}[weights]
    got = bias_tre(fid, tgt, beta(fid), beta(tgt), weights=w)
    assert np.abs(got).max() < 1e-9 * np.abs(beta(tgt)).max()


@pytest.mark.parametrize("layout", ["plate", "box"])
def test_affine_bias_analytical(layout):
    """β(x) = S (x − c) + ω × x + τ with S symmetric and commuting with the fiducials' scatter matrix
    (S diagonal, fiducials symmetric about c along the axes). Then Σ x'_i × S x'_i = 0 and Σ S x'_i = 0, so the
    fit absorbs exactly the rigid part and TRE_bias(r) = S (r − c), including the out-of-plane S_zz h term
    above a plate (which the coplanar fiducials cannot see)."""
    if layout == "plate":
        fid = GRID
    else:
        fid = np.array([[x, y, z] for x in (0.0, 600.0) for y in (0.0, 400.0) for z in (0.0, 250.0)])
    c = fid.mean(0)
    s = np.diag([1.5e-4, -0.8e-4, 2.5e-4])
    omega, tau = np.array([1e-4, 2e-4, -1e-4]), np.array([0.1, 0.0, -0.2])
    beta = lambda x: (x - c) @ s.T + x @ skew(omega).T + tau
    tgt = np.vstack([PLATE_TARGETS, [[1200.0, -500.0, 400.0]]])
    got = bias_tre(fid, tgt, beta(fid), beta(tgt))
    np.testing.assert_allclose(got, (tgt - c) @ s.T, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("weights", [None, "inverse-range"])
def test_bias_tre_matches_project_registration(weights):
    """A general affine sensor bias (non-commuting with the scatter) pushed through least_squares: the exact
    fit agrees with bias_tre to second order in the bias gradient, |G|² · max|r − c| (a few 1e-5 mm here)."""
    from rrbc_core.registration.strategies import least_squares

    rng = np.random.default_rng(11)
    g = rng.normal(scale=1e-4, size=(3, 3))
    g0 = np.array([0.05, -0.03, 0.08])
    fid_b = TRUTH.apply(SPREAD_3D)
    tgt_b = TRUTH.apply(np.vstack([SPREAD_3D.mean(0), [900.0, -300.0, 500.0], [-400.0, 600.0, 200.0]]))
    beta = lambda x: (x - fid_b.mean(0)) @ g.T + g0
    w = None if weights is None else 1.0 / (1.0 + np.linalg.norm(SPREAD_3D, axis=1) / 500.0)
    # the sensor sees every point displaced by β (expressed in the robot frame); the robot is exact
    sensor = TRUTH.apply_inverse(fid_b + beta(fid_b))
    reg = least_squares(sensor, fid_b, weights=w)
    actual = reg.mapping.apply(TRUTH.apply_inverse(tgt_b + beta(tgt_b))) - tgt_b
    pred = bias_tre(fid_b, tgt_b, beta(fid_b), beta(tgt_b), weights=w)
    tol = 10 * np.abs(g).max() ** 2 * np.linalg.norm(tgt_b - fid_b.mean(0), axis=1).max() + 1e-9
    np.testing.assert_allclose(actual, pred, atol=tol)
    assert np.abs(pred).max() > 100 * tol  # the comparison is not trivially satisfied


# =========================================================================================================
# Simple metrics
# =========================================================================================================
def test_simple_metrics_by_hand():
    assert fre_rms([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]]) == pytest.approx(np.sqrt(12.5))
    e = tre([[1.0, 2.0, 2.0], [5.0, 5.0, 5.0]], [[0.0, 0.0, 0.0], [5.0, 5.0, 5.0]])
    np.testing.assert_allclose(e, [3.0, 0.0])
    assert rmst([3.0, 4.0]) == pytest.approx(np.sqrt(12.5))
    assert rmst(np.array([0.2])) == pytest.approx(0.2)
    assert max_error([3.0, 4.0, 1.0]) == 4.0
    assert expected_fre_squared(16, 0.3) == pytest.approx(0.875 * 0.09)
    assert expected_fre_squared(3, 0.3) == pytest.approx(0.03)
    np.testing.assert_allclose(expected_tre_fitzpatrick(GRID, GRID.mean(0, keepdims=True), 0.4), [0.1])
    assert tre(np.zeros((0, 3)), np.zeros((0, 3))).shape == (0,)


COLLINEAR = np.array([[0.0, 0.0, 0.0], [100.0, 50.0, 0.0], [300.0, 150.0, 0.0], [-50.0, -25.0, 0.0]])


@pytest.mark.parametrize(
    "call",
    [
        lambda: fre_rms(np.zeros((0, 3))),
        lambda: fre_rms([[1.0, 2.0]]),
        lambda: fre_rms([[np.nan, 0.0, 0.0]]),
        lambda: tre(np.zeros((2, 3)), np.zeros((3, 3))),
        lambda: tre([[np.inf, 0, 0]], [[0, 0, 0]]),
        lambda: rmst([]),
        lambda: rmst([[1.0, 2.0, 3.0]]),
        lambda: rmst([1.0, -2.0]),
        lambda: rmst([1.0, np.nan]),
        lambda: rmst("abc"),
        lambda: max_error([]),
        lambda: expected_fre_squared(2, 0.1),
        lambda: expected_fre_squared(3.5, 0.1),
        lambda: expected_fre_squared(16, -0.1),
        lambda: expected_fre_squared(16, [0.1, 0.2]),
        lambda: expected_tre_fitzpatrick(COLLINEAR, GRID, 0.1),
        lambda: expected_tre_fitzpatrick(GRID[:2], GRID, 0.1),
        lambda: expected_tre_fitzpatrick(np.zeros((4, 3)), GRID, 0.1),
        lambda: expected_tre_fitzpatrick(GRID, GRID[:, :2], 0.1),
        lambda: expected_tre_fitzpatrick(GRID, GRID, np.nan),
        lambda: tre_covariance_first_order(COLLINEAR, GRID, np.eye(3)),
        lambda: tre_covariance_first_order(GRID, GRID, np.eye(2)),
        lambda: tre_covariance_first_order(GRID, GRID, np.ones((15, 3, 3))),
        lambda: tre_covariance_first_order(GRID, GRID, np.array([[1.0, 0.5, 0], [0, 1, 0], [0, 0, 1]])),
        lambda: tre_covariance_first_order(GRID, GRID, -np.eye(3)),
        lambda: tre_covariance_first_order(GRID, GRID, np.eye(3), weights=-np.ones(16)),
        lambda: tre_covariance_first_order(GRID, GRID, np.eye(3), weights=np.ones(15)),
        lambda: tre_covariance_first_order(GRID, GRID, np.eye(3), weights=np.zeros(16)),
        lambda: tre_covariance_first_order(GRID, GRID, np.eye(3), weights=np.r_[1.0, 1.0, np.zeros(14)]),
        lambda: tre_covariance_first_order(
            GRID, GRID, np.eye(3), weights=np.broadcast_to(np.diag([1.0, 0, 0]), (16, 3, 3))
        ),
        lambda: tre_covariance_first_order(GRID, GRID, np.eye(3), target_cov=np.eye(3)[None].repeat(3, 0)),
        lambda: tre_covariance_first_order(GRID, [[0, 0, np.nan]], np.eye(3)),
        lambda: bias_tre(COLLINEAR, GRID, np.zeros((4, 3)), np.zeros((16, 3))),
        lambda: bias_tre(GRID, GRID, np.zeros((15, 3)), np.zeros((16, 3))),
        lambda: bias_tre(GRID, GRID, np.zeros((16, 3)), np.zeros((15, 3))),
    ],
)
def test_bad_input_raises_input_error(call):
    with pytest.raises(InputError):
        call()


def test_degenerate_message_is_actionable():
    with pytest.raises(InputError, match="collinear"):
        tre_covariance_first_order(COLLINEAR, GRID, np.eye(3))
    with pytest.raises(InputError, match="collinear"):
        expected_tre_fitzpatrick(COLLINEAR, GRID, 0.1)
