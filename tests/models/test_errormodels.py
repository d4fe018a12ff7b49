"""Error terms and error models (rrbc_core.models.errormodels): each term planted alone shows its signature.

Tolerances are either numerical (deterministic terms: exact formulas, 1e-9 relative) or derived from the
sampling distribution of the statistic (random terms), with the bound stated next to each test.
"""

import numpy as np
import pytest
from scipy import stats
from scipy.spatial.transform import Rotation

from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform
from rrbc_core.models.errormodels import TERM_TYPES, ErrorModel, ErrorTerm, PointSet
from rrbc_core.models.errorterms import (
    Affine,
    AnisotropicNoise,
    Drift,
    IsotropicNoise,
    Kinematic,
    Outliers,
    RangeNoise,
    Scale,
    SmoothField,
    WarmUp,
    error_model_from_dict,
    error_model_to_dict,
)
from rrbc_core.models.kinematics import UR5, UR5_TOOL_DOWN_SEED, tool_down

# The sensor hangs 1.5 m above the plate looking straight down: its +z is the robot's -z.
SENSOR_POSE = RigidTransform(np.diag([1.0, -1.0, -1.0]), [-450.0, 0.0, 1550.0])


def plate(nx=12, ny=16, z=50.0, rotation=None, seed_q=None, time=None) -> PointSet:
    """A 525 x 750 mm plate in front of the UR5 (robot frame), tool pointing down, sensor 1.5 m above it."""
    xs, ys = np.linspace(-712.5, -187.5, nx), np.linspace(-375.0, 375.0, ny)
    robot = np.array([[x, y, z] for x in xs for y in ys])
    t = np.arange(len(robot), dtype=float) * 10.0 if time is None else time
    return PointSet(
        robot=robot,
        sensor=SENSOR_POSE.apply_inverse(robot),
        time=t,
        tool_rotation=tool_down(90.0) if rotation is None else rotation,
        joint_seed=seed_q,
    )


def volume_points(rng, n, lo=-1500.0, hi=1500.0) -> PointSet:
    """Random points in a box, with a sensor frame that keeps them in front of the sensor (z from 500 mm)."""
    sensor = rng.uniform([lo, lo, 500.0], [hi, hi, 3000.0], (n, 3))
    return PointSet(robot=SENSOR_POSE.apply(sensor), sensor=sensor, time=np.zeros(n))


def rms(d):
    return float(np.sqrt(np.mean(np.sum(d**2, axis=-1))))


# --- covariance check shared by the noise terms -------------------------------------------------------------
def assert_covariance_matches(samples, cov, family_alpha=1e-3):
    """samples (T, P, 3) ~ N(0, cov_p) independently. Whiten with the Cholesky factor of the claimed covariance:
    z = L⁻¹ d must be N(0, I). With the mean known (zero), the sample second moment S = zᵀz / T has
    Var(S_ii) = 2/T and Var(S_ij) = 1/T (i ≠ j); the mean of z has Var 1/T per component. With T in the
    thousands these are Gaussian to good accuracy, so every standardised entry must lie within the two-sided
    normal quantile of a Bonferroni-corrected family-wise level `family_alpha` over the 9 P statistics."""
    t, p, _ = samples.shape
    chol = np.linalg.cholesky(cov)
    z = np.linalg.solve(chol[None], samples[..., None])[..., 0]  # (T, P, 3)
    s = np.einsum("tpi,tpj->pij", z, z) / t
    iu = np.triu_indices(3)
    se = np.where(iu[0] == iu[1], np.sqrt(2.0 / t), np.sqrt(1.0 / t))
    standardised = np.concatenate([(s[:, iu[0], iu[1]] - np.eye(3)[iu]) / se, z.mean(0) * np.sqrt(t)], axis=1)
    bound = stats.norm.ppf(1 - family_alpha / (2 * standardised.size))
    assert np.abs(standardised).max() < bound, (np.abs(standardised).max(), bound)


# --- isotropic / anisotropic / range noise -------------------------------------------------------------------
def test_isotropic_noise_covariance_both_sides():
    rng = np.random.default_rng(101)
    term = IsotropicNoise(sigma_mm=float(rng.uniform(0.01, 0.2)))
    pts = plate(4, 5)
    for side in ("robot", "sensor"):
        d = term.sample(pts, side, rng, 4000)
        assert d.shape == (4000, len(pts), 3)
        assert_covariance_matches(d, term.covariance(pts.frame(side)))
    np.testing.assert_allclose(term.covariance(pts.sensor)[3], term.sigma_mm**2 * np.eye(3))


