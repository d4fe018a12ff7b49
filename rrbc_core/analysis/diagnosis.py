"""Find what is hidden in measured point pairs (`rrbc diagnose`; contract: docs/cli.md, docs/theory.md §6).

Starting from a rigid sensor→robot fit plus isotropic noise, the diagnosis tests, in this order:
outliers (generalised ESD on deleted studentised residuals of a rigid+affine(+drift)(+arm) model), uniform scale
(similarity vs rigid), affine beyond scale (full linear map vs similarity; only the identifiable terms), drift
(residuals vs time), a scale that changes with time (reported in `scale` as `ppm_per_s`), with joint values in the file the arm's kinematic error (its chain's Jacobian columns beyond the
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

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rrbc_core.analysis.diagnosis_arm import MIN_POINTS as ARM_MIN_POINTS
from rrbc_core.analysis.diagnosis_arm import (
    ArmModel,
    arm_columns,
    arm_untested_hint,
    configuration_columns,
    implausible_scale,
    joint_like_columns,
    short_field,
)
from rrbc_core.analysis.diagnosis_field import fit_field, krige_outliers, noise_beside_field
from rrbc_core.analysis.diagnosis_stats import (
    noise_cov,
    outliers,
    paired,
    sphericity,
    whitener,
)
from rrbc_core.analysis.diagnosis_systematic import Effect, fmt_p, row_systematic, systematic, systematic_at
from rrbc_core.analysis.diagnosis_verdict import rrbc_verdict
from rrbc_core.correction.check_statistics import CheckStatistics, GainTest
from rrbc_core.errors import InputError
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.instrument import INSTRUMENTS
from rrbc_core.registration.strategies import least_squares
from rrbc_core.runtime.memory import release_memory
from rrbc_core.runtime.threads import thread_limited

__all__ = ["Effect", "Diagnosis", "diagnose"]

MANY_POINTS = 100_000  # above this many paired points the phases' freed designs are given back to the OS between them


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
    checks_extrapolation: str | None = None  # the checks outside the fiducials' hull / off their plane, in words
    gain: GainTest | None = None  # whether the basis's points show RRBC's change (rrbc_recommended needs a gain)

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
                "checks_extrapolation": self.checks_extrapolation,
                "gain": None if self.gain is None else self.gain.to_json(),
            },
            "n_points": int(self.n_points),
            "alpha": float(self.alpha),
            "tests": {k: float(v) for k, v in self.tests.items()},
            "limits": list(self.limits),
            "check_statistics": None if self.check_statistics is None else self.check_statistics.to_json(),
        }


# --------------------------------------------------------------------------------------------- diagnose
@thread_limited
def diagnose(
    mset: MeasurementSet,
    alpha: float = 0.01,
    seed: int = 0,
    robot: str | None = None,
    tool_mm: float | tuple[float, float, float] | None = None,
    urdf: str | Path | None = None,
    tip: str | None = None,
    base: str | None = None,
    configuration: bool = True,
    instrument: str | None = None,
) -> Diagnosis:
    """What, beyond a rigid transform plus isotropic noise, is in measured point pairs; and whether RRBC will help.

    Parameters
    ----------
    mset : MeasurementSet
        Rows with both readings (roles registration, fiducial, both, check); repeated ids are repeats. With joint
        columns (the robot model's, `io.joints`) the arm's kinematic error is tested too.
    alpha : float
        Family-wise false-alarm rate over all tests (0 < alpha < 1).
    seed : int
        Seed of the bootstraps.
    robot, urdf, tip, base, tool_mm : optional
        The arm's model (`diagnosis_arm.ArmModel`): "ur5" or "ur10" (columns q1..q6, degrees), or a URDF with its
        tip and base links (columns named after its joints); a tool length along the DH flange's z axis or a point
        (3,) in the tip link's frame (mm). Without robot or urdf, q1..q6 columns are tried as a UR5 and skipped with
        a limit if it does not describe them.
    configuration : bool
        Without an arm model (none given, the UR5 not describing the columns), test whether the residuals follow
        the file's joint-like columns (`diagnosis_arm.configuration_columns`: harmonics of the joint values); named,
        it is the `kinematic` effect with `model` "none" (not identified: give the model to identify it).
    instrument : str, optional
        The sensor (`models.instrument.INSTRUMENTS`): a named scale beyond what it plausibly has
        (`PLAUSIBLE_SCALE_PPM`) is said to be implausible in the limits, with the likelier cause.

    Returns
    -------
    Diagnosis
        The effects found (outliers, scale, affine, drift, kinematic, compliance, smooth_field, anisotropic_noise) with their
        parameters and p-values, the noise per axis (mm), the bias RMS (mm), the verdict on RRBC and
        the limits of what these data can show; `to_json()` is the JSON of `rrbc diagnose --json`.

    Raises
    ------
    InputError
        Fewer than 5 distinct points with both readings, alpha out of range, bad joint columns or robot model, or
        a chosen robot model that does not describe the robot (`robot_model.check_model`).
    """
    if not (0 < float(alpha) < 1):
        raise InputError(f"alpha must be between 0 and 1, got {alpha!r}")
    if instrument is not None and instrument not in INSTRUMENTS:
        raise InputError(f"unknown instrument {instrument!r}: one of {', '.join(INSTRUMENTS)}")
    d = paired(mset)
    n_all = len(d.ids)
    limits: list[str] = []
    model = ArmModel(robot, None if urdf is None else str(urdf), tip, base, tool_mm if tool_mm else None)
    arm = arm_columns(mset, d.rows, d.row_point, n_all, model, limits)
    if arm is None and configuration and not model.chosen:
        arm = configuration_columns(mset, d.rows, d.row_point, n_all, limits)  # no model: the joints' harmonics
    if arm is not None and n_all < ARM_MIN_POINTS:
        limits.append(f"only {n_all} paired points with joint angles: the arm's kinematic error was not tested")
        arm = None
    rng = np.random.default_rng(seed)
    use_time = d.time is not None
    if not use_time:
        limits.append("no usable time column: drift was not tested")
    repeats = bool(np.any(d.count > 1))
    # the family: outliers, scale, affine, [drift], [scale_rate], [kinematic], [compliance], smooth_field,
    # anisotropic_noise, each at alpha/m
    m_tests = 5 + 2 * int(use_time) + int(arm is not None) + int(arm is not None and arm.load_fields is not None)
    a_each = alpha / m_tests
    all_idx = np.arange(n_all)
    extra = None
    if arm is not None:  # the outlier test's model holds the arm: its geometric and load columns
        extra = arm.fields if arm.load_fields is None else np.concatenate([arm.fields, arm.load_fields])

    white = np.eye(3)
    if n_all > MANY_POINTS:
        release_memory()  # what reading and pairing the rows freed, given back before the outlier search's designs
    out_idx, p_out = outliers(d, use_time, a_each, white, extra)
    if n_all > MANY_POINTS:
        release_memory()  # the outlier search's designs, freed, given back before the systematic pass builds its own
    cleared: list[str] = []
    for attempt in range(4):
        inl = np.setdiff1d(all_idx, out_idx)
        ps = systematic(d, inl, white=white, use_time=use_time, arm=arm, a_each=a_each, rng=rng)
        if ps.field is not None and len(out_idx):
            # a flagged point the field predicts from its neighbours is part of the field, not an outlier
            sysr = ps.resid - systematic_at(d, arm, ps, inl)
            fmodel = fit_field(ps.p, sysr)
            cand = np.asarray(out_idx, int)
            cres = d.robot[cand] - ps.reg.mapping.apply(d.sensor[cand]) - systematic_at(d, arm, ps, cand)
            keep = krige_outliers(fmodel, ps.reg.mapping.apply(d.sensor[cand]), cres, n_all, a_each)
            if not keep.all():
                cleared += [d.ids[i] for i in cand[~keep]]
                out_idx = [int(i) for i in cand[keep]]
                continue
        # the noise, judged on what the systematic effects leave
        if repeats:
            cov, nu_pe, noise_source = noise_cov(d, inl, use_time, None, row_systematic(d, arm, ps))
            p_an = sphericity(cov, nu_pe) if nu_pe >= 3 else 1.0
        elif ps.field is not None:
            cov, nu_pe, p_an = noise_beside_field(ps.field, rng)
            noise_source = "fit"
        else:
            cov, nu_pe, noise_source = noise_cov(d, inl, use_time, extra)
            p_an = sphericity(cov, nu_pe) if nu_pe >= 3 else 1.0
        if p_an < a_each and np.allclose(white, np.eye(3)) and attempt < 3:
            white = whitener(cov)  # the other tests on noise-whitened residuals
            out_idx, p_out = outliers(d, use_time, a_each, white, extra)
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
            f"ESD, Bonferroni-adjusted p {fmt_p(p_out)} < {a_each:.2g}); they were removed "
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
        bias_f = resid - systematic_at(d, arm, ps, inl)
        rms = float(np.sqrt(max(float(np.mean(np.sum(bias_f**2, axis=1))) - noise_pp, 0.0)))
        # ... and never more than the rigid bias leaves beside what the arm explains (its honest size): where the arm's
        # columns nearly coincide with the field's linear part, the two fitted displacements cancel and the field's
        # alone is no size
        arm_sq = sum(effects[k].magnitude_mm ** 2 for k in ("kinematic", "compliance") if k in effects)
        total_sq = max(float(np.mean(np.sum(resid**2, axis=1))) - noise_pp, 0.0)
        rms = min(rms, float(np.sqrt(max(total_sq - arm_sq, 0.0))))
        i_obs, i_mean, k_nb = ps.moran
        dropped = [f"{nm} (p {fmt_p(pv)} beside {bs})" for nm, pv, bs in ps.rejudged if bs == "the field"]
        effects["smooth_field"] = Effect(
            "smooth_field",
            {"rms_mm": rms, "length_scale_mm": ps.field.length_mm},
            tests["smooth_field"],
            f"neighbouring residuals point the same way (Moran's I = {i_obs:.3g} with {k_nb} nearest "
            f"neighbours; mean under white noise {i_mean:.3g}, p {fmt_p(tests['smooth_field'])}) after removing "
            f"the accepted lower-order terms; rms_mm is the RMS of the whole non-rigid bias at the points (its linear "
            f"part included, drift and the arm excluded; never more than the rigid bias leaves beside the arm's own size), "
            "the length is the maximum-likelihood correlation length"
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
                f"across it (sphericity, p {fmt_p(p_an)}); the other tests used noise-whitened residuals.",
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

    hint = arm_untested_hint(mset, arm is not None and not arm.model_free, effects, instrument)
    for line in (
        hint,
        implausible_scale(effects, instrument, bool(joint_like_columns(mset))),
        short_field(effects, ps.p, ps.spacing),
    ):
        if line is not None:
            limits.append(line)

    # bias, and RRBC on the file as given: rrbc correct's own figure on its check rows, else leave-one-out
    bias = float(np.sqrt(max(0.0, float(np.mean(np.sum(resid**2, axis=1))) - noise_pp)))
    verdict = rrbc_verdict(mset, d.sensor, d.robot, d.count, tuple(d.ids[i] for i in out_idx), tuple(d.ids))

    ordered = sorted(effects.values(), key=lambda e: -e.magnitude_mm)
    return Diagnosis(
        tuple(ordered),
        (float(sigma[0]), float(sigma[1]), float(sigma[2])),
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
        checks_extrapolation=verdict.checks_extrapolation,
        gain=verdict.gain,
    )
