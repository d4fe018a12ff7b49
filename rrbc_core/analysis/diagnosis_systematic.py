"""The systematic tests of `rrbc diagnose` (`analysis.diagnosis`): uniform scale, affine terms, drift, the arm's
kinematic error and a smooth field, judged one after the other on the rigid residuals of the inliers (nested F-tests
of the linearised residual model, Moran's I with a bootstrap; docs/theory.md §6.1-6.4), and the `Effect` each accepted
one becomes. Conventions as in `analysis.diagnosis`: residual r_i = robot_i − (R sensor_i + t), robot frame, mm."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import special  # the normal tail as scipy.stats computes it, without its import
from scipy.spatial import cKDTree

from rrbc_core.analysis.diagnosis_arm import judge_compliance
from rrbc_core.analysis.diagnosis_field import FieldModel, fit_field, gls_whiten
from rrbc_core.analysis.diagnosis_moran import (
    BOOTSTRAP,
    BOOTSTRAP_EXACT_POINTS,
    moran,
    moran_bootstrap,
    moran_null,
    neighbours,
)
from rrbc_core.analysis.diagnosis_stats import (
    DRIFT_KEPT,
    TIME_FOLLOWS_POSITION,
    Block,
    Columns,
    Geometry,
    LazyColumns,
    as_array,
    column_blocks,
    fit,
    ftest,
    orth,
    time_on_position,
    times,
    usable,
    usable_drift,
)
from rrbc_core.registration.strategies import Registration, least_squares

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


def fmt_p(p: float) -> str:
    return f"{p:.2g}"


@dataclass
class Pass:
    """One pass of the systematic tests over a set of inliers."""

    inl: np.ndarray
    reg: Registration
    p: np.ndarray  # (n, 3) mapped inliers, robot frame
    resid: np.ndarray  # (n, 3) rigid residuals, mm
    effects: dict  # name -> Effect
    tests: dict
    limits: list
    rate: np.ndarray  # drift mm/s (zeros when not accepted)
    t_mean: float
    delta: np.ndarray | None  # the arm's scaled parameter errors when kinematic is accepted
    field: FieldModel | None = None  # once a smooth field is found
    moran: tuple = ()  # (I, its mean under white noise, k)
    rejudged: tuple = ()  # names dropped beside the field or the arm, with their p-values
    c_delta: np.ndarray | None = None  # the load terms' scaled coefficients when compliance is accepted
    spacing: float = 0.0  # the median distance (mm) from each of p to the nearest other (`diagnosis_moran.neighbours`)


def _scale_rate(g: Geometry, y: np.ndarray, blocks: dict, found: dict, tests: dict, x_of, a_each, wsum, t_mean):
    """A scale that changes with time (a thermal ramp): the column (t − t̄)·(p − p̄) beside everything accepted,
    tested like the others; accepted, it is reported in `scale` as `ppm_per_s` (ppm per second about `t0_s`, the
    rows' mean time) beside the scale at t0 (`ppm`, 0 when no constant scale was accepted)."""
    assert g.time is not None  # called only with times
    tt = (g.time - g.time.mean()) / g.tscale
    raw = g._cols([tt[:, None] * g.u])
    x_acc = x_of(blocks)
    q_acc = orth(x_acc)
    col = usable(x_acc, raw, base_basis=q_acc)[0]
    if not col.shape[1]:
        return
    p_sr, _, nu_sr, f_sr, rss_a, rss_sr, _ = ftest(y, x_acc, (x_acc, col))
    tests["scale_rate"] = p_sr
    if p_sr >= a_each:
        return
    coef = fit(y, (x_acc, raw))[0][-1]
    unit = 1e6 / (g.scale * g.tscale)  # a coefficient (mm) in ppm/s
    rate = float(coef) * unit
    beside = raw[:, 0] - q_acc @ (q_acc.T @ raw[:, 0])  # the column's part no accepted term holds
    se = float(np.sqrt(rss_sr / max(nu_sr, 1) / max(float(beside @ beside), 1e-300))) * unit
    old = found.get("scale")
    params = {"ppm": 0.0, **(old.parameters if old is not None else {})}
    params.update({"ppm_per_s": rate, "ppm_per_s_standard_error": se, "t0_s": t_mean})
    text = (
        f"the scale between the frames changes with time at {rate:+.4g} ± {se:.2g} ppm/s (a thermal ramp): the column "
        f"(t − t̄)(p − p̄) beside the accepted terms reduces the residual sum of squares from {rss_a:.3g} to "
        f"{rss_sr:.3g} (F(1, {nu_sr}) = {f_sr:.3g}, p {fmt_p(p_sr)}); ppm is the scale at t0_s, the rows' mean time."
    )
    size = float(np.sqrt(max(0.0, rss_a - rss_sr) / wsum))
    found["scale"] = Effect(
        "scale",
        params,
        old.p_value if old is not None else p_sr,
        (old.evidence + " " if old is not None else "") + text[0].upper() + text[1:],
        magnitude_mm=(old.magnitude_mm if old is not None else 0.0) + size,
    )
    blocks["scale_rate"] = col


def _model_free_effect(arm, q_k, nu_k, f_k, p_k, p_kf, rss_a, rss_k, rms_k) -> Effect:
    """`kinematic` without an arm model (`diagnosis_arm.configuration_columns`): the residuals follow the joint
    values; the arm is named as the cause, its parameters are not identified."""
    cols = ", ".join(arm.model_free[:8]) + (", ..." if len(arm.model_free) > 8 else "")
    return Effect(
        "kinematic",
        {
            "robot": None,
            "model": "none",
            "joint_columns": list(arm.model_free),
            "combinations": int(q_k),
            "rms_mm": rms_k,
        },
        p_k,
        f"the residuals follow the arm's joint configuration, not only the position: {q_k} directions of the "
        f"harmonics of the joint columns ({cols}; no arm model was given) reduce the residual sum of squares beside "
        f"the accepted terms from {rss_a:.3g} to {rss_k:.3g} (F({q_k}, {nu_k}) = {f_k:.3g}, p {fmt_p(p_k)}), more "
        f"than a smooth field of position alone explains (p {fmt_p(p_kf)}): the arm's kinematic or load error, not "
        "the sensor's. Give the arm's model (--robot ur5|ur10, or --urdf ROBOT.urdf --tip LINK, with --tool) to "
        "identify it, and `rrbc calibrate` to correct it.",
        magnitude_mm=rms_k,
    )


def _honest_arm_sizes(g: Geometry, y: np.ndarray, blocks: dict, found: dict, wsum: float) -> None:
    """The sizes of the accepted arm effects (kinematic, compliance) as what each explains beyond every other
    accepted term: the RMS (weighted, in mm, unwhitened) of the fit's change when it is left out, like scale's and
    drift's. The RMS of the arm's own fitted
    displacement is no size: where its columns nearly coincide with the affine ones the joint fit is a cancelling
    pair, hundreds of mm each on millimetre data. This size is never more than the residual it explains, nor than
    the rigid fit's residual RMS."""
    names = [k for k in ("kinematic", "compliance") if k in found and k in blocks]
    if not names:
        return
    res_all = fit(y, tuple(blocks.values()))[1]
    w = g.sw.reshape(g.n, 3)[:, 0] ** 2
    # what the rigid fit leaves (mm): no effect explains more than that
    rigid_res = mm_cols(g, fit(y, blocks["rigid"])[1][:, None])[:, 0].reshape(g.n, 3)
    most = float(np.sqrt(np.sum(w * np.sum(rigid_res**2, axis=1)) / wsum))
    for name in names:
        res_without = fit(y, tuple(v for k, v in blocks.items() if k != name))[1]
        part = mm_cols(g, (res_without - res_all)[:, None])[:, 0].reshape(g.n, 3)  # in mm, unwhitened
        size = min(float(np.sqrt(np.sum(w * np.sum(part**2, axis=1)) / wsum)), most)
        e = found[name]
        found[name] = replace(
            e,
            parameters={**e.parameters, "rms_mm": size},
            evidence=e.evidence
            + f" What it explains beyond the other accepted terms: {size:.3g} mm RMS at these points.",
            magnitude_mm=size,
        )


def mm_cols(g: Geometry, cols: Columns, points: np.ndarray | None = None) -> np.ndarray:
    """Undo the weighting and whitening of point-major columns (3n, k) (or column blocks, `fit`): the fields in mm,
    robot frame. `points` (M,): only those points' rows, (3M, k)."""
    inv = np.linalg.inv(g.white)
    if points is None:
        c = as_array(cols) / g.sw[:, None]
    else:
        rows = (3 * np.asarray(points)[:, None] + np.arange(3)).reshape(-1)
        blocks = [b.at_points(points) if isinstance(b, LazyColumns) else b[rows] for b in column_blocks(cols)]
        c = (np.hstack(blocks) if blocks else np.zeros((len(rows), 0))) / g.sw[rows, None]
    return np.einsum("ab,nbk->nak", inv, c.reshape(-1, 3, c.shape[1])).reshape(len(c), -1)


def _whiten_mm(field: FieldModel, g: Geometry, cols: Columns) -> np.ndarray:
    """gls_whiten(field, mm_cols(g, cols)) (3M, k), made from the field's M points' rows only."""
    return gls_whiten(field, mm_cols(g, cols, field.index), at_points=True)


def systematic(d, inl, *, white, use_time, arm, a_each, rng) -> Pass:
    """One pass of the systematic tests (scale, affine, drift, the arm, a smooth field) over the inliers `inl` of
    the paired data `d`: each accepted effect, the tests' p-values, the limits, and what they leave."""
    s, r, w = d.sensor[inl], d.robot[inl], d.count[inl]
    n = len(inl)
    reg = least_squares(s, r, weights=w)
    p = reg.mapping.apply(s)
    resid = r - p
    g = Geometry(p, d.time[inl] if use_time else None, w, white)
    y = g.vec(resid)
    tests: dict[str, float] = {}
    found: dict[str, Effect] = {}
    limits: list[str] = []
    blocks: dict[str, Block] = {"rigid": g.rigid()}
    x_rigid = blocks["rigid"]
    if g.planar:
        limits.append(
            "the paired points are coplanar (normal " + ", ".join(f"{v:.3f}" for v in g.normal) + "): only the 3 "
            "in-plane affine terms (two in-plane scales, in-plane shear) are testable; out-of-plane scale, shear and "
            "errors that depend on the distance from the plane are invisible to these points"
        )
    # scale: similarity vs rigid; affine beyond scale
    x_scale = (x_rigid, g.scale_col())  # column blocks side by side (`fit`): no copies of the tall columns
    p_sc, _, nu_sc, f_sc, rss0, rss_sc, _ = ftest(y, x_rigid, x_scale)
    tests["scale"] = p_sc
    lin = g.linear()
    p_af, q_af, nu_af, f_af, _, rss_af, _ = ftest(y, x_scale, (x_rigid, lin))
    tests["affine"] = p_af
    del x_scale  # (3n, k): a million points hold 24 MB a column
    wsum = float(np.sum(w))
    if p_af < a_each:
        found["affine"] = affine_effect(p, resid, w, g, rss0, rss_sc, rss_af, q_af, nu_af, f_af, p_af, wsum)
        blocks["affine"] = lin
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
            f"p {fmt_p(p_sc)}); no significant non-uniform part (p {fmt_p(p_af)}).",
            magnitude_mm=float(np.sqrt(max(0.0, rss0 - rss_sc) / wsum)),
        )
        blocks["scale"] = g.scale_col()
    del lin  # kept in blocks when accepted
    x_of = lambda names: tuple(blocks[k] for k in names)  # column blocks (`fit`, `orth`): no stacked copy
    # drift
    rate, t_mean = np.zeros(3), float(np.mean(d.time[inl])) if use_time else 0.0
    dcol_ok = None
    if use_time:
        x_acc = x_of(blocks)
        dcol_ok, surviving = usable_drift(x_acc, g.drift())  # fraction of drift energy kept per direction
        p_dr, q_dr, nu_dr, f_dr, rss_a, rss_d, _ = ftest(y, x_acc, (x_acc, dcol_ok))
        tests["drift"] = p_dr
        lost = int(np.sum(surviving < DRIFT_KEPT))
        if lost:
            limits.append(
                f"with this measurement order, drift along {lost} of 3 directions is (almost) absorbed by "
                f"the fitted transform (least fraction kept {max(surviving.min(), 0):.2g}) and cannot be "
                "detected; randomise the order"
            )
        if p_dr < a_each:
            # the rate from the full drift columns (the absorbed directions are poorly determined: see the limit)
            rate = fit(y, (x_acc, g.drift()))[0][-3:] / g.tscale  # coefficients are in mm
            found["drift"] = Effect(
                "drift",
                {"rate_mm_per_s": rate.tolist()},
                p_dr,
                f"the residuals change linearly with measurement time at {np.linalg.norm(rate):.3g} mm/s "
                f"(F({q_dr}, {nu_dr}) = {f_dr:.3g}, p {fmt_p(p_dr)}).",
                magnitude_mm=float(np.sqrt(max(0.0, rss_a - rss_d) / wsum)),
            )
            blocks["drift"] = dcol_ok
        del x_acc  # (3n, k): _scale_rate builds its own from the blocks accepted now
        r2 = time_on_position(p, g.time) if g.time is not None else 0.0
        if r2 > TIME_FOLLOWS_POSITION:
            limits.append(
                f"time follows position in these data ({r2:.2f} of the times' variance is a linear function of "
                "position): a scale that changes with time cannot be told from an effect of position and was not tested"
            )
        else:
            _scale_rate(g, y, blocks, found, tests, x_of, a_each, wsum, t_mean)
    # the arm (joint angles in the file)
    delta = c_delta = c_map = None
    rejudged = []
    if arm is not None:
        x_acc = x_of(blocks)
        # the arm's directions beside rigid (+ drift) — kfull = (its columns) @ k_map — and, for the test, beside
        # everything accepted
        base = tuple(blocks[k] for k in ("rigid", "drift") if k in blocks)
        # (the arm's columns come from joint angles, not from measured positions: only directions inside the base
        # up to the noise of its rotation columns are left out, 1e-4 of their energy, 1 % of their length)
        kfull, _, k_map = usable(base, g._cols(arm.fields[:, inl]), kept=1e-4)
        ktest = usable(x_acc, kfull)[0]
        p_k, q_k, nu_k, f_k, rss_a, rss_k, _ = ftest(y, x_acc, (x_acc, ktest))
        tests["kinematic"] = p_k
        if p_k < a_each:
            # a smooth field of position alone could explain what the arm's columns fit: judge the arm beside it
            q_b = orth(base)
            fb = fit_field(p, mm_cols(g, (y - q_b @ (q_b.T @ y))[:, None]).reshape(n, 3))
            xw0 = _whiten_mm(fb, g, x_acc)
            xw1 = np.hstack([xw0, _whiten_mm(fb, g, ktest)])
            p_kf = ftest(gls_whiten(fb, mm_cols(g, y[:, None])[:, 0]), xw0, xw1)[0]
            tests["kinematic_beside_field"] = p_kf
        if p_k < a_each and p_kf >= a_each:
            # the arm explains no more than a field of position does (with one tool orientation per place the arm's
            # error is a function of position; and the arm's smooth columns can follow a sensor field): the data
            # cannot tell them apart, and the position effect is the one named
            limits.append(
                f"the arm's kinematic error would explain these residuals (p {fmt_p(p_k)}) but no better than a "
                f"smooth field of position (p {fmt_p(p_kf)} for the arm beside it): reach places in more than one "
                "configuration (another tool orientation) to tell them apart; `rrbc calibrate` compares VEC and RRBC "
                "out of sample"
            )
        if p_k < a_each and p_kf < a_each:
            blocks["kinematic"] = kfull
            rejudged += rejudge(y, blocks, found, a_each, "the arm", tests)
            delta = k_map @ fit(y, x_of(blocks))[0][-kfull.shape[1] :]
            rms_k = float(np.sqrt(np.mean(np.sum(np.einsum("knc,k->nc", arm.fields[:, inl], delta) ** 2, axis=1))))
            found["kinematic"] = (
                _model_free_effect(arm, q_k, nu_k, f_k, p_k, p_kf, rss_a, rss_k, rms_k)
                if arm.model_free
                else Effect(
                    "kinematic",
                    {
                        "robot": arm.robot,
                        "tip": arm.tip,
                        "tool_mm": list(arm.tool_mm),
                        "combinations": int(q_k),
                        "rms_mm": rms_k,
                    },
                    p_k,
                    f"the residuals follow the arm's joint configuration: {q_k} combinations of its kinematic "
                    f"parameters, identifiable at these poses beside the accepted terms, reduce the residual sum of "
                    f"squares from {rss_a:.3g} to {rss_k:.3g} (F({q_k}, {nu_k}) = {f_k:.3g}, p {fmt_p(p_k)}), and "
                    f"more than a smooth field of position alone explains (p {fmt_p(p_kf)}); `rrbc calibrate` "
                    "identifies them and compares model-based correction with RRBC.",
                    magnitude_mm=rms_k,
                )
            )
        if arm.load_fields is not None:
            c_delta, c_map = _compliance(g, p, y, blocks, found, tests, limits, arm, inl, kfull, base, a_each, x_of)
            if c_delta is not None:
                rejudged += rejudge(y, blocks, found, a_each, "the load", tests)
    # smooth field: Moran's I of the residuals after the accepted model, parametric bootstrap under white noise
    qa = orth(x_of(blocks))
    res_acc = y - qa @ (qa.T @ y)
    nb, spacing = neighbours(p)
    i_obs = float(moran(res_acc.reshape(n, 3), nb))
    if n > BOOTSTRAP_EXACT_POINTS:  # Moran's I of many points is close to normal: its exact null moments
        i_mean, i_sd = moran_null(qa, nb)
        p_sm = float(special.ndtr(-(i_obs - i_mean) / max(i_sd, 1e-300)))
    else:
        i_boot = moran_bootstrap(rng, qa, nb, BOOTSTRAP)
        exceed = int(np.sum(i_boot >= i_obs))
        if exceed:
            p_sm = (1 + exceed) / (BOOTSTRAP + 1)
        else:
            z = (i_obs - i_boot.mean()) / max(float(i_boot.std()), 1e-300)
            p_sm = float(min(1.0 / (BOOTSTRAP + 1), special.ndtr(-z)))
        i_mean = float(i_boot.mean())
        del i_boot
    tests["smooth_field"] = p_sm
    del qa, res_acc
    field = None
    if p_sm < a_each:
        # the field's model from the residuals beside everything but scale and affine (a field has a linear part);
        # then, twice: the low-order terms judged again and re-estimated by generalised least squares with the field
        # as part of the error (ordinary least squares lets the field leak into the drift and arm estimates, and
        # their error into the noise), and the field refitted beside them
        q_nl = orth(tuple(v for k, v in blocks.items() if k not in ("scale", "affine")))
        y_mm = mm_cols(g, y[:, None])[:, 0]
        res_nl = mm_cols(g, (y - q_nl @ (q_nl.T @ y))[:, None])[:, 0]
        del q_nl
        # the model's blocks (whitened, weighted) go to mm one at a time when used (`mm_cols` is linear: a fitted
        # contribution is the mm of the block's combination): a million points hold 24 MB a column
        kept = dict(blocks)
        prefit = None  # a field already fitted to these very residuals (the drift's second look, when it finds none)
        if dcol_ok is not None and dcol_ok.shape[1] and "drift" not in found:
            # drift looked for again beside the field: the field's variance swamps a drift in the OLS test
            res_nl, prefit = _drift_beside_field(g, p, y_mm, res_nl, kept, dcol_ok, found, tests, a_each)
            if "drift" in found:
                blocks["drift"] = dcol_ok
        for _ in range(2):
            field = prefit if prefit is not None else fit_field(p, res_nl.reshape(n, 3))
            prefit = None
            y_w = gls_whiten(field, y_mm)
            wb = {k: _whiten_mm(field, g, v) for k, v in kept.items()}
            rejudged += rejudge(y_w, wb, found, a_each, "the field", tests)
            kept = {k: v for k, v in kept.items() if k in wb}
            del wb
            cols = {k: (g.drift() if k == "drift" else v) for k, v in kept.items()}
            coef = fit(y_w, tuple(_whiten_mm(field, g, c) for c in cols.values()))[0]
            contrib, pos = np.zeros(3 * n), 0
            for k, c in cols.items():
                ck = coef[pos : pos + c.shape[1]]
                pos += c.shape[1]
                if k not in ("scale", "affine"):
                    contrib += times(c, ck[:, None])[:, 0]
                if k == "drift":
                    rate = ck / g.tscale
                if k == "kinematic":
                    delta = k_map @ ck
                if k == "compliance":
                    c_delta = c_map @ ck
            res_nl = y_mm - mm_cols(g, contrib[:, None])[:, 0]
            del cols
        for k in [k for k in blocks if k not in kept]:
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
    _honest_arm_sizes(g, y, blocks, found, float(np.sum(w)))
    if "drift" not in found:
        rate = np.zeros(3)
    if "kinematic" not in found:
        delta = None
    if "compliance" not in found:
        c_delta = None
    return Pass(
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
        (i_obs, i_mean, nb.shape[1]),
        tuple(rejudged),
        c_delta,
        spacing,
    )