def test_anisotropic_noise_covariance_structure_and_samples():
    rng = np.random.default_rng(102)
    sp, sa = rng.uniform(0.01, 0.1), rng.uniform(0.2, 0.8)
    term = AnisotropicNoise(sigma_perp_mm=sp, sigma_along_mm=sa)
    pts = volume_points(rng, 20)
    cov = term.covariance(pts.sensor)
    u = pts.sensor / np.linalg.norm(pts.sensor, axis=1, keepdims=True)
    # the viewing direction is an eigenvector with eigenvalue sigma_along², the other two are sigma_perp²
    np.testing.assert_allclose(np.einsum("pij,pj->pi", cov, u), sa**2 * u, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.linalg.eigvalsh(cov), np.tile([sp**2, sp**2, sa**2], (20, 1)), rtol=1e-9)
    d = term.sample(pts, "sensor", rng, 4000)
    assert_covariance_matches(d, cov)
    # along-ray spread really is larger than across
    along = np.einsum("tpi,pi->tp", d, u)
    assert along.std() > 2 * np.sqrt(np.mean(np.sum(d**2, -1) - along**2) / 2)


def test_anisotropic_terms_are_sensor_only_and_need_a_viewing_direction():
    pts = plate(2, 2)
    rng = np.random.default_rng(0)
    for term in (AnisotropicNoise(0.01, 0.1), RangeNoise((0.01, 0.0), (0.01, 0.0, 0.0))):
        with pytest.raises(InputError, match="sensor-side"):
            term.sample(pts, "robot", rng, 1)
        with pytest.raises(InputError, match="sensor-side"):
            ErrorModel(robot=(term,))
    at_origin = PointSet(np.zeros((1, 3)), np.zeros((1, 3)), np.zeros(1))
    with pytest.raises(InputError, match="sensor origin"):
        AnisotropicNoise(0.01, 0.1).sample(at_origin, "sensor", rng, 1)


def test_range_noise_sigmas_follow_the_published_models():
    # laser tracker (docs/theory.md §5.2): half MPE, at 2 m: along (10 + 0.3·2)/2 µm, across (15 + 6·2)/2 µm
    lt = RangeNoise.laser_tracker()
    perp, along = lt.sigmas([[0.0, 0.0, 2000.0]])
    assert perp[0] == pytest.approx(0.0135) and along[0] == pytest.approx(0.0053)
    # stereo: f = 700 px, B = 0.12 m, sigma_d = 0.1 px gives sigma_Z ≈ 1.2 mm at 1 m; lateral rho·sigma_u/f
    st = RangeNoise.stereo(700.0, 0.12, 0.1, 0.2)
    perp, along = st.sigmas([[0.0, 0.0, 1000.0], [0.0, 600.0, 800.0], [0.0, 0.0, 2000.0]])
    np.testing.assert_allclose(along, [1.0 / 0.84, 1.0 / 0.84, 4.0 / 0.84], rtol=1e-12)  # quadratic in range
    np.testing.assert_allclose(perp, [0.2 / 0.7, 0.2 / 0.7, 0.4 / 0.7], rtol=1e-12)  # linear in range


def test_range_noise_sample_covariance_matches_at_many_ranges():
    rng = np.random.default_rng(103)
    term = RangeNoise(perp_mm=tuple(rng.uniform(0.005, 0.05, 2)), along_mm=tuple(rng.uniform(0.005, 0.3, 3)))
    pts = volume_points(rng, 25)
    cov = term.covariance(pts.sensor)
    sp, sa = term.sigmas(pts.sensor)
    rho_m = np.linalg.norm(pts.sensor, axis=1) / 1000
    np.testing.assert_allclose(sa, term.along_mm[0] + term.along_mm[1] * rho_m + term.along_mm[2] * rho_m**2)
    np.testing.assert_allclose(np.trace(cov, axis1=1, axis2=2), sa**2 + 2 * sp**2, rtol=1e-12)
    assert_covariance_matches(term.sample(pts, "sensor", rng, 4000), cov)


