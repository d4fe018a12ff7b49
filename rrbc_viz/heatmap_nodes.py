"""The heat map in the scene (`HeatMapNodes`, held by `nodes.SceneNodes`): its samples coloured by the chosen value,
and a ring around each target with the mean over its region. It owns its two point clouds (/heatmap/points,
/heatmap/rings) and is handed values: a `HeatMap`, the Evaluation and the display options."""

from __future__ import annotations

from typing import Any

import numpy as np

from rrbc_core.session.evaluation import Evaluation
from rrbc_core.session.results import HeatMap

from . import colors
from .node_values import Display

RING_INNER_MARKERS = 1.15  # least inner radius of a heat-map ring, in marker radii (the target sphere is 0.8)
RING_WIDTH_MARKERS = 1.3  # ring width (outer - inner radius), in marker radii
RING_ROWS = 3  # concentric rows of dots across a ring; the dots are as wide as the rows are apart, so they touch


def _ring_dots(inner: float, width: float, rows: int = RING_ROWS) -> np.ndarray:
    """Centres (N, 3) of dots filling a flat ring in the xy-plane about the origin, `rows` circles between radius
    `inner` and `inner + width`, the dots on each about width/rows apart (a point cloud of that point size then
    covers the ring)."""
    step = width / rows
    out = []
    for k in range(rows):
        rad = inner + (k + 0.5) * step
        n = max(12, int(np.ceil(2 * np.pi * rad / (0.75 * step))))
        a = np.arange(n) * (2 * np.pi / n) + (k % 2) * np.pi / n
        out.append(np.stack([rad * np.cos(a), rad * np.sin(a), np.zeros(n)], axis=1))
    return np.vstack(out)


