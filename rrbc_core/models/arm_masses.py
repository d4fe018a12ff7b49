"""The masses of the scenes' DH arm, for the error term `compliance` (`errorterms.Compliance`, robot side): a six-axis
DH arm that gives way under its own weight, so the scenes' simulation, the explorer and the Monte Carlo can show a
bending arm (docs/theory.md §5.1; the model is the one `rrbc calibrate --compliance` identifies,
docs/calibration.md "Compliance").

The arm's links carry the masses and centres of mass of `UR5_LINKS` (kg; m in each link's distal DH frame: the
masses of the UR5 description shipped by example-robot-data, centres of mass near mid-link), plus an optional
payload at the tool point. For a physical point p reached with tool rotation R_p, the joints that put the arm
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


def dh_chain_with_masses(dh: DHParameters, payload_kg: float = 0.0) -> Chain:
    """The DH arm as a `Chain` (`Chain.from_dh`) with `UR5_LINKS`' masses and a payload at the tool point: segment k
    (after joint k's motion, F_k) holds link k + 1, whose distal DH frame is F_k · link(k) — the next joint's origin
    in the chain (the tail for the last link)."""
    chain = Chain.from_dh(dh, "ur5")
    links = [j.origin for j in chain.joints[1:]] + [chain.tail]  # link(k): F_k -> distal DH frame k + 1
    inertia = np.zeros((6, 4))
    for k, ((mass, com), frame) in enumerate(zip(UR5_LINKS, links)):
        inertia[k] = (mass, *(frame[:3, :3] @ (np.array(com) * 1000.0) + frame[:3, 3]))
    if payload_kg > 0:  # the payload at the tool point, in F_6
        tool = chain.tail[:3, :3] @ chain.tool + chain.tail[:3, 3]
        total = inertia[5, 0] + payload_kg
        inertia[5, 1:] = (inertia[5, 0] * inertia[5, 1:] + payload_kg * tool) / total
        inertia[5, 0] = total
    return Chain(chain.name, chain.base, chain.tip, chain.joints, chain.inputs, chain.tail, chain.tool, chain.source,
                 inertia)  # fmt: skip


__all__ = ["UR5_LINKS", "dh_chain_with_masses"]
