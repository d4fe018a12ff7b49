"""Authoring a cell in the app without a browser: a scene click adds the chosen point where its ray meets the
mesh; delete, undo and redo through the panel's buttons; move the sensor; an uploaded mesh becomes the cell's;
the downloads (scene, measurement plan, Slicer markups) hold the session, and the scene reloads to the same
numbers."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import viser

from rrbc_core.errors import InputError
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.session.explorer import ExplorerSession
from tests.viz.helpers import _press


def _scene_click(app, origin, direction):
    """A scene-level click as viser delivers it (SceneClickEvent to the on_click callback)."""
    event = viser.SceneClickEvent(
        client=None,
        client_id=0,
        ray_origin=tuple(origin),
        ray_direction=tuple(direction),
        screen_pos=(0.5, 0.5),
        modifier=None,
    )
    app.authoring.on_scene_click(event)


def test_clicks_add_points_where_the_ray_meets_the_mesh_and_edits_undo(app):
    panel = app.controls.authoring
    n_f = len(app.session.last.fiducial_ids)
    _scene_click(app, [500, 0, 800], [0, 0, -1])  # select mode: nothing is added
    assert len(app.session.last.fiducial_ids) == n_f
    panel.mode.value = "fiducial"
    _scene_click(app, [500, 0, 800], [0, 0, -1])  # straight down onto the fixture plate (top at z = 15)
    ev = app.session.last
    assert len(ev.fiducial_ids) == n_f + 1
    np.testing.assert_allclose(ev.fiducial_positions[-1], [500, 0, 15], atol=1e-3)
    assert ("fiducials", ev.fiducial_ids[-1]) in app.nodes.gizmo_items()  # drawn
    panel.mode.value = "registration point"
    _scene_click(app, [300, 300, 900], [0, 0, -1])  # onto the table (z = 0): the point goes 100 mm above it
    np.testing.assert_allclose(app.session.last.registration_positions[-1], [300, 300, 100], atol=1e-3)
    panel.mode.value = "target"
    panel.region.value = 6.0
    _scene_click(app, [450, 20, 800], [0, 0, -1])
    pid = app.session.last.targets.ids[-1]
    np.testing.assert_allclose(app.session.regions[pid].size, [6, 6, 6])
    _scene_click(app, [5000, 0, 800], [0, 0, -1])  # misses the mesh
    assert "did not meet the cell" in app.last_message
    assert not panel.undo.disabled and panel.redo.disabled
    app.views.select("targets", pid)
    _press(panel.delete)
    assert pid not in app.session.last.targets.ids and app.state.selected is None
    _press(panel.undo)
    assert pid in app.session.last.targets.ids and not panel.redo.disabled
    _press(panel.redo)
    assert pid not in app.session.last.targets.ids
    panel.sensor.value = (1000.0, -500.0, 1300.0)
    _press(panel.move_sensor)
    np.testing.assert_allclose(app.session.sensor_to_robot.translation, [1000, -500, 1300])


def test_downloads_hold_the_session_and_the_scene_reloads_to_the_same_numbers(app, tmp_path):
    app.authoring.set_click_mode("fiducials")
    app.authoring.add_at_ray([520, -60, 800], [0, 0, -1])
    app.evaluate.handle_drag("targets", "H3", [430.0, 40.0, 15.0], "end")
    ((name, content),) = app.authoring.export_authoring("scene")
    assert name.endswith(".toml")
    path = tmp_path / name
    path.write_bytes(content)
    shutil.copy(app.session.scene.mesh_path, tmp_path)  # the scene names its mesh; it opens only meshes beside it
    again = ExplorerSession.from_scene(load_scene(path)).last
    ev = app.session.last
    assert again.fiducial_ids == ev.fiducial_ids
    np.testing.assert_allclose(again.targets.error_rrbc, ev.targets.error_rrbc, rtol=1e-9)
    ((plan_name, plan),) = app.authoring.export_authoring("plan")
    assert plan_name.endswith(".csv") and b"planned_x" in plan
    docs = app.authoring.export_authoring("slicer")
    assert [n.rsplit("_", 1)[1] for n, _ in docs] == ["sensor.mrk.json", "robot.mrk.json"]
    assert json.loads(docs[0][1])["markups"][0]["controlPoints"][0]["label"]


def test_an_uploaded_mesh_becomes_the_cells(app, tmp_path):
    import trimesh

    box = trimesh.creation.box(extents=(600, 600, 20))
    box.apply_translation((450, 0, 40))  # a slab over the plate: clicks now land on its top (z = 50)
    stl = tmp_path / "slab.stl"
    box.export(stl)
    assert app.authoring.upload_mesh("bench_v3.stl", stl.read_bytes())
    assert app.session.name == "bench_v3"  # the cell carries its mesh's name
    app.authoring.set_click_mode("fiducials")
    assert "Adding fiducials" in app.controls.authoring.mode_md.content  # the mode is shown
    app.authoring.add_at_ray([450, 0, 800], [0, 0, -1])
    np.testing.assert_allclose(app.session.last.fiducial_positions[-1], [450, 0, 50], atol=1e-3)
    new = app.session.last.fiducial_ids[-1]
    assert app.state.selected == ("fiducials", new)  # what was added is selected, and said with its place
    assert f"Added fiducial {new} at (450.0, 0.0, 50.0) mm" in app.last_message
    assert not app.authoring.upload_mesh("notes.txt", b"hello")
    assert not app.authoring.upload_mesh("bad.stl", b"\x00" * 10)
    ((name, content),) = app.authoring.export_authoring("scene")
    assert b'mesh = "bench_v3.stl"' in content and b'name = "bench_v3"' in content and name == "bench_v3.toml"
    assert app.authoring.download_authoring("scene") is not None
    assert "keep the mesh bench_v3.stl beside it" in app.last_message
    # the user keeps the two side by side: the scene reloads with its mesh
    from rrbc_core.io.scene_toml import load_scene

    (tmp_path / "saved").mkdir()
    (tmp_path / "saved" / name).write_bytes(content)
    (tmp_path / "saved" / "bench_v3.stl").write_bytes(stl.read_bytes())
    again = load_scene(tmp_path / "saved" / name)
    np.testing.assert_allclose(again.load_mesh().bounds, box.bounds, atol=1e-6)
    assert again.name == "bench_v3" and new in again.fiducials.ids
    with pytest.raises(InputError, match="unknown export"):
        app.authoring.export_authoring("zip")


def test_the_plan_tab_suggests_where_to_measure_for_measured_data():
    from rrbc_viz.serve import serve
    from tests.paths import EXAMPLE_CSV

    app = serve(str(EXAMPLE_CSV))
    try:
        info = app.planning.info.content
        ev = app.session.last  # the Plan tab says what the Explore card says about each target (one coverage)
        assert f"**{int(ev.coverage.inside.sum())} of {len(ev.targets.ids)} targets** inside" in info
        assert "regions**" in info and "fully inside" in info
        assert app.planning.suggest_button.visible and not app.planning.suggest_button.disabled
        plan = app.plan.suggest_fiducials(3)
        assert plan is not None and len(app.planning.ghosts) == 3
        np.testing.assert_allclose(app.planning.ghosts[0].position, plan.suggested[0])
        assert "Measure 3 more fiducials here" in app.planning.suggestion_md.content
        assert not app.planning.accept_button.visible  # nothing to accept: they are places to measure
    finally:
        app.stop()


@pytest.mark.parametrize("fmt", ["stl", "obj", "ply", "glb", "3mf", "off"])
def test_every_advertised_mesh_format_loads(app, tmp_path, fmt):
    """The README and the refusal message name STL, OBJ, PLY, GLB and 3MF (and the File tab takes OFF): each loads
    as the cell's mesh, under its own name."""
    import trimesh

    box = trimesh.creation.box(extents=(600, 600, 20))
    box.apply_translation((450, 0, 40))
    data = box.export(file_type=fmt)
    name = f"bench.{fmt}"
    assert app.authoring.upload_mesh(name, data if isinstance(data, bytes) else data.encode()), app.last_message
    assert app.authoring.uploaded_mesh.name == name and len(app.loaded.mesh.faces) == 12


