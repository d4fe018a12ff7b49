"""Per-point bounds in the running app (issue 37, item 3): each target's 95 % bound drawn as a layer (magnified as the
arrows are, or at true size),
the selected target's card with its bound and budget bars, both the session's numbers (`rrbc correct`'s), both
following a drag."""

import re

import numpy as np
import pytest

from rrbc_core.correction.bound_radius import bound_ellipsoids
from rrbc_viz.selection_card import BAR_CELLS


def _card(app) -> str:
    return app.controls.selection.info.content


@pytest.mark.parametrize("scale", ["arrows", "true"])
def test_the_bounds_layer_draws_each_targets_95_percent_ellipsoid(app, scale):
    """By default magnified as the arrows and landing offsets are (a bound of tenths of a mm is otherwise hidden in
    its marker), at true size when asked; the View's dropdown says which."""
    app.controls.explore.bound_scale.value = {"arrows": "× arrow magnification", "true": "true size"}[scale]
    assert app.state.display.bound_scale == scale
    factor = app.state.display.magnification if scale == "arrows" else 1.0
    ev = app.session.last
    assert "bounds" in app.controls.view.layers and not app.state.layers["bounds"]  # off until asked
    app.evaluate.set_layer("bounds", True)
    assert app.nodes.handle("/bounds").visible
    rot, axes = ev.bounds.rrbc.ellipsoids()
    assert np.allclose(
        axes[np.isfinite(axes[:, 0])], bound_ellipsoids(ev.bounds.rrbc.cov_mm2)[1][np.isfinite(axes[:, 0])]
    )
    shown = 0
    for i, pid in enumerate(ev.targets.ids):
        node = app.nodes.handle(f"/bounds/{pid}")
        if not np.all(np.isfinite(axes[i])):
            assert not node.visible
            continue
        shown += 1
        assert node.visible
        np.testing.assert_allclose(node.scale, factor * axes[i], rtol=1e-6)
        np.testing.assert_allclose(node.position, ev.targets.positions[i])
    assert shown > 0


def test_the_card_shows_the_bound_and_its_budget_and_a_drag_changes_both(app):
    ev = app.session.last
    pid = ev.targets.ids[0]
    app.views.select("targets", pid)
    card = _card(app)
    b = ev.bounds.rrbc
    assert f"95 % bound **{b.bound95_mm[0]:.3f} mm**" in card
    for name, values in b.budget_mm.items():
        m = re.search(rf"\| {name} \| `([█░]+)` \| ([0-9.]+) \|", card)
        assert m is not None, card
        assert float(m.group(2)) == pytest.approx(values[0], abs=5e-4)
        assert len(m.group(1)) == BAR_CELLS
    # the largest source fills its bar
    top = max(b.budget_mm, key=lambda k: b.budget_mm[k][0])
    assert re.search(rf"\| {top} \| `█{{{BAR_CELLS}}}` \|", card)
    node = app.nodes.handle(f"/bounds/{pid}")
    before_scale = np.array(node.scale, float)
    fid = app.session.layout["fiducials"].ids[0]
    start = app.session.layout["fiducials"].positions[0]
    app.evaluate.handle_drag("fiducials", fid, start, phase="start")
    app.evaluate.handle_drag("fiducials", fid, start + np.array([80.0, -60.0, 30.0]))
    app.evaluate.handle_drag("fiducials", fid, start + np.array([80.0, -60.0, 30.0]), phase="end")
    app.evaluate.wait_drags()
    after = app.session.last.bounds.rrbc
    assert _card(app) != card and f"{after.bound95_mm[0]:.3f} mm" in _card(app)
    _, axes = after.ellipsoids()
    if np.all(np.isfinite(axes[0])):  # drawn as the arrows are (the default)
        drawn = app.state.display.magnification * axes[0]
        np.testing.assert_allclose(app.nodes.handle(f"/bounds/{pid}").scale, drawn, rtol=1e-6)
        assert not np.allclose(before_scale, drawn)


