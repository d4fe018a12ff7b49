"""The File tab's actions (`FileController`): open a scene or measurement file (one the tab offers, or an upload),
and export the session's data (the CSV that `rrbc diagnose` and `rrbc correct` read) and results (the JSON of
`rrbc correct`). A file that does not load leaves the current session and says why."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from rrbc_core.errors import InputError
from rrbc_core.session import edits, figures

from .. import sources

if TYPE_CHECKING:
    from ..context import AppContext


class FileController:
    """`actions.FileActions` (module docstring)."""

    def __init__(self, ctx: AppContext):
        self.ctx = ctx

    # --------------------------------------------------------------------------------------------- files
    def ask_discard_unsaved(self, what: str, again, client) -> bool:
        """True (and a question asked) when the session has edits not saved as a scene: `again()` runs once the user
        agrees to discard them."""
        if not edits.has_unsaved_edits(self.ctx.session):
            return False
        self.ctx.controls.file.confirm(
            "Unsaved edits",
            f"The cell **{self.ctx.session.name}** has edits that are not saved (File → Save scene). Opening "
            f"{what} discards them.",
            "Discard the edits and open",
            again,
        )
        return True

    def load(self, source=None, mesh=None, client=None, confirmed: bool = False) -> bool:
        """Open a scene (.toml) or measurement file (.csv; optional mesh). On bad input the current session
        stays and a message says why; returns whether the file was loaded. A session with unsaved edits asks first
        (`confirmed`: the user agreed)."""
        if not confirmed and self.ask_discard_unsaved(
            str(getattr(source, "name", source) or "the default scene"),
            lambda: self.load(source, mesh, client, confirmed=True),
            client,
        ):
            return False
        try:
            loaded = sources.load_source(source, mesh)
        except InputError as exc:
            self.ctx.message(str(exc), client, title="File not loaded")
            return False
        except Exception as exc:  # noqa: BLE001 - e.g. OSError: keep serving
            self.ctx.message(f"{source}: cannot open: {type(exc).__name__}: {exc}", client, title="File not loaded")
            return False
        self.ctx.install(loaded)
        return True

    def load_offered(self, label: str, mesh_label: str | None = None, client=None) -> bool:
        """Open one of the files the File tab offers (`sources.Library`), by its label; anything else is refused."""
        try:
            path = self.ctx.library.pick(label)
            mesh = None if mesh_label is None else self.ctx.library.pick(mesh_label, meshes=True)
        except InputError as exc:
            self.ctx.message(str(exc), client, title="File not loaded")
            return False
        return self.load(path, mesh=mesh, client=client)

    def rescan_files(self) -> None:
        """List the offered folders' files again in the File tab."""
        with self.ctx.lock:
            self.ctx.controls.file.offer(
                [name for name, _ in self.ctx.library.sources()], [name for name, _ in self.ctx.library.meshes()]
            )
            for tab in self.ctx.tabs.values():
                tab.files_offered()

    def load_station(self, station: str, client=None) -> bool:
        """Open another station of the current file (a file with a group column); the settings are kept."""
        with self.ctx.lock:
            if station == self.ctx.session.station:
                return True
            try:
                loaded = sources.load_station(self.ctx.loaded, station)
            except InputError as exc:
                self.ctx.message(str(exc), client, title="Station not opened")
                return False
        self.ctx.install(loaded)
        return True

    def load_upload(self, name: str, content: bytes, client=None, confirmed: bool = False) -> bool:
        if not confirmed and self.ask_discard_unsaved(
            str(name), lambda: self.load_upload(name, content, client, confirmed=True), client
        ):
            return False
        try:
            loaded = sources.load_upload(name, content)
        except InputError as exc:
            self.ctx.message(str(exc), client, title="Upload not loaded")
            return False
        except Exception as exc:  # noqa: BLE001
            self.ctx.message(f"{name}: cannot open: {type(exc).__name__}: {exc}", client, title="Upload not loaded")
            return False
        self.ctx.install(loaded)
        return True

    def upload_refused(self, why: str, client=None) -> None:
        """An upload refused before it was parsed (`upload_spool`: too large, or its header says too much)."""
        self.ctx.message(why, client, title="Upload refused")

    def export(self, what: str, tolerance_mm: float | None = None) -> tuple[str, bytes]:
        """(file name, content) of "csv" (figures.export_measurements(session) as a measurement file), "json"
        (figures.export_json(session)), "corrected" (figures.export_corrected: `rrbc correct --out`'s CSV) or "report"
        (the HTML of `rrbc report` on the "csv" file, `tolerance_mm` its --tolerance; computed outside the lock)."""
        if what == "report":
            from rrbc_core.analysis.acceptance_html import report_html

            with self.ctx.lock:
                slug = sources.slug(self.ctx.session.name)
                mset = figures.export_measurements(self.ctx.session)
                options = figures.report_options(self.ctx.session)
            acc = figures.export_report(mset, options, tolerance_mm)
            return f"rrbc-{slug}-report.html", report_html(acc).encode("utf-8")
        with self.ctx.lock:
            slug = sources.slug(self.ctx.session.name)
            if what == "corrected":
                return f"rrbc-{slug}-corrected.csv", figures.export_corrected(self.ctx.session).encode("utf-8")
            if what == "csv":
                s = self.ctx.session.settings
                text = sources.measurements_csv(
                    figures.export_measurements(self.ctx.session),
                    comments=[
                        f"exported by the rrbc browser app from {self.ctx.session.name}",
                        f"settings: registration {s.registration}, interpolation {s.interpolation}, noise x{s.noise_scale:g}, "
                        f"bias x{s.bias_scale:g}, seed {s.seed}",
                    ],
                )
                return f"rrbc-{slug}.csv", text.encode("utf-8")
            if what == "json":
                return f"rrbc-{slug}-results.json", (
                    json.dumps(figures.export_json(self.ctx.session), indent=2) + "\n"
                ).encode("utf-8")
        raise InputError(f"unknown export '{what}': csv, json, corrected or report")

    def download(self, what: str, client=None, tolerance_mm: float | None = None) -> tuple[str, bytes] | None:
        """Send an export to `client` (every tab if None) as a file download (`export`)."""
        try:
            name, content = self.export(what, tolerance_mm)
        except (InputError, ValueError) as exc:
            self.ctx.message(str(exc), client, title="Export failed")
            return None
        # saved at once under its full name (not a link in a notification)
        (client or self.ctx.server).send_file_download(name, content, save_immediately=True)
        return name, content
