"""In-process tests of the browser app (rrbc_viz): a real viser server on a free port, no browser.

Drags are driven through `EvaluateController.handle_drag` (what the gizmo callback calls) and through viser's own
transform-controls handlers (private API, wrapped in `_gizmo_drag`); GUI handles are driven by assigning
`.value` (viser runs the callbacks synchronously) and fiducial clicks by calling the sphere's click callback.
Every server is stopped at the end of its test.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
import time
import urllib.request

import numpy as np
import pytest
import viser

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import parse_measurements
from rrbc_core.io.scene import default_scene_path
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.session import figures
from rrbc_viz import colors
from rrbc_viz.app import RunningApp
from rrbc_viz.controls import LESSON_NEXT, LESSON_PREVIOUS
from rrbc_viz.node_values import gizmo_name
from rrbc_viz.serve import serve
from tests.paths import EXAMPLE_CSV
from tests.viz.helpers import _gizmo_drag, _press

RRBC = [sys.executable, "-m", "rrbc_core.cli"]


def _click(handle) -> None:
    """Call a scene node's click callbacks as viser would for a click on it."""
    event = viser.SceneNodePointerEvent(
        client=None,
        client_id=0,
        event="click",
        target=handle,
        ray_origin=(0.0, 0.0, 0.0),
        ray_direction=(0.0, 0.0, -1.0),
        screen_pos=(0.5, 0.5),
        instance_index=None,
        modifier=None,
    )
    entries = handle._impl.click_cb
    assert entries, "the node has no click callback"
    for entry in entries:
        entry.callback(event)


def _target_arrows(app: RunningApp) -> np.ndarray:
    return np.asarray(app.nodes.handle("/corrections/targets").points, float)


def _assert_arrows_match(app: RunningApp, ev) -> None:
    mag = app.state.display.magnification
    pts = _target_arrows(app)
    np.testing.assert_allclose(pts[:, 0], ev.targets.positions, atol=1e-3)
    np.testing.assert_allclose(pts[:, 1], ev.targets.positions + mag * ev.targets.correction_robot, atol=1e-2)
    inc = np.flatnonzero(ev.included)
    fpts = np.asarray(app.nodes.handle("/corrections/fiducials").points, float)
    assert len(fpts) == len(inc)
    np.testing.assert_allclose(fpts[:, 1], ev.fiducial_positions[inc] + mag * ev.corrections_robot[inc], atol=1e-2)


# ------------------------------------------------------------------------------------------------- start-up
def test_serve_builds_the_scene_and_panel(app):
    base = f"http://127.0.0.1:{app.port}"
    assert app.port > 0 and app.url.startswith(base + "/?websocket=") and app.guard.token in app.url
    with urllib.request.urlopen(app.url, timeout=10) as r:
        assert r.status == 200
    ev = app.session.evaluate()
    for pid in ev.targets.ids:
        name = f"/targets/{pid}/gizmo"
        assert app.evaluate.gizmo_name("targets", pid) == name
        assert app.server.scene.get_handle_by_name(name) is app.evaluate.gizmo("targets", pid)
    for pid in ev.fiducial_ids:
        assert app.server.scene.get_handle_by_name(f"/fiducials/{pid}/gizmo") is not None
    for name in (
        "/mesh/cell",
        "/frames/robot",
        "/frames/sensor_true",
        "/frames/sensor_registered",
        "/registration/points",
        "/hull/edges",
        "/landing/rigid",
        "/landing/rrbc",
        "/heatmap/points",
    ):
        assert app.server.scene.get_handle_by_name(name) is not None, name
    assert all(app.nodes.handle(f"/regions/{pid}") is not None for pid in ev.targets.ids)
    _assert_arrows_match(app, ev)
    np.testing.assert_allclose(np.asarray(app.nodes.handle("/hull/edges").points), ev.hull_edges, atol=1e-3)
    mag = app.state.display.magnification
    assert (
        f"×{mag:g}" in app.controls.explore.scale.content
        and f"drawn as {mag:g} mm" in app.controls.explore.scale.content
    )
    sm = ev.summary
    assert f"{sm['rmst_rigid_mm']:.3f} mm rigid" in app.controls.explore.summary.content
    assert f"{sm['rmst_rrbc_mm']:.3f} mm RRBC" in app.controls.explore.summary.content
    for i, pid in enumerate(ev.targets.ids):
        assert (
            f"| {pid} | {ev.targets.error_rigid[i]:.3f} | {ev.targets.error_rrbc[i]:.3f} |"
            in app.controls.explore.table.content
        )
    # camera framed on the cell (mm scale), not viser's default
    assert np.linalg.norm(app.server.initial_camera.position) > 500
    assert app.server.initial_camera.far > 5000


