"""What the app's controllers share (`AppContext`): the stage they draw on, the one lock, the session, the typed view
state, the scene views and panels, and each other — by their narrow interfaces (`actions`), so a controller depends on
what it calls, never on the app.

Every controller gets the same context; the app (`app.RunningApp`) builds the views first, then the context, then
the controllers (no field is filled in later). A
controller changes the session and the state only under `lock`, and sends one change's scene updates in one
`server.atomic()` block."""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from rrbc_core.errors import one_line
from rrbc_core.session.explorer import ExplorerSession

from .state import AppState

if TYPE_CHECKING:
    import viser

    from . import sources
    from .actions import (
        Actions,
        AuthoringActions,
        EvaluateActions,
        FileActions,
        MonteCarloActions,
        PlanActions,
        PresentActions,
        TabHooks,
        VecActions,
        ViewActions,
    )
    from .camera import CameraDirector
    from .controls import Controls
    from .model_check_nodes import ModelCheckNode
    from .nodes import SceneNodes
    from .planning_panel import PlanningPanel
    from .slice_nodes import SliceNode
    from .stage import Stage

    class Controllers(Actions, Protocol):
        """The app as its controllers see each other: `actions.Actions` and the presenter."""

        @property
        def present(self) -> PresentActions: ...


@dataclass(eq=False)
class AppContext:
    """The shared services of one app (module docstring). `server` is where it draws: the viser server (every tab) or
    one tab's `stage.ClientStage`; `viser_server` the server behind it. The views (scene nodes, slice, camera, the
    panels) are built before the controllers and handed in whole; the controllers are reached through `app`, the
    running app (`app.RunningApp`), by their interfaces."""

    server: Stage
    viser_server: viser.ViserServer
    loaded: sources.Loaded
    library: sources.Library
    nodes: SceneNodes
    slice_node: SliceNode
    check_node: ModelCheckNode
    camera: CameraDirector
    controls: Controls
    app: Controllers
    #: make a loaded source the current one (the app's `install`)
    install: Callable[..., None]
    lock: threading.RLock = field(default_factory=threading.RLock)
    state: AppState = field(default_factory=AppState)
    heat_samples_per_target: int = 200
    guard: Any = None  # access.AccessGuard of the server (None in tests that build an app by hand)

    @property
    def planning(self) -> PlanningPanel:
        """The Plan tab's panel."""
        return self.controls.plan

    # the controllers, by their interfaces
    @property
    def evaluate(self) -> EvaluateActions:
        return self.app.evaluate

    @property
    def present(self) -> PresentActions:
        return self.app.present

    @property
    def views(self) -> ViewActions:
        return self.app.views

    @property
    def plan(self) -> PlanActions:
        return self.app.plan

    @property
    def tabs(self) -> Mapping[str, TabHooks]:
        """The plug-in tabs' controllers by name (`tab_plugin`): reached through their hooks."""
        return self.app.tabs

    @property
    def montecarlo(self) -> MonteCarloActions:
        return self.app.montecarlo

    @property
    def vec(self) -> VecActions:
        return self.app.vec

    @property
    def authoring(self) -> AuthoringActions:
        return self.app.authoring

    @property
    def files(self) -> FileActions:
        return self.app.files

    @property
    def session(self) -> ExplorerSession:
        """The current session (replaced when a file is loaded)."""
        return self.loaded.session

    def message(self, text: str, client: Any = None, error: bool = True, title: str | None = None) -> None:
        """Show a message: a notification to `client` (every tab if None) and the status line."""
        line = one_line(str(text))
        self.state.messages.append(line)
        self.controls.show_status(("⚠ " if error else "✓ ") + line)
        targets = [client] if client is not None else list(self.server.get_clients().values())
        for c in targets:
            try:
                c.add_notification(
                    title or ("Not done" if error else "Done"),
                    line,
                    auto_close_seconds=10.0,
                    color="red" if error else "green",
                )
            except Exception:  # noqa: BLE001 - a closing tab must not break the app
                pass

    @property
    def last_message(self) -> str | None:
        return self.state.messages[-1] if self.state.messages else None