def test_an_uploaded_scene_that_fails_names_the_users_file_not_the_servers_folders(app):
    import tempfile

    assert app.files.load_upload("empty.toml", b"") is False
    assert app.files.load_upload("cell.toml", b'[scene]\nname = "x"\nmesh = "cell.glb"\n') is False
    for message in app.state.messages[-2:]:
        assert tempfile.gettempdir() not in message and "rrbc-upload-" not in message, message


def test_uploaded_meshes_leave_no_temporary_files(tmp_path):
    """Issue 31: a replaced upload's copy is removed at once, the last one when the app stops; a refused one never
    stays."""
    import trimesh

    from rrbc_viz.serve import serve

    a = serve(port=0)
    try:
        box = trimesh.creation.box(extents=(600, 600, 20))
        box.apply_translation((450, 0, 40))
        data = box.export(file_type="stl")
        assert a.authoring.upload_mesh("one.stl", data)
        first = a.authoring.uploaded_mesh.parent
        assert a.authoring.upload_mesh("two.stl", data)
        second = a.authoring.uploaded_mesh.parent
        assert not first.exists() and second.exists()
        assert not a.authoring.upload_mesh("bad.stl", b"\x00" * 10)
        assert a.authoring.uploaded_mesh.parent == second  # the refused upload left nothing, the cell kept two.stl
    finally:
        a.stop()
    assert not second.exists()


