"""The RRBC browser app: a viser server over one `rrbc_core.session.explorer.ExplorerSession`, by composition.

    from rrbc_viz.serve import serve
    app = serve()                      # bundled default scene, 127.0.0.1, a free port; returns at once
    print(app.url)
    app.evaluate.handle_drag("targets", "H1", [400, -150, 40], "end")
    app.stop()

`RunningApp` builds the shared context (`context.AppContext`: the stage, the lock, the typed view state
`state.AppState`, the session), the scene views (`nodes.SceneNodes`, `slice_nodes.SliceNode`, the camera director)
and the panels (`controls.Controls`, `planning_panel.PlanningPanel`), then one controller per feature
(`controllers/`), each with a narrow interface (`actions`): `evaluate` (drags, settings, display options, layers),
`present` (an evaluation onto every view), `views` (camera, presentation, slice, selection, lesson), `plan`,
`montecarlo`, `vec`, `authoring` and `files`; and the plug-in tabs' controllers (`tabs`: Diagnose, Model; see
`tab_plugin`). The panels are handed the app as `actions.Actions` and
call the controllers; the controllers give the scene views and panels values, never touching their handles.

Shared state, by design. ONE session, one scene and one control panel are shared by every browser tab (viser's
`server.scene` / `server.gui`): a teacher's demo, where a drag or a setting made in one tab is seen live in all.
Notifications go to the tab that caused them (to every tab when the change came from Python); the status line
shows the last message to everyone. `rrbc view --per-client` gives every tab its own app on a client-scoped stage
(`per_client.PerClientApp`, `stage.ClientStage`).

Concurrency. viser runs gizmo callbacks (async) on its event loop and GUI callbacks on a thread pool. A gizmo
callback only records its event in a latest-wins queue (`drag_queue.DragQueue`: per handle only the newest update
is handled, a drag's start and end never dropped), which one thread works off; every change to the session and the
scene goes through one re-entrant lock, and scene updates of one change are sent in one `server.atomic()` block.
The heat map is recomputed at most every 0.3 s during a drag (`controllers.evaluate`); the Monte Carlo, a slow
scene's planning and the Diagnose tab's diagnosis run outside the lock.

Frames and units: the scene is drawn in the robot frame, in millimetres (see `nodes`).
"""

from __future__ import annotations

import contextlib
import io
import threading
from collections.abc import Sequence
from dataclasses import replace
from typing import Any, TypeVar

import numpy as np
import viser

from rrbc_core.session.evaluation import Evaluation
from rrbc_core.session.explorer import ExplorerSession

from . import sources, upload_spool
from .camera import OPENING, CameraDirector, preset_view
from .context import AppContext
from .controllers.edit import AuthoringController
from .controllers.evaluate import EvaluateController
from .controllers.load import FileController
from .controllers.plan import PlanController
from .controllers.present import Presenter
from .controllers.simulate import MonteCarloController
from .controllers.vec import VecController
from .controllers.viewing import PRESENTATION_MARKERS, ViewController
from .controls import Controls
from .model_check_nodes import ModelCheckNode
from .node_values import Display, nice_down
from .nodes import SceneNodes
from .picture import scene_extent
from .planning_panel import PlanningPanel
from .slice_nodes import SliceNode
from .stage import Stage
from .state import AppState
from .tab_plugin import TabController, TabSpec
from .tabs import TABS
from .worker_pool import RetiringExecutor

T = TypeVar("T")
HEAT_SAMPLES_PER_TARGET = 200  # heat-map samples inside each target's region of variability


