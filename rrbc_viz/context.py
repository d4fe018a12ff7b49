"""What the app's controllers share (`AppContext`): the stage they draw on, the one lock, the session, the typed view
state, the scene views and panels, and each other — by their narrow interfaces (`actions`), so a controller depends on
what it calls, never on the app.

Every controller gets the same context; the app (`app.RunningApp`) builds it and fills in the controllers. A
controller changes the session and the state only under `lock`, and sends one change's scene updates in one
`server.atomic()` block."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from rrbc_core.errors import one_line
from rrbc_core.session.explorer import ExplorerSession

from .state import AppState

if TYPE_CHECKING:
    from . import files
    from .actions import (
        AuthoringActions,
        DiagnoseActions,
        EvaluateActions,
        FileActions,
        MonteCarloActions,
        PlanActions,
        PresentActions,
        VecActions,
        ViewActions,
    )
    from .camera import CameraDirector
    from .controls import Controls
    from .nodes import SceneNodes
    from .planning_panel import PlanningPanel
    from .slice_nodes import SliceNode


@dataclass(eq=False)
class AppContext:
    """The shared services of one app (module docstring). `server` is where it draws: the viser server (every tab) or
    one tab's `stage.ClientStage`; `viser_server` the server behind it."""

    server: Any
    viser_server: Any
    loaded: files.Loaded
    library: files.Library
    lock: threading.RLock = field(default_factory=threading.RLock)
    state: AppState = field(default_factory=AppState)
    heat_samples_per_target: int = 200
    guard: Any = None  # access.AccessGuard of the server (None in tests that build an app by hand)
    # the scene's views and the panels (the app sets them once built)
    nodes: SceneNodes = None  # type: ignore[assignment]
    slice_node: SliceNode = None  # type: ignore[assignment]
    camera: CameraDirector = None  # type: ignore[assignment]
    controls: Controls = None  # type: ignore[assignment]
    planning: PlanningPanel = None  # type: ignore[assignment]
    # the controllers, by their interfaces
    evaluate: EvaluateActions = None  # type: ignore[assignment]
    present: PresentActions = None  # type: ignore[assignment]
    views: ViewActions = None  # type: ignore[assignment]
    plan: PlanActions = None  # type: ignore[assignment]
    diagnose: DiagnoseActions = None  # type: ignore[assignment]
    montecarlo: MonteCarloActions = None  # type: ignore[assignment]
    vec: VecActions = None  # type: ignore[assignment]
    authoring: AuthoringActions = None  # type: ignore[assignment]
    files: FileActions = None  # type: ignore[assignment]
    #: make a loaded source the current one (the app's `install`)
    install: Callable[..., None] = None  # type: ignore[assignment]

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
