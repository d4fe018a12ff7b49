"""How far each corrected point may be off: a 95 % bound on its 3-D error, its covariance and the budget it is made of.

For a point the robot is sent to (a target's or check's corrected position, robot frame) the error is the sum of
three parts, each with a covariance (robot frame, mm²; docs/uncertainty.md derives them):

* **instrument**: the point's own readings. Its sensor reading (`models.instrument.Instrument.sensor_cov`, rotated
  into the robot frame) and the robot's own noise where it goes (per-axis σ_r), divided by the number of readings
  averaged for it.
* **registration**: the least-squares transform's uncertainty from the registration points' noise, propagated to
  the point (first order, rotation vector and translation). RRBC's corrections carry the same transform error at the
  fiducials with the opposite sign, so for RRBC what is left is the transform's error at the point less its
  interpolated error at the fiducials: G(p) = [−[R (p − F(p))]×, (1 − w(p)) I], with F the interpolator applied to
  the fiducials' own positions and w to ones (exact for interpolators that are linear in their values).
* **interpolation**: the correction's own error there. K-fold cross-validation over the fiducials (the folds of
  `interpolation.auto`) gives each held-out fiducial's error r_i at its distance d_i from the nearest fiducial left
  in. Its expected square is modelled as E|r|² = A + B d²: A = 2 ν, with ν a fiducial's own noise (3-D variance,
  from the instrument), is the held-out fiducial's own noise and about one neighbour's carried into the prediction
  (what a point on a fiducial gets); B is the mean of (|r_i|² − A)/d_i² (least squares weighted for a spread that
  grows as d², clipped at 0). A regular grid's fiducials are all about one spacing from the rest, so A and B cannot
  both be fitted: A is fixed by the noise. At a point d(p) from its nearest fiducial the interpolation's variance is
  ν + B d(p)² (the point's own noise is the instrument's part), with the shape of the residuals' mean r rᵀ: it grows
  away from the fiducials, outside their hull and off their plane. Off coplanar (or collinear) fiducials the folds
  see nothing of the field's change with height, and a smooth interpolator's in-plane error (curvature) says little
  about it; a point h off the plane adds g² h², g² the field's mean squared rate of change along the plane
  (`field_slope`): the field is assumed to change off the plane as it does along it, which such data cannot test.
  For rigid (no correction) it is the correction not made: the fiducials' mean |correction|² less their noise.

The bound is the radius holding 95 % of a normal error with that covariance (a scaled χ² matched in mean and variance
to the sum of the eigenvalues' χ²₁ terms; exact for an isotropic covariance). Where the bound cannot be trusted it is
NaN (null in JSON) with a warning: fewer than `MIN_FIDUCIALS` fiducials to cross-validate.

The noise, when no instrument is given, is estimated from the data (`bound_inputs.estimate_noise`): from repeated readings of a
point when the file has them, else from the fiducials' nearest-neighbour differences at zero distance (the nugget).
Units mm; frames as in the measurement file.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from rrbc_core.correction.bound_inputs import (
    MIN_FIDUCIALS,
    complete_instrument,
    estimate_noise,
    field_slope,
    fit_quadratic,
    fold_distances,
    predictive_factor,
    tested_distance,
)
from rrbc_core.correction.bound_radius import LEVEL, bound95, bound_ellipsoids
from rrbc_core.correction.bound_registration import own_cov, point_registration_cov, registration_theta_cov
from rrbc_core.errors import InputError
from rrbc_core.interpolation.auto import folds_of
from rrbc_core.interpolation.hull import Hull, covered
from rrbc_core.models.instrument import Instrument

BUDGET_KEYS = ("instrument", "registration", "interpolation", "arm")


@dataclass(frozen=True, eq=False)
class PointBounds:
    """Bounds of M points: `bound95_mm` (M,) (NaN: not given), `cov_mm2` (M, 3, 3) robot frame, and `budget_mm`
    {name: (M,)} the RMS contribution (sqrt of the trace of its covariance) of each source that applies."""

    bound95_mm: np.ndarray
    cov_mm2: np.ndarray
    budget_mm: dict[str, np.ndarray]

    def ellipsoids(self, level: float = LEVEL) -> tuple[np.ndarray, np.ndarray]:
        """`bound_ellipsoids` of the points' covariances, NaN semi-axes where no bound is given."""
        rot, axes = bound_ellipsoids(self.cov_mm2, level)
        axes[~np.isfinite(self.bound95_mm)] = np.nan
        return rot, axes

    def row_json(self, k: int, suffix: str = "", cov: bool = True) -> dict:
        """Point k's keys for a JSON row: ``bound95{suffix}_mm``, ``budget{suffix}_mm`` and, with `cov`,
        ``cov{suffix}_mm2`` (`rows_json` gives every point's at once)."""
        return self.rows_json(suffix, cov)[k]

    def rows_json(self, suffix: str = "", cov: bool = True, start: int = 0, stop: int | None = None) -> list[dict]:
        """Points `start`..`stop`'s (default every point's) `row_json`, built from whole arrays (a million rows stay
        cheap)."""
        sl = slice(start, stop)
        bounds = self.bound95_mm[sl].tolist()
        covs = self.cov_mm2[sl].tolist() if cov else None
        names = list(self.budget_mm)
        budgets = list(zip(*(self.budget_mm[n][sl].tolist() for n in names))) if names else [()] * len(bounds)
        out = []
        for k, b in enumerate(bounds):
            if b != b:  # NaN: no bound
                row: dict = {f"bound95{suffix}_mm": None, f"budget{suffix}_mm": None}
                if cov:
                    row[f"cov{suffix}_mm2"] = None
            else:
                row = {f"bound95{suffix}_mm": b, f"budget{suffix}_mm": dict(zip(names, budgets[k]))}
                if covs is not None:
                    row[f"cov{suffix}_mm2"] = covs[k]
            out.append(row)
        return out


