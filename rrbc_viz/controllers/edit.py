"""Authoring a cell in the app: a click on the cell adds the chosen kind of point where the click's ray meets the
mesh; delete the selected point; undo/redo; move the sensor; upload a mesh; download the scene, the measurement
plan and Slicer markups. The session does the editing (`rrbc_core.session.edits`); here the click becomes a
point and the scene is redrawn (`AuthoringController`).

Frames and units: robot frame, mm. A registration point goes `REGISTRATION_LIFT_MM` above the clicked surface
(registration points are held in free space); the others sit on it.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import traceback
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.models.visibility import cast_from
from rrbc_core.runtime.memory import release_memory
from rrbc_core.session import edits, figures

from .. import sources
from ..authoring_panel import CLICK_MODES, REGISTRATION_LIFT_MM

if TYPE_CHECKING:
    from ..context import AppContext


def surface_hit(mesh, origin, direction) -> np.ndarray | None:
    """Where the ray from `origin` along `direction` (robot frame) first meets the mesh, or None."""
    d = np.asarray(direction, float).reshape(3)
    n = np.linalg.norm(d)
    if mesh is None or not n > 0:
        return None
    d = d / n
    t, _ = cast_from(mesh, np.asarray(origin, float).reshape(3), d[None])
    return None if not np.isfinite(t[0]) else np.asarray(origin, float) + float(t[0]) * d


class AuthoringController:
    """`actions.AuthoringActions` (module docstring): what a click adds is in the app's state (`click_mode`,
    `target_region_mm`)."""

    def __init__(self, ctx: AppContext):
        self.ctx = ctx
        self.uploaded_mesh: Path | None = None  # the mesh uploaded in this session (a saved scene refers to it)

    def set_click_mode(self, kind: str | None, region_mm: float | None = None) -> None:
        """What a click on the cell adds: None (clicks select), "registration", "fiducials", "targets",
        "candidates"; `region_mm`: the cube edge of an added target's region."""
        if kind not in {k for _, k in CLICK_MODES}:
            raise InputError(f"unknown click mode {kind!r}")
        self.ctx.state.click_mode = kind
        if region_mm is not None:
            self.ctx.state.target_region_mm = float(region_mm)
        word = dict((k, w) for w, k in CLICK_MODES)[kind]
        self.ctx.controls.authoring.show_mode(
            "Clicks **select** points." if kind is None else f"**Adding {word}s**: click on the cell's mesh."
        )

    def on_scene_click(self, event) -> None:
        if self.ctx.state.click_mode is None:
            return
        try:
            self.add_at_ray(event.ray_origin, event.ray_direction, client=event.client)
        except Exception:  # noqa: BLE001 - keep serving
            traceback.print_exc()
            self.ctx.message("internal error while adding a point (see the server log)", event.client)

    def add_at_ray(self, origin, direction, kind: str | None = None, client=None):
        """Add a point of `kind` (default: the click mode) where the ray meets the cell; returns the Evaluation
        or None (a message says why)."""
        kind = kind or self.ctx.state.click_mode
        if kind is None:
            return None  # clicks select: nothing to add
        try:  # what a tab sends is data: a ray of 3 finite numbers each, a direction that is not zero
            origin, direction = (np.asarray(v, float).reshape(3) for v in (origin, direction))
            usable = bool(np.all(np.isfinite(origin)) and np.all(np.isfinite(direction)) and np.any(direction))
        except (TypeError, ValueError):
            usable = False
        if not usable:
            self.ctx.message(
                "the click's ray is not a ray (not finite numbers): nothing added", client, title="Not added"
            )
            return None
        with self.ctx.lock:
            hit = surface_hit(self.ctx.loaded.mesh, origin, direction)
            if hit is None:
                self.ctx.message(
                    "the click did not meet the cell's mesh: click on a surface", client, title="Not added"
                )
                return None
            if kind == "registration":
                hit = hit + [0.0, 0.0, REGISTRATION_LIFT_MM]
            before = set(self._ids(kind))
            ev = self._author(
                lambda s: edits.add_point(s, kind, hit, region_mm=self.ctx.state.target_region_mm), client
            )
            if ev is None:
                return None
            new = [p for p in self._ids(kind) if p not in before]
            word = dict((k, w) for w, k in CLICK_MODES)[kind]
            where = ", ".join(f"{v + 0.0:.1f}" for v in np.round(hit, 1))  # no "-0.0"
            self.ctx.message(f"Added {word} {new[0]} at ({where}) mm", client, title="Added", error=False)
            if kind in ("targets", "fiducials"):  # the new point is selected: its card shows it, its handle moves it
                # in the view of the tab that added it, beside the panel (the camera keeps its direction)
                self.ctx.camera.keep_in_view(hit, self.ctx.views.work_points(), None if client is None else [client])
                self.ctx.views.select(kind, new[0], client=client)
            return ev

    def _ids(self, kind: str) -> tuple:
        if kind == "candidates":
            return tuple(self.ctx.session.candidates.ids)
        return tuple(self.ctx.session.layout[kind].ids)

    def delete_selected(self, client=None):
        """Delete the selected point."""
        with self.ctx.lock:
            if self.ctx.state.selected is None:
                self.ctx.message("select a point first (click it)", client, title="Nothing deleted")
                return None
            kind, pid = self.ctx.state.selected
            self.ctx.state.selected = None
            return self._author(lambda s: edits.remove_point(s, kind, pid), client)

    def undo(self, client=None):
        return self._author(lambda s: edits.undo(s), client)

    def redo(self, client=None):
        return self._author(lambda s: edits.redo(s), client)

    def move_sensor(self, position, client=None):
        return self._author(lambda s: edits.move_sensor(s, position), client)

    def apply_edit(self, change, client=None):
        """A structural edit `change(session) -> Evaluation` made elsewhere (the Plan tab using a plan's fiducials):
        applied and redrawn as this tab's own edits are; None and a message when refused."""
        return self._author(change, client)

    def _author(self, change, client):
        """Apply a structural edit to the session and redraw the scene (points were added or removed)."""
        with self.ctx.lock:
            try:
                ev = change(self.ctx.session)
            except InputError as exc:
                self.ctx.message(str(exc), client, title="Not done")
                return None
            if self.ctx.state.selected is not None:
                kind, pid = self.ctx.state.selected
                ids = ev.targets.ids if kind == "targets" else ev.fiducial_ids if kind == "fiducials" else ()
                if pid not in ids:
                    self.ctx.state.selected = None
            self.redraw(ev)
        self.ctx.montecarlo.request()
        return ev

    def redraw(self, ev) -> None:
        """Rebuild the scene's nodes for the session as it is now (caller holds the lock)."""
        with self.ctx.server.atomic():
            self.ctx.present.build_scene(ev)
            self.ctx.present.show(ev, heat=True)
            self.sync_history()

    def sync_history(self) -> None:
        """Undo and Redo (File tab) and the Plan tab's Undo offered as the session's edit history allows."""
        session = self.ctx.session
        self.ctx.controls.sync_authoring(edits.can_undo(session), edits.can_redo(session))
        self.ctx.planning.sync_undo(edits.can_undo(session))

    def upload_mesh(self, name: str, content: bytes, client=None) -> bool:
        """Use an uploaded mesh (any format trimesh reads; robot frame, mm) as the cell's mesh: it is drawn, clicks
        land on it, and a saved scene refers to it (kept in a temporary directory of this server; save the mesh
        beside the downloaded scene)."""
        with tempfile.TemporaryDirectory(prefix="rrbc-upload-") as tmp:
            src = Path(tmp) / sources.safe_file_name(name, Path(str(name)).suffix.lower() or ".stl")
            src.write_bytes(content)
            return self.upload_mesh_file(name, src, client)

    def upload_mesh_file(self, name: str, path, client=None) -> bool:
        """`upload_mesh` of a file already on this server's disk (the upload button writes it there as it arrives,
        `upload_spool`): it is moved into a temporary folder of its own, under the user's file name."""
        from rrbc_core.authoring.cell_geometry import load_cell_mesh

        suffix = Path(str(name)).suffix.lower()
        src = Path(path)
        if suffix not in (".stl", ".obj", ".ply", ".glb", ".gltf", ".3mf", ".off"):
            self.ctx.message(f"{name}: not a mesh file (STL, OBJ, PLY, GLB, 3MF)", client, title="Upload refused")
            return False
        with self.ctx.lock:
            d = Path(tempfile.mkdtemp(prefix="rrbc-mesh-"))
            path = d / sources.safe_file_name(name, suffix)  # the user's own name: a saved scene names it so
            shutil.move(str(src), path)
            try:
                mesh = load_cell_mesh(path)
            except InputError as exc:
                shutil.rmtree(d, ignore_errors=True)
                release_memory()  # what reading it took before the refusal
                self.ctx.message(str(exc).replace(str(path), str(name)), client, title="Upload refused")
                return False
            self.ctx.loaded = sources.Loaded(self.ctx.loaded.session, mesh, self.ctx.loaded.label)
            if self.uploaded_mesh is not None:  # the mesh it replaces: its temporary copy goes
                shutil.rmtree(self.uploaded_mesh.parent, ignore_errors=True)
            self.uploaded_mesh = path
            if self.ctx.session.kind == "scene":  # the cell is now this mesh's: it carries its name
                self.ctx.session.name = path.stem
            self.redraw(self.ctx.session.last)
        release_memory()  # the mesh it replaced and the reading's buffers: back to the OS (issue 42)
        self.ctx.message(f"{name}: the cell's mesh now ({len(mesh.faces)} triangles)", client, error=False)
        return True

    def new_cell_from_mesh(self, client=None, confirmed: bool = False) -> bool:
        """*New cell from this mesh*: an empty start on the cell's mesh (the uploaded one, else the scene's) -
        `rrbc_core.authoring.scene_new.empty_scene`: one target where the arm can work, registration points over it,
        candidate locations around it, no fiducials - opened as the session (asks first if edits are unsaved), the
        camera framed on the whole cell. The scene and a copy of the mesh live in a temporary folder of this server
        until the user saves the scene."""
        from rrbc_core.authoring.scene_new import NewSceneOptions, empty_scene

        session = self.ctx.session
        scene = getattr(session, "scene", None)
        mesh = self.uploaded_mesh or (
            Path(session.mesh_path) if session.kind == "scene" and session.mesh_path else None
        )
        if scene is None or mesh is None:
            self.ctx.message("open a scene or upload a cell mesh first", client, title="No new cell")
            return False
        if not confirmed and self.ctx.files.ask_discard_unsaved(
            f"a new cell on {mesh.name}", lambda: self.new_cell_from_mesh(client, confirmed=True), client
        ):
            return False
        robot = scene.robot_model if scene.robot_model in ("ur5", "ur10") else "none"
        opts = NewSceneOptions(robot=robot, tool_mm=float(scene.tool_mm), sensor_kind=scene.sensor_kind, name=mesh.stem)
        d = Path(tempfile.mkdtemp(prefix="rrbc-mesh-"))
        try:
            made = empty_scene(mesh, d / f"{sources.slug(mesh.stem)}.toml", opts)
            loaded = sources.load_source(made.path)
        except InputError as exc:
            shutil.rmtree(d, ignore_errors=True)
            self.ctx.message(str(exc).replace(str(mesh), mesh.name), client, title="No new cell")
            return False
        except Exception as exc:  # noqa: BLE001 - keep serving; say what failed
            shutil.rmtree(d, ignore_errors=True)
            self.ctx.message(f"{mesh.name}: no new cell: {type(exc).__name__}", client, title="No new cell")
            return False
        loaded = sources.Loaded(loaded.session, loaded.mesh, f"a new cell on {mesh.name}")
        old = self.uploaded_mesh
        self.uploaded_mesh = d / Path(loaded.session.mesh_path).name  # the copy beside the new scene
        self.ctx.install(loaded)
        if old is not None:
            shutil.rmtree(old.parent, ignore_errors=True)
        self.ctx.views.show_camera("whole cell")
        target = loaded.session.last.targets.positions[0]
        self.ctx.message(
            f"A new cell on {mesh.name}: one target T1 at ({', '.join(f'{v + 0.0:.0f}' for v in target)}) mm, "
            f"{len(loaded.session.last.registration_positions)} registration points, no fiducials (RRBC equals "
            "rigid until you add some). Add fiducials and targets (Click on the cell adds), then Save scene.",
            client,
            title="New cell",
            error=False,
        )
        return True

    def forget_upload_unless_used(self, mesh_path) -> None:
        """A new source was opened: the uploaded mesh's temporary copy goes unless it is that source's mesh (a saved
        scene must not name a mesh of an earlier cell)."""
        up = self.uploaded_mesh
        if up is not None and (mesh_path is None or Path(mesh_path).resolve() != up.resolve()):
            self.remove_upload()

    def remove_upload(self) -> None:
        """Remove the uploaded mesh's temporary copy (the app stops)."""
        if self.uploaded_mesh is not None:
            shutil.rmtree(self.uploaded_mesh.parent, ignore_errors=True)
            self.uploaded_mesh = None

    def export_authoring(self, what: str) -> list[tuple[str, bytes]]:
        """Files of "scene" (the session as a scene TOML), "plan" (the measurement plan CSV) or "slicer" (two
        markups files of the current data)."""
        from rrbc_core.io.slicer_markups import to_markups

        with self.ctx.lock:
            slug = sources.slug(self.ctx.session.name)
            if what == "scene":
                mesh = self.uploaded_mesh
                text = edits.scene_toml(self.ctx.session, mesh=mesh.name if mesh is not None else None)
                return [(f"{slug}.toml", text.encode("utf-8"))]
            if what == "plan":
                return [(f"{slug}-measurement-plan.csv", edits.measurement_plan(self.ctx.session).encode("utf-8"))]
            if what == "slicer":
                sensor, robot = to_markups(figures.export_measurements(self.ctx.session))
                return [
                    (f"{slug}_sensor.mrk.json", (json.dumps(sensor, indent=1) + "\n").encode("utf-8")),
                    (f"{slug}_robot.mrk.json", (json.dumps(robot, indent=1) + "\n").encode("utf-8")),
                ]
        raise InputError(f"unknown export '{what}': scene, plan or slicer")

    def download_authoring(self, what: str, client=None) -> list[tuple[str, bytes]] | None:
        try:
            out = self.export_authoring(what)
        except (InputError, ValueError) as exc:
            self.ctx.message(str(exc), client, title="Export failed")
            return None
        for name, content in out:  # saved at once under their full names (not links in a notification)
            (client or self.ctx.server).send_file_download(name, content, save_immediately=True)
        if what == "scene":
            edits.mark_saved(self.ctx.session)
            mesh = self.uploaded_mesh.name if self.uploaded_mesh is not None else Path(self.ctx.session.mesh_path).name
            self.ctx.message(
                f"Saved {out[0][0]}: keep the mesh {mesh} beside it (the scene names it)", client, title="Saved",
                error=False,
            )  # fmt: skip
        return out
