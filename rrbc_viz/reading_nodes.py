"""A fiducial's two readings in the scene (`ReadingNodes`, held by `nodes.SceneNodes`), for the lesson step that maps
the robot's readings back: where the registration puts the sensor's reading (R s + t) and the robot's own reading b,
both robot frame. They lie a fraction of a millimetre apart, inside the fiducial's sphere, so the pair is drawn
beside it: s at a point a few marker radii above the fiducial (a grey leader joins them) and b at s plus the readings'
offset magnified, a line between, each labelled. It owns /readings/*."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import colors
from .node_values import FiducialReadings


class ReadingNodes:
    """The readings' nodes (module docstring)."""

    def __init__(self, scene) -> None:
        self.scene = scene
        self._handles: list[Any] = []
        self._key: tuple | None = None

    def clear(self) -> None:
        for h in self._handles:
            h.remove()
        self._handles = []
        self._key = None

    def show(self, readings: FiducialReadings | None, marker_mm: float) -> None:
        """Draw `readings` (None removes them); unchanged readings are not sent again."""
        key = (
            None
            if readings is None
            else (
                readings.pid,
                np.asarray(readings.fiducial, float).tobytes(),
                np.asarray(readings.sensor, float).tobytes(),
                np.asarray(readings.robot, float).tobytes(),
                float(readings.magnification),
                float(marker_mm),
            )
        )
        if key == self._key:
            return
        self.clear()
        self._key = key
        if readings is None:
            return
        s, b = readings.drawn(marker_mm)
        sc = self.scene
        r = 0.8 * marker_mm
        offset = float(np.linalg.norm(np.asarray(readings.robot) - np.asarray(readings.sensor)))
        self._handles = [
            sc.add_line_segments(
                "/readings/leader",
                np.array([[readings.fiducial, s]], float),
                colors=colors.LAND_STALK,
                thickness=1.0,
                thickness_units="screen",
            ),
            sc.add_line_segments(
                "/readings/offset",
                np.array([[s, b]], float),
                colors=colors.READING_ROBOT,
                thickness=2.5,
                thickness_units="screen",
            ),
            sc.add_icosphere("/readings/sensor", radius=r, color=colors.READING_SENSOR, position=s),
            sc.add_icosphere("/readings/robot", radius=r, color=colors.READING_ROBOT, position=b),
            sc.add_label(
                "/readings/sensor_label",
                f"s: {readings.pid}'s sensor reading, placed by (R, t)",
                position=s,
                font_size_mode="screen",
                font_screen_scale=0.75,
                anchor="top-right",
            ),
            sc.add_label(
                "/readings/robot_label",
                f"b: the robot's reading ({offset:.3f} mm away, drawn ×{readings.magnification:g})",
                position=b,
                font_size_mode="screen",
                font_screen_scale=0.75,
                anchor="bottom-left",
            ),
        ]
