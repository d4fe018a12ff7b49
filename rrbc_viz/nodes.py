"""The 3-D scene: viser nodes for one session, created once and then updated in place.

Frame and units: every node is placed in the ROBOT frame, in millimetres (the scene frame is the robot frame;
viser's +z is up, as in the scenes). Correction arrows and landing offsets are drawn `magnification` times
longer than they are (said on screen); regions of variability and heat-map samples can be drawn `region_zoom`
times larger about their target. Both are display-only transforms.

Node tree (one group per layer of `LAYERS`; a layer's visibility is its group's):

    /mesh/cell                         the work-cell mesh
    /frames/robot, /frames/sensor_true, /frames/sensor_registered   (+ …/label)
    /registration/points               batched spheres (+ /registration/labels/<id>)
    /fiducials/<id>/gizmo              transform controls, translation only (drag a fiducial)
    /fiducials/<id>/gizmo/sphere       the fiducial (click: exclude/include), …/label
    /corrections/fiducials, /corrections/targets   arrows
    /hull/edges                        line segments, screen-space thickness
    /targets/<id>/gizmo                transform controls, translation only (drag a target)
    /targets/<id>/gizmo/sphere         the target (magenta when extrapolated), …/label
    /regions/<id>                      translucent box / icosphere with per-axis scale
    /landing/anchor, /landing/rigid, /landing/rrbc, /landing/lines
    /heatmap/points                    point cloud, float32: the samples, in their region (true size × region zoom)
    /heatmap/rings                     point cloud, unlit: a flat ring of dots around each target, coloured by
                                       its region's mean value (regions are mm-sized in a metre-sized cell)
    (labels: every …/label node; the "labels" layer toggles them all)

Ids are used in node names with "/" replaced by "_" (`node_key`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import viser
import viser.transforms as vtf

from rrbc_core.session.evaluation import Evaluation
from rrbc_core.session.explorer import ExplorerSession

from . import colors
from .heatmap_nodes import HeatMapNodes

#: The scene's layers, each a group node whose visibility the View tab and the lesson steps switch.
LAYERS = (
    "mesh",
    "frames",
    "registration",
    "fiducials",
    "corrections",
    "hull",
    "targets",
    "regions",
    "landing",
    "labels",
    "heatmap",
)

#: (kind, id, robot-frame position mm, phase, client=...) -> anything
DragCallback = Callable[..., object]
#: (fiducial id, client=...) -> anything
ClickCallback = Callable[..., object]

GIZMO_LIMITS = ((-1e7, 1e7),) * 3


def node_key(pid: str) -> str:
    return str(pid).replace("/", "_") or "_"


def gizmo_name(kind: str, pid: str) -> str:
    """Scene-node name of the drag gizmo of a point: kind "targets" or "fiducials", e.g. /targets/H1/gizmo."""
    return f"/{kind}/{node_key(pid)}/gizmo"


@dataclass
class Display:
    """Display-only options (no effect on any number)."""

    magnification: float = 200.0  # arrows and landing offsets drawn this many times longer
    marker_mm: float = 8.0  # radius of fiducial / target spheres
    region_zoom: float = 1.0  # regions and heat-map samples drawn this many times larger about their target
    handles: str = "targets"  # which points show drag handles: targets, fiducials, both, none
    heat_value: str = "rrbc"  # rrbc | rigid (scene); correction | std (measurements)


HANDLE_CHOICES = ("targets", "fiducials", "both", "none")


def _wxyz(rotation) -> np.ndarray:
    return np.asarray(vtf.SO3.from_matrix(np.asarray(rotation, float)).wxyz, float)


def _unit_sphere():
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    return np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.uint32)


def _identity_wxyzs(n: int) -> np.ndarray:
    q = np.zeros((n, 4), np.float32)
    q[:, 0] = 1.0
    return q


def fiducial_labels(ev: Evaluation) -> list[str]:
    """Label texts of every fiducial (correction size, or 'excluded')."""
    norms = np.linalg.norm(ev.corrections, axis=1)
    return [
        f"{pid} · e {norms[i]:.3f} mm" if ev.included[i] else f"{pid} · excluded"
        for i, pid in enumerate(ev.fiducial_ids)
    ]


def fiducial_label(pid: str, ev: Evaluation, i: int) -> str:
    return fiducial_labels(ev)[i]


def target_labels(ev: Evaluation) -> list[str]:
    """Label texts of every target (errors against the truth, or the correction and its std without truth)."""
    t = ev.targets
    corr = np.linalg.norm(t.correction, axis=1)
    std = None if t.correction_std is None else np.linalg.norm(t.correction_std, axis=1)
    out = []
    for i, pid in enumerate(t.ids):
        if np.isfinite(t.error_rigid[i]):
            s = f"{pid} · rigid {t.error_rigid[i]:.3f} / RRBC {t.error_rrbc[i]:.3f} mm"
        else:
            s = f"{pid} · ê {corr[i]:.3f} mm"
            if std is not None:
                s += f" ± {std[i]:.3f}"
        if bool(t.extrapolated[i]):
            s += " ⚠ extrapolated"
        out.append(s)
    return out


def target_label(pid: str, ev: Evaluation, i: int) -> str:
    return target_labels(ev)[i]


class SceneNodes(HeatMapNodes):
    """Creates the nodes of a session (`build`) and refreshes them from an Evaluation (`update`)."""

    def __init__(self, server: viser.ViserServer, on_drag: DragCallback, on_fiducial_click: ClickCallback):
        self.server = server
        self.scene = server.scene
        self._on_drag = on_drag
        self._on_click = on_fiducial_click
        self._sphere_v, self._sphere_f = _unit_sphere()
        self.groups: dict[str, viser.SceneNodeHandle] = {}
        self.gizmos: dict[tuple[str, str], viser.TransformControlsHandle] = {}
        self.spheres: dict[tuple[str, str], viser.IcosphereHandle] = {}
        self.labels: dict[str, viser.LabelHandle] = {}  # node name of the label -> handle
        self._sent: dict = {}  # (id(handle), attribute) -> the value last assigned by update()
        self.regions: dict[str, viser.SceneNodeHandle] = {}
        self.region_kind: dict[str, tuple[str, np.ndarray]] = {}  # id -> (kind, size)
        self.nodes: dict[str, viser.SceneNodeHandle] = {}  # other nodes by name
        self.layers: dict[str, bool] = {name: True for name in LAYERS}
        self.display = Display()
        self.kind = "scene"
        self.extent_mm = 1000.0
        self.target_arrows = True  # the lesson hides the targets' arrows while it shows the fiducials' only
        self._heat_rings_args = None  # what the heat-map rings were last drawn from (redrawn on a resize)

    # ------------------------------------------------------------------------------------------ building
    def clear(self) -> None:
        for h in list(self.groups.values()):
            try:
                h.remove()
            except Exception:  # noqa: BLE001 - already gone
                pass
        self.groups.clear(), self.gizmos.clear(), self.spheres.clear(), self.labels.clear()
        self.regions.clear(), self.region_kind.clear(), self.nodes.clear()
        self._heat_rings_args = None
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
            self.nodes["/mesh/cell"] = sc.add_mesh_trimesh("/mesh/cell", mesh, cast_shadow=False, receive_shadow=False)

        # frames ---------------------------------------------------------------------------------------
        axes = 0.12 * self.extent_mm
        self.nodes["/frames/robot"] = sc.add_frame("/frames/robot", axes_length=axes, axes_radius=axes * 0.03)
        self._label("/frames/robot/label", "robot base", (0.0, 0.0, axes * 0.2))
        if session.sensor_to_robot is not None:
            T = session.sensor_to_robot
            self.nodes["/frames/sensor_true"] = sc.add_frame(
                "/frames/sensor_true",
                axes_length=axes,
                axes_radius=axes * 0.03,
                wxyz=_wxyz(T.rotation),
                position=np.asarray(T.translation, float),
            )
            self._label("/frames/sensor_true/label", "sensor (true pose)", (0.0, 0.0, axes * 0.2))
        m = ev.registration.mapping
        self.nodes["/frames/sensor_registered"] = sc.add_frame(
            "/frames/sensor_registered",
            axes_length=axes * 1.3,
            axes_radius=axes * 0.012,
            origin_color=(255, 255, 255),
            wxyz=_wxyz(m.rotation),
            position=np.asarray(m.translation, float),
        )
        self._label("/frames/sensor_registered/label", "sensor (registered)", (0.0, 0.0, -axes * 0.2))

        # registration points --------------------------------------------------------------------------
        n = len(ev.registration_ids)
        if n:
            self.nodes["/registration/points"] = sc.add_batched_meshes_simple(
                "/registration/points",
                self._sphere_v,
                self._sphere_f,
                batched_wxyzs=_identity_wxyzs(n),
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

        # landing points --------------------------------------------------------------------------------
        m_t = len(ev.targets.ids)
        if m_t:
            for key, color, s in (
                ("anchor", colors.LAND_ANCHOR, 0.35),
                ("rigid", colors.LAND_RIGID, 0.45),
                ("rrbc", colors.LAND_RRBC, 0.45),
            ):
                self.nodes[f"/landing/{key}"] = sc.add_batched_meshes_simple(
                    f"/landing/{key}",
                    self._sphere_v,
                    self._sphere_f,
                    batched_wxyzs=_identity_wxyzs(m_t),
                    batched_positions=ev.targets.positions.astype(np.float32),
                    batched_scales=np.full(m_t, s * r, np.float32),
                    batched_colors=color,
                    cast_shadow=False,
                    receive_shadow=False,
                )
            self.nodes["/landing/lines"] = sc.add_line_segments(
                "/landing/lines",
                np.zeros((2 * m_t, 2, 3), np.float32),
                self._landing_line_colors(m_t),
                thickness=2.0,
                thickness_units="screen",
            )

        # heat map (filled by update_heatmap) ------------------------------------------------------------
        self.nodes["/heatmap/points"] = sc.add_point_cloud(
            "/heatmap/points",
            np.zeros((1, 3), np.float32),
            np.zeros((1, 3), np.uint8),
            point_size=0.5,
            point_shape="circle",
            precision="float32",
            visible=False,
        )
        if m_t:  # unlit points (flat shading): the ring shows the legend's colours, whatever the lighting
            self.nodes["/heatmap/rings"] = sc.add_point_cloud(
                "/heatmap/rings",
                np.zeros((1, 3), np.float32),
                np.zeros((1, 3), np.uint8),
                point_size=1.0,
                point_shape="circle",
                point_shading="flat",
                precision="float32",
                visible=False,
            )

        self.set_handles(display.handles)
        self.set_layer("labels", self.layers["labels"])
        self.update(ev)

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
            self.set_handles(self.display.handles)
        return new

    def _label(self, name: str, text: str, position) -> None:
        self.labels[name] = self.scene.add_label(
            name,
            text,
            position=np.asarray(position, float),
            font_size_mode="screen",
            font_screen_scale=0.75,
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
            # async: runs on viser's event loop, in order (start, updates, end); never awaits.
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
        if kind == "fiducials":

            def on_click(event: viser.SceneNodePointerEvent, pid=pid) -> None:
                self._on_click(pid, client=event.client)

            sphere.on_click(on_click)
        self.gizmos[(kind, pid)] = tc
        self.spheres[(kind, pid)] = sphere
        self._label(f"{name}/label", label, (0.0, 0.0, 1.6 * r))

    def _gizmo_scale(self) -> float:
        return 5.0 * self.display.marker_mm

    def _arrow_sizes(self) -> dict:
        r = self.display.marker_mm
        return {"shaft_radius": 0.22 * r, "head_radius": 0.55 * r, "head_length": 1.4 * r}

    @staticmethod
    def _landing_line_colors(m: int) -> np.ndarray:
        c = np.empty((2 * m, 2, 3), np.uint8)
        c[:m] = colors.LAND_RIGID
        c[m:] = colors.LAND_RRBC
        return c

    # ------------------------------------------------------------------------------------------ updating
    def update(self, ev: Evaluation) -> None:
        """Refresh every node that depends on the Evaluation (call inside `server.atomic()`). Only changed
        properties are sent (viser skips unchanged values; a gizmo being dragged already sits where the user
        put it, so it is not sent back)."""
        mag = self.display.magnification
        m = ev.registration.mapping
        reg_frame = self.nodes["/frames/sensor_registered"]
        reg_frame.wxyz = _wxyz(m.rotation)
        reg_frame.position = np.asarray(m.translation, float)
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
            self._assign(self.gizmos[("fiducials", pid)], "position", tuple(ev.fiducial_positions[i]))
            self._assign(self.labels[f"{gizmo_name('fiducials', pid)}/label"], "text", texts[i])
        inc = np.flatnonzero(ev.included)
        arrows = self.nodes["/corrections/fiducials"]
        if len(inc):
            start = ev.fiducial_positions[inc]
            arrows.points = np.stack([start, start + mag * ev.corrections_robot[inc]], axis=1).astype(np.float32)
        arrows.visible = bool(len(inc))

        # hull
        hull = self.nodes["/hull/edges"]
        if len(ev.hull_edges):
            hull.points = np.asarray(ev.hull_edges, np.float32)
        hull.visible = bool(len(ev.hull_edges))

        # targets
        t = ev.targets
        texts = target_labels(ev)
        for i, pid in enumerate(t.ids):
            self._assign(
                self.spheres[("targets", pid)],
                "color",
                colors.TARGET_EXTRAPOLATED if t.extrapolated[i] else colors.TARGET,
            )
            self._assign(self.gizmos[("targets", pid)], "position", tuple(t.positions[i]))
            self._assign(self.labels[f"{gizmo_name('targets', pid)}/label"], "text", texts[i])
            region = self.regions.get(pid)
            if region is not None:
                self._assign(region, "position", tuple(t.positions[i]))
        tarrows = self.nodes["/corrections/targets"]
        if len(t.ids):
            tarrows.points = np.stack([t.positions, t.positions + mag * t.correction_robot], axis=1).astype(np.float32)
        tarrows.visible = bool(len(t.ids)) and self.target_arrows

        # landing: anchor = the target; offsets from the truth (or from the rigid landing without truth)
        if len(t.ids):
            known = np.all(np.isfinite(t.truth), axis=1)[:, None]
            ref = np.where(known, t.truth, t.robot_rigid)
            anchor = t.positions
            rigid = anchor + mag * (t.robot_rigid - ref)
            rrbc = anchor + mag * (t.robot_rrbc - ref)
            self.nodes["/landing/anchor"].batched_positions = anchor.astype(np.float32)
            self.nodes["/landing/rigid"].batched_positions = rigid.astype(np.float32)
            self.nodes["/landing/rrbc"].batched_positions = rrbc.astype(np.float32)
            self.nodes["/landing/lines"].points = np.concatenate(
                [np.stack([anchor, rigid], 1), np.stack([anchor, rrbc], 1)]
            ).astype(np.float32)

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

    def set_layer(self, layer: str, visible: bool) -> None:
        self.layers[layer] = bool(visible)
        if layer == "labels":
            for h in self.labels.values():
                h.visible = bool(visible)
        elif layer in self.groups:
            self.groups[layer].visible = bool(visible)

    def set_handles(self, which: str) -> None:
        """Show drag handles on targets, fiducials, both or none (hidden handles keep their sphere)."""
        self.display.handles = which
        for (kind, _), tc in self.gizmos.items():
            on = which == "both" or which == kind
            tc.disable_axes = not on
            tc.disable_sliders = not on

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
        for key, s in (("anchor", 0.35), ("rigid", 0.45), ("rrbc", 0.45)):
            h = self.nodes.get(f"/landing/{key}")
            if h is not None:
                h.batched_scales = np.full(len(h.batched_positions), s * r, np.float32)
        for pid, h in self.regions.items():
            kind, size = self.region_kind[pid]
            h.scale = float(self.display.region_zoom) if kind == "box" else tuple(size * self.display.region_zoom)
        rings = self.nodes.get("/heatmap/rings")
        if rings is not None and self._heat_rings_args is not None:
            self._update_heat_rings(rings, *self._heat_rings_args)
