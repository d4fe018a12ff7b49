"""Editing a scene session (rrbc_core.session.edits): add and delete points, move the sensor, undo/redo, save
the scene (it reloads to the same numbers) and the measurement plan (filled, it reads as a measurement file)."""

from __future__ import annotations

import io
import shutil

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import read_measurements
from rrbc_core.io.scene import default_scene_path
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.session import edits
from rrbc_core.session.explorer import ExplorerSession


@pytest.fixture
def session():
    return ExplorerSession.from_scene(load_scene(default_scene_path()))


def _numbers(ev):
    return (ev.summary["rmst_rigid_mm"], ev.summary["rmst_rrbc_mm"], ev.targets.error_rrbc.copy())


def test_add_delete_undo_redo(session):
    ev0 = session.last
    n_f = len(ev0.fiducial_ids)
    ev = edits.add_point(session, "fiducials", [500.0, 150.0, 15.0])
    assert len(ev.fiducial_ids) == n_f + 1 and ev.fiducial_ids[-1] == f"F{n_f + 1}"
    ev = edits.add_point(session, "targets", [450.0, 0.0, 15.0], region_mm=6.0)
    assert ev.targets.ids[-1] == "T9" and session.regions["T9"].kind == "box"
    np.testing.assert_allclose(session.regions["T9"].size, [6, 6, 6])
    edits.add_point(session, "candidates", [480.0, 120.0, 15.0])
    assert session.candidates.ids[-1] == f"C{len(session.candidates.ids):03d}"
    ev = edits.remove_point(session, "fiducials", "F1")
    assert "F1" not in ev.fiducial_ids
    ev = edits.undo(session)
    assert "F1" in ev.fiducial_ids
    ev = edits.undo(session)
    ev = edits.undo(session)
    ev = edits.undo(session)
    assert ev.fiducial_ids == ev0.fiducial_ids and ev.targets.ids == ev0.targets.ids
    np.testing.assert_allclose(ev.targets.error_rrbc, ev0.targets.error_rrbc)  # the same numbers as before
    with pytest.raises(InputError, match="nothing to undo"):
        edits.undo(session)
    ev = edits.redo(session)
    assert len(ev.fiducial_ids) == n_f + 1
    # refusals leave the session as it was
    with pytest.raises(InputError, match="taken"):
        edits.add_point(session, "targets", [400.0, 0.0, 15.0], pid="F1")
    with pytest.raises(InputError, match="at least 3"):
        for pid in list(session.layout["registration"].ids):
            edits.remove_point(session, "registration", pid)
    assert len(session.layout["registration"].ids) == 3
    with pytest.raises(InputError, match="reach"):
        edits.add_point(session, "targets", [3000.0, 0.0, 15.0])
    assert session.last.targets.ids[-1] != "T9" or len(session.last.targets.ids) == len(ev0.targets.ids)


def test_a_saved_scene_reloads_to_the_same_numbers(session, tmp_path):
    edits.add_point(session, "fiducials", [500.0, 150.0, 15.0])
    edits.add_point(session, "targets", [450.0, 10.0, 15.0], region_mm=3.0)
    session.move("targets", "H2", [410.0, -40.0, 15.0])
    edits.move_sensor(session, [1000.0, -500.0, 1300.0])
    ev = session.last
    path = tmp_path / "saved.toml"
    path.write_text(edits.scene_toml(session), encoding="utf-8")
    shutil.copy(session.scene.mesh_path, tmp_path)  # the scene names its mesh; it opens only meshes beside it
    again = ExplorerSession.from_scene(load_scene(path))
    ev2 = again.last
    assert ev2.fiducial_ids == ev.fiducial_ids and ev2.targets.ids == ev.targets.ids
    np.testing.assert_allclose(ev2.targets.positions, ev.targets.positions)
    np.testing.assert_allclose(again.sensor_to_robot.translation, session.sensor_to_robot.translation)
    np.testing.assert_allclose(again.sensor_to_robot.rotation, session.sensor_to_robot.rotation, atol=1e-12)
    for a, b in zip(_numbers(ev), _numbers(ev2)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
    assert again.candidates.ids == session.candidates.ids


def test_the_measurement_plan_filled_in_reads_as_a_measurement_file(session, tmp_path):
    text = edits.measurement_plan(session)
    lines = [ln for ln in text.splitlines() if not ln.startswith("#")]
    header = lines[0].split(",")
    assert header[-3:] == ["planned_x", "planned_y", "planned_z"]
    rows = [ln.split(",") for ln in lines[1:]]
    roles = [r[1] for r in rows]
    n_r, n_f = len(session.layout["registration"].ids), len(session.layout["fiducials"].ids)
    assert roles == ["registration"] * n_r + ["fiducial"] * n_f + ["target"] * len(session.layout["targets"].ids)
    assert all(r[2:8] == [""] * 6 for r in rows)  # readings left to fill
    # fill it the way a user would: with what was measured (here: the session's own readings)
    ev = session.last
    readings = {}
    for _kind, rd, ids in (
        ("registration", ev.registration_readings, ev.registration_ids),
        ("fiducial", ev.fiducial_readings, ev.fiducial_ids),
    ):
        for i, pid in enumerate(ids):
            readings[pid] = (rd.sensor[i], rd.robot[i])
    for i, pid in enumerate(ev.targets.ids):
        readings[pid] = (ev.targets.sensor[i], np.full(3, np.nan))
    out = io.StringIO()
    out.write(lines[0] + "\n")
    for r in rows:
        s, rob = readings[r[0]]
        cells = [repr(float(v)) for v in s] + ["" if not np.isfinite(v) else repr(float(v)) for v in rob]
        out.write(",".join(r[:2] + cells + r[8:]) + "\n")
    filled = tmp_path / "filled.csv"
    filled.write_text(out.getvalue(), encoding="utf-8")
    m = read_measurements(filled)
    assert len(m.ids) == len(rows) and "planned_x" in m.extra
    measured = ExplorerSession.from_measurements(m).last
    order = [list(measured.targets.ids).index(pid) for pid in ev.targets.ids]  # the plan's order is a path
    np.testing.assert_allclose(measured.targets.correction[order], ev.targets.correction, atol=1e-9)
