"""Rigid transforms between the sensor frame and the robot frame, and rotation averaging.

Convention (the only one in this project): a transform (R, t) maps sensor-frame points to robot-frame points,

    robot = R @ sensor + t,        sensor = R.T @ (robot - t).

Points are stored as rows (N x 3, mm). `map_points` (and `RigidTransform.apply` / `apply_inverse` over it) is the
one place that maps points; nothing else in the project writes `X @ R.T + t` by hand.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from rrbc_core.errors import InputError

_ORTHO_TOL = 1e-6


def _as_points(points) -> np.ndarray:
    """Return points as a float array of shape (..., 3); a single 3-vector stays 1-D."""
    p = np.asarray(points, dtype=float)
    if p.shape[-1:] != (3,):
        raise InputError(f"points must have 3 coordinates (last axis of size 3), got shape {p.shape}")
    return p


def map_points(points, matrix, translation) -> np.ndarray:
    """Points as rows (..., 3) mapped by `matrix` (3, 3) and `translation` (3,): matrix @ p + t for each row (the
    convention, written once; `matrix` is a rotation for a rigid transform, any 3x3 for a linear map)."""
    return np.asarray(points, float) @ np.asarray(matrix, float).T + translation


def project_to_so3(matrix) -> np.ndarray:
    """Closest rotation (Frobenius norm) to a 3x3 matrix: R = U diag(1, 1, sign det(U V^T)) V^T.

    This is the orthogonal polar factor with the determinant fix (Moakher 2002), so the result is never a
    reflection. Works on a stack (..., 3, 3).
    """
    m = np.asarray(matrix, dtype=float)
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    d = np.where(d == 0, 1.0, d)
    u = u.copy()
    u[..., :, 2] *= d[..., None]
    return u @ vt


def chordal_mean(rotations, weights=None) -> np.ndarray:
    """Chordal L2 mean of rotations (K x 3 x 3): argmin_R sum_k w_k ||R_k - R||_F^2 over SO(3).

    Equal to the SO(3) projection of the weighted arithmetic mean of the matrices (Moakher 2002; it is also
    what scipy's Rotation.mean computes).
    """
    rs = np.asarray(rotations, dtype=float)
    if rs.ndim != 3 or rs.shape[1:] != (3, 3) or len(rs) == 0:
        raise InputError(f"chordal_mean needs a non-empty stack of 3x3 rotations, got shape {rs.shape}")
    w = np.ones(len(rs)) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != (len(rs),) or np.any(w < 0) or w.sum() <= 0:
        raise InputError("chordal_mean weights must be one non-negative number per rotation, not all zero")
    m = np.einsum("k,kij->ij", w / w.sum(), rs)
    return project_to_so3(m)


def skew(v) -> np.ndarray:
    """(..., 3, 3): the cross-product matrices [v]× of vectors v (..., 3), [v]× u = v × u."""
    v = np.asarray(v, float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def rotation_from_rotvec(rotvec) -> np.ndarray:
    """Rotation matrix from a rotation vector (axis * angle, rad), Rodrigues' formula."""
    v = np.asarray(rotvec, dtype=float)
    theta = float(np.linalg.norm(v))
    k = skew(v)
    if theta < 1e-12:
        return np.eye(3) + k
    return np.eye(3) + np.sin(theta) / theta * k + (1 - np.cos(theta)) / theta**2 * (k @ k)


def rotation_from_euler_zyx(alpha: float, beta: float, gamma: float) -> np.ndarray:
    """R = Rz(alpha) @ Ry(beta) @ Rx(gamma) (intrinsic Z-Y-X Euler angles, rad), as in Van Wyk & Marvel eq. 8."""
    ca, sa = np.cos(alpha), np.sin(alpha)
    cb, sb = np.cos(beta), np.sin(beta)
    cg, sg = np.cos(gamma), np.sin(gamma)
    rz = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cg, -sg], [0.0, sg, cg]])
    return rz @ ry @ rx