# --- outliers --------------------------------------------------------------------------------------------------
def test_outliers_fraction_size_and_direction():
    rng = np.random.default_rng(104)
    fraction, size = float(rng.uniform(0.05, 0.3)), float(rng.uniform(1.0, 10.0))
    term = Outliers(fraction=fraction, size_mm=size)
    pts = plate(10, 10)
    trials = 200
    d = term.sample(pts, "robot", rng, trials)
    lengths = np.linalg.norm(d, axis=-1)
    hit = lengths > 0
    n = trials * len(pts)
    # the number of displaced points is Binomial(n, fraction): inside its central 99.9 % interval
    lo, hi = stats.binom.interval(0.999, n, fraction)
    assert lo <= hit.sum() <= hi
    np.testing.assert_allclose(lengths[hit], size, rtol=1e-12)
    # directions uniform: each component of a unit vector has mean 0 and variance 1/3; 5 standard errors
    dirs = d[hit] / size
    assert np.abs(dirs.mean(0)).max() < 5 * np.sqrt(1 / 3 / hit.sum())
    # independent between trials: the same point is not always hit
    assert 0 < hit.mean(0).min() and hit.mean(0).max() < 1
    with pytest.raises(InputError, match="fraction"):
        Outliers(1.5, 1.0)


# --- deterministic geometric terms ------------------------------------------------------------------------------
def test_scale_grows_linearly_with_distance_from_its_centre():
    rng = np.random.default_rng(105)
    ppm, centre = float(rng.uniform(-500, 500)), tuple(rng.uniform(-300, 300, 3))
    term = Scale(ppm=ppm, center_mm=centre)
    pts = volume_points(rng, 300)
    for side in ("robot", "sensor"):
        d = term.sample(pts, side, rng, 5)
        assert d.shape == (1, len(pts), 3)  # deterministic: broadcastable
        r = pts.frame(side) - np.array(centre)
        dist = np.linalg.norm(r, axis=1)
        slope, intercept = np.polyfit(dist, np.linalg.norm(d[0], axis=1), 1)
        assert slope == pytest.approx(abs(ppm) * 1e-6, rel=1e-9)
        assert abs(intercept) < 1e-9
        # radial: parallel to x - c, pointing outwards for ppm > 0
        np.testing.assert_allclose(d[0], ppm * 1e-6 * r, rtol=1e-12, atol=1e-15)


def test_affine_is_linear_in_x():
    rng = np.random.default_rng(106)
    g = rng.normal(0, 1e-4, (3, 3))
    c = rng.uniform(-200, 200, 3)
    term = Affine(matrix=g, center_mm=tuple(c))
    pts = volume_points(rng, 200)
    d = term.sample(pts, "sensor", rng, 3)[0]
    # least-squares fit of d = G x + b recovers G and b = -G c, with a zero residual
    design = np.c_[pts.sensor, np.ones(len(pts))]
    coef, res, *_ = np.linalg.lstsq(design, d, rcond=None)
    np.testing.assert_allclose(coef[:3].T, g, atol=1e-15)
    np.testing.assert_allclose(coef[3], -g @ c, atol=1e-12)
    assert np.abs(design @ coef - d).max() < 1e-12
    # superposition: d(x1) + d(x2) = d(x1 + x2 - c)
    x1, x2 = pts.sensor[0], pts.sensor[1]
    combo = PointSet(np.zeros((1, 3)), (x1 + x2 - c)[None], np.zeros(1))
    np.testing.assert_allclose(term.sample(combo, "sensor", rng, 1)[0, 0], d[0] + d[1], atol=1e-12)
    with pytest.raises(InputError, match="3x3"):
        Affine(matrix=np.eye(2))


def test_drift_regression_slope_recovers_rate():
    rng = np.random.default_rng(107)
    rate = tuple(rng.normal(0, 1e-3, 3))
    t0 = float(rng.uniform(0, 100))
    pts = plate(8, 8, time=np.sort(rng.uniform(0, 3600, 64)))
    d = Drift(rate_mm_per_s=rate, t0_s=t0).sample(pts, "robot", rng, 1)[0]
    for k in range(3):
        slope, intercept = np.polyfit(pts.time, d[:, k], 1)
        assert slope == pytest.approx(rate[k], rel=1e-9, abs=1e-15)
        assert intercept == pytest.approx(-rate[k] * t0, rel=1e-9, abs=1e-12)
    # planted with noise on top: the OLS slope is unbiased with standard error sigma / sqrt(Σ (t - t̄)²)
    sigma = 0.05
    model = ErrorModel(robot=(Drift(rate, t0), IsotropicNoise(sigma)))
    noisy = model.sample(pts, "robot", rng, 1)[0]
    se = sigma / np.sqrt(np.sum((pts.time - pts.time.mean()) ** 2))
    for k in range(3):
        assert abs(np.polyfit(pts.time, noisy[:, k], 1)[0] - rate[k]) < 5 * se


