"""Per-point bounds (issue 37, items 1-2): each corrected target and check gets a 95 % bound on its 3-D error, its
covariance and its budget; the bound holds on held-out checks of seeded files whose bias is not the bounds' model,
and where the data cannot back a number, there is none and a warning says why."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.stats import chi2

from rrbc_core.correction.bound_radius import bound95
from rrbc_core.correction.bound_registration import point_registration_cov, registration_theta_cov
from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.correction.stations import correct_stations
from rrbc_core.errors import InputError
from rrbc_core.methods import MethodOptions
from rrbc_core.models.instrument import instrument_from_flags, preset
from rrbc_core.registration import register
from rrbc_core.simulation.field_data import field_measurements
from rrbc_core.simulation.station_data import drawn_stations

#: the two-moment (scaled χ²) radius's own error for three terms, at most (measured over random covariances with
#: 200 000 draws each: 0.0024; docs/uncertainty.md)
APPROXIMATION = 0.003


def _coverage(pairs) -> tuple[float, int]:
    """Share of (error, bound) with error <= bound among the bounded points, and how many were bounded."""
    e = np.concatenate([p[0] for p in pairs])
    b = np.concatenate([p[1] for p in pairs])
    ok = np.isfinite(b)
    return float(np.mean(e[ok] <= b[ok])), int(ok.sum())


def test_the_bound_is_the_chi2_radius_for_an_isotropic_error_and_holds_95_percent_of_any_normal_error():
    s = 0.37
    assert bound95((s**2 * np.eye(3))[None])[0] == pytest.approx(s * np.sqrt(chi2.ppf(0.95, 3)), rel=1e-12)
    rng = np.random.default_rng(3)
    n = 20000
    se = np.sqrt(0.95 * 0.05 / n)
    for _ in range(12):
        lam = rng.uniform(0.0, 1.0, 3) ** rng.uniform(1, 6)
        lam[rng.integers(3)] = 1.0
        q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        cov = q @ np.diag(lam) @ q.T
        z = rng.multivariate_normal(np.zeros(3), cov, n)
        inside = np.mean(np.linalg.norm(z, axis=1) <= bound95(cov[None])[0])
        assert abs(inside - 0.95) <= 4 * se + APPROXIMATION


def test_the_registration_covariance_is_the_least_squares_fits_own_spread():
    """First-order propagation against 3000 refits of noisy registration points, at a point far outside them."""
    rng = np.random.default_rng(7)
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    rot *= np.linalg.det(rot)
    t = rng.normal(0, 500, 3)
    s = rng.uniform(-300, 300, (8, 3))
    sigma = 0.05
    p = np.array([[900.0, -700.0, 400.0]])
    row_cov = np.broadcast_to(sigma**2 * np.eye(3), (8, 3, 3))
    cov = point_registration_cov(rot, p, np.ones(1), registration_theta_cov(rot, s, row_cov))[0]
    trials = 3000
    out = np.empty((trials, 3))
    b = s @ rot.T + t
    for k in range(trials):
        reg = register("least-squares", s, b + rng.normal(0, sigma, b.shape))
        out[k] = reg.mapping.apply(p)[0]
    mc = np.cov(out.T)
    # a variance's relative standard error over n draws is sqrt(2 / (n - 1)); 4 of them
    assert np.trace(cov) == pytest.approx(np.trace(mc), rel=4 * np.sqrt(2 / (trials - 1)))


def test_rrbc_takes_out_the_registrations_error_at_a_fiducial():
    m = field_measurements(1)
    res = correct_measurements(m, MethodOptions.named("least-squares", "idw"))
    b = res.bounds
    # the checks' registration part is far below rigid's: the corrections carry the transform's error
    assert np.median(b.checks.budget_mm["registration"]) < 0.5 * np.median(b.checks_rigid.budget_mm["registration"])


@pytest.mark.parametrize(
    "method", ["idw", pytest.param("tps", marks=pytest.mark.slow), pytest.param("auto", marks=pytest.mark.slow), "none"]
)
def test_bounds_hold_on_held_out_checks_of_real_like_stations(method):
    """Stations of a lift-column robot (`simulation.station_data`: a smooth field per station, fiducials around the
    checks), sizes drawn per seed as real cells have them. Between 90 and 99 % of the bounded checks lie within their
    bound, up to two binomial standard errors; each file's median bound is at most twice its checks' 95th
    percentile error (sharp); at most a tenth of the checks go unbounded."""
    pairs, sharp, withheld, total = [], [], 0, 0
    for seed in range(8):
        m = drawn_stations(seed)
        res = correct_stations(m, MethodOptions.named("least-squares", method))
        e = np.concatenate([st.error_rrbc for st in res.stations])
        b = np.concatenate([st.bounds.checks.bound95_mm for st in res.stations])
        ok = np.isfinite(b)
        withheld += int(np.sum(~ok))
        total += len(b)
        pairs.append((e, b))
        sharp.append(np.median(b[ok]) / np.percentile(e[ok], 95))
    cover, n = _coverage(pairs)
    se = np.sqrt(0.95 * 0.05 / n)
    assert 0.90 - 2 * se <= cover <= 0.99 + 2 * se, cover
    assert max(sharp) <= 2.0, sharp
    assert withheld <= 0.1 * total


def _rigid_and_rrbc_cover(msets, method: str, sharp: bool = False) -> None:
    """Over the files' checks, rigid's and RRBC's bounds each hold between 90 and 99 % of the bounded checks, up to
    two binomial standard errors; with `sharp`, each median bound is at most twice the 95th percentile error."""
    pairs, pairs_rigid = [], []
    for m in msets:
        res = correct_measurements(m, MethodOptions.named("least-squares", method))
        pairs.append((res.error_rrbc, res.bounds.checks.bound95_mm))
        pairs_rigid.append((res.error_rigid, res.bounds.checks_rigid.bound95_mm))
    for p in (pairs, pairs_rigid):
        cover, n = _coverage(p)
        se = np.sqrt(0.95 * 0.05 / n)
        assert 0.90 - 2 * se <= cover <= 0.99 + 2 * se, (cover, n)
        if sharp:
            e, b = np.concatenate([x[0] for x in p]), np.concatenate([x[1] for x in p])
            ok = np.isfinite(b)
            assert np.median(b[ok]) <= 2.0 * np.percentile(e[ok], 95)


@pytest.mark.parametrize(
    "shape",
    [
        {},
        {"layout": "plane"},
        {"polar": True, "noise_mm": 0.08},
        {"repeats": True},
        {"n_fiducials": 100, "n_checks": 100},
    ],
    ids=["volume", "plane", "polar", "repeats", "dense"],
)
def test_bounds_hold_on_a_smooth_field_in_a_volume_or_off_coplanar_fiducials(shape):
    _rigid_and_rrbc_cover([field_measurements(100 + seed, **shape) for seed in range(8)], "idw")


def test_a_point_the_fiducials_cannot_speak_for_gets_no_bound_and_a_warning():
    m = field_measurements(5, layout="plane")
    res = correct_measurements(m, MethodOptions.named("least-squares", "idw"))
    off = res.checks_corrected.off_plane_mm
    b = res.bounds.checks.bound95_mm
    # far off the plane: none; near it: a bound
    assert np.all(np.isnan(b[off > 140])) and np.all(np.isfinite(b[off < 5]))
    assert any("no bound for" in w and "checks" in w for w in res.warnings())
    rows = res.to_json()["checks"]
    far = [r for r in rows if r.get("off_plane_mm", 0) > 140]
    assert far and all(r["bound95_mm"] is None and r["budget_mm"] is None for r in far)


def test_too_few_fiducials_to_cross_validate_give_no_rrbc_bound_but_rigid_keeps_its_own():
    m = field_measurements(2, n_fiducials=5)
    res = correct_measurements(m, MethodOptions.named("least-squares", "idw"))
    assert np.all(np.isnan(res.bounds.checks.bound95_mm))
    assert np.any(np.isfinite(res.bounds.checks_rigid.bound95_mm))
    assert any("too few to cross-validate" in w for w in res.warnings())


def test_the_interpolations_share_grows_away_from_the_fiducials():
    m = field_measurements(9, n_checks=0)
    res = correct_measurements(m, MethodOptions.named("least-squares", "idw"))
    fid = res.fiducials.sensor
    centre = fid.mean(axis=0)
    direction = np.array([1.0, 0.3, -0.2]) / np.linalg.norm([1.0, 0.3, -0.2])
    pts = centre + np.outer([0, 100, 200, 300, 400], direction)
    d = cKDTree(fid).query(pts)[0]
    v = res.bounds.profile.variance(d)
    order = np.argsort(d)
    assert np.all(np.diff(v[order]) >= 0) and v[order][-1] > v[order][0]


def test_noise_is_estimated_from_repeats_within_its_sampling_error():
    sigma = 0.05
    m = field_measurements(4, repeats=True, noise_mm=sigma)
    res = correct_measurements(m, MethodOptions.named("least-squares", "idw"))
    inst = res.bounds.instrument
    assert "repeated readings" in inst.source
    dof = int(inst.source.split("(")[1].split()[0])
    # one row's per-axis variance is the sensor's and the robot's: 2 σ²; a variance's relative SE is sqrt(2 / dof)
    assert inst.sigma_mm**2 == pytest.approx(2 * sigma**2, rel=4 * np.sqrt(2 / (3 * dof)))


def test_an_instrument_far_noisier_than_the_data_is_named_in_the_warnings():
    m = field_measurements(4, repeats=True, noise_mm=0.02)
    res = correct_measurements(m, MethodOptions.named("least-squares", "idw"), preset("total-station"))
    assert any("stated noise" in w for w in res.warnings())
    assert res.bounds.instrument.name == "total-station"


def test_a_polar_instruments_noise_lies_along_and_across_the_line_of_sight():
    inst = preset("total-station")
    p = np.array([[0.0, 30000.0, 0.0]])  # 30 m along y
    c = inst.sensor_cov(p)[0]
    sd = inst.distance_mm + inst.distance_ppm * 1e-6 * 30000
    st2 = inst.floor_mm**2 + (inst.angle_urad * 1e-6 * 30000) ** 2
    assert np.allclose(c, np.diag([st2, sd**2, st2]))


@pytest.mark.parametrize(
    "kwargs, says",
    [
        ({"name": "tracker", "sensor_noise_mm": 0.1}, "polar"),
        ({"name": "cmm", "distance_noise_mm": 0.1}, "per-axis"),
        ({"name": None, "sensor_noise_mm": 0.1, "angle_noise_urad": 3.0}, "one kind"),
        ({"name": None, "sensor_noise_mm": -1.0}, "between 0"),
        ({"name": None, "robot_noise_mm": float("nan")}, "between 0"),
        ({"name": "laser"}, "not one of"),
    ],
)
def test_instrument_figures_that_cannot_be_are_refused(kwargs, says):
    with pytest.raises(InputError, match=says):
        instrument_from_flags(**kwargs)


def test_given_figures_override_a_preset_and_say_so():
    inst = instrument_from_flags("tracker", angle_noise_urad=10.0, robot_noise_mm=0.03)
    assert inst.angle_urad == 10.0 and inst.distance_mm == preset("tracker").distance_mm
    assert "--angle-noise-urad given" in inst.source and inst.robot_mm == 0.03


def test_the_drawn_ellipsoid_is_the_covariances_95_percent_region_and_the_bound_when_isotropic():
    from rrbc_core.correction.bound_radius import bound_ellipsoids

    rng = np.random.default_rng(11)
    q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    cov = q @ np.diag([0.04, 0.01, 0.0025]) @ q.T
    rot, axes = bound_ellipsoids(np.stack([cov, 0.09 * np.eye(3), np.full((3, 3), np.nan)]))
    assert np.allclose(np.linalg.det(rot[:2]), 1.0)
    # each axis's end lies on x' C^-1 x = chi2_3(0.95)
    for k in range(3):
        x = rot[0][:, k] * axes[0][k]
        assert x @ np.linalg.solve(cov, x) == pytest.approx(chi2.ppf(0.95, 3))
    assert np.allclose(axes[1], bound95((0.09 * np.eye(3))[None])[0])
    assert np.all(np.isnan(axes[2]))


def _board_and_points_above(seed: int):
    """A stationing-shaped file (the public stationing data's form): 8 registration points on a board (role `both`:
    also fiducials), 40 points 160-420 mm above it, every other one a fiducial, the rest checks; an error that grows
    with the height above the board (a random smooth field times (h / 420 mm)², 3 mm RMS at the top), so the
    board's points carry almost none. Noise 0.05 mm per axis on both sides."""
    from rrbc_core.io.measurements import MeasurementSet

    rng = np.random.default_rng(seed)
    board = np.column_stack([rng.uniform(-300, 300, (8, 2)), np.zeros(8)])
    above = np.column_stack([rng.uniform(-300, 300, (40, 2)), rng.uniform(160, 420, 40)])
    p = np.vstack([board, above])
    k = rng.normal(size=(6, 3)) / 300.0  # six random plane waves, wavelengths about 2 m
    amp, phase = rng.normal(size=(6, 3)), rng.uniform(0, 2 * np.pi, 6)
    field = np.sin(p @ k.T + phase) @ amp
    field *= 3.0 / np.sqrt(np.mean(np.sum(field[8:] ** 2, axis=1)))
    err = field * ((p[:, 2] / 420.0) ** 2)[:, None]
    sensor = p + rng.normal(0, 0.05, p.shape)
    robot = p + err + rng.normal(0, 0.05, p.shape)
    roles = ["both"] * 8 + ["fiducial" if i % 2 == 0 else "check" for i in range(40)]
    n = len(roles)
    return MeasurementSet(
        tuple(f"P{i}" for i in range(n)),
        tuple(roles),
        sensor,
        robot,
        np.full(n, np.nan),
        tuple(range(2, n + 2)),
        "board",
    )


