"""What a user sees of the camera, the selection and the landings, in headless Chromium on the real app.

For every Learn step, after the server moves the tab's camera, the objects the step talks about are projected with
the camera the page itself renders with (three.js, read from the page): each must fall inside the canvas and on the
canvas itself (`document.elementFromPoint` is the canvas there, so no panel or notification covers it), and the
segment from the camera to it must not cross the work-cell mesh (a ray test with trimesh against the mesh the app
drew), so no geometry hides it. Also: only the selected point has a gizmo in the page, and a refused drag (out of
the arm's reach) returns the handle to its place in the page.
"""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_viz import teaching
from rrbc_viz.camera import PANEL_WIDTH_PX, PRESENTATION_PANEL_WIDTH_PX
from rrbc_viz.serve import serve

from .helpers import (
    SOFTWARE_WEBGL_TITLE,
    decode_png,
    dismiss_software_webgl_notification,
    drag,
    next_frames,
    node_screen_position,
    page_caught_up,
    wait_camera,
    wait_for,
)

pytestmark = pytest.mark.browser

# Robot-frame points -> page pixels with the page's camera; the camera's position in the robot frame.
_JS_PROJECT_MANY = """(pts) => {
  const m = window.__viserMutable;
  const obj = m.nodeRefFromName['/mesh'];
  const cam = m.camera;
  obj.updateWorldMatrix(true, false);
  cam.updateMatrixWorld();
  const V = cam.position.constructor;
  const r = m.canvas.getBoundingClientRect();
  const out = pts.map((p) => {
    const w = obj.localToWorld(new V(p[0], p[1], p[2]));
    const inFront = w.clone().applyMatrix4(cam.matrixWorldInverse).z < 0;
    const q = w.clone().project(cam);
    const x = r.left + (q.x + 1) / 2 * r.width, y = r.top + (1 - q.y) / 2 * r.height;
    const el = document.elementFromPoint(x, y);
    const note = el ? el.closest('.mantine-Notification-root') : null;
    return {x: x, y: y, inFront: inFront, onCanvas: el === m.canvas, notice: note ? note.innerText : '',
            over: el ? (el.tagName + '.' + el.className + ':' + (el.innerText || '').slice(0, 60)) : null};
  });
  const c = obj.worldToLocal(cam.position.clone());
  return {points: out, camera: [c.x, c.y, c.z], canvas: [r.left, r.top, r.width, r.height]};
}"""

_JS_SOLID_CELL = (
    """() => { const o = window.__viserMutable.nodeRefFromName['/mesh/cell']; return !!(o && o.visible); }"""
)


def _step_objects(app, step) -> dict[str, np.ndarray]:
    """Robot-frame points of what a step talks about, by name (the visible part of each marker: its top): what it
    frames and the points whose labels it shows (its text names them)."""
    ev = app.session.last
    r = app.state.display.marker_mm
    up = np.array([0.0, 0.0, 0.9 * r])
    out = {}
    for name in dict.fromkeys(step.focus + step.labels):
        if name == "registration":
            out[name] = ev.registration_positions + up
        elif name == "fiducials":
            out[name] = ev.fiducial_positions + up
        elif name == "targets":
            out[name] = ev.targets.positions + up
        elif name == "robot":
            out[name] = np.zeros((1, 3))
        elif name == "sensor":
            out[name] = np.asarray(app.session.sensor_to_robot.translation, float).reshape(1, 3)
        elif name == "corrections":
            inc = np.flatnonzero(ev.included)
            out[name] = ev.fiducial_positions[inc] + app.state.display.magnification * ev.corrections_robot[inc]
        elif name == "landing":
            land = app.state.landing
            out[name] = np.array([land.anchor, land.rigid, land.rrbc])
    return out


def _hidden_by_mesh(mesh, camera: np.ndarray, points: np.ndarray, slack_mm: float) -> np.ndarray:
    """Per point: whether the segment camera -> point crosses the mesh more than `slack_mm` before the point."""
    d = points - camera
    dist = np.linalg.norm(d, axis=1)
    dirs = d / dist[:, None]
    locs, idx, _ = mesh.ray.intersects_location(np.repeat(camera[None], len(points), 0), dirs, multiple_hits=True)
    hidden = np.zeros(len(points), bool)
    if len(idx):
        hit = np.linalg.norm(locs - camera, axis=1)
        hidden[np.unique(idx[hit < dist[idx] - slack_mm])] = True
    return hidden


