"""Seeded measurement files of one station whose robot carries a smooth bias field of position: for the per-point
bounds' coverage tests and study (`correction.bounds`, scripts/uncertainty_study.py).

Physics. The sensor frame is the robot frame turned by a random rotation and moved up to 2 m; a physical point p
(robot frame, mm) is read by the robot as p + f(p) + noise, f a sum of six plane waves in random directions with
wavelengths `wavelength_mm` × U(0.5, 1.5) scaled to `bias_mm` RMS over the ±400 mm box, and by the sensor as its
sensor-frame position plus noise: per-axis N(0, `noise_mm`), or with `polar` the same σ along the line of sight from
the sensor frame's origin and a third of it across (a tracker's shape). The robot's own reading noise is
N(0, `noise_mm`) per axis. The field and the noise are not the bounds' model: the bounds see only the readings.

Layouts: ``volume`` (registration points, fiducials and checks uniform in the box) or ``plane`` (registration points
and fiducials on z ≈ 0 within 1 mm, checks up to ±150 mm off it). `repeats` reads every point twice.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from rrbc_core.io.measurements import MeasurementSet

BOX_MM = 400.0


def _field(rng: np.random.Generator, wavelength_mm: float, bias_mm: float):
    k = rng.normal(size=(6, 3))
    k /= np.linalg.norm(k, axis=1)[:, None]
    k *= 2 * np.pi / wavelength_mm * rng.uniform(0.5, 1.5, (6, 1))
    amp = rng.normal(size=(6, 3))
    phase = rng.uniform(0, 2 * np.pi, 6)

    def raw(p: np.ndarray) -> np.ndarray:
        return np.sin(p @ k.T + phase) @ amp

    box = rng.uniform(-BOX_MM, BOX_MM, (2000, 3))
    scale = bias_mm / np.sqrt(np.mean(np.sum(raw(box) ** 2, axis=1))) if bias_mm > 0 else 0.0
    return lambda p: scale * raw(p)


def field_measurements(
    seed: int,
    *,
    n_fiducials: int = 30,
    n_checks: int = 60,
    n_registration: int = 6,
    layout: str = "volume",
    noise_mm: float = 0.03,
    bias_mm: float = 0.5,
    wavelength_mm: float = 800.0,
    repeats: bool = False,
    polar: bool = False,
) -> MeasurementSet:
    """One seeded station (module docstring): ``R*`` registration, ``F*`` fiducial and ``C*`` check rows (checks
    carry the robot's reading of the point: what `rrbc correct` scores against)."""
    rng = np.random.default_rng(seed)
    rot = Rotation.random(random_state=seed).as_matrix()
    t = rng.uniform(-2000, 2000, 3)
    bias = _field(rng, wavelength_mm, bias_mm)

    def points(n: int, on_plane: bool) -> np.ndarray:
        p = rng.uniform(-BOX_MM, BOX_MM, (n, 3))
        if layout == "plane":
            p[:, 2] = rng.normal(0, 0.3, n) if on_plane else rng.uniform(-150, 150, n)
        return p

    phys = np.vstack([points(n_registration, True), points(n_fiducials, True), points(n_checks, False)])
    ids = (
        [f"R{i}" for i in range(n_registration)]
        + [f"F{i}" for i in range(n_fiducials)]
        + [f"C{i}" for i in range(n_checks)]
    )
    roles = ["registration"] * n_registration + ["fiducial"] * n_fiducials + ["check"] * n_checks

    def sensor_noise(ps: np.ndarray) -> np.ndarray:
        if not polar:
            return rng.normal(0, noise_mm, ps.shape)
        u = ps / np.linalg.norm(ps, axis=1)[:, None]
        across = rng.normal(0, noise_mm / 3, ps.shape)
        across -= np.sum(across * u, axis=1)[:, None] * u
        return across + u * rng.normal(0, noise_mm, (len(ps), 1))

    all_ids, all_roles, sensor, robot = [], [], [], []
    for _ in range(2 if repeats else 1):
        ps = (phys - t) @ rot  # robot = R sensor + t
        sensor.append(ps + sensor_noise(ps))
        robot.append(phys + bias(phys) + rng.normal(0, noise_mm, phys.shape))
        all_ids += ids
        all_roles += roles
    n = len(all_ids)
    return MeasurementSet(
        tuple(all_ids),
        tuple(all_roles),
        np.vstack(sensor),
        np.vstack(robot),
        np.full(n, np.nan),
        tuple(range(1, n + 1)),
        f"<field seed {seed}>",
    )