def test_warm_up_exponential_approach():
    amp, tau = (0.3, -0.1, 0.05), 600.0
    pts = PointSet(np.zeros((4, 3)), np.ones((4, 3)), np.array([0.0, tau, 3 * tau, 50 * tau]))
    d = WarmUp(amplitude_mm=amp, tau_s=tau).sample(pts, "sensor", np.random.default_rng(0), 2)[0]
    np.testing.assert_allclose(d[0], 0.0, atol=1e-15)
    np.testing.assert_allclose(d[1], np.array(amp) * (1 - np.exp(-1)), rtol=1e-12)
    np.testing.assert_allclose(d[2], np.array(amp) * (1 - np.exp(-3)), rtol=1e-12)
    np.testing.assert_allclose(d[3], amp, rtol=1e-12)
    with pytest.raises(InputError, match="tau_s"):
        WarmUp(amp, 0.0)


# --- smooth field ------------------------------------------------------------------------------------------------
def test_smooth_field_is_deterministic_per_seed():
    x = np.random.default_rng(1).uniform(-1000, 1000, (50, 3))
    a, b, c = SmoothField(0.3, 250.0, 7), SmoothField(0.3, 250.0, 7), SmoothField(0.3, 250.0, 8)
    np.testing.assert_array_equal(a.field(x), b.field(x))
    assert np.abs(a.field(x) - c.field(x)).max() > 1e-3
    pts = PointSet(x, x, np.zeros(50))
    s1 = a.sample(pts, "robot", np.random.default_rng(1), 4)
    s2 = a.sample(pts, "robot", np.random.default_rng(2), 9)
    assert s1.shape == (1, 50, 3) and a.random is False
    np.testing.assert_array_equal(s1, s2)


# Statistics over K field realisations (seeds) and N random points in a cube of side 50·length.
# With M features, w_j ~ N(0, I3) and frequencies ω_j, the spatial mean of |β|² over a region much larger than the
# correlation length is rms²·Σ_j |w_j|² / (3M) (cross terms of different frequencies average out), i.e.
# rms²·χ²(3M)/(3M): relative standard deviation sqrt(2/(3M)) per realisation. Estimating it from N points adds
# about Var(|β|²)/N_eff = (2/3)/N_eff; we allow N_eff = N/2 for correlation between nearby points.
K_FIELDS, N_POINTS = 10, 5000


def _field_stats(length, lag_vector):
    rng = np.random.default_rng(108)
    x = rng.uniform(0, 50 * length, (N_POINTS, 3))
    ms, corr = [], []
    for seed in range(K_FIELDS):
        f = SmoothField(rms_mm=1.0, length_mm=length, seed=seed)
        b, bl = f.field(x), f.field(x + lag_vector)
        ms.append(np.mean(np.sum(b**2, 1)))
        corr.append(np.sum(b * bl) / np.sqrt(np.sum(b * b) * np.sum(bl * bl)))
    return np.array(ms), np.array(corr)


def test_smooth_field_rms_matches_over_a_large_region():
    length, m = 120.0, 256
    rms_mm = float(np.random.default_rng(109).uniform(0.05, 2.0))
    ms, _ = _field_stats(length, np.zeros(3))
    se = np.sqrt((2 / (3 * m) + 2 * (2 / 3) / N_POINTS) / K_FIELDS)
    assert abs(ms.mean() - 1.0) < 5 * se
    # rms_mm scales the field linearly
    x = np.random.default_rng(3).uniform(0, 1000, (100, 3))
    np.testing.assert_allclose(SmoothField(rms_mm, length, 4).field(x), rms_mm * SmoothField(1.0, length, 4).field(x))


