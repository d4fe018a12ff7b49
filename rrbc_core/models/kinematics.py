"""Forward and inverse kinematics of a UR5-like 6-axis arm (standard DH), and perturbed "true" robots.

Frames and units: every position is in the robot base frame, in mm; joint angles and DH angles are in rad
(function arguments whose names end in `_deg` are in degrees). The tool point (TCP) is the flange origin
moved `tool_mm` along the flange z axis; `rotation` is the flange/tool orientation (its columns are the tool
x, y, z axes in the base frame).

Standard (distal) DH: joint i (i = 1..6) contributes

    A_i = Rz(q_i + theta_offset_i) · Tz(d_i) · Tx(a_i) · Rx(alpha_i)

and the tool pose is A_1 · … · A_6 · Tz(tool_mm). Joint i turns about the z axis of frame i−1.

Kinematic errors (docs/theory.md §5.1): a "true" robot is the nominal one with small Gaussian errors on the joint
zero offsets, link lengths and twists (`perturbed`). The nominal controller computes positions with the nominal
parameters, so the error is smooth in space and depends on the joint configuration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from rrbc_core.errors import InputError

# Converged-solution tolerances of the inverse kinematics: position in mm, orientation in rad (1e-9 rad moves a
# point 1 m away by 1e-6 mm, so both mean "1e-6 mm at the scale of the arm").
POSITION_TOL_MM = 1e-6
ORIENTATION_TOL_RAD = 1e-9

# Weight that turns an orientation error (rad) into mm for the damped least-squares step.
_ORIENT_SCALE_MM = 100.0
# Fallback solver for arms that are not UR-like: the tool is moved from the seed's pose to the target in sub-steps
# of at most these sizes and the joints are corrected after each (continuation from the seed).
_SUB_STEP_MM = 50.0
_SUB_STEP_RAD = 0.2
# Largest joint step (rad, max norm) per damped least-squares iteration, and the iteration limit of the final solve.
_MAX_STEP_RAD = 0.2
_MAX_ITER = 300


def _vector6(name: str, value) -> np.ndarray:
    v = np.array(value, dtype=float).reshape(-1) if np.ndim(value) else np.array([value], dtype=float)
    if v.shape != (6,) or not np.all(np.isfinite(v)):
        raise InputError(f"{name} must be 6 finite numbers (one per joint), got {np.asarray(value).tolist()!r}")
    return v


@dataclass(frozen=True, eq=False)
class DHParameters:
    """Standard (distal) DH parameters of a 6-joint arm.

    a, d: (6,) link lengths / offsets in mm; alpha: (6,) link twists in rad; theta_offset: (6,) joint zero
    offsets in rad (joint angle used in the DH matrix = q + theta_offset); tool_mm: tool (stylus) length along
    the flange z axis, mm. Arrays are copied and made read-only.
    """

    a: np.ndarray
    d: np.ndarray
    alpha: np.ndarray
    theta_offset: np.ndarray
    tool_mm: float = 0.0

    def __post_init__(self):
        for name in ("a", "d", "alpha", "theta_offset"):
            v = _vector6(f"DH parameter {name}", getattr(self, name))
            v.setflags(write=False)
            object.__setattr__(self, name, v)
        t = self.tool_mm
        if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not np.isfinite(t):
            raise InputError(f"tool_mm must be one finite number (mm), got {t!r}")
        object.__setattr__(self, "tool_mm", float(self.tool_mm))

    def with_tool(self, tool_mm: float) -> DHParameters:
        """The same arm with a different tool length (mm along the flange z axis)."""
        return DHParameters(self.a, self.d, self.alpha, self.theta_offset, tool_mm)

    def same_as(self, other: DHParameters) -> bool:
        """True when every parameter is exactly equal (the class compares by identity with ==)."""
        names = ("a", "d", "alpha", "theta_offset")
        return all(np.array_equal(getattr(self, n), getattr(other, n)) for n in names) and self.tool_mm == other.tool_mm

    def as_dict(self) -> dict:
        return {
            "a": self.a.tolist(),
            "d": self.d.tolist(),
            "alpha": self.alpha.tolist(),
            "theta_offset": self.theta_offset.tolist(),
            "tool_mm": self.tool_mm,
        }


UR5 = DHParameters(
    a=np.array([0.0, -425.0, -392.25, 0.0, 0.0, 0.0]),
    d=np.array([89.159, 0.0, 0.0, 109.15, 94.65, 82.3]),
    alpha=np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0]),
    theta_offset=np.zeros(6),
)
"""Nominal UR5 (CB3) DH parameters (UR manual; docs/theory.md §5.1), no tool."""

UR10 = DHParameters(
    a=np.array([0.0, -612.0, -572.3, 0.0, 0.0, 0.0]),
    d=np.array([127.3, 0.0, 0.0, 163.941, 115.7, 92.2]),
    alpha=np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0]),
    theta_offset=np.zeros(6),
)
"""Nominal UR10 (CB3) DH parameters (UR's published table), no tool."""

#: Arm models by the name a scene gives (`robot.model`); "none" (a robot without kinematics) has no entry.
ROBOT_DH = {"ur5": UR5, "ur10": UR10}

UR5_TOOL_DOWN_SEED = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])
"""A UR5 configuration (rad) with the tool pointing straight down (−z of the base), elbow up, about 0.5 m in
front of the base; use it as the IK seed for probing a plate in front of the robot (see `tool_down`)."""
UR5_TOOL_DOWN_SEED.setflags(write=False)


