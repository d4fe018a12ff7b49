"""In-process tests of the app's Plan tab (rrbc_viz.planning_panel): a real viser server, no browser.

What a user sees is read off the handles: the Plan tab's markdown, the colours of the regions of variability and
their halos, the ghost spheres and their labels, the fiducial gizmos. Buttons are pressed through their viser
callbacks, drags go through viser's transform-controls handlers (as in tests/viz/test_viz.py).
"""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

from rrbc_core.session import planning_view
from rrbc_viz import colors
from rrbc_viz.controllers.plan import PLAN_INTERVAL_S
from rrbc_viz.planning_panel import rmst_line
from rrbc_viz.serve import serve
from tests.paths import EXAMPLE_CSV, ROOT
from tests.viz.helpers import _gizmo_drag, _press

F1_AWAY = [400.0, -60.0, 0.0]  # F1 (table corner next to H1) slid in under the plate: H1's region leaves the hull
_RMST = re.compile(r"Predicted RMST: rigid \*\*([0-9.]+) ± ([0-9.]+) mm\*\*, RRBC \*\*([0-9.]+) ± ([0-9.]+) mm\*\*")


def settled(app):
    """Wait for background planning (used when an update is slow, e.g. on a loaded machine); returns app."""
    assert app.plan.wait_idle(30)
    return app


def shown_rmst(app) -> tuple[float, float, float, float]:
    """(rigid, rigid std, RRBC, RRBC std) mm as the Plan tab says them."""
    m = _RMST.search(app.planning.info.content)
    assert m, app.planning.info.content
    return tuple(float(x) for x in m.groups())


def shown_coverage(app) -> dict[str, str]:
    return dict(re.findall(r"\| (H\d) \| (?:inside|⚠ outside) \| ([0-9.]+ %)", app.planning.coverage_md.content))


def test_plan_tab_shows_the_sessions_planning(app):
    st = planning_view.planning_state(app.session)
    assert app.state.plan is st
    assert rmst_line(st.predicted) in app.planning.info.content
    p = st.predicted
    assert shown_rmst(app) == pytest.approx((p.rigid_mm, p.rigid_std_mm, p.rrbc_mm, p.rrbc_std_mm), abs=5e-4)
    assert shown_coverage(app) == {pid: "100 %" for pid in st.target_ids}
    assert f"**{len(st.target_ids)} of {len(st.target_ids)} targets**" in app.planning.info.content
    assert "Coverage" in app.planning.legend.content and "0 % (red)" in app.planning.legend.content
    assert "⚠ The session uses" not in app.planning.info.content
    app.controls.explore.interpolation.value = "tps"  # not the planner's model: the tab says so (numbers unchanged)
    assert "⚠ The session uses least-squares + tps" in app.planning.info.content
    assert shown_rmst(app) == pytest.approx((p.rigid_mm, p.rigid_std_mm, p.rrbc_mm, p.rrbc_std_mm), abs=5e-4)


def test_coverage_colours_follow_a_fiducial_drag_out_of_the_hull(app):
    panel = app.planning
    region = lambda pid: app.nodes.handle(f"/regions/{pid}")
    assert (
        tuple(region("H1").color) == colors.REGION and not app.nodes.handle("/targets/H1/gizmo/coverage").visible
    )  # toggle off
    panel.colour.value = True  # the user ticks "Colour regions by coverage"
    full = colors.coverage_color(1.0)
    for pid in app.session.last.targets.ids:
        assert (
            tuple(region(pid).color) == full and tuple(app.nodes.handle(f"/targets/{pid}/gizmo/coverage").color) == full
        )
        assert app.nodes.handle(f"/targets/{pid}/gizmo/coverage").visible
    # drag F1 away (start, updates, end through viser's gizmo handlers): H1's region leaves the hull
    p0 = np.array(app.evaluate.gizmo("fiducials", "F1").position, float)
    _gizmo_drag(app, "fiducials", "F1", [p0 + (np.asarray(F1_AWAY) - p0) * f for f in (0.3, 0.7, 1.0)])
    settled(app)
    st = planning_view.planning_state(app.session)
    assert st.coverage_of("H1") < 1.0
    c = colors.coverage_color(st.coverage_of("H1"))
    assert c != full
    assert tuple(region("H1").color) == c and tuple(app.nodes.handle("/targets/H1/gizmo/coverage").color) == c
    assert tuple(region("H5").color) == full  # far from F1: still covered
    assert shown_coverage(app)["H1"] != "100 %" and f"⚠ H1 {shown_coverage(app)['H1']}" in panel.info.content
    assert "⚠" in panel.coverage_md.content.split("| H1 |")[1].split("\n")[0]
    # toggle off: the regions get their own colour back, the halos go
    panel.colour.value = False
    assert tuple(region("H1").color) == colors.REGION and not app.nodes.handle("/targets/H1/gizmo/coverage").visible


