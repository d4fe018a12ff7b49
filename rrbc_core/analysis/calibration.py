"""Model-based calibration (volumetric error compensation, VEC) of a serial arm together with the sensor-to-robot
transform, from measured poses with joint angles (docs/calibration.md).

Model. A row measured with joint angles q (rad; the file gives degrees) has its physical point at FK(θ, q), the
arm's forward kinematics with the TRUE parameters θ = θ₀ + δ (θ₀ nominal: standard DH a, d, α, joint offsets,
and the tool length); the sensor reads it at s = T⁻¹(FK(θ, q)) + noise. Identification minimises
Σ |T(s_i) − FK(θ₀ + δ, q_i)|² (robot frame, mm) over δ and T (robot = R @ sensor + t).

Identifiability. Not every parameter can be told apart from these data: an error of the base is absorbed by T,
some link errors act alike at the data's poses. At the solution's linearisation (parameters scaled to mm: angles
× `ANGLE_SCALE_MM`), the singular value decomposition of the residuals' Jacobian gives the combinations the data
determine (singular value above `RANK_TOL` of the largest); the fit moves only along those, the others stay at
their nominal values. Uncertainty: σ̂² (JᵀJ)⁺ in the identified subspace, σ̂² = RSS / (3N − r).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from rrbc_core.errors import InputError
from rrbc_core.models.kinematics import DHParameters, forward

ANGLE_SCALE_MM = 500.0  # an angle error of 1 rad moves a point ~500 mm at a UR5's reach: parameters compared in mm
RANK_TOL = 1e-4  # singular values below this fraction of the largest: a combination the data do not determine
PARAM_NAMES = (
    tuple(f"theta{i + 1}" for i in range(6))
    + tuple(f"a{i + 1}" for i in range(6))
    + tuple(f"d{i + 1}" for i in range(6))
    + tuple(f"alpha{i + 1}" for i in range(6))
    + ("tool",)
)
ANGULAR = np.array([n.startswith(("theta", "alpha")) for n in PARAM_NAMES])
N_DH = len(PARAM_NAMES)  # 25; then 6 for T (rotation vector rad, translation mm)


def dh_vector(dh: DHParameters) -> np.ndarray:
    return np.concatenate([dh.theta_offset, dh.a, dh.d, dh.alpha, [dh.tool_mm]]).astype(float)


def dh_from(v: np.ndarray) -> DHParameters:
    v = np.asarray(v, float)
    return DHParameters(a=v[6:12], d=v[12:18], alpha=v[18:24], theta_offset=v[0:6], tool_mm=float(v[24]))


@dataclass(frozen=True, eq=False)
class Calibration:
    """An identified arm and registration.

    `nominal` and `identified` DHParameters; `delta` (25,) identified errors (rad for theta/alpha, mm otherwise)
    with `delta_se` (25,) standard errors (NaN where a parameter is not identifiable on its own); `rotation`
    (3, 3), `translation` (3,) mm: sensor → robot; `rank` the number of identified combinations, `combinations`
    their descriptions (the largest loadings), `sigma_mm` the residual noise per axis, `residuals` (N, 3) mm."""

    nominal: DHParameters
    identified: DHParameters
    delta: np.ndarray
    delta_se: np.ndarray
    identifiable: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    rank: int
    combinations: tuple
    sigma_mm: float
    residuals: np.ndarray
    chi2: float = float("nan")
    chi2_dof: int = 0

    @property
    def kinematic_p_value(self) -> float:
        """P-value of "no kinematic error" (χ² of the identified arm errors against their uncertainty)."""
        from scipy.stats import chi2

        return float(chi2.sf(self.chi2, self.chi2_dof)) if self.chi2_dof else 1.0

    def sensor_to_robot(self, s) -> np.ndarray:
        return np.asarray(s, float).reshape(-1, 3) @ self.rotation.T + self.translation


def _residuals(x: np.ndarray, theta0: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    theta = theta0 + x[:N_DH]
    r = Rotation.from_rotvec(x[N_DH : N_DH + 3]).as_matrix()
    t = x[N_DH + 3 :]
    p, _ = forward(dh_from(theta), q)
    return ((s @ r.T + t) - p).reshape(-1)


def _jacobian(x, theta0, q, s) -> np.ndarray:
    """Central differences (N·3, 31) in the parameters' own units."""
    out = np.empty((3 * len(q), len(x)))
    for k in range(len(x)):
        h = 1e-7 if (k < N_DH and ANGULAR[k]) or N_DH <= k < N_DH + 3 else 1e-4
        e = np.zeros(len(x))
        e[k] = h
        out[:, k] = (_residuals(x + e, theta0, q, s) - _residuals(x - e, theta0, q, s)) / (2 * h)
    return out


def position_jacobian(dh: DHParameters, q_rad) -> np.ndarray:
    """∂FK/∂θ (N, 3, 25): how the tool point (robot frame, mm) of `dh` at joints q (N, 6) rad moves per unit of each
    parameter in `PARAM_NAMES`, angles scaled by `ANGLE_SCALE_MM` (so every column is in mm per mm-equivalent).
    Central differences."""
    q = np.asarray(q_rad, float).reshape(-1, 6)
    theta0 = dh_vector(dh)
    sc = _scales()[:N_DH]
    out = np.empty((len(q), 3, N_DH))
    for k in range(N_DH):
        h = 1e-7 if ANGULAR[k] else 1e-4
        e = np.zeros(N_DH)
        e[k] = h
        plus, _ = forward(dh_from(theta0 + e), q)
        minus, _ = forward(dh_from(theta0 - e), q)
        out[:, :, k] = (np.asarray(plus) - np.asarray(minus)).reshape(-1, 3) / (2 * h) / sc[k]
    return out


