"""The Plan tab's controller (`PlanController`): the planning state shown (the predicted RMST and each target's
coverage, in `state.AppState.plan`), when it is recomputed during drags (throttled, or in a background worker on slow
scenes), coverage colours, suggestions (the planner on a snapshot of the session, outside the app's lock) and
accepting them (one step of the session's edit history: Undo takes them away). The panel
(`planning_panel.PlanningPanel`) only shows what it is given.

During drags the planning state is recomputed at most every `PLAN_INTERVAL_S`, and at a drag's end; when an update
takes longer than `PLAN_LIVE_MAX_S` (large scenes), drags hand it to a background thread instead, which computes it
whenever the drag pauses for `PLAN_QUIET_S` or ends."""

from __future__ import annotations

import copy
import threading
import time
import traceback
from typing import TYPE_CHECKING

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.session import planning_view
from rrbc_core.session.evaluation import Evaluation
from rrbc_core.session.results import PlanningState
from rrbc_core.session.tolerance_plan import TolerancePlan, plan_to_tolerance

from .. import colors
from ..drag_queue import drags_waiting
from ..planning_panel import K_MAX, failure_text, measured_info, render_coverage, render_state
from ..worker import CoalescingWorker

if TYPE_CHECKING:
    from rrbc_core.session.explorer import ExplorerSession

    from ..context import AppContext

PLAN_INTERVAL_S = 0.25  # least time between planning recomputations while dragging
PLAN_LIVE_MAX_S = 0.05  # a planning update slower than this runs in the background during drags …
PLAN_QUIET_S = 0.15  # … once the drag has paused (no update) this long, or ended: computing it while the drag
#                      goes on would slow every drag update (the worker holds the GIL for much of its time)
PROGRESS_INTERVAL_S = 0.2  # the planner's progress is shown at most this often


def _compute(session: ExplorerSession) -> PlanningState | Exception:
    """planning_view.planning_state(session), or the exception that says why not."""
    try:
        return planning_view.planning_state(session)
    except InputError as exc:
        return exc
    except Exception as exc:  # noqa: BLE001 - keep serving; say so in the tab
        traceback.print_exc()
        return exc


def _outside_the_lock(run):
    """(run(), None), or (None, why) when it raised: a planner run on a snapshot keeps the app serving whatever it
    meets (a bad request in words, anything else as an internal error, its traceback in the log)."""
    try:
        return run(), None
    except InputError as exc:
        return None, str(exc)
    except Exception as exc:  # noqa: BLE001 - keep serving
        traceback.print_exc()
        return None, f"internal error: {type(exc).__name__}: {exc}"


