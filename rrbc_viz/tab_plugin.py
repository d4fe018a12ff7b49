"""A tab of the control panel as a plug-in: its panel, its controller and one entry in the app's list (`tabs.TABS`).

A new tab touches three files: its panel's module (the panel class, and the protocol of what it asks of its
controller), its controller's module (in `controllers/`, a `TabController`), and `tabs.py` (one `TabSpec`). The
control panel (`controls.Controls`) lays the tab out among the others and builds its panel; the app
(`app.RunningApp`) builds its controller, handing it the context and its own panel; the other controllers reach it
only through the hooks below, which the app calls at the moments they name. The panel is built before its
controller (views first, then controllers), so it is handed a function that returns its controller when the user
acts.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Generic, TypeVar

if TYPE_CHECKING:
    from rrbc_core.session.evaluation import Evaluation

    from .context import AppContext

P = TypeVar("P")


class TabController(Generic[P]):
    """A plug-in tab's controller over the app's context and its own panel (`panel`, of type P); it implements
    `actions.TabHooks`, whose hooks do nothing here unless overridden. Every hook but `stop` is called with the app's
    lock held, inside one `server.atomic()` block."""

    def __init__(self, ctx: AppContext, panel: P):
        self.ctx = ctx
        self.panel = panel

    def installed(self) -> None:
        """A source became the current one (a file, a station, a scene): forget what was shown for the last."""

    def evaluated(self, ev: Evaluation) -> None:
        """An evaluation of the current session was shown (a drag, a setting, an edit)."""

    def display_changed(self) -> None:
        """The display options changed (magnification, marker size, …)."""

    def files_offered(self) -> None:
        """The folders the app offers files from were listed again."""

    def stop(self) -> None:
        """The app stops: end any work of this tab's own (no lock held)."""


@dataclass(frozen=True)
class TabSpec:
    """One plug-in tab. `name` is how tests and scripts reach it (`RunningApp.tabs[name]` its controller,
    `Controls.tabs[name]` its panel); `label` and `icon` (a `viser.Icon` name) what the tab bar shows.
    `panel(gui, controller)` builds the panel inside its tab, handed a function returning its controller;
    `controller(ctx, panel)` builds the controller once the context exists."""

    name: str
    label: str
    icon: str
    panel: Callable[[Any, Callable[[], Any]], Any]
    controller: Callable[[AppContext, Any], TabController[Any]]