# ------------------------------------------------------------------------------------------------- dragging
def test_drag_target_recomputes_everything(app):
    before = app.session.last
    label = app.nodes.handle("/targets/H1/gizmo/label")
    old_label = label.text
    new = np.array([405.0, -140.0, 15.0])
    assert app.evaluate.handle_drag("targets", "H1", new, "start") is not None
    ev = app.evaluate.handle_drag("targets", "H1", new, "update")
    assert ev is app.session.last
    np.testing.assert_allclose(ev.targets.positions[0], new)
    np.testing.assert_allclose(app.evaluate.gizmo("targets", "H1").position, new)
    fresh = app.session.evaluate()
    np.testing.assert_allclose(ev.targets.correction, fresh.targets.correction)
    assert not np.allclose(ev.targets.correction[0], before.targets.correction[0])
    _assert_arrows_match(app, fresh)
    assert label.text != old_label and f"{fresh.targets.error_rrbc[0]:.3f}" in label.text
    assert (
        f"| H1 | {fresh.targets.error_rigid[0]:.3f} | {fresh.targets.error_rrbc[0]:.3f} |"
        in app.controls.explore.table.content
    )
    # the landing bullseye of the selected target (H1): truth-anchored offsets at the bullseye's scale, floating
    # above the target, and the same offsets at true size in the panel's SVG
    land = app.state.landing
    t = fresh.targets
    assert land.target == "H1" and land.lift > 0
    assert land.anchor[2] == pytest.approx(t.positions[0, 2] + land.lift)
    np.testing.assert_allclose(
        app.nodes.handle("/landing/rrbc").position, land.anchor + land.scale * (t.robot_rrbc[0] - t.truth[0]), atol=1e-6
    )
    np.testing.assert_allclose(
        app.nodes.handle("/landing/rigid").position,
        land.anchor + land.scale * (t.robot_rigid[0] - t.truth[0]),
        atol=1e-6,
    )
    assert land.ring_mm >= max(
        np.linalg.norm(t.robot_rigid[0] - t.truth[0]), np.linalg.norm(t.robot_rrbc[0] - t.truth[0])
    )
    svg = app.controls.selection.bullseye.html.content
    dx = float(re.search(r'data-kind="rrbc" data-dx-mm="([^"]+)"', svg).group(1))
    assert dx == pytest.approx(t.robot_rrbc[0, 0] - t.truth[0, 0], rel=1e-5, abs=1e-9)
    np.testing.assert_allclose(app.nodes.handle("/regions/H1").position, new)
    app.evaluate.handle_drag("targets", "H1", new, "end")


def test_gizmo_messages_drive_the_drag(app):
    path = [np.array([400.0, -150.0, 15.0 + dz]) for dz in (2.0, 5.0, 9.0)]
    _gizmo_drag(app, "targets", "H2", path)
    ev = app.session.last
    i = ev.targets.ids.index("H2")
    np.testing.assert_allclose(ev.targets.positions[i], path[-1])
    _assert_arrows_match(app, app.session.evaluate())
    assert app.montecarlo.runner.wait_idle(60)  # drag end queued a Monte Carlo run


def test_drag_fiducial_moves_its_correction_and_hull(app):
    ev0 = app.session.last
    ev = app.evaluate.handle_drag("fiducials", "F12", [760.0, 0.0, 120.0], "update")
    assert ev is not None
    i = ev.fiducial_ids.index("F12")
    assert not np.allclose(ev.corrections[i], ev0.corrections[i])
    np.testing.assert_allclose(np.asarray(app.nodes.handle("/hull/edges").points), ev.hull_edges, atol=1e-3)
    _assert_arrows_match(app, app.session.evaluate())
    app.evaluate.handle_drag("fiducials", "F12", [760.0, 0.0, 120.0], "end")


