"""Authoring a cell in headless Chromium, as an integrator does it: upload their mesh from the File tab, start a new
cell on it (*New cell from this mesh*), place a fiducial by clicking on the mesh in the 3-D view, save the scene (a
real download), load the saved scene back and see the same numbers in the page."""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_viz.serve import serve

from .helpers import wait_camera, wait_for

pytestmark = pytest.mark.browser

_JS_PROJECT = """(p) => { const m = window.__viserMutable; const obj = m.nodeRefFromName['/mesh'];
  obj.updateWorldMatrix(true, false); m.camera.updateMatrixWorld(); const V = m.camera.position.constructor;
  const q = obj.localToWorld(new V(p[0], p[1], p[2])).project(m.camera); const r = m.canvas.getBoundingClientRect();
  return [r.left + (q.x + 1) / 2 * r.width, r.top + (1 - q.y) / 2 * r.height]; }"""

_JS_TABLE_ROWS = """() => Array.from(document.querySelectorAll('table tr'))
  .map((tr) => Array.from(tr.cells).map((c) => c.innerText.trim()))"""


def _rows(page):
    return {r[0]: r[1:] for r in page.evaluate(_JS_TABLE_ROWS) if r and r[0].startswith("T")}


def _server_rows(app):
    """The targets' rows of the table the server last sent (the Explore tab's markdown), as `_rows` reads them."""
    rows = {}
    for line in app.controls.explore.table.content.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells and cells[0].startswith("T"):
            rows[cells[0]] = cells[1:]
    return rows


def test_upload_a_mesh_click_to_place_save_and_reload_to_the_same_numbers(viser_app, page_for, tmp_path):
    import trimesh

    from rrbc_viz.tables import target_table

    slab = trimesh.creation.box(extents=(700, 700, 20))
    slab.apply_translation((450, 0, 40))  # over the fixture plate: its top is at z = 50
    mesh_file = tmp_path / "slab.stl"
    slab.export(mesh_file)
    app = viser_app(lambda: serve(data_dirs=[tmp_path], simple_arm=True, plain_light=True))
    page, _ = page_for(app.url)
    page.get_by_role("tab", name="File").click()
    with page.expect_file_chooser() as chooser:
        page.get_by_text("Upload cell mesh").click()
    chooser.value.set_files(str(mesh_file))
    wait_for(lambda: app.authoring.uploaded_mesh is not None, 30, message="the mesh uploaded", page=page)
    # an empty start on it: the demo's points go, one target T1 on the slab, the camera on the whole cell
    page.get_by_role("button", name="New cell from this mesh").click()
    page.get_by_text("A new cell on slab.stl", exact=False).first.wait_for(state="visible", timeout=30_000)
    assert app.session.last.targets.ids == ("T1",) and len(app.session.last.fiducial_ids) == 0
    assert abs(app.session.last.targets.positions[0][2] - 51.0) < 1e-6  # on the slab's top (a hair above it)
    page.get_by_label("Click on the cell adds").click()
    page.get_by_role("option", name="fiducial", exact=True).click()
    wait_for(lambda: app.state.click_mode == "fiducials", 10, message="click mode on the server", page=page)
    app.views.show_camera("work area")  # the target and the registration points over it
    wait_camera(page, app)
    n = len(app.session.last.fiducial_ids)
    t1 = app.session.last.targets.positions[0]
    spot = np.array([t1[0] + 60.0, t1[1] + 40.0, 50.0])  # on the slab beside T1
    x, y = page.evaluate(_JS_PROJECT, spot.tolist())
    page.mouse.click(x, y)
    wait_for(
        lambda: len(app.session.last.fiducial_ids) == n + 1, 15, message="a fiducial added by the click", page=page
    )
    added = app.session.last.fiducial_positions[-1]
    assert abs(added[2] - 50.0) < 1e-3 and np.linalg.norm(added[:2] - spot[:2]) < 5.0  # on the slab, where clicked
    page.get_by_role("tab", name="Explore").click()
    # the page shows the table the server sent after the click: the click's evaluation is in the session before its
    # table is sent (on a loaded machine, seconds before), so wait for the table of that evaluation, then the page
    wait_for(
        lambda: app.controls.explore.table.content == target_table(app.session.last)
        and len(_rows(page)) == 1
        and _rows(page) == _server_rows(app),
        30,
        message="the table",
        page=page,
    )
    before = _rows(page)
    # save: a real download, kept beside the mesh under the name the scene refers to
    page.get_by_role("tab", name="File").click()
    with page.expect_download(timeout=30_000) as dl:  # the download starts at once, under its full name
        page.get_by_text("Save scene (TOML)").click()
    saved = tmp_path / dl.value.suggested_filename
    assert saved.name == "slab.toml", saved.name  # the cell took its mesh's name
    dl.value.save_as(saved)
    assert 'mesh = "slab.stl"' in saved.read_text()  # the mesh file as uploaded, already beside it here
    page.get_by_text("keep the mesh slab.stl beside it", exact=False).first.wait_for(state="visible", timeout=15_000)
    # reload it through the File tab, as a user would: the folder was given with --data; rescan, pick, load
    page.get_by_role("button", name="Rescan folders").click()
    label = f"{tmp_path.name}/{saved.name}"
    wait_for(lambda: label in app.controls.file.path.options, 10, message="the rescan", page=page)
    page.get_by_label("Scene or data file").click()
    page.get_by_role("option", name=label, exact=True).click()
    wait_for(lambda: app.controls.file.path.value == label, 10, message="the pick", page=page)
    page.get_by_role("button", name="Load file").click()
    wait_for(  # a load rebuilds the whole cell in the page: on a loaded CI machine it took over 20 s
        lambda: app.loaded.label.endswith(saved.name) or saved.name in app.loaded.label,
        60,
        message="the saved scene loaded",
        page=page,
    )
    assert len(app.session.last.fiducial_ids) == n + 1
    page.get_by_role("tab", name="Explore").click()
    with app.ctx.lock:  # the load's install holds it from setting the label until the table is sent
        after = _server_rows(app)
    # first the page catches up with the table the server sent after the load, then that table is the one from
    # before the save (two steps, so a failure says whether the page lagged or the numbers changed)
    assert after == before, (after, before)
    try:
        wait_for(lambda: _rows(page) == after, 60, message="the reloaded table", page=page)
    except TimeoutError as exc:
        raise AssertionError(f"page {_rows(page)} / server {after}") from exc
