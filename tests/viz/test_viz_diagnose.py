"""The Diagnose tab is `rrbc diagnose` (issue 25, item 1): on a file opened as it is, on the same file edited in the
app, and on a scene's data set (what the CSV download writes, which is what `rrbc simulate --out` writes), the tab
shows exactly the lines the command prints and its verdict is the command's JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rrbc_core.cli import main
from rrbc_core.io.measurements import MeasurementSet, read_measurements
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.session import data_set
from rrbc_core.simulation.datasets import simulated_data
from rrbc_viz.diagnosis_panel import unescape
from rrbc_viz.serve import serve
from tests.paths import DEMO, EXAMPLE_CSV
from tests.support.joint_data import joint_file
from tests.viz.helpers import _press


def _cli(capsys, *args) -> str:
    capsys.readouterr()
    assert main(["diagnose", *map(str, args)]) == 0
    return capsys.readouterr().out


def _tab_lines(app) -> list[str]:
    """The tab's paragraphs after its heading, as plain text (a fenced block's lines as they are)."""
    paragraphs = app.controls.tabs["diagnose"].diagnosis.content.split("\n\n")
    assert paragraphs[0].startswith(("Diagnosis of", "**Edited data.**")), paragraphs[0]
    out = []
    for p in paragraphs[1:]:
        if p.startswith("```\n") and p.endswith("\n```"):
            out += p[4:-4].split("\n")
        else:
            out.append(unescape(p))
    return out


def _assert_tab_is_cli(app, capsys, path, *options) -> None:
    _press(app.controls.tabs["diagnose"].diagnose)
    assert app.state.diagnosis is not None, app.controls.tabs["diagnose"].diagnosis.content
    text = _cli(capsys, path, *options)
    assert _tab_lines(app) == text.rstrip("\n").split("\n")
    assert app.state.diagnosis.to_json() == json.loads(_cli(capsys, path, *options, "--json"))


def _repeats_time_checks(path, seed: int = 3):
    """A simulated file of the demo scene with repeated readings (each registration point measured again at the
    end, new noise), a time column and check rows: the layout of a real measuring session."""
    scene = load_scene(DEMO)
    m = simulated_data(scene, seed=seed)
    rng = np.random.default_rng(seed)
    reg = [i for i, r in enumerate(m.roles) if r in ("registration", "both")]
    t_end = float(np.nanmax(m.time))
    again = MeasurementSet(
        ids=tuple(m.ids[i] for i in reg),
        roles=tuple(m.roles[i] for i in reg),
        sensor=m.sensor[reg] + rng.normal(0, 0.03, (len(reg), 3)),
        robot=m.robot[reg] + rng.normal(0, 0.03, (len(reg), 3)),
        time=t_end + 5.0 * (1 + np.arange(len(reg))),
        lines=tuple(0 for _ in reg),
        extra={k: tuple(v[i] for i in reg) for k, v in m.extra.items()},
    )
    both = MeasurementSet(
        ids=m.ids + again.ids,
        roles=m.roles + again.roles,
        sensor=np.vstack([m.sensor, again.sensor]),
        robot=np.vstack([m.robot, again.robot]),
        time=np.concatenate([m.time, again.time]),
        lines=tuple(0 for _ in range(len(m) + len(again))),
        extra={k: m.extra[k] + again.extra[k] for k in m.extra},
    )
    write_measurements(path, both)
    return path


@pytest.mark.parametrize("which", ["example", "repeats_time_checks", "joints"])
def test_the_tab_shows_what_rrbc_diagnose_prints_for_a_file_as_opened(which, tmp_path, capsys):
    if which == "example":
        path = EXAMPLE_CSV
    elif which == "repeats_time_checks":
        path = _repeats_time_checks(tmp_path / "session.csv")
    else:
        path = joint_file(tmp_path / "arm.csv", seed=5)
    mset = read_measurements(path)
    if which == "repeats_time_checks":
        assert len(set(mset.ids)) < len(mset.ids) and np.isfinite(mset.time).all() and "check" in mset.roles
    if which == "joints":
        assert "q1" in mset.extra
    app = serve(path, port=0)
    try:
        _assert_tab_is_cli(app, capsys, path)
        assert app.state.diagnosis_data.measurements is app.session.mset  # the file as opened, every row
        head = app.controls.tabs["diagnose"].diagnosis.content.split("\n\n")[0]
        assert "as opened" in head and "Edited" not in head
        if which == "example":
            # the numbers the issue measured on the CLI, now in the tab: noise from the repeats, the field, checks
            dg = app.state.diagnosis
            assert dg.noise_source == "repeats" and "smooth_field" in dg.names and dg.basis == "checks"
            assert dg.bias_rms_mm > 5 * max(dg.noise_sigma_mm)
    finally:
        app.stop()


def test_edited_measured_data_are_diagnosed_as_edited_and_the_download_reproduces_the_tab(tmp_path, capsys):
    app = serve(EXAMPLE_CSV, port=0)
    try:
        fid = app.session.last.fiducial_ids
        app.evaluate.toggle_fiducial(fid[5])  # exclude one fiducial
        _press(app.controls.tabs["diagnose"].diagnose)
        head = unescape(app.controls.tabs["diagnose"].diagnosis.content.split("\n\n")[0])
        assert head.startswith("**Edited data.**") and fid[5] in head
        rows = app.state.diagnosis_data.measurements
        assert fid[5] not in rows.ids and len(rows) < len(app.session.mset)
        name, content = app.files.export("csv")
        path = tmp_path / name
        path.write_bytes(content)
        _assert_tab_is_cli(app, capsys, path)
    finally:
        app.stop()


@pytest.mark.slow
def test_a_scenes_tab_is_rrbc_diagnose_of_its_download_which_is_what_rrbc_simulate_writes(tmp_path, capsys):
    app = serve(port=0)
    try:
        name, content = app.files.export("csv")
        download = tmp_path / name
        download.write_bytes(content)
        # the scene as loaded: the download's rows are those of `rrbc simulate --out` with the scene's seed
        out = tmp_path / "sim.csv"
        capsys.readouterr()
        assert main(["simulate", str(DEMO), "--trials", "5", "--out", str(out)]) == 0
        a, b = read_measurements(out), read_measurements(download)
        assert a.ids == b.ids and a.roles == b.roles and a.extra == b.extra
        for x, y in ((a.sensor, b.sensor), (a.robot, b.robot), (a.time, b.time)):
            np.testing.assert_array_equal(x, y)
        assert {"registration", "fiducial", "target", "check"} <= set(a.roles) and "q1" in a.extra
        data = data_set.session_data(app.session)
        assert data.robot == "ur5" and data.tool_mm == 100.0  # the scene's arm reads the joint columns
        _assert_tab_is_cli(app, capsys, download, "--robot", "ur5", "--tool", "100")
        assert "rrbc diagnose DATA.csv --tool 100" in app.controls.tabs["diagnose"].diagnosis.content
        # after edits and new settings the tab diagnoses the data as they are now, and the download follows
        app.evaluate.handle_drag("fiducials", "F12", [760.0, 0.0, 120.0], "end")
        app.evaluate.change_settings(bias_scale=0.5, seed=11)
        name, content = app.files.export("csv")
        download.write_bytes(content)
        _assert_tab_is_cli(app, capsys, download, "--tool", "100")
        assert "seed 11, noise x1, bias x0.5" in unescape(app.controls.tabs["diagnose"].diagnosis.content)
    finally:
        app.stop()


def test_the_verdict_goes_stale_when_its_data_change_not_when_the_method_does(app):
    panel = app.controls.tabs["diagnose"].diagnosis
    _press(app.controls.tabs["diagnose"].diagnose)
    fresh = panel.content
    app.evaluate.set_display(magnification=50.0)
    app.evaluate.change_settings(interpolation="tps")
    assert panel.content == fresh and not app.state.diagnosis_stale
    verdict = app.state.diagnosis
    ev = app.evaluate.handle_drag("fiducials", "F12", [760.0, 0.0, 120.0], "update")  # marked at once, not recomputed
    assert ev is not None and app.state.diagnosis_stale and app.state.diagnosis is verdict
    assert panel.content == "**(data changed since — press again)**\n\n" + fresh
    app.evaluate.handle_drag("fiducials", "F12", [760.0, 0.0, 120.0], "end")
    assert panel.content.count("data changed since") == 1
    _press(app.controls.tabs["diagnose"].diagnose)
    assert "data changed since" not in panel.content and not app.state.diagnosis_stale


def test_the_tab_says_why_it_cannot_diagnose_and_a_new_file_clears_it(tmp_path, capsys):
    rows = ["id,role,sensor_x,sensor_y,sensor_z,robot_x,robot_y,robot_z"]
    pts = [(0, 0, 0), (400, 0, 0), (0, 300, 0), (400, 300, 90), (200, 150, 40), (100, 250, 70)]
    for k, (x, y, z) in enumerate(pts):
        role = "registration" if k < 3 else "fiducial"
        rows.append(f"P{k},{role},{x},{y},{z},{x + 100.01 * (k % 2)},{y - 50},{z + 20}")
    small = tmp_path / "small.csv"
    small.write_text("\n".join(rows) + "\n")
    app = serve(small, port=0)
    try:
        panel = app.controls.tabs["diagnose"].diagnosis
        app.evaluate.toggle_fiducial("P4")
        app.evaluate.toggle_fiducial("P5")  # 4 paired points left: too few
        _press(app.controls.tabs["diagnose"].diagnose)
        assert app.state.diagnosis is None and panel.content.startswith("⚠ Cannot diagnose:")
        # the command line refuses the same download with the same words
        name, content = app.files.export("csv")
        path = tmp_path / name
        path.write_bytes(content)
        capsys.readouterr()
        assert main(["diagnose", str(path)]) == 2
        err = capsys.readouterr().err.strip().removeprefix("rrbc: error: ")
        assert "at least 5" in err and err.split(": ", 1)[-1] in " ".join(panel.content.split())
        app.files.load(EXAMPLE_CSV)
        assert panel.content.startswith("Tests the session's data") and app.state.diagnosis is None
    finally:
        app.stop()
