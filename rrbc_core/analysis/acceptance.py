"""`rrbc report`: the integrator's acceptance of a measured cell, as one object (docs/cli.md, `rrbc report`).

Every figure comes from the commands' own functions on the same file, so the report says what they print:

- `rrbc correct` (`correction.stations.correct_stations`): the registration, RRBC with the chosen interpolation,
  each target's and check's corrected position, error, 95 % bound and warnings;
- `rrbc diagnose` (`analysis.diagnosis_stations.diagnose_stations`): what it names, its limits and whether the
  checks show RRBC's gain (`correction.check_statistics.gain_test`);
- `rrbc calibrate` (`analysis.vec_compare.compare`) when an arm model is given (`--robot`, `--urdf`): VEC and
  VEC + RRBC beside rigid and RRBC, its recommendation and the per-point bounds of every method.

**The recommended method**: calibrate's recommendation when it ran; else RRBC when diagnose recommends it (a gain
the points show), else rigid. **The verdict against a tolerance** T (mm), for that method: PASS when every target's
95 % bound and every check's 3-D error are at most T; FAIL naming every point that is not (a check by its measured
error, a target by its bound); UNDECIDED when nothing fails but some target has no bound (too few fiducials to
cross-validate), when the file has neither targets nor checks, or when no tolerance is given.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import MeasurementSet

VERDICTS = ("PASS", "FAIL", "UNDECIDED")
METHOD_NAMES = {"rigid": "rigid", "rrbc": "RRBC", "vec": "VEC", "vec_rrbc": "VEC + RRBC"}


def _parts(cj: dict) -> list[dict]:
    return cj["groups"] if "groups" in cj else [cj]


def _correct_points(cj: dict) -> list[dict]:
    """Each target and check of `rrbc correct --json`'s object: id, role, group, the rigid and RRBC positions,
    errors (checks), bounds, extrapolation, and the distance (sensor frame, mm) to the nearest fiducial."""
    out = []
    for part in _parts(cj):
        fid = np.array([f["sensor"] for f in part["fiducials"]], float).reshape(-1, 3)
        tree = cKDTree(fid) if len(fid) else None
        for role, key in (("target", "targets"), ("check", "checks")):
            for p in part.get(key) or []:
                near = float(tree.query(np.asarray(p["sensor"], float))[0]) if tree is not None else None
                out.append(
                    {
                        "id": p["id"],
                        "role": role,
                        "group": part.get("group"),
                        "robot": {"rigid": p["robot_rigid"], "rrbc": p["robot_rrbc"]},
                        "error_mm": (
                            {"rigid": p["error_rigid_mm"], "rrbc": p["error_rrbc_mm"]} if role == "check" else None
                        ),
                        "bound95_mm": {"rigid": p.get("bound95_rigid_mm"), "rrbc": p.get("bound95_mm")},
                        "correction_mm": float(np.linalg.norm(p["correction_mm"])),
                        "extrapolated": bool(p["extrapolated"]),
                        "rrbc_worse": bool(p.get("rrbc_worse", False)),
                        "nearest_fiducial_mm": near,
                    }
                )
    return out


def _with_calibration(points: list[dict], cal: dict) -> None:
    """Add calibrate's four methods' commands, errors and bounds to the points (matched by id and station)."""
    rows = {(r["id"], r.get("group")): r for r in list(cal["targets"]) + list(cal["check_points"])}
    for p in points:
        r = rows.get((p["id"], p["group"]))
        if r is None:
            continue
        p["robot"] = {m: r[m] for m in METHOD_NAMES}
        if p["role"] == "check":
            p["error_mm"] = dict(r["error_mm"])
        p["bound95_mm"] = dict(r["bound95_mm"])


def verdict_of(points: list[dict], method: str, tolerance_mm: float | None) -> tuple[str, list[dict], str]:
    """(verdict, failing points, reason) for `method` against `tolerance_mm` (module docstring)."""
    if tolerance_mm is None:
        return (
            "UNDECIDED",
            [],
            "no tolerance given (rrbc report --tolerance MM; in the app, the File tab's Report tolerance)",
        )
    if not points:
        return "UNDECIDED", [], "the file has neither targets nor checks"
    failing, unbounded = [], []
    for p in points:
        if p["role"] == "check":
            err = (p["error_mm"] or {}).get(method)
            if err is not None and err > tolerance_mm:
                failing.append({"id": p["id"], "role": "check", "group": p["group"], "what": "error", "mm": err})
        else:
            b = (p["bound95_mm"] or {}).get(method)
            if b is None:
                unbounded.append(p["id"])
            elif b > tolerance_mm:
                failing.append({"id": p["id"], "role": "target", "group": p["group"], "what": "bound95", "mm": b})
    if failing:
        return "FAIL", failing, f"{len(failing)} point(s) beyond {tolerance_mm:g} mm"
    if unbounded:
        shown = ", ".join(unbounded[:8]) + (" ..." if len(unbounded) > 8 else "")
        return "UNDECIDED", [], f"no 95 % bound for {len(unbounded)} target(s) ({shown}): too few fiducials"
    return "PASS", [], f"every point within {tolerance_mm:g} mm"


def acceptance(
    mset: MeasurementSet,
    tolerance_mm: float | None = None,
    options=None,
    instrument=None,
    robot: str | None = None,
    urdf=None,
    tip: str | None = None,
    base=None,
    tool=None,
) -> dict:
    """The report's object (module docstring; the JSON of `rrbc report --json`). `options`, `instrument`: as for
    `rrbc correct`; `robot`/`urdf`/`tip`/`base`/`tool`: an arm model, which adds calibrate's methods (the file must
    have its joint columns). `tolerance_mm` > 0 or None."""
    from rrbc_core.analysis.diagnosis_stations import StationsDiagnosis, diagnose_stations
    from rrbc_core.correction.stations import correct_stations
    from rrbc_core.io.groups import group_names, has_groups

    if tolerance_mm is not None and not (np.isfinite(tolerance_mm) and tolerance_mm > 0):
        raise InputError(f"--tolerance must be a positive number of mm, got {tolerance_mm!r}")
    result = correct_stations(mset, options, instrument)
    cj = result.to_json()
    points = _correct_points(cj)
    arm = robot is not None or urdf is not None
    from rrbc_core.analysis.arm_verdict import ALPHA

    # rrbc diagnose's call, as `arm_verdict` makes it (level, seed): with an arm, calibrate's verdict reuses it
    dg = diagnose_stations(mset, alpha=ALPHA, seed=0, robot=robot, urdf=urdf, tip=tip, base=base, tool_mm=tool)
    if isinstance(dg, StationsDiagnosis):
        d_rrbc = dg.rrbc()
        effects = {name: f"in {len(where)} of {len(dg.groups)} stations" for name, where in dg.effects().items()}
        limits = sorted({x for d in dg.diagnoses for x in d.limits})
        rrbc_ok = bool(d_rrbc["recommended"])
        gain = d_rrbc["gain"]
    else:
        effects = {e.name: e.evidence for e in dg.effects}
        limits = list(dg.limits)
        rrbc_ok = bool(dg.rrbc_recommended)
        gain = None if dg.gain is None else dg.gain.to_json()
    summary = cj["summary"]
    methods: dict = {
        "rigid": {"rmst_mm": summary.get("rmst_rigid_mm")},
        "rrbc": {"rmst_mm": summary.get("rmst_rrbc_mm"), "interpolation": cj["interpolation"]},
    }
    calibration = None
    if arm:
        from rrbc_core.analysis.arm_verdict import verdict_of as arm_verdict_of
        from rrbc_core.analysis.vec_compare import compare

        calibration = compare(mset, robot=robot, urdf=urdf, tip=tip, base=base, tool=tool, verdict=arm_verdict_of(dg))
        _with_calibration(points, calibration)
        for m in METHOD_NAMES:
            methods.setdefault(m, {})
            methods[m]["calibrate_rmst_mm"] = calibration["rmst_mm"][m]
            methods[m]["cv_rmst_mm"] = calibration["cv_rmst_mm"][m]
        recommended = calibration["recommended"]
        basis = f"rrbc calibrate's recommendation: {calibration['recommendation_basis']}"
    else:
        recommended = "rrbc" if rrbc_ok else "rigid"
        shown = (
            ""
            if gain is None
            else f" (paired test of the squared errors over {gain['n']} points, p {gain['p_gain']:.2g})"
        )
        basis = (
            f"RRBC lowers the RMS error and the points show it{shown}"
            if rrbc_ok
            else f"the points do not show a gain from RRBC{shown}, so rigid"
        )
    verdict, failing, reason = verdict_of(points, recommended, tolerance_mm)
    regs = [{"group": p.get("group"), **p["registration"]} for p in _parts(cj)]
    n_checks = sum(p["role"] == "check" for p in points)
    return {
        "verdict": verdict,
        "tolerance_mm": tolerance_mm,
        "criterion": (
            f"every target's 95 % bound and every check's 3-D error, for the recommended method "
            f"({METHOD_NAMES[recommended]}), at most the tolerance"
        ),
        "reason": reason,
        "failing": failing,
        "recommended": recommended,
        "recommendation_basis": basis,
        "methods": methods,
        "points": points,
        "measured": {
            "source": mset.source,
            "rows": len(mset.ids),
            "stations": list(group_names(mset)) if has_groups(mset) else [],
            "fiducials": sum(len(p["fiducials"]) for p in _parts(cj)),
            "targets": len(points) - n_checks,
            "checks": n_checks,
            "instrument": _parts(cj)[0]["bounds"]["instrument"],  # the first station's (each estimates its own)
            "arm": None if calibration is None else calibration["robot"],
        },
        "registration": regs,
        # VEC's sensor-to-robot transform, identified with the arm (calibrate's `sensor_to_robot`): null without a model
        "arm_transform": None if calibration is None else calibration["sensor_to_robot"],
        "check_statistics": cj.get("check_statistics"),
        "diagnosis": {"effects": effects, "limits": limits, "rrbc_gain": gain},
        "warnings": list(cj.get("warnings") or []),
    }
