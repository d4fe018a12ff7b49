"""Find what is hidden in measured point pairs (`rrbc diagnose`; contract: docs/cli.md, docs/theory.md §6).

Starting from a rigid sensor→robot fit plus isotropic noise, the diagnosis tests, in this order:
outliers (generalised ESD on deleted studentised residuals of a rigid+affine(+drift) model), uniform scale
(similarity vs rigid), affine beyond scale (full linear map vs similarity; only the identifiable terms), drift
(residuals vs time), smooth field (Moran's I of the residuals, k-nearest-neighbour weights, parametric bootstrap)
and anisotropic noise (sphericity likelihood ratio of the noise covariance). All model tests are nested F-tests
of the linearised residual model (docs/theory.md §6.1). False alarms are controlled family-wise: each of the m tests
run is judged at alpha/m (Bonferroni).

Conventions: residual r_i = robot_i − (R sensor_i + t), robot frame, mm. `scale.ppm` is the scale of the
sensor→robot map minus one (robot ≈ (1 + ppm·1e-6)·R·sensor + t); `affine.matrix` G is the symmetric (non-rigid)
linear part in the robot frame: robot ≈ R sensor + t + G (x − x̄); `drift.rate_mm_per_s` is the rate of change of
the residual (robot frame); `anisotropic_noise.axis` is in the sensor frame; `noise_sigma_mm` is per robot axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats
from scipy.spatial import cKDTree

from rrbc_core.analysis.diagnosis_stats import (
    _BOOTSTRAP,
    _DRIFT_KEPT,
    _fit,
    _ftest,
    _Geometry,
    _length_scale,
    _loo,
    _moran,
    _moran_bootstrap,
    _moran_weights,
    _noise_cov,
    _orth,
    _outliers,
    _paired,
    _sphericity,
    _usable_drift,
    _whitener,
)
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
    RRBC's leave-one-out verdict (``rrbc_recommended``, ``expected_rmst_change``, the two RMS values); the
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
                "loo_rms_rigid_mm": float(self.loo_rms_rigid_mm),
                "loo_rms_rrbc_mm": float(self.loo_rms_rrbc_mm),
            },
            "n_points": int(self.n_points),
            "alpha": float(self.alpha),
            "tests": {k: float(v) for k, v in self.tests.items()},
            "limits": list(self.limits),
        }


# --------------------------------------------------------------------------------------------- diagnose
def _fmt_p(p: float) -> str:
    return f"{p:.2g}"


@thread_limited
def diagnose(mset: MeasurementSet, alpha: float = 0.01, seed: int = 0) -> Diagnosis:
    """What, beyond a rigid transform plus isotropic noise, is in measured point pairs; and whether RRBC will help.

    Parameters
    ----------
    mset : MeasurementSet
        Rows with both readings (roles registration, fiducial, both, check); repeated ids are repeats.
    alpha : float
        Family-wise false-alarm rate over all tests (0 < alpha < 1).
    seed : int
        Seed of the bootstrap of the smooth-field test.

    Returns
    -------
    Diagnosis
        The effects found (outliers, scale, affine, drift, smooth_field, anisotropic_noise) with their parameters
        and p-values, the noise per axis (mm), the bias RMS (mm), the leave-one-out verdict on RRBC and the limits
        of what these data can show; `to_json()` is the JSON of `rrbc diagnose --json`.

    Raises
    ------
    InputError
        Fewer than 5 distinct points with both readings, or alpha out of range.
    """
    if not (0 < float(alpha) < 1):
        raise InputError(f"alpha must be between 0 and 1, got {alpha!r}")
    d = _paired(mset)
    rng = np.random.default_rng(seed)
    use_time = d.time is not None
    limits: list[str] = []
    if not use_time:
        limits.append("no usable time column: drift was not tested")
    repeats = bool(np.any(d.count > 1))
    # the family: outliers, scale, affine, [drift], smooth_field, anisotropic_noise, each at alpha/m
    m_tests = 5 + int(use_time)
    a_each = alpha / m_tests
    tests: dict[str, float] = {}
    effects: list[Effect] = []
    all_idx = np.arange(len(d.ids))

    # 1-2. outliers first (isotropic), then the noise covariance; if the noise is anisotropic, whiten and redo
    white = np.eye(3)
    out_idx, p_out = _outliers(d, use_time, a_each, white)
    cov, nu_pe, noise_source = _noise_cov(d, np.setdiff1d(all_idx, out_idx), use_time)
    p_an = _sphericity(cov, nu_pe) if nu_pe >= 3 else 1.0
    if p_an < a_each:
        white = _whitener(cov)
        out_idx, p_out = _outliers(d, use_time, a_each, white)
        cov, nu_pe, noise_source = _noise_cov(d, np.setdiff1d(all_idx, out_idx), use_time)
        p_an = _sphericity(cov, nu_pe) if nu_pe >= 3 else 1.0
    tests["outliers"] = p_out
    inl = np.setdiff1d(all_idx, out_idx)
    s, r, w = d.sensor[inl], d.robot[inl], d.count[inl]
    n = len(inl)
    reg = least_squares(s, r, weights=w)
    p = reg.mapping.apply(s)
    rot = reg.mapping.rotation
    resid = r - p
    g = _Geometry(p, d.time[inl] if use_time else None, w, white)
    y = g.vec(resid)
    if out_idx:
        ids = [d.ids[i] for i in out_idx]
        full_reg = least_squares(d.sensor, d.robot, weights=d.count)
        big = np.linalg.norm(d.robot[out_idx] - reg.mapping.apply(d.sensor[out_idx]), axis=1)
        effects.append(
            Effect(
                "outliers",
                {"ids": ids},
                p_out,
                f"{len(ids)} point(s) deviate from a rigid+linear fit of the others by "
                f"{', '.join(f'{b:.3g}' for b in big)} mm (deleted studentised residual, generalised "
                f"ESD, Bonferroni-adjusted p {_fmt_p(p_out)} < {a_each:.2g}); they were removed "
                f"before the other tests (FRE with them {full_reg.fre_rms_mm:.3g} mm, without "
                f"{reg.fre_rms_mm:.3g} mm).",
                magnitude_mm=float(np.sqrt(np.sum(big**2) / len(d.ids))),
            )
        )

    x_rigid = g.rigid()
    if g.planar:
        limits.append(
            "the paired points are coplanar (normal " + ", ".join(f"{v:.3f}" for v in g.normal) + "): only the 3 "
            "in-plane affine terms (two in-plane scales, in-plane shear) are testable; out-of-plane scale, shear and "
            "errors that depend on the distance from the plane are invisible to these points"
        )

    # 3a. scale: similarity vs rigid
    x_scale = np.hstack([x_rigid, g.scale_col()])
    p_sc, q_sc, nu_sc, f_sc, rss0, rss_sc, _ = _ftest(y, x_rigid, x_scale)
    tests["scale"] = p_sc
    sim = least_squares(s, r, weights=w, with_scale=True)
    ppm = (float(sim.details["scale"]) - 1.0) * 1e6
    wsum = float(np.sum(w))
    # 3b. affine beyond scale
    x_aff = np.hstack([x_rigid, g.linear()])
    p_af, q_af, nu_af, f_af, _, rss_af, _ = _ftest(y, x_scale, x_aff)
    tests["affine"] = p_af
    accepted = [x_rigid]
    if p_af < a_each:
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
        mag = float(np.sqrt(max(0.0, rss0 - rss_af) / wsum))
        effects.append(
            Effect(
                "affine",
                {"matrix": gm.tolist()},
                p_af,
                f"a linear map beyond rigid + uniform scale reduces the residual sum of squares from "
                f"{rss_sc:.3g} to {rss_af:.3g} (F({q_af}, {nu_af}) = {f_af:.3g}, p {_fmt_p(p_af)}); the "
                f"matrix is its symmetric part (rotations absorb the rest)"
                + ("; only the in-plane terms are identifiable on these coplanar points" if g.planar else "")
                + ".",
                magnitude_mm=mag,
            )
        )
        accepted = [x_aff]
    elif p_sc < a_each:
        se = np.sqrt(rss_sc / max(nu_sc, 1) / float(np.sum(g.scale_col() ** 2))) / g.scale * 1e6
        mag = float(np.sqrt(max(0.0, rss0 - rss_sc) / wsum))
        effects.append(
            Effect(
                "scale",
                {"ppm": ppm, "ppm_standard_error": float(se)},
                p_sc,
                f"a uniform scale of {ppm:+.4g} ± {se:.2g} ppm between the frames reduces the residual "
                f"sum of squares from {rss0:.3g} to {rss_sc:.3g} (F(1, {nu_sc}) = {f_sc:.3g}, "
                f"p {_fmt_p(p_sc)}); no significant non-uniform part (p {_fmt_p(p_af)}).",
                magnitude_mm=mag,
            )
        )
        accepted = [x_scale]
    x_acc = np.hstack(accepted)

    # 4. drift
    if use_time:
        dcol = g.drift()
        dcol_ok, surviving = _usable_drift(x_acc, dcol)  # fraction of drift energy kept per direction
        x_dr = np.hstack([x_acc, dcol_ok])
        p_dr, q_dr, nu_dr, f_dr, rss_a, rss_d, _ = _ftest(y, x_acc, x_dr)
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
            coef_dr = _fit(y, np.hstack([x_acc, dcol]))[0]
            rate = coef_dr[-3:] / g.tscale  # the columns carry the whitening: coefficients are in mm
            mag = float(np.sqrt(max(0.0, rss_a - rss_d) / wsum))
            effects.append(
                Effect(
                    "drift",
                    {"rate_mm_per_s": rate.tolist()},
                    p_dr,
                    f"the residuals change linearly with measurement time at "
                    f"{np.linalg.norm(rate):.3g} mm/s (F({q_dr}, {nu_dr}) = {f_dr:.3g}, "
                    f"p {_fmt_p(p_dr)}).",
                    magnitude_mm=mag,
                )
            )
            x_acc = x_dr

    # 5. smooth field: Moran's I of the residuals after the accepted model, parametric bootstrap under white noise
    qa = _orth(x_acc)
    res_acc = y - qa @ (qa.T @ y)
    nb = _moran_weights(p)
    i_obs = float(_moran(res_acc.reshape(n, 3), nb))
    i_boot = _moran_bootstrap(rng, qa, nb)
    exceed = int(np.sum(i_boot >= i_obs))
    if exceed:
        p_sm = (1 + exceed) / (_BOOTSTRAP + 1)
    else:
        z = (i_obs - i_boot.mean()) / max(float(i_boot.std()), 1e-300)
        p_sm = float(min(1.0 / (_BOOTSTRAP + 1), stats.norm.sf(z)))
    tests["smooth_field"] = p_sm
    smooth = p_sm < a_each
    if n < _SMALL_N:
        # Moran's I only sees a field whose correlation reaches the k-th neighbour; with few points that distance
        # approaches the extent, and a longer field is mostly absorbed by the rigid/linear fit (power study,
        # docs/diagnosis_power.md: 12 points found a field of length half the extent in few sets at any size).
        reach = float(np.median(cKDTree(p).query(p, k=nb.shape[1] + 1)[0][:, -1]))
        limits.append(
            f"only {n} paired points: a smooth field with correlation length below about {reach:.0f} mm (the median "
            f"distance to the {nb.shape[1]}th nearest neighbour) cannot be detected reliably; longer fields are largely "
            "absorbed by the fitted transform"
            + ("" if smooth else "; an empty or low-order verdict does not rule out a smooth field")
            + (
                "; the reported affine/scale term may be the linear part of a smooth field"
                if any(e.name in ("affine", "scale") for e in effects)
                else ""
            )
        )
    if smooth:
        res_pts = (res_acc / g.sw).reshape(n, 3) @ np.linalg.inv(white).T  # back to mm, robot frame
        ell, v = _length_scale(p, res_pts)
        nn = nb[:, 0]
        nug = 0.5 * np.mean((res_pts - res_pts[nn]) ** 2, axis=0)  # ≈ σ² per axis + a little of the field
        # the field's RMS over the points: all of the rigid residual beyond the noise (its linear part included)
        field_var = float(np.mean(np.sum(resid**2, axis=1))) - float(np.sum(nug)) * (3 * n - 6) / (3 * n)
        rms = float(np.sqrt(max(field_var, v, 0.0)))
        effects.append(
            Effect(
                "smooth_field",
                {"rms_mm": rms, "length_scale_mm": ell},
                p_sm,
                f"neighbouring residuals point the same way (Moran's I = {i_obs:.3g} with {nb.shape[1]} "
                f"nearest neighbours; white-noise bootstrap mean {i_boot.mean():.3g}, p {_fmt_p(p_sm)}) "
                f"after removing the accepted lower-order terms; rms_mm is the RMS of the whole non-rigid bias "
                f"at the points (its linear part included).",
                magnitude_mm=rms,
            )
        )
        if not repeats:  # the fit residuals hold the field: noise from nearest-neighbour differences instead
            diff = (res_pts - res_pts[nn]) / np.sqrt(2)
            cov = diff.T @ diff / n
            nu_pe = n / 2.0
            p_an = _sphericity(cov, nu_pe) if nu_pe >= 3 else 1.0
    sigma = np.sqrt(np.clip(np.diag(cov), 0, None))

    # 6. anisotropic noise
    if nu_pe >= 3:
        tests["anisotropic_noise"] = p_an
        cov_s = rot.T @ cov @ rot  # sensor frame
        ev, evec = np.linalg.eigh(cov_s)
        ratio = float(np.sqrt(ev[2] / max(np.mean(ev[:2]), 1e-300)))
        if p_an < a_each and ratio > 1:
            axis = evec[:, 2] * (1 if evec[np.argmax(np.abs(evec[:, 2])), 2] > 0 else -1)
            effects.append(
                Effect(
                    "anisotropic_noise",
                    {"axis": axis.tolist(), "ratio": ratio},
                    p_an,
                    f"the noise ({'repeated measurements' if repeats else 'fit residuals'}) is "
                    f"{ratio:.3g} times larger along the sensor axis "
                    f"({', '.join(f'{a:.3f}' for a in axis)}) than across it (sphericity likelihood "
                    f"ratio, p {_fmt_p(p_an)}); the other tests used noise-whitened residuals.",
                    magnitude_mm=float(np.sqrt(ev[2])),
                )
            )
    else:
        limits.append("too few degrees of freedom to test noise anisotropy")

    # 8. bias and RRBC by leave-one-out
    noise_pp = float(np.sum(sigma**2)) * float(np.mean(1.0 / w)) * (3 * n - 6) / (3 * n)
    bias = float(np.sqrt(max(0.0, float(np.mean(np.sum(resid**2, axis=1))) - noise_pp)))
    loo_rigid, loo_rrbc = _loo(s, r, w)
    change = loo_rrbc / loo_rigid - 1.0 if loo_rigid > 0 else 0.0

    effects.sort(key=lambda e: -e.magnitude_mm)
    return Diagnosis(
        tuple(effects),
        tuple(float(v) for v in sigma),
        noise_source,
        bias,
        bool(loo_rrbc < loo_rigid),
        float(change),
        loo_rigid,
        loo_rrbc,
        n,
        float(alpha),
        tests,
        tuple(limits),
    )
