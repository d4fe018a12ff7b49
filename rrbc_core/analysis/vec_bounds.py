"""Per-point 95 % bounds for `rrbc calibrate`'s four methods (rigid, RRBC, VEC, VEC+RRBC) at its targets and checks:
the same budget as `rrbc correct`'s (`correction.bounds`, docs/uncertainty.md) with the arm model's part.

- *instrument*: one row's noise per axis, from repeats within a station (`correction.bound_inputs.estimate_noise`), else
  the smaller of two upper bounds: the stations' fiducials' nearest-neighbour differences (averaged) and the arm
  calibration's residual per axis;
- *registration* (rigid, RRBC): each station's least-squares transform's uncertainty at the point, for RRBC less
  its IDW-interpolated value at the station's fiducials;
- *arm* (VEC, VEC+RRBC): the identified parameters' covariance (transforms included) carried to the point
  (`analysis.calibration.Calibration.prediction_cov`);
- *interpolation*: each method's cross-validated error over the fiducials (the folds `rrbc calibrate` scores with)
  against the held-out fiducial's distance from the nearest fiducial of its station left in
  (`correction.bounds.profile_from_squares`); for rigid and VEC it is the correction they do not make. Held-out
  registration points count only when fewer than `MIN_FIDUCIALS` other fiducials were held out (their errors are
  fit residuals), as in `rrbc correct`.

A point farther from its station's fiducials than the folds tested gets no bound (NaN), as in `rrbc correct`.
Units mm, robot frame.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from rrbc_core.correction.bound_inputs import MIN_FIDUCIALS, estimate_noise, tested_from
from rrbc_core.correction.bound_registration import point_registration_cov, registration_theta_cov
from rrbc_core.correction.bounds import assemble_bounds, no_bounds, profile_from_squares

METHODS = ("rigid", "rrbc", "vec", "vec_rrbc")


def _held_distances(folds, rows_fid, s, g) -> np.ndarray:
    """(H,) each held-out fiducial's distance (sensor frame, mm) from the nearest fiducial of its station left in,
    in the order `_cv_squared` concatenates them (inf when its station has none left)."""
    out = []
    for held in folds:
        keep = np.setdiff1d(np.arange(len(rows_fid)), held)
        for i in rows_fid[held]:
            same = rows_fid[keep][g[rows_fid[keep]] == g[i]]
            out.append(float(np.min(np.linalg.norm(s[same] - s[i], axis=1))) if len(same) else np.inf)
    return np.array(out)


def row_noise(mset, fit, rows_fid, s, b, g) -> tuple[float, str]:
    """One row's per-axis noise variance (mm²) and where it came from (module docstring)."""
    per, why = [], ""
    for k in np.unique(g[rows_fid]):
        fr = rows_fid[g[rows_fid] == k]
        rigid = s[fr] @ fit.rot[k].T + fit.t[k]
        est = estimate_noise(None, fit.rot[k], s[fr], b[fr] - rigid)
        if est is not None:
            per.append(est[0])
            why = est[1]
    from rrbc_core.io.measurements import select_rows

    reps = []  # repeats within each station (a station's own transform; an id may recur at another station)
    for k in np.unique(g):
        rep = estimate_noise(select_rows(mset, np.flatnonzero(g == k)), fit.rot[k], np.zeros((0, 3)), np.zeros((0, 3)))
        if rep is not None:
            reps.append(rep)
    if reps:
        return float(np.mean([r[0] for r in reps])), reps[0][1] + (
            f", averaged over {len(reps)} stations" if len(reps) > 1 else ""
        )
    sigma2 = float(fit.cal.sigma_mm) ** 2  # the arm fit's residual per axis: the noise, or more where it misfits
    if per and float(np.mean(per)) < sigma2:
        return float(np.mean(per)), why + (f", averaged over {len(per)} stations" if len(per) > 1 else "")
    return sigma2, "the calibration's residual per axis (an upper bound: the noise and what the arm model misses)"