def test_a_replaced_mesh_gives_its_memory_back(tmp_path):
    """Issue 42: an accepted mesh's memory is returned when another replaces it (without `release_memory` the big
    upload's pages stay: glibc keeps freed pages, and this test fails). The resident set after a big mesh and then a small one again is
    within half the big file's size of where the small one left it."""
    import re

    import trimesh

    from rrbc_viz.serve import serve

    def rss_mb() -> float:
        return int(re.search(r"VmRSS:\s+(\d+)", open("/proc/self/status").read()).group(1)) / 1024

    small = trimesh.creation.box(extents=(600, 600, 20))
    small.apply_translation((450, 0, 40))
    big = trimesh.creation.icosphere(subdivisions=7, radius=300.0)  # 327 680 triangles, 15.6 MB as binary STL
    big.apply_translation((450, 0, 400))
    small_stl, big_stl = small.export(file_type="stl"), big.export(file_type="stl")
    a = serve(port=0)
    try:
        assert a.authoring.upload_mesh("small.stl", small_stl)
        before = rss_mb()
        assert a.authoring.upload_mesh("big.stl", big_stl)
        assert a.authoring.upload_mesh("small.stl", small_stl)
        assert rss_mb() - before < 0.5 * len(big_stl) / 2**20, (before, rss_mb())
    finally:
        a.stop()


