"""How the robot holds its tool at a point: straight down turned by the scene's yaw, or leaned (the Arm tab's targets,
varied registration poses). Robot base frame; angles in degrees."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from rrbc_core.models.kinematics import tool_down

TILT_MAX_DEG = 60.0
VARIED_TILT_DEG = 30.0


def tool_rotation(yaw_deg: float, tilt_deg: float = 0.0, azimuth_deg: float = 0.0) -> np.ndarray:
    """Tool rotation (3, 3), robot frame: tool-down turned by yaw (kinematics.tool_down), then its axis leaned by
    tilt_deg towards the azimuth azimuth_deg (degrees)."""
    base = tool_down(yaw_deg)
    if tilt_deg == 0:
        return base
    a = np.radians(azimuth_deg)
    # about k = (sin a, −cos a, 0): the tool axis −z goes to (sin t cos a, sin t sin a, −cos t)
    axis = np.array([np.sin(a), -np.cos(a), 0.0])
    return Rotation.from_rotvec(axis * np.radians(tilt_deg)).as_matrix() @ base
