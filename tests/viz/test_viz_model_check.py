"""The Model tab is `rrbc check-model` (issue 36, item 4): the open scene's model held against an offered measurement
file shows the command's own lines and JSON, draws every compared row (outside ones marked), and *Extend the model*
loads the scene with the added terms and checks it again; the download is the extended scene."""

from __future__ import annotations

import dataclasses
import json
import tomllib

import numpy as np
import pytest

from rrbc_core.analysis.scene_check_text import check_lines
from rrbc_core.cli import main
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.models.errorterms import SmoothField
from rrbc_core.simulation.datasets import measured_data
from rrbc_core.simulation.montecarlo import work_cell_from_scene
from rrbc_viz import model_check_panel
from rrbc_viz.diagnosis_panel import unescape
from rrbc_viz.serve import serve
from tests.paths import DEMO, EXAMPLE_CSV


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A data folder with a file of the demo cell whose truth has a smooth field the scene lacks."""
    d = tmp_path_factory.mktemp("data")
    scene = load_scene(DEMO)
    planted = scene.error_model.extended(robot=[SmoothField(rms_mm=0.4, length_mm=250.0, seed=2)])
    cell = work_cell_from_scene(dataclasses.replace(scene, error_model=planted), seed=0)
    write_measurements(d / "planted.csv", measured_data(cell, 5))
    return d


def _tab_lines(text: str) -> list[str]:
    """The tab's paragraphs as plain text, without the heading the app adds (an extension's gain)."""
    return [unescape(p) for p in text.split("\n\n") if not p.startswith("**")]


@pytest.mark.slow
def test_the_tab_is_the_command_and_extending_loads_the_extended_scene(folder, capsys, monkeypatch):
    app = serve(DEMO, port=0, data_dirs=[folder])
    try:
        label = f"{folder.name}/planted.csv"
        result = app.tabs["model_check"].run(label)
        assert result is not None, app.controls.tabs["model_check"].text()
        # the command's JSON and lines (the first line names the files as each was given)
        capsys.readouterr()
        monkeypatch.chdir(DEMO.parent)
        assert main(["check-model", str(folder / "planted.csv"), DEMO.name, "--json"]) == 0
        cli = json.loads(capsys.readouterr().out)
        assert cli.pop("written") is None
        assert json.loads(json.dumps(result.to_json())) == cli
        assert main(["check-model", str(folder / "planted.csv"), DEMO.name]) == 0
        text = capsys.readouterr().out.rstrip("\n").split("\n")
        assert text == check_lines(result, str(folder / "planted.csv"), DEMO.name)  # the command's lines
        # the tab: the same lines (its own hints), the figures as a table of the same numbers
        tab = _tab_lines(app.controls.tabs["model_check"].text())
        same = check_lines(result, "planted.csv", DEMO.name, hints=model_check_panel.APP_HINTS)
        rest = next(i for i, line in enumerate(same) if line.startswith("rows outside"))
        assert tab[0] == same[0] and tab[2:] == same[rest:]
        assert tab[1] == unescape(model_check_panel.figures_table(result))
        for key in ("fre_mm", "rmst_rigid_mm", "rmst_rrbc_mm"):
            iv = result.predicted[key]
            assert f"{result.measured[key]:.4g} | {iv.mean:.4g} | {iv.lo95:.4g} – {iv.hi95:.4g}" in tab[1]
        # every compared row drawn; the outside ones are the JSON's
        assert app.check_node.shown() == result.n_rows == len(result.z)
        assert int(np.sum(result.z > 2.7955)) == len(cli["outside"])
        # the download: the scene's own text with the added terms
        name, content = app.tabs["model_check"].download()
        assert name == "demo_workcell-extended.toml"
        doc = tomllib.loads(content.decode())
        assert len(doc["error_model"]["robot"]) == len(load_scene(DEMO).error_model.robot) + len(result.added)
        # extend: the scene with the added terms is loaded and checked again against the same file
        again = app.tabs["model_check"].extend()
        assert again is not None
        assert app.session.kind == "scene"
        robot_terms = [t.kind for t in app.session.scene.error_model.robot]
        assert robot_terms[-len(result.added) :] == [t.table["type"] for t in result.added]
        shown = app.controls.tabs["model_check"].text()
        assert shown.startswith("**Extended model loaded**") and "smooth_field" not in {
            e.name for e in again.unexplained
        }
        assert "as extended here" in shown  # the re-check says which model it held
        # the loaded extension can be downloaded: the first terms, and any new ones after them
        _, content2 = app.tabs["model_check"].download()
        assert content2.decode().startswith(content.decode().rstrip("\n"))
    finally:
        app.stop()


def test_on_measured_data_the_tab_asks_for_a_scene(folder):
    app = serve(EXAMPLE_CSV, port=0, data_dirs=[folder])
    try:
        assert app.controls.tabs["model_check"].text() == model_check_panel.NOT_A_SCENE
        assert app.tabs["model_check"].run(f"{folder.name}/planted.csv") is None
        assert app.controls.tabs["model_check"].text() == model_check_panel.NOT_A_SCENE
    finally:
        app.stop()


def test_a_file_not_offered_is_refused_in_the_tab(folder):
    app = serve(DEMO, port=0, data_dirs=[folder])
    try:
        assert app.tabs["model_check"].run("/etc/passwd") is None
        assert "not one of the files offered" in app.controls.tabs["model_check"].text()
        assert app.check_node.shown() == 0
    finally:
        app.stop()
