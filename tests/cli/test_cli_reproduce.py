"""`rrbc reproduce vanwyk2018` end to end through the console script (docs/cli.md), and the report."""

import json

import numpy as np
import pytest

from rrbc_core.studies import reference_data, vanwyk2018
from rrbc_core.studies.reproduction import METHODS
from tests.support.cli_run import rrbc

QUICK = ["--replicates", "8", "--layouts", "A", "--no-confusion"]


run = rrbc  # the command in this process (`tests.support.cli_run`); the console script: tests/cli/test_cli.py


@pytest.fixture(scope="module")
def quick_report(tmp_path_factory):
    """One quick run, written into a folder whose parent does not exist yet (the command creates both)."""
    out = tmp_path_factory.mktemp("rep") / "no" / "such" / "report"
    res = run("reproduce", "vanwyk2018", "--out", out, "--json", *QUICK)
    assert res.returncode == 0, res.stderr
    return out, json.loads(res.stdout)


@pytest.mark.slow
def test_json_has_the_contract_fields(quick_report):
    _, j = quick_report
    for key in ("measured", "baseline", "extended", "misfit", "cause", "assumptions"):
        assert key in j
    assert set(j["misfit"]) >= {"baseline", "extended", "baseline_cv", "extended_cv"}
    assert [r["method"] for r in j["measured"]] == list(METHODS)
    assert [r["method"] for r in j["baseline"]] == list(METHODS)
    for row in j["baseline"] + j["extended"]:
        for key in ("mean_mm", "var_mm2", "max_mm", "r", "p", "ps"):
            assert key in row and row[key] is not None
    assert isinstance(j["cause"], str) and len(j["cause"]) > 40
    assert j["samples_per_method"] == 80
    assert len(j["assumptions"]) >= 5


@pytest.mark.slow
def test_measured_rows_in_the_json_are_the_published_numbers(quick_report):
    _, j = quick_report
    published = {r.method: r for r in reference_data.vanwyk2018()}
    for row in j["measured"]:
        p = published[row["method"]]
        assert (row["mean_mm"], row["var_mm2"], row["max_mm"], row["r"], row["ps"]) == (
            p.mean_mm,
            p.var_mm2,
            p.max_mm,
            p.r,
            p.ps,
        )


def test_extended_model_never_fits_worse_in_sample_than_the_baseline(quick_report):
    """Every extension nests the baseline (phi = 0 or pi/4 reproduces it with common random numbers), so its
    best in-sample misfit cannot be above the baseline's."""
    _, j = quick_report
    base = j["misfit"]["baseline"]
    for m in j["models"]:
        assert m["misfit"] <= base + 1e-6, m["name"]


def test_report_files_are_written_and_link_their_figures(quick_report):
    out, j = quick_report
    text = (out / "report.md").read_text()
    for fig in (
        "predicted_vs_measured.png",
        "error_vs_distance.png",
        "error_ranges.png",
        "peg_success.png",
        "layouts.png",
    ):
        assert (out / fig).stat().st_size > 5000, fig
        assert f"]({fig})" in text
    assert "Van Wyk" in text and "10.1109/TASE.2017.2720478" in text
    assert "rrbc reproduce vanwyk2018" in text  # the command that reproduces every number
    summary = json.loads((out / "summary.json").read_text())
    assert summary["misfit"] == j["misfit"]
    # the report quotes the misfit numbers of the JSON
    assert f"{j['misfit']['baseline']:.1f}" in text and f"{j['misfit']['extended_cv']:.1f}" in text


@pytest.mark.parametrize(
    "args, words",
    [
        (["reproduce", "nobody2099"], "invalid choice"),
        (["reproduce", "vanwyk2018", "--replicates", "2"], "at least 5"),
        (["reproduce", "vanwyk2018", "--replicates", "many"], "not an integer"),
        (["reproduce", "vanwyk2018", "--replicates", "1000000000"], "from 5 to 2000"),  # 12 GB a minute, unbounded
        (["reproduce", "vanwyk2018", "--layouts", "A,Z"], "unknown layout"),
        (["reproduce", "vanwyk2018", "--layouts", ","], "at least one layout"),
    ],
)
def test_bad_input_is_one_line_exit_2(args, words):
    res = run(*args)
    assert res.returncode == 2
    assert res.stdout == ""
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr
    assert words in res.stderr


def test_out_that_is_a_file_is_refused_and_left_alone(tmp_path):
    f = tmp_path / "report"
    f.write_text("keep me")
    res = run("reproduce", "vanwyk2018", "--out", f, *QUICK)
    assert res.returncode == 2 and "is not a folder" in res.stderr
    assert f.read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]  # no temporary leftovers


@pytest.mark.slow
def test_out_in_a_missing_parent_is_created(quick_report):
    out, _ = quick_report  # written by a run whose --out's parent folders did not exist
    assert (out / "report.md").is_file()


def test_out_under_a_file_is_refused(tmp_path):
    (tmp_path / "file").write_text("x")
    res = run("reproduce", "vanwyk2018", "--out", tmp_path / "file" / "below", *QUICK)
    assert res.returncode == 2 and "cannot create or write it" in res.stderr


def test_peg_prediction_recovers_a_known_capture_radius():
    """Success counts drawn from a known capture radius on known horizontal errors are fitted back within the
    resolution the counts allow."""
    from rrbc_core.studies import model_fit, reproduction

    rng = np.random.default_rng(5)
    horiz = np.abs(rng.normal(0, 1, size=(1, 30, 7, 80))) * np.linspace(0.2, 0.6, 7)[None, None, :, None]
    ds = reproduction.DirectionStats(reproduction.MODELS[0], np.zeros(1), {}, horiz, horiz, 30)
    fit = model_fit.Fit("baseline", 0.0, 0.0, {}, 0.0, 0.0, np.zeros((4, 7)), np.ones((4, 7)), np.zeros((4, 7)))
    true_c = 0.45
    p = reproduction.success_probability(horiz[0], true_c)[0]
    successes = np.round(p * reference_data.PEG_TRIES)
    peg = vanwyk2018.peg_prediction(ds, fit, successes)
    assert abs(peg.capture_mm - true_c) < 0.02
    assert np.all(np.abs(peg.successes - successes) <= 3)
