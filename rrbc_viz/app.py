"""The RRBC browser app: a viser server over one `rrbc_core.explorer.ExplorerSession`.

    app = serve()                      # bundled default scene, 127.0.0.1, a free port; returns at once
    print(app.url)
    app.handle_drag("targets", "H1", [400, -150, 40], "end")
    app.stop()

Shared state, by design. ONE session, one scene and one control panel are shared by every browser tab
(viser's `server.scene` / `server.gui`): this is a teacher's demo, so every tab shows the same work cell, a drag
or a setting made in one tab is seen live in all of them, and a tab opened later joins the current state.
Notifications (a refused move, a file that did not load) go to the tab that caused them (to every tab when the
change came from Python); the status line at the top of the panel shows the last message to everyone.
Per-student state would mean one session per `ClientHandle` built in `on_client_connect` (client-scoped
scene and GUI); it is not done.

Concurrency. viser runs gizmo callbacks (async) on its event loop and GUI callbacks on a thread pool. A gizmo
callback only records its event in a latest-wins queue (`drag_queue.DragQueue`: per handle only the newest update
is handled, a drag's start and end never dropped), which one thread works off; every change to the session and the
scene goes through one re-entrant lock, and scene updates of one change are sent in one `server.atomic()` block. A drag update re-evaluates the session (milliseconds) and updates node
properties in place; the heat map is recomputed at most every `HEAT_INTERVAL_S` during a drag and at its end;
Monte Carlo runs in a background thread (`montecarlo.MonteCarloRunner`) after a setting changes, a drag ends or
the seed changes. (A heat map that takes longer than `HEAT_LIVE_MAX_S` waits for the drag's end.)
The Plan tab (`planning_panel`) shows the core's coverage and fast predicted RMST for the fiducials as they are
now, recomputed like the heat map (at most every `planning_panel.PLAN_INTERVAL_S` during a drag, and at its end;
on scenes where it takes longer than `PLAN_LIVE_MAX_S`, drags hand it to a background thread instead);
Suggest runs the planner on a snapshot of the session outside the lock (drags go on meanwhile).
The Diagnose tab diagnoses the session's data set (`ExplorerSession.data()`: the file as opened or edited, or
the scene's simulated data set as the CSV download writes it) on a button press, outside the lock, and shows the
lines `rrbc diagnose` prints for it; a change to those data marks the verdict stale instead of recomputing it.

Frames and units: the scene is drawn in the robot frame, in millimetres (see `nodes`).
"""

from __future__ import annotations

import contextlib
import io
import socket
import threading
import time
import traceback
from dataclasses import replace

import numpy as np
import viser

from rrbc_core.analysis.diagnosis import Diagnosis
from rrbc_core.errors import InputError, one_line
from rrbc_core.runtime.threads import apply_process_policy
from rrbc_core.session import authoring, views
from rrbc_core.session.data_set import check_statistics
from rrbc_core.session.evaluation import Evaluation
from rrbc_core.session.explorer import ExplorerSession

from . import diagnosis_panel, files, tables, teaching
from .access import AccessGuard, new_token, page_url
from .app_authoring import AuthoringActions
from .app_tabs import TabActions
from .app_vec import VecActions
from .app_views import ViewActions
from .camera import OPENING, CameraDirector, preset_view
from .colors import legend_markdown
from .controls import HEAT_CHOICES, Controls
from .drag_queue import DragQueue
from .montecarlo import MonteCarloRunner
from .nodes import LAYERS, Display, SceneNodes, gizmo_name, nice_down
from .planning_panel import PlanningPanel
from .slice_nodes import SliceNode

HEAT_SAMPLES_PER_TARGET = 200  # heat-map samples inside each target's region of variability
HEAT_INTERVAL_S = 0.3  # least time between heat-map recomputations while dragging
HEAT_LIVE_MAX_S = 0.05  # a heat map slower than this to compute is refreshed only when a drag ends
DEFAULT_LAYERS = {name: name not in ("labels", "heatmap", "slice") for name in LAYERS}
_KINDS = {
    "target": "targets",
    "targets": "targets",
    "fiducial": "fiducials",
    "fiducials": "fiducials",
    "registration": "registration",
}