def method_bounds(
    mset, fit, folds, sq: dict, rows_reg, rows_fid, rows_pts, s, b, q, gi, idw_by_group
) -> tuple[dict, dict, list]:
    """Each method's `PointBounds` at rows_pts (method -> PointBounds), the instrument's JSON and warnings.

    `fit` a `vec_compare.MethodsFit`; `folds` and `sq` (method -> (H,) held-out squared errors) as `vec_compare`
    scores them; s, b, q the rows' sensor readings, robot readings and joint values; gi (R,) stations or None;
    `idw_by_group(src, values, dst, g_src, g_dst)` the IDW by station RRBC corrects with."""
    g = np.zeros(len(s), int) if gi is None else np.asarray(gi, int)
    m = len(rows_pts)
    var, why = row_noise(mset, fit, rows_fid, s, b, g)
    instrument = {"name": "estimated", "kind": "cartesian", "sigma_mm": float(np.sqrt(var)), "source": why}
    own = np.broadcast_to(var * np.eye(3), (m, 3, 3)).copy()
    warnings: list[str] = []
    none = no_bounds(m)
    if not folds or not len(rows_fid):
        warnings.append("no bound: no fiducials to cross-validate the methods over")
        return dict.fromkeys(METHODS, none), instrument, warnings
    dist = _held_distances(folds, rows_fid, s, g)
    finite = np.isfinite(dist)
    # registration points' errors are fit residuals: only the other fiducials' make the profiles when there are
    # enough of them (as `rrbc correct`'s, `correction.bounds`)
    free = finite & ~np.isin(np.concatenate([rows_fid[h] for h in folds]), rows_reg)
    if np.count_nonzero(free) >= MIN_FIDUCIALS:
        finite = free
    tested = tested_from(dist)
    gp = g[rows_pts]
    sp = s[rows_pts]
    # distance of each point from its station's nearest fiducial
    d = np.full(m, np.inf)
    for k in np.unique(gp):
        fr = rows_fid[g[rows_fid] == k]
        if len(fr):
            d[gp == k] = cKDTree(s[fr]).query(sp[gp == k])[0]
    beyond = d > tested
    if np.any(beyond):
        warnings.append(
            f"no bound for {int(beyond.sum())} of {m} points: farther from their station's fiducials than the "
            f"{tested:.4g} mm the cross-validation tested"
        )
    # registration: each station's transform, its error at the point (RRBC: less its IDW value at the fiducials)
    reg = np.zeros((m, 3, 3))
    reg_rrbc = np.zeros((m, 3, 3))
    fid_rigid = np.einsum("nij,nj->ni", fit.rot[g[rows_fid]], s[rows_fid]) + fit.t[g[rows_fid]]
    rigid_p = np.einsum("nij,nj->ni", fit.rot[gp], sp) + fit.t[gp]
    f_p = idw_by_group(fid_rigid, fid_rigid, rigid_p, g[rows_fid], gp)
    w_p = idw_by_group(fid_rigid, np.ones_like(fid_rigid), rigid_p, g[rows_fid], gp)[:, 0]
    for k in np.unique(gp):
        rr = rows_reg[g[rows_reg] == k]
        theta = registration_theta_cov(fit.rot[k], s[rr], np.broadcast_to(var * np.eye(3), (len(rr), 3, 3)))
        at = gp == k
        reg[at] = point_registration_cov(fit.rot[k], sp[at], np.ones(int(at.sum())), theta)
        lever = (rigid_p[at] - f_p[at]) @ fit.rot[k]  # robot-frame lever back to the sensor frame
        reg_rrbc[at] = point_registration_cov(fit.rot[k], lever, 1.0 - w_p[at], theta)
    arm = fit.cal.prediction_cov(q[rows_pts], sp, gp if gi is not None else None)
    noise3 = 3 * var
    out = {}
    for name in METHODS:
        prof = profile_from_squares(sq[name][finite], dist[finite], np.ones(int(finite.sum()), bool), noise3)
        interp = prof.variance(d, np.ones(m, bool))[:, None, None] * np.eye(3) / 3
        parts = {"instrument": own, "interpolation": interp}
        if name in ("rigid", "rrbc"):
            parts["registration"] = reg if name == "rigid" else reg_rrbc
        else:
            parts["arm"] = arm
        out[name] = assemble_bounds(parts, beyond)
    return out, instrument, warnings


def bounds_rows(bounds: dict) -> list[dict]:
    """Each point's ``bound95_mm``, ``budget_mm`` and ``cov_mm2``, each {method: value or null}."""
    per = {name: pb.rows_json() for name, pb in bounds.items()}
    n = len(next(iter(per.values()))) if per else 0
    return [
        {key: {name: per[name][k][key] for name in per} for key in ("bound95_mm", "budget_mm", "cov_mm2")}
        for k in range(n)
    ]
