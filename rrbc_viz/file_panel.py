"""The File tab (`FilePanel`): open one of the files offered (the scenes folder and the folders named on the command
line: no free-text server path), or upload one; download the data or the results; the stations of a file with a
`group` column. Built inside its tab by `controls.Controls`; handed the app as `actions.Actions`."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import viser

from rrbc_core.io.measurements import FILE_LIMIT_BYTES

from . import upload_spool

if TYPE_CHECKING:
    from .actions import Actions

NO_MESH = "(no mesh)"
NO_STATION = "(no stations)"


class FilePanel:
    """File tab: open one of the files offered (scenes/ and the folders named on the command line: no free-text
    server path), or upload one; download the data or the results."""

    def __init__(self, gui, app: Actions):
        self.gui = gui
        self.confirm_yes: viser.GuiButtonHandle | None = None  # the last question's buttons (`confirm`)
        self.confirm_keep: viser.GuiButtonHandle | None = None
        self._showing = False  # show_stations is setting the Station menu: not a user's choice
        self.path = gui.add_dropdown(
            "Scene or data file", ("",), initial_value="", hint="Files in scenes/ and in the folders given by --data"
        )
        self.mesh_path = gui.add_dropdown("Mesh (for .csv, optional)", (NO_MESH,), initial_value=NO_MESH)
        self.load = gui.add_button("Load file", icon=viser.Icon.FILE)
        self.rescan = gui.add_button("Rescan folders", icon=viser.Icon.REFRESH)
        self.upload = gui.add_upload_button("Upload CSV or TOML", icon=viser.Icon.UPLOAD)
        gui.add_markdown(
            "Only files in the bundled scenes/ and in folders named with `rrbc view --data DIR` can be opened here; "
            "anything else: upload it. An uploaded scene cannot bring its mesh along."
        )
        self.station = gui.add_dropdown(
            "Station",
            (NO_STATION,),
            initial_value=NO_STATION,
            hint="The file has a group column: each station is registered and corrected on its own",
            visible=False,
        )
        self.download_csv = gui.add_button("Download data (CSV)", icon=viser.Icon.DOWNLOAD)
        self.download_json = gui.add_button("Download results (JSON)", icon=viser.Icon.DOWNLOAD)
        self.download_corrected = gui.add_button(
            "Download corrected targets (CSV)",
            icon=viser.Icon.DOWNLOAD,
            hint="What `rrbc correct DATA.csv --out corrected.csv` writes for the data above: each target's and "
            "check's corrected robot position, its 95 % bound and whether it is extrapolated",
        )
        self.report_tolerance = gui.add_number(
            "Report tolerance (mm)", 0.0, min=0.0, step=0.01, hint="The acceptance report's tolerance; 0: none"
        )
        self.download_report = gui.add_button(
            "Download report (HTML)",
            icon=viser.Icon.DOWNLOAD,
            hint="What `rrbc report DATA.csv --out report.html` writes for the data above (least squares, this "
            "interpolation with its default options): every method, every point, a verdict against the tolerance",
        )

        @self.load.on_click
        def _(event: viser.GuiEvent) -> None:
            mesh = self.mesh_path.value
            app.files.load_offered(self.path.value, None if mesh == NO_MESH else mesh, client=event.client)

        self.rescan.on_click(lambda event: app.files.rescan_files())

        @self.station.on_update
        def _(event: viser.GuiEvent) -> None:
            if self.station.value != NO_STATION and not self._showing:
                app.files.load_station(self.station.value, client=event.client)

        # written to disk as it arrives and refused from its declared size before anything is kept (upload_spool)
        upload_spool.spool(
            gui,
            self.upload,
            FILE_LIMIT_BYTES,
            on_file=lambda client, name, path: app.files.load_upload(name, path.read_bytes(), client=client),
            on_refused=lambda client, why: app.files.upload_refused(why, client=client),
        )

        self.download_csv.on_click(lambda event: app.files.download("csv", client=event.client))
        self.download_json.on_click(lambda event: app.files.download("json", client=event.client))
        self.download_corrected.on_click(lambda event: app.files.download("corrected", client=event.client))

        @self.download_report.on_click
        def _(event: viser.GuiEvent) -> None:
            tol = self.report_tolerance.value  # this panel's own widget, passed with the action
            app.files.download("report", client=event.client, tolerance_mm=tol if tol and tol > 0 else None)

    def confirm(self, title: str, text: str, yes: str, on_yes: Callable[[], object]) -> None:
        """Ask before an action that discards something (a modal: `yes` runs `on_yes`, "Keep editing" closes)."""
        with self.gui.add_modal(title) as modal:
            self.gui.add_markdown(text)
            go = self.gui.add_button(yes, color="red")
            keep = self.gui.add_button("Keep editing")

        def _yes(event: viser.GuiEvent) -> None:
            modal.close()
            on_yes()

        go.on_click(_yes)
        keep.on_click(lambda event: modal.close())
        self.confirm_yes, self.confirm_keep = go, keep  # the question last asked

    def show_stations(self, stations: tuple[str, ...], current: str | None) -> None:
        """The Station menu: shown with the file's stations when it has a group column, hidden otherwise."""
        self._showing = True
        try:
            self.station.options = tuple(stations) or (NO_STATION,)
            self.station.value = current if current in stations else self.station.options[0]
            self.station.visible = bool(stations)
        finally:
            self._showing = False

    def offer(self, sources: list[str], meshes: list[str]) -> None:
        """The files the tab offers (labels)."""
        self.path.options = tuple(sources) or ("",)
        if self.path.value not in self.path.options:
            self.path.value = self.path.options[0]
        self.mesh_path.options = (NO_MESH, *meshes)
        if self.mesh_path.value not in self.mesh_path.options:
            self.mesh_path.value = NO_MESH