def test_a_new_cell_from_an_uploaded_mesh_starts_empty_framed_on_it_and_saves_with_its_mesh(app, tmp_path):
    """Issue 30, item 3: *New cell from this mesh* - the demo's points go, one target and registration points over
    it come, no fiducials; every tab's camera shows the whole new cell; the saved scene names the uploaded mesh and
    reloads; a replaced upload's temporary copy goes; edits not saved are asked about first."""
    import trimesh

    box = trimesh.creation.box(extents=(500, 400, 30))
    box.apply_translation((420, -80, 200))  # a raised bench, away from the demo's plate: top at z = 215
    assert app.authoring.upload_mesh("bench_v3.stl", box.export(file_type="stl"))
    uploaded_dir = app.authoring.uploaded_mesh.parent
    demo_ids = set(app.session.last.targets.ids)
    assert app.authoring.new_cell_from_mesh()
    ev = app.session.last
    assert ev.targets.ids == ("T1",) and not set(ev.targets.ids) & (demo_ids - {"T1"})
    assert len(ev.fiducial_ids) == 0 and len(ev.registration_positions) >= 4
    t = ev.targets.positions[0]
    assert box.bounds[0, 0] <= t[0] <= box.bounds[1, 0] and box.bounds[0, 1] <= t[1] <= box.bounds[1, 1]
    assert abs(t[2] - 215.0) <= 1.5  # on the bench's top
    assert app.session.name == "bench_v3" and app.state.camera_preset == "whole cell"
    assert "A new cell on bench_v3.stl: one target T1" in app.last_message
    assert not uploaded_dir.exists() and app.authoring.uploaded_mesh.exists()  # the copy beside the new scene
    # the user adds a fiducial, then saves: the scene names the uploaded mesh and reloads with it
    app.authoring.set_click_mode("fiducials")
    app.authoring.add_at_ray([t[0] + 60, t[1], 800], [0, 0, -1])
    assert len(app.session.last.fiducial_ids) == 1
    ((name, content),) = app.authoring.export_authoring("scene")
    assert name == "bench_v3.toml" and b'mesh = "bench_v3.stl"' in content
    (tmp_path / name).write_bytes(content)
    (tmp_path / "bench_v3.stl").write_bytes(app.authoring.uploaded_mesh.read_bytes())
    again = load_scene(tmp_path / name)
    np.testing.assert_allclose(again.load_mesh().bounds, box.bounds, atol=1e-6)
    # an edit not saved: a second new cell asks first, and nothing changes until the user agrees
    asked = []
    app.ctx.controls.file.confirm = lambda title, text, button, again: asked.append(again)
    assert not app.authoring.new_cell_from_mesh()
    assert len(asked) == 1 and len(app.session.last.fiducial_ids) == 1
    asked[0]()
    assert len(app.session.last.fiducial_ids) == 0
    # another source opened: the upload's copy goes, and a saved scene names that source's own mesh
    kept = app.authoring.uploaded_mesh
    assert app.files.load(None, confirmed=True)
    assert app.authoring.uploaded_mesh is None and not kept.exists()
    ((_, content),) = app.authoring.export_authoring("scene")
    assert b"bench_v3" not in content


@pytest.mark.slow
def test_a_new_cell_on_a_mesh_the_arm_cannot_reach_is_refused_and_nothing_changes(app):
    import trimesh

    far = trimesh.creation.box(extents=(300, 300, 20))
    far.apply_translation((5000, 0, 0))  # 5 m away: beyond the UR5's reach
    assert app.authoring.upload_mesh("far.stl", far.export(file_type="stl"))
    before = app.session.last.targets.ids
    assert not app.authoring.new_cell_from_mesh()
    assert "no upward-facing surface" in app.last_message and "far.stl" in app.last_message
    assert "rrbc-mesh-" not in app.last_message
    assert app.session.last.targets.ids == before


def test_a_click_ray_that_is_not_a_ray_adds_nothing_and_says_so(app, capsys):
    """Issue 42, item 2: a tab's click with NaN, infinite, zero or malformed rays: nothing added, a message, no
    traceback; a real ray afterwards still adds the point."""
    app.authoring.set_click_mode("fiducials")
    before = app.session.layout["fiducials"].ids
    for origin, direction in (
        ([float("nan"), 0, 800], [0, 0, -1]),
        ([520, -60, 800], [0, 0, float("inf")]),
        ([520, -60, 800], [0, 0, 0]),
        ([520, -60], [0, 0, -1]),
        ("abc", [0, 0, -1]),
    ):
        assert app.authoring.add_at_ray(origin, direction) is None
        assert "not a ray" in app.last_message
    assert app.session.layout["fiducials"].ids == before
    assert "Traceback" not in capsys.readouterr().err
    assert app.authoring.add_at_ray([520, -60, 800], [0, 0, -1]) is not None
    assert len(app.session.layout["fiducials"].ids) == len(before) + 1
