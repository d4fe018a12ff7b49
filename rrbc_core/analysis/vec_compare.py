"""`rrbc calibrate`: RRBC against volumetric error compensation (VEC) on the same measurement file
(docs/calibration.md).

The robot model is a chain (`analysis.robot_model.robot_chain`: a URDF, or the UR5/UR10 DH tables), checked against
the file's robot columns before anything is fitted (`robot_model.require_model`). From the registration and fiducial
rows (with joint values) it identifies the arm's kinematic errors and the sensor-to-robot transform
(`calibration.calibrate`), then predicts, for every check and target row, the robot command four ways (robot frame,
mm):

- rigid: least-squares registration of the registration rows, b̂ = R s + t;
- rrbc: RRBC over the fiducials (IDW k = 4, p = 2), as `rrbc correct`; over position, or over the arm's
  configuration where the cross-validation says so (`configuration_rrbc`; JSON `interpolation_space`);
- vec: the point p = T_vec(s); the joints q* that put the IDENTIFIED arm's tool there, from the row's joints; the
  command the NOMINAL controller needs to go to q* (`calibration.vec_commands`);
- vec_rrbc: vec, then RRBC on vec's residuals at the fiducials (e_i = b_i − b̂_vec(s_i), IDW to the row; over
  position or configuration, as rrbc).

Check rows carry the robot's reading of the point (its truth); RMS errors over them give `rmst_mm`. `cv_rmst_mm` does
the same over the fiducials by cross-validation (at most `CV_FOLDS` folds; fiducial i in fold i mod folds: the other
fiducials and the registration rows fit), and `recommended` is the simplest method whose cross-validated error is
within one standard error of the smallest (`one_standard_error_choice`) — chosen without the check rows. Whether
the file holds a kinematic error or compliance at all (`kinematic_error.claimed`, `compliance.claimed`) is
`rrbc diagnose`'s decision on the same file and model (`analysis.arm_verdict`). A fiducial row that is also a registration row (role `both`) is held out only when at
least `MIN_REGISTRATION` registration rows remain (else it stays in every fit and is not scored): a file whose
registration rows are `both` and listed first works.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from rrbc_core.analysis.arm_verdict import RULE as ARM_RULE
from rrbc_core.analysis.arm_verdict import arm_verdict
from rrbc_core.analysis.calibration import NOT_CONVERGED, Calibration, calibrate, fixed_transforms, vec_commands
from rrbc_core.analysis.configuration_rrbc import (
    INTERPOLATED,
    choose_spaces,
    configuration_idw,
    configuration_key,
    joint_levers,
    resolve_spaces,
    spaces_json,
)
from rrbc_core.analysis.extrapolation_cv import METHOD_ORDER, beyond_points, extrapolation_folds, mixture_choice
from rrbc_core.analysis.robot_model import require_model, robot_chain
from rrbc_core.analysis.saved_model import export_calibrated_urdf
from rrbc_core.analysis.vec_bounds import bounds_rows, method_bounds
from rrbc_core.correction.configuration_check import configuration_check
from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform
from rrbc_core.io.groups import station_index
from rrbc_core.io.joints import joint_values
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.chain import Chain
from rrbc_core.models.loads import candidate_terms, gravity_loads
from rrbc_core.runtime.threads import thread_limited

METHODS = METHOD_ORDER  # rigid, rrbc, vec, vec_rrbc: simplest first (`extrapolation_cv.METHOD_ORDER`)
CV_FOLDS = 10
MIN_REGISTRATION = 3
TERM_SE = 2.0  # load terms: the gain must exceed this many standard errors ...
TERM_GAIN = 0.05  # ... and this fraction of the RMS


def _idw(src, values, dst) -> np.ndarray:
    """IDW (interpolation.IDW: k = 4, p = 2, the defaults of `rrbc correct`) of `values` at `src` to `dst`."""
    from rrbc_core.interpolation.idw import IDW

    return IDW().fit(src, values).predict(dst).values


def _kabsch(sensor, robot) -> tuple[np.ndarray, np.ndarray]:
    from rrbc_core.registration import register

    reg = register("least-squares", np.asarray(sensor, float), np.asarray(robot, float))
    return np.asarray(reg.mapping.rotation, float), np.asarray(reg.mapping.translation, float)


@dataclass(frozen=True, eq=False)
class MethodsFit:
    rot: np.ndarray  # (G, 3, 3): each station's rigid registration (G = 1 without stations)
    t: np.ndarray  # (G, 3)
    cal: Calibration
    fid_sensor: np.ndarray
    fid_robot: np.ndarray
    vec_fid: np.ndarray  # VEC's commands for the fiducials' sensor readings
    fid_group: np.ndarray  # (F,) the fiducials' stations
    grouped: bool = False
    fid_q: np.ndarray | None = None  # (F, I) the fiducials' joint values
    levers: np.ndarray | None = None  # (I,) joint space's scale (`configuration_rrbc.joint_levers`)
    spaces: dict | None = None  # rrbc / vec_rrbc -> "position" or "configuration" (None: position)


def fit_methods(
    rows_reg, rows_fid, s, b, q, chain: Chain, gi=None, terms=(), gravity=None, fixed: Calibration | None = None
) -> MethodsFit:
    """The rigid registration (rows_reg), the calibration (rows_reg and rows_fid) and VEC's commands at the fiducials,
    from sensor readings s (R, 3), robot readings b (R, 3) and joint values q (R, I) (rad or mm) of `chain`; with
    stations, `gi` (R,) each row's station 0..G-1: a rigid registration and a transform per station, the arm's errors
    shared. `terms`: load terms identified with the arm (`models.loads`, under `gravity`). `fixed`: a saved arm
    (`analysis.saved_model`) kept as it is: only each station's sensor-to-robot transform is fitted, to the
    registration and fiducial rows. `predict_methods` uses it."""
    grouped = gi is not None
    gi = np.zeros(len(s), int) if gi is None else np.asarray(gi, int)
    n_g = int(gi.max()) + 1
    fits = [_kabsch(s[rows_reg[gi[rows_reg] == g]], b[rows_reg[gi[rows_reg] == g]]) for g in range(n_g)]
    rot, t = np.array([f[0] for f in fits]), np.array([f[1] for f in fits])
    rows = np.union1d(rows_reg, rows_fid)
    if fixed is not None:
        cal = fixed_transforms(fixed, q[rows], s[rows], gi[rows], n_g, grouped)
    elif grouped:  # sensor -> robot per station, started from the stations' rigid registrations
        cal = calibrate(chain, q[rows], s[rows], rot, t, groups=gi[rows], terms=terms, gravity=gravity)
    else:
        cal = calibrate(chain, q[rows], s[rows], rot[0], t[0], terms=terms, gravity=gravity)
    vec_fid = vec_commands(cal, s[rows_fid], q[rows_fid], gi[rows_fid] if grouped else None)
    levers = joint_levers(chain, q[rows_fid])
    return MethodsFit(rot, t, cal, s[rows_fid], b[rows_fid], vec_fid, gi[rows_fid], grouped, q[rows_fid], levers)


def _idw_by_group(src, values, dst, g_src, g_dst, interpolate=_idw) -> np.ndarray:
    """IDW corrections at dst from the fiducials of the same station only (zero where a station has none);
    `interpolate(src, values, dst)` the interpolation (position-space IDW by default)."""
    out = np.zeros((len(dst), 3))
    for g in np.unique(g_dst):
        into, fro = g_dst == g, g_src == g
        if np.any(fro):
            out[into] = interpolate(src[fro], values[fro], dst[into])
    return out


def predict_methods(f: MethodsFit, s_rows, q_rows, g_rows=None) -> dict:
    """The four commands (D, 3) for rows with sensor readings s_rows, joint values q_rows and (with stations)
    stations g_rows (D,); rrbc and vec_rrbc interpolated in the space `f.spaces` chose (position by default), and
    both also under `configuration_rrbc.configuration_key` interpolated over the joints."""
    g_rows = np.zeros(len(s_rows), int) if g_rows is None else np.asarray(g_rows, int)
    rigid = np.einsum("nij,nj->ni", f.rot[g_rows], s_rows) + f.t[g_rows]
    fid_rigid = np.einsum("nij,nj->ni", f.rot[f.fid_group], f.fid_sensor) + f.t[f.fid_group]
    vec = vec_commands(f.cal, s_rows, q_rows, g_rows if f.grouped else None)
    if not len(f.fid_sensor):
        return {"rigid": rigid, "rrbc": rigid, "vec": vec, "vec_rrbc": vec}
    rrbc = rigid + _idw_by_group(fid_rigid, f.fid_robot - fid_rigid, rigid, f.fid_group, g_rows)
    vec_rrbc = vec + _idw_by_group(f.vec_fid, f.fid_robot - f.vec_fid, vec, f.fid_group, g_rows)
    out = {"rigid": rigid, "rrbc": rrbc, "vec": vec, "vec_rrbc": vec_rrbc}
    if f.fid_q is not None and f.levers is not None:
        levers = f.levers

        def over_joints(src, values, dst):
            return configuration_idw(src, values, dst, levers)

        q_rows = np.asarray(q_rows, float)
        for m, base, fid_base in (("rrbc", rigid, fid_rigid), ("vec_rrbc", vec, f.vec_fid)):
            corr = _idw_by_group(f.fid_q, f.fid_robot - fid_base, q_rows, f.fid_group, g_rows, over_joints)
            out[configuration_key(m)] = base + corr
    return resolve_spaces(out, f.spaces)


def one_standard_error_choice(squared: dict, among: tuple[str, ...] = METHODS) -> str:
    """The recommended method from held-out squared errors (method -> (H,) mm², the same held-out points): the
    simplest method (`METHODS` order: rigid, rrbc, vec, vec_rrbc) whose mean squared error exceeds the smallest by no
    more than one standard error of their paired difference — the one-standard-error rule of cross-validation, so a
    difference the held-out points cannot resolve does not decide. `among`: the methods to choose from."""
    return mixture_choice([(1.0, squared)], among)


def cv_folds(rows_reg: np.ndarray, rows_fid: np.ndarray, gi=None) -> list[np.ndarray]:
    """Cross-validation folds over the fiducials (indices into rows_fid; module docstring): fiducial i in fold
    i mod k, k = min(CV_FOLDS, fiducials); a fiducial that is also a registration row is held out only where at
    least MIN_REGISTRATION registration rows remain (with stations, `gi` (R,): in its station)."""
    if len(rows_fid) < 2:
        return []
    gi = np.zeros(int(max(rows_reg.max(initial=0), rows_fid.max(initial=0))) + 1, int) if gi is None else gi
    k = min(CV_FOLDS, len(rows_fid))
    folds = []
    for f in range(k):
        held = np.arange(f, len(rows_fid), k)
        both = held[np.isin(rows_fid[held], rows_reg)]
        left = np.setdiff1d(rows_reg, rows_fid[both])
        short = [g for g in np.unique(gi[rows_fid[both]]) if np.sum(gi[left] == g) < MIN_REGISTRATION]
        held = np.setdiff1d(held, both[np.isin(gi[rows_fid[both]], short)])
        if len(held):
            folds.append(held)
    return folds


def _rms(a, b) -> float:
    return float(np.sqrt(np.mean(np.sum((np.asarray(a) - np.asarray(b)) ** 2, axis=1))))


def _cv_squared(folds, rows_reg, rows_fid, s, b, q, chain, gi, terms=(), gravity=None, fixed=None) -> dict:
    """Per method, the held-out fiducials' squared errors (H,) mm² over `folds`: index arrays into rows_fid, each
    left out and scored (`cv_folds`), or (left out, scored) pairs (`extrapolation_cv.extrapolation_folds`)."""
    g_of = (lambda rows: None) if gi is None else (lambda rows: gi[rows])
    errs: dict[str, list] = {m: [] for m in METHODS + tuple(configuration_key(m) for m in INTERPOLATED)}
    for fold in folds:
        held, scored = fold if isinstance(fold, tuple) else (fold, fold)
        keep = np.setdiff1d(np.arange(len(rows_fid)), held)
        f = fit_methods(
            np.setdiff1d(rows_reg, rows_fid[held]), rows_fid[keep], s, b, q, chain, gi, terms, gravity, fixed
        )
        pred = predict_methods(f, s[rows_fid[scored]], q[rows_fid[scored]], g_of(rows_fid[scored]))
        for m in pred:
            errs[m].append(np.sum((pred[m] - b[rows_fid[scored]]) ** 2, axis=1))
    return {m: np.concatenate(v) if v else np.zeros(0) for m, v in errs.items()}


def _better(sq_a: np.ndarray, sq_b: np.ndarray) -> bool:
    """a beats b clearly: its mean squared error is lower by more than `TERM_SE` standard errors of the paired
    difference and its RMS by at least `TERM_GAIN` (a load term is a claim about the arm; a gain the held-out
    fiducials barely resolve is not enough to make it)."""
    d = sq_b - sq_a
    se = float(np.std(d, ddof=1) / np.sqrt(len(d))) if len(d) > 1 else np.inf
    gain = 1.0 - np.sqrt(float(np.mean(sq_a)) / max(float(np.mean(sq_b)), 1e-300))
    return bool(float(np.mean(d)) > TERM_SE * se and gain >= TERM_GAIN)


def select_terms(folds, rows_reg, rows_fid, s, b, q, chain, gi, candidates, gravity) -> tuple[tuple, dict, dict]:
    """The load terms that enter (docs/calibration.md, "Compliance"): all candidates together must beat the geometric
    arm clearly (VEC's cross-validated error over the fiducials, `_better`); then each term in turn leaves unless
    the others without it lose clearly. Returns (entered terms, VEC's squared
    errors per held-out fiducial for the entered model, {"geometric": RMS, "all": RMS, "without <term>": RMS ...})."""
    sq_geo = _cv_squared(folds, rows_reg, rows_fid, s, b, q, chain, gi)
    table = {"geometric": float(np.sqrt(np.mean(sq_geo["vec"])))}
    if not candidates or not folds:
        return (), sq_geo, table
    sq_all = _cv_squared(folds, rows_reg, rows_fid, s, b, q, chain, gi, candidates, gravity)
    table["all terms"] = float(np.sqrt(np.mean(sq_all["vec"])))
    if not _better(sq_all["vec"], sq_geo["vec"]):
        return (), sq_geo, table
    entered, current = tuple(candidates), sq_all
    for term in candidates:
        rest = tuple(t for t in entered if t != term)
        sq_rest = _cv_squared(folds, rows_reg, rows_fid, s, b, q, chain, gi, rest, gravity) if rest else sq_geo
        table[f"without {term.name}"] = float(np.sqrt(np.mean(sq_rest["vec"])))
        if not _better(current["vec"], sq_rest["vec"]):
            entered, current = rest, sq_rest
    return entered, current, table


def _recommend(
    sq, folds, rows_reg, rows_fid, rows_pred, s, b, q, chain, gi, terms, gravity, fixed, config_beyond, spaces=None
):
    """The recommended method and its basis in words (docs/calibration.md, "Recommended method"): the
    one-standard-error rule over ordinary cross-validation for the checks and targets it speaks for, and over
    buffered leave-out folds (`extrapolation_cv`) for those beyond the fiducials, weighted by their shares; where
    most checks and targets lie where no fold can test (off the fiducials' plane, or too far to leave anything out),
    no correction learnt from the fiducials is recommended. Returns (method, basis, `Beyond`, the buffered folds'
    squared errors per method, {} where none was run)."""
    beyond = beyond_points(s, rows_fid, rows_pred, gi)
    if not folds:
        return "rigid", "too few fiducials to cross-validate: rigid", beyond, {}
    if beyond.share == 0.0:
        return (
            one_standard_error_choice(sq),
            "the one-standard-error rule over the cross-validated fiducials",
            beyond,
            {},
        )
    far = extrapolation_folds(s, rows_reg, rows_fid, beyond, gi, min_poses=0 if fixed is not None else 8)
    sq_far = (
        resolve_spaces(_cv_squared(far, rows_reg, rows_fid, s, b, q, chain, gi, terms, gravity, fixed), spaces)
        if far
        else {}
    )
    n_far = len(far)
    inside = 1.0 - beyond.share
    tested = beyond.share - beyond.untestable_share if n_far else 0.0
    untested = 1.0 - inside - tested
    words = (
        f"{beyond.share:.0%} of the checks and targets lie outside the fiducials' hull and farther from them than the "
        f"fiducials lie from each other ({untested:.0%} where no held-out fiducial can test: off the fiducials' plane "
        "or line, or too far to leave fiducials out)"
    )
    if untested <= 0.5:
        parts = [(inside / (inside + tested), sq)] + ([(tested / (inside + tested), sq_far)] if tested else [])
        return (
            mixture_choice(parts),
            f"{words}: the one-standard-error rule weighing, by their shares, the cross-validated fiducials and "
            f"{n_far} folds that leave out every fiducial as near to one fiducial as those points are to theirs "
            "and predict it from the rest",
            beyond,
            sq_far,
        )
    # corrections interpolated from the fiducials (rrbc, and vec_rrbc's residuals) are not tested there; the arm's
    # model is a function of the joints, not of position: it is tested where the points' configurations are like
    # the fiducials' (`configuration_check`), or where the arm was identified elsewhere (a saved model)
    if fixed is not None or not config_beyond:
        # every point beyond and untestable (inside + tested = 0): the cross-validated fiducials are all there is
        spoken = inside + tested
        parts = [(inside / spoken, sq)] + ([(tested / spoken, sq_far)] if tested else []) if spoken else [(1.0, sq)]
        why = (
            "the saved arm's vec"
            if fixed is not None
            else "vec (the points are reached in configurations like the fiducials')"
        )
        return (
            mixture_choice(parts, ("rigid", "vec")),
            f"{words}: chosen between rigid and {why} by the one-standard-error rule over the cross-validated "
            "fiducials",
            beyond,
            sq_far,
        )
    return (
        "rigid",
        f"{words}, and reached in other joint configurations than the fiducials: nothing tests corrections "
        "interpolated from the fiducials or an arm identified from them alone there: rigid; measure fiducials "
        "around the checks, or identify the arm once on data that covers its configurations and reuse it (--model)",
        beyond,
        sq_far,
    )


def drop_unphysical_terms(fit: MethodsFit, terms: tuple, refit) -> tuple[MethodsFit, tuple, list[dict]]:
    """Take out, one at a time, the entered load term with the most negative identified value (a compliance, a
    bending or a backlash below zero: the arm would stiffen under its load, which no arm does) and `refit(terms)` ->
    (MethodsFit, terms) with the rest, until every value is at least zero. Returns the final fit and terms and what
    was taken out ({name, value, std_error, unit})."""
    refused = []
    while terms:
        cal = fit.cal
        negative = [(c, tm, se) for tm, c, se in zip(cal.terms, cal.coef, cal.coef_se) if c < 0]
        if not negative:
            break
        c, worst, se = min(negative, key=lambda x: x[0] / x[2] if x[2] and np.isfinite(x[2]) else x[0])
        refused.append(
            {
                "name": worst.name,
                "value": float(c),
                "std_error": float(se) if np.isfinite(se) else None,
                "unit": worst.unit,
            }
        )
        fit, terms = refit(tuple(t for t in terms if t.name != worst.name))
    return fit, terms, refused


@thread_limited
def compare(
    mset: MeasurementSet,
    robot: str | None = None,
    tool=None,
    urdf=None,
    tip: str | None = None,
    base=None,
    compliance: bool = False,
    backlash: bool = False,
    gravity=None,
    model=None,
    save_model: str | None = None,
    export_urdf: str | None = None,
    verdict=None,
) -> dict:
    """The JSON object of `rrbc calibrate` (docs/cli.md) for a measurement file with joint values. The model:
    `robot` (ur5, ur10; default ur5) or `urdf` with `tip` and `base` (`robot_model.robot_chain`); `tool`: a length along the DH
    flange's z axis or a point (3,) in the tip link's frame, mm. `compliance` (and `backlash`): load terms under
    `gravity` (m/s², base frame) enter where cross-validation says they help (`select_terms`). `model`: a saved arm
    (`saved_model.SavedModel`) kept fixed; only the sensor-to-robot transforms are fitted. `save_model`: a path to
    write the identified arm to (`saved_model.save_model`). `export_urdf`: a path to write the identified arm to as a
    URDF (`models.urdf_export`; a URDF model only). `verdict`: `arm_verdict`'s for this file and model when the
    caller has already run `rrbc diagnose`'s function on them (`rrbc report`), so it is not run twice."""
    if save_model is not None:
        from pathlib import Path

        if model is not None:
            raise InputError("--save-model with --model: the arm is the saved one already; nothing new to save")
        if Path(save_model).is_dir() or not Path(save_model).parent.is_dir():
            raise InputError(f"--save-model {save_model}: must be a file in an existing directory")
    if export_urdf is not None:
        from rrbc_core.io.measurements_write import output_path

        if urdf is None and (model is None or model.urdf is None):
            raise InputError(
                "--export-urdf writes a URDF's joints: give the arm as a URDF (--urdf ROBOT.urdf, or --urdf ur5 for "
                "the packaged UR5), not a DH table (--robot)"
            )
        output_path(export_urdf)
    fixed = None
    if model is not None:
        chain, fixed = model.chain_for(urdf=urdf, tip=tip, base=base, robot=robot if urdf is None else None)
        gravity = fixed.gravity
    else:
        chain = robot_chain(None if urdf is not None else robot, urdf, tip, base, tool)
        if compliance and chain.inertia is None:
            gravity_loads(chain, np.zeros((1, len(chain.inputs))))  # refuses, naming what is missing
    q = joint_values(mset, chain)
    if q is None:
        raise InputError(
            f"{mset.source}: no joint columns ({', '.join(chain.columns)}): calibration needs the arm's configurations"
        )
    s, b = np.asarray(mset.sensor, float), np.asarray(mset.robot, float)
    roles = np.array(mset.roles)
    rows_reg = np.flatnonzero(np.isin(roles, ("registration", "both")))
    rows_fid = np.flatnonzero(np.isin(roles, ("fiducial", "both")))
    rows_chk = np.flatnonzero(roles == "check")
    rows_tgt = np.flatnonzero(roles == "target")
    if len(rows_reg) < MIN_REGISTRATION:
        raise InputError(f"{mset.source}: at least 3 registration rows are needed, got {len(rows_reg)}")
    if fixed is None and len(np.union1d(rows_reg, rows_fid)) < 8:
        raise InputError(
            f"{mset.source}: {len(np.union1d(rows_reg, rows_fid))} registration and fiducial rows: too few poses to "
            "identify the arm (at least 8; more, in varied configurations, identify more; or reuse a saved arm "
            "with --model)"
        )
    names, gi = station_index(mset, MIN_REGISTRATION)
    known = np.union1d(rows_reg, rows_fid)
    model_check = require_model(chain, q[known], b[known], mset.source)
    folds = cv_folds(rows_reg, rows_fid, gi)
    terms: tuple = ()
    load_table: dict = {}
    candidates: tuple = ()
    if compliance and fixed is None:
        candidates = candidate_terms(chain, gravity_loads(chain, q[known], gravity), backlash)
        terms, sq, load_table = select_terms(folds, rows_reg, rows_fid, s, b, q, chain, gi, candidates, gravity)
    else:
        sq = _cv_squared(folds, rows_reg, rows_fid, s, b, q, chain, gi, fixed=fixed)
    fit = fit_methods(rows_reg, rows_fid, s, b, q, chain, gi, terms, gravity, fixed)
    refused: list[dict] = []
    if terms:

        def refit(rest: tuple) -> tuple[MethodsFit, tuple]:
            nonlocal sq
            sq_rest = _cv_squared(folds, rows_reg, rows_fid, s, b, q, chain, gi, rest, gravity)
            sq_geo = _cv_squared(folds, rows_reg, rows_fid, s, b, q, chain, gi)
            if not rest or not _better(sq_rest["vec"], sq_geo["vec"]):  # what is left must still earn its place
                rest, sq_rest = (), sq_geo
            sq = sq_rest
            return fit_methods(rows_reg, rows_fid, s, b, q, chain, gi, rest, gravity, fixed), rest

        fit, terms, refused = drop_unphysical_terms(fit, terms, refit)
    # rrbc and vec_rrbc interpolate over position or over the joints, as the same cross-validation says
    spaces = choose_spaces(sq) if folds else dict.fromkeys(INTERPOLATED, "position")
    space_table = spaces_json(sq, spaces)
    fit = replace(fit, spaces=spaces)
    sq = resolve_spaces(sq, spaces)
    g_of = (lambda rows: None) if gi is None else (lambda rows: gi[rows])
    rmst = dict.fromkeys(METHODS)
    if len(rows_chk):
        pred = predict_methods(fit, s[rows_chk], q[rows_chk], g_of(rows_chk))
        rmst = {m: _rms(pred[m], b[rows_chk]) for m in METHODS}
    cv_values = {m: float(np.sqrt(np.mean(sq[m]))) for m in METHODS} if folds else {}
    cv: dict[str, float | None] = {m: cv_values.get(m) for m in METHODS}
    rows_pts = np.concatenate([rows_tgt, rows_chk]).astype(int)
    config = configuration_check(s, q, np.array([i.kind != "prismatic" for i in chain.inputs]), rows_fid, rows_pts)
    recommended, basis, beyond, sq_far = _recommend(
        sq,
        folds,
        rows_reg,
        rows_fid,
        np.concatenate([rows_chk, rows_tgt]).astype(int),
        s,
        b,
        q,
        chain,
        gi,
        terms,
        gravity,
        fixed,
        config is not None and config.flagged,
        spaces,
    )
    cal = fit.cal
    # whether the file holds an arm error is rrbc diagnose's decision on the same file and model (arm_verdict):
    # one rule for both commands; which method corrects best stays the cross-validated recommendation's question
    if fixed is not None:
        verdict = None
    elif verdict is None:
        verdict = arm_verdict(mset, robot, tool, urdf, tip, base)
    pbounds, instrument, bound_warnings = method_bounds(
        mset, fit, folds, sq, rows_reg, rows_fid, rows_pts, s, b, q, gi, _idw_by_group
    )
    targets: list[dict] = []
    check_points: list[dict] = []
    brows = bounds_rows(pbounds)
    pred_pts = predict_methods(fit, s[rows_pts], q[rows_pts], g_of(rows_pts)) if len(rows_pts) else {}
    for k, i in enumerate(rows_pts):
        row = {"id": mset.ids[i], **{m: pred_pts[m][k].tolist() for m in METHODS}}
        if gi is not None:
            row["group"] = names[gi[i]]
        if k >= len(rows_tgt):
            row["error_mm"] = {m: float(np.linalg.norm(pred_pts[m][k] - b[i])) for m in METHODS}
        row.update(brows[k])
        (targets if k < len(rows_tgt) else check_points).append(row)
    angular = chain.angular
    if save_model is not None:
        from rrbc_core.analysis.saved_model import from_calibration
        from rrbc_core.analysis.saved_model import save_model as write_model

        write_model(save_model, from_calibration(cal, robot, urdf, mset.source, len(known)))
    if export_urdf is not None:
        export_calibrated_urdf(export_urdf, urdf if urdf is not None else model.urdf, cal, mset.source, len(known))
    return {
        "robot": chain.name,
        "model": {
            "source": chain.source,
            "base": chain.base,
            "tip": chain.tip,
            "joints": [{"column": i.column, "unit": i.unit} for i in chain.inputs],
            "tool_mm": chain.tool.tolist(),
            "check": model_check.to_json(),
        },
        "tool_mm": chain.tool.tolist(),
        "poses": int(len(known)),
        "checks": int(len(rows_chk)),
        "rmst_mm": rmst,
        "cv_rmst_mm": cv,
        "recommended": recommended,
        "recommendation_basis": basis,
        "interpolation_space": space_table,
        "extrapolated_share": beyond.share,
        "extrapolation_cv_rmst_mm": {m: float(np.sqrt(np.mean(sq_far[m]))) if sq_far else None for m in METHODS},
        "extrapolation_folds": len(sq_far["rigid"]) if sq_far else 0,
        "identifiable": {
            "rank": cal.rank,
            "parameters": [n for n, ok in zip(cal.names, cal.identifiable) if ok],
            "combinations": list(cal.combinations),
        },
        "parameters": [
            {
                "name": n,
                "error": float(d),
                "std_error": None if not ok else float(se),
                "identifiable": bool(ok),
                "unit": "rad" if ang else "mm",
            }
            for n, d, se, ok, ang in zip(cal.names, cal.delta, cal.delta_se, cal.identifiable, angular)
        ]
        + [
            {
                "name": tm.name,
                "error": float(c),
                "std_error": None if not ok else float(se),
                "identifiable": bool(ok),
                "unit": tm.unit,
                "kind": tm.kind,
            }
            for tm, c, se, ok in zip(cal.terms, cal.coef, cal.coef_se, cal.coef_identifiable)
        ],
        "compliance": {
            "claimed": bool(verdict is not None and verdict.compliance),
            "requested": bool(compliance),
            "gravity_m_s2": list(cal.gravity),
            "candidates": [tm.name for tm in candidates],
            "entered": [tm.name for tm in cal.terms],
            "refused": refused,
            "cv_rmst_mm": load_table,
            "rule": f"all candidate terms must beat the geometric arm's cross-validated VEC error over the fiducials by "
            f"more than {TERM_SE:g} standard errors and {TERM_GAIN:.0%} of its RMS; then each term stays only if the "
            "model without it is worse by as much; a term identified below zero (an arm stiffening under load) is "
            "taken out and the rest fitted again",
        },
        "saved_model": None if model is None else model.describe(),
        "saved_to": save_model,
        "exported_urdf": export_urdf,
        "units": "per parameter (unit): angles rad, lengths mm, compliances rad/Nm",
        "sensor_to_robot": (
            {**(tr := RigidTransform(cal.rotation, cal.translation)).as_dict(), **tr.export_forms()}
            if cal.rotations is None or cal.translations is None
            else [
                {"group": g, "rotation": r.tolist(), "translation": t.tolist(), **RigidTransform(r, t).export_forms()}
                for g, r, t in zip(names, cal.rotations, cal.translations)
            ]
        ),
        "groups": list(names),
        "residual_sigma_mm": cal.sigma_mm,
        "kinematic_error": {
            "claimed": bool(verdict is not None and verdict.kinematic),
            "chi2": cal.chi2,
            "dof": cal.chi2_dof,
            "p_value": cal.kinematic_p_value,
            "rule": ARM_RULE,
            "verdict": None if verdict is None else verdict.to_json(),
        },
        "targets": targets,
        "check_points": check_points,
        "bounds": {"level": 0.95, "instrument": instrument, "warnings": bound_warnings},
        "configuration": None
        if config is None
        else {
            "flagged": config.flagged,
            "p_value": config.p_value,
            "beyond": int(config.beyond.sum()),
            "points": len(config.distance_rad),
            "largest_change_deg": float(np.degrees(config.distance_rad.max())),
            "fiducials_largest_change_deg": float(np.degrees(config.fiducial_rad.max())),
        },
        "warnings": [w for w in ([config.warning(space=spaces["rrbc"])] if config is not None else []) if w]
        + ([] if cal.converged else [NOT_CONVERGED]),
    }
