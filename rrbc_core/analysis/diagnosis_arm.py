"""The arm in `rrbc diagnose`: with joint angles in the file (columns q1..q6, degrees), an error of the arm's
kinematic (DH) parameters is a test like scale or affine (docs/theory.md §6.5).

Model. A row measured at joints q has the residual r = robot − (R sensor + t) = FK(θ₀, q) − FK(θ₀ + δ, q) ≈
−J(q) δ to first order, J = ∂FK/∂θ at the nominal arm (`calibration.position_jacobian`: 25 parameters — joint
offsets, a, d, α, tool — angles scaled to mm). The test's columns are J at each point (the mean over the point's
rows: a point measured in several configurations has the mean of their errors), and the F-test counts only the
combinations these poses determine beside the rigid (and accepted) terms. A uniform scale lies inside this span
(all lengths scaled together scale the arm), so with joint angles a scale that the arm explains is reported as
kinematic; an error that depends on the configuration (the same place reached two ways disagreeing) has no
place in any position-only term.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.analysis.calibration import position_jacobian
from rrbc_core.errors import InputError
from rrbc_core.io.joints import joint_angles
from rrbc_core.models.kinematics import ROBOT_DH

MIN_POINTS = 12  # fewer paired points with joints: the kinematic test is not run (said in the limits)


@dataclass(frozen=True, eq=False)
class ArmColumns:
    """Per paired point `fields` (25, N, 3) mm per scaled parameter (the mean over its rows), per paired row
    `row_fields` (R, 3, 25), the robot name and the tool length (mm)."""

    fields: np.ndarray
    row_fields: np.ndarray
    robot: str
    tool_mm: float


def arm_columns(mset, rows: np.ndarray, row_point: np.ndarray, n_points: int, robot: str, tool_mm: float):
    """`ArmColumns` for the paired rows `rows` (indices into the file) grouped by `row_point`, or None when the
    file has no joint columns. Raises InputError for a bad robot name or bad joint columns."""
    if robot not in ROBOT_DH:
        raise InputError(f"--robot must be one of {', '.join(ROBOT_DH)}, got {robot!r}")
    q = joint_angles(mset)
    if q is None:
        return None
    jac = position_jacobian(ROBOT_DH[robot].with_tool(float(tool_mm)), q[rows])  # (R, 3, 25)
    mean = np.zeros((n_points, 3, jac.shape[2]))
    np.add.at(mean, row_point, jac)
    mean /= np.bincount(row_point, minlength=n_points)[:, None, None]
    return ArmColumns(np.moveaxis(mean, 2, 0), jac, robot, float(tool_mm))