@pytest.mark.parametrize("method", ["idw", "tps"])
def test_bounds_hold_where_the_registration_points_carry_no_error_and_the_checks_do(method):
    """The registration points' corrections are fit residuals (the registration was fitted to them) and, on a board
    below the work, nearly nothing: held out in the cross-validation they would tell the bounds the error is small.
    Only the fiducials that are not registration points make the profile (and rigid's error) when there are six of
    them: between 90 and 99 % of the bounded checks within their bound, up to two binomial standard errors, rigid
    and RRBC alike, and sharp (the median bound at most twice the 95th percentile error)."""
    _rigid_and_rrbc_cover([_board_and_points_above(seed) for seed in range(16)], method, sharp=True)


def test_the_predictive_factor_makes_a_bound_from_an_estimated_variance_hold_95_percent():
    """A variance estimated from n points' 3-D errors, then a new point: the plug-in bound (the χ² radius of the
    estimate) holds less than 95 %; times `predictive_factor(3 n)` it holds 95 % (the ratio is F(3, 3n)-distributed
    for normal errors), within three Monte Carlo standard errors."""
    from rrbc_core.correction.bound_inputs import predictive_factor

    rng = np.random.default_rng(11)
    trials, n = 40_000, 8
    sigma2 = np.mean(rng.normal(size=(trials, n, 3)) ** 2, axis=(1, 2))  # per axis
    new = np.sum(rng.normal(size=(trials, 3)) ** 2, axis=1)
    plug_in = np.sqrt(chi2.ppf(0.95, 3) * sigma2)
    se = np.sqrt(0.95 * 0.05 / trials)
    assert np.mean(np.sqrt(new) <= plug_in) < 0.95 - 3 * se
    assert abs(np.mean(np.sqrt(new) <= plug_in * predictive_factor(3 * n)) - 0.95) < 3 * se
    assert predictive_factor(10**6) == pytest.approx(1.0, abs=1e-4)


