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
#: (name, position) -> None: a label the scene owns moved (its parent's frame, mm)
Move = Callable[[str, Any], None]
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
        self._zoom = 1.0  # the sensor's frames' axes drawn this many times their length (`zoom`)
        self._sizes: dict[str, tuple[Any, float, float]] = {}  # frame name -> (handle, axes length, radius) at zoom 1
        self._move: Move | None = None

    def build(self, extent_mm: float, true_pose, registered, label: MakeLabel, move: Move) -> None:
        """The frames, their axes `AXES_SHARE` of the point sets' extent long (the sensor's times the zoom, `zoom`);
        `true_pose` (a RigidTransform or None) and `registered` (the registration's mapping) where they are, until
        `show`."""
        sc = self._scene
        axes = AXES_SHARE * extent_mm
        self._move = move
        self._sizes = {}
        self._poses = {}
        # (name, rotation, origin, label, length and radius as shares of `axes`, more of its look)
        frames: list[tuple[str, np.ndarray, np.ndarray, str, float, float, dict]] = [
            ("/frames/robot", np.eye(3), np.zeros(3), "robot base", 1.0, 0.03, {})
        ]
        if true_pose is not None:
            rot, origin = np.asarray(true_pose.rotation, float), np.asarray(true_pose.translation, float)
            frames.append(("/frames/sensor_true", rot, origin, "sensor (true pose)", 1.0, 0.03, {}))
        rot, origin = np.asarray(registered.rotation, float), np.asarray(registered.translation, float)
        # thin and longer, its origin black: seen against the cell's light surfaces
        frames.append(
            (
                "/frames/sensor_registered",
                rot,
                origin,
                "sensor (registered)",
                1.3,
                0.012,
                {"origin_color": (20, 20, 20)},
            )
        )
        for name, rot, origin, text, length, radius, look in frames:
            handle = sc.add_frame(
                name,
                axes_length=axes * length * self._scale(name),
                axes_radius=axes * radius * self._scale(name),
                wxyz=wxyz(rot),
                position=origin,
                **look,
            )
            self._sizes[name] = (handle, axes * length, axes * radius)
            self._poses[name] = (rot, origin)
            label(name + "/label", text, self._label_position(name))
        self._registered = self._sizes["/frames/sensor_registered"][0]
        self._magnified = true_pose is not None

    def zoom(self, factor: float) -> None:
        """The sensor's frames' axes drawn `factor` times their length and thickness (the lesson step that talks
        about them: high above the work they are a few pixels long), their labels kept clear of them."""
        self._zoom = float(factor)
        for name, (handle, length, radius) in self._sizes.items():
            handle.axes_length = length * self._scale(name)
            handle.axes_radius = radius * self._scale(name)
        self._place_labels()

    def _scale(self, name: str) -> float:
        return 1.0 if name == "/frames/robot" else self._zoom

    def _place_labels(self) -> None:
        if self._move is not None:
            for name in self._sizes:
                self._move(name + "/label", self._label_position(name))

    def _label_position(self, name: str) -> np.ndarray:
        """Frame `name`'s label position in its own coordinates (mm): clear of its axes, which run from its origin in
        any direction: above their highest tip (the robot's and the true sensor's) or below their lowest (the
        registered sensor's, drawn beside the true one). Labels hang from their anchor upwards, so the one below
        starts lower by about a label's height at the frames' own scale."""
        rotation, _ = self._poses[name]
        length = self._sizes[name][1] * self._scale(name)
        heights = rotation[2] * length  # the axes' tips' heights above the origin (robot frame z up)
        if name == "/frames/sensor_registered":
            world = np.array([0.0, 0.0, min(0.0, float(heights.min())) - 0.6 * length])
        else:
            world = np.array([0.0, 0.0, max(0.0, float(heights.max())) + 0.15 * length])
        return rotation.T @ world

    def show(self, registered_wxyz, registered_position, magnification: float, relabel: Relabel) -> None:
        """The registered frame where the picture draws it, its error `magnification` times larger (its label says
        so when a true pose is drawn beside it)."""
        self._registered.wxyz = registered_wxyz
        self._registered.position = registered_position
        rotation = vtf.SO3(np.asarray(registered_wxyz, float)).as_matrix()
        self._poses["/frames/sensor_registered"] = (rotation, np.asarray(registered_position, float))
        if self._move is not None and "/frames/sensor_registered" in self._sizes:
            self._move(REGISTERED_LABEL, self._label_position("/frames/sensor_registered"))
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
