"""The targets' regions of variability (/regions/<id>: a translucent box or icosphere, drawn `region_zoom` times
larger about its target) and their coverage halos (/targets/<id>/gizmo/coverage: a translucent sphere that follows
the target's gizmo in the browser, visible from afar where a region of a few mm is a pixel). Robot frame, mm. The
class keeps its handles and is handed values (`build`, `move`, `paint`, `resize`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from . import colors
from .node_values import gizmo_name, node_key

HALO_MARKERS = 1.8  # coverage halo radius, in marker radii (the target sphere is 0.8)
HALO_OPACITY = 0.45
REGION_OPACITY = 0.35

#: (handle, attribute, value) -> None: assigns unless the value is the one last sent (`nodes.SceneNodes._assign`)
Assign = Callable[[Any, str, Any], None]


class RegionNodes:
    """Regions of variability and coverage halos (module docstring)."""

    def __init__(self, scene) -> None:
        self._scene = scene
        self._regions: dict[str, Any] = {}  # target id -> box or icosphere handle
        self._kinds: dict[str, tuple[str, np.ndarray]] = {}  # target id -> (kind, size mm)
        self._halos: dict[str, Any] = {}  # target id -> coverage halo

    def clear(self) -> None:
        self._regions.clear()
        self._kinds.clear()
        self._halos.clear()

    def any(self) -> bool:
        """Whether any target has a region drawn."""
        return bool(self._regions)

    def build(self, regions: dict, ids, positions, zoom: float) -> None:
        """A region per target id that has one in `regions` (id -> a region with `kind` "box" or "sphere" and
        `size` (3,) mm), at `positions` (N, 3)."""
        for pid, p in zip(ids, np.asarray(positions, float).reshape(-1, 3)):
            region = regions.get(pid)
            if region is None:
                continue
            name = f"/regions/{node_key(pid)}"
            size = np.asarray(region.size, float)
            h: Any
            if region.kind == "box":
                h = self._scene.add_box(
                    name,
                    color=colors.REGION,
                    dimensions=tuple(size),
                    opacity=REGION_OPACITY,
                    scale=zoom,
                    position=p,
                    cast_shadow=False,
                    receive_shadow=False,
                )
            else:
                h = self._scene.add_icosphere(
                    name,
                    radius=1.0,
                    color=colors.REGION,
                    subdivisions=3,
                    opacity=REGION_OPACITY,
                    scale=tuple(size * zoom),
                    position=p,
                    cast_shadow=False,
                    receive_shadow=False,
                )
            self._regions[pid] = h
            self._kinds[pid] = (region.kind, size)

    def build_halos(self, ids, marker_mm: float) -> None:
        """A hidden coverage halo around each of these targets (children of their gizmos: they follow a drag)."""
        self._halos = {
            pid: self._scene.add_icosphere(
                f"{gizmo_name('targets', pid)}/coverage",
                radius=HALO_MARKERS * marker_mm,
                color=colors.REGION,
                subdivisions=2,
                opacity=HALO_OPACITY,
                visible=False,
                cast_shadow=False,
                receive_shadow=False,
            )
            for pid in ids
        }

    def move(self, pid: str, position, assign: Assign) -> None:
        """Target `pid`'s region follows it."""
        region = self._regions.get(pid)
        if region is not None:
            assign(region, "position", tuple(position))

    def paint(self, colours: dict | None, marker_mm: float, assign: Assign) -> None:
        """Colour each region and its halo by `colours` (target id -> RGB), or give the regions their own colour
        back and hide the halos (None)."""
        colours = colours or {}
        for pid, region in self._regions.items():
            assign(region, "color", tuple(colours.get(pid, colors.REGION)))
        for pid, halo in self._halos.items():
            assign(halo, "visible", pid in colours)
            if pid in colours:
                assign(halo, "color", tuple(colours[pid]))
            assign(halo, "radius", HALO_MARKERS * marker_mm)

    def resize(self, zoom: float) -> None:
        """New region zoom."""
        for pid, region in self._regions.items():
            kind, size = self._kinds[pid]
            region.scale = float(zoom) if kind == "box" else tuple(size * zoom)