def test_smooth_field_correlation_near_one_at_small_lag_and_zero_at_large_lag():
    length, m = 120.0, 256
    # lag ≪ length: 1 - corr ≈ (r²/2) Σ|w_j|²(ω_j·e)² / Σ|w_j|², expectation r²/(2 length²) (the squared-
    # exponential kernel), relative sd sqrt(2·E|w|⁴/(E|w|²)²/M) = sqrt(10/(3M)) per realisation.
    r = 0.05 * length
    _, corr = _field_stats(length, np.array([r, 0.0, 0.0]))
    assert corr.min() > 0.99
    expected = 1 - np.exp(-(r**2) / (2 * length**2))
    assert abs((1 - corr).mean() / expected - 1) < 5 * np.sqrt(10 / (3 * m) / K_FIELDS)
    # lag ≫ length: corr ≈ Σ|w_j|² cos(ω_j·r) / Σ|w_j|², mean exp(-50) ≈ 0, sd sqrt(E|w|⁴/(2(E|w|²)² M))
    # = sqrt(5/(6M)) per realisation, plus the N-point sampling term 1/(3N) (doubled for correlation).
    _, corr = _field_stats(length, np.array([0.0, 10 * length, 0.0]))
    assert abs(corr.mean()) < 5 * np.sqrt((5 / (6 * m) + 2 / (3 * N_POINTS)) / K_FIELDS)


# --- kinematic ------------------------------------------------------------------------------------------------------
def test_kinematic_error_magnitude_matches_theory_notes():
    # docs/theory.md §5.1: raw kinematic error RMS over a 750 x 525 mm plate, default sigmas, median 1.53 mm
    # (5-95 %: 0.68-2.66 mm) over random robots; the brief asks for the order 0.5-3 mm.
    pts = plate(seed_q=UR5_TOOL_DOWN_SEED)
    values = np.array([rms(Kinematic(seed=s).sample(pts, "robot", None, 1)[0]) for s in range(20)])
    assert 0.5 < np.median(values) < 3.0
    assert np.mean((values > 0.3) & (values < 5.0)) >= 0.9


def test_kinematic_error_depends_on_tool_orientation():
    # Same physical points, tool tilted 20°: the wrist joints change by ~20°, and joint/link errors of 0.1° and
    # 0.2 mm on 0.1-0.4 m levers change the error by ~0.1 mm; the IK is accurate to 1e-6 mm, so a difference
    # above 0.01 mm is a real configuration effect.
    tilt = tool_down(90.0) @ Rotation.from_euler("x", 20, degrees=True).as_matrix()
    for seed in range(3):
        k = Kinematic(seed)
        d_down = k.displacement(plate(6, 6))
        d_tilt = k.displacement(plate(6, 6, rotation=tilt))
        assert rms(d_tilt - d_down) > 0.01


def test_kinematic_error_is_smooth_in_position():
    # The error is a smooth function of the joints with gradients of order |error| / (shortest lever ≈ 100 mm),
    # so points 1 mm apart differ by about 1 % of the error or less; we require < 2 % of the RMS error.
    base = plate(6, 6)
    shifted = PointSet(base.robot + [1.0, 0.0, 0.0], base.sensor, base.time, base.tool_rotation)
    for seed in range(3):
        k = Kinematic(seed)
        d0, d1 = k.displacement(base), k.displacement(shifted)
        assert np.linalg.norm(d1 - d0, axis=1).max() < 0.02 * rms(d0)


def test_kinematic_error_is_zero_without_parameter_errors():
    d = Kinematic(seed=5, joint_offset_deg=0.0, link_mm=0.0, twist_deg=0.0).sample(plate(5, 5), "robot", None, 1)
    assert np.abs(d).max() < 1e-6


def test_kinematic_needs_tool_rotation_and_robot_side():
    pts = plate(2, 2)
    no_rot = PointSet(pts.robot, pts.sensor, pts.time)
    with pytest.raises(InputError, match="tool_rotation"):
        Kinematic(1).sample(no_rot, "robot", None, 1)
    with pytest.raises(InputError, match="robot-side"):
        Kinematic(1).sample(pts, "sensor", None, 1)
    far = PointSet(pts.robot + [5000.0, 0, 0], pts.sensor, pts.time, pts.tool_rotation)
    with pytest.raises(InputError, match="kinematic error term: .*point 0"):
        Kinematic(1).sample(far, "robot", None, 1)


def test_kinematic_true_robot_is_seeded_perturbation():
    k = Kinematic(seed=3, dh=UR5.with_tool(100.0))
    assert k.true_robot().same_as(Kinematic(seed=3, dh=UR5.with_tool(100.0)).true_robot())
    assert not k.true_robot().same_as(Kinematic(seed=4, dh=UR5.with_tool(100.0)).true_robot())
    assert k.true_robot().tool_mm == 100.0