@dataclass(frozen=True)
class CVProfile:
    """The interpolation's cross-validated error against distance: E|r|² = a_mm2 + b * d² (d mm), from `n`
    held-out fiducials over `folds` folds; `noise_mm2` the part the held-out fiducials' own noise explains (taken
    out); `shape` (3, 3) the residuals' mean r rᵀ over its trace (robot frame)."""

    a_mm2: float
    b: float
    noise_mm2: float
    n: int
    folds: int
    rms_mm: float
    shape: np.ndarray = field(compare=False)
    tail: float = 1.0
    b_outside: float = 0.0
    distances: np.ndarray | None = field(default=None, compare=False)  # (n,) each held-out fiducial's d

    def variance(self, d: np.ndarray, inside=True) -> np.ndarray:
        """(M,): the interpolation's 3-D variance at distances d (M,) from the nearest fiducial, inside the
        fiducials' hull or not (`inside`, (M,) bool), mm² (the model's A + B d² less the held-out fiducial's own
        noise; B `b` inside, `b_outside` outside)."""
        b = np.where(np.asarray(inside, bool), self.b, self.b_outside)
        return np.maximum(self.a_mm2 + b * np.asarray(d, float) ** 2 - self.noise_mm2, 0.0)

    def to_json(self) -> dict:
        return {
            "a_mm2": self.a_mm2,
            "b_per_mm2": self.b,
            "b_outside_per_mm2": self.b_outside,
            "noise_mm2": self.noise_mm2,
            "fiducials": self.n,
            "folds": self.folds,
            "cv_rms_mm": self.rms_mm,
            "tail_factor": self.tail,
        }


