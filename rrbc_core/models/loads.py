"""The arm under its own weight: gravity loads on a chain's joints and the elastostatic deflections they cause
(docs/calibration.md, "Compliance"). Calibration identifies these terms beside the geometric errors
(`analysis.calibration`), diagnosis tests them (`analysis.diagnosis_arm`), the simulation plants them
(`simulation.arm_data`).

Loads. Each moving joint k carries its segment (`Chain.inertia`: mass m_k, kg, centre c_k in its frame F_k) and
every segment after it. With gravity g (m/s², base frame; default `GRAVITY`, the base frame's −z) and the nominal
frames at the pose, the moment of that load about the joint's origin o_k is

    M_k = Σ_(j ≥ k) (c_j − o_k) × m_j g / 1000      N·m (positions in mm)

and the torque about a revolute joint's axis is τ_k = (R_k a_k) · M_k.

Terms (one coefficient each, named `<joint>.<kind>`):
- `compliance` (rad/Nm), revolute joints: the joint turns by Δq_k = c_k τ_k (a positive c: it gives way to the load);
- `bending` (rad/Nm), prismatic joints (a lift column): the joint's origin tilts by the rotation vector c_b M⊥ in its
  frame, M⊥ the part of the moment perpendicular to its axis — a column bending under the moment of the arm it
  carries;
- `backlash` (rad), revolute joints: Δq_k = b_k sign(τ_k), the play taken up in the direction of the load.

A term is a candidate only where the data can see it: its factor (τ, |M⊥| or sign τ) must vary across the poses by
at least `MIN_SPREAD` of the largest such spread and `MIN_TORQUE_NM` (a joint whose load hardly changes acts as a
zero offset, which the geometric terms already hold). Loads use the nominal arm at the commanded joints: the
deflections are small, so their own effect on the loads is second order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.models.chain import Chain

GRAVITY = (0.0, 0.0, -9.80665)  # m/s², the base frame's −z
KINDS = ("compliance", "bending", "backlash")
UNITS = {"compliance": "rad/Nm", "bending": "rad/Nm", "backlash": "rad"}
MIN_TORQUE_NM = 0.5  # a term whose factor varies less than this (N·m standard deviation) is not a candidate
MIN_SPREAD = 0.02  # ... or less than this fraction of the largest spread among the joints


@dataclass(frozen=True)
class LoadTerm:
    """One load-dependent term: `kind` in `KINDS`, on moving joint `joint` (index into `chain.joints`)."""

    name: str
    kind: str
    joint: int

    @property
    def unit(self) -> str:
        return UNITS[self.kind]


@dataclass(frozen=True, eq=False)
class Loads:
    """Gravity loads at N poses: `torque` (N, K) N·m about each revolute joint's axis (0 for prismatic joints),
    `moment_perp` (N, K, 3) N·m, each joint's moment perpendicular to its axis, in its frame G_k."""

    torque: np.ndarray
    moment_perp: np.ndarray


def gravity_vector(gravity=None) -> np.ndarray:
    """Gravity (3,) m/s² in the base frame: `GRAVITY` or the given vector (finite, not zero)."""
    g = np.asarray(GRAVITY if gravity is None else gravity, float).reshape(-1)
    if g.shape != (3,) or not np.all(np.isfinite(g)) or np.linalg.norm(g) == 0:
        raise InputError(f"gravity must be three finite numbers (m/s², base frame), not all zero; got {gravity!r}")
    return g


def gravity_loads(chain: Chain, q, gravity=None) -> Loads:
    """The gravity loads (module docstring) of `chain` at inputs q (N, I) rad or mm; gravity (3,) m/s² in the base
    frame (default `GRAVITY`). Raises InputError when the chain has no masses."""
    if chain.inertia is None:
        raise InputError(
            f"{chain.source}: the robot model has no link masses (<inertial> in a URDF): the compliance model needs "
            "them; give a URDF with inertial data (--urdf)"
        )
    g = gravity_vector(gravity)
    g_rot, g_pos, f_rot, f_pos = chain.frames(q)
    mass, com = chain.inertia[:, 0], chain.inertia[:, 1:]
    centre = f_pos + np.einsum("nkij,kj->nki", f_rot, com)  # (N, K, 3) mm
    weight = mass[:, None] * g  # (K, 3) N
    # moment of segment j about the base origin, and its force; M_k = Σ_(j≥k) c_j × W_j − o_k × Σ_(j≥k) W_j
    own = np.cross(centre, weight[None]) / 1000.0  # (N, K, 3) N·m
    tail_moment = np.cumsum(own[:, ::-1], axis=1)[:, ::-1]
    tail_force = np.cumsum(weight[::-1], axis=0)[::-1]  # (K, 3)
    moment = tail_moment - np.cross(g_pos, tail_force[None]) / 1000.0
    local = np.einsum("nkji,nkj->nki", g_rot, moment)  # in G_k
    axes = np.array([j.axis for j in chain.joints])  # (K, 3) in G_k
    along = np.einsum("nki,ki->nk", local, axes)
    prismatic = np.array([j.prismatic for j in chain.joints])
    torque = np.where(prismatic[None], 0.0, along)
    perp = local - along[..., None] * axes[None]
    return Loads(torque, perp)


