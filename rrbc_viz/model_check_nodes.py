"""The Model tab's rows in the scene (`ModelCheckNode`): each row of the measurement file the scene's model was held
against, at its mapped reading (robot frame, mm), grey inside its predicted 95 % region and dark red outside, with a
line along its misfit (measured minus predicted residual) magnified like the correction arrows. It owns its nodes
(/model_check/…) and keeps their handles private."""

from __future__ import annotations

import numpy as np
import viser

from . import colors


class ModelCheckNode:
    """The rows' point cloud and misfit lines (module docstring), created on first show."""

    def __init__(self, scene: viser.SceneApi):
        self._scene = scene
        self._points: viser.PointCloudHandle | None = None
        self._lines: viser.LineSegmentsHandle | None = None

    def show(self, points: np.ndarray, misfit: np.ndarray, outside: np.ndarray, marker_mm: float, mag: float) -> None:
        """Draw rows at `points` (R, 3) mm with misfits (R, 3) mm drawn `mag` times longer; `outside` (R,) bool."""
        self.hide()
        pts = np.asarray(points, np.float32).reshape(-1, 3)
        col = np.where(np.asarray(outside, bool)[:, None], colors.MODEL_OUTSIDE, colors.MODEL_INSIDE).astype(np.uint8)
        self._points = self._scene.add_point_cloud(
            "/model_check/rows", pts, col, point_size=float(marker_mm) * 0.8, point_shape="circle", precision="float32"
        )
        ends = pts + float(mag) * np.asarray(misfit, np.float32).reshape(-1, 3)
        self._lines = self._scene.add_line_segments(
            "/model_check/misfit",
            np.stack([pts, ends], axis=1),
            np.array(colors.MODEL_MISFIT, np.uint8),
            thickness=1.5,
            thickness_units="screen",
        )

    def hide(self) -> None:
        """Remove the rows (a new check, another source)."""
        for h in (self._points, self._lines):
            if h is not None:
                h.remove()
        self._points = self._lines = None

    def shown(self) -> int:
        """How many rows are drawn (tests)."""
        return 0 if self._points is None else len(self._points.points)