def _drift_beside_field(g, p, y_mm, res_nl, kept: dict, dcols, found: dict, tests: dict, a_each: float):
    """The drift test again, by generalised least squares with the field (fitted to `res_nl`) as part of the error:
    beside a field many times the noise, the ordinary F-test's residual variance is the field's and a drift of a few
    noise levels goes unseen, to be mistaken later for anisotropic noise. At a_each / 2 (a second look at the same
    hypothesis: the drift's false-alarm rate stays within 1.5 × a_each). On acceptance the drift joins `found` and
    `kept` (the model's blocks, whitened and weighted like `dcols`; `mm_cols` turns them to mm), and the residuals
    (mm) the field is refitted to lose it. Returns those residuals and, when no drift was found, the field fitted to
    them (None otherwise: it must be refitted without the drift)."""
    field = fit_field(p, res_nl.reshape(len(p), 3))
    y_w = gls_whiten(field, y_mm)
    base = tuple(_whiten_mm(field, g, v) for v in kept.values())
    p_b, q_b, nu_b, f_b, rss_a, rss_d, coef = ftest(y_w, base, (base, _whiten_mm(field, g, dcols)))
    tests["drift_beside_field"] = p_b
    if p_b >= a_each / 2:
        return res_nl, field
    drift_mm = mm_cols(g, times(dcols, coef[-dcols.shape[1] :, None]))[:, 0]  # the fitted drift, mm (3n,)
    found["drift"] = Effect(
        "drift",
        {"rate_mm_per_s": []},  # estimated with the field below
        p_b,
        f"the residuals change linearly with measurement time (beside the smooth field, by generalised least "
        f"squares: F({q_b}, {nu_b}) = {f_b:.3g}, p {fmt_p(p_b)}); seen only beside the field, whose variance hides "
        "it from the ordinary test.",
        magnitude_mm=float(np.sqrt(max(0.0, float(np.mean(drift_mm**2)) * 3))),
    )
    kept["drift"] = dcols
    return res_nl - drift_mm, None