def _scales() -> np.ndarray:
    """Per parameter, mm per unit (angles × ANGLE_SCALE_MM): the columns are compared in mm."""
    sc = np.ones(N_DH + 6)
    sc[:N_DH][ANGULAR] = ANGLE_SCALE_MM
    sc[N_DH : N_DH + 3] = ANGLE_SCALE_MM
    return sc


def _describe(v: np.ndarray, k: int = 3) -> str:
    names = PARAM_NAMES + ("T.rx", "T.ry", "T.rz", "T.x", "T.y", "T.z")
    top = np.argsort(-np.abs(v))[:k]
    return " ".join(f"{'+' if v[i] >= 0 else '-'}{abs(v[i]):.2f}·{names[i]}" for i in top)


def calibrate(q_rad, sensor, nominal: DHParameters, rotation0=None, translation0=None) -> Calibration:
    """Identify the arm's errors and the sensor-to-robot transform from N poses (module docstring).

    Parameters
    ----------
    q_rad : (N, 6) joint angles, rad.
    sensor : (N, 3) the sensor's readings of the tool point, sensor frame, mm.
    nominal : the controller's DH parameters (with its tool).
    rotation0, translation0 : a starting registration (default: the identity; pass the rigid fit).
    """
    q = np.asarray(q_rad, float).reshape(-1, 6)
    s = np.asarray(sensor, float).reshape(-1, 3)
    if len(q) != len(s):
        raise InputError(f"{len(q)} joint configurations for {len(s)} sensor readings")
    if len(q) < 6:
        raise InputError(f"calibration needs at least 6 poses with joint angles, got {len(q)}")
    theta0 = dh_vector(nominal)
    x0 = np.zeros(N_DH + 6)
    if rotation0 is not None:
        x0[N_DH : N_DH + 3] = Rotation.from_matrix(np.asarray(rotation0, float)).as_rotvec()
        x0[N_DH + 3 :] = np.asarray(translation0, float)
    # the transform alone first (the arm nominal), then the identifiable subspace at that point
    fit_t = least_squares(lambda z: _residuals(np.concatenate([np.zeros(N_DH), z]), theta0, q, s), x0[N_DH:])
    x0[N_DH:] = fit_t.x
    sc = _scales()
    for _ in range(2):  # re-linearise once at the solution
        j = _jacobian(x0, theta0, q, s) / sc  # columns per mm of effect
        _, sv, vt = np.linalg.svd(j, full_matrices=False)
        rank = int(np.sum(sv > RANK_TOL * sv[0]))
        basis = vt[:rank].T  # (31, r) in scaled units
        fit = least_squares(lambda z, x0=x0, b=basis: _residuals(x0 + (b @ z) / sc, theta0, q, s), np.zeros(rank))
        x0 = x0 + (basis @ fit.x) / sc
    res = _residuals(x0, theta0, q, s).reshape(-1, 3)
    dof = max(3 * len(q) - rank, 1)
    sigma2 = float(np.sum(res**2) / dof)
    j = _jacobian(x0, theta0, q, s) / sc
    jr = j @ basis
    cov_z = sigma2 * np.linalg.pinv(jr.T @ jr)
    cov = (basis @ cov_z @ basis.T) / np.outer(sc, sc)
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    # is there a kinematic error at all? H0: the arm's identified combinations are zero (δ = 0 up to what the
    # transform absorbs). χ² = δᵀ Cov(δ)⁺ δ with its rank as the degrees of freedom, δ in the scaled units.
    cov_dh = (basis @ cov_z @ basis.T)[:N_DH, :N_DH]
    d_scaled = x0[:N_DH] * sc[:N_DH]
    w, v = np.linalg.eigh(cov_dh)
    keep = w > w.max() * 1e-9
    chi2 = float(np.sum((v[:, keep].T @ d_scaled) ** 2 / w[keep]))
    chi2_dof = int(keep.sum())
    null = np.eye(len(x0)) - basis @ basis.T
    alone = np.linalg.norm(null, axis=0) < 1e-3  # a unit change of this parameter lies in the identified space
    delta = x0[:N_DH]
    return Calibration(
        nominal=nominal,
        identified=dh_from(theta0 + delta),
        delta=delta,
        delta_se=np.where(alone[:N_DH], se[:N_DH], np.nan),
        identifiable=alone[:N_DH],
        rotation=Rotation.from_rotvec(x0[N_DH : N_DH + 3]).as_matrix(),
        translation=x0[N_DH + 3 :].copy(),
        rank=rank,
        combinations=tuple(_describe(basis[:, k]) for k in range(rank)),
        sigma_mm=float(np.sqrt(sigma2)),
        residuals=res,
        chi2=chi2,
        chi2_dof=chi2_dof,
    )
