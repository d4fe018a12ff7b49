"""The Diagnose tab (`DiagnoseController`): `rrbc diagnose` on the session's data set (`session.data_set`: the file as
opened or edited, or the scene's simulated data set as the CSV download writes it), run outside the app's lock, its
lines shown as the command prints them (`diagnosis_panel`), and marked stale when the data change. A plug-in tab
(`tab_plugin`, listed in `tabs.TABS`)."""

from __future__ import annotations

import traceback
from typing import TYPE_CHECKING

from rrbc_core.analysis.diagnosis import Diagnosis
from rrbc_core.errors import InputError
from rrbc_core.session import data_set
from rrbc_core.session.data_set import data_key

from .. import diagnosis_panel
from ..diagnosis_panel import DiagnosePanel
from ..tab_plugin import TabController

if TYPE_CHECKING:
    from rrbc_core.session.evaluation import Evaluation

    from ..context import AppContext


class DiagnoseController(TabController[DiagnosePanel]):
    """`diagnosis_panel.DiagnoseTabActions`: what it shows is in the app's state (`diagnosis`, `diagnosis_data`,
    `diagnosis_stale`)."""

    def __init__(self, ctx: AppContext, panel: DiagnosePanel):
        super().__init__(ctx, panel)
        self._forget()

    def _forget(self) -> None:
        st = self.ctx.state
        st.diagnosis, st.diagnosis_data, st.diagnosis_stale = None, None, False
        self._diagnosis_key: tuple | None = None
        self._diagnosis_text = ""

    def installed(self) -> None:
        """Nothing diagnosed (a new source): the tab's prompt."""
        self._forget()
        self.panel.show_prompt()

    def evaluated(self, ev: Evaluation) -> None:
        self.check_stale()

    # ------------------------------------------------------------------------------------------ diagnosis
    def run(self, client=None) -> Diagnosis | None:
        """Diagnose the session's data set (`ExplorerSession.data()`: the file as opened or edited, or the scene's
        simulated data set as the CSV download writes it) and show, in the Diagnose tab, exactly the lines
        `rrbc diagnose` prints for it. The data are taken under the lock; the diagnosis (seconds on a scene with
        an arm) runs outside it, so drags go on. Returns None (and says why in the tab) on InputError."""
        with self.ctx.lock:
            session = self.ctx.session
            key = data_key(session)
            try:
                data = data_set.session_data(session)
            except InputError as exc:
                data, error = None, str(exc)
        result, text = None, ""
        if data is not None:
            try:
                result = data.diagnose()
            except InputError as exc:
                text = diagnosis_panel.render_error(str(exc))
            except Exception as exc:  # noqa: BLE001 - keep serving
                traceback.print_exc()
                text = diagnosis_panel.render_error(f"internal error: {type(exc).__name__}: {exc}")
            else:
                text = diagnosis_panel.render(result, data)
        else:
            text = diagnosis_panel.render_error(error)
        with self.ctx.lock:
            if self.ctx.session is not session:  # another source was loaded meanwhile
                return None
            self.ctx.state.diagnosis = result
            self.ctx.state.diagnosis_data = data
            self._diagnosis_key = key
            self._diagnosis_text = text
            self.ctx.state.diagnosis_stale = False
            with self.ctx.server.atomic():
                self.panel.show(text)
            self.check_stale()  # the data changed while it ran: say so at once
        if result is None:
            self.ctx.message("diagnosis failed: see the Diagnose tab", client, title="Not diagnosed")
        return result

    def check_stale(self) -> None:
        """Mark the Diagnose tab's content stale once the data set it was computed from changed (caller holds the
        lock): a change of its key (`data_set.data_key`) — a moved or excluded point, a new seed or size — not a
        method change, which leaves the data as they are."""
        if self._diagnosis_key is None or self.ctx.state.diagnosis_stale:
            return
        if data_key(self.ctx.session) != self._diagnosis_key:
            self.ctx.state.diagnosis_stale = True
            self.panel.show(diagnosis_panel.STALE + "\n\n" + self._diagnosis_text)
