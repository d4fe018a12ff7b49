"""The presenter: pushes an `Evaluation` to every scene view and panel (`Presenter.show`), the one place a change
of the session becomes pixels — the scene nodes (points, arrows, hull, regions, bullseye), the Explore tab's results,
the lesson's text, the selected point's card, the plug-in tabs (the Diagnose tab's stale mark), the Plan tab, the heat map, the error
slice and the check statistics. Callers hold the app's lock and an open `server.atomic()` block."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from rrbc_core.errors import InputError
from rrbc_core.session import figures
from rrbc_core.session.data_set import check_statistics
from rrbc_core.session.evaluation import Evaluation

from .. import tables, teaching
from ..colors import legend_markdown
from ..node_values import draws_sensor
from ..picture import ScenePicture, scene_extent, scene_picture

if TYPE_CHECKING:
    from ..context import AppContext


class Presenter:
    """`actions.PresentActions`: shows an evaluation everywhere (module docstring)."""

    def __init__(self, ctx: AppContext):
        self.ctx = ctx

    def show(self, ev: Evaluation, heat: bool = False, plan: bool = True) -> None:
        """Push `ev` to the scene and the panels. heat: refresh the heat map, the slice and the check statistics now
        (a drag's end, a setting); plan: recompute the Plan tab now (else it is marked stale until its next due
        refresh)."""
        ctx = self.ctx
        session = ctx.session
        ctx.vec.show()  # the Arm tab, and VEC's landings for the bullseye
        picture = self.draw_scene(ev)
        ctx.controls.show_headline(tables.headline(ev, session.kind))
        ctx.controls.explore.show_results(
            tables.scale_line(ctx.state.display.magnification) + tables.changes_line(picture.changed),
            tables.summary(ev, session.kind) + tables.stations_line(session),
            tables.target_table(ev),
        )
        if ctx.state.lesson_index is not None:
            ctx.controls.learn.show_text(teaching.render(ctx.state.lesson_index, ev, self.lesson_context()))
        ctx.state.heat_stale = True
        for tab in ctx.tabs.values():
            tab.evaluated(ev)  # the Diagnose tab's stale mark, …
        ctx.plan.refresh(session, due=plan)
        ctx.views.show_selection(ev)  # after the Plan tab: the card shows its coverage of the selected target
        if heat:
            self.update_heat()
            ctx.views.update_slice()
            self.update_checks()

    def draw_scene(self, ev: Evaluation) -> ScenePicture:
        """Draw `ev` in the 3-D scene as the state says (`picture.scene_picture`; caller holds the lock, inside
        atomic()); the bullseye shown is remembered in the state. Returns the picture drawn."""
        picture = scene_picture(self.ctx.session, self.ctx.state, ev)
        self.ctx.state.landing = picture.landing
        self.ctx.nodes.show(picture)
        lesson = self.ctx.state.lesson_index
        sight = lesson is not None and teaching.STEPS[lesson].sight_lines
        self.ctx.nodes.show_sight_lines(ev.targets.positions if sight else None)
        readings = lesson is not None and teaching.STEPS[lesson].readings
        magnification = self.ctx.state.display.magnification
        self.ctx.nodes.show_readings(teaching.fiducial_readings(ev, magnification) if readings else None)
        return picture

    def build_scene(self, ev: Evaluation) -> None:
        """Rebuild the 3-D scene for the session as it is now: a source loaded, the cell edited (caller holds the lock,
        inside atomic()). The extent the frames are sized from is taken from `ev`."""
        ctx = self.ctx
        ctx.state.extent_mm = scene_extent(ev)
        ctx.state.error_slice = None
        ctx.state.drag_baseline = None  # another cell: the last drag's changes say nothing here
        ctx.state.vec_tool_asked = None  # its tool sliders show its tools
        picture = scene_picture(ctx.session, ctx.state, ev)
        ctx.state.landing = picture.landing
        ctx.nodes.build(ctx.session, picture, ctx.loaded.mesh, ctx.state.layers)
        ctx.slice_node.clear()
        ctx.plan.build(ctx.session)

    def picture(self) -> ScenePicture:
        """What the scene shows now (the session's last evaluation in the current state)."""
        return scene_picture(self.ctx.session, self.ctx.state, self.ctx.session.last)

    def update_checks(self) -> None:
        """The Explore tab's check statistics and histogram (`data_set.check_statistics`: rrbc correct on the CSV
        download), refreshed when the heat map is (a drag's end, a setting, a load), not on every drag update."""
        session = self.ctx.session
        try:
            stats = check_statistics(session)
        except InputError:
            stats = None
        self.ctx.controls.checks.show(stats, session.settings.method.describe())

    def update_heat(self) -> None:
        """Recompute the heat map now if its layer is on (else leave it stale until shown)."""
        ctx = self.ctx
        st = ctx.state
        if not st.layers.get("heatmap"):
            return
        start = time.perf_counter()
        st.heat_map = figures.heat_map(ctx.session, ctx.heat_samples_per_target)
        st.heat_cost = time.perf_counter() - start
        st.heat_time = time.monotonic()
        st.heat_stale = False
        legend = ctx.nodes.update_heatmap(st.heat_map, ctx.session.last)
        ctx.controls.view.show_heat_legend("Nothing to show." if legend is None else legend_markdown(*legend))

    def lesson_context(self) -> teaching.LessonContext:
        ctx = self.ctx
        return teaching.LessonContext(
            ctx.session.kind,
            ctx.state.display.magnification,
            dict(ctx.session.regions),
            self.picture().frame_mag,
            sensor_drawn=draws_sensor(ctx.session),
            compact=ctx.state.presentation,
        )
