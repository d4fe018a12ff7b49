"""The frames of the scene: the robot's base, the sensor's true pose (scene mode) and its registered pose, drawn
with its error magnified (`node_values.registered_frame_pose`), its label saying by how much. Robot frame, mm. The
class keeps its handles; the frames' labels are made by the scene (`label`, `relabel`: they follow the labels layer
and a lesson's de-overlap like every other label)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import viser.transforms as vtf

from .node_values import wxyz
from .picture import AXES_SHARE

#: (name, text, position) -> None: a label node the scene owns (`nodes.SceneNodes._label`)
MakeLabel = Callable[[str, str, Any], None]
#: (name, text) -> None: a new text for a label the scene owns
Relabel = Callable[[str, str], None]
REGISTERED_LABEL = "/frames/sensor_registered/label"


class FrameNodes:
    """Robot, true-sensor and registered-sensor frames (module docstring)."""

    def __init__(self, scene) -> None:
        self._scene = scene
        self._registered: Any = None
        self._poses: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # frame name -> (rotation (3, 3), origin (3,))
        self._magnified = False  # the registered frame is drawn beside a true pose, its error magnified
        self._mag = 1.0
        self._compact = False

    def build(self, extent_mm: float, true_pose, registered, label: MakeLabel) -> None:
        """The frames, their axes `AXES_SHARE` of the point sets' extent long; `true_pose` (a RigidTransform or None)
        and `registered` (the registration's mapping) where they are, until `show`."""
        sc = self._scene
        axes = AXES_SHARE * extent_mm
        sc.add_frame("/frames/robot", axes_length=axes, axes_radius=axes * 0.03)
        self._poses = {"/frames/robot": (np.eye(3), np.zeros(3))}
        label("/frames/robot/label", "robot base", (0.0, 0.0, axes * 0.2))
        if true_pose is not None:
            sc.add_frame(
                "/frames/sensor_true",
                axes_length=axes,
                axes_radius=axes * 0.03,
                wxyz=wxyz(true_pose.rotation),
                position=np.asarray(true_pose.translation, float),
            )
            self._poses["/frames/sensor_true"] = (
                np.asarray(true_pose.rotation, float),
                np.asarray(true_pose.translation, float),
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
        self._poses["/frames/sensor_registered"] = (
            np.asarray(registered.rotation, float),
            np.asarray(registered.translation, float),
        )
        label(REGISTERED_LABEL, "sensor (registered)", (0.0, 0.0, -axes * 0.2))
        self._magnified = true_pose is not None

    def show(self, registered_wxyz, registered_position, magnification: float, relabel: Relabel) -> None:
        """The registered frame where the picture draws it, its error `magnification` times larger (its label says
        so when a true pose is drawn beside it)."""
        self._registered.wxyz = registered_wxyz
        self._registered.position = registered_position
        rotation = vtf.SO3(np.asarray(registered_wxyz, float)).as_matrix()
        self._poses["/frames/sensor_registered"] = (rotation, np.asarray(registered_position, float))
        self._mag = magnification
        if self._magnified:
            relabel(REGISTERED_LABEL, self._label_text())

    def set_compact(self, compact: bool, relabel: Relabel) -> None:
        """Presentation mode: the registered frame's label in its short form."""
        self._compact = compact
        if self._magnified:
            relabel(REGISTERED_LABEL, self._label_text())

    def to_robot(self, frame: str, local) -> np.ndarray:
        """A point (3,) given in frame `frame`'s own coordinates (e.g. a label's position), in the robot frame (mm)."""
        rotation, origin = self._poses.get(frame, (np.eye(3), np.zeros(3)))
        return rotation @ np.asarray(local, float) + origin

    def _label_text(self) -> str:
        if self._compact:
            return f"registered (error ×{self._mag:g})"
        return f"sensor (registered, error ×{self._mag:g})"