_JS_HIDE_SOFTWARE_NOTICE = """(title) => { for (const n of document.querySelectorAll('.mantine-Notification-root')) {
  const t = n.innerText || ''; if (t.includes(title) || t.includes('WebGL is running in software mode'))
  n.style.display = 'none'; } }"""


def _project_past_software_notice(page, pts: np.ndarray) -> dict:
    """Project ``pts`` with the page's camera; if viser's headless-only "software WebGL" notice covers one of them
    (on a loaded machine it can appear long after the page connected, and its close button may not answer in
    time), hide that notice - as a user closes it once - and project again. Anything else covering a point (our
    panel, our notifications) is left for the test to see."""
    res = page.evaluate(_JS_PROJECT_MANY, pts.tolist())
    for _ in range(3):
        covered = [p for p in res["points"] if not p["onCanvas"]]
        if not any(SOFTWARE_WEBGL_TITLE in p["notice"] or "software mode" in (p["over"] or "") for p in covered):
            return res
        page.evaluate(_JS_HIDE_SOFTWARE_NOTICE, SOFTWARE_WEBGL_TITLE)
        next_frames(page, 2)
        res = page.evaluate(_JS_PROJECT_MANY, pts.tolist())
    return res


@pytest.mark.parametrize("projector", [False, True], ids=["1280x800", "presentation-1280x720"])
def test_every_learn_step_frames_what_it_talks_about_in_view_and_unhidden(viser_app, page_for, projector):
    """Also as a teacher runs it: presentation mode on a 1280x720 projector, nobody touching the camera."""
    app = viser_app(lambda: serve(present=projector, plain_light=True))
    page, _ = page_for(app.url, dismiss_notification=False)
    if projector:
        page.set_viewport_size({"width": 1280, "height": 720})
    # viser's own "software WebGL" notice (headless only; a user closes it once) would cover the top left
    dismiss_software_webgl_notification(page, timeout_s=10.0)
    mesh = app.loaded.mesh
    for i, step in enumerate(teaching.STEPS):
        app.views.lesson_go(i)
        wait_camera(page, app)
        dismiss_software_webgl_notification(page, timeout_s=0.3)  # on a loaded machine it can come late
        objects = _step_objects(app, step)
        for name, pts in objects.items():
            res = _project_past_software_notice(page, pts)
            left, top, w, h = res["canvas"]
            for j, p in enumerate(res["points"]):
                where = f"step {i + 1}: {name} #{j} at {p['x']:.0f},{p['y']:.0f}"
                assert p["inFront"], where
                assert left <= p["x"] <= left + w and top <= p["y"] <= top + h, where + " off the canvas"
                assert p["onCanvas"], where + f" under {p['over']}"
            if not page.evaluate(_JS_SOLID_CELL):
                continue  # the cell is drawn see-through at this step: nothing opaque can hide anything
            if name in ("robot", "sensor"):
                continue  # frame origins sit inside the robot's base and the sensor head's casing by design
            hidden = _hidden_by_mesh(mesh, np.array(res["camera"]), pts, slack_mm=0.5 * app.state.display.marker_mm)
            assert not hidden.any(), f"step {i + 1}: {name} {np.flatnonzero(hidden).tolist()} hidden by the mesh"
    # the views were framed beside the panel from the canvas's width in its own pixels: after every step's frames
    # (slow under software WebGL, which lowers viser's adaptive render scale) it is still the page's CSS width
    css_width = page.evaluate("() => window.innerWidth")
    widths = [c.camera.image_width for c in app.server.get_clients().values()]
    assert widths and all(w == css_width for w in widths), (widths, css_width)
    app.views.lesson_stop()


