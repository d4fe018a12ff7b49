"""The 3-D scene: viser nodes for one session, created once and then updated in place.

Frame and units: every node is placed in the ROBOT frame, in millimetres (the scene frame is the robot frame;
viser's +z is up, as in the scenes). Correction arrows and landing offsets are drawn `magnification` times
longer than they are (said on screen); regions of variability and heat-map samples can be drawn `region_zoom`
times larger about their target. Both are display-only transforms.

Node tree (one group per layer of `LAYERS`; a layer's visibility is its group's):

    /mesh/cell, /mesh/ghost            the work-cell mesh, solid / see-through (only the one shown exists)
    /arm/...                           the UR5 reaching the selected target, and where its real tool lands
    /sensor/camera<i>/body, …/frustum  the sensor's cameras and their viewing frusta (robot_nodes)
    /frames/robot, /frames/sensor_true, /frames/sensor_registered   (+ …/label)
    /registration/points               batched spheres (+ /registration/labels/<id>)
    /fiducials/<id>/gizmo              transform controls, translation only (drag a fiducial)
    /fiducials/<id>/gizmo/sphere       the fiducial (click: exclude/include), …/label
    /corrections/fiducials, /corrections/targets   arrows
    /hull/edges                        line segments, screen-space thickness
    /targets/<id>/gizmo                transform controls, translation only (drag a target)
    /targets/<id>/gizmo/sphere         the target (magenta when extrapolated), …/label
    /regions/<id>                      translucent box / icosphere with per-axis scale
    /bounds/<id>                       translucent ellipsoid: the target's 95 % bound (× the arrows' magnification or true size: Display.bound_scale)
    /check_errors/arrows, /tips, /label<k>   a measurement file's check rows' errors (check_error_nodes)
    /landing/anchor, /landing/rigid, /landing/rrbc   the landing bullseye of the selected target (LandingDisplay),
    /landing/lines, /landing/rings, /landing/scale   floating above it: stalk, offsets, scale rings, ring label
    /heatmap/points                    point cloud, float32: the samples, in their region (true size × region zoom)
    /slice/image                       image: the error slice (slice_nodes), the plane coloured by predicted error
    /heatmap/rings                     point cloud, unlit: a flat ring of dots around each target, coloured by
                                       its region's mean value (regions are mm-sized in a metre-sized cell)
    (labels: every …/label node; the "labels" layer toggles them all)

Ids are used in node names with "/" replaced by "_" (`node_key`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

import numpy as np
import viser

from rrbc_core.session.evaluation import Evaluation
from rrbc_core.session.explorer import ExplorerSession

from . import colors
from .bound_nodes import BoundNodes
from .check_error_nodes import CheckErrorNodes
from .frame_nodes import FrameNodes
from .heatmap_nodes import HeatMapNodes
from .landing_nodes import LandingNodes
from .mesh_nodes import GHOST_NODE, SOLID_NODE, add_cell_mesh
from .node_values import (
    LAYERS,
    Display,
    FiducialReadings,
    fiducial_label,
    fiducial_labels,
    gizmo_name,
    gizmo_size,
    identity_wxyzs,
    label_heights,
    label_side,
    node_key,
    target_label,
    target_labels,
    unit_sphere,
)
from .picture import ScenePicture
from .point_labels import PointLabels
from .reading_nodes import ReadingNodes
from .region_nodes import RegionNodes
from .robot_nodes import ArmNodes, ArmPoser, SensorNodes, build_robot_nodes
from .stage import Stage

#: (kind, id, robot-frame position mm, phase, client=...) -> anything
DragCallback = Callable[..., object]
#: (kind, id, client=...) -> anything: a target or fiducial sphere was clicked
ClickCallback = Callable[..., object]

GIZMO_LIMITS = ((-1e7, 1e7),) * 3
#: the targets whose correction the last fiducial drag changed most are drawn this much larger
CHANGED_SCALE = 1.6


class SceneNodes:
    """Creates the nodes of a session (`build`) and refreshes them from an Evaluation (`update`)."""

    def __init__(
        self, server: Stage, on_drag: DragCallback, on_point_click: ClickCallback, arm_meshes: bool = True
    ) -> None:
        self._server = server
        self._arm_meshes = arm_meshes  # False: the arm drawn as links and joints (lighter in software rendering)
        self._scene = server.scene
        self._on_drag = on_drag
        self._on_click = on_point_click
        # what this view last drew, set only through its verbs (`build`, `show`, `set_*`); never read by a controller
        self._selected: tuple[str, str] | None = None  # the point carrying the drag gizmo
        self._changed_labels: frozenset[str] = frozenset()  # labels of the targets the last fiducial drag changed most
        self._see_through = False  # the work cell drawn see-through (ghost) instead of solid
        self._cell_mesh: Any = None  # the work cell's mesh (a trimesh.Trimesh), None without one
        self._arm: ArmNodes | None = None  # scenes with an arm (a DH arm or a URDF)
        self._arm_marks_allowed = True  # the arm's model-error mark, unless a lesson hides it (`set_arm_marks_visible`)
        self._scene_model: Any = None
        self._session: ExplorerSession | None = None  # the session built (build)
        self._dragging: set[tuple[str, str]] = set()  # handles the user is dragging (the app leaves them be)
        self._poser: ArmPoser | None = None  # poses the arm (None without one)
        self._sphere_v, self._sphere_f = unit_sphere()
        self._groups: dict[str, viser.SceneNodeHandle] = {}
        self._gizmos: dict[tuple[str, str], viser.TransformControlsHandle] = {}
        self._spheres: dict[tuple[str, str], viser.IcosphereHandle] = {}
        self._labels = PointLabels(self._scene, self._assign)  # the points' and registration points' labels
        self._sent: dict = {}  # (id(handle), attribute) -> the value last assigned by show()
        self._nodes: dict[str, Any] = {}  # other nodes by name (their handle types vary)
        self._layers: dict[str, bool] = {name: True for name in LAYERS}
        self._display = Display()
        self._kind = "scene"
        self._extent_mm = 1000.0
        self._heat = HeatMapNodes(self._scene)  # the heat map's samples and rings
        self._bullseye = LandingNodes(self._scene)  # the selected target's landing bullseye
        self._readings = ReadingNodes(self._scene)  # a fiducial's two readings (lesson step 5)
        self._check_errors = CheckErrorNodes(self._scene)  # a measurement file's check rows' errors
        self._frames = FrameNodes(self._scene)  # the robot's and the sensor's frames
        self._sensor: SensorNodes | None = None  # the sensor's cameras (scene mode)
        self._regions = RegionNodes(self._scene)  # the targets' regions of variability and coverage halos
        self._bounds = BoundNodes(self._scene)  # the targets' 95 % bound ellipsoids

    # ------------------------------------------------------------------------------------------ inspecting
    def handle(self, name: str) -> Any:
        """The viser handle of node `name` (tests and scripts look at what is drawn), or None."""
        return self._scene.get_handle_by_name(name)

    def gizmo(self, kind: str, pid: str) -> viser.TransformControlsHandle:
        """The drag gizmo of a point (tests and scripts)."""
        return self._gizmos[(kind, pid)]

    def gizmo_items(self) -> dict[tuple[str, str], viser.TransformControlsHandle]:
        """(kind, id) -> drag gizmo of every draggable point (a copy; tests and scripts)."""
        return dict(self._gizmos)

    def arm_nodes(self) -> ArmNodes | None:
        """The arm's nodes (tests and scripts), None without an arm."""
        return self._arm

    def gizmo_scale(self) -> float:
        """The drag gizmos' size (mm): tests and scripts grab a handle's arrow this far out."""
        return gizmo_size(self._display.marker_mm)

    def label_names(self) -> list[str]:
        """The names of every point and frame label, in the order they were made."""
        return self._labels.names()

    def label_anchor(self, name: str) -> np.ndarray:
        """Where label `name` is drawn (robot frame, mm): its position, under its point's handle if it has one."""
        p = self._labels.position(name)
        parent = name.rsplit("/", 1)[0]
        if parent.startswith("/frames/"):  # a frame's label: placed in the frame's own coordinates
            return self._frames.to_robot(parent, p)
        if parent.endswith("/gizmo"):
            kind, pid = parent.strip("/").split("/")[:2]
            tc = self._gizmos.get((kind, pid))
            if tc is not None:
                p = p + np.asarray(tc.position, float)
        return p

    # ------------------------------------------------------------------------------------------ building
    def clear(self) -> None:
        for h in list(self._groups.values()):
            with contextlib.suppress(Exception):  # already gone
                h.remove()
        self._groups.clear()
        self._gizmos.clear()
        self._spheres.clear()
        self._labels.clear()
        self._regions.clear()
        self._bounds.clear()
        self._nodes.clear()
        self._cell_mesh = None
        self._heat.clear()
        self._bullseye.clear()
        self._readings.clear()
        self._check_errors.clear()
        self._sent.clear()  # new handles may reuse ids of removed ones

    def build(self, session: ExplorerSession, picture: ScenePicture, mesh, layers: dict[str, bool]) -> None:
        """(Re)create every node for `session` (after a source is loaded or the cell edited) and show `picture`."""
        self.clear()
        ev = picture.ev
        display = picture.display
        self._kind = session.kind
        self._display = display
        self._selected = picture.selected
        self._layers = {name: bool(layers.get(name, True)) for name in LAYERS}
        self._extent_mm = picture.extent_mm
        sc = self._scene
        for name in LAYERS:
            if name != "labels":
                self._groups[name] = sc.add_frame(f"/{name}", show_axes=False, visible=self._layers[name])
        r = display.marker_mm

        self._cell_mesh = mesh
        if mesh is not None:
            self._nodes.update(add_cell_mesh(sc, mesh, self._see_through))

        # the arm and the sensor, as what they are (robot_nodes) ----------------------------------------------
        scene = getattr(session, "scene", None) if session.kind == "scene" else None
        self._scene_model = scene
        self._session = session
        self._arm, self._poser, self._sensor = build_robot_nodes(
            sc, self._server, session, ev, self._arm_meshes, self._show_arm
        )
        self._show_arm_marks()  # its model-error mark as its layer says

        # frames ---------------------------------------------------------------------------------------
        self._frames.build(
            self._extent_mm, session.sensor_to_robot, ev.registration.mapping, self._add_label, self._labels.move
        )
        self._frames.set_compact(self._labels.compact, self._labels.set_text)

        # registration points --------------------------------------------------------------------------
        n = len(ev.registration_ids)
        if n:
            self._nodes["/registration/points"] = sc.add_batched_meshes_simple(
                "/registration/points",
                self._sphere_v,
                self._sphere_f,
                batched_wxyzs=identity_wxyzs(n),
                batched_positions=ev.registration_positions.astype(np.float32),
                batched_scales=np.full(n, 0.8 * r, np.float32),
                batched_colors=colors.REGISTRATION,
                cast_shadow=False,
                receive_shadow=False,
            )
            for pid, p in zip(ev.registration_ids, ev.registration_positions):
                self._add_label(f"/registration/labels/{node_key(pid)}", str(pid), np.asarray(p) + (0.0, 0.0, 1.6 * r))

        # fiducials and targets (draggable) -------------------------------------------------------------
        for i, pid in enumerate(ev.fiducial_ids):
            self._point("fiducials", pid, ev.fiducial_positions[i], colors.FIDUCIAL, fiducial_label(pid, ev, i))
        for i, pid in enumerate(ev.targets.ids):
            self._point("targets", pid, ev.targets.positions[i], colors.TARGET, target_label(pid, ev, i))

        # corrections, hull -----------------------------------------------------------------------------
        z = np.zeros((1, 2, 3), np.float32)
        self._nodes["/corrections/fiducials"] = sc.add_arrows(
            "/corrections/fiducials", z, np.array(colors.CORRECTION_FIDUCIAL, np.uint8), **self._arrow_sizes()
        )
        self._nodes["/corrections/targets"] = sc.add_arrows(
            "/corrections/targets", z, np.array(colors.CORRECTION_TARGET, np.uint8), **self._arrow_sizes()
        )
        self._nodes["/hull/edges"] = sc.add_line_segments(
            "/hull/edges", z, np.array(colors.HULL, np.uint8), thickness=2.0, thickness_units="screen"
        )

        # regions of variability ------------------------------------------------------------------------
        self._regions.build(session.regions, ev.targets.ids, ev.targets.positions, display.region_zoom)
        self._bounds.build(ev.targets.ids)

        # landing bullseye of one target (filled by update) --------------------------------------------------
        if len(ev.targets.ids):
            self._nodes.update(self._bullseye.build(r))

        # heat map (filled by update_heatmap) ------------------------------------------------------------
        self._nodes.update(self._heat.build(with_rings=len(ev.targets.ids) > 0))

        # coverage halos: one around each target with a region, following its gizmo; hidden until painted
        if session.kind == "scene":
            ids = session.layout["targets"].ids
            with_region = [pid for pid in ids if pid in session.regions and ("targets", pid) in self._gizmos]
            self._regions.build_halos(with_region, self._display.marker_mm)
        self.set_selected(self._selected)
        self.set_layer("labels", self._layers["labels"])
        self.show(picture)

    def update_heatmap(self, hm, ev: Evaluation) -> tuple[str, float, float] | None:
        """Show a `HeatMap` (`heatmap_nodes.HeatMapNodes.show`); returns (title, lo, hi) for the legend, or None."""
        return self._heat.show(hm, ev, self._display)

    def paint_regions(self, colours: dict | None) -> None:
        """Colour each target's region of variability and its halo by `colours` (target id -> RGB; the Plan tab's
        coverage scale), or give the regions their own colour back and hide the halos (None)."""
        self._regions.paint(colours, self._display.marker_mm, self._assign)

    def add_new_fiducials(self, ev: Evaluation) -> list[str]:
        """Create the nodes of fiducials `ev` has and the scene does not yet (accepted suggestions); returns
        their ids. Their drag handles follow the current choice (View → Drag handles on)."""
        texts = fiducial_labels(ev)
        new = []
        for i, pid in enumerate(ev.fiducial_ids):
            if ("fiducials", pid) not in self._gizmos:
                self._point("fiducials", pid, ev.fiducial_positions[i], colors.FIDUCIAL, texts[i])
                new.append(pid)
        if new:
            self.set_selected(self._selected)
        return new

    def _add_label(self, name: str, text: str, position) -> None:
        self._labels.add(name, text, position, self._layers.get("labels", True))

    def _point(self, kind: str, pid: str, position, color, label: str) -> None:
        r = self._display.marker_mm
        name = gizmo_name(kind, pid)
        tc = self._scene.add_transform_controls(
            name,
            scale=self.gizmo_scale(),
            line_width=3.0,
            disable_rotations=True,
            depth_test=False,
            translation_limits=GIZMO_LIMITS,
            position=np.asarray(position, float),
        )

        async def on_update(event: viser.TransformControlsEvent, kind=kind, pid=pid) -> None:
            # async: runs on viser's event loop, in order (start, updates, end); never awaits. While the user drags
            # a handle the app does not move it (`dragging`): the drag's end must read the user's last position,
            # not one the app set from an older update it handled meanwhile
            if event.phase != "end":
                self._dragging.add((kind, pid))
            self._on_drag(kind, pid, np.asarray(event.target.position, float), event.phase, client=event.client)

        tc.on_update(on_update)
        sphere = self._scene.add_icosphere(
            f"{name}/sphere",
            radius=r if kind == "fiducials" else 0.8 * r,
            color=color,
            subdivisions=2,
            cast_shadow=False,
            receive_shadow=False,
        )

        def on_click(event: viser.SceneNodePointerEvent, kind=kind, pid=pid) -> None:
            self._on_click(kind, pid, client=event.client)

        sphere.on_click(on_click)
        self._gizmos[(kind, pid)] = tc
        self._spheres[(kind, pid)] = sphere
        self._add_label(f"{name}/label", label, (0.0, 0.0, 1.6 * r))

    def _arrow_sizes(self) -> dict:
        r = self._display.marker_mm
        return {"shaft_radius": 0.22 * r, "head_radius": 0.55 * r, "head_length": 1.4 * r}

    # ------------------------------------------------------------------------------------------ updating
    def show(self, picture: ScenePicture) -> None:
        """Draw `picture` (`picture.scene_picture`; call inside `server.atomic()`). Only changed properties are sent
        (viser skips unchanged values; a gizmo being dragged already sits where the user put it, so it is not sent
        back)."""
        ev = picture.ev
        if picture.selected != self._selected:
            self.set_selected(picture.selected)
        self.set_display(picture.display)
        mag = self._display.magnification
        self._frames.show(
            picture.registered_wxyz, picture.registered_position, picture.frame_mag, self._labels.set_text
        )
        reg = self._nodes.get("/registration/points")
        if reg is not None:  # registration points only move when moved from Python (no gizmo)
            reg.batched_positions = ev.registration_positions.astype(np.float32)
            for pid, p in zip(ev.registration_ids, ev.registration_positions):
                self._labels.move(
                    f"/registration/labels/{node_key(pid)}",
                    np.asarray(p, float) + (0.0, 0.0, 1.6 * self._display.marker_mm),
                )

        # fiducials (only what changed is assigned: viser's property setters cost ~40 µs each)
        texts = fiducial_labels(ev)
        for i, pid in enumerate(ev.fiducial_ids):
            inc = bool(ev.included[i])
            self._assign(
                self._spheres[("fiducials", pid)], "color", colors.FIDUCIAL if inc else colors.FIDUCIAL_EXCLUDED
            )
            if ("fiducials", pid) not in self._dragging:
                self._assign(self._gizmos[("fiducials", pid)], "position", tuple(ev.fiducial_positions[i]))
            self._labels.set_text(f"{gizmo_name('fiducials', pid)}/label", texts[i])
        inc_idx = np.flatnonzero(ev.included)
        arrows = self._nodes["/corrections/fiducials"]
        if len(inc_idx):
            start = ev.fiducial_positions[inc_idx]
            arrows.points = np.stack([start, start + mag * ev.corrections_robot[inc_idx]], axis=1).astype(np.float32)
        arrows.visible = bool(len(inc_idx))

        # hull
        hull = self._nodes["/hull/edges"]
        if len(ev.hull_edges):
            hull.points = np.asarray(ev.hull_edges, np.float32)
        hull.visible = bool(len(ev.hull_edges))

        # targets
        t = ev.targets
        compact = self._labels.compact
        texts = target_labels(ev, compact=compact)
        if compact:  # presentation mode: the selected target's numbers, the others (a lesson's) by name only; and
            # all by name while a lesson step labels the targets (the selected one's long text hid its neighbours':
            # its numbers are on its card and its bullseye)
            numbers = () if self._labels.lesson_shows("targets") else (self._selected,)
            texts = [
                x if ("targets", pid) in numbers else pid + (" ⚠" if t.extrapolated[i] else "")
                for i, (pid, x) in enumerate(zip(t.ids, texts))
            ]
        changed = dict(picture.changed)  # a fiducial's drag marks the targets it changed most: larger, and labelled
        # with the change (whatever the labels layer: issue 39, the size alone was easy to miss)
        texts = [x + (f" · Δê {changed[pid]:.3f} mm" if pid in changed else "") for pid, x in zip(t.ids, texts)]
        marked = frozenset(f"{gizmo_name('targets', pid)}/label" for pid in changed)
        if marked != self._changed_labels:
            self._changed_labels = marked
            self._show_labels()
        for i, pid in enumerate(t.ids):
            self._assign(self._spheres[("targets", pid)], "scale", CHANGED_SCALE if pid in changed else 1.0)
            self._assign(
                self._spheres[("targets", pid)],
                "color",
                (colors.CHECK_EXTRAPOLATED if t.extrapolated[i] else colors.CHECK)
                if pid in ev.check_ids  # a check stays a check's colour, outside the hull too
                else colors.TARGET_EXTRAPOLATED
                if t.extrapolated[i]
                else colors.TARGET,
            )
            if ("targets", pid) not in self._dragging:
                self._assign(self._gizmos[("targets", pid)], "position", tuple(t.positions[i]))
            self._labels.set_text(f"{gizmo_name('targets', pid)}/label", texts[i])
            self._regions.move(pid, t.positions[i], self._assign)
        self._bounds.show(t.ids, t.positions, picture.bound_rotations, picture.bound_axes, self._assign)
        self._check_errors.show(picture.check_errors, self._display.marker_mm)
        tarrows = self._nodes["/corrections/targets"]
        if len(t.ids):
            tarrows.points = np.stack([t.positions, t.positions + mag * t.correction_robot], axis=1).astype(np.float32)
        tarrows.visible = bool(len(t.ids)) and picture.target_arrows

        # landing: the bullseye of the selected target (the first target while a fiducial or nothing is selected)
        land = picture.landing
        if land is not None:
            self._bullseye.show(land, self._assign)
            self._update_arm(land.position, mag, picture.tool, picture.bias_scale, picture.drag_active)

    def _update_arm(self, position, magnification: float, tool, bias: float, moving: bool) -> None:
        """Pose the arm to reach `position` (the bullseye's target) with the tool down or leaned (tool: (tilt,
        azimuth) degrees), or, for measured data, at the selected point's joint values (the first target's before)."""
        if self._poser is None:
            return
        if self._kind != "measurements":
            self._poser.reach(self._scene_model, position, magnification, tool, bias, moving)
            return
        assert self._session is not None  # built
        t = self._session.last.targets if self._session.last is not None else None
        sel = self._selected or (("targets", t.ids[0]) if t is not None and len(t.ids) else None)
        if sel is not None:
            self._poser.at_joints(self._session, sel, magnification)

    def _show_arm(self, on: bool) -> None:
        self._groups["arm"].visible = on and self._layers.get("arm", True)

    def _assign(self, handle, attr: str, value) -> None:
        """Set handle.attr = value unless it is the value this object last set there (tuples/str compare
        exactly); a gizmo moved by the user is re-sent once, which viser itself skips when unchanged."""
        key = (id(handle), attr)
        if self._sent.get(key) == value:
            return
        setattr(handle, attr, np.asarray(value, float) if isinstance(value, tuple) and attr == "position" else value)
        self._sent[key] = value

    def snap(self, kind: str, pid: str, position) -> None:
        """Put a gizmo back (a refused move); nothing when the point has no gizmo."""
        tc = self._gizmos.get((kind, pid))
        if tc is None:
            return
        tc.position = np.asarray(position, float)
        self._sent[(id(tc), "position")] = tuple(np.asarray(position, float))

    def resnap(self, kind: str, pid: str) -> None:
        """Send a gizmo's position again even though the server's copy has not changed. viser skips a value
        np.allclose to the one it holds, so step off by more than its tolerance and back; the two messages share
        a redundancy key, so a tab receives only the last."""
        tc = self._gizmos[(kind, pid)]
        p = np.array(tc.position, float)
        tc.position = p + np.array([1e-4 * (1.0 + float(np.abs(p).max())), 0.0, 0.0])
        tc.position = p

    def set_label_scale(self, factor: float) -> None:
        """Labels' screen size × factor (presentation mode)."""
        self._labels.set_scale(factor)
        self._show_labels()
        scale, compact = self._labels.scale, self._labels.compact
        self._frames.set_compact(compact, self._labels.set_text)
        if self._arm is not None:
            self._arm.marks["label"].font_screen_scale = 0.75 * scale
            self._arm.marks["label"].anchor = "top-center" if compact else "bottom-left"
            self._arm.compact = compact
            self._arm.refresh_label()
        self._bullseye.set_label_scale(scale)

    def set_see_through(self, on: bool) -> None:
        """Draw the work cell solid or see-through (what lies under its surfaces shows)."""
        self._see_through = bool(on)
        shown, gone = (GHOST_NODE, SOLID_NODE) if self._see_through else (SOLID_NODE, GHOST_NODE)
        if self._cell_mesh is None or shown in self._nodes:
            return
        old = self._nodes.pop(gone, None)
        if old is not None:
            with contextlib.suppress(Exception):  # already gone
                old.remove()
        self._nodes.update(add_cell_mesh(self._scene, self._cell_mesh, self._see_through))

    def set_layer(self, layer: str, visible: bool) -> None:
        self._layers[layer] = bool(visible)
        if layer == "labels":
            self._show_labels()
        elif layer == "arm_error":
            self._show_arm_marks()
        elif layer in self._groups:
            self._groups[layer].visible = bool(visible)

    def set_selected(self, selected: tuple[str, str] | None) -> None:
        """Select a point (kind, id) or none: only the selected point carries a drag gizmo (the others keep their
        sphere, clickable), and its label shows even when the labels layer is off."""
        if selected is not None and selected not in self._gizmos:
            selected = None
        self._selected = selected
        for key, tc in self._gizmos.items():
            on = key == selected
            self._assign(tc, "disable_axes", not on)
            self._assign(tc, "disable_sliders", not on)
        r = self._display.marker_mm
        self._labels.raise_label(self._selected_label(), *label_heights(r), label_side(r))
        self._show_labels()

    def applicable_layers(self) -> tuple[str, ...]:
        """The layers this build has something in (the View tab lists only these)."""
        missing = set()
        if self._cell_mesh is None:
            missing.add("mesh")
        if self._arm is None:
            missing.add("arm")
        if self._arm is None or not self._arm.marks:
            missing.add("arm_error")
        if self._scene.get_handle_by_name("/sensor/camera0/body") is None:
            missing.add("sensor")
        if not self._regions.any():
            missing.add("regions")
        if self._session is not None and not len(self._session.layout["targets"].ids):
            missing.add("bounds")
        return tuple(n for n in LAYERS if n not in missing)

    def set_lesson_labels(self, kinds: tuple[str, ...], named: tuple[tuple[str, str], ...] = ()) -> None:
        """Show these kinds of point's labels (teaching.Step.labels), those `named` ((kind, id)) kept first."""
        self._labels.set_lesson(kinds, tuple(gizmo_name(k, pid) + "/label" for k, pid in named))
        self._show_labels()

    def declutter_lesson_labels(self, pose, image_px, panel_px: float) -> frozenset[str]:
        """Hide the lesson step's labels that would overlap another or run under the panel when seen by `pose` (a
        `CameraPose`) in an image of `image_px` (width, height) CSS px (`lesson_labels.declutter`: the selected
        point's label first, then in the file's order). Returns the names hidden."""
        mine = self._selected_label()
        hidden = self._labels.declutter(mine, self.label_anchor, pose, image_px, panel_px)
        self._place_ring_label(mine, pose, image_px, panel_px)
        self._readings.keep_inside(pose, image_px, panel_px)
        self._show_labels()
        return hidden

    def _place_ring_label(self, mine: str | None, pose, image_px, panel_px: float) -> None:
        """The bullseye's ring label clear of the selected point's label too (`LandingNodes.place_label`)."""
        avoid = np.zeros((0, 4)) if mine is None else self._labels.box(mine, self.label_anchor(mine), pose, image_px)
        self._bullseye.place_label(avoid, pose, image_px, panel_px, 0.8 * self._labels.scale)

    def drag_ended(self, kind: str, pid: str) -> None:
        """The user let go of a point's handle: the app places it again from now on."""
        self._dragging.discard((kind, pid))

    def show_readings(self, readings: FiducialReadings | None) -> None:
        """A fiducial's two readings beside it (`reading_nodes`), or none (None)."""
        self._readings.show(readings, self._display.marker_mm, self._labels.scale)

    def show_sight_lines(self, points) -> None:
        """The sensor's lines of sight to `points` (N, 3) robot frame mm, or none (None); scene mode only."""
        if self._sensor is not None:
            self._sensor.show_sight_lines(points)

    def set_frames_zoom(self, factor: float) -> None:
        """The sensor's frames' axes drawn `factor` times their length (`AppState.frames_zoom`)."""
        self._frames.zoom(factor)

    def set_arm_marks_visible(self, on: bool) -> None:
        """Let the arm's model-error mark show (its layer permitting) or hide it (a lesson hides it)."""
        self._arm_marks_allowed = bool(on)
        self._show_arm_marks()

    def _show_arm_marks(self) -> None:
        if self._arm is not None:
            self._arm.set_marks_visible(self._arm_marks_allowed and bool(self._layers.get("arm_error", False)))

    def set_display(self, display: Display) -> None:
        """New display options; markers, gizmos, arrows and regions resized when their sizes changed."""
        old, self._display = self._display, display
        if (old.marker_mm, old.region_zoom) != (display.marker_mm, display.region_zoom):
            self._apply_sizes()

    def _selected_label(self) -> str | None:
        return None if self._selected is None else f"{gizmo_name(*self._selected)}/label"

    def _show_labels(self) -> None:
        # presentation mode: only the selected point's label and a lesson step's (large labels would overlap)
        self._labels.show(bool(self._layers.get("labels")), self._selected_label(), self._changed_labels)

    def _apply_sizes(self) -> None:
        """Marker size and region zoom changed: resize spheres, gizmos, arrows, regions."""
        r = self._display.marker_mm
        for (kind, _pid), s in self._spheres.items():
            s.radius = r if kind == "fiducials" else 0.8 * r
        for tc in self._gizmos.values():
            tc.scale = self.gizmo_scale()
        self._labels.lift_point_labels(*label_heights(self._display.marker_mm))
        for key in ("/corrections/fiducials", "/corrections/targets"):
            for k, v in self._arrow_sizes().items():
                setattr(self._nodes[key], k, v)
        reg = self._nodes.get("/registration/points")
        if reg is not None:
            reg.batched_scales = np.full(len(reg.batched_positions), 0.8 * r, np.float32)
        self._bullseye.resize(r)
        self._regions.resize(self._display.region_zoom)
        self._heat.resize(self._display)
