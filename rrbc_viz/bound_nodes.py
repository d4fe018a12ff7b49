"""Each target's 95 % bound in the scene (/bounds/<id>: a translucent ellipsoid about the target, magnified as the
arrows are or at true size (`picture.BOUND_SCALES`, the semi-axes it is handed), the
95 % region of its corrected position's error covariance, `rrbc_core.correction.bound_radius.bound_ellipsoids`; hidden
where the data back no bound). Robot frame, mm. The class keeps its handles and is handed values (`build`, `show`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from . import colors
from .node_values import node_key, wxyz

BOUND_OPACITY = 0.3

#: (handle, attribute, value) -> None: assigns unless the value is the one last sent (`nodes.SceneNodes._assign`)
Assign = Callable[[Any, str, Any], None]


class BoundNodes:
    """The targets' bound ellipsoids (module docstring)."""

    def __init__(self, scene) -> None:
        self._scene = scene
        self._nodes: dict[str, Any] = {}  # target id -> icosphere

    def clear(self) -> None:
        self._nodes.clear()

    def build(self, ids) -> None:
        """One hidden ellipsoid per target id."""
        self._nodes = {
            pid: self._scene.add_icosphere(
                f"/bounds/{node_key(pid)}",
                radius=1.0,
                color=colors.BOUND,
                subdivisions=3,
                opacity=BOUND_OPACITY,
                visible=False,
                cast_shadow=False,
                receive_shadow=False,
            )
            for pid in ids
        }

    def show(self, ids, positions, rotations, axes, assign: Assign) -> None:
        """Ellipsoid of target ids[i] at positions[i] (3,) with axes' rotation rotations[i] (3, 3) and semi-axes
        axes[i] (3,) mm; hidden where the semi-axes are NaN (no bound)."""
        for i, pid in enumerate(ids):
            node = self._nodes.get(pid)
            if node is None:
                continue
            ok = bool(np.all(np.isfinite(axes[i])))
            assign(node, "visible", ok)
            if ok:
                assign(node, "position", tuple(float(x) for x in positions[i]))
                assign(node, "wxyz", tuple(float(x) for x in wxyz(rotations[i])))
                assign(node, "scale", tuple(float(max(a, 1e-6)) for a in axes[i]))