# --- forward kinematics -----------------------------------------------------------------------------------
def _joint_matrices(dh: DHParameters, q: np.ndarray) -> np.ndarray:
    """DH matrices A_i for joint angles q (..., 6) -> (..., 6, 4, 4)."""
    th = q + dh.theta_offset
    ct, st = np.cos(th), np.sin(th)
    ca, sa = np.cos(dh.alpha), np.sin(dh.alpha)
    m = np.zeros(q.shape + (4, 4))
    m[..., 0, 0] = ct
    m[..., 0, 1] = -st * ca
    m[..., 0, 2] = st * sa
    m[..., 0, 3] = dh.a * ct
    m[..., 1, 0] = st
    m[..., 1, 1] = ct * ca
    m[..., 1, 2] = -ct * sa
    m[..., 1, 3] = dh.a * st
    m[..., 2, 1] = sa
    m[..., 2, 2] = ca
    m[..., 2, 3] = dh.d
    m[..., 3, 3] = 1.0
    return m


def _frames(dh: DHParameters, q: np.ndarray) -> np.ndarray:
    """Cumulative transforms T_0^i for i = 0..6 (…, 7, 4, 4); T_0^0 = I (base)."""
    a = _joint_matrices(dh, q)
    out = np.empty(q.shape[:-1] + (7, 4, 4))
    out[..., 0, :, :] = np.eye(4)
    for i in range(6):
        out[..., i + 1, :, :] = out[..., i, :, :] @ a[..., i, :, :]
    return out


def joint_frames(dh: DHParameters, q) -> np.ndarray:
    """The arm's frames for joints q (6,) rad: (8, 4, 4) homogeneous transforms in the robot base frame, mm — the
    base (identity), the six DH frames T_0^1 … T_0^6 (the flange is T_0^6) and the tool point's frame (T_0^6
    moved `tool_mm` along its z). Joint i turns about the z axis of frame i−1."""
    q = _as_joints(q).reshape(6)
    f = _frames(dh, q)
    tool = f[6].copy()
    tool[:3, 3] += dh.tool_mm * tool[:3, 2]
    return np.concatenate([f, tool[None]], axis=0)


def _as_joints(q) -> np.ndarray:
    qa = np.asarray(q, dtype=float)
    if qa.ndim == 0 or qa.shape[-1] != 6:
        raise InputError(f"joint angles must have 6 values on the last axis (rad), got shape {qa.shape}")
    if not np.all(np.isfinite(qa)):
        raise InputError("joint angles must be finite")
    return qa


def forward(dh: DHParameters, q) -> tuple[np.ndarray, np.ndarray]:
    """Tool position (..., 3) in mm and tool rotation (..., 3, 3), robot base frame, for joints q (..., 6) rad."""
    qa = _as_joints(q)
    t = _frames(dh, qa)[..., 6, :, :]
    rot = t[..., :3, :3]
    pos = t[..., :3, 3] + dh.tool_mm * rot[..., :, 2]
    return pos, rot.copy()