def test_predicted_rmst_text_changes_while_dragging(app):
    before = app.planning.info.content
    rmst0 = shown_rmst(app)
    app.evaluate.handle_drag("fiducials", "F1", app.evaluate.gizmo("fiducials", "F1").position, "start")
    time.sleep(PLAN_INTERVAL_S + 0.05)  # a refresh is due: the next drag update recomputes (no drag end needed)
    ev = app.evaluate.handle_drag("fiducials", "F1", F1_AWAY, "update")
    assert ev is not None
    settled(app)
    st = planning_view.planning_state(app.session)
    assert app.state.plan is st and app.planning.info.content != before
    assert shown_rmst(app) != rmst0
    p = st.predicted
    assert shown_rmst(app) == pytest.approx((p.rigid_mm, p.rigid_std_mm, p.rrbc_mm, p.rrbc_std_mm), abs=5e-4)
    # an update right after is throttled (marked stale), the drag's end always refreshes
    app.evaluate.handle_drag("fiducials", "F1", np.add(F1_AWAY, [0.0, 0.0, 10.0]), "update")
    app.evaluate.handle_drag("fiducials", "F1", np.add(F1_AWAY, [0.0, 0.0, 10.0]), "end")
    settled(app)
    assert app.state.plan is planning_view.planning_state(app.session) and not app.state.plan_stale


def test_suggest_shows_ghosts_accept_adds_fiducials_and_lowers_the_prediction(app):
    panel = app.planning
    app.evaluate.handle_drag("fiducials", "F1", F1_AWAY, "end")
    settled(app)
    cov0 = planning_view.planning_state(app.session).coverage
    rmst0 = shown_rmst(app)
    assert panel.accept_button.disabled and panel.clear_button.disabled and not panel.ghosts
    panel.k.value = 3
    _press(panel.suggest_button)
    result = app.session.suggestion
    assert result is not None and len(result.suggested_ids) == 3
    # ghost spheres at the suggested places, labelled +1 … +3 with the candidate's id
    assert len(panel.ghosts) == 3
    for i, (cid, p) in enumerate(zip(result.suggested_ids, result.suggested)):
        ghost = app.server.scene.get_handle_by_name(f"/plan/ghosts/{i}")
        assert ghost is panel.ghosts[i]
        np.testing.assert_allclose(ghost.position, p)
        assert ghost.opacity is not None and ghost.opacity < 1 and tuple(ghost.color) == colors.GHOST
        assert panel.ghost_labels[i].text == f"+{i + 1} {cid}"
    text = panel.suggestion_md.content
    assert "**Suggested: 3 fiducials**" in text and all(cid in text for cid in result.suggested_ids)
    assert f"RRBC {result.predicted.rrbc_mm:.3f} → **{result.predicted_after.rrbc_mm:.3f}" in text
    assert not panel.accept_button.disabled
    n = len(app.session.layout["fiducials"].ids)

    _press(panel.accept_button)
    ev = app.session.last
    assert ev.fiducial_ids[n:] == tuple(result.suggested_ids)
    for cid, p in zip(result.suggested_ids, result.suggested):  # real, draggable fiducials now
        np.testing.assert_allclose(app.evaluate.gizmo("fiducials", cid).position, p)
        assert app.server.scene.get_handle_by_name(f"/fiducials/{cid}/gizmo/sphere") is not None
    assert not panel.ghosts and app.server.scene.get_handle_by_name("/plan/ghosts/0") is None
    assert panel.accept_button.disabled
    st = planning_view.planning_state(app.session)
    np.testing.assert_array_equal(st.coverage, np.asarray(result.coverage_after))
    for pid, c in zip(st.target_ids, result.coverage_after):
        if c >= 1.0:
            assert shown_coverage(app)[pid] == "100 %"
    assert cov0[0] < 1.0 and result.coverage_after[0] == 1.0  # the plan covers H1 again …
    assert shown_coverage(app)["H1"] == "100 %"  # … and the tab says so once accepted
    rmst1 = shown_rmst(app)
    assert rmst1[2] < rmst0[2], (rmst0, rmst1)  # predicted RMST with RRBC, as the tab says it, went down
    assert f"{rmst0[2]:.3f} → {rmst1[2]:.3f} mm" in app.last_message
    assert f"over {len(ev.fiducial_ids)} of {len(ev.fiducial_ids)} fiducials" in app.controls.explore.summary.content
    assert app.montecarlo.runner.wait_idle(60)  # accepting queued a Monte Carlo run of the new layout
    # an accepted fiducial drags like any other
    cid = result.suggested_ids[0]
    assert app.evaluate.handle_drag("fiducials", cid, np.add(result.suggested[0], [0.0, 0.0, 5.0]), "end") is not None


