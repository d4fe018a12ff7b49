"""A fiducial's two readings in the scene (`ReadingNodes`, held by `nodes.SceneNodes`), for the lesson step that maps
the robot's readings back: where the registration puts the sensor's reading (R s + t) and the robot's own reading b,
both robot frame. They lie a fraction of a millimetre apart, inside the fiducial's sphere, so the pair is drawn
beside it: s at a point a few marker radii above the fiducial (a grey leader joins them) and b at s plus the readings'
offset magnified, a line between, each labelled. It owns /readings/*."""

from __future__ import annotations

from typing import Any

import numpy as np

from rrbc_core.geometry.label_layout import label_boxes

from . import colors
from .node_values import FiducialReadings

#: Each label's anchor (below left of s, above right of b) and the one mirrored left-right (`keep_inside`).
_MIRRORED = {"top-right": "top-left", "bottom-left": "bottom-right"}


class ReadingNodes:
    """The readings' nodes (module docstring)."""

    def __init__(self, scene) -> None:
        self.scene = scene
        self._handles: list[Any] = []
        self._key: tuple | None = None

    def keep_inside(self, pose, image_px, panel_px: float) -> None:
        """Each label drawn on its own side of its point, or mirrored left-right where its own would leave the view's
        free part (left of the panel) seen by `pose` (a `CameraPose`) in an image of `image_px` (width, height) CSS
        px: the larger labels of presentation mode ran off a projector's view."""
        free = float(image_px[0]) - panel_px
        for h, own in zip(self._handles[-2:], ("top-right", "bottom-left")):  # (the labels: made last, s's first)
            where = np.asarray(h.position, float)[None]
            for anchor in (own, _MIRRORED[own]):
                box = label_boxes(where, [h.text], pose, image_px, h.font_screen_scale, anchor)[0]
                if np.all(np.isfinite(box)) and box[0] >= 0 and box[2] <= free:
                    h.anchor = anchor
                    break
            else:
                h.anchor = own

    def clear(self) -> None:
        for h in self._handles:
            h.remove()
        self._handles = []
        self._key = None

    def show(self, readings: FiducialReadings | None, marker_mm: float, label_scale: float = 1.0) -> None:
        """Draw `readings` (None removes them); unchanged readings are not sent again. `label_scale`: the labels'
        screen size × this (the point labels' scale: presentation mode's is larger, and its labels say less, so that
        they stay short enough for the view)."""
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
                float(label_scale),
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
        mag = f"×{readings.magnification:g}"
        if label_scale > 1.0:  # large labels: a few words each (the step's text says the rest)
            texts = (f"s: {readings.pid} by the sensor", f"b: by the robot, {mag}")
        else:
            texts = (
                f"s: {readings.pid}'s sensor reading, placed by (R, t)",
                f"b: the robot's reading ({offset:.3f} mm away, drawn {mag})",
            )
        font = 0.75 * float(label_scale)
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
                texts[0],
                position=s,
                font_size_mode="screen",
                font_screen_scale=font,
                anchor="top-right",
            ),
            sc.add_label(
                "/readings/robot_label",
                texts[1],
                position=b,
                font_size_mode="screen",
                font_screen_scale=font,
                anchor="bottom-left",
            ),
        ]