def test_target_outside_the_hull_is_flagged(app):
    sphere = app.nodes.handle("/targets/H1/gizmo/sphere")
    assert tuple(sphere.color) == colors.TARGET
    ev = app.evaluate.handle_drag("targets", "H1", [150.0, -150.0, 300.0], "end")
    assert "H1" in ev.summary["extrapolated"] and bool(ev.targets.extrapolated[0])
    assert tuple(sphere.color) == colors.TARGET_EXTRAPOLATED
    assert "extrapolated" in app.nodes.handle("/targets/H1/gizmo/label").text
    assert "| H1 |" in app.controls.explore.table.content and "⚠ extrapolated |" in app.controls.explore.table.content
    assert "Extrapolated" in app.controls.explore.summary.content
    ev = app.evaluate.handle_drag("targets", "H1", [400.0, -150.0, 15.0], "end")
    assert not ev.targets.extrapolated[0] and tuple(sphere.color) == colors.TARGET


# ------------------------------------------------------------------------------------------------- settings
def test_selecting_a_fiducial_then_excluding_and_including_it(app):
    sphere = app.nodes.handle("/fiducials/F3/gizmo/sphere")
    n = len(app.session.last.fiducial_ids)
    _click(sphere)  # a click selects: F3 alone carries the drag gizmo, its card shows its numbers
    assert app.state.selected == ("fiducials", "F3") and app.controls.selection.choice.value.startswith(
        "fiducial F3 · "
    )
    assert [key for key, tc in app.nodes.gizmo_items().items() if not tc.disable_axes] == [("fiducials", "F3")]
    assert "**Fiducial F3**" in app.controls.selection.info.content and app.controls.selection.exclude.visible
    assert app.nodes.handle("/fiducials/F3/gizmo/label").visible  # its label, with the labels layer off
    assert not app.nodes.handle("/fiducials/F1/gizmo/label").visible
    assert app.session.last.summary["fiducials_used"] == n
    _press(app.controls.selection.exclude)
    ev = app.session.last
    assert "F3" in ev.settings.excluded and ev.summary["fiducials_used"] == n - 1
    assert tuple(sphere.color) == colors.FIDUCIAL_EXCLUDED
    assert f"over {n - 1} of {n} fiducials" in app.controls.explore.summary.content
    assert len(app.nodes.handle("/corrections/fiducials").points) == n - 1
    assert "excluded" in app.nodes.handle("/fiducials/F3/gizmo/label").text
    assert "**excluded**" in app.controls.selection.info.content
    _press(app.controls.selection.exclude)
    assert app.session.last.summary["fiducials_used"] == n and tuple(sphere.color) == colors.FIDUCIAL
    app.controls.selection.choice.value = "target H2"  # picking from the list selects too
    assert app.state.selected == ("targets", "H2") and not app.evaluate.gizmo("targets", "H2").disable_axes
    assert app.evaluate.gizmo("fiducials", "F3").disable_axes and app.state.landing.target == "H2"
    assert "**Target H2**" in app.controls.selection.info.content and app.controls.selection.bullseye.html.visible
    app.controls.selection.choice.value = "none"
    assert app.state.selected is None and all(tc.disable_axes for tc in app.nodes.gizmo_items().values())
    with pytest.raises(InputError, match="no target 'H99'"):
        app.views.select("targets", "H99")