def _factor(term: LoadTerm, loads: Loads) -> np.ndarray:
    """The term's scalar factor per pose (N,): τ, sign τ or |M⊥|."""
    if term.kind == "compliance":
        return loads.torque[:, term.joint]
    if term.kind == "backlash":
        return np.sign(loads.torque[:, term.joint])
    return np.linalg.norm(loads.moment_perp[:, term.joint], axis=1)


def candidate_terms(chain: Chain, loads: Loads, backlash: bool = False) -> tuple[LoadTerm, ...]:
    """The terms the data can see (module docstring): compliance of each revolute joint, bending of each prismatic
    joint, and (with `backlash`) backlash of each revolute joint loaded both ways at some poses."""
    spread = np.std(loads.torque, axis=0)
    bend = np.std(np.linalg.norm(loads.moment_perp, axis=2), axis=0)
    top = max(float(np.max(spread, initial=0.0)), float(np.max(bend, initial=0.0)))
    floor = max(MIN_TORQUE_NM, MIN_SPREAD * top)
    terms: list[LoadTerm] = []
    for k, j in enumerate(chain.joints):
        if j.prismatic:
            if bend[k] >= floor:
                terms.append(LoadTerm(f"{j.name}.bending", "bending", k))
        elif spread[k] >= floor:
            terms.append(LoadTerm(f"{j.name}.compliance", "compliance", k))
            signs = np.sign(loads.torque[:, k])
            if backlash and min(np.mean(signs > 0), np.mean(signs < 0)) >= 0.1:
                terms.append(LoadTerm(f"{j.name}.backlash", "backlash", k))
    return tuple(terms)


def named_terms(chain: Chain, names) -> tuple[LoadTerm, ...]:
    """Terms from their names (`<joint>.<kind>`, as `candidate_terms` and a saved model name them); InputError for a
    joint the chain does not have, or a kind the joint cannot take."""
    index = {j.name: k for k, j in enumerate(chain.joints)}
    out = []
    for name in names:
        joint, _, kind = str(name).rpartition(".")
        if joint not in index or kind not in KINDS:
            raise InputError(f"no load term {name!r} on {chain.name}: terms are <joint>.{'|'.join(KINDS)}")
        if (kind == "bending") != chain.joints[index[joint]].prismatic:
            raise InputError(f"load term {name!r}: bending is a prismatic joint's term, the others a revolute's")
        out.append(LoadTerm(str(name), kind, index[joint]))
    return tuple(out)


def deflections(chain: Chain, terms, coef, loads: Loads) -> tuple[np.ndarray, np.ndarray]:
    """The joints' deflections for coefficients `coef` (T,) of `terms`: `dv` (N, K) rad added to the joints' values,
    `drot` (N, K, 3) rad rotation vectors of their origins (`Chain.kinematics`)."""
    n, kk = loads.torque.shape
    dv, drot = np.zeros((n, kk)), np.zeros((n, kk, 3))
    for term, c in zip(terms, np.asarray(coef, float).reshape(-1)):
        if term.kind == "bending":
            drot[:, term.joint] += c * loads.moment_perp[:, term.joint]
        else:
            dv[:, term.joint] += c * _factor(term, loads)
    return dv, drot


def term_jacobian(terms, loads: Loads, d_params: np.ndarray) -> np.ndarray:
    """∂p/∂coefficient (N, 3, T) mm per unit (rad/Nm or rad), from the chain's parameter Jacobian `d_params`
    (N, 3, P) at the same poses (`Chain.kinematics`): a joint's offset column times τ (or sign τ); for bending, the
    joint's three origin-rotation columns times M⊥."""
    out = np.zeros((d_params.shape[0], 3, len(terms)))
    for t, term in enumerate(terms):
        base = 6 * term.joint
        if term.kind == "bending":  # a prismatic joint's rotation columns are about its frame's x, y, z
            out[:, :, t] = np.einsum(
                "nip,np->ni", d_params[:, :, base + 1 : base + 4], loads.moment_perp[:, term.joint]
            )
        else:
            out[:, :, t] = d_params[:, :, base] * _factor(term, loads)[:, None]
    return out


def factor_scale(term: LoadTerm, loads: Loads) -> float:
    """The RMS of the term's factor over the poses (N·m, or 1 for backlash): with the calibration's angle scale, the
    mm a unit coefficient moves a point by — how the fit compares the term with the others."""
    return max(float(np.sqrt(np.mean(_factor(term, loads) ** 2))), 1e-12)


__all__ = [
    "GRAVITY",
    "KINDS",
    "LoadTerm",
    "Loads",
    "candidate_terms",
    "deflections",
    "factor_scale",
    "gravity_loads",
    "gravity_vector",
    "named_terms",
    "term_jacobian",
]
