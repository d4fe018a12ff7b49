"""RRBC proper: corrections at the fiducials (steps 5–6) and corrected targets (steps 8–9).

Frames and units: sensor points s and robot points b in mm; corrections e are sensor-frame vectors (mm). Names
follow docs/architecture.md ("Frames in names"): `T_robot_sensor` maps the sensor frame to the robot frame,
`s_sensor`/`p_sensor` are sensor-frame points, `b_robot` robot readings, `b_hat_robot` corrected robot points.

    e_i = mapping⁻¹(b_i) − s_i          (rigid case: e_i = Rᵀ (b_i − t) − s_i)
    ê(x) = interpolator(x)              (fitted on the fiducials' sensor points and corrections)
    b̂(x) = mapping(x + ê(x))            (rigid case: R (x + ê(x)) + t)

For a piecewise (clustered) mapping, each point uses the piece of the kernel nearest its sensor position.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.points import as_points


def _pieces(T_robot_sensor, p_sensor):
    return T_robot_sensor.piece_of(p_sensor) if T_robot_sensor.piecewise else None


def _inverse(T_robot_sensor, b_robot, pieces):
    return T_robot_sensor.apply_inverse(b_robot) if pieces is None else T_robot_sensor.apply_inverse(b_robot, pieces)


def _forward(T_robot_sensor, p_sensor, pieces):
    return T_robot_sensor.apply(p_sensor) if pieces is None else T_robot_sensor.apply(p_sensor, pieces)


def fiducial_corrections(T_robot_sensor, s_sensor, b_robot) -> np.ndarray:
    """Corrections at the fiducials (RRBC steps 5–6): the robot readings taken back into the sensor frame by the
    inverse registration, minus the sensor readings.

    Parameters
    ----------
    T_robot_sensor : SensorToRobot
        The registration's mapping (`Registration.mapping`).
    s_sensor : array_like, (N, 3)
        The fiducials as the sensor read them, sensor frame, mm.
    b_robot : array_like, (N, 3)
        The same fiducials as the robot read them, robot frame, mm.

    Returns
    -------
    e_sensor : ndarray, (N, 3)
        Corrections, sensor-frame vectors, mm.
    """
    s_fid = as_points(s_sensor, "fiducial sensor points")
    b_fid = as_points(b_robot, "fiducial robot points")
    if s_fid.shape != b_fid.shape:
        raise InputError(f"fiducials must pair up: {len(s_fid)} sensor vs {len(b_fid)} robot points")
    return _inverse(T_robot_sensor, b_fid, _pieces(T_robot_sensor, s_fid)) - s_fid


@dataclass(frozen=True, eq=False)
class CorrectedPoints:
    """Targets (or check points) corrected by RRBC. All (M, 3) mm unless stated.

    sensor: as measured (sensor frame); correction: interpolated ê (sensor frame); correction_std: its
    standard deviation where the interpolator has one, else None; robot_rigid: mapping(sensor);
    robot_rrbc: mapping(sensor + correction); extrapolated (M,) bool: outside the fiducials' hull;
    off_plane_mm (M,): distance from the fiducials' plane/line (0 for a 3-D fiducial set).
    """

    sensor: np.ndarray
    correction: np.ndarray
    correction_std: np.ndarray | None
    robot_rigid: np.ndarray
    robot_rrbc: np.ndarray
    extrapolated: np.ndarray
    off_plane_mm: np.ndarray


def correct_points(T_robot_sensor, fitted_interpolator, p_sensor) -> CorrectedPoints:
    """Corrected robot positions of sensor-measured points (RRBC steps 8–9): b̂ = T_robot_sensor(x + ê(x)).

    Parameters
    ----------
    T_robot_sensor : SensorToRobot
        The registration's mapping.
    fitted_interpolator : FittedInterpolator
        The correction field fitted on the fiducials (sensor frame).
    p_sensor : array_like, (M, 3)
        The points as the sensor read them, sensor frame, mm.

    Returns
    -------
    CorrectedPoints
        Rigid and RRBC positions (robot frame, mm), the interpolated corrections and their coverage.
    """
    x_sensor = as_points(p_sensor, "target sensor points")
    pred = fitted_interpolator.predict(x_sensor)
    pieces = _pieces(T_robot_sensor, x_sensor)
    b_rigid_robot = _forward(T_robot_sensor, x_sensor, pieces)
    b_hat_robot = _forward(T_robot_sensor, x_sensor + pred.values, pieces)
    return CorrectedPoints(
        x_sensor, pred.values, pred.std, b_rigid_robot, b_hat_robot, pred.extrapolated, pred.off_plane_mm
    )
