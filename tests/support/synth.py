"""Synthetic work cells for tests: a true rigid relation, a smooth robot-side bias field, noise (mm).

A point's truth is x (sensor frame, noise-free). The sensor reports x + ε; the robot reports where it really
is when commanded to the point, T(x) + β(T(x)) + η, where β is the robot's position-dependent bias (it carries
the same bias when it later acts at a target, so a check point's truth is T(x) + β(T(x))).
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from rrbc_core.geometry.transforms import RigidTransform


@dataclass(frozen=True)
class BiasField:
    """Sum of plane waves: β(p) = Σ_j a_j sin(2π k_j·p / λ_j + φ_j), robot frame, mm."""

    amplitudes: np.ndarray  # (J, 3) mm
    directions: np.ndarray  # (J, 3) unit
    wavelengths: np.ndarray  # (J,) mm
    phases: np.ndarray  # (J,)

    def __call__(self, p):
        p = np.atleast_2d(p)
        arg = 2 * np.pi * (p @ self.directions.T) / self.wavelengths + self.phases
        return np.sin(arg) @ self.amplitudes

    @classmethod
    def random(cls, rng, rms_mm, wavelength_range=(700.0, 1500.0), waves=3):
        d = rng.normal(size=(waves, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        a = rng.normal(size=(waves, 3))
        # sin² averages 1/2: RMS of |β| ≈ sqrt(Σ|a_j|²/2)
        a *= rms_mm / np.sqrt(np.sum(a**2) / 2)
        return cls(a, d, rng.uniform(*wavelength_range, waves), rng.uniform(0, 2 * np.pi, waves))


def random_transform(rng) -> RigidTransform:
    return RigidTransform(Rotation.random(random_state=rng.integers(2**31)).as_matrix(), rng.uniform(-800, 800, 3))


def cell_points(rng):
    """Fiducials: a 4x4x2 grid over 600 x 450 x 200 mm; registration: 8 box corners (a larger volume);
    checks: 300 uniform points inside the fiducial box (sensor frame, truth)."""
    gx, gy, gz = np.meshgrid(np.linspace(0, 600, 4), np.linspace(0, 450, 4), np.linspace(0, 200, 2))
    fid = np.c_[gx.ravel(), gy.ravel(), gz.ravel()]
    cx, cy, cz = np.meshgrid([-200, 800], [-150, 600], [-50, 300])
    regp = np.c_[cx.ravel(), cy.ravel(), cz.ravel()].astype(float)
    checks = rng.uniform([20, 20, 10], [580, 430, 190], (300, 3))
    return regp, fid, checks


def measure(rng, true: RigidTransform, field, truth_sensor, sigma_mm):
    """(sensor measurement, robot measurement, robot truth) for points with sensor-frame truth (N, 3)."""
    robot_true = true.apply(truth_sensor)
    if field is not None:
        robot_true = robot_true + field(robot_true)
    s = truth_sensor + rng.normal(0, sigma_mm, truth_sensor.shape)
    b = robot_true + rng.normal(0, sigma_mm, truth_sensor.shape)
    return s, b, robot_true