def test_method_controls_change_the_numbers(app):
    c = app.controls
    rmst0 = app.session.last.summary["rmst_rrbc_mm"]
    c.explore.interpolation.value = "gp"
    ev = app.session.last
    assert ev.settings.interpolation == "gp" and ev.targets.correction_std is not None
    assert ev.summary["rmst_rrbc_mm"] != pytest.approx(rmst0)
    assert "| std |" in c.explore.table.content
    std0 = float(np.linalg.norm(ev.targets.correction_std[0]))
    assert f"| {std0:.3f} |" in c.explore.table.content
    fre0 = ev.registration.fre_rms_mm
    c.explore.registration.value = "three-point"
    ev = app.session.last
    assert ev.registration.method == "three-point" and ev.registration.fre_rms_mm != pytest.approx(fre0)
    assert f"FRE {ev.registration.fre_rms_mm:.3f} mm" in c.explore.summary.content
    assert ev.summary == app.session.evaluate().summary
    c.explore.interpolation.value = "idw"
    assert c.explore.neighbors.visible and not c.explore.smoothing.visible
    c.explore.neighbors.value = 2
    assert app.session.last.settings.neighbors == 2
    rigid0 = app.session.last.summary["rmst_rigid_mm"]
    c.explore.bias.value = 2.0
    assert app.session.last.settings.bias_scale == 2.0
    assert app.session.last.summary["rmst_rigid_mm"] != pytest.approx(rigid0)
    seed0 = app.session.last.settings.seed
    c.explore.new_seed.value = True
    assert app.session.last.settings.seed != seed0 and str(app.session.last.settings.seed) in c.explore.seed_md.content
    c.explore.magnification.value = 1000
    assert "×1000" in c.explore.scale.content
    _assert_arrows_match(app, app.session.last)


def test_refused_setting_keeps_the_session_and_says_why(app):
    for pid in app.session.last.fiducial_ids:
        app.evaluate.toggle_fiducial(pid)
    # the last one cannot be excluded with idw: the core refuses, the app says so and stays consistent
    ev = app.session.last
    assert ev.summary["fiducials_used"] == 1
    assert app.last_message and "fiducial" in app.last_message
    assert "⚠" in app.controls.status.content


def test_layers_lesson_and_heat_map(app):
    c = app.controls
    c.view.layers["hull"].value = False
    assert app.nodes.handle("/hull").visible is False
    c.view.layers["heatmap"].value = True
    node = app.nodes.handle("/heatmap/points")
    hm = app.state.heat_map
    assert node.visible and len(node.points) == len(hm.positions)
    assert f"{float(np.nanmin(np.r_[hm.error_rigid, hm.error_rrbc])):.4f} mm" in c.view.legend.content
    c.view.heat_value.value = "rigid error"
    assert "rigid only" in c.view.legend.content
    # lesson: Next starts at step 1 with its layers; numbers are live
    c.learn.lesson_nav.value = LESSON_NEXT
    assert app.state.lesson_index == 0 and "Step 1 of 9" in c.learn.lesson.content
    assert c.view.layers["registration"].value and not c.view.layers["targets"].value
    assert app.nodes.handle("/targets").visible is False
    for _ in range(5):
        c.learn.lesson_nav.value = LESSON_NEXT
    assert "Step 6 of 9" in c.learn.lesson.content  # fiducial corrections only
    assert app.nodes.handle("/corrections").visible and not app.nodes.handle("/corrections/targets").visible
    ev = app.session.last
    n = np.linalg.norm(ev.corrections[ev.included], axis=1)
    assert f"{n.max():.3f} mm" in c.learn.lesson.content and f"{n.min():.3f} mm" in c.learn.lesson.content
    c.learn.lesson_nav.value = LESSON_PREVIOUS
    assert "Step 5 of 9" in c.learn.lesson.content
    for _ in range(4):
        c.learn.lesson_nav.value = LESSON_NEXT
    sm = app.session.last.summary
    assert (
        "Step 9 of 9" in c.learn.lesson.content and f"{sm['rmst_rrbc_mm']:.3f} mm with RRBC" in c.learn.lesson.content
    )
    assert c.view.layers["landing"].value
    app.evaluate.handle_drag("targets", "H3", [410.0, 40.0, 15.0], "end")
    sm = app.session.last.summary
    assert f"{sm['rmst_rrbc_mm']:.3f} mm with RRBC" in c.learn.lesson.content
    # Next after the last step ends the lesson as End lesson does (issue 39: it stayed on step 9 without a word);
    # the row of buttons never changes under a click
    c.learn.lesson_nav.value = LESSON_NEXT
    assert app.state.lesson_index is None and "ninth and last step" in c.learn.lesson.content
    assert tuple(c.learn.lesson_nav.options) == (LESSON_PREVIOUS, LESSON_NEXT)
    assert c.view.layers["heatmap"].value and not c.view.layers["hull"].value
    assert app.nodes.handle("/corrections/targets").visible
    c.learn.lesson_nav.value = LESSON_NEXT  # and starts again
    assert app.state.lesson_index == 0 and "Step 1 of 9" in c.learn.lesson.content
    c.learn.lesson_end.value = True
    assert app.state.lesson_index is None and c.view.layers["heatmap"].value and not c.view.layers["hull"].value
    assert "Lesson ended" in c.learn.lesson.content