# Meshes and lines of a gizmo the user can see (itself and every ancestor visible), outside its own children (the
# point's sphere and label): the gizmo's arrows and planes.
_JS_GIZMO_VISIBLE = """(name) => { const m = window.__viserMutable.nodeRefFromName; const o = m[name];
  if (!o) return null; const own = new Set();
  for (const child of [name + '/sphere', name + '/label']) { if (m[child]) m[child].traverse((c) => own.add(c)); }
  let n = 0;
  o.traverse((c) => { if (!(c.isMesh || c.isLine2) || own.has(c)) return;
    let v = true; for (let q = c; q; q = q.parent) if (!q.visible) v = false; if (v) n += 1; });
  return n; }"""


def test_only_the_selected_point_has_a_gizmo_and_a_refused_drag_returns_it(viser_app, page_for):
    app = viser_app(lambda: serve(simple_arm=True, plain_light=True))
    page, _ = page_for(app.url)
    # the View tab's camera presets, clicked as a user does (a button group's click carries the option's text: the
    # message guard once dropped it as "not a true/false value", and the camera never moved)
    cid = next(iter(app.server.get_clients()))
    wait_for(lambda: cid in app.ctx.camera.last, 30.0, message="the opening camera sent", page=page)
    opening = np.array(app.ctx.camera.last[cid].position)
    page.get_by_role("tab", name="View").click()
    page.get_by_role("button", name="close-up", exact=True).click()
    wait_for(
        lambda: np.linalg.norm(np.array(app.ctx.camera.last[cid].position) - opening) > 1.0,
        15.0,
        message="the close-up preset moved the camera",
        page=page,
    )
    assert not app.messages, app.messages
    wait_camera(page, app)
    wait_for(lambda: page.evaluate(_JS_GIZMO_VISIBLE, "/targets/H1/gizmo"), 10.0, message="H1's gizmo")
    page_caught_up(page, app.server)

    def gizmo_meshes(name: str) -> int:
        wait_for(lambda: page.evaluate("(n) => !!window.__viserMutable.nodeRefFromName[n]", name + "/sphere"), 10.0)
        return int(page.evaluate(_JS_GIZMO_VISIBLE, name))

    assert gizmo_meshes("/targets/H1/gizmo") > 0
    for kind, ids in (("targets", app.session.last.targets.ids), ("fiducials", app.session.last.fiducial_ids)):
        for pid in ids:
            if (kind, pid) != ("targets", "H1"):
                assert gizmo_meshes(f"/{kind}/{pid}/gizmo") == 0, pid
    # a refused drag: pull H1's z arrow far up, beyond the arm's reach. The session keeps the last place it
    # accepted; the handle in the page must end there, not where the mouse let go
    app.views.show_camera("whole cell")
    wait_camera(page, app)
    grip = node_screen_position(page, "/targets/H1/gizmo", (0.0, 0.0, 0.7 * app.nodes.gizmo_scale()))
    drag(page, grip, (grip[0], 5.0), steps=10, step_ms=25)  # each move waits for a frame (software WebGL)
    wait_for(lambda: app.messages, 15.0, message="a refusal message")
    assert "reach" in app.last_message, app.last_message
    refused_z = float(app.last_message.split("point 0 at (")[1].split(")")[0].split(",")[2])
    # the drag's end reaches the server and every drag event is handled (latest wins: no backlog, even on a
    # loaded machine); then the server's handle is where the session kept the point
    wait_for(lambda: app.evaluate.drags.ends >= 1, 30.0, message="the drag's end handled")
    assert app.evaluate.wait_drags(30.0)
    kept = np.array(app.session.last.targets.positions[0])
    assert kept[2] < refused_z - 10.0
    np.testing.assert_allclose(app.evaluate.gizmo("targets", "H1").position, kept)

    def page_position():
        return np.array(
            page.evaluate(
                "(n) => { const o = window.__viserMutable.nodeRefFromName[n]; o.updateWorldMatrix(true, false);"
                " const m = window.__viserMutable.nodeRefFromName['/mesh']; const V = o.position.constructor;"
                " const w = o.localToWorld(new V(0, 0, 0)); const l = m.worldToLocal(w); return [l.x, l.y, l.z]; }",
                "/targets/H1/gizmo/sphere",
            )
        )

    wait_for(lambda: np.linalg.norm(page_position() - kept) < 0.5, 15.0, message="H1's handle at the kept place")


