"""The masses of the packaged DH arms (UR5, UR10), for the error term `compliance` (`errorterms.Compliance`, robot
side) and for `--robot ur5|ur10 --compliance`: a six-axis DH arm that gives way under its own weight, so the scenes'
simulation, the explorer and the Monte Carlo can show a bending arm and `rrbc diagnose` / `rrbc calibrate` can test
and identify it (docs/theory.md §5.1; the model is the one `rrbc calibrate --compliance` identifies,
docs/calibration.md "Compliance").

The links carry the masses and centres of mass of `UR5_LINKS` or `UR10_LINKS` (kg; m in each link's distal DH
frame; sources in docs/calibration.md "Compliance"), plus an optional payload at the tool point. A DH table that is
neither (a scene's own `dh`) takes the links of the packaged arm whose upper-arm and forearm lengths are nearest
(`links_for`). For a physical point p reached with tool rotation R_p, the joints that put the arm
there are q = IK(p, R_p) (as the `kinematic` term solves them); the gravity torque τ(q) about each joint (along the
base frame's −z) deflects joint i by c_i τ_i, so the controller commanded q − c τ to get there and reports
FK(q − c τ). Displacement = reported − p (mm): zero where the arm is not loaded, largest stretched out.
"""

from __future__ import annotations

import numpy as np

from rrbc_core.models.chain import Chain
from rrbc_core.models.kinematics import DHParameters

#: per link 1..6: mass (kg) and centre of mass (x, y, z) in metres in the link's distal DH frame
UR5_LINKS = (
    (3.7, (0.0, -0.02561, 0.00193)),
    (8.393, (0.2125, 0.0, 0.11336)),
    (2.275, (0.15, 0.0, 0.0265)),
    (1.219, (0.0, -0.0018, 0.01634)),
    (1.219, (0.0, 0.0018, 0.01634)),
    (0.1879, (0.0, 0.0, -0.001159)),
)

#: the UR10 (CB3): per link 1..6, mass (kg) and centre of mass (m) in the link's distal DH frame, as Universal Robots
#: publishes them with the CB3 UR10's DH table
UR10_LINKS = (
    (7.1, (0.021, 0.0, 0.027)),
    (12.7, (0.38, 0.0, 0.158)),
    (4.27, (0.24, 0.0, 0.068)),
    (2.0, (0.0, 0.007, 0.018)),
    (2.0, (0.0, 0.007, 0.018)),
    (0.365, (0.0, 0.0, -0.026)),
)

#: the packaged arms' links by name (`kinematics.ROBOT_DH`)
ARM_LINKS = {"ur5": UR5_LINKS, "ur10": UR10_LINKS}


def links_for(dh: DHParameters) -> tuple[str, tuple]:
    """The packaged arm (name, links) whose upper-arm and forearm lengths |a2|, |a3| (mm) are nearest `dh`'s."""
    from rrbc_core.models.kinematics import ROBOT_DH

    size = np.abs(np.asarray(dh.a, float)[1:3])
    name = min(ARM_LINKS, key=lambda n: float(np.sum((np.abs(ROBOT_DH[n].a[1:3]) - size) ** 2)))
    return name, ARM_LINKS[name]


def dh_chain_with_masses(dh: DHParameters, payload_kg: float = 0.0) -> Chain:
    """The DH arm as a `Chain` (`Chain.from_dh`) with its packaged arm's masses (`links_for`) and a payload at the tool
    point: segment k (after joint k's motion, F_k) holds link k + 1, whose distal DH frame is F_k · link(k) — the
    next joint's origin in the chain (the tail for the last link)."""
    name, masses = links_for(dh)
    chain = Chain.from_dh(dh, name)
    links = [j.origin for j in chain.joints[1:]] + [chain.tail]  # link(k): F_k -> distal DH frame k + 1
    inertia = np.zeros((6, 4))
    for k, ((mass, com), frame) in enumerate(zip(masses, links)):
        inertia[k] = (mass, *(frame[:3, :3] @ (np.array(com) * 1000.0) + frame[:3, 3]))
    if payload_kg > 0:  # the payload at the tool point, in F_6
        tool = chain.tail[:3, :3] @ chain.tool + chain.tail[:3, 3]
        total = inertia[5, 0] + payload_kg
        inertia[5, 1:] = (inertia[5, 0] * inertia[5, 1:] + payload_kg * tool) / total
        inertia[5, 0] = total
    return Chain(chain.name, chain.base, chain.tip, chain.joints, chain.inputs, chain.tail, chain.tool, chain.source,
                 inertia)  # fmt: skip


__all__ = ["ARM_LINKS", "UR10_LINKS", "UR5_LINKS", "dh_chain_with_masses", "links_for"]