class PlanController:
    """`actions.PlanActions` (module docstring). Its own bookkeeping (when planning last ran and what it cost, the
    background worker, whether a Suggest runs) is private; what the tab shows is in the app's state."""

    def __init__(self, ctx: AppContext):
        self.ctx = ctx
        self.cost_s = 0.0  # seconds the last (uncached) planning update took (a slow scene plans in the background)
        self._measured = False  # the first computation for the current source was done (its cost is not typical)
        self._time = 0.0  # when planning was last shown (monotonic s)
        self._busy = False  # a Suggest is running
        self._busy_lock = threading.Lock()
        self._progress_time = 0.0
        self._progress_k = 0
        # background planning (slow scenes, during drags); every synchronous refresh makes its work stale
        self._worker = CoalescingWorker(self._background, PLAN_QUIET_S, name="rrbc-planning")

    # ------------------------------------------------------------------------------------------ lifecycle
    def build(self, session: ExplorerSession) -> None:
        """A new source (or a rebuilt cell): nothing planned yet (caller holds the lock, inside atomic())."""
        self.cost_s, self._measured = 0.0, False
        self.ctx.state.plan = None
        self.ctx.state.plan_stale = False
        self.ctx.state.tolerance_plan = None
        self.ctx.planning.build(session.kind == "scene")

    def stop(self) -> None:
        self._worker.stop()

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until no background planning is queued or running (tests, scripts). True if idle in time."""
        return self._worker.wait_idle(timeout)

    # ------------------------------------------------------------------------------------------ refreshing
    def slow(self) -> bool:
        """The last planning update took longer than PLAN_LIVE_MAX_S: during drags it runs in the background."""
        return self.cost_s > PLAN_LIVE_MAX_S

    def live_due(self) -> bool:
        """Whether a drag update should recompute planning now, synchronously (throttled)."""
        return not self.slow() and time.monotonic() - self._time >= PLAN_INTERVAL_S

    def refresh(self, session: ExplorerSession, due: bool = True) -> None:
        """Recompute (or take from the session's cache) and show the planning state (caller holds the app lock,
        inside atomic()). due=False marks it stale instead (a drag update between throttled refreshes)."""
        st = self.ctx.state
        if session.kind != "scene":
            st.plan = None
            if due:
                self._show_coverage(session)
            return
        if not due:
            st.plan_stale = True
            return
        self._worker.invalidate()  # a background result requested before this is older: it will be dropped
        start = time.perf_counter()
        self._time = time.monotonic()
        state = _compute(session)
        if state is not st.plan and not isinstance(state, Exception):  # a cache hit says nothing about the cost
            cost = time.perf_counter() - start
            # the first computation for a source pays one-off start-up costs (up to ~5x): it counts at a fifth, so a
            # scene whose planning is slow even then (the 200-fiducial stress cell) never blocks a drag
            self.cost_s = cost if self._measured else cost / 5.0
            self._measured = True
        self._show_state(session, state)

    def _show_coverage(self, session: ExplorerSession) -> None:
        """Measured data: each target inside the hull or not, and its region's coverage."""
        panel = self.ctx.planning
        try:
            plan = planning_view.coverage_plan(session, 0)
        except InputError as exc:
            panel.show_planning(f"Cannot plan: {exc}", "")
            return
        ev = session.last
        n_in = int(np.sum(ev.coverage.inside)) if ev.coverage is not None else 0
        full = int(np.sum(plan.coverage >= 1.0))
        state = PlanningState(plan.target_ids, plan.coverage, None, 0)
        panel.show_planning(
            measured_info(n_in, len(ev.targets.ids), full, len(plan.target_ids)),
            render_coverage(state, ev.coverage, ev.targets.ids),
        )

    def _show_state(self, session: ExplorerSession, state: PlanningState | Exception) -> None:
        st = self.ctx.state
        self._time = time.monotonic()
        if isinstance(state, Exception):
            st.plan = None
            self.ctx.planning.show_failure(failure_text(state))
            return
        st.plan_stale = False
        st.plan = state
        excluded = sum(1 for pid in session.layout["fiducials"].ids if pid in session.settings.excluded)
        ev = session.last
        self.ctx.planning.show_planning(
            render_state(state, excluded, session.settings, ev.coverage),
            render_coverage(state, ev.coverage, ev.targets.ids),
        )
        self._apply_colours()
        if session.suggestion is not None:
            self.ctx.planning.refresh_suggestion(session.suggestion, planning_view.suggestion_current(session))

    def request_background(self, session: ExplorerSession) -> None:
        """Recompute planning on a snapshot of `session` in the worker thread (caller holds the app lock); drag
        updates of a slow scene do this instead of waiting. Requests coalesce: the newest starts once none has
        come for PLAN_QUIET_S (the drag paused or ended); a result is shown unless a synchronous refresh came
        after its request or another source was loaded."""
        if session.kind != "scene":
            return
        self.ctx.state.plan_stale = True
        self._worker.submit((session, copy.copy(session)))  # the thread starts with the first request

    def _background(self, job, fresh) -> None:
        """The worker's job: compute on the snapshot, show it if still wanted (under the app lock)."""
        live, snapshot = job
        while drags_waiting():  # drags first (any session's): the plan follows when they pause
            if not fresh():
                return  # a newer request supersedes this one (or the worker stopped)
            time.sleep(PLAN_QUIET_S)
        start = time.perf_counter()
        state = _compute(snapshot)
        cost = time.perf_counter() - start
        with self.ctx.lock:
            if fresh() and self.ctx.session is live:
                if not isinstance(state, Exception) and state is not self.ctx.state.plan:  # a cache hit: no cost
                    self.cost_s = cost
                with self.ctx.server.atomic():
                    self._show_state(snapshot, state)

    # ------------------------------------------------------------------------------------------- colours
    def set_coverage_colours(self, on: bool) -> None:
        """Colour each target's region (and a halo around it) by coverage, or back to the region colour."""
        with self.ctx.lock:
            self.ctx.state.coverage_colours = bool(on)
            self.ctx.planning.sync_colour(on)
            with self.ctx.server.atomic():
                self._apply_colours()

    def _apply_colours(self) -> None:
        """Regions and halos on the coverage scale when the toggle is on; regions back to their colour when off
        (the scene's nodes paint them: `nodes.SceneNodes.paint_regions`)."""
        state = self.ctx.state.plan
        if not self.ctx.state.coverage_colours or state is None:
            self.ctx.nodes.paint_regions(None)
            return
        self.ctx.nodes.paint_regions(
            {pid: colors.coverage_color(c) for pid, c in zip(state.target_ids, state.coverage)}
        )

    # ------------------------------------------------------------------------------------------ suggesting
    def _claim(self) -> bool:
        """Mark a planner run (Suggest, or a plan to a tolerance) as running; False if one already is."""
        with self._busy_lock:
            if self._busy:
                return False
            self._busy = True
        return True

    def _release(self) -> None:
        with self._busy_lock:
            self._busy = False

    def _begin(self, k: int) -> bool:
        """Mark a Suggest as running (False if a planner run already is)."""
        if not self._claim():
            return False
        self._progress_k = k
        self.ctx.planning.set_busy(True, k)
        return True

    def _end(self) -> None:
        self._release()
        self.ctx.planning.set_busy(False)

    def _progress(self, *args) -> None:
        """The planner's progress callback: shows its last label (at most every PROGRESS_INTERVAL_S)."""
        now = time.monotonic()
        if now - self._progress_time < PROGRESS_INTERVAL_S:
            return
        self._progress_time = now
        label = next((a for a in args if isinstance(a, str)), None)
        nums = [a for a in args if isinstance(a, (int, float)) and not isinstance(a, bool)]
        extra = label or (" / ".join(f"{x:g}" for x in nums[:2]) if nums else "")
        self.ctx.planning.show_progress(self._progress_k, extra)

    def suggest_fiducials(self, k: int | None = None, client=None, seed: int | None = None):
        """Suggest `k` (default 4, at most K_MAX) more fiducials for the session as it is now and show them as ghost
        spheres. The planner runs on a snapshot of the session outside the app's lock (a drag meanwhile goes on;
        the suggestion is then marked as made for the old layout). Returns the planning.PlanResult, or None (and
        a visible message) when refused."""
        panel = self.ctx.planning
        k = 4 if k is None else int(k)
        if not 1 <= k <= K_MAX:
            self.ctx.message(f"K must be between 1 and {K_MAX}, got {k}", client, title="Cannot plan")
            return None
        with self.ctx.lock:
            session = self.ctx.session
            marker = float(self.ctx.state.display.marker_mm)
            if session.kind != "scene":  # measured data: coverage first, then spread (no error model needed)
                try:
                    plan = planning_view.coverage_plan(session, k)
                except InputError as exc:
                    self.ctx.message(str(exc), client, title="Cannot plan")
                    return None
                with self.ctx.server.atomic():
                    panel.show_coverage_suggestion(plan, marker)
                return plan
            if not self._begin(k):
                self.ctx.message("a suggestion is already being computed", client, title="Planning")
                return None
            snapshot = copy.copy(session)  # settings and layout are immutable values
        result, error = _outside_the_lock(
            lambda: planning_view.suggest_fiducials(snapshot, k, seed=seed, progress=self._progress)
        )
        with self.ctx.lock:
            self._end()
            if self.ctx.session is not session:  # another source was loaded meanwhile
                return None
            if error is not None:
                panel.show_refusal(error)
                self.ctx.message(error, client, title="Cannot plan")
                return None
            planning_view.adopt_suggestion(session, snapshot)
            self.ctx.state.tolerance_plan = None  # the ghosts are the suggestion's now
            with self.ctx.server.atomic():
                panel.show_suggestion(result, planning_view.suggestion_current(session), marker)
        return result

    def accept_suggestions(self, client=None) -> Evaluation | None:
        """Add the suggested fiducials to the cell (measured from the error model), remove the ghosts, update
        everything (planning included). None, and a message, when there is nothing to accept."""
        with self.ctx.lock:
            before = self.ctx.state.plan
            known = set(self.ctx.session.layout["fiducials"].ids)
            try:
                ev = planning_view.accept_suggestions(self.ctx.session)
            except InputError as exc:
                self.ctx.message(str(exc), client, title="Not accepted")
                return None
            new = [pid for pid in ev.fiducial_ids if pid not in known]
            with self.ctx.server.atomic():
                self.ctx.nodes.add_new_fiducials(ev)
                self.ctx.planning.remove_ghosts(prompt=True)
                self.ctx.present.show(ev, heat=True)
                self.ctx.authoring.sync_history()
            after = self.ctx.state.plan
            text = f"Added {len(new)} fiducial{'s' if len(new) != 1 else ''}: {', '.join(new)} (Undo takes them away)."
            if before is not None and after is not None and before.predicted and after.predicted:
                text += (
                    f" Predicted RMST with RRBC {before.predicted.rrbc_mm:.3f} → {after.predicted.rrbc_mm:.3f} mm, "
                    f"rigid {before.predicted.rigid_mm:.3f} → {after.predicted.rigid_mm:.3f} mm."
                )
            self.ctx.message(text, client, error=False, title="Fiducials added")
        self.ctx.montecarlo.request()
        return ev

    def clear_suggestions(self) -> None:
        with self.ctx.lock:
            planning_view.clear_suggestion(self.ctx.session)
            self.ctx.state.tolerance_plan = None
            with self.ctx.server.atomic():
                self.ctx.planning.remove_ghosts(prompt=True)

    # ------------------------------------------------------------------------------------------ a tolerance
    def plan_tolerance(self, tolerance_mm, client=None) -> TolerancePlan | None:
        """The fewest of the scene's candidates bringing every target's 95 % bound under `tolerance_mm`, for the
        cell as it is now (`tolerance_plan.plan_to_tolerance`, the function `rrbc plan --tolerance` calls), shown as
        ghosts with the command's text. Computed on a snapshot outside the app's lock, like Suggest. None, and a
        visible message, when refused."""
        panel = self.ctx.planning
        with self.ctx.lock:
            session = self.ctx.session
            if session.kind != "scene":
                self.ctx.message(
                    "planning to a tolerance needs a scene: its error model gives the planned fiducials' data",
                    client,
                    title="Cannot plan",
                )
                return None
            if not self._begin_tolerance(tolerance_mm):
                self.ctx.message("a plan is already being computed", client, title="Planning")
                return None
            snapshot = copy.copy(session)
            marker = float(self.ctx.state.display.marker_mm)

        def progress(_n: int, label: str) -> None:  # each step (seconds apart): the tab says how far it has come
            with self.ctx.lock:
                if self.ctx.session is session:
                    panel.show_tolerance_progress(float(tolerance_mm), label.removeprefix("planning: "))

        result, error = _outside_the_lock(
            lambda: plan_to_tolerance(None, tolerance_mm, start=snapshot, progress=progress)
        )
        with self.ctx.lock:
            self._end_tolerance()
            if self.ctx.session is not session:  # another source was loaded meanwhile
                return None
            if error is not None or result is None:
                panel.show_tolerance_refusal(str(error))
                self.ctx.message(str(error), client, title="Cannot plan")
                return None
            self.ctx.state.tolerance_plan = result
            planning_view.clear_suggestion(session)  # the ghosts are the plan's now
            with self.ctx.server.atomic():
                panel.show_tolerance_plan(result, marker)
        return result

    def use_tolerance_plan(self, client=None) -> Evaluation | None:
        """Replace the cell's fiducials by the last plan's (one step of the edit history), or say why not."""
        plan = self.ctx.state.tolerance_plan
        if plan is None:
            self.ctx.message("no plan to a tolerance to use", client, title="Not done")
            return None

        def change(session):
            return planning_view.use_fiducials(session, plan.fiducial_ids, plan.fiducial_positions)

        ev = self.ctx.authoring.apply_edit(change, client)
        if ev is not None:
            with self.ctx.lock:
                self.ctx.state.tolerance_plan = None
                with self.ctx.server.atomic():
                    self.ctx.planning.remove_ghosts(prompt=True)
            self.ctx.message(
                f"The cell's fiducials are now the plan's {len(plan.fiducial_ids)} (Undo brings the former back).",
                client,
                error=False,
                title="Fiducials replaced",
            )
        return ev

    def _begin_tolerance(self, tolerance_mm) -> bool:
        if not self._claim():
            return False
        try:
            shown = float(tolerance_mm)
        except (TypeError, ValueError):
            shown = float("nan")
        self.ctx.planning.set_tolerance_busy(True, shown)
        return True

    def _end_tolerance(self) -> None:
        self._release()
        self.ctx.planning.set_tolerance_busy(False)
