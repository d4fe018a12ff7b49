"""A measurement file's check rows' errors in the scene (`CheckErrorNodes`, held by `nodes.SceneNodes`): from each
check an arrow along its error (corrected position − measured robot position, after RRBC or rigid as the View tab
picks: `node_values.CheckErrors`) magnified as the correction arrows are (less where that would not fit the view:
`node_values.legible_magnification`), coloured by the error's size on the
heat-map scale from 0 to the largest, a dot at its tip, and the largest few labelled with their size. It owns
/check_errors/arrows, /check_errors/tips and /check_errors/label<k> under the layer's group."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import colors
from .node_values import CHECK_ERROR_LABELS, CheckErrors


class CheckErrorNodes:
    """The check rows' error arrows (module docstring)."""

    def __init__(self, scene) -> None:
        self.scene = scene
        self._arrows: Any = None
        self._tips: Any = None
        self._labels: list[Any] = []
        self._count = -1

    def clear(self) -> None:
        """Forget the handles (the scene removed them with their group)."""
        self._arrows, self._tips, self._labels, self._count = None, None, [], -1

    def _remove(self) -> None:
        for h in [self._arrows, self._tips, *self._labels]:
            if h is not None:
                h.remove()
        self.clear()

    def show(self, errors: CheckErrors | None, marker_mm: float) -> None:
        """Draw `errors` (None: nothing). Handles are kept while the number of checks stays, and updated."""
        n = 0 if errors is None else len(errors.ids)
        if n != self._count:
            self._remove()
            self._count = n
            if errors is None or not n:
                return
            sc = self.scene
            self._arrows = sc.add_line_segments(
                "/check_errors/arrows",
                np.zeros((n, 2, 3), np.float32),
                colors=np.zeros((n, 2, 3), np.uint8),
                thickness=3.0,
                thickness_units="screen",
            )
            self._tips = sc.add_point_cloud(
                "/check_errors/tips",
                np.zeros((n, 3), np.float32),
                np.zeros((n, 3), np.uint8),
                point_size=0.5 * marker_mm,
                point_shape="circle",
            )
            self._labels = [
                sc.add_label(
                    f"/check_errors/label{k}",
                    "",
                    position=np.zeros(3),
                    font_size_mode="screen",
                    font_screen_scale=0.7,
                    anchor="bottom-left",
                )
                for k in range(min(CHECK_ERROR_LABELS, n))
            ]
        if errors is None or not n:
            return
        tips = errors.starts + errors.vectors
        rgb = colors.scale_colors(errors.sizes_mm, 0.0, float(np.nanmax(errors.sizes_mm)))
        self._arrows.points = np.stack([errors.starts, tips], axis=1).astype(np.float32)
        self._arrows.colors = np.repeat(rgb[:, None, :], 2, axis=1)
        self._tips.points = tips.astype(np.float32)
        self._tips.colors = rgb
        self._tips.point_size = 0.5 * marker_mm
        what = "RRBC" if errors.method == "rrbc" else "rigid"
        for label, i in zip(self._labels, errors.labelled):
            label.text = f"{errors.ids[i]}: {errors.sizes_mm[i]:.3f} mm ({what}, ×{errors.magnification:g})"
            label.position = tuple(float(x) for x in tips[i])
