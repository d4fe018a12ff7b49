"""The Model tab (`ModelCheckController`): `rrbc check-model` in the app. The open scene's error model is held against
a measurement file the app offers (`analysis.scene_check.check_scene_model`, run outside the app's lock: seconds);
the tab shows the command's own lines (`analysis.scene_check_text.check_lines`), the scene shows each compared row
inside or outside its predicted region (`model_check_nodes`); *Extend the model* installs the scene with the added
terms and checks it again against the same file; the download is the scene's own text with the terms appended, as
`rrbc check-model --out` writes it. A plug-in tab (`tab_plugin`, listed in `tabs.TABS`)."""

from __future__ import annotations

import dataclasses
import traceback
from pathlib import Path

from rrbc_core.analysis.scene_check import SceneCheck, check_scene_model
from rrbc_core.analysis.scene_check_text import check_lines
from rrbc_core.errors import InputError
from rrbc_core.io.measurements import read_measurements
from rrbc_core.io.scene_extend import extended_scene_text

from .. import model_check_panel
from ..model_check_panel import ModelCheckPanel
from ..sources import scene_loaded
from ..tab_plugin import TabController

TRIALS = 200
FOLDS = 5


class ModelCheckController(TabController[ModelCheckPanel]):
    """`model_check_panel.ModelCheckTabActions`: what it shows is in the app's state (`model_check`,
    `model_check_file`, `model_check_head`)."""

    def installed(self) -> None:
        """Nothing checked (a new source), unless an extension is being loaded (`extend` sets the head)."""
        st = self.ctx.state
        st.model_check, st.model_check_scene_text = None, None
        self.ctx.check_node.hide()
        self.panel.show(model_check_panel.PROMPT if self.ctx.session.kind == "scene" else model_check_panel.NOT_A_SCENE)

    def files_offered(self) -> None:
        """The measurement files the tab offers (caller holds the lock)."""
        self.panel.offer([name for name, path in self.ctx.library.sources() if path.suffix.lower() == ".csv"])

    def run(self, label: str, client=None, head: str = "") -> SceneCheck | None:
        """Check the open scene's model against the offered file `label`; None (and the reason shown) on bad input."""
        with self.ctx.lock:
            session = self.ctx.session
            scene = session.scene if session.kind == "scene" else None
        if scene is None:
            self.panel.show(model_check_panel.NOT_A_SCENE)
            return None
        result, text = None, ""
        try:
            path = self.ctx.library.pick(label)
            result = check_scene_model(read_measurements(path), scene, trials=TRIALS, folds=FOLDS)
        except InputError as exc:
            text = f"⚠ Not checked: {' '.join(str(exc).split())}"
        except Exception as exc:  # noqa: BLE001 - keep serving
            traceback.print_exc()
            text = f"⚠ Not checked: internal error: {type(exc).__name__}: {exc}"
        with self.ctx.lock:
            if self.ctx.session is not session:  # another source was loaded meanwhile
                return None
            st = self.ctx.state
            st.model_check, st.model_check_file = result, label
            extended = st.model_check_scene_text is not None
            if result is not None:
                scene_name = Path(str(getattr(scene, "path", "") or session.name)).name
                if extended:
                    scene_name = f"{scene_name} as extended here"
                lines = check_lines(result, Path(label).name, scene_name, hints=model_check_panel.APP_HINTS)
                text = model_check_panel.render(result, lines, head)
            with self.ctx.server.atomic():
                added = result is not None and bool(result.added)
                self.panel.show(text, extendable=added, downloadable=added or extended)
                self.show_rows()
        if result is None:
            self.ctx.message("the model was not checked: see the Model tab", client, title="Not checked")
        return result

    def display_changed(self) -> None:
        self.show_rows()

    def show_rows(self) -> None:
        """Draw the compared rows (caller holds the lock)."""
        st = self.ctx.state
        r = st.model_check
        if r is None:
            self.ctx.check_node.hide()
            return
        from rrbc_core.analysis.scene_check import Z95

        self.ctx.check_node.show(r.points_mm, r.misfit_mm, r.z > Z95, st.display.marker_mm, st.display.magnification)

    def extend(self, client=None) -> SceneCheck | None:
        """Install the scene with the terms the last check added, then check it against the same file; the tab keeps
        the first check's out-of-sample gain at its head."""
        with self.ctx.lock:
            r, label = self.ctx.state.model_check, self.ctx.state.model_check_file
            session = self.ctx.session
            if r is None or not r.added or r.extended_model is None or session.kind != "scene":
                self.ctx.message("nothing to extend: check the model first", client, title="Not extended")
                return None
            scene = dataclasses.replace(session.scene, error_model=r.extended_model)
            try:
                text = self._scene_text(r, label)
            except (InputError, OSError):
                text = None  # a scene without a file (an uploaded one): the extension is not downloadable
            g = r.gain
            head = (
                f"**Extended model loaded** ({', '.join(t.table['type'] for t in r.added)} added). Out of sample "
                f"({g['folds']} folds by {g['fold_by']}) the extension predicts the held-out rows with "
                f"{g['prediction_error_before_mm']:.3g} → {g['prediction_error_after_mm']:.3g} mm error, "
                f"{100 * g['coverage_before']:.0f} % → {100 * g['coverage_after']:.0f} % inside their region. The "
                "same file checked against it:"
            )
        self.ctx.install(scene_loaded(scene, f"scene {scene.name} (extended by check-model)"))
        with self.ctx.lock:
            self.ctx.state.model_check_scene_text = text
        return self.run(label, client, head=head)

    def _scene_text(self, r: SceneCheck, label: str) -> str:
        """The open scene's text (its file's, or the extended text it was loaded from) with `r`'s terms appended
        (caller holds the lock)."""
        scene = self.ctx.session.scene
        text = self.ctx.state.model_check_scene_text
        if text is None:
            if getattr(scene, "path", None) is None:
                raise InputError("this scene has no file to extend")
            text = Path(scene.path).read_text(encoding="utf-8")
        if not r.added:
            return text
        header = f"error terms added by rrbc check-model from {Path(label).name} (the app, seed 0)"
        return extended_scene_text(text, [(t.table, t.comment) for t in r.added], header)

    def extended_text(self) -> tuple[str, bytes]:
        """(file name, content) of the scene extended by the last check (its text with the terms appended, as
        `rrbc check-model --out` writes it), or of the extended scene the tab loaded."""
        with self.ctx.lock:
            r, label = self.ctx.state.model_check, self.ctx.state.model_check_file
            loaded = self.ctx.state.model_check_scene_text is not None
            if r is None or not (r.added or loaded) or self.ctx.session.kind != "scene":
                raise InputError("nothing to download: check a scene's model against a file first")
            text = self._scene_text(r, label)
            stem = Path(str(getattr(self.ctx.session.scene, "path", None) or "scene")).stem
        return f"{stem}-extended.toml", text.encode("utf-8")

    def download(self, client=None) -> tuple[str, bytes] | None:
        try:
            name, content = self.extended_text()
        except (InputError, OSError) as exc:
            self.ctx.message(str(exc), client, title="Not downloaded")
            return None
        (client or self.ctx.server).send_file_download(name, content, save_immediately=True)
        return name, content