def _all_points(ev: Evaluation) -> np.ndarray:
    """Registration points, fiducials and targets (robot frame, mm), stacked."""
    return np.vstack(
        [
            ev.registration_positions.reshape(-1, 3),
            ev.fiducial_positions.reshape(-1, 3),
            ev.targets.positions.reshape(-1, 3),
        ]
    )


class RunningApp(TabActions, ViewActions, AuthoringActions, VecActions):
    """A running app. `server` is where it draws (the viser server, shared by every tab; or one tab's
    `stage.ClientStage` with `viser_server` the server behind it), `session` its ExplorerSession (replaced when a
    file is loaded), `port`/`url` where to point a browser. `stop()` frees the port (only an app that owns its
    server stops it: a per-tab app stops its own workers)."""

    def __init__(
        self,
        server,
        loaded: files.Loaded,
        host: str,
        viser_server: viser.ViserServer | None = None,
        library: files.Library | None = None,
    ):
        self.server = server
        self.library = library or files.Library.of()  # the folders the File tab may open files from
        self.viser_server = server if viser_server is None else viser_server
        self.owns_server = viser_server is None
        self.host = host
        self.port = int(self.viser_server.get_port())
        self.url = f"http://{host if host not in ('0.0.0.0', '::', '') else 'localhost'}:{self.port}"
        self._lock = threading.RLock()
        self._stopped = False
        self.quiet = True  # stop() hides viser's "Server stopped" line
        self.heat_samples_per_target = HEAT_SAMPLES_PER_TARGET
        self.loaded = loaded
        self.session: ExplorerSession = loaded.session
        self.display = Display()
        self.layers = dict(DEFAULT_LAYERS)
        self.messages: list[str] = []  # every message shown (status line / notifications), oldest first
        self.lesson_index: int | None = None
        self._lesson_saved_layers: dict[str, bool] | None = None
        self._refused: set = set()  # (kind, id) whose refusal was already announced in the current drag
        self._heat_time = 0.0
        self._heat_cost = 0.0  # seconds the last heat map took
        self._heat_stale = True
        self.heat_map = None  # the last HeatMap shown
        self.mc_plots = None  # the last MonteCarloPlots shown
        self.mc_seconds = None
        self.diagnosis: Diagnosis | None = None  # the last verdict shown in the Diagnose tab (None: none or an error)
        self.diagnosis_stale = False  # the data changed since the Diagnose tab's content was computed
        self.diagnosis_data = None  # the session's data set it was computed from (SessionData), None: nothing shown
        self._diagnosis_key = None  # that data set's key (data_set.data_key)
        self._diagnosis_text = ""  # its content without the stale marker
        self.selected: tuple[str, str] | None = None  # (kind, id) of the selected point (the one with a gizmo)
        self.presentation = False  # presentation mode (set_presentation)
        self.camera = CameraDirector(server)
        self.camera_preset = OPENING
        # gizmo events go through a latest-wins queue handled by one thread (drag_queue): never a backlog
        self.drags = DragQueue(self._on_gizmo, name="rrbc-drags")
        self.nodes = SceneNodes(server, self.drags.submit, self._on_point_click)
        self.slice_node = SliceNode(server.scene)
        self.error_slice = None  # the last ErrorSlice shown
        self.planning: PlanningPanel | None = None
        self.controls = Controls(server, self, plan_tab=self._build_plan_tab)
        self.mc = MonteCarloRunner(self._mc_result, self._mc_started)
        self.mc_draw = 0  # "Run again" presses so far (each draws new noise)
        self.mc_seed: int | None = None  # the noise seed of the last run requested (None: the session's)
        self._install(loaded, first=True)
        self.rescan_files()
        server.on_client_connect(self._frame_new_client)
        server.scene.on_click()(self._on_scene_click)

    @property
    def lock(self) -> threading.RLock:
        """The re-entrant lock every change to the session and the scene goes through (module docstring)."""
        return self._lock

    def _build_plan_tab(self) -> PlanningPanel:
        """Build the Plan tab's panel (Controls calls this inside the tab) with the narrow view it needs."""
        self.planning = PlanningPanel(self.server, self, _PlanningView(self))
        return self.planning

    # ------------------------------------------------------------------------------------------ lifecycle
    def stop(self) -> None:
        """Stop the Monte Carlo worker and the server (frees the port). Safe to call twice."""
        if self._stopped:
            return
        self._stopped = True
        self.drags.stop()
        self.mc.stop()
        self.planning.stop()
        if not self.owns_server:
            return
        with contextlib.redirect_stdout(io.StringIO()) if self.quiet else contextlib.nullcontext():
            self.server.stop()  # viser prints "(viser) Server stopped" on stdout

    def _install(self, loaded: files.Loaded, first: bool = False) -> None:
        """Make `loaded` the current source: rebuild the scene and resync the panel."""
        with self._lock:
            self.mc.cancel()
            self.loaded = loaded
            self.session = loaded.session
            ev = self.session.last
            self.lesson_index = None
            self._lesson_saved_layers = None
            self.nodes.target_arrows = True
            self.heat_map = None
            self.mc_plots = None
            self._heat_stale = True
            self.diagnosis = None
            self.diagnosis_stale = False
            self.diagnosis_data = None
            self._diagnosis_key = None
            self.display = self._default_display(ev)
            if self.presentation:
                from .app_views import PRESENTATION_MARKERS

                self.display = replace(self.display, marker_mm=self.display.marker_mm * PRESENTATION_MARKERS)
            self.selected = ("targets", ev.targets.ids[0]) if len(ev.targets.ids) else None
            self.nodes.selected = self.selected
            self.camera_preset = OPENING
            with self.server.atomic():
                self.nodes.build(self.session, ev, loaded.mesh, self.display, self.layers)
                self.slice_node.clear()
                self.error_slice = None
                self.planning.build(self.session)
                self.controls.sync_settings(self.session.settings, self.session.kind)
                self.controls.sync_display(self.display, self.session.kind)
                self.controls.sync_layers(self.layers)
                self.controls.sync_authoring(authoring.can_undo(self.session), authoring.can_redo(self.session))
                self.planning.sync_undo(authoring.can_undo(self.session))
                self.controls.text["source"] = (
                    f"**{loaded.label}**: {'simulated from the scene error model' if self.session.kind == 'scene' else 'measured data (no error model)'}."
                )
                self.controls.text["lesson"] = (
                    "The nine steps of RRBC, one at a time, each shown in the scene with "
                    "live numbers. Press **Next** to start."
                )
                self.controls.text["diagnosis"] = diagnosis_panel.PROMPT
                self._show(ev, heat=True)
                self._frame_camera(loaded.mesh, ev)
            if not first:
                self._message(f"Loaded {loaded.label}", error=False)
        self.request_monte_carlo()

    def _default_display(self, ev: Evaluation) -> Display:
        """Marker size from the points' extent; magnification so a typical correction is drawn ~8 % of it."""
        pts = _all_points(ev)
        extent = float(np.linalg.norm(pts.max(0) - pts.min(0))) if len(pts) else 1000.0
        marker = float(np.clip(np.round(0.012 * extent * 2) / 2, 0.5, 50.0))
        sizes = np.linalg.norm(ev.corrections[ev.included].reshape(-1, 3), axis=1)
        sizes = sizes[np.isfinite(sizes) & (sizes > 0)]
        mag = nice_down(0.08 * extent / float(np.median(sizes))) if len(sizes) else 200.0
        heat = "rrbc" if self.session.kind == "scene" else "correction"
        slice_value = heat
        return Display(
            magnification=float(np.clip(mag, 1, 2000)),
            marker_mm=marker,
            region_zoom=1.0,
            heat_value=heat,
            slice_value=slice_value,
        )

    def _frame_camera(self, mesh, ev: Evaluation) -> None:
        """The initial camera of new tabs, and that of open tabs: the work area, framed beside the panel."""
        cell = self.cell_geometry()
        view = preset_view(OPENING, cell, marker_mm=self.display.marker_mm)
        whole = preset_view("whole cell", cell).points
        radius = max(0.5 * float(np.linalg.norm(whole.max(0) - whole.min(0))), 10.0)
        # mm: near close enough to look at a region of variability, far enough for the whole cell from afar
        self.camera.set_initial(view, near=max(radius * 3e-4, 0.05), far=radius * 30.0)
        self.camera.show(view)

    # -------------------------------------------------------------------------------------------- showing
    def _show(self, ev: Evaluation, heat: bool = False, plan: bool = True) -> None:
        """Push an Evaluation to the scene and the panel (caller holds the lock, inside server.atomic()). plan:
        recompute the Plan tab now (else it is marked stale until the next due refresh)."""
        self.nodes.bias_scale = float(self.session.settings.bias_scale) if self.session.kind == "scene" else 1.0
        self._show_vec()  # the Arm tab, and VEC's landings for the bullseye
        self.nodes.target_tools = dict(getattr(self.session, "target_tools", {}))
        self.nodes.update(ev)
        c = self.controls
        c.text["scale"] = tables.scale_line(self.display.magnification)
        c.text["summary"] = tables.summary(ev, self.session.kind)
        c.text["table"] = tables.target_table(ev)
        if self.lesson_index is not None:
            c.text["lesson"] = teaching.render(self.lesson_index, ev, self._lesson_context())
        self._heat_stale = True
        self._check_diagnosis()
        self.planning.refresh(self.session, due=plan)
        self._show_selection(ev)  # after the Plan tab: the card shows its coverage of the selected target's region
        if heat:
            self._update_heat()
            self._update_slice()
            self._update_checks()

    def _update_checks(self) -> None:
        """The Explore tab's check statistics and histogram (`data_set.check_statistics`: rrbc correct on the CSV
        download), refreshed when the heat map is (a drag's end, a setting, a load), not on every drag update."""
        s = self.session.settings
        try:
            stats = check_statistics(self.session)
        except InputError:
            stats = None
        self.controls.checks.show(stats, f"{s.registration} + {s.interpolation}")

    def _update_heat(self) -> None:
        """Recompute the heat map now if its layer is on (else leave it stale until shown)."""
        if not self.layers.get("heatmap"):
            return
        start = time.perf_counter()
        self.heat_map = views.heat_map(self.session, self.heat_samples_per_target)
        self._heat_cost = time.perf_counter() - start
        self._heat_time = time.monotonic()
        self._heat_stale = False
        legend = self.nodes.update_heatmap(self.heat_map, self.session.last)
        self.controls.text["legend"] = "Nothing to show." if legend is None else legend_markdown(*legend)

    def _lesson_context(self) -> teaching.LessonContext:
        return teaching.LessonContext(
            self.session.kind, self.display.magnification, dict(self.session.regions), self.nodes.frame_mag
        )

    def _message(self, text: str, client=None, error: bool = True, title: str | None = None) -> None:
        """Show a message: a notification to `client` (every tab if None) and the status line."""
        line = one_line(str(text))
        self.messages.append(line)
        self.controls.text["status"] = ("⚠ " if error else "✓ ") + line
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
        return self.messages[-1] if self.messages else None

    # ------------------------------------------------------------------------------------------- dragging
    def wait_drags(self, timeout: float = 10.0) -> bool:
        """Block until every drag event from the browser has been handled (True if within `timeout` s)."""
        return self.drags.wait_idle(timeout)

    def _on_gizmo(self, kind: str, pid: str, position, phase: str, client=None) -> None:
        try:
            self.handle_drag(kind, pid, position, phase, client=client)
        except Exception:  # noqa: BLE001 - keep the server alive; say so
            traceback.print_exc()
            self._message("internal error while dragging (see the server log)", client)

    def handle_drag(self, kind: str, pid: str, position, phase: str = "update", client=None) -> Evaluation | None:
        """Move point `pid` of `kind` ("targets" or "fiducials"; robot frame, mm) during a drag `phase`
        ("start", "update" or "end") and update every node: what the gizmo callback calls. Returns the new
        Evaluation, or None when the core refuses the move (the gizmo snaps back and a notification says why).
        The heat map is refreshed at most every HEAT_INTERVAL_S while dragging and at "end"; Monte Carlo is
        queued at "end"."""
        kind = _KINDS.get(kind, kind)
        key = (kind, pid)
        with self._lock:
            session = self.session
            if phase == "start":
                self._refused.discard(key)
                return session.last
            group = session.layout.get(kind)
            before = None
            if group is not None and pid in group.ids:
                before = np.array(group.positions[group.index(pid)], float)
            try:
                ev = session.move(kind, pid, position)
            except InputError as exc:
                self._refuse(key, before, str(exc), client, phase)
                return None
            end = phase == "end"
            heat_due = end or (
                self.layers.get("heatmap")
                and self._heat_cost <= HEAT_LIVE_MAX_S
                and time.monotonic() - self._heat_time >= HEAT_INTERVAL_S
            )
            slow_plan = self.planning.slow
            plan_due = not slow_plan and (end or self.planning.live_due())
            with self.server.atomic():
                self._show(ev, heat=bool(heat_due), plan=plan_due)
            if slow_plan:  # a slow scene: planning follows in the background, the drag does not wait
                self.planning.request_background(session)
            if end and key in self._refused:
                # a move in this drag was refused: the tab that dragged may have kept its handle where the
                # refusal happened (its own drag state wins over messages received mid-drag); send the
                # session's place again now that the drag is over
                self.nodes.resnap(kind, pid)
            if end:
                self._refused.discard(key)
        if end:
            self.request_monte_carlo()
        return ev

    def _refuse(self, key, before, message: str, client, phase: str) -> None:
        kind, pid = key
        session = self.session
        if before is not None:
            group = session.layout.get(kind)
            if group is not None and not np.allclose(group.positions[group.index(pid)], before):
                try:  # the core changed the layout before refusing: put the point back
                    session.move(kind, pid, before)
                except InputError:
                    pass
            if (kind, pid) in self.nodes.gizmos:
                self.nodes.snap(kind, pid, before)
        if key not in self._refused:
            self._message(message, client, title=f"Cannot move {pid}")
            self._refused.add(key)
        if phase == "end":
            self._refused.discard(key)

    # ------------------------------------------------------------------------------------------- settings
    def toggle_fiducial(self, pid: str, client=None) -> Evaluation | None:
        """Exclude an included fiducial or include an excluded one (what clicking its sphere does)."""
        with self._lock:
            excluded = pid in self.session.settings.excluded
            return self._apply(lambda s: s.set_excluded(pid, not excluded), client)

    def change_settings(self, client=None, **changes) -> Evaluation | None:
        """Change session settings (names as in explorer.Settings); None (and a message) if refused."""
        with self._lock:
            return self._apply(lambda s: s.update(**changes), client)

    def new_seed(self, client=None) -> Evaluation | None:
        with self._lock:
            seed = int(np.random.default_rng().integers(1, 2**31 - 1))
            return self._apply(lambda s: s.update(seed=seed), client)

    def _apply(self, change, client) -> Evaluation | None:
        with self._lock:
            try:
                ev = change(self.session)
            except InputError as exc:
                self._message(str(exc), client, title="Setting refused")
                ev = None
            except Exception as exc:  # noqa: BLE001 - keep serving; the session keeps its last evaluation
                traceback.print_exc()
                self._message(f"internal error: {type(exc).__name__}: {exc}", client, title="Setting failed")
                ev = None
            with self.server.atomic():
                self.controls.sync_settings(self.session.settings, self.session.kind)
                if ev is not None:
                    self._show(ev, heat=True)
        if ev is not None:
            self.request_monte_carlo()
        return ev

    def set_display(self, client=None, **changes) -> None:
        """Display-only options (Display fields): magnification, marker_mm, region_zoom, heat_value, slice_value,
        slice_axis, slice_offset."""
        with self._lock:
            unknown = sorted(set(changes) - set(Display.__dataclass_fields__))
            if unknown:
                raise InputError(
                    f"unknown display option(s) {', '.join(unknown)}: {', '.join(Display.__dataclass_fields__)}"
                )
            new = replace(self.display, **changes)
            heat_values = [v for _, v in HEAT_CHOICES[self.session.kind]]
            if new.heat_value not in heat_values:
                raise InputError(f"heat_value must be one of {', '.join(heat_values)} here, got {new.heat_value!r}")
            self._check_slice_display(new)
            if not (new.magnification > 0 and new.marker_mm > 0 and new.region_zoom > 0):
                raise InputError("magnification, marker_mm and region_zoom must be > 0")
            self.display = new
            self.nodes.display = self.display
            with self.server.atomic():
                if "marker_mm" in changes or "region_zoom" in changes:
                    self.nodes.apply_sizes()
                self.controls.sync_display(self.display, self.session.kind)
                heat = any(k in changes for k in ("region_zoom", "heat_value"))
                self._show(self.session.last, heat=heat)
                if any(k.startswith("slice_") for k in changes):
                    self._update_slice()

    def set_layer(self, layer: str, visible: bool) -> None:
        """Show or hide a layer (nodes.LAYERS) in the scene and on its checkbox."""
        if layer not in LAYERS:
            raise InputError(f"unknown layer '{layer}': {', '.join(LAYERS)}")
        with self._lock:
            self.layers[layer] = bool(visible)
            with self.server.atomic():
                self.nodes.set_layer(layer, visible)
                self.controls.sync_layers({layer: bool(visible)})
                if layer == "heatmap" and visible and (self._heat_stale or self.heat_map is None):
                    self._update_heat()
                if layer == "slice" and visible:
                    self._update_slice()

    # ------------------------------------------------------------------------------------------ for tests
    def gizmo(self, kind: str, pid: str) -> viser.TransformControlsHandle:
        return self.nodes.gizmos[(_KINDS.get(kind, kind), pid)]

    @staticmethod
    def gizmo_name(kind: str, pid: str) -> str:
        return gizmo_name(_KINDS.get(kind, kind), pid)


