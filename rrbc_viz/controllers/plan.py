"""The Plan tab's actions (`PlanController`): coverage colours, suggestions (the planner on a snapshot of the session,
outside the app's lock) and accepting them (one step of the session's edit history: Undo takes them away)."""

from __future__ import annotations

import copy
import traceback
from typing import TYPE_CHECKING

from rrbc_core.errors import InputError
from rrbc_core.session import planning_view
from rrbc_core.session.evaluation import Evaluation

from ..syncing import clamped

if TYPE_CHECKING:
    from ..context import AppContext


class PlanController:
    """`actions.PlanActions` (module docstring)."""

    def __init__(self, ctx: AppContext):
        self.ctx = ctx

    # ------------------------------------------------------------------------------------------- planning
    def set_coverage_colours(self, on: bool) -> None:
        """Colour each target's region (and a halo around it) by coverage, or back to the region colour."""
        with self.ctx.lock:
            self.ctx.planning.sync_colour(on)
            with self.ctx.server.atomic():
                self.ctx.planning.apply_colours(self.ctx.session)

    def suggest_fiducials(self, k: int | None = None, client=None, seed: int | None = None):
        """Suggest `k` (default: the tab's K) more fiducials for the session as it is now and show them as ghost
        spheres. The planner runs on a snapshot of the session outside the app's lock (a drag meanwhile goes on;
        the suggestion is then marked as made for the old layout). Returns the planning.PlanResult, or None (and
        a visible message) when refused."""
        panel = self.ctx.planning
        with self.ctx.lock:
            session = self.ctx.session
            k = int(clamped(panel.k)) if k is None else k
            if session.kind != "scene":  # measured data: coverage first, then spread (no error model needed)
                try:
                    plan = planning_view.coverage_plan(session, k)
                except InputError as exc:
                    self.ctx.message(str(exc), client, title="Cannot plan")
                    return None
                with self.ctx.server.atomic():
                    panel.show_coverage_suggestion(plan)
                return plan
            if not panel.begin():
                self.ctx.message("a suggestion is already being computed", client, title="Planning")
                return None
            snapshot = copy.copy(session)  # settings and layout are immutable values
        result, error = None, None
        try:
            result = planning_view.suggest_fiducials(snapshot, k, seed=seed, progress=panel.progress)
        except InputError as exc:
            error = str(exc)
        except Exception as exc:  # noqa: BLE001 - keep serving
            traceback.print_exc()
            error = f"internal error: {type(exc).__name__}: {exc}"
        with self.ctx.lock:
            panel.end(self.ctx.session)
            if self.ctx.session is not session:  # another source was loaded meanwhile
                return None
            if error is not None:
                panel.show_refusal(error)
                self.ctx.message(error, client, title="Cannot plan")
                return None
            planning_view.adopt_suggestion(session, snapshot)
            with self.ctx.server.atomic():
                panel.show_suggestion(session, result)
        return result

    def accept_suggestions(self, client=None) -> Evaluation | None:
        """Add the suggested fiducials to the cell (measured from the error model), remove the ghosts, update
        everything (planning included). None, and a message, when there is nothing to accept."""
        with self.ctx.lock:
            before = self.ctx.planning.state
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
            after = self.ctx.planning.state
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
            with self.ctx.server.atomic():
                self.ctx.planning.remove_ghosts(prompt=True)