def test_accept_is_undone_by_the_plan_tabs_undo(app):
    """Accept is one step of the edit history (issue 25): Undo in the Plan tab takes the fiducials away again and
    the prediction back; Redo (File tab) brings them back."""
    panel = app.planning
    assert panel.undo_button.disabled
    ids0 = app.session.layout["fiducials"].ids
    rmst0 = shown_rmst(app)
    panel.k.value = 2
    _press(panel.suggest_button)
    new = app.session.suggestion.suggested_ids
    _press(panel.accept_button)
    assert app.session.layout["fiducials"].ids == ids0 + tuple(new) and not panel.undo_button.disabled
    assert "Undo takes them away" in app.last_message
    _press(panel.undo_button)
    assert app.session.layout["fiducials"].ids == ids0
    assert all(app.server.scene.get_handle_by_name(f"/fiducials/{c}/gizmo/sphere") is None for c in new)
    settled(app)
    assert shown_rmst(app) == rmst0 and panel.undo_button.disabled
    _press(app.controls.authoring.redo)
    assert app.session.layout["fiducials"].ids == ids0 + tuple(new)


def test_a_stale_suggestion_cannot_be_accepted(app):
    """A suggestion is never predicted worse than the fiducials it was made for; once they change (a drag) it
    may be, so Accept is offered only again after a new Suggest."""
    panel = app.planning
    panel.k.value = 2
    _press(panel.suggest_button)
    assert not panel.accept_button.disabled
    app.evaluate.handle_drag("fiducials", "F2", [300.0, 230.0, 10.0], "end")
    settled(app)
    assert panel.accept_button.disabled and "press Suggest again" in panel.suggestion_md.content
    _press(panel.suggest_button)
    assert not panel.accept_button.disabled


def test_clear_and_refusals_are_visible(app):
    panel = app.planning
    assert app.plan.accept_suggestions() is None and "Suggest first" in app.last_message  # nothing to accept
    panel.k.value = 2
    _press(panel.suggest_button)
    assert len(panel.ghosts) == 2 and not panel.clear_button.disabled
    _press(panel.clear_button)
    assert not panel.ghosts and app.session.suggestion is None
    assert app.server.scene.get_handle_by_name("/plan/ghosts/0") is None
    assert "Press **Suggest**" in panel.suggestion_md.content
    # a suggestion made before a drag says so
    _press(panel.suggest_button)
    app.evaluate.handle_drag("fiducials", "F2", [300.0, 230.0, 10.0], "end")
    settled(app)
    assert "press Suggest again" in panel.suggestion_md.content


def test_measured_data_get_coverage_planning_and_a_scene_brings_the_full_plan_back():
    app = serve(EXAMPLE_CSV, port=0)
    try:
        panel = app.planning
        assert "no error model" in panel.info.content and "Predicted RMST" not in panel.info.content
        assert panel.accept_button.disabled and panel.colour.disabled and not panel.suggest_button.disabled
        assert app.plan.suggest_fiducials(2) is not None and len(panel.ghosts) == 2
        # loading a scene brings planning with an error model back
        assert app.files.load(ROOT / "scenes" / "peg_in_hole_cell.toml")
        assert not panel.suggest_button.disabled and "Predicted RMST" in panel.info.content
        ids = app.session.layout["targets"].ids
        assert all(app.nodes.handle(f"/targets/{pid}/gizmo/coverage") is not None for pid in ids)
    finally:
        app.stop()


def test_a_slow_scene_plans_in_the_background_during_drags(app):
    rmst0 = shown_rmst(app)
    app.plan.cost_s = 10.0  # as if each planning update took 10 s (a large scene): drags must not wait for it
    assert app.plan.slow() and not app.plan.live_due()
    p0 = np.array(app.evaluate.gizmo("fiducials", "F1").position, float)
    app.evaluate.handle_drag("fiducials", "F1", p0, "start")
    t0 = time.perf_counter()
    assert app.evaluate.handle_drag("fiducials", "F1", F1_AWAY, "update") is not None
    assert app.state.plan_stale  # the tab still shows the old numbers, marked as following
    assert app.plan.wait_idle(30)
    st = planning_view.planning_state(app.session)
    assert app.state.plan is st and not app.state.plan_stale  # the worker's result for the dragged layout is shown
    assert shown_rmst(app) != rmst0 and shown_coverage(app)["H1"] != "100 %"
    assert app.plan.cost_s < 10.0  # the worker measured the real cost
    app.plan.cost_s = 10.0
    app.evaluate.handle_drag("fiducials", "F1", p0, "end")  # the end too goes to the background
    assert app.plan.wait_idle(30)
    assert shown_rmst(app) == rmst0 and shown_coverage(app)["H1"] == "100 %"
    assert time.perf_counter() - t0 < 30


