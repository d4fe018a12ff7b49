"""Drags, settings, display options and layers: every user change that moves a point, re-evaluates the session or
redraws it (`EvaluateController`, the `actions.EvaluateActions` of the app).

A fiducial drag, end to end: the browser moves the gizmo; viser calls the node's callback (`nodes.SceneNodes`),
which records the event in the latest-wins queue (`drag_queue.DragQueue`); its thread calls `handle_drag`, which
moves the point in the session (`ExplorerSession.move`: re-measured through the scene's measurement model, then
`session.evaluation.evaluate`) and hands the new `Evaluation` to the presenter (`controllers.present.Presenter.show`),
which pushes it to the scene nodes and every panel in one `server.atomic()` block. At the drag's end the Monte Carlo
is queued (`controllers.simulate`). A move the core refuses snaps the gizmo back to the last accepted place.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from rrbc_core.errors import InputError
from rrbc_core.session.evaluation import Evaluation
from rrbc_core.session.explorer import ExplorerSession

from ..drag_queue import DragQueue
from ..node_values import LAYERS, Display, gizmo_name

if TYPE_CHECKING:
    from ..context import AppContext

HEAT_INTERVAL_S = 0.3  # least time between heat-map recomputations while dragging
HEAT_LIVE_MAX_S = 0.05  # a heat map slower than this to compute is refreshed only when a drag ends
KINDS = {
    "target": "targets",
    "targets": "targets",
    "fiducial": "fiducials",
    "fiducials": "fiducials",
    "registration": "registration",
}


class EvaluateController:
    """Moves points and changes settings, display options and layers (module docstring)."""

    def __init__(self, ctx: AppContext):
        self.ctx = ctx
        self._refused: set = set()  # (kind, id) whose refusal was already announced in the current drag
        # gizmo events go through a latest-wins queue handled by one thread (drag_queue): never a backlog
        self.drags = DragQueue(self._on_gizmo, name="rrbc-drags")

    def stop(self) -> None:
        self.drags.stop()

    # ------------------------------------------------------------------------------------------- dragging
    def wait_drags(self, timeout: float = 10.0) -> bool:
        """Block until every drag event from the browser has been handled (True if within `timeout` s)."""
        return self.drags.wait_idle(timeout)

    def _on_gizmo(self, kind: str, pid: str, position, phase: str, client=None) -> None:
        try:
            self.handle_drag(kind, pid, position, phase, client=client)
        except Exception:  # noqa: BLE001 - keep the server alive; say so
            traceback.print_exc()
            self.ctx.message("internal error while dragging (see the server log)", client)

    def handle_drag(self, kind: str, pid: str, position, phase: str = "update", client=None) -> Evaluation | None:
        """Move point `pid` of `kind` ("targets" or "fiducials"; robot frame, mm) during a drag `phase`
        ("start", "update" or "end") and update every node: what the drag queue calls. Returns the new
        Evaluation, or None when the core refuses the move (the gizmo snaps back and a notification says why).
        The heat map is refreshed at most every HEAT_INTERVAL_S while dragging and at "end"; Monte Carlo is
        queued at "end"."""
        ctx = self.ctx
        kind = KINDS.get(kind, kind)
        key = (kind, pid)
        with ctx.lock:
            session = ctx.session
            ctx.state.drag_active = phase != "end"  # the bullseye keeps its scale until the drag ends
            if phase == "end":  # the drag is over: the app places the handle again (where the session has the point)
                ctx.nodes.drag_ended(kind, pid)
            if phase == "start":
                self._refused.discard(key)
                t = session.last.targets  # a fiducial's drag marks the targets whose correction it changes most
                ctx.state.drag_baseline = (tuple(t.ids), t.correction_robot.copy()) if kind == "fiducials" else None
                return session.last
            group = session.layout.get(kind)
            before = None
            if group is not None and pid in group.ids:
                before = np.array(group.positions[group.index(pid)], float)
            try:
                ev = session.move(kind, pid, position, live=phase == "update")  # exact again at the end
            except InputError as exc:
                self._refuse(key, before, str(exc), client, phase)
                return None
            end = phase == "end"
            st = ctx.state
            heat_due = end or (
                st.layers.get("heatmap")
                and st.heat_cost <= HEAT_LIVE_MAX_S
                and time.monotonic() - st.heat_time >= HEAT_INTERVAL_S
            )
            slow_plan = ctx.plan.slow()
            plan_due = not slow_plan and (end or ctx.plan.live_due())
            with ctx.server.atomic():
                ctx.present.show(ev, heat=bool(heat_due), plan=plan_due)
            if slow_plan:  # a slow scene: planning follows in the background, the drag does not wait
                ctx.plan.request_background(session)
            if end and key in self._refused:
                # a move in this drag was refused: the tab that dragged may have kept its handle where the
                # refusal happened (its own drag state wins over messages received mid-drag); send the
                # session's place again now that the drag is over
                ctx.nodes.resnap(kind, pid)
            if end:
                self._refused.discard(key)
                if kind == "targets":  # a target dragged out of the frame is brought back into every tab's view,
                    # with its landing bullseye (ring included) when it shows one, clear of the view's edges
                    ctx.camera.keep_in_view(_target_and_bullseye(ev, pid, st.landing), ctx.views.work_points())
        if end:
            ctx.montecarlo.request()
        return ev

    def _refuse(self, key, before, message: str, client, phase: str) -> None:
        kind, pid = key
        ctx = self.ctx
        session = ctx.session
        if before is not None:
            group = session.layout.get(kind)
            if group is not None and not np.allclose(group.positions[group.index(pid)], before):
                try:  # the core changed the layout before refusing: put the point back
                    session.move(kind, pid, before)
                except InputError:
                    pass
            ctx.nodes.snap(kind, pid, before)
        if key not in self._refused:
            ctx.message(message, client, title=f"Cannot move {pid}")
            self._refused.add(key)
        if phase == "end":
            self._refused.discard(key)

    # ------------------------------------------------------------------------------------------- settings
    def toggle_fiducial(self, pid: str, client=None) -> Evaluation | None:
        """Exclude an included fiducial or include an excluded one (what clicking its sphere does)."""
        with self.ctx.lock:
            excluded = pid in self.ctx.session.settings.excluded
            return self.apply(lambda s: s.set_excluded(pid, not excluded), client)

    def change_settings(self, client=None, **changes: Any) -> Evaluation | None:
        """Change session settings (`Settings` fields or method options by flag); None (and a message) if refused."""
        with self.ctx.lock:
            return self.apply(lambda s: s.update(**changes), client)

    def new_seed(self, client=None) -> Evaluation | None:
        with self.ctx.lock:
            seed = int(np.random.default_rng().integers(1, 2**31 - 1))
            return self.apply(lambda s: s.update(seed=seed), client)

    def apply(self, change: Callable[[ExplorerSession], Evaluation], client=None) -> Evaluation | None:
        """Run a change of the session; show the new evaluation (or say why it was refused) and queue the Monte
        Carlo."""
        ctx = self.ctx
        with ctx.lock:
            try:
                ev = change(ctx.session)
            except InputError as exc:
                ctx.message(str(exc), client, title="Setting refused")
                ev = None
            except Exception as exc:  # noqa: BLE001 - keep serving; the session keeps its last evaluation
                traceback.print_exc()
                ctx.message(f"internal error: {type(exc).__name__}: {exc}", client, title="Setting failed")
                ev = None
            with ctx.server.atomic():
                ctx.controls.sync_settings(ctx.session.settings, ctx.session.kind)
                if ev is not None:
                    ctx.present.show(ev, heat=True)
        if ev is not None:
            ctx.montecarlo.request()
        return ev

    def set_display(self, client=None, **changes: Any) -> None:
        """Display-only options (Display fields): magnification, marker_mm, region_zoom, heat_value, slice_value,
        slice_axis, slice_offset, bound_scale."""
        from ..controls import HEAT_CHOICES
        from ..picture import BOUND_SCALES, CHECK_ERROR_CHOICES

        ctx = self.ctx
        with ctx.lock:
            unknown = sorted(set(changes) - set(Display.__dataclass_fields__))
            if unknown:
                raise InputError(
                    f"unknown display option(s) {', '.join(unknown)}: {', '.join(Display.__dataclass_fields__)}"
                )
            new = replace(ctx.state.display, **changes)
            heat_values = [v for _, v in HEAT_CHOICES[ctx.session.kind]]
            if new.heat_value not in heat_values:
                raise InputError(f"heat_value must be one of {', '.join(heat_values)} here, got {new.heat_value!r}")
            ctx.views.check_slice_display(new)
            if new.check_error not in CHECK_ERROR_CHOICES:
                raise InputError(
                    f"check_error must be one of {', '.join(CHECK_ERROR_CHOICES)}, got {new.check_error!r}"
                )
            if new.bound_scale not in BOUND_SCALES:
                raise InputError(f"bound_scale must be one of {', '.join(BOUND_SCALES)}, got {new.bound_scale!r}")
            if not (new.magnification > 0 and new.marker_mm > 0 and new.region_zoom > 0):
                raise InputError("magnification, marker_mm and region_zoom must be > 0")
            ctx.state.display = new
            with ctx.server.atomic():
                ctx.nodes.set_display(new)
                ctx.controls.sync_display(new, ctx.session.kind)
                heat = any(k in changes for k in ("region_zoom", "heat_value"))
                ctx.present.show(ctx.session.last, heat=heat)
                for tab in ctx.tabs.values():
                    tab.display_changed()
                if any(k.startswith("slice_") for k in changes):
                    ctx.views.update_slice()

    def set_layer(self, layer: str, visible: bool) -> None:
        """Show or hide a layer (nodes.LAYERS) in the scene and on its checkbox."""
        if layer not in LAYERS:
            raise InputError(f"unknown layer '{layer}': {', '.join(LAYERS)}")
        ctx = self.ctx
        with ctx.lock:
            ctx.state.layers[layer] = bool(visible)
            with ctx.server.atomic():
                ctx.nodes.set_layer(layer, visible)
                ctx.controls.sync_layers({layer: bool(visible)})
                if layer == "heatmap" and visible and (ctx.state.heat_stale or ctx.state.heat_map is None):
                    ctx.present.update_heat()
                if layer == "slice" and visible:
                    ctx.views.update_slice()

    # ----------------------------------------------------------------------------------------------- handles
    def gizmo(self, kind: str, pid: str) -> viser.TransformControlsHandle:
        """The drag gizmo of a point (tests and scripts)."""
        return self.ctx.nodes.gizmo(KINDS.get(kind, kind), pid)

    @staticmethod
    def gizmo_name(kind: str, pid: str) -> str:
        return gizmo_name(KINDS.get(kind, kind), pid)


def _target_and_bullseye(ev, pid: str, landing) -> np.ndarray:
    """(K, 3) robot frame mm: target `pid`'s position and, when `landing` (a `LandingDisplay`) is its bullseye, the
    bullseye's centre, landings and the ends of its ring along x and y."""
    pts = [np.asarray(ev.targets.positions[ev.targets.ids.index(pid)], float)]
    if landing is not None and landing.target == pid:
        r = float(landing.ring_mm) * float(landing.scale)
        centre = np.asarray(landing.anchor, float)
        pts += [centre, np.asarray(landing.rigid, float), np.asarray(landing.rrbc, float)]
        pts += [
            centre + d for d in (np.array([r, 0, 0]), np.array([-r, 0, 0]), np.array([0, r, 0]), np.array([0, -r, 0]))
        ]
    return np.vstack(pts)