# --- PointSet --------------------------------------------------------------------------------------------------------
def test_point_set_validation():
    with pytest.raises(InputError, match="robot"):
        PointSet(np.zeros((3, 2)), np.zeros((3, 3)), np.zeros(3))
    with pytest.raises(InputError, match="sensor"):
        PointSet(np.zeros((3, 3)), np.zeros((2, 3)), np.zeros(3))
    with pytest.raises(InputError, match="time"):
        PointSet(np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(4))
    with pytest.raises(InputError, match="tool_rotation"):
        PointSet(np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(3), tool_rotation=np.zeros((2, 3, 3)))
    with pytest.raises(InputError, match="side"):
        plate(2, 2).frame("camera")
    p = plate(2, 2)
    assert p.tool_rotation.shape == (4, 3, 3) and len(p) == 4


# --- ErrorModel -------------------------------------------------------------------------------------------------------
def _full_model():
    return ErrorModel(
        robot=(
            Kinematic(seed=3),
            IsotropicNoise(0.03),
            Drift((1e-4, 0.0, -2e-4), 5.0),
            Outliers(0.05, 2.0),
            WarmUp((0.05, 0.0, 0.02), 900.0),
        ),
        sensor=(
            RangeNoise.laser_tracker(),
            AnisotropicNoise(0.01, 0.05),
            Scale(20.0, (1.0, 2.0, 3.0)),
            Affine(((1e-5, 2e-6, 0.0), (0.0, -1e-5, 0.0), (0.0, 0.0, 3e-6))),
            SmoothField(0.1, 300.0, 11, features=64),
        ),
    )


def test_error_model_sums_its_terms_in_order():
    pts = plate(4, 4)
    model = _full_model()
    for side in ("robot", "sensor"):
        got = model.sample(pts, side, np.random.default_rng(42), 3)
        rng = np.random.default_rng(42)
        expected = sum(t.sample(pts, side, rng, 3) for t in model.terms(side))
        assert got.shape == (3, len(pts), 3)
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)
    assert all(isinstance(t, ErrorTerm) for t in model.robot + model.sensor)


def test_deterministic_only_and_without():
    model = _full_model()
    det = model.deterministic()
    assert det.kinds == ("kinematic", "drift", "warm_up", "scale", "affine", "smooth_field")
    pts = plate(3, 3)
    a = det.sample(pts, "sensor", np.random.default_rng(1), 4)
    b = det.sample(pts, "sensor", np.random.default_rng(2), 4)
    np.testing.assert_array_equal(a, b)  # no noise left: identical in every trial and for every rng
    np.testing.assert_array_equal(a[0], a[3])
    assert model.only("scale", "drift").kinds == ("drift", "scale")
    assert "kinematic" not in model.without("kinematic", "outliers").kinds
    assert model.without("kinematic", "outliers").robot == (
        IsotropicNoise(0.03),
        Drift((1e-4, 0.0, -2e-4), 5.0),
        WarmUp((0.05, 0.0, 0.02), 900.0),
    )
    assert ErrorModel().sample(pts, "robot", np.random.default_rng(0), 2).shape == (2, 9, 3)
    with pytest.raises(InputError, match="unknown error term kind 'noise'"):
        model.without("noise")


def test_error_model_covariance_sums_random_terms():
    pts = plate(3, 3)
    model = _full_model()
    expected = RangeNoise.laser_tracker().covariance(pts.sensor) + AnisotropicNoise(0.01, 0.05).covariance(pts.sensor)
    np.testing.assert_allclose(model.covariance(pts, "sensor"), expected)
    np.testing.assert_allclose(model.covariance(pts, "robot")[0], (0.03**2 + 0.05 * 4.0 / 3) * np.eye(3))


def test_sampling_arguments_are_checked():
    pts = plate(2, 2)
    with pytest.raises(InputError, match="side"):
        _full_model().sample(pts, "camera", np.random.default_rng(0), 1)
    with pytest.raises(InputError, match="trials"):
        _full_model().sample(pts, "robot", np.random.default_rng(0), 0)
    with pytest.raises(InputError, match="Generator"):
        _full_model().sample(pts, "robot", None, 1)
    with pytest.raises(InputError, match=r"ErrorModel.sensor\[0\] \(kinematic\) is a robot-side term"):
        ErrorModel(sensor=(Kinematic(1),))
    with pytest.raises(InputError, match="not an error term"):
        ErrorModel(robot=("isotropic_noise",))