def test_the_chi2_quantile_curve_is_scipys_to_1e_10():
    """`chi2_quantile` (a spline through scipy's quantiles) against scipy's own at 20 000 seeded degrees of freedom
    in [1, 3] and at both ends, at 95 % and 99 %; and the bound from the trace and Frobenius norm against the
    eigenvalues' on random covariances."""
    from rrbc_core.correction.bound_radius import chi2_quantile

    nu = np.concatenate([[1.0, 3.0], np.random.default_rng(11).uniform(1.0, 3.0, 20_000)])
    for level in (0.95, 0.99):
        exact = chi2.ppf(level, nu)
        assert np.max(np.abs(chi2_quantile(nu, level) / exact - 1.0)) < 1e-10
    a = np.random.default_rng(12).normal(size=(500, 3, 3))
    cov = a @ a.transpose(0, 2, 1)
    lam = np.linalg.eigvalsh(cov)
    s1, s2 = lam.sum(axis=1), (lam**2).sum(axis=1)
    by_eigen = np.sqrt(s2 / s1 * chi2.ppf(0.95, s1**2 / s2))
    assert np.max(np.abs(bound95(cov) / by_eigen - 1.0)) < 1e-10


def test_points_bounded_in_passes_are_bounded_as_in_one(monkeypatch):
    """`bound_points` bounds long point lists in passes (`POINTS_PER_PASS`): the same numbers and warnings as one
    pass, on a file with points beyond what the folds tested."""
    from rrbc_core.correction import bounds as bounds_module

    m = field_measurements(21, n_fiducials=40, n_checks=700)
    whole = correct_measurements(m).bounds
    monkeypatch.setattr(bounds_module, "POINTS_PER_PASS", 97)
    passes = correct_measurements(m).bounds
    assert passes.warnings == whole.warnings
    for name in ("checks", "checks_rigid"):
        a, b = getattr(whole, name), getattr(passes, name)
        assert np.array_equal(a.bound95_mm, b.bound95_mm, equal_nan=True)
        assert np.array_equal(a.cov_mm2, b.cov_mm2, equal_nan=True)
        assert a.budget_mm.keys() == b.budget_mm.keys()
        assert all(np.array_equal(a.budget_mm[k], b.budget_mm[k], equal_nan=True) for k in a.budget_mm)
