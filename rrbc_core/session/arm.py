"""The arm as the app draws it: the scene's robot posed (by the nominal controller's inverse kinematics) to reach
a place, and where the real, biased arm's tool then lands.

Frames and units: robot base frame, mm, rad. A scene's kinematic error term (models.errorterms.Kinematic)
stands for the real arm (perturbed DH parameters); the controller knows only the nominal ones. Commanded to put
its tool at p with the tool pointing down, the controller solves q = IK_nominal(p); the real arm at q puts its
tool at FK_real(q) ≠ p. With the bias size b (the app's "Bias size ×") the landing is p + b·(FK_real(q) − p).
A scene without a kinematic term has no real arm to differ: the landing is p.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.models.kinematics import (
    ROBOT_DH,
    UR5_TOOL_DOWN_SEED,
    forward,
    inverse,
    inverse_path,
    joint_frames,
    tool_down,
)


@dataclass(frozen=True, eq=False)
class ArmPose:
    """`joints` (6,) rad; `frames` (8, 4, 4) of the nominal arm (kinematics.joint_frames); `commanded` (3,) the
    place the tool was sent to; `landed` (3,) where the real arm's tool arrives (mm, robot frame)."""

    joints: np.ndarray
    frames: np.ndarray
    commanded: np.ndarray
    landed: np.ndarray


def _kinematic_term(error_model):
    for side in ("robot", "sensor"):
        for term in error_model.terms(side):
            if hasattr(term, "true_robot"):
                return term
    return None


def arm_pose(scene, position, bias_scale: float = 1.0, tool_rotation=None) -> ArmPose:
    """The scene's arm reaching `position` (3,) mm with its tool pointing down (module docstring), or with the tool
    rotation `tool_rotation` (3, 3) robot frame (a target reached with a leaned tool, `vec_view.tool_rotation`).

    Raises InputError if the scene has no arm model or the place is out of reach."""
    model = getattr(scene, "robot_model", None)
    if model not in ROBOT_DH:
        raise InputError(f"this cell has no arm model to draw (robot model {model!r}; arms: {', '.join(ROBOT_DH)})")
    p = np.asarray(position, float).reshape(3)
    term = _kinematic_term(scene.error_model)
    nominal = term.dh if term is not None else ROBOT_DH[model].with_tool(scene.tool_mm)
    seed = UR5_TOOL_DOWN_SEED if scene.joint_seed is None else scene.joint_seed
    rot = tool_down(scene.tool_yaw_deg) if tool_rotation is None else np.asarray(tool_rotation, float)
    q = inverse_path(nominal, p[None], rot, seed)[0] if tool_rotation is not None else inverse(nominal, p, rot, seed)
    landed = p
    if term is not None:
        real, _ = forward(term.true_robot(), q)
        landed = p + float(bias_scale) * (np.asarray(real, float) - p)
    return ArmPose(q, joint_frames(nominal, q), p, landed)