def test_a_target_without_a_bound_says_why_on_its_card(measured):
    ev = measured.session.last
    pid = ev.targets.ids[0]
    # move it far from every fiducial: beyond what their cross-validation tested
    far = ev.targets.positions[0] + np.array([0.0, 0.0, 2000.0])
    measured.evaluate.handle_drag("targets", pid, ev.targets.positions[0], phase="start")
    measured.evaluate.handle_drag("targets", pid, far, phase="end")
    measured.evaluate.wait_drags()
    measured.views.select("targets", pid)
    i = measured.session.last.targets.ids.index(pid)
    assert np.isnan(measured.session.last.bounds.rrbc.bound95_mm[i])
    assert "95 % bound: none" in _card(measured) and "cross-validation tested" in _card(measured)
    assert not measured.nodes.handle(f"/bounds/{pid}").visible


def test_a_fiducial_drag_marks_the_targets_whose_correction_it_changed_most(app):
    """Issue 39, item 2: after a fiducial's drag the targets whose correction changed most (at least a fifth of the
    largest change, at most three) are drawn larger and named under the scale line with their change; a target's
    drag clears the mark. The changes are the session's own corrections before and after."""
    from rrbc_core.session.results import correction_changes, largest_changes
    from rrbc_viz.nodes import CHANGED_SCALE

    app.controls.view.layers["labels"].value = False  # the marked targets are labelled all the same
    ev0 = app.session.last
    before = ev0.targets.correction_robot.copy()
    fid = app.session.layout["fiducials"].ids[0]
    start = np.array(app.session.layout["fiducials"].positions[0], float)
    goal = start + np.array([120.0, -80.0, 40.0])
    app.evaluate.handle_drag("fiducials", fid, start, phase="start")
    app.evaluate.handle_drag("fiducials", fid, goal)
    ev = app.evaluate.handle_drag("fiducials", fid, goal, phase="end")
    changes = correction_changes(ev0.targets.ids, before, ev.targets.ids, ev.targets.correction_robot)
    marked = largest_changes(ev.targets.ids, changes)
    assert marked and marked[0][1] == pytest.approx(np.nanmax(changes))
    for pid in ev.targets.ids:
        scale = np.atleast_1d(np.asarray(app.nodes.handle(f"/targets/{pid}/gizmo/sphere").scale, float))
        want = CHANGED_SCALE if pid in dict(marked) else 1.0
        assert np.allclose(scale, want), (pid, scale)
        label = app.nodes.handle(f"/targets/{pid}/gizmo/label")
        if pid in dict(marked):  # labelled with its change, the labels layer off
            assert label.visible and label.text.endswith(f" · Δê {dict(marked)[pid]:.3f} mm"), label.text
        else:
            assert "Δê" not in label.text and label.visible == (app.state.selected == ("targets", pid))
    text = app.controls.explore.scale.content
    assert all(f"**{pid}** {mm:.3f} mm" in text for pid, mm in marked), text
    t0 = ev.targets.positions[0]
    app.evaluate.handle_drag("targets", ev.targets.ids[0], t0, phase="start")  # a target's drag clears the mark
    app.evaluate.handle_drag("targets", ev.targets.ids[0], t0 + np.array([1.0, 0.0, 0.0]), phase="end")
    assert "changed these targets" not in app.controls.explore.scale.content
    for pid in ev.targets.ids:
        label = app.nodes.handle(f"/targets/{pid}/gizmo/label")
        assert "Δê" not in label.text and label.visible == (app.state.selected == ("targets", pid))
    assert all(
        np.allclose(np.asarray(app.nodes.handle(f"/targets/{p}/gizmo/sphere").scale, float), 1.0)
        for p in ev.targets.ids
    )


def test_largest_changes_are_a_fifth_of_the_largest_and_at_most_three():
    from rrbc_core.session.results import correction_changes, largest_changes

    ids = ("A", "B", "C", "D", "E")
    now = np.array([[1.0, 0, 0], [0, 0.5, 0], [0, 0, 0.1], [0.3, 0, 0], [0, 0, 0]])
    changes = correction_changes(("A", "B", "C", "D"), np.zeros((4, 3)), ids, now)
    assert np.isnan(changes[4]) and changes[0] == pytest.approx(1.0)  # E was not there before
    assert largest_changes(ids, changes) == (("A", 1.0), ("B", 0.5), ("D", 0.3))
    assert largest_changes(ids, changes, k=1) == (("A", 1.0),)
    assert largest_changes(ids, np.full(5, 1e-5)) == ()  # nothing changed enough to say