def _jacobian(frames: np.ndarray, tool_mm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Geometric Jacobian (…, 6, 6) [linear mm/rad; angular 1/1] of the tool point, plus its position and rotation."""
    rot = frames[..., 6, :3, :3]
    p = frames[..., 6, :3, 3] + tool_mm * rot[..., :, 2]
    z = frames[..., :6, :3, 2]  # joint axes z_{i-1}: (..., 6, 3)
    o = frames[..., :6, :3, 3]
    jv = np.cross(z, p[..., None, :] - o)  # (..., 6, 3)
    j = np.concatenate([jv, z], axis=-1)  # (..., 6 joints, 6 rows)
    return np.swapaxes(j, -1, -2), p, rot


def _rot_log(r: np.ndarray) -> np.ndarray:
    """Rotation vectors (…, 3) of rotation matrices (…, 3, 3)."""
    shape = r.shape[:-2]
    return Rotation.from_matrix(r.reshape(-1, 3, 3)).as_rotvec().reshape(shape + (3,))


def _check_rotations(rot: np.ndarray, what: str) -> None:
    if not np.all(np.isfinite(rot)):
        raise InputError(f"{what} must be finite")
    err = np.abs(np.swapaxes(rot, -1, -2) @ rot - np.eye(3)).max(axis=(-1, -2))
    det = np.linalg.det(rot)
    bad = np.flatnonzero(np.atleast_1d((err > 1e-6) | (det < 0)))
    if bad.size:
        where = "" if rot.ndim == 2 else f" (index {bad[0]})"
        raise InputError(f"{what}{where} is not a proper rotation matrix (orthonormal, determinant +1)")


def _lm(dh: DHParameters, q: np.ndarray, pos: np.ndarray, rot: np.ndarray, tol_p: float, tol_o: float, max_iter: int):
    """Batched damped least squares (Levenberg–Marquardt) on [position error (mm); orientation error (rad) x
    `_ORIENT_SCALE_MM`], from joints q (P,6) towards poses pos (P,3), rot (P,3,3). Steps are capped at
    `_MAX_STEP_RAD` (max norm). Returns q, position error (P,) mm, orientation error (P,) rad."""
    q = q.copy()
    n = len(q)
    lam = np.full(n, 1e-3)
    scale = np.array([1.0] * 3 + [_ORIENT_SCALE_MM] * 3)

    def residual(qq, idx):
        jac, p, r = _jacobian(_frames(dh, qq), dh.tool_mm)
        return jac, pos[idx] - p, _rot_log(rot[idx] @ np.swapaxes(r, -1, -2))

    jac, ep, eo = residual(q, np.arange(n))
    cost = np.sum(ep**2, -1) + _ORIENT_SCALE_MM**2 * np.sum(eo**2, -1)
    perr, oerr = np.linalg.norm(ep, axis=-1), np.linalg.norm(eo, axis=-1)
    for _ in range(max_iter):
        act = np.flatnonzero(((perr > tol_p) | (oerr > tol_o)) & (lam < 1e12))
        if act.size == 0:
            break
        js = jac[act] * scale[:, None]
        e = np.concatenate([ep[act], eo[act]], -1) * scale
        h = np.swapaxes(js, -1, -2) @ js + lam[act, None, None] * np.eye(6)
        dq = np.linalg.solve(h, np.einsum("pji,pj->pi", js, e)[..., None])[..., 0]
        dq *= np.minimum(1.0, _MAX_STEP_RAD / np.maximum(np.abs(dq).max(-1), 1e-300))[:, None]
        qn = q[act] + dq
        jn, epn, eon = residual(qn, act)
        cn = np.sum(epn**2, -1) + _ORIENT_SCALE_MM**2 * np.sum(eon**2, -1)
        ok = cn < cost[act]
        acc = act[ok]
        q[acc], jac[acc], ep[acc], eo[acc], cost[acc] = qn[ok], jn[ok], epn[ok], eon[ok], cn[ok]
        perr[acc] = np.linalg.norm(epn[ok], axis=-1)
        oerr[acc] = np.linalg.norm(eon[ok], axis=-1)
        lam[acc] = np.maximum(lam[acc] / 10.0, 1e-12)
        lam[act[~ok]] *= 10.0
    return q, perr, oerr


def _continuation(dh: DHParameters, pos: np.ndarray, rot: np.ndarray, seeds: np.ndarray):
    """Generic fallback: move the tool pose from forward(seed) to the target along a straight line (position) and
    a geodesic (rotation) in sub-steps of at most `_SUB_STEP_MM` / `_SUB_STEP_RAD`, correcting the joints by
    damped least squares after each sub-step, then solve to full accuracy."""
    p0, r0 = forward(dh, seeds)
    dp = pos - p0
    rv = _rot_log(rot @ np.swapaxes(r0, -1, -2))  # base-frame rotation taking r0 to rot
    steps = np.ceil(np.maximum(np.linalg.norm(dp, axis=-1) / _SUB_STEP_MM, np.linalg.norm(rv, axis=-1) / _SUB_STEP_RAD))
    steps = np.maximum(steps, 1).astype(int)
    q = seeds.copy()
    for k in range(1, int(steps.max())):
        idx = np.flatnonzero(steps > k)
        s = (k / steps[idx])[:, None]
        rk = Rotation.from_rotvec(s * rv[idx]).as_matrix() @ r0[idx]
        q[idx], _, _ = _lm(dh, q[idx], p0[idx] + s * dp[idx], rk, 1e-3, 1e-6, 30)
    return _lm(dh, q, pos, rot, 1e-3 * POSITION_TOL_MM, 1e-3 * ORIENTATION_TOL_RAD, _MAX_ITER)


# --- closed form for UR-structured arms -----------------------------------------------------------------------
_UR_ALPHA = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])


def _ur_ideal(dh: DHParameters) -> DHParameters | None:
    """The arm with UR structure closest to `dh` (twists snapped to (π/2, 0, 0, π/2, −π/2, 0); a1 = a4 = a5 =
    a6 = d2 = d3 = 0), for which the inverse is closed-form; None if `dh` is not UR-like."""
    if np.abs(dh.alpha - _UR_ALPHA).max() > 0.1 or min(abs(dh.a[1]), abs(dh.a[2])) < 1.0:
        return None
    a, d = dh.a.copy(), dh.d.copy()
    a[[0, 3, 4, 5]] = 0.0
    d[[1, 2]] = 0.0
    return DHParameters(a, d, _UR_ALPHA, dh.theta_offset, dh.tool_mm)


def _wrap(x):
    return (x + np.pi) % (2 * np.pi) - np.pi


def _ur_candidates(ideal: DHParameters, pos: np.ndarray, rot: np.ndarray, q6_hint: np.ndarray) -> np.ndarray:
    """All 8 closed-form solutions (P, 8, 6) rad of a UR-structured arm for tool poses pos (P,3), rot (P,3,3);
    NaN where that branch cannot reach. Branch index = 4·shoulder + 2·wrist + elbow. `q6_hint` (P,) is used for
    joint 6 at a wrist singularity (sin q5 = 0), where only q4 + q6 is determined."""
    a2, a3 = ideal.a[1], ideal.a[2]
    d1, d4, d5, d6 = ideal.d[0], ideal.d[3], ideal.d[4], ideal.d[5]
    n = len(pos)
    z = rot[:, :, 2]
    pf = pos - ideal.tool_mm * z  # flange origin
    p05 = pf - d6 * z  # wrist (frame 5) origin; its component along the joint-2 axis is d4
    r = np.hypot(p05[:, 0], p05[:, 1])
    psi = np.arctan2(p05[:, 1], p05[:, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        asn = np.arcsin(d4 / r)
    out = np.full((n, 8, 6), np.nan)
    for i1, th1 in enumerate((psi + asn, psi + np.pi - asn)):
        c1, s1 = np.cos(th1), np.sin(th1)
        # R01 = Rz(th1) Rx(pi/2): columns x1 = (c1, s1, 0), y1 = (0, 0, 1), z1 = (s1, -c1, 0)
        r01 = np.zeros((n, 3, 3))
        r01[:, 0, 0], r01[:, 1, 0] = c1, s1
        r01[:, 2, 1] = 1.0
        r01[:, 0, 2], r01[:, 1, 2] = s1, -c1
        r16 = np.swapaxes(r01, 1, 2) @ rot
        p16 = np.einsum("nji,nj->ni", r01, pf - [0.0, 0.0, d1])
        # R16 = Rz(th234) Ry(-th5) Rz(th6): its last row is (s5 c6, -s5 s6, c5)
        c5 = np.clip(r16[:, 2, 2], -1.0, 1.0)
        for i5, th5 in enumerate((np.arccos(c5), -np.arccos(c5))):
            s5 = np.sin(th5)
            sing = np.abs(s5) < 1e-9
            safe = np.where(sing, 1.0, s5)
            th6 = np.where(sing, q6_hint + ideal.theta_offset[5], np.arctan2(-r16[:, 2, 1] / safe, r16[:, 2, 0] / safe))
            # Rz(th234) = R16 Rz(-th6) Ry(th5): th234 from its first column
            c6, s6 = np.cos(th6), np.sin(th6)
            m00 = (r16[:, 0, 0] * c6 - r16[:, 0, 1] * s6) * np.cos(th5) - r16[:, 0, 2] * s5
            m10 = (r16[:, 1, 0] * c6 - r16[:, 1, 1] * s6) * np.cos(th5) - r16[:, 1, 2] * s5
            th234 = np.arctan2(m10, m00)
            p15 = p16 - d6 * r16[:, :, 2]
            x = p15[:, 0] - d5 * np.sin(th234)
            y = p15[:, 1] + d5 * np.cos(th234)
            c3 = (x**2 + y**2 - a2**2 - a3**2) / (2 * a2 * a3)
            c3 = np.where(np.abs(c3) <= 1.0 + 1e-12, np.clip(c3, -1.0, 1.0), np.nan)
            for i3, th3 in enumerate((np.arccos(c3), -np.arccos(c3))):
                th2 = np.arctan2(y, x) - np.arctan2(a3 * np.sin(th3), a2 + a3 * np.cos(th3))
                th = np.stack([th1 + 0 * th3, th2, th3, th234 - th2 - th3, th5 + 0 * th3, th6 + 0 * th3], -1)
                out[:, 4 * i1 + 2 * i5 + i3] = _wrap(th - ideal.theta_offset)
    return out


def _solve(dh: DHParameters, pos: np.ndarray, rot: np.ndarray, seeds: np.ndarray):
    """Inverse kinematics on the seed's configuration branch, batched over points.

    For a UR-like arm: the closed-form solutions of the nearest UR-structured arm give 8 candidates per pose;
    the seed's branch (shoulder, wrist, elbow) is the branch of the candidate nearest the seed at the seed's own
    pose; that branch's candidate at the target is refined by damped least squares on the actual parameters
    (a small correction for perturbed robots). Points where this fails, and arms that are not UR-like, fall
    back to continuation from the seed (`_continuation`).

    pos (P,3), rot (P,3,3), seeds (P,6). Returns q (P,6) (the 2π-representation nearest the seed), position
    error (P,) mm, orientation error (P,) rad.
    """
    n = len(pos)
    q = np.full((n, 6), np.nan)
    perr = np.full(n, np.inf)
    oerr = np.full(n, np.inf)
    # beyond any reach of the chain: unreachable without iterating (a point 1e9 mm away costs no solver time)
    near = np.flatnonzero(np.linalg.norm(pos, axis=1) <= reach_bound(dh) + POSITION_TOL_MM)
    if len(near) < n:
        if len(near):
            q[near], perr[near], oerr[near] = _solve(dh, pos[near], rot[near], seeds[near])
        return q, perr, oerr
    ideal = _ur_ideal(dh)
    if ideal is not None:
        ps, rs = forward(ideal, seeds)
        at_seed = _ur_candidates(ideal, ps, rs, seeds[:, 5])
        dist = np.linalg.norm(_wrap(at_seed - seeds[:, None, :]), axis=-1)
        branch = np.argmin(np.where(np.isnan(dist), np.inf, dist), axis=1)
        cand = _ur_candidates(ideal, pos, rot, seeds[:, 5])[np.arange(n), branch]
        ok = ~np.isnan(cand).any(-1)
        if ok.any():
            start = seeds[ok] + _wrap(cand[ok] - seeds[ok])
            tol_p, tol_o = 1e-3 * POSITION_TOL_MM, 1e-3 * ORIENTATION_TOL_RAD
            q[ok], perr[ok], oerr[ok] = _lm(dh, start, pos[ok], rot[ok], tol_p, tol_o, _MAX_ITER)
    retry = np.flatnonzero((perr > POSITION_TOL_MM) | (oerr > ORIENTATION_TOL_RAD))
    if retry.size:
        qr, pr, orr = _continuation(dh, pos[retry], rot[retry], seeds[retry])
        better = pr + _ORIENT_SCALE_MM * orr < np.nan_to_num(perr[retry] + _ORIENT_SCALE_MM * oerr[retry], nan=np.inf)
        if ideal is not None:  # accept a continuation result only on the seed's branch
            pi_, ri_ = forward(ideal, qr)
            d = np.linalg.norm(_wrap(_ur_candidates(ideal, pi_, ri_, qr[:, 5]) - qr[:, None, :]), axis=-1)
            better &= np.argmin(np.where(np.isnan(d), np.inf, d), axis=1) == branch[retry]
        idx = retry[better]
        q[idx], perr[idx], oerr[idx] = qr[better], pr[better], orr[better]
    q = seeds + _wrap(q - seeds)
    return q, perr, oerr


def reach_bound(dh: DHParameters) -> float:
    """An upper bound (mm) on the tool point's distance from the base origin at any joint values: each DH link
    moves the frame by (a cos θ, a sin θ, d), of length sqrt(a² + d²), and the tool adds |tool_mm| (the triangle
    inequality); a point farther than this is unreachable."""
    return float(np.sum(np.hypot(dh.a, dh.d)) + abs(dh.tool_mm))


def _unreachable(perr, oerr) -> np.ndarray:
    return np.flatnonzero((perr > POSITION_TOL_MM) | (oerr > ORIENTATION_TOL_RAD))


def inverse(dh: DHParameters, position, rotation, seed_q) -> np.ndarray:
    """Joint angles (6,) rad that put the tool at `position` (3,) mm with `rotation` (3, 3), robot base frame.

    The solution is on the configuration branch (shoulder, elbow, wrist) of `seed_q` (6,) rad: for a UR-like
    arm the closed-form solutions of the nearest UR-structured arm give the branch's starting point, which damped
    least squares on the position and orientation error refines for the actual parameters; other arms are
    solved by continuation from the seed's pose. Near a singularity (sin q3 = 0, sin q5 = 0, or the wrist centre
    at horizontal distance d4 from the base axis) neighbouring branches meet and the branch a seed stands for is
    ambiguous. Raises InputError if the pose cannot be reached on that branch to 1e-6 mm / 1e-9 rad.
    """
    p = np.asarray(position, dtype=float)
    r = np.asarray(rotation, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise InputError(f"position must be 3 finite numbers (mm), got shape {p.shape}")
    if r.shape != (3, 3):
        raise InputError(f"rotation must be a 3x3 matrix, got shape {r.shape}")
    _check_rotations(r, "rotation")
    seed = _vector6("seed_q", seed_q)
    q, perr, oerr = _solve(dh, p[None], r[None], seed[None])
    if _unreachable(perr, oerr).size:
        raise InputError(
            f"pose at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) mm is not reachable on the seed's configuration branch "
            f"(remaining error {perr[0]:.3g} mm, {np.degrees(oerr[0]):.3g} deg); move it inside the arm's reach, "
            "change the tool orientation, or give a seed on the wanted branch (shoulder, elbow, wrist)"
        )
    return q[0]


def _path_poses(positions, rotations) -> tuple[np.ndarray, np.ndarray]:
    """Checked tool positions (P, 3) mm and rotations (P, 3, 3) (one (3, 3) is used for all)."""
    p = np.asarray(positions, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or not np.all(np.isfinite(p)):
        raise InputError(f"positions must be a finite (P, 3) array in mm, got shape {p.shape}")
    r = np.asarray(rotations, dtype=float)
    if r.shape == (3, 3):
        r = np.broadcast_to(r, (len(p), 3, 3))
    if r.shape != (len(p), 3, 3):
        raise InputError(f"rotations must be (3, 3) or ({len(p)}, 3, 3) for {len(p)} positions, got shape {r.shape}")
    _check_rotations(r, "rotations")
    return p, r


def inverse_path(dh: DHParameters, positions, rotations, seed_q) -> np.ndarray:
    """Joint angles (P, 6) rad for tool positions (P, 3) mm and rotations (P, 3, 3) or one (3, 3) for all.

    Every point is solved from the same nominal `seed_q` (6,) rad, not from the previous point, so all points
    use one consistent configuration branch whatever their order. Raises InputError naming the unreachable
    point indices (0-based).
    """
    p, r = _path_poses(positions, rotations)
    seed = _vector6("seed_q", seed_q)
    if len(p) == 0:
        return np.zeros((0, 6))
    q, perr, oerr = _solve(dh, p, np.ascontiguousarray(r), np.tile(seed, (len(p), 1)))
    bad = _unreachable(perr, oerr)
    if bad.size:
        shown = ", ".join(f"{i} at ({p[i, 0]:.1f}, {p[i, 1]:.1f}, {p[i, 2]:.1f}) mm" for i in bad[:5]) + (
            f" and {bad.size - 5} more" if bad.size > 5 else ""
        )
        raise InputError(
            f"{bad.size} of {len(p)} points are not reachable on the seed's configuration branch: point {shown}; "
            "move them inside the arm's reach, change the tool orientation, or change the seed"
        )
    return q


def reachable(dh: DHParameters, positions, rotations, seed_q) -> np.ndarray:
    """Which tool positions (P, 3) mm with rotations (P, 3, 3) or (3, 3) the arm reaches on the configuration branch
    of `seed_q` (6,) rad: (P,) bool, the test `inverse_path` refuses with (never raises for unreachable points)."""
    p, r = _path_poses(positions, rotations)
    if len(p) == 0:
        return np.zeros(0, bool)
    _, perr, oerr = _solve(dh, p, np.ascontiguousarray(r), np.tile(_vector6("seed_q", seed_q), (len(p), 1)))
    ok = np.ones(len(p), bool)
    ok[_unreachable(perr, oerr)] = False
    return ok


def perturbed(
    dh: DHParameters,
    rng: np.random.Generator,
    joint_offset_deg: float = 0.1,
    link_mm: float = 0.2,
    twist_deg: float = 0.05,
) -> DHParameters:
    """A "true" robot: `dh` with independent Gaussian errors (1 sigma) on every joint zero offset (deg),
    every link length a and offset d (mm) and every twist alpha (deg). The tool length is kept.

    Draw order from `rng` (fixed): theta_offset (6), a (6), d (6), alpha (6). Zero sigmas give `dh` exactly.
    """
    for name, v in (("joint_offset_deg", joint_offset_deg), ("link_mm", link_mm), ("twist_deg", twist_deg)):
        if (
            isinstance(v, bool)
            or not isinstance(v, (int, float, np.integer, np.floating))
            or not np.isfinite(v)
            or v < 0
        ):
            raise InputError(f"{name} must be a finite number >= 0, got {v!r}")
    d_theta = rng.normal(0.0, 1.0, 6) * np.radians(joint_offset_deg)
    d_a = rng.normal(0.0, 1.0, 6) * link_mm
    d_d = rng.normal(0.0, 1.0, 6) * link_mm
    d_alpha = rng.normal(0.0, 1.0, 6) * np.radians(twist_deg)
    return DHParameters(
        a=dh.a + d_a, d=dh.d + d_d, alpha=dh.alpha + d_alpha, theta_offset=dh.theta_offset + d_theta, tool_mm=dh.tool_mm
    )


def tool_down(yaw_deg: float = 0.0) -> np.ndarray:
    """Tool rotation (3, 3) with the tool z axis along −z of the base frame (probing straight down), turned by
    `yaw_deg` degrees about the base z axis (yaw 0: tool x = base x, tool y = −base y)."""
    y = np.radians(float(yaw_deg))
    c, s = np.cos(y), np.sin(y)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rz @ np.diag([1.0, -1.0, -1.0])
