"""`rrbc calibrate`: RRBC against volumetric error compensation (VEC) on the same measurement file
(docs/calibration.md).

From the registration and fiducial rows (with joint angles) it identifies the arm's kinematic errors and the
sensor-to-robot transform (`calibration.calibrate`), then predicts, for every check and target row, the robot
command four ways (robot frame, mm):

- rigid: least-squares registration of the registration rows, b̂ = R s + t;
- rrbc: RRBC over the fiducials (IDW k = 4, p = 2), as `rrbc correct`;
- vec: the point p = T_vec(s); the joints that put the IDENTIFIED arm's tool there, q* = IK(θ̂, p, the row's tool
  orientation, seeded with the row's joints); the command the NOMINAL controller needs to go to q*,
  b̂ = FK(θ₀, q*);
- vec_rrbc: vec, then RRBC on vec's residuals at the fiducials (e_i = b_i − b̂_vec(s_i), IDW to the row).

Check rows carry the robot's reading of the point (its truth); RMS errors over them give `rmst_mm`. Without check
rows, `cv_rmst_mm` does the same over the fiducials by cross-validation (each fiducial held out: the other
fiducials and the registration rows fit; at most `CV_FOLDS` folds), and `recommended` is the method with the
smallest cross-validated error — chosen without the check rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.analysis.calibration import PARAM_NAMES, Calibration, calibrate
from rrbc_core.errors import InputError
from rrbc_core.io.joints import joint_angles
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.kinematics import ROBOT_DH, forward, inverse

METHODS = ("rigid", "rrbc", "vec", "vec_rrbc")
CV_FOLDS = 10
KINEMATIC_ALPHA = 1e-3
KINEMATIC_MARGIN = 0.8


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
    rot: np.ndarray
    t: np.ndarray
    cal: Calibration
    fid_sensor: np.ndarray
    fid_robot: np.ndarray
    vec_fid: np.ndarray  # VEC's commands for the fiducials' sensor readings


def _vec_command(cal: Calibration, nominal, s, q_row) -> np.ndarray:
    """b̂_vec for one row (module docstring). Where the identified arm's inverse kinematics does not converge on
    the row's branch (a model stretched by errors it does not describe), the first-order command is used instead:
    p + FK(θ₀, q_row) − FK(θ̂, q_row), the identified error at the row's configuration."""
    p = cal.sensor_to_robot(s)[0]
    b_row, rot = forward(nominal, q_row)
    try:
        q_star = inverse(cal.identified, p, rot, q_row)
    except InputError:
        p_id, _ = forward(cal.identified, q_row)
        return p + np.asarray(b_row, float) - np.asarray(p_id, float)
    b, _ = forward(nominal, q_star)
    return np.asarray(b, float)


def fit_methods(rows_reg, rows_fid, s, b, q, nominal) -> MethodsFit:
    """The rigid registration (rows_reg), the calibration (rows_reg and rows_fid) and VEC's commands at the fiducials,
    from sensor readings s (R, 3), robot readings b (R, 3) and joints q (R, 6) rad; `predict_methods` uses it."""
    rot, t = _kabsch(s[rows_reg], b[rows_reg])
    rows = np.concatenate([rows_reg, rows_fid])
    cal = calibrate(q[rows], s[rows], nominal, rot, t)  # started from the rigid registration (sensor -> robot)
    vec_fid = np.array([_vec_command(cal, nominal, s[i], q[i]) for i in rows_fid]).reshape(-1, 3)
    return MethodsFit(rot, t, cal, s[rows_fid], b[rows_fid], vec_fid)


def predict_methods(f: MethodsFit, nominal, s_rows, q_rows) -> dict:
    """The four commands (D, 3) for rows with sensor readings s_rows and joints q_rows."""
    rigid = s_rows @ f.rot.T + f.t
    fid_rigid = f.fid_sensor @ f.rot.T + f.t
    rrbc = rigid + _idw(fid_rigid, f.fid_robot - fid_rigid, rigid) if len(f.fid_sensor) else rigid
    vec = np.array([_vec_command(f.cal, nominal, s_rows[i], q_rows[i]) for i in range(len(s_rows))]).reshape(-1, 3)
    vec_rrbc = vec + _idw(f.vec_fid, f.fid_robot - f.vec_fid, vec) if len(f.fid_sensor) else vec
    return {"rigid": rigid, "rrbc": rrbc, "vec": vec, "vec_rrbc": vec_rrbc}


def _rms(a, b) -> float:
    return float(np.sqrt(np.mean(np.sum((np.asarray(a) - np.asarray(b)) ** 2, axis=1))))


