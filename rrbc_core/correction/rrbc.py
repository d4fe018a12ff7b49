"""RRBC proper: corrections at the fiducials (steps 5–6) and corrected targets (steps 8–9).

Frames and units: sensor points s and robot points b in mm; corrections e are sensor-frame vectors (mm).

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


def _pieces(mapping, sensor):
    return mapping.piece_of(sensor) if mapping.piecewise else None


def _inverse(mapping, robot, pieces):
    return mapping.apply_inverse(robot) if pieces is None else mapping.apply_inverse(robot, pieces)


def _forward(mapping, sensor, pieces):
    return mapping.apply(sensor) if pieces is None else mapping.apply(sensor, pieces)


def fiducial_corrections(mapping, sensor, robot) -> np.ndarray:
    """Corrections e_i (N, 3), sensor frame, mm: the robot-measured fiducials taken back into the sensor frame
    by the inverse registration, minus the sensor-measured fiducials (RRBC steps 5–6)."""
    s = as_points(sensor, "fiducial sensor points")
    b = as_points(robot, "fiducial robot points")
    if s.shape != b.shape:
        raise InputError(f"fiducials must pair up: {len(s)} sensor vs {len(b)} robot points")
    return _inverse(mapping, b, _pieces(mapping, s)) - s


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


def correct_points(mapping, fitted_interpolator, sensor) -> CorrectedPoints:
    """RRBC steps 8–9 for sensor-measured points (M, 3)."""
    x = as_points(sensor, "target sensor points")
    pred = fitted_interpolator.predict(x)
    pieces = _pieces(mapping, x)
    rigid = _forward(mapping, x, pieces)
    rrbc = _forward(mapping, x + pred.values, pieces)
    return CorrectedPoints(x, pred.values, pred.std, rigid, rrbc, pred.extrapolated, pred.off_plane_mm)
