"""The robot as the app draws it from its URDF: which description, where its root link sits in the robot frame, its
joint values for a pose, and where its tool point is (issue 30: the real robot on screen).

Two sources:

- a scene's DH arm (`robot.model` ur5 or ur10): the description that ships with the `example-robot-data` package
  (`urdf.PACKAGED`). Its joints are the DH table's (same zeros, same senses); its root link is turned about the
  base's z axis against the DH base frame (the ROS ``base_link`` convention), which `dh_arm_description` measures
  by fitting the two chains' flange points over sampled poses (`ALIGN_TOL_MM`) rather than assuming it;
- a user's URDF (`urdf_arm_description`): a scene's ``[robot] urdf``/``tip`` or ``rrbc view data.csv --urdf``; its
  root link is the robot frame.

Frames: the robot (scene) frame, mm; joint values in the chain's units (rad, mm) unless stated (`joint_values_si`:
radians and metres, as URDFs and `yourdfpy` take them). `reach` solves the position of a URDF arm's tool point by
damped least squares (the DH arms keep their analytic inverse kinematics, `session.arm`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.models.chain import Chain
from rrbc_core.models.urdf import load_urdf, resolve_urdf

__all__ = ["ALIGN_TOL_MM", "ArmDescription", "dh_arm_description", "reach", "urdf_arm_description"]

#: Largest RMS distance (mm) between the packaged URDF's flange and the DH arm's over sampled poses for the two to
#: count as one arm.
ALIGN_TOL_MM = 0.01
#: The tip link of the packaged UR descriptions: the flange (the DH table's last frame).
_DH_TIP = "tool0"


@dataclass(frozen=True, eq=False)
class ArmDescription:
    """A robot drawn from a URDF (module docstring).

    `urdf`: the file; `chain`: its chain from the root link to `chain.tip`, tool point `chain.tool` (mm, tip
    frame); `rotation` (3, 3) and `translation` (3,) mm: the root link's frame in the robot frame
    (p_robot = rotation @ p_root + translation)."""

    urdf: Path
    chain: Chain
    rotation: np.ndarray
    translation: np.ndarray

    def joint_values_si(self, q) -> dict[str, float]:
        """{joint name: value} in radians and metres for the chain's inputs q (I,) (rad or mm)."""
        qa = np.asarray(q, float).reshape(len(self.chain.inputs))
        return {i.name: float(v) / (1000.0 if i.unit == "m" else 1.0) for i, v in zip(self.chain.inputs, qa)}

    def tip_frame(self, q) -> np.ndarray:
        """(4, 4) the tip link's frame in the robot frame at inputs q (I,), mm."""
        f_rot, f_pos = self.chain.frames(np.asarray(q, float)[None])[2:]
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = f_rot[0, -1], f_pos[0, -1]
        m = m @ self.chain.tail
        out = np.eye(4)
        out[:3, :3] = self.rotation @ m[:3, :3]
        out[:3, 3] = self.rotation @ m[:3, 3] + self.translation
        return out

    def tool_point(self, q) -> np.ndarray:
        """(3,) the tool point in the robot frame at inputs q (I,), mm."""
        p = self.chain.forward(np.asarray(q, float)[None])[0]
        return self.rotation @ p + self.translation

    def joint_points(self, q) -> np.ndarray:
        """(K + 2, 3) robot frame, mm, at inputs q (I,): the root link's origin, each moving joint's origin (before
        its motion) and the tip link's origin: what an arm is drawn from as links and joints when its URDF has no
        geometry of its own."""
        g_pos = self.chain.frames(np.asarray(q, float)[None])[1][0]  # (K, 3) root frame
        root = np.vstack([np.zeros(3), g_pos])
        return np.vstack([root @ self.rotation.T + self.translation, self.tip_frame(q)[:3, 3]])

    def has_geometry(self) -> tuple[bool, bool]:
        """(visual, collision): whether any link of the URDF has visual, or collision, geometry."""
        import yourdfpy

        robot = yourdfpy.URDF.load(
            str(self.urdf),
            build_scene_graph=False,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
        )
        links = robot.robot.links
        return any(link.visuals for link in links), any(link.collisions for link in links)