def test_display_controls_and_heat_map_follow_drags(app):
    c = app.controls
    # the first target starts selected: it alone has a drag handle
    assert app.state.selected == ("targets", "H1")
    assert [key for key, tc in app.nodes.gizmo_items().items() if not tc.disable_axes] == [("targets", "H1")]
    assert all(tc.disable_sliders for key, tc in app.nodes.gizmo_items().items() if key != ("targets", "H1"))
    c.view.marker.value = 4.0
    assert app.nodes.handle("/fiducials/F1/gizmo/sphere").radius == pytest.approx(4.0)
    assert app.evaluate.gizmo("targets", "H1").scale == pytest.approx(app.nodes.gizmo_scale())
    c.view.layers["heatmap"].value = True
    owner = np.array(app.state.heat_map.target) == "H1"
    centre0 = np.asarray(app.nodes.handle("/heatmap/points").points, float)[owner].mean(0)
    c.view.region_zoom.value = 10.0
    assert app.nodes.handle("/regions/H1").scale == pytest.approx(10.0)  # H1's region is a box: uniform zoom
    assert app.nodes.handle("/regions/H3").scale == pytest.approx((6.0, 6.0, 6.0))  # sphere r 0.6 mm, zoomed
    pts = np.asarray(app.nodes.handle("/heatmap/points").points, float)[owner]
    np.testing.assert_allclose(pts.mean(0), centre0, atol=2.0)
    app.evaluate.handle_drag("targets", "H1", [420.0, -150.0, 15.0], "end")  # the heat map follows at drag end
    pts = np.asarray(app.nodes.handle("/heatmap/points").points, float)[owner]
    assert abs(pts.mean(0)[0] - 420.0) < 3.0
    hm = figures.heat_map(app.session)
    np.testing.assert_allclose(app.state.heat_map.error_rrbc, hm.error_rrbc)
    with pytest.raises(InputError):
        app.evaluate.set_display(handles="both")  # no such option any more: selection decides


def test_monte_carlo_plots_follow_the_setup(app):
    assert app.montecarlo.runner.wait_idle(60)
    first = app.state.mc_plots
    assert first is not None
    centres, rigid, rrbc = first.histogram()
    np.testing.assert_allclose(app.controls.montecarlo.mc_hist.data[1], rigid)
    app.controls.explore.interpolation.value = "tps"
    assert app.montecarlo.runner.wait_idle(60)
    assert app.state.mc_plots is not first
    d, a, b, ha, hb = app.state.mc_plots.by_distance()
    data = app.controls.montecarlo.mc_dist.data
    np.testing.assert_allclose(data[0], d)
    np.testing.assert_allclose(data[2], b)
    np.testing.assert_allclose(data[3], a - ha)  # the rigid mean's interval, drawn as two dashed lines
    np.testing.assert_allclose(data[6], b + hb)
    assert "tps" in app.controls.montecarlo.mc_info.content


def test_run_again_draws_new_noise_and_a_setting_change_does_not(app):
    assert app.montecarlo.runner.wait_idle(60)
    seeded = app.state.mc_plots
    app.montecarlo.request()  # the same setup, seeded by the session's seed: the same numbers
    assert app.montecarlo.runner.wait_idle(60)
    np.testing.assert_array_equal(app.state.mc_plots.rigid, seeded.rigid)
    _press(app.controls.montecarlo.mc_run)  # Run again
    assert app.montecarlo.runner.wait_idle(60)
    again = app.state.mc_plots
    assert not np.array_equal(again.rigid, seeded.rigid) and "noise draw 1" in app.controls.montecarlo.mc_info.content
    _press(app.controls.montecarlo.mc_run)
    assert app.montecarlo.runner.wait_idle(60)
    assert (
        not np.array_equal(app.state.mc_plots.rigid, again.rigid)
        and "noise draw 2" in app.controls.montecarlo.mc_info.content
    )