def test_clicking_selects_and_the_error_slice_changes_after_a_real_drag(viser_app, page_for):
    app = viser_app(lambda: serve(simple_arm=True, plain_light=True))
    page, _ = page_for(app.url)
    app.evaluate.set_layer("slice", True)
    app.views.show_camera("close-up")
    wait_camera(page, app)
    others = [name for name in app.state.layers if name != "slice" and app.state.layers[name]]

    def slice_alone_shot():
        """The view with every layer but the slice hidden: what changes is the slice."""
        for name in others:
            app.evaluate.set_layer(name, False)
        page_caught_up(page, app.server)
        png = page.screenshot(animations="disabled")
        for name in others:
            app.evaluate.set_layer(name, True)
        page_caught_up(page, app.server)
        return decode_png(png).astype(int)

    before = slice_alone_shot()

    # a real click on fiducial F5's sphere selects it: its gizmo appears, H1's goes
    def click_f5() -> bool:
        """Click F5's sphere where the page draws it now; True once the server has it selected. Under load the page
        may still be redrawing the layers just switched back on, and a click then lands on nothing: click again."""
        if app.state.selected == ("fiducials", "F5"):
            return True
        page.mouse.click(*node_screen_position(page, "/fiducials/F5/gizmo/sphere"))
        try:  # the click's answer, or a second click
            wait_for(lambda: app.state.selected == ("fiducials", "F5"), 2.0, message="F5 selected", page=page)
        except TimeoutError:
            return False
        return True

    wait_for(click_f5, 30.0, interval_s=0.2, message="F5 selected by a click", page=page)
    wait_for(lambda: page.evaluate(_JS_GIZMO_VISIBLE, "/fiducials/F5/gizmo"), 5.0, message="F5's gizmo shown")
    assert page.evaluate(_JS_GIZMO_VISIBLE, "/targets/H1/gizmo") == 0
    page_caught_up(page, app.server)
    image0 = np.array(app.slice_node.handle.image)
    f0 = np.array(app.evaluate.gizmo("fiducials", "F5").position)
    scale = app.nodes.gizmo_scale()
    a = node_screen_position(page, "/fiducials/F5/gizmo", (0.7 * scale, 0.0, 0.0))
    b = node_screen_position(page, "/fiducials/F5/gizmo", (2.5 * scale, 0.0, 0.0))
    drag(page, a, b, steps=8)
    wait_for(lambda: not np.allclose(app.evaluate.gizmo("fiducials", "F5").position, f0), 5.0, message="F5 moved")
    # the drag's end: the slice is recomputed and sent
    wait_for(
        lambda: not np.array_equal(np.array(app.slice_node.handle.image), image0),
        30.0,
        message="a new slice",
        page=page,
    )
    # only the slice is drawn in both shots (same camera): pixels that changed are the slice's new colours; the new
    # image reaches the browser and is drawn when it is drawn (a loaded machine takes seconds), so poll for it
    for name in others:
        app.evaluate.set_layer(name, False)
    counts = []

    def slice_changed() -> bool:
        after = decode_png(page.screenshot(animations="disabled")).astype(int)
        changed = np.abs(after - before).max(axis=2) > 10
        changed[:, 860:] = False  # the panel, whose numbers changed too
        counts.append(int(changed.sum()))
        return counts[-1] > 2000

    wait_for(slice_changed, 30.0, interval_s=0.5, message="the slice redrawn (over 2000 pixels changed)", page=page)