@dataclass(frozen=True, eq=False)
class Bounds:
    """A correction's per-point bounds: the instrument used (its figures' sources), the interpolation's
    cross-validation profile (None: not cross-validated), the bounds of the RRBC and rigid positions of the targets
    and checks (None where there are no such points), and warnings."""

    instrument: Instrument
    profile: CVProfile | None
    targets: PointBounds | None
    checks: PointBounds | None
    targets_rigid: PointBounds | None
    checks_rigid: PointBounds | None
    warnings: tuple[str, ...] = ()

    def to_json(self) -> dict:
        """``bounds`` in the JSON of `rrbc correct` (docs/cli.md)."""
        return {
            "level": LEVEL,
            "instrument": self.instrument.to_json(),
            "interpolation_profile": None if self.profile is None else self.profile.to_json(),
        }


def _rigid_error(c_robot, fid_registered, reg_residuals, n_reg: int, fid_noise: float):
    """Rigid's uncorrected error (the correction not made): its 3-D variance beyond a fiducial's own noise, its shape
    (3, 3) and the tail factor (the fiducials' 95th percentile of |c| against a normal error's), from the fiducials'
    corrections c (F, 3) robot frame: those of the fiducials that are not registration points when there are
    `MIN_FIDUCIALS` of them, else all, those that are registration points too scaled by n/(n − 2) (their correction
    is a fit residual, smaller than a point's error by that factor); without fiducials, from the registration
    residuals. (None, I/3, 1) when neither holds enough."""
    free = ~np.asarray(fid_registered, bool)
    if np.count_nonzero(free) >= MIN_FIDUCIALS:  # enough points the registration did not see: theirs alone
        c = np.asarray(c_robot, float)[free]
        scale = np.ones(len(c))
    elif len(c_robot):
        c = np.asarray(c_robot, float)
        scale = np.where(np.asarray(fid_registered, bool), n_reg / max(n_reg - 2, 1), 1.0)
    elif reg_residuals is not None and len(reg_residuals) > 3:
        c = np.asarray(reg_residuals, float)
        scale = np.full(len(c), len(c) / (len(c) - 2))
        fid_noise = 0.0  # already inside the residuals' spread
    else:
        return None, np.eye(3) / 3, 1.0
    sq = scale * np.sum(c**2, axis=1)
    v = max(float(np.mean(sq)) - fid_noise, 0.0)
    s = (c * scale[:, None]).T @ c
    shape = s / np.trace(s) if np.trace(s) > 0 else np.eye(3) / 3
    total = v + fid_noise
    tail = tail_factor(sq, np.full(len(sq), total), shape) if total > 0 else 1.0
    return v, shape, tail


def tail_factor(sq: np.ndarray, model: np.ndarray, shape: np.ndarray, fitted: int = 1) -> float:
    """The tail the samples show, at least 1: the 95th percentile of |r| / sqrt(model), squared errors sq (H,)
    against their modelled 3-D variances model (H,), over a normal error's with the covariance's `shape` (3, 3);
    times the predictive factor of a variance estimated from these samples (`predictive_factor`, `fitted` the
    model's parameters fitted to them); 1 with fewer than `MIN_FIDUCIALS` usable samples."""
    ok = model > 0
    n = int(np.count_nonzero(ok))
    if n < MIN_FIDUCIALS:
        return 1.0
    z = np.sqrt(sq[ok] / model[ok])
    empirical = max(float(np.percentile(z, 100 * LEVEL)) / float(bound95(shape[None])[0]), 1.0)
    return empirical * predictive_factor(3 * n - fitted)