def rejudge(y, blocks: dict, found: dict, a_each: float, beside: str, tests: dict) -> list:
    """Drop accepted low-order terms (scale, affine, drift) that are no longer significant beside a newly accepted
    systematic effect; `blocks` and `found` are updated. Returns [(name, p), ...] of the dropped."""
    dropped = []
    for name in ("scale", "affine", "drift"):
        if name not in blocks:
            continue
        others = tuple(v for k, v in blocks.items() if k != name)
        p_b = ftest(y, others, (others, usable(others, blocks[name])[0]))[0]
        tests[f"{name}_beside_{beside.split()[-1]}"] = p_b
        if p_b >= a_each:
            del blocks[name]
            found.pop(name, None)
            dropped.append((name, p_b, beside))
    return dropped


def affine_effect(p, resid, w, g, rss0, rss_sc, rss_af, q_af, nu_af, f_af, p_af, wsum) -> Effect:
    # the linear map in unwhitened coordinates: residual ≈ L (p − p̄)
    ga = Geometry(p, None, w)
    # (rotations lie in the linear map's span: the split of its antisymmetric part is arbitrary, the symmetric part
    # taken below is not; column blocks, no stacked copy)
    coef = fit(ga.vec(resid), (ga.rigid(), ga.linear()))[0]
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
        f"{rss_sc:.3g} to {rss_af:.3g} (F({q_af}, {nu_af}) = {f_af:.3g}, p {fmt_p(p_af)}); the "
        f"matrix is its symmetric part (rotations absorb the rest)"
        + ("; only the in-plane terms are identifiable on these coplanar points" if g.planar else "")
        + ".",
        magnitude_mm=float(np.sqrt(max(0.0, rss0 - rss_af) / wsum)),
    )