def compare(mset: MeasurementSet, robot: str = "ur5", tool_mm: float = 0.0) -> dict:
    """The JSON object of `rrbc calibrate` (docs/cli.md) for a measurement file with joint angles."""
    if robot not in ROBOT_DH:
        raise InputError(f"--robot must be one of {', '.join(ROBOT_DH)}, got {robot!r}")
    q = joint_angles(mset)
    if q is None:
        raise InputError(
            f"{mset.source}: no joint columns q1..q6 (degrees): calibration needs the arm's configurations"
        )
    nominal = ROBOT_DH[robot].with_tool(tool_mm)
    s, b = np.asarray(mset.sensor, float), np.asarray(mset.robot, float)
    roles = np.array(mset.roles)
    rows_reg = np.flatnonzero(np.isin(roles, ("registration", "both")))
    rows_fid = np.flatnonzero(np.isin(roles, ("fiducial", "both")))
    rows_chk = np.flatnonzero(roles == "check")
    rows_tgt = np.flatnonzero(roles == "target")
    if len(rows_reg) < 3:
        raise InputError(f"{mset.source}: at least 3 registration rows are needed, got {len(rows_reg)}")
    if len(np.union1d(rows_reg, rows_fid)) < 8:
        raise InputError(
            f"{mset.source}: {len(np.union1d(rows_reg, rows_fid))} registration and fiducial rows: too few poses to "
            "identify the arm (at least 8; more, in varied configurations, identify more)"
        )
    fit = fit_methods(rows_reg, rows_fid, s, b, q, nominal)
    rmst = dict.fromkeys(METHODS)
    if len(rows_chk):
        pred = predict_methods(fit, nominal, s[rows_chk], q[rows_chk])
        rmst = {m: _rms(pred[m], b[rows_chk]) for m in METHODS}
    # cross-validation over the fiducials (no check rows used)
    folds = np.array_split(np.arange(len(rows_fid)), min(CV_FOLDS, len(rows_fid))) if len(rows_fid) >= 2 else []
    errs: dict[str, list] = {m: [] for m in METHODS}
    for held in folds:
        keep = np.setdiff1d(np.arange(len(rows_fid)), held)
        f = fit_methods(np.setdiff1d(rows_reg, rows_fid[held]), rows_fid[keep], s, b, q, nominal)
        pred = predict_methods(f, nominal, s[rows_fid[held]], q[rows_fid[held]])
        for m in METHODS:
            errs[m].append(np.sum((pred[m] - b[rows_fid[held]]) ** 2, axis=1))
    cv_values = {m: float(np.sqrt(np.mean(np.concatenate(errs[m])))) for m in METHODS} if folds else {}
    cv: dict[str, float | None] = {m: cv_values.get(m) for m in METHODS}
    recommended = min(METHODS, key=lambda m: cv_values[m]) if folds else "rigid"
    cal = fit.cal
    # a kinematic error is claimed only when the arm's identified errors are significant against their stated
    # uncertainty AND the arm model beats a model-free correction out of sample: a smooth sensor field leaks into
    # the DH fit (its χ² alone would call it kinematic), but then RRBC does as well as VEC without an arm model
    claimed = bool(
        folds
        and cal.kinematic_p_value < KINEMATIC_ALPHA
        and min(cv_values["vec"], cv_values["vec_rrbc"]) < KINEMATIC_MARGIN * cv_values["rrbc"]
    )
    targets = []
    if len(rows_tgt):
        pred = predict_methods(fit, nominal, s[rows_tgt], q[rows_tgt])
        for k, i in enumerate(rows_tgt):
            targets.append({"id": mset.ids[i], **{m: pred[m][k].tolist() for m in METHODS}})
    return {
        "robot": robot,
        "tool_mm": float(tool_mm),
        "poses": int(len(np.union1d(rows_reg, rows_fid))),
        "checks": int(len(rows_chk)),
        "rmst_mm": rmst,
        "cv_rmst_mm": cv,
        "recommended": recommended,
        "identifiable": {
            "rank": cal.rank,
            "parameters": [n for n, ok in zip(PARAM_NAMES, cal.identifiable) if ok],
            "combinations": list(cal.combinations),
        },
        "parameters": [
            {"name": n, "error": float(d), "std_error": None if not ok else float(se), "identifiable": bool(ok)}
            for n, d, se, ok in zip(PARAM_NAMES, cal.delta, cal.delta_se, cal.identifiable)
        ],
        "units": "theta/alpha rad, a/d/tool mm",
        "sensor_to_robot": {"rotation": cal.rotation.tolist(), "translation": cal.translation.tolist()},
        "residual_sigma_mm": cal.sigma_mm,
        "kinematic_error": {
            "claimed": claimed,
            "chi2": cal.chi2,
            "dof": cal.chi2_dof,
            "p_value": cal.kinematic_p_value,
            "rule": f"p < {KINEMATIC_ALPHA:g} (χ² of the identified arm errors, independent noise assumed) and "
            f"VEC's cross-validated RMST below {KINEMATIC_MARGIN:g} × RRBC's",
        },
        "targets": targets,
    }
