"""The arm as the app draws it: the scene's robot posed (by the nominal controller's inverse kinematics) to reach
a place, and where the real, biased arm's tool then lands.

Frames and units: robot base frame, mm, rad. A scene's kinematic error term (models.errorterms.Kinematic)
stands for the real arm (perturbed DH parameters); the controller knows only the nominal ones. Commanded to put
its tool at p with the tool pointing down, the controller solves q = IK_nominal(p); the real arm at q puts its
tool at FK_real(q) ≠ p. With the bias size b (the app's "Bias size ×") the landing is p + b·(FK_real(q) − p).
A scene without a kinematic term has no real arm to differ: the landing is p.

What is drawn (`arm_description`): the arm's own URDF with its meshes — a DH arm's packaged description (the same
joints), or a scene's `robot.urdf` for a robot the kinematics do not model, posed by damped least squares on its
tool point (`urdf_pose`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.models.arm_description import ArmDescription, dh_arm_description, reach, urdf_arm_description
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
    """`joints` (I,) the arm's joint values (rad, mm for prismatic joints): a DH arm's six, or a URDF chain's inputs;
    `frames` (8, 4, 4) of the nominal DH arm (kinematics.joint_frames), None for an arm drawn from a URDF only;
    `commanded` (3,) the place the tool was sent to; `landed` (3,) where the real arm's tool arrives (mm, robot
    frame)."""

    joints: np.ndarray
    frames: np.ndarray | None
    commanded: np.ndarray
    landed: np.ndarray


def arm_description(scene) -> ArmDescription | None:
    """The URDF the app draws the scene's arm from (models.arm_description): the scene's `robot.urdf`, else the
    packaged description of its DH arm with the scene's tool; None for a robot without either, or when the packaged
    description cannot be had (the app then draws generated links)."""
    urdf = getattr(scene, "robot_urdf", None)
    tool = float(getattr(scene, "tool_mm", 0.0) or 0.0)
    if urdf is not None:
        return urdf_arm_description(urdf, tip=scene.robot_tip, tool_mm=(0.0, 0.0, tool))
    if getattr(scene, "robot_model", None) in ROBOT_DH:
        try:
            return dh_arm_description(scene.robot_model, tool)
        except InputError:
            return None
    return None


def urdf_pose(desc: ArmDescription, position, seed=None) -> ArmPose:
    """A URDF arm (no DH model, no error term) reaching `position` (3,) mm with its tool point (`reach`): it lands
    where it is sent. Raises InputError out of reach."""
    p = np.asarray(position, float).reshape(3)
    q = reach(desc, p, seed)
    return ArmPose(q, None, p, p)


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
    if model not in ROBOT_DH and getattr(scene, "robot_urdf", None) is not None:
        desc = arm_description(scene)
        assert desc is not None
        return urdf_pose(desc, position)
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


_ROLES = {"registration": ("registration", "both"), "fiducials": ("fiducial", "both"), "targets": ("target", "check")}


def _tool_hint(chain, q: np.ndarray, robot: np.ndarray, limit_mm: float) -> str:
    """Words for a model that misses the robot columns: when a tool point in the tip link's frame, fitted by least
    squares (robot ≈ p_tip(q) + R_tip(q) t), brings it within `limit_mm` RMS, that tool (give --tool); else "" (the
    URDF, its tip or its base is not this robot's)."""
    zero = chain.with_tool(np.zeros(3))
    p0 = zero.forward(q)
    cols = np.stack([zero.with_tool(np.eye(3)[k]).forward(q) - p0 for k in range(3)], axis=2)  # (N, 3, 3) = R_tip
    tool, *_ = np.linalg.lstsq(cols.reshape(-1, 3), (robot - p0).reshape(-1), rcond=None)
    rms = float(np.sqrt(np.mean(np.sum((p0 + np.einsum("nij,j->ni", cols, tool) - robot) ** 2, axis=1))))
    if rms > limit_mm or not np.all(np.isfinite(tool)):
        return ""
    tool = np.where(np.abs(tool) < 0.05, 0.0, tool)  # no "-0.0"
    shown = ",".join(f"{v:.1f}" for v in tool)
    if not np.any(tool):
        return f"; with no tool (the tip link's origin) it fits ({rms:.2f} mm RMS): leave out --tool"
    return (
        f"; with a tool point at ({shown}) mm in the tip link's frame it fits ({rms:.2f} mm RMS): give --tool {shown}"
    )


def attach_arm(session, urdf, tip: str | None = None, base: str | None = None, tool=None) -> None:
    """Give a session on measured data its robot (`rrbc view data.csv --urdf`): the URDF's description and each
    point's joint values from the file's joint columns (`io.joints.joint_values`), after holding the model against
    the robot columns as `rrbc calibrate` does (the nominal forward kinematics of the registration and fiducial rows
    within `analysis.robot_model.MODEL_CHECK_MM` RMS of their robot readings, else the URDF, its tip or its base is
    not this robot's).

    Sets ``session.arm`` (ArmDescription), ``session.arm_joints`` {(kind, id): (I,) rad or mm} and
    ``session.arm_spec`` (urdf, tip, base, tool: kept when another station opens). `tool` (3,) mm in the tip link's
    frame (default: the file's tool columns, `io.joints.file_tool`, else the tip link's origin). Raises InputError
    naming what is missing or wrong (a tool that would make the model fit is named)."""
    from rrbc_core.analysis.robot_model import MODEL_CHECK_MM
    from rrbc_core.io.joints import file_tool, joint_values

    mset = session.mset
    if session.kind != "measurements" or mset is None:
        raise InputError("--urdf poses the robot of a measurement file; a scene names its own (robot.urdf)")
    if tool is None:
        tool = file_tool(mset)
    if tool is not None:  # a length Z is a point along the tip link's z axis (as `rrbc calibrate --tool Z`)
        t = np.asarray(tool, float)
        tool = np.array([0.0, 0.0, float(t)]) if t.ndim == 0 else t.reshape(3)
    desc = urdf_arm_description(urdf, tip=tip, base=base, tool_mm=tool)
    q = joint_values(mset, desc.chain)
    if q is None:
        raise InputError(
            f"{mset.source}: no joint columns ({', '.join(desc.chain.columns)}): the robot cannot be posed at its "
            "points"
        )
    roles = np.array(mset.roles)
    known = np.flatnonzero(np.isin(roles, ("registration", "fiducial", "both")) & np.all(np.isfinite(mset.robot), 1))
    if len(known):
        d = np.linalg.norm(desc.chain.forward(q[known]) - mset.robot[known], axis=1)
        rms = float(np.sqrt(np.mean(d**2)))
        if rms > MODEL_CHECK_MM:
            hint = _tool_hint(desc.chain, q[known], mset.robot[known], MODEL_CHECK_MM)
            raise InputError(
                f"{mset.source}: {desc.chain.name} ({desc.chain.base} → {desc.chain.tip}, tool "
                f"({', '.join(f'{v:g}' for v in desc.chain.tool)}) mm) places the registration and fiducial rows "
                f"{rms:.1f} mm RMS from their robot columns (at most {MODEL_CHECK_MM:g} mm)"
                + (hint or ": not this robot, or another --tip, --base or --tool")
            )
    joints: dict[tuple[str, str], np.ndarray] = {}
    for kind, which in _ROLES.items():
        for i in np.flatnonzero(np.isin(roles, which)):
            joints.setdefault((kind, mset.ids[i]), q[i])
    session.arm, session.arm_joints, session.arm_spec = desc, joints, (urdf, tip, base, tool)


def measured_arm_pose(session, kind: str, pid: str) -> ArmPose:
    """The robot of a measured session (`attach_arm`) at the joint values of point (kind, id): its tool where the
    nominal model puts it (commanded and landed alike: measured data hold no second arm). Raises InputError for a
    point without joint values."""
    q = getattr(session, "arm_joints", {}).get((kind, pid))
    if q is None or session.arm is None:
        raise InputError(f"no joint values for {kind} {pid!r}")
    p = session.arm.tool_point(q)
    return ArmPose(np.asarray(q, float), None, p, p)
