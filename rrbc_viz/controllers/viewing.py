"""What a user looks at (`ViewController`): the camera (presets, per-step framing, framing new tabs for their window),
presentation mode, the see-through cell, the error slice, the selected point (its drag gizmo, info card and landing
bullseye) and the lesson."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.session import figures
from rrbc_core.session.evaluation import Evaluation
from rrbc_core.session.slices import VALUES as SLICE_VALUES
from rrbc_core.session.slices import default_plane

from .. import selection_card, teaching
from ..camera import (
    DEFAULT_IMAGE,
    OBLIQUE,
    PRESETS,
    CellGeometry,
    View,
    frame_margin,
    panel_px,
    preset_view,
)
from ..colors import legend_markdown
from ..node_values import LAYERS, label_heights
from ..picture import AXES_SHARE
from ..slice_nodes import SLICE_CHOICES

if TYPE_CHECKING:
    from ..context import AppContext

SLICE_NOTE = (
    "The plane is sampled on a grid; each point is measured without noise and corrected with the current "
    "fiducials. White line: the fiducials' hull; clear: points the arm cannot reach. Rigid and RRBC share one "
    "scale. The 95 % bound is what rrbc correct would bound a target there by; clear where it gives none (farther "
    "from the fiducials than their cross-validation tested)."
)


PRESENTATION_LABEL_SCALE = 3.0  # labels' screen size in presentation mode: 0.75 x 3 x 12 px x 720/800 = 24 px
PRESENTATION_MARKERS = 1.5  # markers' size in presentation mode


#: the Learn tab's text once Next has gone past the last step
LESSON_FINISHED = (
    "That was the ninth and last step: the layers are back as they were before the lesson. Press **Next** to start "
    "again."
)


class ViewController:
    """`actions.ViewActions`: the camera, presentation mode, the see-through cell, the error slice, the selection and
    the lesson (module docstring)."""

    def __init__(self, ctx: AppContext):
        self.ctx = ctx

    # --------------------------------------------------------------------------------------------- camera
    def cell_geometry(self) -> CellGeometry:
        ev = self.ctx.session.last
        mesh = self.ctx.loaded.mesh
        scene = getattr(self.ctx.session, "scene", None)
        sensor = (
            None
            if self.ctx.session.sensor_to_robot is None
            else np.asarray(self.ctx.session.sensor_to_robot.translation)
        )
        return CellGeometry(
            registration=ev.registration_positions.reshape(-1, 3),
            fiducials=ev.fiducial_positions.reshape(-1, 3),
            targets=ev.targets.positions.reshape(-1, 3),
            mesh_bounds=None if mesh is None else np.asarray(mesh.bounds, float),
            sensor_position=sensor,
            sensor_kind=None if scene is None else scene.sensor_kind,
        )

    def work_points(self) -> np.ndarray:
        """(N, 3) robot frame, mm: the targets and fiducials (what a reframed view keeps beside a dragged point)."""
        g = self.cell_geometry()
        return np.vstack([g.targets, g.fiducials])

    def focus_points(self, names) -> np.ndarray:
        """Robot-frame points (K, 3) of what a lesson step talks about (teaching.Step.focus)."""
        cell = self.cell_geometry()
        plain = [n for n in names if n not in ("corrections", "landing")]
        parts = [cell.points(*plain)] if plain else []
        ev = self.ctx.session.last
        r = self.ctx.state.display.marker_mm
        if "corrections" in names:
            inc = np.flatnonzero(ev.included)
            mag = self.ctx.state.display.magnification
            parts.append(ev.fiducial_positions[inc] + mag * ev.corrections_robot[inc])
            if self.ctx.state.target_arrows:
                parts.append(ev.targets.positions + mag * ev.targets.correction_robot)
        if "sensor" in names:
            # both sensor frames with their axes (a sphere of one axis length around each origin)
            axes = AXES_SHARE * self.ctx.state.extent_mm * 1.3 * self.ctx.state.frames_zoom
            d = np.vstack([np.eye(3), -np.eye(3)]) * axes
            for origin in (self.ctx.present.picture().registered_position, cell.sensor_position):
                if origin is not None:
                    parts.append(np.asarray(origin, float) + d)
        land = self.ctx.state.landing
        if "landing" in names and land is not None:
            ring = land.ring_mm * land.scale
            parts += [land.anchor, land.rigid, land.rrbc, land.position]
            parts += [land.anchor + d for d in ([ring, 0, 0], [-ring, 0, 0], [0, ring, 0], [0, -ring, 0])]
        pts = np.vstack([p.reshape(-1, 3) for p in parts if len(p)]) if parts else np.zeros((0, 3))
        # a margin of a few marker radii: the spheres themselves must fit, not just their centres
        d = np.vstack([np.eye(3), -np.eye(3)]) * 2.0 * r
        return np.vstack([pts, (pts[:, None, :] + d[None]).reshape(-1, 3)])

    def _selected_label_points(self, step) -> np.ndarray:
        """(K, 3) robot frame, mm: where the selected point's label is drawn (over its drag gizmo) with a margin of a
        few marker radii, when the step labels points of its kind (issue 39: at 1280x720 the step framed H1 at the
        view's left edge and its raised label ran off it); else none."""
        sel = self.ctx.state.selected
        if sel is None or sel[0] not in step.labels:
            return np.zeros((0, 3))
        r = self.ctx.state.display.marker_mm
        anchor = self._selected_position() + [0.0, 0.0, label_heights(r)[1]]
        return anchor + np.vstack([np.zeros(3), np.eye(3), -np.eye(3)]) * 2.0 * r

    def _selected_position(self) -> np.ndarray:
        """(3,) robot frame, mm: the selected point (there is one)."""
        assert self.ctx.state.selected is not None
        kind, pid = self.ctx.state.selected
        ev = self.ctx.session.last
        if kind == "targets":
            return np.asarray(ev.targets.positions[ev.targets.ids.index(pid)], float)
        return np.asarray(ev.fiducial_positions[ev.fiducial_ids.index(pid)], float)

    def current_view(self) -> View:
        """What the camera should show now: the lesson step's focus, else the last preset."""
        if self.ctx.state.lesson_index is not None:
            step = teaching.STEPS[self.ctx.state.lesson_index]
            direction = OBLIQUE if step.direction is None else np.asarray(step.direction, float)
            return View(np.vstack([self.focus_points(step.focus), self._selected_label_points(step)]), direction)
        return self.preset_view(self.ctx.state.camera_preset)

    def preset_view(self, name: str) -> View:
        selected = None
        if self.ctx.state.selected is not None:
            kind, pid = self.ctx.state.selected
            selected = [self._selected_position()]
            if kind == "targets":
                land = self.ctx.state.landing
                if land is not None and self.ctx.state.layers.get("landing") and land.target == pid:
                    ring = land.ring_mm * land.scale
                    selected += [land.anchor, land.rigid, land.rrbc]
                    selected += [land.anchor + d for d in ([ring, 0, 0], [-ring, 0, 0], [0, ring, 0], [0, -ring, 0])]
        return preset_view(name, self.cell_geometry(), selected=selected, marker_mm=self.ctx.state.display.marker_mm)

    def show_camera(self, preset: str, client=None) -> dict:
        """Move the camera to a preset (camera.PRESETS): of `client`'s tab, or of every tab (client None).
        Returns the poses sent, by client id."""
        if preset not in PRESETS:
            raise InputError(f"unknown camera preset '{preset}': {', '.join(PRESETS)}")
        with self.ctx.lock:
            self.ctx.state.camera_preset = preset
            poses = self.ctx.camera.show(self.preset_view(preset), None if client is None else [client])
            self.place_labels(poses)  # the selected label and the ring label apart in the new view
            return poses

    def frame_new_client(self, client) -> None:
        """A tab connected: once it reports its camera (window size), frame the current view for it."""
        guard = self.ctx.guard
        if guard is not None and guard.is_refused(client.client_id):
            return  # refused at the handshake (access.AccessGuard)
        done = {"flag": False}

        def on_camera(_camera) -> None:
            if done["flag"]:
                return
            done["flag"] = True
            try:
                with self.ctx.lock:
                    self.place_labels(self.ctx.camera.show(self.current_view(), [client]))
            except Exception:  # noqa: BLE001 - a closing tab must not break the app
                pass

        client.camera.on_update(on_camera)

    def set_presentation(self, on: bool) -> None:
        """Presentation mode (a projector at 1280x720): large panel text, a collapsible panel, larger markers and
        labels; the camera reframes for the new panel."""
        with self.ctx.lock:
            on = bool(on)
            if on == self.ctx.state.presentation:
                return
            self.ctx.state.presentation = on
            self.ctx.camera.set_panel(panel_px(on), frame_margin(on))
            with self.ctx.server.atomic():
                self.ctx.controls.apply_theme(on)
                self.ctx.controls.show_legend(self._legend())
                self.ctx.controls.sync_presentation(on)
                self.ctx.nodes.set_label_scale(PRESENTATION_LABEL_SCALE if on else 1.0)
                marker = self.ctx.state.display.marker_mm * (PRESENTATION_MARKERS if on else 1 / PRESENTATION_MARKERS)
                self.ctx.evaluate.set_display(marker_mm=float(marker))
                self.ctx.state.initial_camera = self.ctx.camera.reframe_initial(self.current_view())
                if self.ctx.state.lesson_index is not None:  # the step's text for this mode (shorter when presenting)
                    ev, lesson = self.ctx.session.last, self.ctx.present.lesson_context()
                    self.ctx.controls.learn.show_text(teaching.render(self.ctx.state.lesson_index, ev, lesson))
                self.place_labels(self.ctx.camera.show(self.current_view()))

    def _legend(self) -> bool | None:
        """The colour legend: open while exploring, closed to its title during a lesson (it needs the room), not
        shown in presentation mode (a projector needs the room; a lesson's text names the colours it shows)."""
        if self.ctx.state.presentation:
            return None
        return self.ctx.state.lesson_index is None

    def set_see_through(self, on: bool) -> None:
        """Draw the work cell see-through (View tab checkbox; lesson steps whose arrows point into surfaces)."""
        with self.ctx.lock:
            self.ctx.state.see_through = bool(on)
            self.ctx.nodes.set_see_through(on)
            self.ctx.controls.sync_see_through(on)

    # ---------------------------------------------------------------------------------------------- slice
    def slice_plane(self):
        """The error slice's plane: normal to Display.slice_axis at slice_offset (default: the work's median),
        spanning the point sets widened by 35 % on each side (slices.default_plane)."""
        cell = self.cell_geometry()
        pts = cell.points("registration", "fiducials", "targets")
        return default_plane(pts, self.ctx.state.display.slice_axis, self.ctx.state.display.slice_offset)

    def slice_range(self) -> tuple[float, float]:
        """Offsets (mm) the slice can take along its axis: the point sets' extent, widened like the plane."""
        pts = self.cell_geometry().points("registration", "fiducials", "targets")
        k = "xyz".index(self.ctx.state.display.slice_axis)
        lo, hi = float(pts[:, k].min()), float(pts[:, k].max())
        pad = 0.35 * max(hi - lo, 10.0)
        return lo - pad, hi + pad

    def check_slice_display(self, new) -> None:
        if new.slice_axis not in ("x", "y", "z"):
            raise InputError(f"slice_axis must be x, y or z, got {new.slice_axis!r}")
        if new.slice_value not in SLICE_VALUES:
            raise InputError(f"slice_value must be one of {', '.join(SLICE_VALUES)}, got {new.slice_value!r}")
        if new.slice_offset is not None and not np.isfinite(new.slice_offset):
            raise InputError("slice_offset must be a finite number of mm")

    def update_slice(self) -> None:
        """Recompute and redraw the error slice if its layer is on (caller holds the lock)."""
        if not self.ctx.state.layers.get("slice"):
            return
        value = self.ctx.state.display.slice_value
        shown = self.ctx.state.error_slice = figures.error_slice(
            self.ctx.session, self.slice_plane(), bound=value == "bound95"
        )
        values = shown.values[value]
        if not np.any(np.isfinite(values)):
            note = (
                "No bound anywhere on this plane: too few fiducials to cross-validate, or the plane lies farther from "
                "them than their cross-validation tested."
                if value == "bound95"
                else "Nothing to show for this value here (no truth, or not gp)."
            )
            self.ctx.controls.view.show_slice_legend(note)
        else:
            lo, hi = self.ctx.slice_node.show(shown, value)
            name = dict((v, k) for k, v in SLICE_CHOICES)[value]
            self.ctx.controls.view.show_slice_legend(legend_markdown(name, lo, hi, note=SLICE_NOTE))
        self.ctx.controls.sync_slice(
            self.ctx.state.display, self.slice_range(), self.ctx.session.kind, shown.plane.offset_mm
        )

    # ------------------------------------------------------------------------------------------ selection
    def select(self, kind: str | None, pid: str | None = None, client=None) -> None:
        """Select a point (kind "targets"/"fiducials", id) or none (kind None): it alone carries the drag gizmo;
        the info card and the bullseye show its numbers."""
        with self.ctx.lock:
            ev = self.ctx.session.last
            sel: tuple[str, str] | None = None
            if kind is not None:
                kind = {"target": "targets", "fiducial": "fiducials"}.get(kind, kind)
                ids = ev.targets.ids if kind == "targets" else ev.fiducial_ids if kind == "fiducials" else ()
                if pid is None or pid not in ids:
                    raise InputError(f"there is no {kind[:-1] if kind.endswith('s') else kind} '{pid}' to select")
                sel = (kind, pid)
            self.ctx.state.selected = sel
            with self.ctx.server.atomic():
                self.ctx.nodes.set_selected(sel)
                self.ctx.present.draw_scene(ev)  # the landing bullseye follows the selected target
                self.show_selection(ev)
                if self.ctx.state.lesson_index is None:  # (a lesson keeps its own labels in view: `place_labels`)
                    self.keep_label_in_view(client)

    def set_point_sort(self, sort: str) -> None:
        """Order the point list (the "Selected point" dropdown) by `sort` (selection_card.SORTS)."""
        if sort not in selection_card.SORTS:
            raise InputError(f"unknown order {sort!r}: {', '.join(selection_card.SORTS)}")
        with self.ctx.lock:
            self.ctx.state.point_sort = sort
            self.show_selection(self.ctx.session.last)

    def on_point_click(self, kind: str, pid: str, client=None) -> None:
        try:
            self.select(kind, pid, client=client)
        except Exception as exc:  # noqa: BLE001 - keep serving
            self.ctx.message(str(exc), client)

    def show_selection(self, ev: Evaluation) -> None:
        """Refresh the info card, the bullseye and the selection dropdown (caller holds the lock)."""
        c = self.ctx.controls
        sel = self.ctx.state.selected
        names = selection_card.point_names(ev, self.ctx.state.point_sort)
        c.sync_selection(names, selection_card.choice_of(sel, names), sel)
        state = self.ctx.state.plan
        fraction = None
        if sel is not None and sel[0] == "targets" and state is not None and sel[1] in state.target_ids:
            fraction = state.coverage_of(sel[1])  # the Plan tab's own number for this target's region
        c.selection.show_card(selection_card.info_card(ev, sel, fraction))
        land = self.ctx.state.landing
        target = land.target if land is not None else None  # the target whose bullseye the scene shows
        explore = sel[1] if sel is not None and sel[0] == "targets" else None
        last_step = self.ctx.state.lesson_index == len(teaching.STEPS) - 1
        vec = self.ctx.state.vec_landings().get(explore) if explore else None
        if explore:
            c.show_bullseye(*selection_card.bullseye_svg(ev, explore, vec), where="explore")
        else:
            c.show_bullseye(None, where="explore")
        if target and last_step:
            c.show_bullseye(*selection_card.bullseye_svg(ev, target), where="learn")
        else:
            c.show_bullseye(None, where="learn")

    # --------------------------------------------------------------------------------------------- lesson
    def lesson_go(self, index: int) -> str:
        """Show lesson step `index` (0-based, clamped): its layers, its text, and every tab's camera framed on
        what the step talks about. Returns the text."""
        with self.ctx.lock:
            index = int(np.clip(index, 0, len(teaching.STEPS) - 1))
            if self.ctx.state.lesson_index is None:
                self.ctx.state.lesson_saved_layers = dict(self.ctx.state.layers)
                self.ctx.state.lesson_saved_zoom = float(self.ctx.state.display.region_zoom)

            self.ctx.state.lesson_index = index
            self.ctx.controls.show_legend(self._legend())
            step = teaching.STEPS[index]
            with self.ctx.server.atomic():
                zoom = step.region_zoom or self.ctx.state.lesson_saved_zoom or 1.0
                if float(self.ctx.state.display.region_zoom) != zoom:
                    self.ctx.evaluate.set_display(region_zoom=float(zoom))
                for name in LAYERS:
                    self.ctx.evaluate.set_layer(name, name in step.layers)
                self.ctx.state.target_arrows = step.target_arrows
                self.ctx.state.lesson_labels = tuple(step.labels)
                self.ctx.state.frames_zoom = float(step.frames_zoom or 1.0)
                self.ctx.nodes.set_frames_zoom(self.ctx.state.frames_zoom)
                named = step.named(self.ctx.session.last) if step.named is not None else ()
                self.ctx.nodes.set_lesson_labels(step.labels, named)
                self.ctx.nodes.set_arm_marks_visible(False)
                self.set_see_through(step.see_through)
                self.ctx.present.draw_scene(self.ctx.session.last)
                text = teaching.render(index, self.ctx.session.last, self.ctx.present.lesson_context())
                self.ctx.controls.learn.show_text(text)
                self.show_selection(self.ctx.session.last)
                self.place_labels(self.ctx.camera.show(self.current_view()))
            return text

    def keep_label_in_view(self, client=None) -> None:
        """The selected point's label drawn with the anchor that keeps it left of the panel in the view of `client`
        (default: the first tab with a camera): its text runs left from a point near the panel
        (`lesson_labels.inside_anchor`)."""
        self.place_labels(self.ctx.camera.current(None if client is None else [client]))

    def place_labels(self, poses: dict) -> None:
        """Labels placed for the first tab's view in `poses` (client id -> pose), or the initial camera's: the selected
        point's kept left of the panel, the bullseye's ring label clear of it, and a lesson's labels that would
        overlap or run under the panel hidden (`nodes.SceneNodes.declutter_lesson_labels`)."""
        clients = self.ctx.server.get_clients()
        for cid, pose in poses.items():
            cam = clients[cid].camera if cid in clients else None
            if cam is not None:
                size = (float(cam.image_width), float(cam.image_height))
                self.ctx.nodes.declutter_lesson_labels(pose, size, panel_px(self.ctx.state.presentation))
                return
        initial = self.ctx.state.initial_camera
        if initial is not None:
            self.ctx.nodes.declutter_lesson_labels(initial, DEFAULT_IMAGE, panel_px(self.ctx.state.presentation))

    def lesson_step(self, delta: int) -> str:
        """Next (+1) or previous (-1) step; the first press of either starts the lesson at step 1, and Next after the
        last step ends it (the layers restored, as *End lesson* does)."""
        index = self.ctx.state.lesson_index
        if index is not None and delta > 0 and index >= len(teaching.STEPS) - 1:
            self.lesson_stop(LESSON_FINISHED)
            return LESSON_FINISHED
        return self.lesson_go(0 if index is None else index + delta)

    def lesson_stop(self, text: str = "Lesson ended. Press **Next** to start again.") -> None:
        """End the lesson: the layers, region zoom and look as they were before it; `text` in the Learn tab."""
        with self.ctx.lock:
            saved = self.ctx.state.lesson_saved_layers
            zoom = self.ctx.state.lesson_saved_zoom
            self.ctx.state.lesson_index = None
            self.ctx.state.lesson_saved_layers = None
            self.ctx.state.lesson_saved_zoom = None
            if zoom is not None and float(self.ctx.state.display.region_zoom) != zoom:
                self.ctx.evaluate.set_display(region_zoom=float(zoom))
            self.ctx.controls.show_legend(self._legend())
            with self.ctx.server.atomic():
                for name, visible in (saved or {}).items():
                    self.ctx.evaluate.set_layer(name, visible)
                self.ctx.state.target_arrows = True
                self.ctx.state.lesson_labels = ()
                self.ctx.state.frames_zoom = 1.0
                self.ctx.nodes.set_frames_zoom(1.0)
                self.ctx.nodes.set_lesson_labels(())
                self.ctx.nodes.set_arm_marks_visible(True)
                self.set_see_through(False)
                self.ctx.present.draw_scene(self.ctx.session.last)
                self.ctx.controls.learn.show_text(text)
                self.show_selection(self.ctx.session.last)
                self.place_labels(self.ctx.camera.show(self.current_view()))