@pytest.mark.parametrize("present", [False, True], ids=["1280x800", "projector 1280x720"])
def test_a_target_dragged_out_of_the_frame_comes_back_into_view(viser_app, page_for, present):
    """Issue 39: a target dragged beyond what the camera shows is brought back into the view (beside the panel) at
    the drag's end, with its landing bullseye and clear of the view's edges (on the projector it stayed at the very
    edge, its label and bullseye cut off); the camera keeps its viewing direction."""
    app = viser_app(lambda: serve(simple_arm=True, plain_light=True, present=present))
    page, _ = page_for(app.url)
    if present:
        page.set_viewport_size({"width": 1280, "height": 720})
    app.views.select("targets", "H1")
    app.views.show_camera("selected point")  # a tight view of H1 and its bullseye
    wait_camera(page, app)
    cid = next(iter(app.server.get_clients()))
    before = app.ctx.camera.last[cid]
    i = app.session.last.targets.ids.index("H1")
    start = np.array(app.session.last.targets.positions[i], float)
    # well out of that view to its left (across the viewing direction), still within the arm's reach
    right = np.cross(before.forward, [0.0, 0.0, 1.0])
    away = start - 250.0 * right / np.linalg.norm(right)
    res = page.evaluate(_JS_PROJECT_MANY, [away.tolist()])
    assert not res["points"][0]["onCanvas"] or res["points"][0]["x"] > res["canvas"][2] - 400, res  # out of view
    assert app.evaluate.handle_drag("targets", "H1", start, "start") is not None
    ev = app.evaluate.handle_drag("targets", "H1", away, "end")
    assert ev is not None, app.last_message
    wait_for(lambda: app.ctx.camera.last[cid] is not before, 10.0, message="the camera moved", page=page)
    after = app.ctx.camera.last[cid]
    np.testing.assert_allclose(after.forward, before.forward, atol=1e-6)  # the same viewing direction
    wait_camera(page, app)

    land = app.state.landing
    assert land is not None and land.target == "H1"
    r = land.ring_mm * land.scale
    ring = [land.anchor + d for d in ([r, 0, 0], [-r, 0, 0], [0, r, 0], [0, -r, 0])]
    shown = np.vstack([away, land.anchor, land.rigid, land.rrbc, *ring])
    panel = PRESENTATION_PANEL_WIDTH_PX if present else PANEL_WIDTH_PX

    def seen() -> bool:  # H1 and its bullseye on the canvas, left of the panel, 30 px in from the view's edges
        res = page.evaluate(_JS_PROJECT_MANY, shown.tolist())
        left, top, w, h = res["canvas"]
        return all(
            p["inFront"] and left + 30 <= p["x"] <= left + w - panel - 30 and top + 30 <= p["y"] <= top + h - 30
            for p in res["points"]
        )

    wait_for(seen, 15.0, message="H1 and its bullseye in the page's view, left of the panel", page=page)


@pytest.mark.parametrize("size", [(1600, 900), (1280, 800)], ids=["1600x900", "1280x800"])
def test_the_opening_view_frames_the_work_with_the_arm_behind_it(viser_app, page_for, size):
    """Issue 39, item 3: as the app opens on a wide screen and on the default one, every target and fiducial and the
    selected target's bullseye (its centre and both landings) are on the canvas beside the panel, none hidden by the
    cell; and the camera looks at the work from its far side: the robot's base is farther from the camera than the
    work's centre (the arm stands behind the work as context, not in front of it)."""
    app = viser_app(lambda: serve(plain_light=True))
    page, _ = page_for(app.url, dismiss_notification=False)
    page.set_viewport_size({"width": size[0], "height": size[1]})
    dismiss_software_webgl_notification(page, timeout_s=10.0)
    app.views.show_camera("work area")  # what a new tab opens with, framed for this tab's size
    wait_camera(page, app)
    ev = app.session.last
    up = np.array([0.0, 0.0, 0.9 * app.state.display.marker_mm])
    land = app.state.landing
    pts = np.vstack([ev.targets.positions + up, ev.fiducial_positions + up, [land.anchor, land.rigid, land.rrbc]])
    res = _project_past_software_notice(page, pts)
    left, top, w, h = res["canvas"]
    for j, p in enumerate(res["points"]):
        assert p["inFront"] and p["onCanvas"], (j, p)
        assert left <= p["x"] <= left + w - PANEL_WIDTH_PX and top <= p["y"] <= top + h, (j, p)
    camera = np.array(res["camera"])
    hidden = _hidden_by_mesh(app.loaded.mesh, camera, pts, slack_mm=0.5 * app.state.display.marker_mm)
    assert not hidden.any(), np.flatnonzero(hidden)
    work = np.vstack([ev.targets.positions, ev.fiducial_positions])
    centre = 0.5 * (work.min(0) + work.max(0))
    assert np.linalg.norm(camera) > np.linalg.norm(camera - centre) + 0.25 * np.linalg.norm(centre[:2])