def test_stop_ends_a_running_monte_carlo_at_its_next_chunk_and_keeps_the_last_plots(app, monkeypatch):
    """A slow run (gp, 1000 trials) is stopped by the Stop button: the worker is idle again long before the run
    would have finished, the plots are still those of the last finished run, and the panel says it stopped."""
    import threading

    assert app.montecarlo.runner.wait_idle(60)
    before = app.state.mc_plots
    monkeypatch.setattr(figures, "MC_CHUNK_TRIALS", 5)
    started = threading.Event()
    real = app.controls.montecarlo.mc_stop
    app.montecarlo.runner._on_start = lambda: (app.montecarlo._mc_started(), started.set())
    app.controls.montecarlo.mc_trials.value = 1000  # queues a run of the new setup
    assert started.wait(30)
    assert real.disabled is False  # Stop is offered while a run is under way
    _press(real)
    assert app.montecarlo.runner.wait_idle(30)
    assert app.state.mc_plots is before and real.disabled is True
    assert "stopped" in app.controls.montecarlo.mc_info.content


def test_measured_data_hide_the_controls_that_do_not_apply(app, measured):
    for a, scene in ((app, True), (measured, False)):
        e, mc, plan = a.controls.explore, a.controls.montecarlo, a.planning
        assert e.noise.visible is scene and e.bias.visible is scene and e.new_seed.visible is scene
        assert mc.mc_run.visible is scene and mc.mc_trials.visible is scene and mc.mc_hist.visible is scene
        assert mc.mc_stop.visible is scene
        # measured data: Suggest proposes places to measure (coverage, no error model); nothing to accept or colour
        assert plan.suggest_button.visible and plan.k.visible
        assert plan.accept_button.visible is scene and plan.colour.visible is scene


def test_exports_come_from_the_session(app):
    name, content = app.files.export("csv")
    assert name.endswith(".csv")
    mset = parse_measurements(content.decode("utf-8"), name)
    ref = figures.export_measurements(app.session)
    assert mset.ids == ref.ids and mset.roles == ref.roles
    np.testing.assert_allclose(mset.sensor, ref.sensor)
    name, content = app.files.export("json")
    assert json.loads(content) == json.loads(json.dumps(figures.export_json(app.session)))
    app.controls.file.download_csv.value = True  # no tab connected: nothing to send, nothing breaks
    app.controls.file.download_json.value = True


def test_the_file_tabs_corrected_targets_and_report_are_the_commands_on_its_csv(measured, tmp_path):
    """Issue 40, items 2 and 3: the File tab's corrected targets are `rrbc correct CSV --out` and its report is `rrbc
    report CSV --interpolation NAME [--tolerance T] --out` on the CSV the same tab downloads (one answer, the
    same bytes), with the app's interpolation changed from the default."""
    from html import escape as html_escape

    from tests.support.cli_run import rrbc

    app = measured
    app.controls.explore.interpolation.value = "tps"  # as a user sets it
    name, data = app.files.export("csv")
    path = tmp_path / name
    path.write_bytes(data)
    name, corrected = app.files.export("corrected")
    assert name.endswith("-corrected.csv")
    assert rrbc("correct", path, "--interpolation", "tps", "--out", tmp_path / "c.csv").returncode == 0
    assert corrected == (tmp_path / "c.csv").read_bytes()
    name, html = app.files.export("report", tolerance_mm=0.2)
    assert name.endswith("-report.html")
    r = rrbc("report", path, "--interpolation", "tps", "--tolerance", "0.2", "--out", tmp_path / "r.html")
    assert r.returncode == 0, r.stderr
    source = html_escape(figures.export_measurements(app.session).source).encode()  # the file the app opened
    assert html.replace(source, html_escape(str(path)).encode()) == (tmp_path / "r.html").read_bytes()
    assert b"0.2 mm" in html or b"0.2&nbsp;mm" in html
    app.controls.file.download_corrected.value = True  # no tab connected: nothing to send, nothing breaks


