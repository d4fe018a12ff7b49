"""The landing bullseye in the scene (`LandingNodes`, held by `nodes.SceneNodes`): for the selected target, where the
robot lands rigid-only and with RRBC (and with VEC when the Arm tab compares it), as offsets from the truth drawn
around an anchor floating above the target, with scale rings and a label. It owns its nodes (/landing/…) and is
handed a `node_values.LandingDisplay`. Robot frame, mm."""

from __future__ import annotations

import numpy as np

from rrbc_core.geometry.label_layout import sphere_boxes

from . import colors
from .lesson_labels import side_anchor
from .node_values import RING_SEGMENTS, LandingDisplay

#: Sphere radii of the bullseye's points, in marker radii.
RADII = {"anchor": 0.45, "rigid": 0.6, "rrbc": 0.6, "vec": 0.6}


def _line_colors() -> np.ndarray:
    c = np.empty((3, 2, 3), np.uint8)
    c[0], c[1], c[2] = colors.LAND_STALK, colors.LAND_RIGID, colors.LAND_RRBC
    return c


class LandingNodes:
    """The bullseye's nodes (module docstring). `build` returns them by name (SceneNodes keeps the registry)."""

    def __init__(self, scene):
        self.scene = scene
        self.handles: dict = {}

    def build(self, marker_mm: float) -> dict:
        sc = self.scene
        h = {}
        for key, color in (
            ("anchor", colors.LAND_ANCHOR),
            ("rigid", colors.LAND_RIGID),
            ("rrbc", colors.LAND_RRBC),
            ("vec", colors.LAND_VEC),
        ):
            h[f"/landing/{key}"] = sc.add_icosphere(
                f"/landing/{key}",
                radius=RADII[key] * marker_mm,
                color=color,
                subdivisions=2,
                cast_shadow=False,
                receive_shadow=False,
            )
        h["/landing/lines"] = sc.add_line_segments(
            "/landing/lines", np.zeros((3, 2, 3), np.float32), _line_colors(), thickness=2.5, thickness_units="screen"
        )
        h["/landing/rings"] = sc.add_line_segments(
            "/landing/rings",
            np.zeros((2 * RING_SEGMENTS, 2, 3), np.float32),
            np.array(colors.LAND_RING, np.uint8),
            thickness=1.5,
            thickness_units="screen",
        )
        h["/landing/scale"] = sc.add_label(
            "/landing/scale", "", font_size_mode="screen", font_screen_scale=0.8, anchor="bottom-left"
        )
        self.handles = h
        return h

    def clear(self) -> None:
        self.handles = {}

    def show(self, land: LandingDisplay, assign) -> None:
        """Place the bullseye for `land`; `assign(handle, attr, value)` sets a property only when it changed."""
        h = self.handles
        if not h:
            return
        h["/landing/anchor"].position = land.anchor
        h["/landing/rigid"].position = land.rigid
        h["/landing/rrbc"].position = land.rrbc
        vec_node = h["/landing/vec"]
        if land.vec is not None:
            vec_node.position = land.vec
        assign(vec_node, "visible", land.vec is not None)  # (the landing layer's frame hides it too)
        h["/landing/lines"].points = np.array(
            [[land.position, land.anchor], [land.anchor, land.rigid], [land.anchor, land.rrbc]], np.float32
        )
        h["/landing/rings"].points = land.rings().astype(np.float32)
        scale = h["/landing/scale"]
        scale.position = land.anchor + np.array([0.71, -0.71, 0.0]) * land.ring_mm * land.scale
        assign(scale, "text", f"{land.target}: ring {land.ring_mm:g} mm")

    def resize(self, marker_mm: float) -> None:
        for key, f in RADII.items():
            node = self.handles.get(f"/landing/{key}")
            if node is not None:
                node.radius = f * marker_mm

    def spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """The shown spheres' centres (K, 3) robot frame mm and radii (K,) mm: the truth's centre and the landings."""
        shown = [n for k, n in self.handles.items() if k.rsplit("/", 1)[-1] in RADII and n.visible]
        centres = np.array([n.position for n in shown], float).reshape(-1, 3)
        return centres, np.array([n.radius for n in shown], float)

    def label(self) -> tuple[np.ndarray, str] | None:
        """The ring label: (where, robot frame mm; its text), None before `build`."""
        node = self.handles.get("/landing/scale")
        if node is None:
            return None
        return np.asarray(node.position, float), str(node.text)

    def ring_points(self) -> np.ndarray:
        """The scale ring's points (RING_SEGMENTS, 3) robot frame mm as drawn (none before `build`)."""
        rings = self.handles.get("/landing/rings")
        if rings is None:
            return np.zeros((0, 3))
        return np.asarray(rings.points, float)[:RING_SEGMENTS, 0]

    def place_label(self, avoid, pose, image_px, panel_px: float, font_scale: float) -> None:
        """The ring label where, seen by `pose` in an image of `image_px`, it meets neither the ring's line, the
        bullseye's spheres, the boxes `avoid` ((K, 4) CSS px: the selected point's label) nor the panel
        (`lesson_labels.side_anchor`): hung `RING_GAP_PX` below the ring's lowest point on screen, else above its
        highest; hidden where no side of either is clear (issue 39: the ring ran through it)."""
        node = self.handles.get("/landing/scale")
        if node is None:
            return
        text = str(node.text)
        boxes = [np.asarray(avoid, float).reshape(-1, 4), sphere_boxes(*self.spheres(), pose, image_px)]
        pts = self.ring_points()
        hangs = [(np.asarray(node.position, float), "top-center")]
        if len(pts):  # points along the ring, 4 a segment, avoided
            seg = np.vstack([pts, pts[:1]])
            t = np.linspace(0.0, 1.0, 4, endpoint=False)[None, :, None]
            along = (seg[:-1, None] + t * np.diff(seg, axis=0)[:, None]).reshape(-1, 3)
            dots = sphere_boxes(along, np.zeros(len(along)), pose, image_px)
            boxes.append(dots)
            if np.isfinite(dots).all():
                y = dots[:, 3]
                hangs = [
                    (_beside(along[int(np.argmax(y))], -1.0, pose, image_px), "top-center"),
                    (_beside(along[int(np.argmin(y))], 1.0, pose, image_px), "bottom-center"),
                ]
        for where, own in hangs:
            anchor = side_anchor(where, text, np.vstack(boxes), pose, image_px, panel_px, font_scale, own)
            if anchor is not None:
                node.position = where
                self.set_label_anchor(anchor)
                return
        self.set_label_anchor(None)

    def set_label_anchor(self, anchor) -> None:
        """Draw the ring label with `anchor` (viser's label anchors: "bottom-left", "top-left", ...), or hide it
        (None: no side of its point is clear)."""
        node = self.handles.get("/landing/scale")
        if node is None:
            return
        if node.visible != (anchor is not None):
            node.visible = anchor is not None
        if anchor is not None and node.anchor != anchor:
            node.anchor = anchor

    def set_label_scale(self, factor: float) -> None:
        node = self.handles.get("/landing/scale")
        if node is not None:
            node.font_screen_scale = 0.8 * factor
            node.anchor = "top-center" if factor > 1.0 else "bottom-left"


#: the ring label hangs this far (CSS px) below the ring's lowest point on screen (or above its highest)
RING_GAP_PX = 8.0


def _beside(point, up: float, pose, image_px) -> np.ndarray:
    """`point` (3,) moved `RING_GAP_PX` up (`up` 1) or down (-1) on screen, along the robot frame's z (mm)."""
    per_mm = float(np.diff(sphere_boxes(np.reshape(point, (1, 3)), [1.0], pose, image_px)[0, [1, 3]])[0]) / 2.0
    return np.asarray(point, float) + np.array([0.0, 0.0, up * RING_GAP_PX / max(per_mm, 1e-9)])