# --- tables ----------------------------------------------------------------------------------------------------------
def test_table_round_trip():
    model = _full_model()
    table = error_model_to_dict(model)
    assert table["sensor"][1] == {"type": "anisotropic_noise", "sigma_perp_mm": 0.01, "sigma_along_mm": 0.05}
    assert table["robot"][0]["dh"] == "UR5"
    again = error_model_from_dict(table)
    assert again == model
    assert error_model_to_dict(again) == table
    # a custom arm round-trips through its parameter table
    custom = ErrorModel(robot=(Kinematic(seed=2, link_mm=0.1, dh=UR5.with_tool(120.0)),))
    t2 = error_model_to_dict(custom)
    assert t2["robot"][0]["dh"] == {"tool_mm": 120.0}
    back = error_model_from_dict(t2)
    assert back.robot[0].dh.same_as(UR5.with_tool(120.0))
    assert error_model_to_dict(back) == t2
    odd = UR5.with_tool(50.0)
    odd = type(odd)(odd.a + 0.5, odd.d, odd.alpha, odd.theta_offset, 50.0)
    t3 = error_model_to_dict(ErrorModel(robot=(Kinematic(seed=2, dh=odd),)))
    assert set(t3["robot"][0]["dh"]) == {"a", "d", "alpha", "theta_offset", "tool_mm"}
    assert error_model_from_dict(t3).robot[0].dh.same_as(odd)
    assert set(TERM_TYPES) == {
        "isotropic_noise",
        "anisotropic_noise",
        "range_noise",
        "scale",
        "affine",
        "smooth_field",
        "kinematic",
        "compliance",
        "outliers",
        "drift",
        "warm_up",
        "arm_errors",
        "sampled_field",
        "field_uncertainty",
        "linear_uncertainty",
    }
    fields = {
        "robot": [
            {"type": "sampled_field", "points_mm": [[0.0, 0.0, 0.0], [50.0, 0.0, 0.0]], "vectors_mm": [[0.1, 0.0, 0.0], [0.0, 0.1, 0.0]], "length_mm": 40.0},
            {"type": "field_uncertainty", "points_mm": [[0.0, 0.0, 0.0]], "length_mm": 40.0, "field_var_mm2": [0.01, 0.01, 0.0], "noise_var_mm2": 0.001},
        ]
    }  # fmt: skip
    assert error_model_to_dict(error_model_from_dict(fields)) == {**fields, "sensor": []}


def test_table_defaults_and_lists():
    m = error_model_from_dict(
        {
            "robot": [{"type": "kinematic", "seed": 3}],
            "sensor": [{"type": "scale", "ppm": 12}, {"type": "drift", "rate_mm_per_s": [0, 0, 1e-4]}],
        }
    )
    assert m.robot == (Kinematic(3),)
    assert m.sensor == (Scale(12.0), Drift((0.0, 0.0, 1e-4)))
    assert error_model_from_dict({}) == ErrorModel()


