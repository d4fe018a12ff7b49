"""The 3-D scene: viser nodes for one session, created once and then updated in place.

Frame and units: every node is placed in the ROBOT frame, in millimetres (the scene frame is the robot frame;
viser's +z is up, as in the scenes). Correction arrows and landing offsets are drawn `magnification` times
longer than they are (said on screen); regions of variability and heat-map samples can be drawn `region_zoom`
times larger about their target. Both are display-only transforms.

Node tree (one group per layer of `LAYERS`; a layer's visibility is its group's):

    /mesh/cell, /mesh/ghost            the work-cell mesh, solid / see-through (one of them shown)
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

import time
from collections.abc import Callable
from typing import Any, Literal

import numpy as np
import viser

from rrbc_core.errors import InputError
from rrbc_core.session.arm import arm_description, arm_pose, measured_arm_pose
from rrbc_core.session.evaluation import Evaluation
from rrbc_core.session.explorer import ExplorerSession
from rrbc_core.session.tools import tool_rotation

from . import colors
from .heatmap_nodes import HeatMapNodes
from .landing_nodes import LandingNodes
from .node_values import (
    LAYERS,
    Display,
    LandingDisplay,
    fiducial_label,
    fiducial_labels,
    frame_magnification,
    gizmo_name,
    identity_wxyzs,
    landing_display,
    node_key,
    registered_frame_pose,
    target_label,
    target_labels,
    unit_sphere,
    wxyz,
)
from .robot_nodes import ArmNodes, SensorNodes

#: The scene's layers, each a group node whose visibility the View tab and the lesson steps switch.

#: While a drag is under way the arm is posed at most this often (s); always at the drag's end.
ARM_DRAG_INTERVAL_S = 0.25
#: (kind, id, robot-frame position mm, phase, client=...) -> anything
DragCallback = Callable[..., object]
#: (kind, id, client=...) -> anything: a target or fiducial sphere was clicked
ClickCallback = Callable[..., object]

GIZMO_LIMITS = ((-1e7, 1e7),) * 3
HALO_MARKERS = 1.8  # coverage halo radius, in marker radii (the target sphere is 0.8)
HALO_OPACITY = 0.45


class SceneNodes:
    """Creates the nodes of a session (`build`) and refreshes them from an Evaluation (`update`)."""

    def __init__(self, server: viser.ViserServer, on_drag: DragCallback, on_point_click: ClickCallback):
        self.server = server
        self.scene = server.scene
        self._on_drag = on_drag
        self._on_click = on_point_click
        self.selected: tuple[str, str] | None = None  # (kind, id) of the point carrying the drag gizmo
        self.landing_lift = 0.0  # mm: the landing display floats this far above the targets
        self.see_through = False  # the work cell drawn see-through (ghost) instead of solid
        self.label_scale = 1.0  # labels' screen size factor (presentation mode)
        self.true_pose = None  # the sensor's true pose (scene mode), for the magnified registered frame
        self.frame_mag = 1.0  # the registered frame's error is drawn this many times larger
        self.arm: ArmNodes | None = None  # scenes with an arm (a DH arm or a URDF)
        self.scene_model = None
        self.session: Any = None  # the session built (build)
        self.lesson_labels: tuple[str, ...] = ()  # kinds of point whose labels a lesson step shows
        self.lesson_hidden: frozenset[str] = frozenset()  # ... less those that would overlap (lesson_labels.declutter)
        self.landing_hold = False  # a drag is under way: the bullseye keeps its ring (its drawing scale)
        self.dragging: set[tuple[str, str]] = set()  # handles the user is dragging (the app leaves them be)
        self._arm_key: tuple | None = None
        self._arm_time = -1e18  # when the arm was last posed (time.monotonic)
        self.bias_scale = 1.0  # the session's bias size (the real arm's landing scales with it)
        self.vec_landings: dict | None = None  # target id -> VEC's landing (3,), robot frame mm (Arm tab on)
        self.target_tools: dict = {}  # target id -> (tilt, azimuth) degrees of its leaned tool (the arm is drawn so)
        self._sphere_v, self._sphere_f = unit_sphere()
        self.groups: dict[str, viser.SceneNodeHandle] = {}
        self.gizmos: dict[tuple[str, str], viser.TransformControlsHandle] = {}
        self.spheres: dict[tuple[str, str], viser.IcosphereHandle] = {}
        self.labels: dict[str, viser.LabelHandle] = {}  # node name of the label -> handle
        self._sent: dict = {}  # (id(handle), attribute) -> the value last assigned by update()
        self.regions: dict[str, Any] = {}  # box or icosphere handles
        self.halos: dict[str, viser.SceneNodeHandle] = {}  # target id -> coverage halo (paint_regions)
        self.region_kind: dict[str, tuple[str, np.ndarray]] = {}  # id -> (kind, size)
        self.nodes: dict[str, Any] = {}  # other nodes by name (their handle types vary)
        self.layers: dict[str, bool] = {name: True for name in LAYERS}
        self.display = Display()
        self.kind = "scene"
        self.extent_mm = 1000.0
        self.target_arrows = True  # the lesson hides the targets' arrows while it shows the fiducials' only
        self.heat = HeatMapNodes(self.scene)  # the heat map's samples and rings
        self.bullseye = LandingNodes(self.scene)  # the selected target's landing bullseye

    # ------------------------------------------------------------------------------------------ building
    def clear(self) -> None:
        for h in list(self.groups.values()):
            try:
                h.remove()
            except Exception:  # noqa: BLE001 - already gone
                pass
        self.groups.clear()
        self.gizmos.clear()
        self.spheres.clear()
        self.labels.clear()
        self.regions.clear()
        self.region_kind.clear()
        self.nodes.clear()
        self.halos.clear()
        self.heat.clear()
        self.bullseye.clear()
        self._sent.clear()  # new handles may reuse ids of removed ones

    def build(self, session: ExplorerSession, ev: Evaluation, mesh, display: Display, layers: dict[str, bool]) -> None:
        """(Re)create every node for `session` (after a source is loaded)."""
        self.clear()
        self.kind = session.kind
        self.display = display
        self.layers = {name: bool(layers.get(name, True)) for name in LAYERS}
        pts = np.vstack(
            [
                ev.registration_positions.reshape(-1, 3),
                ev.fiducial_positions.reshape(-1, 3),
                ev.targets.positions.reshape(-1, 3),
            ]
        )
        self.extent_mm = float(np.linalg.norm(pts.max(0) - pts.min(0))) if len(pts) else 1000.0
        self.extent_mm = max(self.extent_mm, 1.0)
        sc = self.scene
        for name in LAYERS:
            if name != "labels":
                self.groups[name] = sc.add_frame(f"/{name}", show_axes=False, visible=self.layers[name])
        r = display.marker_mm

        if mesh is not None:
            self.nodes["/mesh/cell"] = sc.add_mesh_trimesh(
                "/mesh/cell", mesh, cast_shadow=False, receive_shadow=False, visible=not self.see_through
            )
            self.nodes["/mesh/ghost"] = sc.add_mesh_simple(  # the see-through cell: shows what lies under surfaces
                "/mesh/ghost",
                np.asarray(mesh.vertices, np.float32),
                np.asarray(mesh.faces, np.uint32),
                color=(170, 170, 175),
                opacity=0.18,
                side="double",
                cast_shadow=False,
                receive_shadow=False,
                visible=self.see_through,
            )

        # the arm and the sensor, as what they are (robot_nodes) ----------------------------------------------
        scene = getattr(session, "scene", None) if session.kind == "scene" else None
        self.arm = None
        self.scene_model = scene
        self._arm_key = None
        has_arm = scene is not None and (scene.robot_model in ("ur5", "ur10") or scene.robot_urdf is not None)
        self.session = session
        if has_arm and len(ev.targets.ids):
            self.arm = ArmNodes(sc, arm_description(scene), self.server)
            self.arm.build()
        elif session.kind == "measurements" and session.arm is not None:  # rrbc view data.csv --urdf
            self.arm = ArmNodes(sc, session.arm, self.server)
            self.arm.build()
        if scene is not None and scene.sensor_kind != "ground_truth":
            T = scene.sensor_to_robot
            look = scene.sensor_look_at if scene.sensor_look_at is not None else ev.targets.positions.mean(0)
            SensorNodes(sc).build(scene.sensor_kind, T.rotation, T.translation, look)

        # frames ---------------------------------------------------------------------------------------
        axes = 0.12 * self.extent_mm
        self.nodes["/frames/robot"] = sc.add_frame("/frames/robot", axes_length=axes, axes_radius=axes * 0.03)
        self._label("/frames/robot/label", "robot base", (0.0, 0.0, axes * 0.2))
        self.true_pose = session.sensor_to_robot
        if session.sensor_to_robot is not None:
            T = session.sensor_to_robot
            self.nodes["/frames/sensor_true"] = sc.add_frame(
                "/frames/sensor_true",
                axes_length=axes,
                axes_radius=axes * 0.03,
                wxyz=wxyz(T.rotation),
                position=np.asarray(T.translation, float),
            )
            self._label("/frames/sensor_true/label", "sensor (true pose)", (0.0, 0.0, axes * 0.2))
        m = ev.registration.mapping
        self.nodes["/frames/sensor_registered"] = sc.add_frame(
            "/frames/sensor_registered",
            axes_length=axes * 1.3,
            axes_radius=axes * 0.012,
            origin_color=(255, 255, 255),
            wxyz=wxyz(m.rotation),
            position=np.asarray(m.translation, float),
        )
        self._label("/frames/sensor_registered/label", "sensor (registered)", (0.0, 0.0, -axes * 0.2))
        if session.sensor_to_robot is not None:  # the registered frame's error is drawn magnified: say so, always
            self.nodes["/frames/sensor_registered/note"] = sc.add_label(
                "/frames/sensor_registered/note",
                "",
                position=(0.0, 0.0, -axes * 0.45),
                font_size_mode="screen",
                font_screen_scale=0.75,
                anchor="top-left",
            )

        # registration points --------------------------------------------------------------------------
        n = len(ev.registration_ids)
        if n:
            self.nodes["/registration/points"] = sc.add_batched_meshes_simple(
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
                self._label(f"/registration/labels/{node_key(pid)}", str(pid), np.asarray(p) + (0.0, 0.0, 1.6 * r))

        # fiducials and targets (draggable) -------------------------------------------------------------
        for i, pid in enumerate(ev.fiducial_ids):
            self._point("fiducials", pid, ev.fiducial_positions[i], colors.FIDUCIAL, fiducial_label(pid, ev, i))
        for i, pid in enumerate(ev.targets.ids):
            self._point("targets", pid, ev.targets.positions[i], colors.TARGET, target_label(pid, ev, i))

        # corrections, hull -----------------------------------------------------------------------------
        z = np.zeros((1, 2, 3), np.float32)
        self.nodes["/corrections/fiducials"] = sc.add_arrows(
            "/corrections/fiducials", z, np.array(colors.CORRECTION_FIDUCIAL, np.uint8), **self._arrow_sizes()
        )
        self.nodes["/corrections/targets"] = sc.add_arrows(
            "/corrections/targets", z, np.array(colors.CORRECTION_TARGET, np.uint8), **self._arrow_sizes()
        )
        self.nodes["/hull/edges"] = sc.add_line_segments(
            "/hull/edges", z, np.array(colors.HULL, np.uint8), thickness=2.0, thickness_units="screen"
        )

        # regions of variability ------------------------------------------------------------------------
        for i, pid in enumerate(ev.targets.ids):
            region = session.regions.get(pid)
            if region is None:
                continue
            h: Any
            name = f"/regions/{node_key(pid)}"
            size = np.asarray(region.size, float)
            zoom = display.region_zoom
            if region.kind == "box":
                h = sc.add_box(
                    name,
                    color=colors.REGION,
                    dimensions=tuple(size),
                    opacity=0.35,
                    scale=zoom,
                    position=ev.targets.positions[i],
                    cast_shadow=False,
                    receive_shadow=False,
                )
            else:
                h = sc.add_icosphere(
                    name,
                    radius=1.0,
                    color=colors.REGION,
                    subdivisions=3,
                    opacity=0.35,
                    scale=tuple(size * zoom),
                    position=ev.targets.positions[i],
                    cast_shadow=False,
                    receive_shadow=False,
                )
            self.regions[pid] = h
            self.region_kind[pid] = (region.kind, size)

        # landing bullseye of one target (filled by update) --------------------------------------------------
        self.landing: LandingDisplay | None = None
        if len(ev.targets.ids):
            self.nodes.update(self.bullseye.build(r))

        # heat map (filled by update_heatmap) ------------------------------------------------------------
        self.nodes.update(self.heat.build(with_rings=len(ev.targets.ids) > 0))

        # coverage halos: one around each target with a region, following its gizmo; hidden until painted
        self.halos = {}
        if session.kind == "scene":
            for pid in session.layout["targets"].ids:
                if pid in session.regions and ("targets", pid) in self.gizmos:
                    self.halos[pid] = self.scene.add_icosphere(
                        f"{gizmo_name('targets', pid)}/coverage",
                        radius=HALO_MARKERS * self.display.marker_mm,
                        color=colors.REGION,
                        subdivisions=2,
                        opacity=HALO_OPACITY,
                        visible=False,
                        cast_shadow=False,
                        receive_shadow=False,
                    )
        self.set_selected(self.selected)
        self.set_layer("labels", self.layers["labels"])
        self.update(ev)

    def update_heatmap(self, hm, ev: Evaluation) -> tuple[str, float, float] | None:
        """Show a `HeatMap` (`heatmap_nodes.HeatMapNodes.show`); returns (title, lo, hi) for the legend, or None."""
        return self.heat.show(hm, ev, self.display)

    def paint_regions(self, colours: dict | None) -> None:
        """Colour each target's region of variability and its halo by `colours` (target id -> RGB; the Plan tab's
        coverage scale), or give the regions their own colour back and hide the halos (None)."""
        colours = colours or {}
        for pid, region in self.regions.items():
            self._assign(region, "color", tuple(colours.get(pid, colors.REGION)))
        for pid, halo in self.halos.items():
            self._assign(halo, "visible", pid in colours)
            if pid in colours:
                self._assign(halo, "color", tuple(colours[pid]))
            self._assign(halo, "radius", HALO_MARKERS * self.display.marker_mm)

    def add_new_fiducials(self, ev: Evaluation) -> list[str]:
        """Create the nodes of fiducials `ev` has and the scene does not yet (accepted suggestions); returns
        their ids. Their drag handles follow the current choice (View → Drag handles on)."""
        texts = fiducial_labels(ev)
        new = []
        for i, pid in enumerate(ev.fiducial_ids):
            if ("fiducials", pid) not in self.gizmos:
                self._point("fiducials", pid, ev.fiducial_positions[i], colors.FIDUCIAL, texts[i])
                new.append(pid)
        if new:
            self.set_selected(self.selected)
        return new

    def _label(self, name: str, text: str, position) -> None:
        self.labels[name] = self.scene.add_label(
            name,
            text,
            position=np.asarray(position, float),
            font_size_mode="screen",
            font_screen_scale=0.75 * self.label_scale,
            anchor="bottom-left",
            visible=self.layers.get("labels", True),
        )

    def _point(self, kind: str, pid: str, position, color, label: str) -> None:
        r = self.display.marker_mm
        name = gizmo_name(kind, pid)
        tc = self.scene.add_transform_controls(
            name,
            scale=self._gizmo_scale(),
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
                self.dragging.add((kind, pid))
            self._on_drag(kind, pid, np.asarray(event.target.position, float), event.phase, client=event.client)

        tc.on_update(on_update)
        sphere = self.scene.add_icosphere(
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
        self.gizmos[(kind, pid)] = tc
        self.spheres[(kind, pid)] = sphere
        self._label(f"{name}/label", label, (0.0, 0.0, 1.6 * r))

    def _gizmo_scale(self) -> float:
        return 5.0 * self.display.marker_mm

    def _arrow_sizes(self) -> dict:
        r = self.display.marker_mm
        return {"shaft_radius": 0.22 * r, "head_radius": 0.55 * r, "head_length": 1.4 * r}

    # ------------------------------------------------------------------------------------------ updating
    def update(self, ev: Evaluation) -> None:
        """Refresh every node that depends on the Evaluation (call inside `server.atomic()`). Only changed
        properties are sent (viser skips unchanged values; a gizmo being dragged already sits where the user
        put it, so it is not sent back)."""
        mag = self.display.magnification
        m = ev.registration.mapping
        reg_frame = self.nodes["/frames/sensor_registered"]
        self.frame_mag = frame_magnification(self.true_pose, m, 0.12 * self.extent_mm, mag)
        wxyz, position = registered_frame_pose(self.true_pose, m, self.frame_mag)
        reg_frame.wxyz = wxyz
        reg_frame.position = position
        note = self.nodes.get("/frames/sensor_registered/note")
        if note is not None:
            self._assign(note, "text", self._frame_note())
        reg = self.nodes.get("/registration/points")
        if reg is not None:  # registration points only move when moved from Python (no gizmo)
            reg.batched_positions = ev.registration_positions.astype(np.float32)
            for pid, p in zip(ev.registration_ids, ev.registration_positions):
                label = self.labels[f"/registration/labels/{node_key(pid)}"]
                label.position = np.asarray(p, float) + (0.0, 0.0, 1.6 * self.display.marker_mm)

        # fiducials (only what changed is assigned: viser's property setters cost ~40 µs each)
        texts = fiducial_labels(ev)
        for i, pid in enumerate(ev.fiducial_ids):
            inc = bool(ev.included[i])
            self._assign(
                self.spheres[("fiducials", pid)], "color", colors.FIDUCIAL if inc else colors.FIDUCIAL_EXCLUDED
            )
            if ("fiducials", pid) not in self.dragging:
                self._assign(self.gizmos[("fiducials", pid)], "position", tuple(ev.fiducial_positions[i]))
            self._assign(self.labels[f"{gizmo_name('fiducials', pid)}/label"], "text", texts[i])
        inc_idx = np.flatnonzero(ev.included)
        arrows = self.nodes["/corrections/fiducials"]
        if len(inc_idx):
            start = ev.fiducial_positions[inc_idx]
            arrows.points = np.stack([start, start + mag * ev.corrections_robot[inc_idx]], axis=1).astype(np.float32)
        arrows.visible = bool(len(inc_idx))

        # hull
        hull = self.nodes["/hull/edges"]
        if len(ev.hull_edges):
            hull.points = np.asarray(ev.hull_edges, np.float32)
        hull.visible = bool(len(ev.hull_edges))

        # targets
        t = ev.targets
        compact = self.label_scale > 1.0
        texts = target_labels(ev, compact=compact)
        if compact:  # presentation mode: the selected target's numbers, the others (a lesson's) by name only
            texts = [
                x if self.selected == ("targets", pid) else pid + (" ⚠" if t.extrapolated[i] else "")
                for i, (pid, x) in enumerate(zip(t.ids, texts))
            ]
        for i, pid in enumerate(t.ids):
            self._assign(
                self.spheres[("targets", pid)],
                "color",
                colors.TARGET_EXTRAPOLATED
                if t.extrapolated[i]
                else colors.CHECK
                if pid in ev.check_ids
                else colors.TARGET,
            )
            if ("targets", pid) not in self.dragging:
                self._assign(self.gizmos[("targets", pid)], "position", tuple(t.positions[i]))
            self._assign(self.labels[f"{gizmo_name('targets', pid)}/label"], "text", texts[i])
            region = self.regions.get(pid)
            if region is not None:
                self._assign(region, "position", tuple(t.positions[i]))
        tarrows = self.nodes["/corrections/targets"]
        if len(t.ids):
            tarrows.points = np.stack([t.positions, t.positions + mag * t.correction_robot], axis=1).astype(np.float32)
        tarrows.visible = bool(len(t.ids)) and self.target_arrows

        # landing: the bullseye of the selected target (the first target while a fiducial or nothing is selected)
        if len(t.ids):
            sel = self.selected
            i = t.ids.index(sel[1]) if sel is not None and sel[0] == "targets" else 0
            held = self.landing if self.landing_hold else None  # during a drag the bullseye keeps its scale
            ring = held.ring_mm if held is not None and held.target == t.ids[i] else None
            land = landing_display(t, i, self.display.marker_mm, (self.vec_landings or {}).get(t.ids[i]), ring)
            self.landing = land
            self.bullseye.show(land, self._assign)
            self._update_arm(land.position, mag, self.target_tools.get(land.target))

    def _update_arm(self, position, magnification: float, tool=None) -> None:
        """Pose the arm to reach `position` (the bullseye's target) with the tool down or leaned (tool: (tilt,
        azimuth) degrees); hide it where it cannot reach."""
        if self.arm is None:
            return
        if self.kind == "measurements":  # at the selected point's joint values (the first target's before)
            t = self.session.last.targets if self.session.last is not None else None
            sel = self.selected or (("targets", t.ids[0]) if t is not None and len(t.ids) else None)
            if sel is None or sel == self._arm_key:
                return
            self._arm_key = sel
            try:
                pose = measured_arm_pose(self.session, *sel)
            except InputError:
                self.groups["arm"].visible = False
                return
            self.groups["arm"].visible = self.layers.get("arm", True)
            self.arm.show(pose, magnification)
            return
        bias = self.bias_scale
        key = (tuple(np.round(position, 9)), bias, magnification, tool)
        if key == self._arm_key:
            return
        now = time.monotonic()
        if self.landing_hold and now - self._arm_time < ARM_DRAG_INTERVAL_S:
            return  # during a drag the arm follows a few times a second (its inverse kinematics and meshes cost)
        self._arm_key, self._arm_time = key, now
        rot = None
        if tool is not None:
            rot = tool_rotation(float(getattr(self.scene_model, "tool_yaw_deg", 0.0) or 0.0), *tool)
        try:
            pose = arm_pose(self.scene_model, position, bias, rot)
        except InputError:
            self.groups["arm"].visible = False
            return
        self.groups["arm"].visible = self.layers.get("arm", True)
        self.arm.show(pose, magnification)

    def _assign(self, handle, attr: str, value) -> None:
        """Set handle.attr = value unless it is the value this object last set there (tuples/str compare
        exactly); a gizmo moved by the user is re-sent once, which viser itself skips when unchanged."""
        key = (id(handle), attr)
        if self._sent.get(key) == value:
            return
        setattr(handle, attr, np.asarray(value, float) if isinstance(value, tuple) and attr == "position" else value)
        self._sent[key] = value

    def snap(self, kind: str, pid: str, position) -> None:
        """Put a gizmo back (a refused move)."""
        self.gizmos[(kind, pid)].position = np.asarray(position, float)
        self._sent[(id(self.gizmos[(kind, pid)]), "position")] = tuple(np.asarray(position, float))

    def resnap(self, kind: str, pid: str) -> None:
        """Send a gizmo's position again even though the server's copy has not changed. viser skips a value
        np.allclose to the one it holds, so step off by more than its tolerance and back; the two messages share
        a redundancy key, so a tab receives only the last."""
        tc = self.gizmos[(kind, pid)]
        p = np.array(tc.position, float)
        tc.position = p + np.array([1e-4 * (1.0 + float(np.abs(p).max())), 0.0, 0.0])
        tc.position = p

    def _frame_note(self) -> str:
        """The registered frame's note; short in presentation mode (large text must stay left of the panel)."""
        if self.label_scale > 1.0:
            return f"registered ×{self.frame_mag:g}"
        return f"registration error ×{self.frame_mag:g} (drawn beside the true pose)"

    def set_label_scale(self, factor: float) -> None:
        """Labels' screen size × factor (presentation mode)."""
        self.label_scale = float(factor)
        # large labels centred over their point (short texts): they stay in the view's free part
        anchor: Literal["bottom-center", "bottom-left"] = "bottom-center" if self.label_scale > 1.0 else "bottom-left"
        for h in self.labels.values():
            h.font_screen_scale = 0.75 * self.label_scale
            h.anchor = anchor
        self._show_labels()
        if "/frames/sensor_registered/note" in self.nodes:
            self._assign(self.nodes["/frames/sensor_registered/note"], "text", self._frame_note())
        for name in ("/landing/scale", "/frames/sensor_registered/note"):
            if name in self.nodes:
                self.nodes[name].font_screen_scale = 0.8 * self.label_scale
                self.nodes[name].anchor = "top-center" if self.label_scale > 1.0 else "bottom-left"
        if self.arm is not None:
            self.arm.marks["label"].font_screen_scale = 0.75 * self.label_scale
            self.arm.marks["label"].anchor = "top-center" if self.label_scale > 1.0 else "bottom-left"
            self.arm.compact = self.label_scale > 1.0
            self.arm.refresh_label()
        self.bullseye.set_label_scale(self.label_scale)

    def set_see_through(self, on: bool) -> None:
        """Draw the work cell solid or see-through (what lies under its surfaces shows)."""
        self.see_through = bool(on)
        if "/mesh/cell" in self.nodes:
            self.nodes["/mesh/cell"].visible = not self.see_through
            self.nodes["/mesh/ghost"].visible = self.see_through

    def set_layer(self, layer: str, visible: bool) -> None:
        self.layers[layer] = bool(visible)
        if layer == "labels":
            self._show_labels()
        elif layer in self.groups:
            self.groups[layer].visible = bool(visible)

    def set_selected(self, selected: tuple[str, str] | None) -> None:
        """Select a point (kind, id) or none: only the selected point carries a drag gizmo (the others keep their
        sphere, clickable), and its label shows even when the labels layer is off."""
        if selected is not None and selected not in self.gizmos:
            selected = None
        self.selected = selected
        for key, tc in self.gizmos.items():
            on = key == selected
            self._assign(tc, "disable_axes", not on)
            self._assign(tc, "disable_sliders", not on)
        self._show_labels()

    def applicable_layers(self) -> tuple[str, ...]:
        """The layers this build has something in (the View tab lists only these)."""
        missing = set()
        if "/mesh/cell" not in self.nodes:
            missing.add("mesh")
        if self.arm is None:
            missing.add("arm")
        if self.scene.get_handle_by_name("/sensor/camera0/body") is None:
            missing.add("sensor")
        if not self.regions:
            missing.add("regions")
        return tuple(n for n in LAYERS if n not in missing)

    def set_lesson_labels(self, kinds: tuple[str, ...]) -> None:
        """Show the labels of these kinds of point (a lesson step's, teaching.Step.labels) besides the others."""
        self.lesson_labels = tuple(kinds)
        self.lesson_hidden = frozenset()
        self._show_labels()

    def hide_lesson_labels(self, names) -> None:
        """Of the lesson step's labels, hide these (lesson_labels.declutter: they would overlap)."""
        self.lesson_hidden = frozenset(names)
        self._show_labels()

    def _show_labels(self) -> None:
        # presentation mode: only the selected point's label and a lesson step's (large labels of every point would
        # overlap)
        on = bool(self.layers.get("labels")) and self.label_scale <= 1.0
        lesson = tuple(f"/{k}/" for k in self.lesson_labels)
        mine = None if self.selected is None else f"{gizmo_name(*self.selected)}/label"
        hidden = self.lesson_hidden
        for name, h in self.labels.items():
            self._assign(h, "visible", on or name == mine or (name.startswith(lesson) and name not in hidden))

    def apply_sizes(self) -> None:
        """Marker size and region zoom changed: resize spheres, gizmos, arrows, regions."""
        r = self.display.marker_mm
        for (kind, _pid), s in self.spheres.items():
            s.radius = r if kind == "fiducials" else 0.8 * r
        for tc in self.gizmos.values():
            tc.scale = self._gizmo_scale()
        for name, h in self.labels.items():
            if name.endswith("/gizmo/label"):
                h.position = np.array([0.0, 0.0, 1.6 * r])
        for key in ("/corrections/fiducials", "/corrections/targets"):
            for k, v in self._arrow_sizes().items():
                setattr(self.nodes[key], k, v)
        reg = self.nodes.get("/registration/points")
        if reg is not None:
            reg.batched_scales = np.full(len(reg.batched_positions), 0.8 * r, np.float32)
        self.bullseye.resize(r)
        for pid, region in self.regions.items():
            kind, size = self.region_kind[pid]
            region.scale = float(self.display.region_zoom) if kind == "box" else tuple(size * self.display.region_zoom)
        self.heat.resize(self.display)