def systematic_at(d, arm, ps: Pass, idx: np.ndarray) -> np.ndarray:
    """What the accepted drift and arm predict (mm, (len(idx), 3)) at points idx (all points' indexing)."""
    out = np.zeros((len(idx), 3))
    if d.time is not None and np.any(ps.rate):
        out += np.outer(d.time[idx] - ps.t_mean, ps.rate)
    if ps.delta is not None:
        out += np.einsum("knc,k->nc", arm.fields[:, idx], ps.delta)
    if ps.c_delta is not None:
        out += np.einsum("knc,k->nc", arm.load_fields[:, idx], ps.c_delta)
    return out


def row_systematic(d, arm, ps: Pass) -> np.ndarray:
    """The same per paired row (R, 3): drift at the row's time, the arm at the row's joints."""
    out = np.zeros((len(d.row_point), 3))
    if d.time is not None and np.any(ps.rate):
        out += np.outer(d.row_time - ps.t_mean, ps.rate)
    if ps.delta is not None:
        out += arm.row_fields @ ps.delta
    if ps.c_delta is not None:
        out += arm.load_row_fields @ ps.c_delta
    return out


def _compliance(g, p, y, blocks, found, tests, limits, arm, inl, kfull, base, a_each, x_of):
    """The `compliance` test (`diagnosis_arm.judge_compliance`) and, when accepted, its Effect and block; returns
    the load terms' scaled coefficients (T,) and the map (T, j) from the block's columns to them, or (None, None)."""
    n = len(p)
    cache: dict = {}

    def beside_field(x0, cols):
        if "fb" not in cache:
            q_b = orth(base)
            cache["fb"] = fit_field(p, mm_cols(g, (y - q_b @ (q_b.T @ y))[:, None]).reshape(n, 3))
        fb = cache["fb"]
        xw0 = _whiten_mm(fb, g, x0)
        xw1 = np.hstack([xw0, _whiten_mm(fb, g, cols)])
        return ftest(gls_whiten(fb, mm_cols(g, y[:, None])[:, 0]), xw0, xw1)[0]

    out = judge_compliance(y, x_of(blocks), kfull, g._cols(arm.load_fields[:, inl]), a_each, tests, beside_field)
    if out is None:
        return None, None
    p_c, p_cf, cols, c_map, q_c, nu_c, f_c, rss_a, rss_c = out
    if p_c < a_each and p_cf >= a_each:
        limits.append(
            f"the arm's deflection under its own weight would explain these residuals (p {fmt_p(p_c)}) but no better "
            f"than a smooth field of position (p {fmt_p(p_cf)} beside it): reach places in more than one "
            "configuration to tell them apart; `rrbc calibrate --compliance` compares the models out of sample"
        )
    if not (p_c < a_each and p_cf < a_each):
        return None, None
    blocks["compliance"] = cols
    if "kinematic" in blocks:  # the geometric terms judged again beside the load: a bending arm is not a bent one
        others = x_of([k for k in blocks if k != "kinematic"])
        p_kc = ftest(y, others, (others, usable(others, blocks["kinematic"])[0]))[0]
        tests["kinematic_beside_compliance"] = p_kc
        if p_kc >= a_each:
            del blocks["kinematic"]
            found.pop("kinematic", None)
    coef = fit(y, (x_of([k for k in blocks if k != "compliance"]), kfull, cols))[0][-cols.shape[1] :]
    c_delta = c_map @ coef
    contrib = np.einsum("knc,k->nc", arm.load_fields[:, inl], c_delta)
    rms_c = float(np.sqrt(np.mean(np.sum(contrib**2, axis=1))))
    params = {"robot": arm.robot, "terms": [t.name for t in arm.load_terms], "rms_mm": rms_c}
    if c_map.shape[0] == c_map.shape[1]:  # every term's own coefficient is determined: rad/Nm (residual = −effect)
        params["compliance_rad_per_Nm"] = {
            t.name: float(-c / sc) for t, c, sc in zip(arm.load_terms, c_delta, arm.load_scales)
        }
    found["compliance"] = Effect(
        "compliance",
        params,
        p_c,
        f"the residuals follow the gravity load on the arm's joints: {q_c} combinations of its load terms "
        f"({', '.join(t.name for t in arm.load_terms)}), beyond the geometric kinematic terms, reduce the residual "
        f"sum of squares from {rss_a:.3g} to {rss_c:.3g} (F({q_c}, {nu_c}) = {f_c:.3g}, p {fmt_p(p_c)}), and more "
        f"than a smooth field of position alone explains (p {fmt_p(p_cf)}); `rrbc calibrate --compliance` "
        "identifies it.",
        magnitude_mm=rms_c,
    )
    return c_delta, c_map
