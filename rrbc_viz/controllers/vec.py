"""The Arm (VEC) tab's actions (`VecController`): VEC on or off, the registration points' tool orientations, a
target's leaned tool. Every number comes from `rrbc_core.session.vec_view`."""

from __future__ import annotations

import traceback
from typing import TYPE_CHECKING

from rrbc_core.errors import InputError
from rrbc_core.session import vec_view

from .. import vec_panel

if TYPE_CHECKING:
    from ..context import AppContext


class VecController:
    """`actions.VecActions`: what it shows is in the app's state (`vec_on`, `vec_target`, `vec_view`)."""

    def __init__(self, ctx: AppContext):
        self.ctx = ctx
        self._vec_panel_state: tuple | None = None  # what the tab's widgets last showed

    def set_vec(self, on: bool, client=None) -> None:
        """Compare with VEC (calibrate the arm on the current data) or stop."""
        with self.ctx.lock:
            self.ctx.state.vec_on = bool(on) and self.ctx.session.has_arm
            if on and not self.ctx.session.has_arm:
                self.ctx.message(vec_panel.NO_ARM, client, title="No arm to calibrate")
            self._vec_panel_state = None  # the box the user ticked may have to be unticked again
            with self.ctx.server.atomic():
                self.show(client)
                self.ctx.present.draw_scene(self.ctx.session.last)  # the bullseyes show (or drop) VEC's landing
                self.ctx.views.show_selection(self.ctx.session.last)

    def set_varied_registration(self, varied: bool, client=None):
        """Measure the registration points with leaned tools (True) or tool down."""
        with self.ctx.lock:
            return self.ctx.evaluate.apply(lambda s: vec_view.set_varied_registration(s, varied), client)

    def ask_target_tool(self, pid: str, tilt_deg: float, azimuth_deg: float = 0.0) -> None:
        """The user chose this tool on the sliders; `set_target_tool` applies it when the running computation ends.
        From now on the sliders are the user's: the server sends them no value (one it sent, even the value the user
        chose a moment ago, would set a slider back under keys still pressed) until a value is refused, another
        target is chosen or another cell is built. Takes no lock (one assignment): it is called while the previous
        value's computation holds it."""
        self.ctx.state.vec_tool_asked = (str(pid), float(tilt_deg), float(azimuth_deg))

    def set_target_tool(self, pid: str, tilt_deg: float, azimuth_deg: float = 0.0, client=None):
        """Reach target `pid` with its tool leaned tilt_deg towards azimuth_deg (degrees). A slider moved quickly
        sends many updates, each handled with the slider's latest value: one that changes nothing is not applied
        again (VEC, the heat map and the Monte Carlo would be recomputed for nothing)."""
        with self.ctx.lock:
            session = self.ctx.session
            if pid in session.layout["targets"].ids and session.tool_of("targets", pid) == (
                float(tilt_deg),
                float(azimuth_deg),
            ):
                self.ctx.state.vec_target = pid
                return session.last
            self.ctx.state.vec_target = pid
            out = self.ctx.evaluate.apply(lambda s: vec_view.set_target_tool(s, pid, tilt_deg, azimuth_deg), client)
            if out is None:  # refused: the sliders show the tool the session holds (unless a newer value waits)
                if self.ctx.state.vec_tool_asked == (pid, float(tilt_deg), float(azimuth_deg)):
                    self.ctx.state.vec_tool_asked = None
                with self.ctx.server.atomic():
                    self._sync_panel()
            return out

    def sync_vec_target(self, pid: str) -> None:
        """The tab's target choice changed: show that target's tool on the sliders."""
        with self.ctx.lock:
            self.ctx.state.vec_target = pid
            self.ctx.state.vec_tool_asked = None
            with self.ctx.server.atomic():
                self._sync_panel()

    def _sync_panel(self) -> None:
        s = self.ctx.session
        targets = tuple(s.layout["targets"].ids)
        if self.ctx.state.vec_target not in targets:
            self.ctx.state.vec_target = targets[0] if targets else ""
        tool: tuple[float, float] | None
        tool = s.tool_of("targets", self.ctx.state.vec_target) if self.ctx.state.vec_target else (0.0, 0.0)
        asked = self.ctx.state.vec_tool_asked
        if asked is not None and asked[0] == self.ctx.state.vec_target:
            tool = None  # the user moves the sliders: send them nothing
        elif asked is not None:  # the sliders now show another target: its tool, and that target's when it is back
            self.ctx.state.vec_tool_asked = None
        state = (
            targets,
            self.ctx.state.vec_target,
            tool,
            self.ctx.state.vec_on,
            getattr(s, "varied_registration", False),
            s.has_arm,
        )
        if state != self._vec_panel_state:  # a drag re-shows every frame: send the widgets only what changed
            self._vec_panel_state = state
            self.ctx.controls.vec.sync(*state)

    def show(self, client=None) -> None:
        """Refresh the tab (caller holds the lock, inside server.atomic()): VEC is computed only when on."""
        self.ctx.state.vec_on = self.ctx.state.vec_on and self.ctx.session.has_arm
        self._sync_panel()
        if not self.ctx.session.has_arm:
            self.ctx.state.vec_view, text = None, vec_panel.NO_ARM
        elif not self.ctx.state.vec_on:
            self.ctx.state.vec_view, text = None, "Tick **Compare with VEC** to calibrate the arm on the current data."
        else:
            try:
                self.ctx.state.vec_view = vec_view.vec_view(self.ctx.session)
                text = vec_panel.render(self.ctx.state.vec_view, self.ctx.state.vec_target)
            except InputError as exc:
                self.ctx.state.vec_view, text = None, f"VEC not computed: {exc}"
            except Exception as exc:  # noqa: BLE001 - keep serving
                traceback.print_exc()
                self.ctx.state.vec_view, text = None, f"VEC failed (internal error: {type(exc).__name__}: {exc})"
        self.ctx.controls.vec.show_table(text)
