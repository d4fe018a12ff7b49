"""The Model tab's rows in the scene (`ModelCheckNode`): each row of the measurement file the scene's model was held
against, at its mapped reading (robot frame, mm): small grey dots inside their predicted 95 % region, large dark-red
ones outside (larger than the targets' spheres, so a target does not hide them), each with a line along its misfit
(measured minus predicted residual) magnified like the correction arrows. It owns its nodes (/model_check/…) and
keeps their handles private."""

from __future__ import annotations

import numpy as np
import viser

from . import colors

INSIDE_SIZE, OUTSIDE_SIZE = 0.8, 2.4  # dot diameters in marker sizes


class ModelCheckNode:
    """The rows' dots and misfit lines (module docstring), created on each show."""

    def __init__(self, scene: viser.SceneApi):
        self._scene = scene
        self._handles: dict[str, viser.SceneNodeHandle] = {}
        self._count = 0

    def show(self, points: np.ndarray, misfit: np.ndarray, outside: np.ndarray, marker_mm: float, mag: float) -> None:
        """Draw rows at `points` (R, 3) mm with misfits (R, 3) mm drawn `mag` times longer; `outside` (R,) bool."""
        self.hide()
        pts = np.asarray(points, np.float32).reshape(-1, 3)
        out = np.asarray(outside, bool)
        for name, mask, color, size in (
            ("inside", ~out, colors.MODEL_INSIDE, INSIDE_SIZE),
            ("outside", out, colors.MODEL_OUTSIDE, OUTSIDE_SIZE),
        ):
            if mask.any():
                self._handles[name] = self._scene.add_point_cloud(
                    f"/model_check/{name}",
                    pts[mask],
                    np.array(color, np.uint8),
                    point_size=float(marker_mm) * size,
                    point_shape="circle",
                    precision="float32",
                )
        ends = pts + float(mag) * np.asarray(misfit, np.float32).reshape(-1, 3)
        self._handles["misfit"] = self._scene.add_line_segments(
            "/model_check/misfit",
            np.stack([pts, ends], axis=1),
            np.array(colors.MODEL_MISFIT, np.uint8),
            thickness=1.5,
            thickness_units="screen",
        )
        self._count = len(pts)

    def hide(self) -> None:
        """Remove the rows (a new check, another source)."""
        for h in self._handles.values():
            h.remove()
        self._handles = {}
        self._count = 0

    def shown(self) -> int:
        """How many rows are drawn (tests)."""
        return self._count
