"""Find what is hidden in measured point pairs (`rrbc diagnose`; contract: docs/cli.md, docs/theory.md §6).

Starting from a rigid sensor→robot fit plus isotropic noise, the diagnosis tests, in this order:
outliers (generalised ESD on deleted studentised residuals of a rigid+affine(+drift)(+arm) model), uniform scale
(similarity vs rigid), affine beyond scale (full linear map vs similarity; only the identifiable terms), drift
(residuals vs time), with joint angles in the file the arm's kinematic error (its DH Jacobian's columns beyond the
accepted terms, `diagnosis_arm`), smooth field (Moran's I of the residuals, k-nearest-neighbour weights, parametric
bootstrap) and anisotropic noise (sphericity likelihood ratio of the noise covariance). All model tests are nested
F-tests of the linearised residual model (docs/theory.md §6.1). False alarms are controlled family-wise: each of
the m tests run is judged at alpha/m (Bonferroni).

Systematic effects first, noise last. A kinematic error has a scale and linear part: once the arm is accepted,
scale and affine are judged again beside it. Once a smooth field is found it becomes part of the error model
(`diagnosis_field`): the low-order terms are judged again by generalised least squares with the field's
covariance (a field's own linear part is not a separate effect), the points flagged as outliers are kept only if
the field does not predict them from their neighbours, and the noise (its size and its anisotropy) is judged on
what the field leaves. With repeated measurements the noise comes from the repeats less what drift and the arm
predict for each row.

Conventions: residual r_i = robot_i − (R sensor_i + t), robot frame, mm. `scale.ppm` is the scale of the
sensor→robot map minus one (robot ≈ (1 + ppm·1e-6)·R·sensor + t); `affine.matrix` G is the symmetric (non-rigid)
linear part in the robot frame: robot ≈ R sensor + t + G (x − x̄); `drift.rate_mm_per_s` is the rate of change of
the residual (robot frame); `anisotropic_noise.axis` is in the sensor frame; `noise_sigma_mm` is per robot axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats
from scipy.spatial import cKDTree

from rrbc_core.analysis.diagnosis_arm import MIN_POINTS as ARM_MIN_POINTS
from rrbc_core.analysis.diagnosis_arm import arm_columns
from rrbc_core.analysis.diagnosis_field import fit_field, gls_whiten, krige_outliers, noise_beside_field
from rrbc_core.analysis.diagnosis_stats import (
    _BOOTSTRAP,
    _BOOTSTRAP_EXACT_POINTS,
    _BOOTSTRAP_LARGE,
    _DRIFT_KEPT,
    _fit,
    _ftest,
    _Geometry,
    _moran,
    _moran_bootstrap,
    _moran_weights,
    _noise_cov,
    _orth,
    _outliers,
    _paired,
    _sphericity,
    _usable,
    _usable_drift,
    _whitener,
)
from rrbc_core.analysis.diagnosis_verdict import rrbc_verdict
from rrbc_core.correction.check_statistics import CheckStatistics
from rrbc_core.errors import InputError
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.registration.strategies import least_squares
from rrbc_core.runtime.threads import thread_limited

__all__ = ["Effect", "Diagnosis", "diagnose"]

_SMALL_N = 40  # below this many paired points the smooth-field test's reach is stated as a limit (power study)


@dataclass(frozen=True)
class Effect:
    name: str
    parameters: dict
    p_value: float
    evidence: str
    magnitude_mm: float = 0.0  # RMS of the effect's contribution at the points; orders the list

    def to_json(self) -> dict:
        return {
            "name": self.name,
            "parameters": self.parameters,
            "p_value": float(self.p_value),
            "evidence": self.evidence,
        }


@dataclass(frozen=True)
class Diagnosis:
    """The verdict of `diagnose`: ``effects`` (`Effect`: name, parameters, p-value, evidence), largest first;
    ``noise_sigma_mm`` per robot axis and where it came from (``noise_source``: repeats or fit); ``bias_rms_mm``;
    RRBC's verdict on the file as given (``rrbc_recommended``, ``expected_rmst_change``, the two RMS values and
    their ``basis`` — the file's check rows scored as `rrbc correct` scores them, else leave-one-out — and with
    outliers ``expected_change_without_outliers``; ``assumes`` says what it is); the
    p-value of every test run (``tests``) and what these data cannot show (``limits``). `to_json()` is the JSON of
    `rrbc diagnose --json`.
    """

    effects: tuple[Effect, ...]
    noise_sigma_mm: tuple[float, float, float]
    noise_source: str  # "repeats" or "fit"
    bias_rms_mm: float
    rrbc_recommended: bool
    expected_rmst_change: float
    loo_rms_rigid_mm: float
    loo_rms_rrbc_mm: float
    n_points: int
    alpha: float
    tests: dict = field(default_factory=dict)  # test name -> p-value (all tests run)
    limits: tuple[str, ...] = ()
    expected_change_without_outliers: float | None = None
    basis: str = "leave-one-out"  # or "checks": rrbc correct's own figure on the file's check rows
    checks_rms_mm: tuple[float, float] | None = None  # rrbc correct's check RMST (rigid, RRBC), None without checks
    check_statistics: CheckStatistics | None = None  # rrbc correct's before/after statistics of the checks

    @property
    def assumes(self) -> str:
        """What `expected_rmst_change` is: `rrbc correct`'s own figure on the file's check rows, or a prediction."""
        if self.basis == "checks":
            text = (
                "rrbc correct on this file as given: its check rows scored by the same pipeline (registration rows, "
                "fiducial rows, IDW k = 4, p = 2) against the robot values the file gives them, whether those are "
                "noisy readings or noise-free truth; not a prediction for other points"
            )
            if self.expected_change_without_outliers is not None:
                text += (
                    "; expected_rmst_change_without_outliers is the same with the outliers' rows removed from the file"
                )
            return text
        text = (
            "no check rows, so a prediction of rrbc correct on this file as given: each paired point left out in turn and predicted by a rigid fit and "
            "RRBC (IDW k = 4, p = 2) from all the others (as on a file whose rows are all `both`), scored at the "
            "inliers with their own readings as the truth; for points measured like these; against noise-free truth "
            "RRBC does worse than this (the readings' own noise dilutes the difference)"
        )
        if self.expected_change_without_outliers is not None:
            text += (
                "; the outliers stay in the fits but are not scored; "
                "expected_rmst_change_without_outliers is the same with them removed from the file"
            )
        return text

    @property
    def names(self) -> list[str]:
        return [e.name for e in self.effects]

    def to_json(self) -> dict:
        return {
            "effects": [e.to_json() for e in self.effects],
            "noise_sigma_mm": [float(v) for v in self.noise_sigma_mm],
            "noise_source": self.noise_source,
            "bias_rms_mm": float(self.bias_rms_mm),
            "rrbc": {
                "recommended": bool(self.rrbc_recommended),
                "expected_rmst_change": float(self.expected_rmst_change),
                "basis": self.basis,
                "loo_rms_rigid_mm": float(self.loo_rms_rigid_mm),
                "loo_rms_rrbc_mm": float(self.loo_rms_rrbc_mm),
                "checks_rms_rigid_mm": None if self.checks_rms_mm is None else float(self.checks_rms_mm[0]),
                "checks_rms_rrbc_mm": None if self.checks_rms_mm is None else float(self.checks_rms_mm[1]),
                "expected_rmst_change_without_outliers": (
                    None
                    if self.expected_change_without_outliers is None
                    else float(self.expected_change_without_outliers)
                ),
                "assumes": self.assumes,
            },
            "n_points": int(self.n_points),
            "alpha": float(self.alpha),
            "tests": {k: float(v) for k, v in self.tests.items()},
            "limits": list(self.limits),
            "check_statistics": None if self.check_statistics is None else self.check_statistics.to_json(),
        }


# --------------------------------------------------------------------------------------------- diagnose
def _fmt_p(p: float) -> str:
    return f"{p:.2g}"


@dataclass
class _Pass:
    """One pass of the systematic tests over a set of inliers."""

    inl: np.ndarray
    reg: object
    p: np.ndarray  # (n, 3) mapped inliers, robot frame
    resid: np.ndarray  # (n, 3) rigid residuals, mm
    effects: dict  # name -> Effect
    tests: dict
    limits: list
    rate: np.ndarray  # drift mm/s (zeros when not accepted)
    t_mean: float
    delta: np.ndarray | None  # the arm's scaled parameter errors when kinematic is accepted
    field: object = None  # diagnosis_field.FieldModel once a smooth field is found
    moran: tuple = ()  # (I, bootstrap mean, k)
    rejudged: tuple = ()  # names dropped beside the field or the arm, with their p-values


def _mm_cols(g: _Geometry, cols: np.ndarray) -> np.ndarray:
    """Undo the weighting and whitening of point-major columns (3n, k): the fields in mm, robot frame."""
    inv = np.linalg.inv(g.white)
    c = cols / g.sw[:, None]
    return np.einsum("ab,nbk->nak", inv, c.reshape(g.n, 3, -1)).reshape(3 * g.n, -1)


def _systematic(d, inl, white, use_time, arm, a_each, rng) -> _Pass:
    s, r, w = d.sensor[inl], d.robot[inl], d.count[inl]
    n = len(inl)
    reg = least_squares(s, r, weights=w)
    p = reg.mapping.apply(s)
    resid = r - p
    g = _Geometry(p, d.time[inl] if use_time else None, w, white)
    y = g.vec(resid)
    tests: dict[str, float] = {}
    found: dict[str, Effect] = {}
    limits: list[str] = []
    blocks = {"rigid": g.rigid()}
    x_rigid = blocks["rigid"]
    if g.planar:
        limits.append(
            "the paired points are coplanar (normal " + ", ".join(f"{v:.3f}" for v in g.normal) + "): only the 3 "
            "in-plane affine terms (two in-plane scales, in-plane shear) are testable; out-of-plane scale, shear and "
            "errors that depend on the distance from the plane are invisible to these points"
        )
    # scale: similarity vs rigid; affine beyond scale
    x_scale = np.hstack([x_rigid, g.scale_col()])
    p_sc, _, nu_sc, f_sc, rss0, rss_sc, _ = _ftest(y, x_rigid, x_scale)
    tests["scale"] = p_sc
    x_aff = np.hstack([x_rigid, g.linear()])
    p_af, q_af, nu_af, f_af, _, rss_af, _ = _ftest(y, x_scale, x_aff)
    tests["affine"] = p_af
    del x_scale, x_aff  # (3n, k) each: a million points hold 24 MB a column
    wsum = float(np.sum(w))
    if p_af < a_each:
        found["affine"] = _affine_effect(p, resid, w, g, rss0, rss_sc, rss_af, q_af, nu_af, f_af, p_af, wsum)
        blocks["affine"] = g.linear()
    elif p_sc < a_each:
        sim = least_squares(s, r, weights=w, with_scale=True)
        ppm = (float(sim.details["scale"]) - 1.0) * 1e6
        se = np.sqrt(rss_sc / max(nu_sc, 1) / float(np.sum(g.scale_col() ** 2))) / g.scale * 1e6
        found["scale"] = Effect(
            "scale",
            {"ppm": ppm, "ppm_standard_error": float(se)},
            p_sc,
            f"a uniform scale of {ppm:+.4g} ± {se:.2g} ppm between the frames reduces the residual "
            f"sum of squares from {rss0:.3g} to {rss_sc:.3g} (F(1, {nu_sc}) = {f_sc:.3g}, "
            f"p {_fmt_p(p_sc)}); no significant non-uniform part (p {_fmt_p(p_af)}).",
            magnitude_mm=float(np.sqrt(max(0.0, rss0 - rss_sc) / wsum)),
        )
        blocks["scale"] = g.scale_col()
    x_of = lambda names: np.hstack([blocks[k] for k in names])  # noqa: E731
    # drift
    rate, t_mean = np.zeros(3), float(np.mean(d.time[inl])) if use_time else 0.0
    if use_time:
        x_acc = x_of(blocks)
        dcol_ok, surviving = _usable_drift(x_acc, g.drift())  # fraction of drift energy kept per direction
        p_dr, q_dr, nu_dr, f_dr, rss_a, rss_d, _ = _ftest(y, x_acc, np.hstack([x_acc, dcol_ok]))
        tests["drift"] = p_dr
        lost = int(np.sum(surviving < _DRIFT_KEPT))
        if lost:
            limits.append(
                f"with this measurement order, drift along {lost} of 3 directions is (almost) absorbed by "
                f"the fitted transform (least fraction kept {max(surviving.min(), 0):.2g}) and cannot be "
                "detected; randomise the order"
            )
        if p_dr < a_each:
            # the rate from the full drift columns (the absorbed directions are poorly determined: see the limit)
            rate = _fit(y, np.hstack([x_acc, g.drift()]))[0][-3:] / g.tscale  # coefficients are in mm
            found["drift"] = Effect(
                "drift",
                {"rate_mm_per_s": rate.tolist()},
                p_dr,
                f"the residuals change linearly with measurement time at {np.linalg.norm(rate):.3g} mm/s "
                f"(F({q_dr}, {nu_dr}) = {f_dr:.3g}, p {_fmt_p(p_dr)}).",
                magnitude_mm=float(np.sqrt(max(0.0, rss_a - rss_d) / wsum)),
            )
            blocks["drift"] = dcol_ok
    # the arm (joint angles in the file)
    delta = None
    rejudged = []
    if arm is not None:
        x_acc = x_of(blocks)
        # the arm's directions beside rigid (+ drift) — kfull = (its columns) @ k_map — and, for the test, beside
        # everything accepted
        base = np.hstack([blocks[k] for k in ("rigid", "drift") if k in blocks])
        # (the arm's columns come from joint angles, not from measured positions: only directions inside the base
        # up to the noise of its rotation columns are left out, 1e-4 of their energy, 1 % of their length)
        kfull, _, k_map = _usable(base, g._cols(arm.fields[:, inl]), kept=1e-4)
        ktest = _usable(x_acc, kfull)[0]
        p_k, q_k, nu_k, f_k, rss_a, rss_k, _ = _ftest(y, x_acc, np.hstack([x_acc, ktest]))
        tests["kinematic"] = p_k
        if p_k < a_each:
            # a smooth field of position alone could explain what the arm's columns fit: judge the arm beside it
            q_b = _orth(base)
            fb = fit_field(p, _mm_cols(g, (y - q_b @ (q_b.T @ y))[:, None]).reshape(n, 3))
            xw0 = gls_whiten(fb, _mm_cols(g, x_acc))
            xw1 = np.hstack([xw0, gls_whiten(fb, _mm_cols(g, ktest))])
            p_kf = _ftest(gls_whiten(fb, _mm_cols(g, y[:, None])[:, 0]), xw0, xw1)[0]
            tests["kinematic_beside_field"] = p_kf
        if p_k < a_each and p_kf >= a_each:
            # the arm explains no more than a field of position does (with one tool orientation per place the arm's
            # error is a function of position; and the arm's smooth columns can follow a sensor field): the data
            # cannot tell them apart, and the position effect is the one named
            limits.append(
                f"the arm's kinematic error would explain these residuals (p {_fmt_p(p_k)}) but no better than a "
                f"smooth field of position (p {_fmt_p(p_kf)} for the arm beside it): reach places in more than one "
                "configuration (another tool orientation) to tell them apart; `rrbc calibrate` compares VEC and RRBC "
                "out of sample"
            )
        if p_k < a_each and p_kf < a_each:
            blocks["kinematic"] = kfull
            rejudged += _rejudge(y, blocks, found, a_each, "the arm", tests)
            delta = k_map @ _fit(y, x_of(blocks))[0][-kfull.shape[1] :]
            rms_k = float(np.sqrt(np.mean(np.sum(np.einsum("knc,k->nc", arm.fields[:, inl], delta) ** 2, axis=1))))
            found["kinematic"] = Effect(
                "kinematic",
                {"robot": arm.robot, "tool_mm": arm.tool_mm, "combinations": int(q_k), "rms_mm": rms_k},
                p_k,
                f"the residuals follow the arm's joint configuration: {q_k} combinations of its kinematic (DH) "
                f"parameters, identifiable at these poses beside the accepted terms, reduce the residual sum of "
                f"squares from {rss_a:.3g} to {rss_k:.3g} (F({q_k}, {nu_k}) = {f_k:.3g}, p {_fmt_p(p_k)}), and "
                f"more than a smooth field of position alone explains (p {_fmt_p(p_kf)}); `rrbc calibrate` "
                "identifies them and compares model-based correction with RRBC.",
                magnitude_mm=rms_k,
            )
    # smooth field: Moran's I of the residuals after the accepted model, parametric bootstrap under white noise
    x_acc = x_of(blocks)
    qa = _orth(x_acc)
    res_acc = y - qa @ (qa.T @ y)
    nb = _moran_weights(p)
    i_obs = float(_moran(res_acc.reshape(n, 3), nb))
    large = n > _BOOTSTRAP_EXACT_POINTS
    i_boot = _moran_bootstrap(rng, qa, nb, _BOOTSTRAP_LARGE if large else _BOOTSTRAP)
    exceed = int(np.sum(i_boot >= i_obs))
    if large:  # Moran's I of many points is close to normal: its null moments from the bootstrap, the tail from z
        z = (i_obs - i_boot.mean()) / max(float(i_boot.std(ddof=1)), 1e-300)
        p_sm = float(stats.norm.sf(z))
    elif exceed:
        p_sm = (1 + exceed) / (_BOOTSTRAP + 1)
    else:
        z = (i_obs - i_boot.mean()) / max(float(i_boot.std()), 1e-300)
        p_sm = float(min(1.0 / (_BOOTSTRAP + 1), stats.norm.sf(z)))
    tests["smooth_field"] = p_sm
    boot_mean = float(i_boot.mean())
    del qa, res_acc, i_boot, x_acc
    field = None
    if p_sm < a_each:
        # the field's model from the residuals beside everything but scale and affine (a field has a linear part);
        # then, twice: the low-order terms judged again and re-estimated by generalised least squares with the field
        # as part of the error (ordinary least squares lets the field leak into the drift and arm estimates, and
        # their error into the noise), and the field refitted beside them
        q_nl = _orth(np.hstack([v for k, v in blocks.items() if k not in ("scale", "affine")]))
        y_mm = _mm_cols(g, y[:, None])[:, 0]
        res_nl = _mm_cols(g, (y - q_nl @ (q_nl.T @ y))[:, None])[:, 0]
        del q_nl
        mm_blocks = {k: _mm_cols(g, v) for k, v in blocks.items()}
        for _ in range(2):
            field = fit_field(p, res_nl.reshape(n, 3))
            y_w = gls_whiten(field, y_mm)
            wb = {k: gls_whiten(field, v) for k, v in mm_blocks.items()}
            rejudged += _rejudge(y_w, wb, found, a_each, "the field", tests)
            mm_blocks = {k: v for k, v in mm_blocks.items() if k in wb}
            del wb
            cols = {k: (_mm_cols(g, g.drift()) if k == "drift" else v) for k, v in mm_blocks.items()}
            coef = _fit(y_w, np.hstack([gls_whiten(field, c) for c in cols.values()]))[0]
            contrib, pos = np.zeros_like(y_mm), 0
            for k, c in cols.items():
                ck = coef[pos : pos + c.shape[1]]
                pos += c.shape[1]
                if k not in ("scale", "affine"):
                    contrib += c @ ck
                if k == "drift":
                    rate = ck / g.tscale
                if k == "kinematic":
                    delta = k_map @ ck
            res_nl = y_mm - contrib
        for k in [k for k in blocks if k not in mm_blocks]:
            del blocks[k]
        if "drift" in found:
            found["drift"] = replace(found["drift"], parameters={"rate_mm_per_s": rate.tolist()})
    if n < _SMALL_N:
        # Moran's I only sees a field whose correlation reaches the k-th neighbour; with few points that distance
        # approaches the extent, and a longer field is mostly absorbed by the rigid/linear fit (power study,
        # docs/diagnosis_power.md: 12 points found a field of length half the extent in few sets at any size).
        reach = float(np.median(cKDTree(p).query(p, k=nb.shape[1] + 1)[0][:, -1]))
        limits.append(
            f"only {n} paired points: a smooth field with correlation length below about {reach:.0f} mm (the median "
            f"distance to the {nb.shape[1]}th nearest neighbour) cannot be detected reliably; longer fields are largely "
            "absorbed by the fitted transform"
            + ("" if field is not None else "; an empty or low-order verdict does not rule out a smooth field")
            + (
                "; the reported affine/scale term may be the linear part of a smooth field"
                if any(k in ("affine", "scale") for k in found)
                else ""
            )
        )
    if "drift" not in found:
        rate = np.zeros(3)
    if "kinematic" not in found:
        delta = None
    return _Pass(
        inl,
        reg,
        p,
        resid,
        found,
        tests,
        limits,
        rate,
        t_mean,
        delta,
        field,
        (i_obs, boot_mean, nb.shape[1]),
        tuple(rejudged),
    )


def _rejudge(y, blocks: dict, found: dict, a_each: float, beside: str, tests: dict) -> list:
    """Drop accepted low-order terms (scale, affine, drift) that are no longer significant beside a newly accepted
    systematic effect; `blocks` and `found` are updated. Returns [(name, p), ...] of the dropped."""
    dropped = []
    for name in ("scale", "affine", "drift"):
        if name not in blocks:
            continue
        others = np.hstack([v for k, v in blocks.items() if k != name])
        p_b = _ftest(y, others, np.hstack([others, _usable(others, blocks[name])[0]]))[0]
        tests[f"{name}_beside_{beside.split()[-1]}"] = p_b
        if p_b >= a_each:
            del blocks[name]
            found.pop(name, None)
            dropped.append((name, p_b, beside))
    return dropped


def _affine_effect(p, resid, w, g, rss0, rss_sc, rss_af, q_af, nu_af, f_af, p_af, wsum) -> Effect:
    # the linear map in unwhitened coordinates: residual ≈ L (p − p̄)
    ga = _Geometry(p, None, w)
    coef, *_ = np.linalg.lstsq(np.hstack([ga.rigid(), ga.linear()]), ga.vec(resid), rcond=1e-10)
    lin = coef[6:].reshape(3, 3) / ga.scale
    if ga.planar:  # the in-plane part, in-plane coordinates only
        proj = np.eye(3) - np.outer(ga.normal, ga.normal)
        lin = lin @ proj
    gm = 0.5 * (lin + lin.T)
    if ga.planar:
        gm = proj @ gm @ proj
    return Effect(
        "affine",
        {"matrix": gm.tolist()},
        p_af,
        f"a linear map beyond rigid + uniform scale reduces the residual sum of squares from "
        f"{rss_sc:.3g} to {rss_af:.3g} (F({q_af}, {nu_af}) = {f_af:.3g}, p {_fmt_p(p_af)}); the "
        f"matrix is its symmetric part (rotations absorb the rest)"
        + ("; only the in-plane terms are identifiable on these coplanar points" if g.planar else "")
        + ".",
        magnitude_mm=float(np.sqrt(max(0.0, rss0 - rss_af) / wsum)),
    )


def _systematic_at(d, arm, ps: _Pass, idx: np.ndarray) -> np.ndarray:
    """What the accepted drift and arm predict (mm, (len(idx), 3)) at points idx (all points' indexing)."""
    out = np.zeros((len(idx), 3))
    if d.time is not None and np.any(ps.rate):
        out += np.outer(d.time[idx] - ps.t_mean, ps.rate)
    if ps.delta is not None:
        out += np.einsum("knc,k->nc", arm.fields[:, idx], ps.delta)
    return out


def _row_systematic(d, arm, ps: _Pass) -> np.ndarray:
    """The same per paired row (R, 3): drift at the row's time, the arm at the row's joints."""
    out = np.zeros((len(d.row_point), 3))
    if d.time is not None and np.any(ps.rate):
        out += np.outer(d.row_time - ps.t_mean, ps.rate)
    if ps.delta is not None:
        out += arm.row_fields @ ps.delta
    return out


@thread_limited
def diagnose(
    mset: MeasurementSet, alpha: float = 0.01, seed: int = 0, robot: str = "ur5", tool_mm: float = 0.0
) -> Diagnosis:
    """What, beyond a rigid transform plus isotropic noise, is in measured point pairs; and whether RRBC will help.

    Parameters
    ----------
    mset : MeasurementSet
        Rows with both readings (roles registration, fiducial, both, check); repeated ids are repeats. With joint
        columns q1..q6 (degrees) the arm's kinematic error is tested too.
    alpha : float
        Family-wise false-alarm rate over all tests (0 < alpha < 1).
    seed : int
        Seed of the bootstraps.
    robot, tool_mm : str, float
        The arm's nominal model ("ur5" or "ur10") and tool length along the flange axis (mm), used only with
        joint columns.

    Returns
    -------
    Diagnosis
        The effects found (outliers, scale, affine, drift, kinematic, smooth_field, anisotropic_noise) with their
        parameters and p-values, the noise per axis (mm), the bias RMS (mm), the verdict on RRBC and
        the limits of what these data can show; `to_json()` is the JSON of `rrbc diagnose --json`.

    Raises
    ------
    InputError
        Fewer than 5 distinct points with both readings, alpha out of range, bad joint columns or robot name.
    """
    if not (0 < float(alpha) < 1):
        raise InputError(f"alpha must be between 0 and 1, got {alpha!r}")
    d = _paired(mset)
    n_all = len(d.ids)
    arm = arm_columns(mset, d.rows, d.row_point, n_all, robot, tool_mm)
    limits: list[str] = []
    if arm is not None and n_all < ARM_MIN_POINTS:
        limits.append(f"only {n_all} paired points with joint angles: the arm's kinematic error was not tested")
        arm = None
    rng = np.random.default_rng(seed)
    use_time = d.time is not None
    if not use_time:
        limits.append("no usable time column: drift was not tested")
    repeats = bool(np.any(d.count > 1))
    # the family: outliers, scale, affine, [drift], [kinematic], smooth_field, anisotropic_noise, each at alpha/m
    m_tests = 5 + int(use_time) + int(arm is not None)
    a_each = alpha / m_tests
    all_idx = np.arange(n_all)
    extra = arm.fields if arm is not None else None

    white = np.eye(3)
    out_idx, p_out = _outliers(d, use_time, a_each, white, extra)
    cleared: list[str] = []
    for attempt in range(4):
        inl = np.setdiff1d(all_idx, out_idx)
        ps = _systematic(d, inl, white, use_time, arm, a_each, rng)
        if ps.field is not None and len(out_idx):
            # a flagged point the field predicts from its neighbours is part of the field, not an outlier
            sysr = ps.resid - _systematic_at(d, arm, ps, inl)
            fmodel = fit_field(ps.p, sysr)
            cand = np.asarray(out_idx, int)
            cres = d.robot[cand] - ps.reg.mapping.apply(d.sensor[cand]) - _systematic_at(d, arm, ps, cand)
            keep = krige_outliers(fmodel, ps.reg.mapping.apply(d.sensor[cand]), cres, n_all, a_each)
            if not keep.all():
                cleared += [d.ids[i] for i in cand[~keep]]
                out_idx = [int(i) for i in cand[keep]]
                continue
        # the noise, judged on what the systematic effects leave
        if repeats:
            cov, nu_pe, noise_source = _noise_cov(d, inl, use_time, None, _row_systematic(d, arm, ps))
            p_an = _sphericity(cov, nu_pe) if nu_pe >= 3 else 1.0
        elif ps.field is not None:
            cov, nu_pe, p_an = noise_beside_field(ps.field, rng)
            noise_source = "fit"
        else:
            cov, nu_pe, noise_source = _noise_cov(d, inl, use_time, extra)
            p_an = _sphericity(cov, nu_pe) if nu_pe >= 3 else 1.0
        if p_an < a_each and np.allclose(white, np.eye(3)) and attempt < 3:
            white = _whitener(cov)  # the other tests on noise-whitened residuals
            out_idx, p_out = _outliers(d, use_time, a_each, white, extra)
            continue
        break
    effects = dict(ps.effects)
    tests = {"outliers": p_out, **ps.tests}
    limits += ps.limits
    inl, reg, resid, n = ps.inl, ps.reg, ps.resid, len(ps.inl)
    w = d.count[inl]
    if out_idx:
        ids = [d.ids[i] for i in out_idx]
        full_reg = least_squares(d.sensor, d.robot, weights=d.count)
        big = np.linalg.norm(d.robot[out_idx] - reg.mapping.apply(d.sensor[out_idx]), axis=1)
        effects["outliers"] = Effect(
            "outliers",
            {"ids": ids},
            p_out,
            f"{len(ids)} point(s) deviate from a rigid+linear fit of the others by "
            f"{', '.join(f'{b:.3g}' for b in big)} mm (deleted studentised residual, generalised "
            f"ESD, Bonferroni-adjusted p {_fmt_p(p_out)} < {a_each:.2g}); they were removed "
            f"before the other tests (FRE with them {full_reg.fre_rms_mm:.3g} mm, without "
            f"{reg.fre_rms_mm:.3g} mm).",
            magnitude_mm=float(np.sqrt(np.sum(big**2) / n_all)),
        )
    if cleared:
        cleared = list(dict.fromkeys(cleared))
        limits.append(
            f"{', '.join(cleared[:20])}{' …' if len(cleared) > 20 else ''} first looked like outliers (a rigid + "
            "linear model) but a smooth field fitted to the others predicts them: they were kept and judged with the "
            "systematic effects"
        )
    cov = 0.5 * (cov + cov.T)
    sigma = np.sqrt(np.clip(np.diag(cov), 0, None))
    noise_pp = float(np.sum(sigma**2)) * float(np.mean(1.0 / w)) * (3 * n - 6) / (3 * n)
    if ps.field is not None:
        # the field's RMS over the points: the rigid residual less drift and the arm, less the noise
        bias_f = resid - _systematic_at(d, arm, ps, inl)
        rms = float(np.sqrt(max(float(np.mean(np.sum(bias_f**2, axis=1))) - noise_pp, 0.0)))
        i_obs, i_mean, k_nb = ps.moran
        dropped = [f"{nm} (p {_fmt_p(pv)} beside {bs})" for nm, pv, bs in ps.rejudged if bs == "the field"]
        effects["smooth_field"] = Effect(
            "smooth_field",
            {"rms_mm": rms, "length_scale_mm": ps.field.length_mm},
            tests["smooth_field"],
            f"neighbouring residuals point the same way (Moran's I = {i_obs:.3g} with {k_nb} nearest "
            f"neighbours; white-noise bootstrap mean {i_mean:.3g}, p {_fmt_p(tests['smooth_field'])}) after removing "
            f"the accepted lower-order terms; rms_mm is the RMS of the whole non-rigid bias at the points (its linear "
            f"part included, drift and the arm excluded), the length is the maximum-likelihood correlation length"
            + (f"; judged beside the field, {', '.join(dropped)} is part of it" if dropped else "")
            + ".",
            magnitude_mm=rms,
        )
    # anisotropic noise
    if nu_pe >= 3:
        tests["anisotropic_noise"] = p_an
        cov_s = reg.mapping.rotation.T @ cov @ reg.mapping.rotation  # sensor frame
        ev, evec = np.linalg.eigh(cov_s)
        ratio = float(np.sqrt(max(ev[2], 0.0) / max(np.mean(ev[:2]), 1e-300)))
        if p_an < a_each and ratio > 1:
            axis = evec[:, 2] * (1 if evec[np.argmax(np.abs(evec[:, 2])), 2] > 0 else -1)
            src = {"repeats": "repeated measurements", "fit": "fit residuals"}[noise_source]
            effects["anisotropic_noise"] = Effect(
                "anisotropic_noise",
                {"axis": axis.tolist(), "ratio": ratio},
                p_an,
                f"the noise ({src}{', beside the smooth field' if ps.field is not None and not repeats else ''}) "
                f"is {ratio:.3g} times larger along the sensor axis ({', '.join(f'{a:.3f}' for a in axis)}) than "
                f"across it (sphericity, p {_fmt_p(p_an)}); the other tests used noise-whitened residuals.",
                magnitude_mm=float(np.sqrt(max(ev[2], 0.0))),
            )
    else:
        limits.append("too few degrees of freedom to test noise anisotropy")
    if arm is not None and "kinematic" in effects:
        limits.append(
            "with joint angles a uniform scale is the same as all the arm's lengths scaled together: a scale the "
            "arm explains is reported as kinematic"
        )
        if "affine" in effects or "scale" in effects:
            limits.append(
                "beside the arm's error, a smooth field of position (a sensor's distortion) is seen only through "
                "what the arm's columns cannot follow: its linear part is reported as affine/scale and the rest, "
                "absorbed by the arm's columns, may go unnamed"
            )

    # bias, and RRBC on the file as given: rrbc correct's own figure on its check rows, else leave-one-out
    bias = float(np.sqrt(max(0.0, float(np.mean(np.sum(resid**2, axis=1))) - noise_pp)))
    verdict = rrbc_verdict(mset, d.sensor, d.robot, d.count, tuple(d.ids[i] for i in out_idx), tuple(d.ids))

    ordered = sorted(effects.values(), key=lambda e: -e.magnitude_mm)
    return Diagnosis(
        tuple(ordered),
        tuple(float(v) for v in sigma),
        noise_source,
        bias,
        verdict.recommended,
        float(verdict.change),
        verdict.loo_rigid_mm,
        verdict.loo_rrbc_mm,
        n,
        float(alpha),
        tests,
        tuple(limits),
        expected_change_without_outliers=verdict.without_outliers,
        basis=verdict.basis,
        checks_rms_mm=(verdict.rms_rigid_mm, verdict.rms_rrbc_mm) if verdict.basis == "checks" else None,
        check_statistics=verdict.statistics,
    )