class HeatMapNodes:
    """The heat map's nodes (module docstring)."""

    def __init__(self, scene) -> None:
        self.scene = scene
        self.points: Any = None  # the samples' point cloud (viser's PointCloudHandle once built)
        self.rings: Any = None  # the rings' point cloud (None without targets)
        self.display = Display()  # the display options the map was last drawn with
        self._rings_args: tuple | None = None  # what the rings were last drawn from (redrawn on a resize)

    def build(self, with_rings: bool) -> dict:
        """Create the two point clouds (hidden until `show`); returns them by name."""
        self._rings_args = None
        self.points = self.scene.add_point_cloud(
            "/heatmap/points",
            np.zeros((1, 3), np.float32),
            np.zeros((1, 3), np.uint8),
            point_size=0.5,
            point_shape="circle",
            precision="float32",
            visible=False,
        )
        self.rings = None
        if with_rings:  # unlit (flat shading): the ring shows the legend's colours, whatever the light
            self.rings = self.scene.add_point_cloud(
                "/heatmap/rings",
                np.zeros((1, 3), np.float32),
                np.zeros((1, 3), np.uint8),
                point_size=1.0,
                point_shape="circle",
                point_shading="flat",
                precision="float32",
                visible=False,
            )
        out = {"/heatmap/points": self.points}
        if self.rings is not None:
            out["/heatmap/rings"] = self.rings
        return out

    def clear(self) -> None:
        self.points = self.rings = None
        self._rings_args = None

    def resize(self, display: Display) -> None:
        """Redraw the rings for new marker sizes or region zoom."""
        self.display = display
        if self.rings is not None and self._rings_args is not None:
            self._update_heat_rings(self.rings, *self._rings_args)

    # ------------------------------------------------------------------------------------------ heat map
    def show(self, hm: HeatMap | None, ev: Evaluation, display: Display) -> tuple[str, float, float] | None:
        """Show a `HeatMap` (from views.heat_map(session)) coloured by the chosen value; returns (title, lo, hi) for
        the legend, or None if there is nothing to show. Samples are drawn `region_zoom` times farther from
        their target than they are."""
        self.display = display
        node = self.points
        rings = self.rings
        if hm is None or len(hm.positions) == 0:
            node.visible = False
            if rings is not None:
                rings.visible = False
            return None
        key = self.display.heat_value
        if key == "std" and hm.std_mm is not None:
            values, title = hm.std_mm, "Correction std (gp), mm"
            lo, hi = float(np.nanmin(values)), float(np.nanmax(values))
        elif key in ("correction", "std"):
            values, title = hm.correction_mm, "Correction size |ê|, mm"
            lo, hi = float(np.nanmin(values)), float(np.nanmax(values))
        else:
            values = hm.error_rigid if key == "rigid" else hm.error_rrbc
            title = f"Predicted error, {'rigid only' if key == 'rigid' else 'with RRBC'} (shared scale, mm)"
            both = np.concatenate([hm.error_rigid, hm.error_rrbc])
            both = both[np.isfinite(both)]
            if not len(both):
                node.visible = False
                if rings is not None:
                    rings.visible = False
                return None
            lo, hi = float(both.min()), float(both.max())
        centre = dict(zip(ev.targets.ids, ev.targets.positions))
        owner = np.array([centre[o] for o in hm.target]) if len(hm.target) else np.zeros((0, 3))
        offsets = hm.positions - owner
        pts = owner + self.display.region_zoom * offsets
        spread = float(np.median(np.abs(offsets))) if len(offsets) else 1.0
        node.points = pts.astype(np.float32)
        node.colors = colors.scale_colors(values, lo, hi)
        node.point_size = max(0.05, 0.6 * spread * self.display.region_zoom)
        node.visible = True
        if rings is not None:
            self._rings_args = (hm, ev, values, lo, hi, offsets)
            self._update_heat_rings(rings, *self._rings_args)
        return title, lo, hi

    def _update_heat_rings(self, rings, hm, ev: Evaluation, values, lo: float, hi: float, offsets) -> None:
        """A flat ring of dots around each target, coloured by the mean of `values` over its region's samples (same
        colour scale as the samples). A region is a few mm across in a cell of about a metre: at the overview its
        samples cover a pixel or two (and hide inside the target sphere), the ring (a few marker radii) stays
        visible. Its inner radius clears the target sphere and the region as drawn (× region zoom), so up close
        the samples stay visible; the dots are lifted by their radius so the surface a target sits on does not
        cut them."""
        t = ev.targets
        r = self.display.marker_mm
        vals = np.asarray(values, float)
        width = RING_WIDTH_MARKERS * r
        size = width / RING_ROWS
        # per target at once (group the samples by owner): the mean value and the region's reach
        index = {pid: i for i, pid in enumerate(t.ids)}
        owner = np.fromiter((index.get(o, -1) for o in hm.target), int, len(hm.target))
        known = owner >= 0
        ok = known & np.isfinite(vals)
        n_t = len(t.ids)
        counts = np.bincount(owner[ok], minlength=n_t)
        sums = np.bincount(owner[ok], weights=vals[ok], minlength=n_t)
        with np.errstate(invalid="ignore", divide="ignore"):
            means = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
        reach = np.zeros(n_t)
        np.maximum.at(reach, owner[known], np.linalg.norm(offsets[known, :2], axis=1) * self.display.region_zoom)
        has = np.bincount(owner[known], minlength=n_t) > 0
        inner = np.where(has, np.maximum(RING_INNER_MARKERS * r, 1.1 * reach), RING_INNER_MARKERS * r)
        ring_colors = colors.scale_colors(means, lo, hi)
        pts, cols = [], []
        for i in range(n_t):
            dots = _ring_dots(float(inner[i]), width) + t.positions[i] + (0.0, 0.0, 0.5 * size)
            pts.append(dots)
            cols.append(np.repeat(ring_colors[i : i + 1], len(dots), axis=0))
        if not pts:
            rings.visible = False
            return
        rings.points = np.vstack(pts).astype(np.float32)
        rings.colors = np.vstack(cols).astype(np.uint8)
        rings.point_size = float(size)
        rings.visible = True
