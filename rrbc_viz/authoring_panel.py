"""File tab → "Edit the cell": what a click on the cell adds, delete, undo/redo, move the sensor, upload a mesh, and
the downloads that author a cell (scene file, measurement plan, Slicer markups). Forwards to the app
(`controllers.edit.AuthoringController`); holds no state of its own."""

from __future__ import annotations

from typing import TYPE_CHECKING

import viser

from rrbc_core.io.mesh_file import MESH_MAX_BYTES, refuse_from_header

from . import upload_spool
from .syncing import clamped

if TYPE_CHECKING:
    from .actions import Actions


#: What a click on the cell adds: (label, point kind or None for selecting).
CLICK_MODES = (
    ("nothing (select)", None),
    ("registration point", "registration"),
    ("fiducial", "fiducials"),
    ("target", "targets"),
    ("candidate", "candidates"),
)
REGISTRATION_LIFT_MM = 100.0  # a registration point goes this far above the clicked surface


class AuthoringPanel:
    def __init__(self, gui, app: Actions):
        with gui.add_folder("Edit the cell"):
            self.mode = gui.add_dropdown("Click on the cell adds", tuple(k for k, _ in CLICK_MODES))
            self.mode_md = gui.add_markdown("Clicks **select** points.")
            self.region = gui.add_slider("Target region (mm)", 0.5, 50.0, 0.5, 4.0)
            gui.add_markdown(
                f"Points land where you click on the mesh (registration points {REGISTRATION_LIFT_MM:g} mm above it, "
                "in free space). Robot frame, mm."
            )
            self.delete = gui.add_button("Delete selected point", icon=viser.Icon.TRASH)
            self.undo = gui.add_button("Undo", icon=viser.Icon.ARROW_BACK_UP, disabled=True)
            self.redo = gui.add_button("Redo", icon=viser.Icon.ARROW_FORWARD_UP, disabled=True)
            self.sensor = gui.add_vector3("Sensor at (mm)", (1100.0, -450.0, 1250.0), step=10.0)
            self.move_sensor = gui.add_button("Move the sensor there")
            self.mesh = gui.add_upload_button("Upload cell mesh", icon=viser.Icon.UPLOAD)
            self.new_cell = gui.add_button(
                "New cell from this mesh",
                icon=viser.Icon.FILE_PLUS,
                hint="An empty start on the cell's mesh: one target, registration points over it, no fiducials",
            )
            self.save_scene = gui.add_button("Save scene (TOML)", icon=viser.Icon.DOWNLOAD)
            self.plan = gui.add_button("Measurement plan (CSV)", icon=viser.Icon.DOWNLOAD)
            self.slicer = gui.add_button("Slicer markups (2 files)", icon=viser.Icon.DOWNLOAD)

        def on_mode(event: viser.GuiEvent) -> None:
            app.authoring.set_click_mode(dict(CLICK_MODES)[self.mode.value], clamped(self.region))

        self.mode.on_update(on_mode)
        self.region.on_update(on_mode)
        self.delete.on_click(lambda event: app.authoring.delete_selected(client=event.client))
        self.undo.on_click(lambda event: app.authoring.undo(client=event.client))
        self.redo.on_click(lambda event: app.authoring.redo(client=event.client))
        self.move_sensor.on_click(lambda event: app.authoring.move_sensor(self.sensor.value, client=event.client))
        self.new_cell.on_click(lambda event: app.authoring.new_cell_from_mesh(client=event.client))
        self.save_scene.on_click(lambda event: app.authoring.download_authoring("scene", client=event.client))
        self.plan.on_click(lambda event: app.authoring.download_authoring("plan", client=event.client))
        self.slicer.on_click(lambda event: app.authoring.download_authoring("slicer", client=event.client))

        # written to disk as it arrives, refused from its size and header before the rest is kept (upload_spool)
        upload_spool.spool(
            gui,
            self.mesh,
            MESH_MAX_BYTES,
            on_file=lambda client, name, path: app.authoring.upload_mesh_file(name, path, client=client),
            on_refused=lambda client, why: app.files.upload_refused(why, client=client),
            check=refuse_from_header,
        )

    def show_mode(self, markdown: str) -> None:
        """What a click on the cell does now."""
        self.mode_md.content = markdown

    def sync(self, can_undo: bool, can_redo: bool, scene: bool, sensor=None) -> None:
        if sensor is not None:
            self.sensor.value = tuple(float(round(v, 1)) for v in sensor)
        self.undo.disabled = not can_undo
        self.redo.disabled = not can_redo
        for w in (
            self.mode,
            self.mode_md,
            self.region,
            self.delete,
            self.undo,
            self.redo,
            self.sensor,
            self.move_sensor,
        ):
            w.visible = scene
        self.save_scene.visible = self.plan.visible = self.new_cell.visible = scene