def test_a_layout_the_planner_refuses_gives_a_message_not_a_crash(app):
    panel = app.planning
    f1 = np.array(app.evaluate.gizmo("fiducials", "F1").position, float)
    assert app.evaluate.handle_drag("fiducials", "F2", f1, "end") is not None  # two fiducials at one place
    settled(app)
    assert panel.info.content.startswith("⚠ Cannot plan:") and "coincide" in panel.info.content
    assert app.state.plan is None and panel.coverage_md.content == ""
    assert app.plan.suggest_fiducials(2) is None
    assert "coincide" in app.last_message and panel.suggestion_md.content.startswith("⚠ Cannot suggest:")
    assert not panel.ghosts and not panel.suggest_button.disabled  # the user can fix it and try again
    app.evaluate.handle_drag("fiducials", "F2", [300.0, 230.0, 0.0], "end")
    settled(app)
    assert "Predicted RMST: rigid" in panel.info.content and app.state.plan is not None
    assert len(shown_coverage(app)) == 8


def test_the_plan_tab_plans_to_a_tolerance_as_rrbc_plan_does_and_its_fiducials_can_be_used(app, monkeypatch):
    """One answer: the tab's plan to a tolerance is `rrbc plan --tolerance`'s (the same function on the scene as the
    app has it: unedited, the scene as written), its text is the command's; Use puts its fiducials in the cell, whose
    targets' bounds over the plan's fresh draws are then the plan's (all under the tolerance), and Undo brings the
    former fiducials back."""
    import copy
    import json
    import subprocess

    from rrbc_core.io.scene import default_scene_path
    from rrbc_core.session.tolerance_plan import drawn_bounds, fresh_seeds, tolerance_text
    from tests.paths import RRBC

    panel = app.planning
    before = tuple(app.session.layout["fiducials"].ids)
    panel.tolerance.value = 0.5
    shown = []  # the tab says how far the plan has come at each of its steps
    monkeypatch.setattr(panel, "show_tolerance_progress", lambda tol, label: shown.append((tol, label)))
    _press(panel.tolerance_button)
    plan = app.state.tolerance_plan
    assert shown and shown[0][0] == 0.5 and shown[-1][1].startswith(f"{len(plan.fiducial_ids)} fiducials"), shown
    assert plan is not None and plan.met, panel.tolerance_md.content
    cli = subprocess.run(
        [*RRBC, "plan", str(default_scene_path()), "--tolerance", "0.5", "--json"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert cli.returncode == 0, cli.stderr
    assert json.loads(cli.stdout) == json.loads(json.dumps(plan.to_json()))
    assert tolerance_text(plan).splitlines()[0] in panel.tolerance_md.content
    assert len(panel.ghosts) == len(plan.fiducial_ids) and not panel.use_plan_button.disabled
    _press(panel.use_plan_button)
    assert app.state.tolerance_plan is None and not panel.ghosts and panel.use_plan_button.disabled
    assert tuple(app.session.layout["fiducials"].ids) == plan.fiducial_ids
    assert app.session.last.bounds is not None
    # the plan's bounds are the medians over its fresh draws of the cell as it now is
    again = drawn_bounds(copy.copy(app.session), fresh_seeds(app.session.settings.seed))
    np.testing.assert_allclose(again.bound95_mm, plan.bound95_mm, rtol=1e-9)
    assert np.all(again.bound95_mm < 0.5)
    _press(panel.undo_button)
    assert tuple(app.session.layout["fiducials"].ids) == before


def test_a_tolerance_that_cannot_be_is_said_in_the_tab_and_measured_data_cannot_plan_to_one(app, measured):
    panel = app.planning
    assert app.plan.plan_tolerance(0.0) is None
    assert "Cannot plan" in panel.tolerance_md.content and app.state.tolerance_plan is None
    assert measured.plan.plan_tolerance(0.5) is None
    assert not measured.planning.tolerance_button.visible
