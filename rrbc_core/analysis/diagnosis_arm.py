"""The arm in `rrbc diagnose`: with joint values in the file (the columns of the robot model, `io.joints`), an error
of the arm's kinematic parameters is a test like scale or affine (docs/theory.md §6.5).

The model: `--urdf FILE [--tip LINK] [--base LINK]` or `--robot ur5|ur10` (columns q1..q6, degrees), with `--tool`
(`robot_model.robot_chain`). Before the test, the model is held against the file's robot columns
(`robot_model.check_model`): a model chosen on the command line that does not describe the robot is refused (one
line, the disagreement in mm); without a choice, q1..q6 columns are tried as a UR5 and, if the UR5 does not describe
them, the kinematic test is left out and the limits say why — no `kinematic` effect is named with a wrong arm.

Model. A row measured at joints q has the residual r = robot − (R sensor + t) = FK(0, q) − FK(δ, q) ≈ −J(q) δ to
first order, J = ∂FK/∂δ at the nominal arm (`calibration.position_jacobian`: joint offsets, the joints' origins, the
tool point; angles scaled to mm). The test's columns are J at each point (the mean over the point's rows: a point
measured in several configurations has the mean of their errors), and the F-test counts only the combinations these
poses determine beside the rigid (and accepted) terms. A uniform scale lies inside this span (all lengths scaled
together scale the arm), so with joint values a scale that the arm explains is reported as kinematic; an error that
depends on the configuration (the same place reached two ways disagreeing) has no place in any position-only term.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.analysis.calibration import position_jacobian
from rrbc_core.analysis.robot_model import ModelCheck, check_model, robot_chain
from rrbc_core.errors import InputError
from rrbc_core.io.joints import joint_values
from rrbc_core.io.measurements import MeasurementSet

MIN_POINTS = 12  # fewer paired points with joints: the kinematic test is not run (said in the limits)


@dataclass(frozen=True, eq=False)
class ArmColumns:
    """Per paired point `fields` (P, N, 3) mm per scaled parameter (the mean over its rows), per paired row
    `row_fields` (R, 3, P), the robot's name, its tip link and tool point (3,) mm, and the model check."""

    fields: np.ndarray
    row_fields: np.ndarray
    robot: str
    tip: str
    tool_mm: tuple
    check: ModelCheck


@dataclass(frozen=True)
class ArmModel:
    """The arm's model as `rrbc diagnose` was asked for it: `robot` (ur5, ur10 or None: not chosen), or `urdf` with
    `tip` and `base`; `tool` a length along the DH flange's z axis or a point (3,) in the tip link's frame (mm)."""

    robot: str | None = None
    urdf: str | None = None
    tip: str | None = None
    base: str | None = None
    tool: object = None

    @property
    def chosen(self) -> bool:
        return self.robot is not None or self.urdf is not None


def arm_columns(
    mset: MeasurementSet, rows: np.ndarray, row_point: np.ndarray, n_points: int, model: ArmModel, limits: list
) -> ArmColumns | None:
    """`ArmColumns` for the paired rows `rows` (indices into the file) grouped by `row_point`, or None when the file
    has no joint columns of the model, or (a model not chosen) the UR5 does not describe them: then `limits` says so.
    Raises InputError for a bad model, bad joint columns, or a chosen model that does not describe the robot."""
    chain = robot_chain(model.robot, model.urdf, model.tip, model.base, model.tool)
    q = joint_values(mset, chain)
    if q is None:
        if model.urdf is not None:
            raise InputError(
                f"{mset.source}: no joint columns of {chain.name} ({', '.join(chain.columns)}): the kinematic test "
                "needs each row's joint values"
            )
        return None
    b = np.asarray(mset.robot, float)[rows]
    check = check_model(chain, q[rows], b)
    if not check.passed:
        if model.chosen:
            raise InputError(check.message(mset.source, chain))
        limits.append(
            f"the joint columns are not a UR5's (with this tool): its forward kinematics lies {check.rms_mm:.1f} mm RMS "
            "from the robot columns, so the arm's kinematic error was not tested; give the robot's model (--robot or "
            "--urdf, --tip) and its tool (--tool)"
        )
        return None
    jac = position_jacobian(chain, q[rows])  # (R, 3, P)
    mean = np.zeros((n_points, 3, jac.shape[2]))
    np.add.at(mean, row_point, jac)
    mean /= np.bincount(row_point, minlength=n_points)[:, None, None]
    return ArmColumns(np.moveaxis(mean, 2, 0), jac, chain.name, chain.tip, tuple(chain.tool.tolist()), check)