def cv_profile(
    method,
    fid_sensor: np.ndarray,
    fid_corr: np.ndarray,
    rotation: np.ndarray,
    noise_mm2: float,
    scored: np.ndarray | None = None,
) -> CVProfile | None:
    """The interpolation's K-fold cross-validation profile (`CVProfile`), None when a fold cannot be fitted.
    `scored` (F,) bool: the held-out fiducials whose errors make the profile (default all; every fiducial is held
    out and predicts the others either way)."""
    n = len(fid_sensor)
    fold = folds_of(n)
    err = np.empty_like(fid_corr)
    dist = fold_distances(fid_sensor)
    inside = np.empty(n, bool)
    for f in range(int(fold.max()) + 1):
        test = fold == f
        try:
            pred = method.fit(fid_sensor[~test], fid_corr[~test]).predict(fid_sensor[test])
        except InputError:
            return None
        err[test] = pred.values - fid_corr[test]
        inside[test] = ~np.asarray(pred.extrapolated, bool)  # the one hull test (`interpolation.hull`)
    if not np.all(np.isfinite(err)):
        return None
    r = err @ np.asarray(rotation, float).T
    k = np.ones(n, bool) if scored is None else np.asarray(scored, bool)
    return profile_from_squares(np.sum(r[k] ** 2, axis=1), dist[k], inside[k], noise_mm2, r[k], int(fold.max()) + 1)


def profile_from_squares(sq, dist, inside, noise_mm2: float, r=None, folds: int = 0) -> CVProfile:
    """The `CVProfile` of held-out squared 3-D errors sq (H,) mm² at distances dist (H,) mm from the nearest
    fiducial left in, inside the rest's hull or not (`inside` (H,) bool), with a fiducial's own noise `noise_mm2`
    (module docstring); `r` (H, 3) the errors themselves for the shape (robot frame; isotropic without)."""
    sq, dist, inside = np.asarray(sq, float), np.asarray(dist, float), np.asarray(inside, bool)
    near = dist > 1e-9
    d2 = dist[near] ** 2
    if np.count_nonzero(near) >= MIN_FIDUCIALS and np.max(d2) >= 4 * np.min(d2):
        a, b = fit_quadratic(d2, sq[near])  # distances spread: the folds' own intercept
    else:  # one spacing (a grid): the held-out fiducial's noise and about one neighbour's carried into it
        a = 2.0 * float(noise_mm2)
        b = max(float(np.mean((sq[near] - a) / d2)), 0.0) if np.any(near) else 0.0
    # held out inside the rest's hull (interpolated) or outside (extrapolated): each its own rate when it has 3
    slopes = []
    for group in (inside & near, ~inside & near):
        k = np.count_nonzero(group)
        slopes.append(max(float(np.mean((sq[group] - a) / dist[group] ** 2)), 0.0) if k >= 3 else b)
    b_in, b_out = slopes[0], max(slopes[1], slopes[0])
    s = r.T @ r if r is not None else np.eye(3)
    shape = s / np.trace(s) if np.trace(s) > 0 else np.eye(3) / 3
    # the tail the fiducials show: their 95th percentile of |r| / sqrt(A + B d²) against a normal error's
    tail = tail_factor(sq, a + np.where(inside, b_in, b_out) * dist**2, shape, fitted=2)
    t2 = tail**2
    return CVProfile(
        a * t2,
        b_in * t2,
        float(noise_mm2),
        len(sq),
        folds,
        float(np.sqrt(np.mean(sq))) if len(sq) else 0.0,
        shape,
        tail,
        b_out * t2,
        dist,
    )


