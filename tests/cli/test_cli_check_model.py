"""`rrbc check-model` end to end through the console script (issue 36; contract in docs/cli.md)."""

import json
import shutil

import pytest

from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.models.errorterms import Drift, SmoothField
from rrbc_core.simulation.datasets import measured_data
from rrbc_core.simulation.montecarlo import work_cell_from_scene
from tests.paths import ROOT
from tests.support.cli_run import rrbc

FIGURES = ("rmst_rigid_mm", "rmst_rrbc_mm", "fre_mm")


def run(*args, timeout=300):
    return rrbc(*args, timeout=timeout)  # in this process (tests/support/cli_run.py)


@pytest.fixture(scope="module")
def cell_dir(tmp_path_factory):
    """The demo scene copied with its mesh (an extended scene is written beside it), a clean file and one with a
    field and a drift the scene lacks (times shuffled: drift separable from position)."""
    import dataclasses

    import numpy as np

    d = tmp_path_factory.mktemp("cell")
    shutil.copy(ROOT / "scenes" / "demo_workcell.toml", d / "scene.toml")
    (d / "meshes").mkdir()
    shutil.copy(ROOT / "scenes" / "meshes" / "demo_workcell.glb", d / "meshes")
    scene = load_scene(d / "scene.toml")
    write_measurements(d / "clean.csv", measured_data(work_cell_from_scene(scene, seed=0), 4))
    planted = scene.error_model.extended(
        robot=[Drift(rate_mm_per_s=(0.0004, -0.0002, 0.0)), SmoothField(rms_mm=0.4, length_mm=250.0, seed=2)]
    )
    cell = work_cell_from_scene(dataclasses.replace(scene, error_model=planted), seed=0)
    cell = dataclasses.replace(cell, time=np.random.default_rng(1).permutation(cell.time))
    write_measurements(d / "planted.csv", measured_data(cell, 5))
    return d


def test_the_json_keeps_the_contract_and_a_clean_file_fits(cell_dir):
    res = run("check-model", cell_dir / "clean.csv", cell_dir / "scene.toml", "--trials", 60, "--folds", 3, "--json")
    assert res.returncode == 0, res.stderr
    j = json.loads(res.stdout)
    for key in FIGURES:
        assert set(j["predicted"][key]) == {"mean", "lo95", "hi95"}
        assert j["predicted"][key]["lo95"] <= j["predicted"][key]["mean"] <= j["predicted"][key]["hi95"]
        assert isinstance(j["measured"][key], float)
    assert all(set(p) >= {"id", "z"} and p["z"] > 2.79 for p in j["outside"])
    assert j["unexplained"] == [] and j["extended_terms"] == [] and j["written"] is None
    assert set(j["gain"]) >= {
        "prediction_error_before_mm",
        "prediction_error_after_mm",
        "coverage_before",
        "coverage_after",
        "folds",
    }
    assert j["gain"]["folds"] == 3


@pytest.mark.slow
def test_a_misfit_is_found_written_and_the_extended_scene_runs_everywhere(cell_dir):
    out = cell_dir / "extended.toml"
    res = run("check-model", cell_dir / "planted.csv", cell_dir / "scene.toml", "--trials", 60, "--out", out, "--json")
    assert res.returncode == 0, res.stderr
    j = json.loads(res.stdout)
    assert j["figures_outside"] and not j["model_fits"]
    names = {e["name"] for e in j["unexplained"]}
    assert "smooth_field" in names
    for e in j["unexplained"]:  # diagnose's keys
        assert set(e) == {"name", "parameters", "p_value", "evidence"}
    assert j["written"] == str(out)
    types = [t["type"] for t in j["extended_terms"]]
    assert "sampled_field" in types and "field_uncertainty" in types
    assert j["gain"]["prediction_error_after_mm"] < j["gain"]["prediction_error_before_mm"]
    text = out.read_text()
    assert text.startswith((cell_dir / "scene.toml").read_text().rstrip("\n"))  # the user's file, unchanged
    assert text.count("# added by rrbc check-model") == len(j["extended_terms"])
    ext = load_scene(out)
    assert len(ext.error_model.robot) == len(load_scene(cell_dir / "scene.toml").error_model.robot) + len(types)
    # the extended scene is a scene: simulate takes it, and check-model against it finds the field explained
    sim = run("simulate", out, "--trials", 20, "--json")
    assert sim.returncode == 0, sim.stderr
    again = run("check-model", cell_dir / "planted.csv", out, "--trials", 60, "--json")
    assert again.returncode == 0, again.stderr
    assert "smooth_field" not in {e["name"] for e in json.loads(again.stdout)["unexplained"]}


@pytest.mark.slow
def test_the_text_says_the_same(cell_dir):
    res = run("check-model", cell_dir / "planted.csv", cell_dir / "scene.toml", "--trials", 60)
    assert res.returncode == 0, res.stderr
    assert "OUTSIDE" in res.stdout and "smooth_field:" in res.stdout and "out of sample" in res.stdout
    assert "verdict: the model misses these data" in res.stdout


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (("nope.csv", "{scene}"), "nope.csv"),
        (("{clean}", "nope.toml"), "nope.toml"),
        (("{clean}", "{scene}", "--trials", "5"), "--trials"),
        (("{clean}", "{scene}", "--folds", "1"), "--folds"),
        (("{clean}", "{scene}", "--out", "{scene}"), "the scene itself"),
        (("{clean}", "{scene}", "--out", "/nonexistent/dir/x.toml"), "no such folder"),
        (("{planted}", "{scene}", "--out", "{elsewhere}"), "write it in the scene's folder"),
        (("{clean}", "{scene}", "--trials", "100000000"), "--trials"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_no_file(cell_dir, tmp_path, args, words):
    values = {
        "scene": cell_dir / "scene.toml",
        "clean": cell_dir / "clean.csv",
        "planted": cell_dir / "planted.csv",
        "elsewhere": tmp_path / "ext.toml",
    }
    res = run("check-model", *(a.format(**values) for a in args), "--json")
    assert res.returncode == 2, (res.stdout, res.stderr)
    assert res.stdout == "" and len(res.stderr.strip().splitlines()) == 1 and words in res.stderr, res.stderr
    assert not (tmp_path / "ext.toml").exists()
    assert not list(tmp_path.iterdir())  # not even a probe left behind
