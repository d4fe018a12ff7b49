"""The Arm (VEC) tab: model-based calibration beside rigid and RRBC, and a target reached with a leaned tool.

Formatting and widgets only: every number comes from `rrbc_core.session.vec_view` (`ExplorerSession.vec_view`,
`set_target_tool`, `set_varied_registration`); lengths in mm, angles in degrees.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import viser

from rrbc_core.session.tools import TILT_MAX_DEG, VARIED_TILT_DEG
from rrbc_core.session.vec_view import VecView

from .syncing import LatestOnly, clamped

if TYPE_CHECKING:
    from .actions import Actions
    from .syncing import Syncing

INTRO = (
    "**Volumetric error compensation (VEC)** models the arm: its kinematic (DH) errors are identified from the "
    "registration points and fiducials with the joint angles the arm reached them in, and each target gets the "
    "command that puts the identified arm on it. RRBC needs no model but corrects by position alone. Lean a "
    "target's tool below: the arm reaches the same place in another configuration, with another error — RRBC's "
    "command does not change, VEC's follows (if it was calibrated in varied orientations)."
)
NO_ARM = (
    "This source has no kinematic arm error (measured data, or a scene whose robot error model has no "
    "`kinematic` term): there is no arm to calibrate here. Load the default scene to try it."
)


def render(view: VecView | None, selected: str | None = None) -> str:
    """Markdown: the per-target errors of rigid, RRBC and VEC, their RMS and what VEC identified."""
    if view is None:
        return NO_ARM
    rows = [
        "| target | tool tilt, towards | rigid | RRBC | VEC |",
        "|---|---|---:|---:|---:|",
    ]
    for i, pid in enumerate(view.ids):
        tilt, az = view.tools[i]
        tool = "down" if tilt == 0 else f"{tilt:.0f}°, {az:.0f}°"
        name = f"**{pid}**" if pid == selected else pid
        rows.append(
            f"| {name} | {tool} | {view.error_rigid[i]:.3f} | {view.error_rrbc[i]:.3f} | {view.error_vec[i]:.3f} |"
        )
    r = view.rmst_mm

    def f(v):
        return "–" if v is None else f"{v:.3f}"

    rows.append(f"| **RMS** | | **{f(r['rigid'])}** | **{f(r['rrbc'])}** | **{f(r['vec'])}** |")
    return (
        "Error at each target against the command that truly reaches it (mm):\n\n"
        + "\n".join(rows)
        + f"\n\nVEC identified {view.rank} combinations of the arm's parameters and the sensor-to-robot transform "
        f"from {view.poses} poses (the same registration points and fiducials RRBC uses)."
    )


class VecPanel:
    """Arm (VEC) tab: show VEC, the registration points' orientations, a target's tool, and the table."""

    def __init__(self, gui, app: Actions, syncing: Syncing):
        self.app, self.syncing = app, syncing
        gui.add_markdown(INTRO)
        self.show = gui.add_checkbox("Compare with VEC", False, hint="Calibrate the arm and predict every target")
        self.varied = gui.add_checkbox(
            "Registration points in varied orientations",
            False,
            hint=f"Measure the registration points with the tool leaned {VARIED_TILT_DEG:g}° in varied directions",
        )
        self.target = gui.add_dropdown("Target", ("",), initial_value="")
        self.tilt = gui.add_slider("Tool tilt (°)", 0.0, TILT_MAX_DEG, 1.0, 0.0)
        self.azimuth = gui.add_slider("Tilt towards (° from x)", -180.0, 180.0, 5.0, 0.0)
        self.vec_table = gui.add_markdown("")

        @self.show.on_update
        def _(event: viser.GuiEvent) -> None:
            if not syncing.on:
                app.vec.set_vec(bool(self.show.value), client=event.client)

        @self.varied.on_update
        def _(event: viser.GuiEvent) -> None:
            if not syncing.on:
                app.vec.set_varied_registration(bool(self.varied.value), client=event.client)

        def apply_tool(client) -> None:  # the sliders' values when it runs: the newest the user chose
            if self.target.value:
                app.vec.set_target_tool(self.target.value, clamped(self.tilt), clamped(self.azimuth), client=client)

        latest = LatestOnly(apply_tool)  # arrow keys send an update per degree: only the newest is computed

        def on_tool(event: viser.GuiEvent) -> None:
            if not syncing.on and self.target.value:
                app.vec.ask_target_tool(self.target.value, clamped(self.tilt), clamped(self.azimuth))
                latest(event.client)

        self.tilt.on_update(on_tool)
        self.azimuth.on_update(on_tool)

        @self.target.on_update
        def _(event: viser.GuiEvent) -> None:
            if not syncing.on:
                app.vec.sync_vec_target(self.target.value)

    def show_table(self, markdown: str) -> None:
        """VEC's table beside rigid and RRBC (`render`), or why there is none."""
        self.vec_table.content = markdown

    def sync(self, targets: tuple, target: str, tool: tuple | None, on: bool, varied: bool, has_arm: bool) -> None:
        """Show the state the app holds (under the syncing flag: the callbacks do nothing)."""
        with self.syncing.quiet():
            self.show.value, self.varied.value = bool(on), bool(varied)
            self.target.options = tuple(targets) or ("",)
            self.target.value = target if target in targets else (targets[0] if targets else "")
            if tool is not None:  # None: the user moves the sliders; a value sent now could set them back
                self.tilt.value, self.azimuth.value = float(tool[0]), float(tool[1])
            for h in (self.show, self.varied, self.target, self.tilt, self.azimuth):
                h.disabled = not has_arm
            for h in (self.varied, self.target, self.tilt, self.azimuth):
                h.visible = bool(on)