@lru_cache(maxsize=8)
def dh_arm_description(model: str, tool_mm: float = 0.0) -> ArmDescription:
    """The packaged URDF of the DH arm `model` (ur5, ur10), its root link placed so that its flange follows the DH
    arm's at the same joint values; the tool `tool_mm` along the flange's z axis.

    Raises InputError if the package lacks the description or the two do not agree to `ALIGN_TOL_MM`."""
    from rrbc_core.models.kinematics import ROBOT_DH
    from rrbc_core.registration.strategies import least_squares

    if model not in ROBOT_DH:
        raise InputError(f"no DH arm {model!r}: arms are {', '.join(ROBOT_DH)}")
    chain = load_urdf(model, tip=_DH_TIP, tool_mm=(0.0, 0.0, float(tool_mm)))
    dh = Chain.from_dh(ROBOT_DH[model], model, tool_mm=(0.0, 0.0, float(tool_mm)))
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (64, 6))
    reg = least_squares(chain.forward(q), dh.forward(q))
    if reg.fre_rms_mm > ALIGN_TOL_MM:
        raise InputError(
            f"the packaged {model} description's flange lies {reg.fre_rms_mm:.3g} mm RMS from the DH arm's: "
            "not the same arm"
        )
    return ArmDescription(
        Path(chain.source),
        chain,
        np.asarray(reg.mapping.rotation, float),
        np.asarray(reg.mapping.translation, float),
    )


def urdf_arm_description(urdf, tip: str | None = None, base: str | None = None, tool_mm=None) -> ArmDescription:
    """A user's URDF (a file or a packaged name), its root link (or `base`) the robot frame; `tool_mm` (3,) in the
    tip link's frame (default its origin). Raises InputError as `urdf.load_urdf`."""
    chain = load_urdf(urdf, tip=tip, base=base, tool_mm=tool_mm)
    return ArmDescription(resolve_urdf(urdf), chain, np.eye(3), np.zeros(3))


def _limits(chain: Chain) -> tuple[np.ndarray, np.ndarray]:
    lo = np.array([-np.inf if i.lower is None else i.lower for i in chain.inputs])
    hi = np.array([np.inf if i.upper is None else i.upper for i in chain.inputs])
    return lo, hi


def reach(desc: ArmDescription, point, seed=None, tol_mm: float = 0.01, iterations: int = 200) -> np.ndarray:
    """Inputs q (I,) (rad or mm) that put the description's tool point on `point` (3,) robot frame, mm, within the
    joints' limits, by damped least squares from `seed` (default the middle of the limits; then further starts).

    Raises InputError when no start reaches the point within `tol_mm` (out of reach)."""
    target = np.linalg.solve(desc.rotation, np.asarray(point, float).reshape(3) - desc.translation)
    chain = desc.chain
    lo, hi = _limits(chain)
    bounded = np.isfinite(lo) & np.isfinite(hi)
    mid = np.where(bounded, 0.5 * (np.where(bounded, lo, 0.0) + np.where(bounded, hi, 0.0)), 0.0)
    starts = [mid if seed is None else np.asarray(seed, float)]
    rng = np.random.default_rng(0)
    span = np.where(bounded, np.where(bounded, hi, 0.0) - np.where(bounded, lo, 0.0), 2 * np.pi)
    starts += [np.clip(mid + rng.uniform(-0.4, 0.4, len(mid)) * span, lo, hi) for _ in range(7)]
    best, best_err = None, np.inf
    for q in starts:
        q = np.clip(np.asarray(q, float), lo, hi)
        lam = 1.0
        for _ in range(iterations):
            p, _, jac = chain.kinematics(q[None])
            assert jac is not None
            r = target - p[0]
            err = float(np.linalg.norm(r))
            if err < tol_mm:
                break
            j = jac[0]
            step = j.T @ np.linalg.solve(j @ j.T + lam**2 * np.eye(3), r)
            q_new = np.clip(q + step, lo, hi)
            if float(np.linalg.norm(target - chain.forward(q_new[None])[0])) < err:
                q, lam = q_new, max(lam * 0.5, 1e-3)
            else:
                lam *= 4.0
        if err < best_err:
            best, best_err = q, err
        if best is not None and best_err < tol_mm:
            return best
    raise InputError(
        f"{chain.name} cannot put its tool on ({', '.join(f'{v:.1f}' for v in np.asarray(point).reshape(3))}) mm: "
        f"the nearest it reaches is {best_err:.1f} mm away"
    )