class RunningApp:
    """A running app (module docstring). `server` is where it draws (the viser server, shared by every tab; or one
    tab's `stage.ClientStage` with `viser_server` the server behind it); `port`/`url` where to point a browser.
    `stop()` frees the port (only an app that owns its server stops it: a per-tab app stops its own workers)."""

    def __init__(
        self,
        server: Stage,
        loaded: sources.Loaded,
        host: str,
        viser_server: viser.ViserServer | None = None,
        library: sources.Library | None = None,
        arm_meshes: bool = True,
        tabs: Sequence[TabSpec] = TABS,
    ):
        if viser_server is None:  # the app draws on the server itself (every tab)
            assert isinstance(server, viser.ViserServer), "a stage other than the server needs viser_server"
            viser_server = server
        self.owns_server = server is viser_server
        self.host = host
        self.port = int(viser_server.get_port())
        self.url = f"http://{host if host not in ('0.0.0.0', '::', '') else 'localhost'}:{self.port}"
        self.quiet = True  # stop() hides viser's "Server stopped" line
        self.worker_pool: RetiringExecutor | None = None  # set by serve: the server's callback threads
        self._stopped = False
        # the views first (they call the controllers only when the user acts), then the context, then the controllers
        nodes = SceneNodes(server, self._on_drag, self._on_point_click, arm_meshes)
        controls = Controls(server, self, [(t.name, t.label, t.icon, t.panel) for t in tabs])
        ctx = AppContext(
            server,
            viser_server,
            loaded,
            library or sources.Library.of(),
            nodes=nodes,
            slice_node=SliceNode(server.scene),
            check_node=ModelCheckNode(server.scene),
            camera=CameraDirector(server),
            controls=controls,
            app=self,
            install=self.install,
            heat_samples_per_target=HEAT_SAMPLES_PER_TARGET,
        )
        self.ctx = ctx
        self.evaluate = EvaluateController(ctx)
        self.present = Presenter(ctx)
        self.views = ViewController(ctx)
        self.plan = PlanController(ctx)
        #: the plug-in tabs' controllers by name (`tab_plugin`, `tabs.TABS`), each handed its own panel
        self.tabs: dict[str, TabController[Any]] = {
            spec.name: spec.controller(ctx, controls.tabs[spec.name]) for spec in tabs
        }
        self.vec = VecController(ctx)
        self.authoring = AuthoringController(ctx)
        self.files = FileController(ctx)
        self.montecarlo = MonteCarloController(ctx)
        self.install(loaded, first=True)
        self.files.rescan_files()
        server.on_client_connect(self.views.frame_new_client)
        server.scene.on_click()(self.authoring.on_scene_click)

    def _on_drag(self, kind: str, pid: str, position, phase: str, client=None) -> None:
        """A gizmo's event (viser's event loop): into the drag queue, handled by its thread."""
        self.evaluate.drags.submit(kind, pid, position, phase, client=client)

    def _on_point_click(self, kind: str, pid: str, client=None) -> None:
        self.views.on_point_click(kind, pid, client=client)

    # ------------------------------------------------------------------------------------------ what it holds
    def tab(self, name: str, kind: type[T]) -> T:
        """The plug-in tab `name`'s controller (`tabs`), checked to be a `kind` (its class), so that a caller's
        use of it is type-checked (examples/03_drive_the_app.py runs the Diagnose tab's this way)."""
        controller = self.tabs[name]
        if not isinstance(controller, kind):
            raise TypeError(f"tab {name!r} is a {type(controller).__name__}, not a {kind.__name__}")
        return controller

    @property
    def session(self) -> ExplorerSession:
        return self.ctx.session

    @property
    def state(self) -> AppState:
        return self.ctx.state

    @property
    def lock(self) -> threading.RLock:
        """The re-entrant lock every change to the session and the scene goes through (module docstring)."""
        return self.ctx.lock

    @property
    def server(self):
        return self.ctx.server

    @property
    def viser_server(self):
        return self.ctx.viser_server

    @property
    def loaded(self) -> sources.Loaded:
        return self.ctx.loaded

    @property
    def nodes(self) -> SceneNodes:
        return self.ctx.nodes

    @property
    def controls(self) -> Controls:
        return self.ctx.controls

    @property
    def planning(self) -> PlanningPanel:
        """The Plan tab's panel."""
        return self.ctx.planning

    @property
    def slice_node(self) -> SliceNode:
        return self.ctx.slice_node

    @property
    def check_node(self) -> ModelCheckNode:
        return self.ctx.check_node

    @property
    def guard(self):
        return self.ctx.guard

    @guard.setter
    def guard(self, value) -> None:
        self.ctx.guard = value

    @property
    def messages(self) -> list[str]:
        return self.ctx.state.messages

    @property
    def last_message(self) -> str | None:
        return self.ctx.last_message

    # ------------------------------------------------------------------------------------------ lifecycle
    def stop(self) -> None:
        """Stop the workers and the server (frees the port). Safe to call twice."""
        if self._stopped:
            return
        self._stopped = True
        self.evaluate.stop()
        self.montecarlo.close()
        self.plan.stop()
        for tab in self.tabs.values():
            tab.stop()
        self.authoring.remove_upload()  # the uploaded mesh's temporary copy (a per-tab app too, when its tab goes)
        upload_spool.close(self.ctx.server.gui)  # uploads still arriving, and what they stored
        if not self.owns_server:
            return
        with contextlib.redirect_stdout(io.StringIO()) if self.quiet else contextlib.nullcontext():
            self.ctx.viser_server.stop()  # viser prints "(viser) Server stopped" on stdout

    def install(self, loaded: sources.Loaded, first: bool = False) -> None:
        """Make `loaded` the current source: rebuild the scene and resync the panel."""
        ctx = self.ctx
        with ctx.lock:
            self.montecarlo.runner.cancel()
            ctx.loaded = loaded
            self.authoring.forget_upload_unless_used(loaded.session.mesh_path)
            ev = ctx.session.last
            st = ctx.state
            st.lesson_index = None
            st.lesson_saved_layers = None
            st.lesson_labels = ()
            st.target_arrows = True
            st.drag_active = False
            st.landing = None
            st.heat_map = None
            st.mc_plots = None
            st.heat_stale = True
            st.display = self._default_display(ev)
            if st.presentation:
                st.display = replace(st.display, marker_mm=st.display.marker_mm * PRESENTATION_MARKERS)
            # the first target; in measured data the first check (what is scored: the headline's numbers)
            first_ids = [p for p in ev.targets.ids if p in ev.check_ids] or list(ev.targets.ids)
            st.selected = ("targets", first_ids[0]) if first_ids else None
            st.camera_preset = OPENING
            session = ctx.session
            with ctx.server.atomic():
                self.present.build_scene(ev)
                ctx.controls.sync_settings(session.settings, session.kind)
                ctx.controls.sync_display(st.display, session.kind)
                ctx.controls.sync_layers(st.layers)
                ctx.controls.view.show_applicable_layers(ctx.nodes.applicable_layers())
                self.authoring.sync_history()
                ctx.controls.explore.show_source(
                    f"**{loaded.label}**: "
                    + (
                        "simulated from the scene error model"
                        if session.kind == "scene"
                        else "measured data (no error model)"
                    )
                    + "."
                )
                ctx.controls.learn.show_text(
                    "The nine steps of RRBC, one at a time, each shown in the scene with live numbers. Press **Next** "
                    "to start."
                )
                for tab in self.tabs.values():
                    tab.installed()
                ctx.controls.file.show_stations(session.stations, session.station)
                self.present.show(ev, heat=True)
                self._frame_camera(loaded.mesh, ev)
            if not first:
                ctx.message(f"Loaded {loaded.label}", error=False)
        self.montecarlo.request()

    def _default_display(self, ev: Evaluation) -> Display:
        """Marker size from the points' extent; magnification so a typical correction is drawn ~8 % of it."""
        extent = scene_extent(ev)
        marker = float(np.clip(np.round(0.012 * extent * 2) / 2, 0.5, 50.0))
        sizes = np.linalg.norm(ev.corrections[ev.included].reshape(-1, 3), axis=1)
        sizes = sizes[np.isfinite(sizes) & (sizes > 0)]
        mag = nice_down(0.08 * extent / float(np.median(sizes))) if len(sizes) else 200.0
        heat = "rrbc" if self.ctx.session.kind == "scene" else "correction"
        return Display(
            magnification=float(np.clip(mag, 1, 2000)),
            marker_mm=marker,
            region_zoom=1.0,
            heat_value=heat,
            slice_value=heat,
        )

    def _frame_camera(self, mesh, ev: Evaluation) -> None:
        """The initial camera of new tabs, and that of open tabs: the work area, framed beside the panel."""
        cell = self.views.cell_geometry()
        view = self.views.preset_view(OPENING)  # (with the selected target's bullseye)
        whole = preset_view("whole cell", cell).points
        radius = max(0.5 * float(np.linalg.norm(whole.max(0) - whole.min(0))), 10.0)
        # mm: near close enough to look at a region of variability, far enough for the whole cell from afar
        self.ctx.state.initial_camera = self.ctx.camera.set_initial(
            view, near=max(radius * 3e-4, 0.05), far=radius * 30.0
        )
        self.views.place_labels(self.ctx.camera.show(view))
