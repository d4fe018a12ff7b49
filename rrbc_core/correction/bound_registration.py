"""The covariances of a corrected point's own readings and of the registration's error carried to it (robot frame,
mm²): two parts of the bounds' budget (`correction.bounds`, docs/uncertainty.md).
"""

from __future__ import annotations

import numpy as np

from rrbc_core.geometry.transforms import skew
from rrbc_core.models.instrument import Instrument


def own_cov(inst: Instrument, rotation: np.ndarray, p_sensor: np.ndarray, count) -> np.ndarray:
    """(M, 3, 3): the covariance of a point's own readings in the robot frame, mm² (module docstring)."""
    r = np.asarray(rotation, float)
    sensor, robot = inst.sensor_and_robot_cov(p_sensor)
    c = np.einsum("ij,njk,lk->nil", r, sensor, r) + robot
    return c / np.asarray(count, float).reshape(-1, 1, 1)


def registration_theta_cov(rotation: np.ndarray, reg_sensor: np.ndarray, row_cov: np.ndarray) -> np.ndarray:
    """(6, 6): the covariance of the least-squares transform's rotation vector (rad, robot frame, about its origin)
    and translation (mm), from the registration points' sensor readings (N, 3) and their rows' noise covariances
    (N, 3, 3) robot frame (sandwich form: H⁻¹ Σ Jᵢᵀ Cᵢ Jᵢ H⁻¹)."""
    q = np.asarray(reg_sensor, float) @ np.asarray(rotation, float).T
    jac = np.concatenate([-skew(q), np.broadcast_to(np.eye(3), (len(q), 3, 3))], axis=2)  # (N, 3, 6)
    h = np.einsum("nij,nik->jk", jac, jac)
    m = np.einsum("nij,nik,nkl->jl", jac, row_cov, jac)
    hinv = np.linalg.pinv(h)
    return hinv @ m @ hinv


def point_registration_cov(
    rotation: np.ndarray, lever_sensor: np.ndarray, weight: np.ndarray, theta_cov: np.ndarray
) -> np.ndarray:
    """(M, 3, 3): G θ Gᵀ with G = [−[R lever]×, weight·I] (lever (M, 3) sensor frame, weight (M,))."""
    q = np.asarray(lever_sensor, float) @ np.asarray(rotation, float).T
    g = np.concatenate([-skew(q), np.asarray(weight, float)[:, None, None] * np.eye(3)], axis=2)
    m = len(g)
    a = (g.reshape(-1, 6) @ np.asarray(theta_cov, float)).reshape(m, 3, 6)  # G θ: one product for every point
    out = np.empty((m, 3, 3))
    for i in range(3):  # (G θ) Gᵀ: its six distinct entries, symmetric
        for j in range(i, 3):
            out[:, i, j] = out[:, j, i] = np.einsum("mk,mk->m", a[:, i], g[:, j])
    return out