# ------------------------------------------------------------------------------------------------- bad files
def test_bad_files_leave_the_server_and_session(app, tmp_path):
    session = app.session
    bad_toml = tmp_path / "bad.toml"
    bad_toml.write_text('[scene]\nname = "x"\nunits = "inch"\nmesh = "m.glb"\n', encoding="utf-8")
    assert app.files.load(bad_toml) is False
    assert app.session is session and "bad.toml" in app.last_message
    assert "bad.toml" in app.controls.status.content
    bad_csv = tmp_path / "bad.csv"
    bad_csv.write_text("id,role,sensor_x\nA,fiducial,1\n", encoding="utf-8")
    assert app.files.load(bad_csv) is False
    assert app.session is session and "bad.csv" in app.last_message
    # the File tab opens only what it offers: a label it did not list is refused, nothing is read
    assert app.files.load_offered(str(bad_csv)) is False and "not one of the files offered" in app.last_message
    assert app.files.load_offered("/etc/passwd") is False and app.session is session
    assert app.files.load_upload("junk.csv", b"\xff\xfe not text") is False
    assert app.files.load_upload("broken.toml", b"[scene\n") is False
    assert app.session is session and "broken.toml" in app.last_message
    with urllib.request.urlopen(app.url, timeout=10) as r:
        assert r.status == 200
    assert app.evaluate.handle_drag("targets", "H1", [401.0, -150.0, 15.0], "end") is not None
    # a good measurement upload replaces the session, once the user agrees to discard the unsaved move of H1
    assert app.files.load_upload("example.csv", EXAMPLE_CSV.read_bytes()) is False
    assert app.session is session and app.controls.file.confirm_yes is not None
    _press(app.controls.file.confirm_yes)
    assert app.session.kind == "measurements"


# ------------------------------------------------------------------------------------------------- measured data
def test_measurement_mode_moves_targets_and_refuses_fiducials(measured):
    app = measured
    c = app.controls
    assert not c.explore.noise.visible and not c.explore.bias.visible  # hidden: measured data have no error model
    assert "Monte Carlo needs a scene" in c.montecarlo.mc_info.content
    c.explore.interpolation.value = "gp"
    ev0 = app.session.last
    i = ev0.targets.ids.index("T1")
    p0 = ev0.targets.positions[i].copy()
    ev = app.evaluate.handle_drag("targets", "T1", p0 + [60.0, 40.0, 0.0], "end")
    assert ev is not None
    assert not np.allclose(ev.targets.correction[i], ev0.targets.correction[i])
    assert not np.allclose(ev.targets.correction_std[i], ev0.targets.correction_std[i])
    std = float(np.linalg.norm(ev.targets.correction_std[i]))
    assert f"± {std:.3f}" in app.nodes.handle("/targets/T1/gizmo/label").text
    assert f"| {std:.3f} |" in c.explore.table.content
    _assert_arrows_match(app, app.session.evaluate())
    # fiducials cannot be moved: refused, the gizmo snaps back, a message says why
    j = ev.fiducial_ids.index("F22")
    f0 = ev.fiducial_positions[j].copy()
    _gizmo_drag(app, "fiducials", "F22", [f0 + [5.0, 0.0, 0.0], f0 + [9.0, 0.0, 0.0]])
    np.testing.assert_allclose(app.evaluate.gizmo("fiducials", "F22").position, f0)
    np.testing.assert_allclose(app.session.last.fiducial_positions[j], f0)
    assert "cannot be moved" in app.last_message
    assert app.evaluate.handle_drag("fiducials", "F22", f0 + [1.0, 0.0, 0.0], "end") is None
    # heat map in measurement mode: correction size / gp std
    c.view.layers["heatmap"].value = True
    assert app.state.heat_map is not None and app.nodes.handle("/heatmap/points").visible
    c.view.heat_value.value = "correction std (gp)"
    assert "std" in c.view.legend.content