@dataclass(frozen=True, eq=False)
class RigidTransform:
    """A proper rigid transform: robot = rotation @ sensor + translation (mm).

    `rotation` is a 3x3 matrix in SO(3) (checked on construction), `translation` a 3-vector in mm.
    """

    rotation: np.ndarray
    translation: np.ndarray
    piecewise: ClassVar[bool] = False  # one transform everywhere (`registration.SensorToRobot`)

    def __post_init__(self):
        r = np.array(self.rotation, dtype=float)
        t = np.array(self.translation, dtype=float).reshape(-1)
        if r.shape != (3, 3) or t.shape != (3,):
            raise InputError(f"a rigid transform needs a 3x3 rotation and a 3-vector, got {r.shape} and {t.shape}")
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(t))):
            raise InputError("a rigid transform must have finite rotation and translation")
        if np.abs(r.T @ r - np.eye(3)).max() > _ORTHO_TOL or np.linalg.det(r) < 0:
            raise InputError("rotation is not a proper rotation matrix (orthonormal with determinant +1)")
        r.setflags(write=False)
        t.setflags(write=False)
        object.__setattr__(self, "rotation", r)
        object.__setattr__(self, "translation", t)

    # --- construction -------------------------------------------------------------------------------------
    @classmethod
    def from_matrix(cls, matrix) -> RigidTransform:
        """From a 4x4 homogeneous matrix [[R, t], [0, 0, 0, 1]]."""
        m = np.asarray(matrix, dtype=float)
        if m.shape != (4, 4):
            raise InputError(f"a homogeneous transform is 4x4, got shape {m.shape}")
        if np.abs(m[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-9:
            raise InputError("the last row of a rigid 4x4 transform must be [0, 0, 0, 1]")
        return cls(m[:3, :3], m[:3, 3])

    def as_matrix(self) -> np.ndarray:
        """4x4 homogeneous matrix."""
        m = np.eye(4)
        m[:3, :3] = self.rotation
        m[:3, 3] = self.translation
        return m

    # --- mapping points -----------------------------------------------------------------------------------
    def apply(self, points) -> np.ndarray:
        """Sensor-frame points (..., 3) -> robot-frame points: R @ p + t."""
        return map_points(_as_points(points), self.rotation, self.translation)

    def apply_inverse(self, points) -> np.ndarray:
        """Robot-frame points (..., 3) -> sensor-frame points: R.T @ (q - t)."""
        q = _as_points(points)
        return (q - self.translation) @ self.rotation

    def apply_vectors(self, vectors) -> np.ndarray:
        """Rotate free vectors (displacements) from the sensor frame to the robot frame: R @ v."""
        return _as_points(vectors) @ self.rotation.T

    # --- algebra ------------------------------------------------------------------------------------------
    def compose(self, other: RigidTransform) -> RigidTransform:
        """self ∘ other: first `other`, then `self` (matrix product self @ other)."""
        return RigidTransform(self.rotation @ other.rotation, self.rotation @ other.translation + self.translation)

    def inverse(self) -> RigidTransform:
        return RigidTransform(self.rotation.T, -self.rotation.T @ self.translation)

    def as_dict(self) -> dict:
        return {"rotation": self.rotation.tolist(), "translation": self.translation.tolist()}

    def rpy(self) -> np.ndarray:
        """(3,) roll, pitch, yaw (rad) of the rotation in the URDF / ROS convention: fixed axes x, then y, then z,
        R = Rz(yaw) Ry(pitch) Rx(roll); pitch in [−π/2, π/2]; at pitch ±π/2 (gimbal lock) roll is 0."""
        r = self.rotation
        pitch = float(np.arcsin(np.clip(-r[2, 0], -1.0, 1.0)))
        if abs(r[2, 0]) < 1.0 - 1e-12:
            roll, yaw = float(np.arctan2(r[2, 1], r[2, 2])), float(np.arctan2(r[1, 0], r[0, 0]))
        else:  # gimbal lock: only yaw - roll (pitch +π/2) or yaw + roll (−π/2) is determined
            roll, yaw = 0.0, float(np.arctan2(-r[0, 1], r[1, 1]))
        return np.array([roll, pitch, yaw])

    def export_forms(self) -> dict:
        """The forms robot controllers and ROS take: ``matrix_4x4`` (row-major, mm), ``xyz_mm``, ``xyz_m`` (a
        URDF origin's units) and ``rpy_rad`` (`rpy`)."""
        return {
            "matrix_4x4": self.as_matrix().tolist(),
            "xyz_mm": self.translation.tolist(),
            "xyz_m": (self.translation / 1000.0).tolist(),
            "rpy_rad": self.rpy().tolist(),
        }


def mean_transform(transforms, origin=None, weights=None) -> RigidTransform:
    """Average rigid transforms: chordal mean of rotations; translation averaged so that the averaged
    transform maps `origin` (sensor frame, mm; default 0) to the weighted mean of the individual images of
    `origin` (docs/theory.md §3.2: averaging translations depends on the origin, so root it where it matters).
    """
    ts = list(transforms)
    if not ts:
        raise InputError("mean_transform needs at least one transform")
    w = np.ones(len(ts)) if weights is None else np.asarray(weights, dtype=float)
    o = np.zeros(3) if origin is None else np.asarray(origin, dtype=float)
    r = chordal_mean([t.rotation for t in ts], w)
    images = np.array([t.apply(o) for t in ts])
    target = (w[:, None] * images).sum(0) / w.sum()
    return RigidTransform(r, target - r @ o)