def _onto_plane(fid_sensor: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The points p (M, 3) moved onto the fiducials' best-fit plane (their height off it is counted apart)."""
    c = fid_sensor.mean(axis=0)
    normal = np.linalg.svd(fid_sensor - c)[2][-1]
    return p - np.outer((p - c) @ normal, normal)


def assemble_bounds(parts: dict[str, np.ndarray], withheld: np.ndarray) -> PointBounds:
    """The bounds of the parts' sum; NaN where `withheld` (M,)."""
    cov = sum(parts.values())
    assert isinstance(cov, np.ndarray)
    budget = {k: np.sqrt(np.maximum(np.trace(v, axis1=1, axis2=2), 0.0)) for k, v in parts.items()}
    b = bound95(cov)
    b[withheld] = np.nan
    return PointBounds(b, cov, budget)


def no_bounds(m: int) -> PointBounds:
    """M points without a bound (NaN)."""
    return PointBounds(np.full(m, np.nan), np.full((m, 3, 3), np.nan), {})


def correction_bounds(
    data,
    mapping,
    reg_sensor: np.ndarray,
    reg_count: np.ndarray,
    fid_sensor: np.ndarray,
    fid_count: np.ndarray,
    fid_corr: np.ndarray,
    method,
    interpolating: bool,
    points: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
    instrument: Instrument | None = None,
    reg_residuals: np.ndarray | None = None,
    fid_registered: np.ndarray | None = None,
) -> Bounds:
    """Per-point bounds of a correction (module docstring).

    Parameters
    ----------
    data : MeasurementSet or None
        The rows (for repeats).
    mapping : SensorToRobot
        The registration's mapping (its rotation R is used).
    reg_sensor, reg_count : (N, 3), (N,)
        Registration points' sensor readings (sensor frame, mm) and how many rows each averages.
    fid_sensor, fid_count, fid_corr : (F, 3), (F,), (F, 3)
        Fiducials' sensor readings, row counts and corrections (sensor frame, mm).
    method : interpolation method object
        What corrects (its `fit` is used for the folds and for F and w).
    interpolating : bool
        False for ``none`` (the corrected position is the rigid one).
    points : {"targets": (sensor (M, 3), count (M,), off_plane_mm (M,)), "checks": ...}
        The points to bound: their sensor readings, row counts and distances from the fiducials' plane or line (0
        for a 3-D fiducial set; `interpolation.hull`).
    instrument : Instrument, optional
        The reading noise (default: estimated from the data).
    reg_residuals : (N, 3), optional
        The registration's residuals (robot frame, mm): rigid's uncorrected error when there are no fiducials.
    fid_registered : (F,) bool, optional
        Which fiducials are registration points too (default none).
    """
    basis = bounds_basis(
        data,
        mapping,
        reg_sensor,
        reg_count,
        fid_sensor,
        fid_count,
        fid_corr,
        method,
        interpolating,
        instrument,
        reg_residuals,
        fid_registered,
    )
    return bound_points(basis, points)


@dataclass(frozen=True, eq=False)
class BoundsBasis:
    """What the bounds need from the registration and the fiducials alone (`bounds_basis`): computed once for a
    set of fiducials, reused for any points (`bound_points`; the app's target drags). Robot frame, mm."""

    instrument: Instrument
    rotation: np.ndarray
    theta: np.ndarray  # (6, 6) the transform's covariance
    fid_sensor: np.ndarray
    interpolating: bool
    profile: CVProfile | None
    fitted: tuple | None  # the interpolator fitted to the fiducials' positions and to ones (F, w; w None: weights
    # that sum to one, w = 0)
    tested_mm: float | None
    slope: float
    v_rigid: float
    shape_rigid: np.ndarray
    tail_rigid: float
    warnings: tuple[str, ...]
    hull: Hull | None = None  # the fiducials' hull (`interpolation.hull`), built once for every drag's points


def bounds_basis(
    data,
    mapping,
    reg_sensor: np.ndarray,
    reg_count: np.ndarray,
    fid_sensor: np.ndarray,
    fid_count: np.ndarray,
    fid_corr: np.ndarray,
    method,
    interpolating: bool,
    instrument: Instrument | None = None,
    reg_residuals: np.ndarray | None = None,
    fid_registered: np.ndarray | None = None,
    profile: CVProfile | None = None,
) -> BoundsBasis:
    """The registration's and the fiducials' part of the bounds (`correction_bounds` for the parameters); `profile`
    given, it is used instead of cross-validating the fiducials (the app's live drag update keeps the one from
    before the drag, `session.evaluation._target_bounds`)."""
    rot = np.asarray(mapping.rotation, float)
    fid_sensor, fid_corr = np.asarray(fid_sensor, float).reshape(-1, 3), np.asarray(fid_corr, float).reshape(-1, 3)
    n_fid = len(fid_sensor)
    fid_registered = np.zeros(n_fid, bool) if fid_registered is None else np.asarray(fid_registered, bool)
    warnings: list[str] = []
    estimate = estimate_noise(data, rot, fid_sensor, fid_corr @ rot.T)
    sensor_var = (
        float(np.mean(np.trace(instrument.sensor_cov(fid_sensor), axis1=1, axis2=2)) / 3)
        if instrument is not None and n_fid
        else 0.0
    )
    inst = complete_instrument(instrument, estimate, sensor_var)
    if estimate is not None and instrument is not None and instrument.name != "estimated" and n_fid:
        if sensor_var > 4 * estimate[0]:
            warnings.append(
                f"the instrument's stated noise ({np.sqrt(sensor_var):.3g} mm per axis at the fiducials) is more than "
                f"twice what the data show ({np.sqrt(estimate[0]):.3g} mm, {estimate[1]}): the bounds are wider than "
                "these data need"
            )
    theta = registration_theta_cov(rot, reg_sensor, own_cov(inst, rot, reg_sensor, reg_count))
    fid_noise = float(np.mean(np.trace(own_cov(inst, rot, fid_sensor, fid_count), axis1=1, axis2=2))) if n_fid else 0.0
    c_robot = fid_corr @ rot.T
    v_rigid, shape_rigid, tail_rigid = _rigid_error(c_robot, fid_registered, reg_residuals, len(reg_sensor), fid_noise)
    if v_rigid is None:
        v_rigid = 0.0
        warnings.append("no fiducials and too few registration points: rigid's bound holds the noise only")

    given, profile, fw = profile, None, None
    if interpolating:
        if n_fid < MIN_FIDUCIALS:
            warnings.append(
                f"no RRBC bound: {n_fid} fiducials are too few to cross-validate the correction "
                f"(at least {MIN_FIDUCIALS})"
            )
        else:
            # registration points' corrections are the fit's residuals, smaller than an unseen point's error (the
            # registration was fitted to them; no check or target is one): where enough fiducials are not, only
            # theirs make the profile
            free = ~fid_registered
            scored = free if np.count_nonzero(free) >= MIN_FIDUCIALS else None
            profile = given if given is not None else cv_profile(method, fid_sensor, fid_corr, rot, fid_noise, scored)
            if profile is None:
                warnings.append("no RRBC bound: the correction could not be cross-validated over the fiducials")
            else:
                try:  # the weight is 0 for a method whose weights sum to one: no second fit
                    ones = (
                        None
                        if getattr(method, "reproduces_constants", False)
                        else method.fit(fid_sensor, np.ones_like(fid_sensor))
                    )
                    fw = (method.fit(fid_sensor, fid_sensor), ones)
                except InputError:
                    fw = None
    return BoundsBasis(
        inst,
        rot,
        theta,
        fid_sensor,
        interpolating,
        profile,
        fw,
        tested_distance(fid_sensor, None if profile is None else profile.distances),
        field_slope(fid_sensor, c_robot, fid_noise) if n_fid else 0.0,
        v_rigid,
        shape_rigid,
        tail_rigid,
        tuple(warnings),
        Hull(fid_sensor) if profile is not None else None,
    )


#: points bounded in one pass (`bound_points`): 100 000 points' covariances are a few MB per array
POINTS_PER_PASS = 100_000


def _joined(parts: list[PointBounds]) -> PointBounds:
    if len(parts) == 1:
        return parts[0]
    names = list(parts[0].budget_mm)
    return PointBounds(
        np.concatenate([b.bound95_mm for b in parts]),
        np.concatenate([b.cov_mm2 for b in parts]),
        {n: np.concatenate([b.budget_mm[n] for b in parts]) for n in names},
    )


def _bound_pass(basis: BoundsBasis, p, count, d, v_off, beyond, project: bool) -> tuple[PointBounds, PointBounds]:
    """Rigid's and RRBC's bounds of points p (M, 3) sensor frame (`bound_points`): their row counts, distances d
    from the nearest fiducial, off-plane variances v_off, whether each is beyond what the folds tested, and
    whether points are projected onto the fiducials' plane for the hull test."""
    inst, rot, theta, fid_sensor, profile, fw = (
        basis.instrument,
        basis.rotation,
        basis.theta,
        basis.fid_sensor,
        basis.profile,
        basis.fitted,
    )
    own = own_cov(inst, rot, p, count)
    rigid_int = (basis.tail_rigid**2 * (basis.v_rigid + v_off))[:, None, None] * basis.shape_rigid
    rigid = assemble_bounds(
        {
            "instrument": own,
            "registration": point_registration_cov(rot, p, np.ones(len(p)), theta),
            "interpolation": rigid_int,
        },
        beyond,
    )
    if not basis.interpolating:
        return rigid, rigid
    if profile is None or len(fid_sensor) == 0:
        return rigid, no_bounds(len(p))
    if fw is not None:
        lever = p - fw[0].values_at(p)
        weight = np.zeros(len(p)) if fw[1] is None else 1.0 - fw[1].values_at(p).mean(axis=1)
    else:  # the transform's error at the point, not cancelled (wider)
        lever, weight = p, np.ones(len(p))
    reg = point_registration_cov(rot, lever, weight, theta)
    q = _onto_plane(fid_sensor, p) if project else p
    inside = ~basis.hull.flags(q)[0] if basis.hull is not None else covered(fid_sensor, q)  # `covered`'s test
    interp = (profile.variance(d, inside) + profile.tail**2 * v_off)[:, None, None] * profile.shape
    return rigid, assemble_bounds({"instrument": own, "registration": reg, "interpolation": interp}, beyond)


def bound_points(basis: BoundsBasis, points: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]) -> Bounds:
    """The bounds of `points` {"targets": (sensor (M, 3), count (M,), off_plane_mm (M,)), "checks": ...} from a
    basis (`bounds_basis`)."""
    inst, fid_sensor, profile = basis.instrument, basis.fid_sensor, basis.profile
    interpolating, tested, slope = basis.interpolating, basis.tested_mm, basis.slope
    warnings = list(basis.warnings)
    n_fid = len(fid_sensor)
    tree = cKDTree(fid_sensor) if n_fid else None
    out: dict[str, PointBounds | None] = {}
    for name, (p, count, off_plane) in points.items():
        p = np.asarray(p, float).reshape(-1, 3)
        if len(p) == 0:
            out[name], out[name + "_rigid"] = None, None
            continue
        h = np.asarray(off_plane, float)
        d = tree.query(p)[0] if tree is not None else np.zeros(len(p))
        beyond = (d > tested) | (h > tested) if tested is not None else np.zeros(len(p), bool)
        if np.any(beyond):
            warnings.append(
                f"no bound for {int(beyond.sum())} of {len(p)} {name}: farther from the fiducials or off their plane "
                f"than the {tested:.4g} mm their cross-validation tested (the error there is not in the data)"
            )
        v_off = slope * h**2  # off coplanar (collinear) fiducials: the field's change over the height
        count = np.broadcast_to(np.asarray(count, float), (len(p),))
        project = bool(np.any(h > 0))
        rigids, rrbcs = [], []
        for k in range(0, len(p), POINTS_PER_PASS):  # a pass's (M, 3, 3) arrays stay in the cache, not gigabytes
            sl = slice(k, k + POINTS_PER_PASS)
            rigid, rrbc = _bound_pass(basis, p[sl], count[sl], d[sl], v_off[sl], beyond[sl], project)
            rigids.append(rigid)
            rrbcs.append(rrbc)
        out[name + "_rigid"] = _joined(rigids)
        out[name] = _joined(rrbcs) if interpolating else out[name + "_rigid"]
    return Bounds(
        inst,
        profile,
        out.get("targets"),
        out.get("checks"),
        out.get("targets_rigid"),
        out.get("checks_rigid"),
        tuple(warnings),
    )
