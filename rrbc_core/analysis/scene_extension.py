"""What `rrbc check-model` adds to a scene: the unexplained effects as error terms (docs/check_model.md).

Every added term acts on the ROBOT side, in the robot frame (= the scene frame), mm. That is no loss: a row's rigid
residual, and a check's error, depend on a robot-side bias β_r and a sensor-side bias β_s only through
β_r − R β_s (models/measurement.py), so a measured effect written robot-side predicts the same residuals
whichever instrument carries it, and its numbers read as `diagnose` reports them:

- `scale` (diagnose's `ppm`: robot ≈ (1 + ppm·1e-6) R sensor + t) -> `scale` with that ppm about the points'
  centroid; `affine` -> `affine` with the whole linear map of position (least squares, beside the drift when drift
  is named too; its symmetric part is diagnose's `matrix` G, which includes any uniform scale) about the centroid,
  and then no separate `scale`: the registration absorbs the map's rotation part only where time does not follow
  position;
- a scale that changes with time (diagnose's `scale` with `ppm_per_s`, about `t0_s`) -> `scale` with `ppm_per_s` and
  `t0_s` (with `ppm` 0 beside an `affine` term, which holds the constant part);
- `drift` (diagnose's `rate_mm_per_s`, the rate of change of the residual) -> `drift` with that rate from the
  file's mean time (a constant offset is the registration's); beside a field, where diagnose gives no rate, the
  rate is the least-squares slope of the remainder on time;
- `smooth_field` -> `sampled_field`: the field's smoothed values (the kriging mean of the fitted field model,
  `diagnosis_field.fit_field`, at up to 500 of the points) with its correlation length; the linear and drift terms
  written beside it are removed first, and the field's own linear part over the points (least squares) is written
  as an `affine` term beside it (the remainder is relative to a registration on a few points: it carries a trend
  that a zero-mean field would bend towards zero away from its points). A field known at points is uncertain, most between them: a
  `field_uncertainty` term beside it draws, every trial, from the fitted field model's posterior (its prior
  variances and noise), so that a prediction holds what the estimate does not know;
- `isotropic_noise` -> `isotropic_noise` with the missing sigma;
- `outliers` -> `outliers` with the share of points flagged and their RMS distance.

Last, the spread (`with_spread`): the extended model is simulated at the file's rows, and when the rows still scatter
about its predicted means by more than its predicted covariances allow (Σ zᵢ² against χ²(3n) at alpha), an
`isotropic_noise` term carries the missing variance s² (the root of mean dᵢᵀ(Cᵢ + s²I)⁻¹dᵢ = 3), added in quadrature
to one already written. On real stationings the named terms explain the trend but not each station's own offset and
scatter, and without this a prediction's 95 % regions were too narrow for stations it had not seen.

Beside them, what the fits do not know: each least-squares fit of a linear map and / or a drift ->
`linear_uncertainty`, its coefficients' covariance (residual variance per axis times (ΦᵀΦ)⁻¹), drawn every trial, so
that a prediction holds the fit's own error (large where time follows position and the two are confounded). What the
written terms leave is not written: a field through it was tried and made a lift arm's prediction of other files
low (a field through a few registration rows takes their noise as systematic).

Not written (listed with the reason): `kinematic` and `compliance` (their parameters are identified by
`rrbc calibrate`, not by diagnose) and `anisotropic_noise` (diagnose's axis is not a line of sight).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.analysis.diagnosis import Effect
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.armterms import ArmErrors
from rrbc_core.models.errormodels import ErrorTerm, PointSet
from rrbc_core.models.errorterms import error_model_from_dict

__all__ = ["AddedTerm", "extension_terms", "spread_effect", "with_spread"]

_FITTED = {"position": "linear map", "time": "drift", "position_time": "linear map and drift"}


@dataclass(frozen=True, eq=False)
class AddedTerm:
    """One added robot-side term: the effect it stands for, its TOML table, a one-line comment and the term."""

    effect: str
    table: dict
    comment: str
    term: ErrorTerm


def _rate(time: np.ndarray, resid: np.ndarray) -> np.ndarray:
    t = time - np.mean(time)
    den = float(np.sum(t**2))
    return np.zeros(3) if den <= 0 else (t @ (resid - resid.mean(axis=0))) / den


def _design(pts: np.ndarray | None, centre, time: np.ndarray | None, t0: float) -> np.ndarray:
    """The least-squares design [1, x − centre, t − t0] (N, k): position columns without `pts` None, the time column
    without `time` None (`fieldterms.LinearUncertainty`'s columns)."""
    n = len(pts) if pts is not None else len(time)  # type: ignore[arg-type]
    cols = [np.ones((n, 1))]
    if pts is not None:
        cols.append(pts - np.asarray(centre, float))
    if time is not None:
        cols.append((time - t0)[:, None])
    return np.hstack(cols)


def _fit(design: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least squares of `values` (N, 3) on `design` (N, k): (the coefficients (k, 3), their covariance per unit noise
    variance (ΦᵀΦ)⁻¹ (k, k))."""
    coef, *_ = np.linalg.lstsq(design, values, rcond=None)
    inv = np.linalg.pinv(design.T @ design)
    return coef, 0.5 * (inv + inv.T)


def _uncertainty_table(basis: str, design: np.ndarray, left: np.ndarray, cov: np.ndarray, centre, t0: float) -> dict:
    """The `linear_uncertainty` table of a least-squares fit with `design` (N, k) whose residual is `left` (N, 3)
    and whose coefficients' covariance per unit noise variance is `cov` (k, k): var_a the residual variance per axis
    on N − k degrees of freedom."""
    n, k = design.shape
    var = np.sum(left**2, axis=0) / max(n - k, 1)
    return {
        "type": "linear_uncertainty",
        "basis": basis,
        "center_mm": centre,
        "t0_s": t0,
        "design_inverse": cov.tolist(),
        "var_mm2": [float(v) for v in var],
    }


def _field_table(points: np.ndarray, resid: np.ndarray) -> tuple[dict, float, dict]:
    """The `sampled_field` table (the field's posterior mean at the points), its RMS (mm) and the
    `field_uncertainty` table (its posterior covariance: the fitted prior variances and noise)."""
    from rrbc_core.analysis.diagnosis_field import fit_field

    fm = fit_field(points, resid - resid.mean(axis=0))
    smooth = np.empty((len(fm.index), 3))
    for a in range(3):
        shrink = fm.lam[a] * fm.d / (fm.lam[a] * fm.d + 1.0)
        smooth[:, a] = fm.u @ (shrink * fm.z[:, a])
    table = {
        "type": "sampled_field",
        "points_mm": np.round(fm.points, 4).tolist(),
        "vectors_mm": np.round(smooth, 6).tolist(),
        "length_mm": round(float(fm.length_mm), 4),
    }
    unknown = {
        "type": "field_uncertainty",
        "points_mm": table["points_mm"],
        "length_mm": table["length_mm"],
        "field_var_mm2": [float(v) for v in fm.lam * fm.sigma2],
        "noise_var_mm2": float(fm.sigma2),
    }
    return table, float(np.sqrt(np.mean(np.sum(smooth**2, axis=1)))), unknown


def _arm_table(by: dict, resid: np.ndarray, arm) -> tuple[dict, str]:
    """The `arm_errors` table for a named kinematic / compliance effect: `rrbc calibrate`'s identification
    (`calibration.calibrate`) of the arm's parameters and the named load terms from the remainder, as the pseudo
    sensor readings FK(q) − remainder (robot frame) against the nominal arm at the rows' joints."""
    from rrbc_core.analysis.calibration import calibrate
    from rrbc_core.models.armterms import arm_chain
    from rrbc_core.models.loads import named_terms

    spec, q = arm
    chain = arm_chain(**spec)
    names = list(by["compliance"].parameters.get("terms", [])) if "compliance" in by else []
    terms = named_terms(chain, names) if names else ()
    cal = calibrate(chain, q, chain.forward(q) - resid, terms=terms)
    params = {n: float(v) for n, v in zip(chain.param_names, cal.delta) if np.isfinite(v) and abs(v) > 1e-12}
    loads = {t.name: float(c) for t, c in zip(cal.terms, cal.coef) if np.isfinite(c)}
    table: dict = {"type": "arm_errors", "parameters": params}
    if loads:
        table["loads"] = loads
    what = " and ".join(n for n in ("kinematic", "compliance") if n in by)
    return (
        table,
        f"rrbc calibrate's identification of the arm's {what} error from what the model leaves ({cal.rank} combinations)",
    )


def extension_terms(effects: list[Effect], remainder: MeasurementSet, arm=None) -> tuple[list[AddedTerm], list[str]]:
    """The added terms for `effects` (module docstring), fitted on `remainder` (`scene_check`: sensor = each row's
    mapped reading in the robot frame, robot = that plus what the model leaves unexplained). `arm`: (the arm's
    spec for `armterms.arm_chain`, the rows' joint values (N, I)) when the file has the scene's arm's joints: a
    named kinematic or compliance effect is then written as an `arm_errors` term.

    Returns
    -------
    (list of AddedTerm, list of str)
        The terms in the order written, and one sentence per effect not written.
    """
    by = {e.name: e for e in effects}
    pts = np.asarray(remainder.sensor, float)
    resid = np.asarray(remainder.robot, float) - pts
    centre = np.round(pts.mean(axis=0), 3).tolist()
    time = np.asarray(remainder.time, float)
    t0 = round(float(np.mean(time)), 3) if np.all(np.isfinite(time)) else 0.0
    tables: list[tuple[str, dict, str]] = []
    fitted: list[tuple] = []  # (basis, design, residual, coefficients' covariance) of the linear fits written
    explained = np.zeros_like(resid)
    if arm is not None and ("kinematic" in by or "compliance" in by):  # first: diagnose judged the rest beside it
        table, how = _arm_table(by, resid, arm)
        tables.append(("kinematic" if "kinematic" in by else "compliance", table, how))
        arm_term = ArmErrors(**{k: v for k, v in table.items() if k != "type"}).on_arm(**arm[0])
        explained += arm_term.displacement(PointSet(pts, pts, np.zeros(len(pts)), joints=arm[1]))
    joint_rate = None
    if "affine" in by:
        # the whole linear map (its rotation part too) and, beside it, the drift, by one least-squares fit: diagnose's
        # symmetric G leaves its rotation to the registration, which cannot take it where time follows position
        with_time = "drift" in by and np.all(np.isfinite(time))
        design = _design(pts, centre, time if with_time else None, t0)
        coef, ccov = _fit(design, resid)
        g, joint_rate = coef[1:4].T, (coef[4] if with_time else None)
        fitted.append(("position_time" if with_time else "position", design, resid - design @ coef, ccov))
        tables.append(
            (
                "affine",
                {"type": "affine", "matrix": np.round(g, 12).tolist(), "center_mm": centre},
                "the linear map of position (least squares"
                + (", beside the drift" if joint_rate is not None else "")
                + "; its symmetric part is diagnose's affine matrix)",
            )
        )
        explained += (pts - np.asarray(centre)) @ g.T
    elif "scale" in by:
        ppm = float(by["scale"].parameters["ppm"])
        table = {"type": "scale", "ppm": ppm, "center_mm": centre}
        tables.append(("scale", table, "diagnose's uniform scale"))
        explained += ppm * 1e-6 * (pts - pts.mean(axis=0))
    if "scale" in by and "ppm_per_s" in by["scale"].parameters and np.all(np.isfinite(time)):
        ppm_s, t_ref = float(by["scale"].parameters["ppm_per_s"]), float(by["scale"].parameters["t0_s"])
        if "affine" in by or not tables or tables[-1][0] != "scale":  # the constant part is the affine's
            tables.append(("scale", {"type": "scale", "ppm": 0.0, "center_mm": centre}, "diagnose's scale rate"))
        tables[-1][1].update({"ppm_per_s": ppm_s, "t0_s": round(t_ref, 3)})
        explained += (ppm_s * 1e-6 * (time - t_ref))[:, None] * (pts - pts.mean(axis=0))
    if "drift" in by and np.all(np.isfinite(time)):
        rate = by["drift"].parameters.get("rate_mm_per_s") or []
        how = "diagnose's drift rate"
        if joint_rate is not None:
            rate, how = joint_rate.tolist(), "the drift beside the linear map, fitted with it"
        elif len(rate) != 3:
            rate, how = _rate(time, resid - explained).tolist(), "the remainder's slope on time (beside the field)"
        if joint_rate is None:
            design = _design(None, centre, time, t0)
            coef, ccov = _fit(design, resid - explained)
            fitted.append(("time", design, resid - explained - design @ coef, ccov))
        tables.append(("drift", {"type": "drift", "rate_mm_per_s": [float(v) for v in rate], "t0_s": t0}, how))
        explained += np.outer(time - t0, rate)
    if "smooth_field" in by:
        rest = resid - explained
        x = np.column_stack([np.ones(len(pts)), pts - pts.mean(axis=0)])
        coef, *_ = np.linalg.lstsq(x, rest, rcond=None)  # (4, 3): the field's offset and linear part
        lin = coef[1:].T  # displacement = lin @ (x − centre)
        if "affine" not in by:  # (an affine term written above already holds the whole linear part)
            tables.append(
                (
                    "smooth_field",
                    {"type": "affine", "matrix": np.round(lin, 9).tolist(), "center_mm": centre},
                    "the field's linear part over these points (a zero-mean field cannot carry a trend)",
                )
            )
        table, rms, unknown = _field_table(pts, rest - x @ coef)
        tables.append(("smooth_field", table, f"the measured field smoothed at its points ({rms:.3g} mm RMS)"))
        tables.append(
            (
                "smooth_field",
                unknown,
                "what the smoothed field does not know (its posterior covariance: small near its points, the "
                "prior's far from them)",
            )
        )
    if "outliers" in by:
        ids = set(by["outliers"].parameters.get("ids", []))
        is_out = np.array([i in ids for i in remainder.ids])
        n_ids = len(set(remainder.ids))
        size = float(np.sqrt(np.mean(np.sum(resid[is_out] ** 2, axis=1)))) if is_out.any() else 0.0
        tables.append(
            (
                "outliers",
                {"type": "outliers", "fraction": round(len(ids) / max(n_ids, 1), 6), "size_mm": round(size, 6)},
                f"{len(ids)} of {n_ids} points flagged, their RMS distance",
            )
        )
    for basis, design, left, ccov in fitted:
        tables.append(
            (
                "drift" if basis == "time" else "affine",
                _uncertainty_table(basis, design, left, ccov, centre, t0),
                f"what the least-squares fit of the {_FITTED[basis]} above does not know (its coefficients' "
                "covariance)",
            )
        )
    if "isotropic_noise" in by:
        sigma = float(by["isotropic_noise"].parameters["sigma_mm"])
        tables.append(("isotropic_noise", {"type": "isotropic_noise", "sigma_mm": sigma}, "the noise the model lacks"))
    not_written = []
    for name, why in (
        ("kinematic", "the file has no joint columns of the scene's arm; `rrbc calibrate` identifies it"),
        ("compliance", "the file has no joint columns of the scene's arm; `rrbc calibrate --compliance` does"),
        ("anisotropic_noise", "diagnose's noise axis is not a line of sight; add an anisotropic_noise term by hand"),
    ):
        if name in by and (arm is None or name == "anisotropic_noise"):
            not_written.append(f"{name}: not written ({why})")
    added = []
    for effect, table, how in tables:
        term = error_model_from_dict({"robot": [table]}, f"check-model's {effect} term").robot[0]
        if isinstance(term, ArmErrors) and arm is not None:
            term = term.on_arm(**arm[0])
        added.append(AddedTerm(effect, table, f"added by rrbc check-model for '{effect}': {how}", term))
    return added, not_written


def spread_effect(misfit: np.ndarray, cov: np.ndarray, alpha: float) -> Effect | None:
    """`isotropic_noise` when rows scatter about an extended model's predicted means by more than it predicts.

    Parameters
    ----------
    misfit : (N, 3) array
        Measured rigid residual less the extended model's predicted mean residual per row, robot frame, mm.
    cov : (N, 3, 3) array
        The extended model's predicted covariance of each row's residual, mm².
    alpha : float
        False-alarm rate of the χ²(3N) test of Σ dᵢᵀCᵢ⁻¹dᵢ.

    Returns
    -------
    Effect or None
        `isotropic_noise` with `sigma_mm` = s, the root of mean dᵢᵀ(Cᵢ + s²I)⁻¹dᵢ = 3 (the per-axis noise that makes
        the rows' mean squared Mahalanobis distance its expected 3); None when the test does not reject.
    """
    from scipy import stats

    d = np.asarray(misfit, float)
    ok = np.all(np.isfinite(d), axis=1)
    d, c = d[ok], np.asarray(cov, float)[ok]
    if len(d) < 2:
        return None
    lam, vec = np.linalg.eigh(c)
    lam = np.maximum(lam, 1e-12)
    proj2 = np.einsum("nik,ni->nk", vec, d) ** 2  # (V^T d)^2 per row

    def mean_z2(s2: float) -> float:
        return float(np.mean(np.sum(proj2 / (lam + s2), axis=1)))

    z2 = mean_z2(0.0)
    nu = 3 * len(d)
    p = float(stats.chi2.sf(z2 * len(d), nu))
    if p >= alpha:
        return None
    lo, hi = 0.0, float(np.mean(np.sum(d**2, axis=1))) / 3.0  # at hi every row's z² <= |d|²/hi: the mean <= 3
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mean_z2(mid) > 3.0 else (lo, mid)
    sigma = float(np.sqrt(hi))
    return Effect(
        "isotropic_noise",
        {"sigma_mm": sigma},
        p,
        f"the rows scatter about the extended model's predictions by more than it predicts (mean z² {z2:.3g} "
        f"against 3, χ²({nu}) p {p:.2g}); sigma_mm is the per-axis noise that brings the mean z² to 3.",
        magnitude_mm=sigma * np.sqrt(3.0),
    )


def with_spread(added: list[AddedTerm], effect: Effect) -> list[AddedTerm]:
    """`added` with `effect`'s missing noise as an `isotropic_noise` term (in quadrature with one already there)."""
    sigma = float(effect.parameters["sigma_mm"])
    kept = [a for a in added if a.table.get("type") != "isotropic_noise"]
    before = [float(a.table["sigma_mm"]) for a in added if a.table.get("type") == "isotropic_noise"]
    total = float(np.sqrt(sigma**2 + sum(b**2 for b in before)))
    table = {"type": "isotropic_noise", "sigma_mm": round(total, 6)}
    how = "the rows' scatter about the extended model's predictions beyond its predicted spread" + (
        " (in quadrature with the noise diagnose found)" if before else ""
    )
    term = error_model_from_dict({"robot": [table]}, "check-model's isotropic_noise term").robot[0]
    return [*kept, AddedTerm("isotropic_noise", table, f"added by rrbc check-model for 'isotropic_noise': {how}", term)]
