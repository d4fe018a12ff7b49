"""The frames of the scene: the robot's base, the sensor's true pose (scene mode) and its registered pose, drawn
with its error magnified (`node_values.registered_frame_pose`) and a note saying by how much. Robot frame, mm. The
class keeps its handles; the frames' labels are made by the scene (`label`: they follow the labels layer)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .node_values import wxyz
from .picture import AXES_SHARE

#: (name, text, position) -> None: a label node the scene owns (`nodes.SceneNodes._label`)
MakeLabel = Callable[[str, str, Any], None]
NOTE = "/frames/sensor_registered/note"


class FrameNodes:
    """Robot, true-sensor and registered-sensor frames (module docstring)."""

    def __init__(self, scene) -> None:
        self._scene = scene
        self._registered: Any = None
        self._note: Any = None
        self._mag = 1.0
        self._compact = False

    def build(self, extent_mm: float, true_pose, registered, label: MakeLabel) -> None:
        """The frames, their axes `AXES_SHARE` of the point sets' extent long; `true_pose` (a RigidTransform or None)
        and `registered` (the registration's mapping) where they are, until `show`."""
        sc = self._scene
        axes = AXES_SHARE * extent_mm
        sc.add_frame("/frames/robot", axes_length=axes, axes_radius=axes * 0.03)
        label("/frames/robot/label", "robot base", (0.0, 0.0, axes * 0.2))
        if true_pose is not None:
            sc.add_frame(
                "/frames/sensor_true",
                axes_length=axes,
                axes_radius=axes * 0.03,
                wxyz=wxyz(true_pose.rotation),
                position=np.asarray(true_pose.translation, float),
            )
            label("/frames/sensor_true/label", "sensor (true pose)", (0.0, 0.0, axes * 0.2))
        self._registered = sc.add_frame(
            "/frames/sensor_registered",
            axes_length=axes * 1.3,
            axes_radius=axes * 0.012,
            origin_color=(20, 20, 20),  # black: seen against the cell's light surfaces
            wxyz=wxyz(registered.rotation),
            position=np.asarray(registered.translation, float),
        )
        label("/frames/sensor_registered/label", "sensor (registered)", (0.0, 0.0, -axes * 0.2))
        self._note = None
        if true_pose is not None:  # the registered frame's error is drawn magnified: say so, always
            self._note = sc.add_label(
                NOTE, "", position=(0.0, 0.0, -axes * 0.45), font_size_mode="screen", font_screen_scale=0.75,
                anchor="top-left",
            )  # fmt: skip

    def show(self, registered_wxyz, registered_position, magnification: float, assign) -> None:
        """The registered frame where the picture draws it, its error `magnification` times larger."""
        self._registered.wxyz = registered_wxyz
        self._registered.position = registered_position
        self._mag = magnification
        if self._note is not None:
            assign(self._note, "text", self._note_text())

    def set_compact(self, compact: bool, label_scale: float, assign) -> None:
        """Presentation mode: a short note, larger and centred (it must stay left of the panel)."""
        self._compact = compact
        if self._note is not None:
            assign(self._note, "text", self._note_text())
            self._note.font_screen_scale = 0.8 * label_scale if compact else 0.75
            self._note.anchor = "top-center" if compact else "top-left"  # below the frame, clear of its label

    def _note_text(self) -> str:
        if self._compact:
            return f"registered ×{self._mag:g}"
        return f"registration error ×{self._mag:g} (drawn beside the true pose)"
