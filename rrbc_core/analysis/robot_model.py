"""The robot model a command uses, and the check that it describes the robot before anything is fitted with it.

Choosing (`robot_chain`): `--urdf FILE [--tip LINK] [--base LINK]` (any robot: `models.urdf.load_urdf`), or
`--robot ur5|ur10` (the DH tables of `models.kinematics` as a `Chain`, columns q1..q6 in degrees); `--tool` adds a
tool point in the tip link's frame (mm).

Checking (`check_model`, docs/calibration.md "Is it this robot?"). The robot columns of a file are the controller's
own positions of the tool point, computed from the same joint values in the same base frame; so the nominal model's
forward kinematics of each row's joints must land on its robot columns with no fit at all, to within what kinematic
errors are: `MODEL_CHECK_MM`, 25 mm RMS. Why 25 mm: what a calibration identifies are small errors of a model that
is right — joint zero offsets of a fraction of a degree, origins off by a few mm; an uncalibrated industrial arm's
absolute position error is a few mm and rarely above 10 mm even at full reach, and the linearised identification is
valid only while errors are that small. A disagreement beyond 25 mm RMS is another arm, another tip or tool, joint
columns in another order or unit, or robot columns in another frame (a user or work-object frame) — a calibration
would "identify" metres of error. The commands then refuse in one line naming the disagreement in mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.models.chain import Chain
from rrbc_core.models.kinematics import ROBOT_DH

MODEL_CHECK_MM = 25.0  # RMS disagreement (mm) beyond which the model does not describe the robot (module docstring)


def robot_chain(
    robot: str | None = None, urdf=None, tip: str | None = None, base: str | None = None, tool=None
) -> Chain:
    """The chain a command works with (module docstring). `tool`: None, a length along the DH flange's z axis
    (a number, mm) or a point (3,) in the tip link's frame (mm)."""
    if urdf is not None:
        from rrbc_core.models.urdf import load_urdf

        chain = load_urdf(urdf, tip=tip, base=base)
    else:
        if tip is not None or base is not None:
            raise InputError("--tip and --base choose links of a URDF: give --urdf")
        name = robot or "ur5"
        if name not in ROBOT_DH:
            raise InputError(f"--robot must be one of {', '.join(ROBOT_DH)}, got {name!r} (or give --urdf)")
        from rrbc_core.models.arm_masses import dh_chain_with_masses

        chain = dh_chain_with_masses(ROBOT_DH[name])  # with its links' masses: compliance can be tested and identified
    if tool is None:
        return chain
    t = np.asarray(tool, float)
    return chain.with_tool(np.array([0.0, 0.0, float(t)]) if t.ndim == 0 else t.reshape(3))


@dataclass(frozen=True)
class ModelCheck:
    """The nominal model against the robot columns: RMS and largest disagreement (mm) over `rows` rows."""

    rms_mm: float
    max_mm: float
    rows: int

    @property
    def passed(self) -> bool:
        return self.rms_mm <= MODEL_CHECK_MM

    def message(self, source: str, chain: Chain) -> str:
        return (
            f"{source}: the robot model {chain.name} ({chain.base} → {chain.tip}) does not describe this robot: its "
            f"forward kinematics of the file's joint values lies {self.rms_mm:.1f} mm RMS (max {self.max_mm:.1f} mm) "
            f"from the robot columns over {self.rows} rows, beyond the {MODEL_CHECK_MM:g} mm kinematic errors can "
            "explain; check the model (--urdf/--robot, --tip, --base, --tool), the joint columns and that the robot "
            "columns are in the base link's frame"
        )

    def to_json(self) -> dict:
        return {"rms_mm": self.rms_mm, "max_mm": self.max_mm, "rows": self.rows, "threshold_mm": MODEL_CHECK_MM}


def check_model(chain: Chain, q, b_robot) -> ModelCheck:
    """Hold the nominal forward kinematics of joint values q (N, I) against robot readings b_robot (N, 3) (mm, the
    chain's base frame), with no fit."""
    b = np.asarray(b_robot, float).reshape(-1, 3)
    d = np.linalg.norm(chain.forward(q) - b, axis=1)
    return ModelCheck(float(np.sqrt(np.mean(d**2))), float(d.max()), int(len(d)))


def require_model(chain: Chain, q, b_robot, source: str) -> ModelCheck:
    """`check_model`, refusing (InputError, one line) a model that does not describe the robot."""
    check = check_model(chain, q, b_robot)
    if not check.passed:
        raise InputError(check.message(source, chain))
    return check
