"""The Arm (VEC) tab in the running app (issue 15, item 4): VEC's errors beside rigid and RRBC, registration points in
varied orientations, a target's leaned tool — every number the tab shows equals the session's `vec_view`."""

import numpy as np

from rrbc_core.session import vec_view
from rrbc_core.session.tools import TILT_MAX_DEG


def _row(text: str, pid: str) -> list[str]:
    line = next(ln for ln in text.splitlines() if ln.startswith(f"| {pid} ") or ln.startswith(f"| **{pid}** "))
    return [c.strip() for c in line.strip("|").split("|")]


def test_vec_tab_shows_the_sessions_vec_and_follows_a_leaned_tool(app):
    panel = app.controls.vec
    assert "Compare with VEC" in app.controls.vec.vec_table.content  # off until asked: nothing computed
    app.vec.set_vec(True)
    assert app.state.vec_view is not None
    pid = app.session.layout["targets"].ids[0]
    view = vec_view.vec_view(app.session)
    row = _row(app.controls.vec.vec_table.content, pid)
    assert row[1] == "down" and [float(x) for x in row[2:]] == [
        round(float(view.error_rigid[0]), 3),
        round(float(view.error_rrbc[0]), 3),
        round(float(view.error_vec[0]), 3),
    ]
    app.vec.set_varied_registration(True)
    assert panel.varied.value and app.session.varied_registration
    before = vec_view.vec_view(app.session)
    truth_before = app.session.last.targets.truth[0].copy()
    app.vec.set_target_tool(pid, 40.0, 0.0)
    after = vec_view.vec_view(app.session)
    leaned = app.session.last
    assert app.vec.set_target_tool(pid, 40.0, 0.0) is leaned  # the slider's same value again: nothing recomputed
    row = _row(app.controls.vec.vec_table.content, pid)
    assert row[1] == "40°, 0°" and float(row[3]) == round(float(after.error_rrbc[0]), 3)
    assert after.error_rrbc[0] > before.error_rrbc[0] and after.error_vec[0] < after.error_rrbc[0]
    assert panel.tilt.value == 40.0 and panel.target.value == pid
    # the scene's target table and landing use the same evaluation: the leaned target's truth moved
    assert np.linalg.norm(app.session.last.targets.truth[0] - truth_before) > 0.1


def test_a_tilt_out_of_range_is_refused_with_a_message_and_changes_nothing(app):
    app.vec.set_vec(True)
    pid = app.session.layout["targets"].ids[0]
    truth = app.session.last.targets.truth.copy()
    assert app.vec.set_target_tool(pid, TILT_MAX_DEG + 5, 0.0) is None
    assert "tilt" in app.last_message
    assert np.array_equal(app.session.last.targets.truth, truth) and app.session.target_tools == {}


def test_measured_data_have_no_arm_and_say_so(measured):
    measured.vec.set_vec(True)
    assert not measured.state.vec_on and measured.state.vec_view is None
    assert "no kinematic arm error" in measured.controls.vec.vec_table.content
    assert measured.controls.vec.tilt.disabled


def test_the_bullseye_shows_vecs_landing_while_the_comparison_is_on(app):
    node = app.nodes.handle("/landing/vec")
    assert not node.visible and app.state.landing.vec is None
    app.vec.set_vec(True)
    land = app.state.landing
    i = app.session.last.targets.ids.index(land.target)
    view = app.state.vec_view
    # drawn like the other landings: its offset from the truth, times the bullseye's scale
    expected = land.anchor + land.scale * (view.robot_vec[i] - app.session.last.targets.truth[i])
    assert node.visible and np.allclose(node.position, expected) and np.allclose(land.vec, expected)
    app.vec.set_vec(False)
    assert not node.visible


def test_the_panel_bullseye_draws_vec_at_true_size(app):
    import re

    from rrbc_viz.selection_card import bullseye_svg

    app.vec.set_vec(True)
    ev, view = app.session.last, app.state.vec_view
    pid = ev.targets.ids[0]
    svg, caption, key = bullseye_svg(ev, pid, view.robot_vec[0])
    dx = float(re.search(r'data-kind="vec" data-dx-mm="([^"]+)"', svg).group(1))
    assert dx == float(f"{view.robot_vec[0][0] - ev.targets.truth[0][0]:.6g}")
    assert f"VEC {view.error_vec[0]:.3f} mm" in caption and "VEC" in key
    assert 'data-kind="vec"' not in bullseye_svg(ev, pid)[0]


def test_a_refused_comparison_unticks_the_box(measured):
    measured.controls.vec.show.value = True  # the user ticks it; there is no arm
    assert not measured.state.vec_on and measured.controls.vec.show.value is False


def test_a_tool_slider_moved_while_an_earlier_value_computes_is_not_set_back(app):
    """Arrow keys send a value per degree; viser runs each update's callback on a thread of its own, so a value
    applied can land while the user's newer ones are still on their way. The server then sends the sliders nothing:
    any value it sent, even the user's own from a moment ago, would set the slider back under the keys (the next key
    goes on from there; a CI run once ended at 17° of 40 presses)."""
    panel = app.controls.vec
    app.vec.set_vec(True)
    pid = app.session.layout["targets"].ids[0]

    def browser_at(tilt: float) -> None:  # the page's slider moved; its message reached the handle
        with panel.syncing.quiet():
            panel.tilt.value = tilt

    browser_at(12.0)
    app.vec.ask_target_tool(pid, 5.0, 0.0)
    app.vec.ask_target_tool(pid, 12.0, 0.0)  # the newest choice, waiting while 5° computes
    app.vec.set_target_tool(pid, 5.0, 0.0)
    assert app.session.tool_of("targets", pid) == (5.0, 0.0)
    assert panel.tilt.value == 12.0
    app.vec.set_target_tool(pid, 12.0, 0.0)  # the waiting value runs
    assert app.session.tool_of("targets", pid) == (12.0, 0.0) and panel.tilt.value == 12.0
    # 17° applied while the page has gone on to 20° and that update's callback has not run yet
    browser_at(17.0)
    app.vec.ask_target_tool(pid, 17.0, 0.0)
    browser_at(20.0)
    app.vec.set_target_tool(pid, 17.0, 0.0)
    assert app.session.tool_of("targets", pid) == (17.0, 0.0) and panel.tilt.value == 20.0
    app.vec.ask_target_tool(pid, 20.0, 0.0)
    app.vec.set_target_tool(pid, 20.0, 0.0)
    assert app.session.tool_of("targets", pid) == (20.0, 0.0) and panel.tilt.value == 20.0
    # a refused value is not left on the slider: it shows the tool the session holds
    browser_at(TILT_MAX_DEG + 5)
    app.vec.ask_target_tool(pid, TILT_MAX_DEG + 5, 0.0)
    assert app.vec.set_target_tool(pid, TILT_MAX_DEG + 5, 0.0) is None
    assert panel.tilt.value == 20.0 and app.state.vec_tool_asked is None
    # another target shows its own tool
    other = app.session.layout["targets"].ids[1]
    browser_at(20.0)
    app.vec.ask_target_tool(pid, 20.0, 0.0)
    app.vec.sync_vec_target(other)
    assert panel.tilt.value == app.session.tool_of("targets", other)[0] and app.state.vec_tool_asked is None