# ------------------------------------------------------------------------------------------------- CLI
def test_cli_view_help_and_bad_scene(tmp_path):
    r = subprocess.run(RRBC + ["view", "--help"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "--port" in r.stdout and "--host" in r.stdout
    bad = tmp_path / "bad.toml"
    bad.write_text("[scene\n", encoding="utf-8")
    r = subprocess.run(RRBC + ["view", str(bad), "--port", "0"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad.toml" in lines[0]


@pytest.mark.parametrize(
    "flags, mode",
    [
        ([], "one session shared by every tab"),
        (["--per-client", "--present", "--plain-light"], "one session per browser tab"),
    ],
)
def test_cli_view_starts_and_prints_the_url(flags, mode):
    """The URL printed, the page served, and Ctrl+C with three tabs still connected stops the server within 10 s
    (issue 42, item 5), exit 0."""
    import signal

    from tests.support.viser_clients import ClientPool

    proc = subprocess.Popen(
        RRBC + ["view", "--port", "0", *flags], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    pool = dragging = None
    stopped_in = None
    try:
        line = proc.stdout.readline()
        assert "http://127.0.0.1:" in line and mode in line
        url = line.split(" at ")[1].split()[0]
        with urllib.request.urlopen(url, timeout=10) as r:
            assert r.status == 200
        pool = ClientPool(url, 3)
        deadline = time.monotonic() + 60
        while not all(rec.arrivals for rec in pool.records) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert all(rec.arrivals for rec in pool.records)  # each tab is being sent its scene
        # every tab drags the selected target while the server is stopped (a stop mid-drag once wrote viser's
        # "Queued a ... on a closed connection" warning to the log)
        scene = load_scene(default_scene_path())
        h1 = np.asarray(scene.targets[0].position, float)
        owners = [str(k) for k in range(3)] if "--per-client" in flags else None
        dragging = threading.Thread(
            target=pool.drag_all,
            args=([gizmo_name("targets", "H1")] * 3, lambda k, t: h1 + [5.0 * t, 0.0, 0.0], 3.0, 20.0, owners),
            daemon=True,
        )
        dragging.start()
        time.sleep(1.0)  # the drags are under way (the stop is what is tested, at any moment of them)
    finally:
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=10)
            stopped_in = time.monotonic() - t0
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if dragging is not None:
            dragging.join(timeout=30)  # its last messages go nowhere: the server is gone
        if pool is not None:
            pool.close()
    assert stopped_in is not None, "Ctrl+C did not stop the server within 10 s"
    assert proc.returncode == 0
    err = proc.stderr.read()
    assert "Traceback" not in err and "Warning" not in err, err  # a quiet log, whatever the tabs were doing


def test_ctrl_c_handed_to_another_thread_still_stops_the_server():
    """The kernel may hand a process's SIGINT to any of its threads. Python then runs its handler in the main thread
    only once that thread wakes: `rrbc view` sleeps in short steps, so it stops within seconds (it used to sleep an
    hour at a time and, under load, ignored Ctrl+C; measured: 2 of 16 stops beside five busy cores). The signal is
    sent here to one of the server's other threads (tgkill), which is what made it hang."""
    import ctypes
    import os
    import signal

    proc = subprocess.Popen(RRBC + ["view", "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert "http://127.0.0.1:" in proc.stdout.readline()
        others = [int(t) for t in os.listdir(f"/proc/{proc.pid}/task") if int(t) != proc.pid]
        assert others, "the server runs other threads"
        libc = ctypes.CDLL(None, use_errno=True)
        assert libc.tgkill(proc.pid, others[0], int(signal.SIGINT)) == 0, os.strerror(ctypes.get_errno())
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
            pytest.fail("a SIGINT handed to another thread did not stop the server within 10 s")
    assert proc.returncode == 0


def test_a_quiet_server_prints_nothing_on_stdout_from_start_to_stop(capfd):
    """`serve(quiet=True)` (what the benchmarks and tests use) hides viser's banner and its "Server stopped" line,
    so a caller's stdout (a --json stream) carries only what the caller prints."""
    a = serve(port=0)
    a.evaluate.handle_drag("targets", "H1", a.session.layout["targets"].positions[0] + [0.5, 0.0, 0.0], "end")
    a.stop()
    assert capfd.readouterr().out == ""


def test_the_results_table_keeps_its_columns_apart_with_gp(app):
    """With gp a right-aligned std column stands before the hull column: that one is centred, so the two never
    run together (they did, left-aligned: '0.081inside')."""
    app.controls.explore.interpolation.value = "gp"
    lines = app.controls.explore.table.content.splitlines()
    assert lines[0].split("|")[-2].strip() == "hull" and lines[1].split("|")[-2] == ":---:"
    cells = [len(re.findall(r"(?<!\\)\|", line)) for line in lines[:3]]  # unescaped separators
    assert cells[0] == cells[1] == cells[2]
