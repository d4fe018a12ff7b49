"""How well `rrbc calibrate`'s recommendation (`analysis.vec_compare`, `analysis.extrapolation_cv`) holds where the
checks lie beyond the fiducials (issue 38): seeded files with joint columns, the roles reassigned so the fiducials
cover one part of the poses and the checks another, and the method recommended without the checks held against
the best at them.

Regimes (every file simulated with `simulation.arm_data.chain_measurements` (our lift-column arm) or
`studies.vec_study.joint_measurements` (a UR5): the arm's kinematic errors, a smooth sensor field, or both):

- **corner**: the fiducials the n poses nearest one corner of the data (sensor frame), the checks the farthest third
  (`far_checks`): hundreds of poses or a few dozen;
- **board**: the fiducials the poses within a few mm of one height (a board, coplanar to 2 %), the checks those far
  above or below it (`board_fiducials`): no held-out fiducial can test the direction off the board.

This is a simulation of the arm model's own structure (random joint values, a smooth field); it says how the rule
behaves on data of these shapes, not how a real arm behaves.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from rrbc_core.io.measurements import MeasurementSet

METHODS = ("rigid", "rrbc", "vec", "vec_rrbc")
#: (kinematic error size, sensor field RMS mm) of the three cells
CELLS = {"kinematic": (1.0, 0.0), "field": (0.0, 1.0), "both": (0.5, 0.5)}


def with_roles(mset: MeasurementSet, roles) -> MeasurementSet:
    """The rows of `mset` whose new role (array over rows) is not "drop", with those roles."""
    roles = np.asarray(roles, dtype=object)
    keep = np.flatnonzero(roles != "drop")

    def pick(a):
        return np.asarray(a)[keep]

    return replace(
        mset,
        ids=tuple(pick(mset.ids)),
        roles=tuple(pick(roles)),
        sensor=pick(mset.sensor),
        robot=pick(mset.robot),
        time=pick(mset.time),
        lines=tuple(0 for _ in keep),
        extra={k: tuple(pick(v)) for k, v in mset.extra.items()},
    )


def far_checks(mset: MeasurementSet, n_fid: int) -> MeasurementSet:
    """The fiducials: the n_fid fiducial and check rows nearest the corner of their bounding box (sensor frame,
    lowest x, y, z); the checks: the farthest third; registration rows kept, the rest dropped."""
    s = np.asarray(mset.sensor)
    roles = np.array(mset.roles, dtype=object)
    free = np.flatnonzero(np.isin(roles, ("fiducial", "check")))
    order = free[np.argsort(np.linalg.norm(s[free] - s[free].min(axis=0), axis=1))]
    roles[free] = "drop"
    roles[order[:n_fid]] = "fiducial"
    roles[order[-len(order) // 3 :]] = "check"
    return with_roles(mset, roles)


def board_fiducials(mset: MeasurementSet, half_mm: float = 5.0, off_mm: float = 300.0) -> MeasurementSet:
    """The fiducials: the fiducial and check rows within half_mm of their median height (sensor z); the checks:
    those more than off_mm above or below it; registration rows kept, the rest dropped."""
    s = np.asarray(mset.sensor)
    roles = np.array(mset.roles, dtype=object)
    free = np.flatnonzero(np.isin(roles, ("fiducial", "check")))
    z = s[:, 2] - np.median(s[free, 2])
    roles[free] = "drop"
    roles[free[np.abs(z[free]) <= half_mm]] = "fiducial"
    roles[free[np.abs(z[free]) > off_mm]] = "check"
    return with_roles(mset, roles)


def cases(quick: bool = False) -> list[tuple[dict, MeasurementSet, dict[str, Any]]]:
    """(description, file, `compare` keyword arguments) of every case (module docstring)."""
    from rrbc_core.models.urdf import load_urdf
    from rrbc_core.simulation.arm_data import chain_measurements
    from rrbc_core.studies.vec_study import joint_measurements

    chain = load_urdf("lift_arm")
    lift: dict[str, Any] = {"urdf": "lift_arm"}
    seeds = (1,) if quick else (1, 2, 3)
    out = []
    for seed in seeds:
        for cell, (kin, field) in CELLS.items():
            full = chain_measurements(
                chain, seed, n_fid=400, n_chk=200, n_tgt=0, noise_mm=0.05, kin_size=kin, field_mm=field
            )
            out.append(
                (
                    {"regime": "corner", "arm": "lift", "cell": cell, "seed": seed, "fiducials": 300},
                    far_checks(full, 300),
                    lift,
                )
            )
            small = chain_measurements(
                chain, seed, n_fid=150, n_chk=80, n_tgt=0, noise_mm=0.05, kin_size=kin, field_mm=field
            )
            for n in (15, 40):
                out.append(
                    (
                        {"regime": "corner", "arm": "lift", "cell": cell, "seed": seed, "fiducials": n},
                        far_checks(small, n),
                        lift,
                    )
                )
            board = chain_measurements(
                chain, seed, n_fid=4000, n_chk=0, n_tgt=0, noise_mm=0.05, kin_size=kin, field_mm=field
            )
            b = board_fiducials(board)
            n_b = sum(r == "fiducial" for r in b.roles)
            out.append(({"regime": "board", "arm": "lift", "cell": cell, "seed": seed, "fiducials": n_b}, b, lift))
        ur5 = joint_measurements(seed, n_fid=400, n_chk=200, n_tgt=0)
        out.append(
            (
                {"regime": "corner", "arm": "ur5", "cell": "kinematic", "seed": seed, "fiducials": 300},
                far_checks(ur5, 300),
                {"robot": "ur5", "tool": 100.0},
            )
        )
    return out


def run(quick: bool = False, progress=None) -> list[dict]:
    """Every case's figures: RMS at the checks per method, the recommended method, its ratio to the best, the share
    of checks beyond the fiducials and the buffered folds run."""
    from rrbc_core.analysis.vec_compare import compare

    rows = []
    todo = cases(quick)
    for k, (desc, mset, kw) in enumerate(todo):
        if progress is not None:
            progress(k + 1, len(todo))
        res = compare(mset, **kw)
        rm = res["rmst_mm"]
        best = min(rm, key=rm.get)
        rows.append(
            {
                **desc,
                "rmst_mm": rm,
                "best": best,
                "recommended": res["recommended"],
                "ratio": rm[res["recommended"]] / rm[best],
                "beyond_share": res["extrapolated_share"],
                "folds": res["extrapolation_folds"],
            }
        )
    return rows