BAD_TABLES = [
    ([1, 2], r"^error_model must be a table"),
    ({"robots": []}, r"^error_model: unknown key 'robots'; valid keys: robot, sensor"),
    ({"sensor": "isotropic_noise"}, r"^error_model\.sensor must be a list of tables"),
    ({"sensor": [3]}, r"^error_model\.sensor\[0\] must be a table with a 'type' key"),
    ({"sensor": [{"sigma_mm": 1}]}, r"^error_model\.sensor\[0\]: missing key 'type'; valid types: isotropic_noise, "),
    ({"sensor": [{"type": "gauss"}]}, r"^error_model\.sensor\[0\]: unknown type 'gauss'; valid types: .*warm_up"),
    (
        {"sensor": [{"type": "isotropic_noise", "sigma_mm": 0.1}, {"type": "anisotropic_noise", "sigma": 0.1}]},
        r"^error_model\.sensor\[1\] \(anisotropic_noise\): unknown key 'sigma'; valid keys: sigma_perp_mm, sigma_along_mm$",
    ),
    (
        {"sensor": [{"type": "anisotropic_noise", "sigma_perp_mm": 0.1}]},
        r"^error_model\.sensor\[0\] \(anisotropic_noise\): missing key 'sigma_along_mm'",
    ),
    (
        {"robot": [{"type": "isotropic_noise", "sigma_mm": "0.1"}]},
        r"^error_model\.robot\[0\] \(isotropic_noise\): sigma_mm must be a number",
    ),
    (
        {"robot": [{"type": "isotropic_noise", "sigma_mm": True}]},
        r"^error_model\.robot\[0\] \(isotropic_noise\): sigma_mm must be a number",
    ),
    (
        {"robot": [{"type": "isotropic_noise", "sigma_mm": -0.1}]},
        r"^error_model\.robot\[0\] \(isotropic_noise\): sigma_mm must be >= 0",
    ),
    (
        {"robot": [{"type": "isotropic_noise", "sigma_mm": float("nan")}]},
        r"^error_model\.robot\[0\] \(isotropic_noise\): sigma_mm must be finite",
    ),
    (
        {"robot": [{"type": "anisotropic_noise", "sigma_perp_mm": 0.1, "sigma_along_mm": 0.2}]},
        r"^error_model\.robot\[0\] \(anisotropic_noise\): anisotropic_noise is a sensor-side term .* sensor list",
    ),
    (
        {"robot": [{"type": "range_noise", "perp_mm": [0, 0], "along_mm": [0, 0, 0]}]},
        r"^error_model\.robot\[0\] \(range_noise\): range_noise is a sensor-side",
    ),
    (
        {"sensor": [{"type": "kinematic", "seed": 1}]},
        r"^error_model\.sensor\[0\] \(kinematic\): kinematic is a robot-side term",
    ),
    (
        {"sensor": [{"type": "range_noise", "perp_mm": [0.01], "along_mm": [0, 0, 0]}]},
        r"\(range_noise\): perp_mm must be a list of 2 numbers",
    ),
    (
        {"sensor": [{"type": "range_noise", "perp_mm": [0.01, -1], "along_mm": [0, 0, 0]}]},
        r"\(range_noise\): perp_mm\[1\] must be >= 0",
    ),
    (
        {"sensor": [{"type": "scale", "ppm": 5, "center_mm": [0, 0]}]},
        r"^error_model\.sensor\[0\] \(scale\): center_mm must be a list of 3",
    ),
    ({"sensor": [{"type": "affine", "matrix": [[1, 0, 0], [0, 1, 0]]}]}, r"\(affine\): matrix must be a 3x3 matrix"),
    (
        {"sensor": [{"type": "smooth_field", "rms_mm": 0.1, "length_mm": 0, "seed": 1}]},
        r"\(smooth_field\): length_mm must be > 0",
    ),
    (
        {"sensor": [{"type": "smooth_field", "rms_mm": 0.1, "length_mm": 100, "seed": 1.5}]},
        r"\(smooth_field\): seed must be an integer",
    ),
    (
        {"robot": [{"type": "kinematic", "seed": 1, "link_mm": -0.2}]},
        r"^error_model\.robot\[0\] \(kinematic\): link_mm must be >= 0",
    ),
    ({"robot": [{"type": "kinematic", "seed": 1, "dh": "UR10"}]}, r"\(kinematic\): dh must be \"UR5\" or a table"),
    ({"robot": [{"type": "kinematic", "seed": 1, "dh": {"a": [0] * 5}}]}, r"\(kinematic\): dh\.a must be a list of 6"),
    (
        {"robot": [{"type": "kinematic", "seed": 1, "dh": {"tool": 5}}]},
        r"\(kinematic\): dh: unknown key 'tool'; valid keys: a, d,",
    ),
    (
        {"robot": [{"type": "outliers", "fraction": 2, "size_mm": 1}]},
        r"^error_model\.robot\[0\] \(outliers\): fraction must be between 0 and 1",
    ),
    ({"robot": [{"type": "warm_up", "amplitude_mm": [0, 0, 1], "tau_s": -5}]}, r"\(warm_up\): tau_s must be > 0"),
    ({"robot": [{"type": "drift", "rate_mm_per_s": 0.001}]}, r"\(drift\): rate_mm_per_s must be a list of 3 numbers"),
]


@pytest.mark.parametrize("table, message", BAD_TABLES)
def test_bad_tables_name_the_place(table, message):
    with pytest.raises(InputError, match=message):
        error_model_from_dict(table)


def test_bad_table_uses_the_callers_location():
    with pytest.raises(InputError, match=r"^simulation\.errors\.sensor\[0\] \(scale\): missing key 'ppm'"):
        error_model_from_dict({"sensor": [{"type": "scale"}]}, where="simulation.errors")