class _PlanningView:
    """`actions.PlanningView` over a RunningApp: what the Plan tab reads, nothing else."""

    def __init__(self, app: RunningApp):
        self._app = app
        self.lock = app.lock

    def live_session(self) -> ExplorerSession:
        return self._app.session

    def marker_mm(self) -> float:
        return float(self._app.display.marker_mm)

    def region_nodes(self) -> dict:
        return self._app.nodes.regions


def _check_host(host: str) -> None:
    """Fail early on an address this machine cannot listen on (viser 1.1.1 would wait forever)."""
    try:
        family, kind, proto, _, address = socket.getaddrinfo(host, 0, type=socket.SOCK_STREAM)[0]
        with socket.socket(family, kind, proto) as probe:
            probe.bind(address)
    except OSError as exc:
        raise InputError(f"cannot listen on host {host!r}: {exc.strerror or exc}") from None


def serve(
    source=None,
    host: str = "127.0.0.1",
    port: int = 0,
    mesh=None,
    quiet: bool = True,
    per_client: bool = False,
    present: bool = False,
    token: str | bool | None = True,
    data_dirs=(),
):
    """Start the app on `host`:`port` (0 = a free port) and return at once. `source`: a scene .toml, a measurement
    .csv (with an optional `mesh` file), an ExplorerSession, or None for the bundled default scene. Bad input
    raises InputError before any server starts. `quiet` hides viser's start-up banner and its "Server stopped"
    line. `per_client`: one independent session per browser tab (per_client.PerClientApp) instead of one shared
    by all; `present`: start in presentation mode (large text, collapsible panel; View → Presentation mode). Sets this process's BLAS/OpenMP pools to one thread (`rrbc_core.threads`, docs/threads.md): the
    server's callbacks and workers then never wait for idle BLAS threads on a busy machine."""
    apply_process_policy()
    if isinstance(source, ExplorerSession):
        loaded = files.Loaded(source, files.load_mesh(mesh) if mesh else None, f"session {source.name}")
        source.evaluate()
    else:
        loaded = files.load_source(source, mesh)
    _check_host(host)
    library = files.Library.of(data_dirs, source)
    out = io.StringIO() if quiet else None
    with contextlib.redirect_stdout(out) if quiet else contextlib.nullcontext():
        server = viser.ViserServer(host=host, port=port, label="RRBC explorer", verbose=False)
    try:
        guard = AccessGuard(server, new_token() if token is True else (token or None))
        server.scene.set_up_direction("+z")
        if per_client:
            from .per_client import PerClientApp

            server.gui.configure_theme(show_share_button=False)
            app = PerClientApp(server, loaded, source, mesh, host, present, library)
        else:
            app = RunningApp(server, loaded, host, library=library)
            if present:
                app.set_presentation(True)
        app.quiet = quiet
        app.guard = guard
        app.url = page_url(app.url, guard.token)
        return app
    except BaseException:
        server.stop()
        raise
