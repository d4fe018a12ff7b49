"""Before/after statistics of the check errors (issue 25, item 4): the numbers against a plain numpy computation,
and the same numbers in `rrbc correct` (text and JSON), `rrbc diagnose` and the app."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rrbc_core.cli import main
from rrbc_core.correction.check_statistics import STATISTICS, check_statistics
from rrbc_core.errors import InputError
from tests.paths import EXAMPLE_CSV


def _plain(e: np.ndarray) -> dict:
    """The statistics by a direct computation: sorted errors and numpy's linear-interpolation percentile by hand."""

    def p95(x):
        x = np.sort(x)
        pos = 0.95 * (len(x) - 1)
        lo = int(np.floor(pos))
        hi = min(lo + 1, len(x) - 1)
        return x[lo] + (pos - lo) * (x[hi] - x[lo])

    d = np.sqrt((e**2).sum(axis=1))
    return {
        "mean": d.sum() / len(d),
        "rms": np.sqrt((d**2).sum() / len(d)),
        "p95": p95(d),
        "max": max(d),
        "p95_xy": p95(np.sqrt(e[:, 0] ** 2 + e[:, 1] ** 2)),
        "p95_z": p95(np.abs(e[:, 2])),
    }


@pytest.mark.parametrize("n", [1, 2, 7, 100, 1001])
def test_statistics_match_a_plain_computation(n):
    rng = np.random.default_rng(n)
    truth = rng.uniform(-500, 500, (n, 3))
    rigid = truth + rng.normal(0, [3.0, 2.0, 1.0], (n, 3))
    rrbc = truth + rng.normal(0, 1.0, (n, 3))
    ids = [f"C{i}" for i in range(n)]
    st = check_statistics(ids, rigid, rrbc, truth)
    for side, pos in (("rigid", rigid), ("rrbc", rrbc)):
        want = _plain(pos - truth)
        got = getattr(st, side)
        assert set(got) == set(STATISTICS)
        for k in STATISTICS:
            assert got[k] == pytest.approx(want[k], rel=1e-12, abs=1e-12), (side, k)
    worse = [i for i, a, b in zip(ids, rigid - truth, rrbc - truth) if np.linalg.norm(b) > np.linalg.norm(a)]
    assert list(st.worse) == worse
    assert st.change("rms") == pytest.approx(100 * (st.rrbc["rms"] / st.rigid["rms"] - 1))
    centres, a, b = st.histogram(20)
    assert len(centres) == 20 and a.sum() == pytest.approx(1.0) and b.sum() == pytest.approx(1.0)


def test_bad_input_is_refused():
    with pytest.raises(InputError):
        check_statistics([], np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))
    with pytest.raises(InputError):
        check_statistics(["a"], [[np.nan, 0, 0]], [[0, 0, 0]], [[0, 0, 0]])


def test_correct_diagnose_and_the_app_show_the_same_statistics(capsys):
    from rrbc_viz.serve import serve

    assert main(["correct", str(EXAMPLE_CSV), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    cs = js["check_statistics"]
    checks = js["checks"]
    e_rigid = np.array([c["error_rigid_mm"] for c in checks])
    e_rrbc = np.array([c["error_rrbc_mm"] for c in checks])
    assert cs["n"] == len(checks) and cs["rigid_mm"]["max"] == pytest.approx(e_rigid.max(), abs=1e-12)
    assert cs["rrbc_mm"]["rms"] == pytest.approx(js["summary"]["rmst_rrbc_mm"], abs=1e-12)
    assert (
        cs["rrbc_worse"]
        == [c["id"] for c in checks if c["rrbc_worse"]]
        == [c["id"] for c, a, b in zip(checks, e_rigid, e_rrbc) if b > a]
    )
    assert main(["correct", str(EXAMPLE_CSV)]) == 0
    text = capsys.readouterr().out
    lines = text.splitlines()
    for pid in cs["rrbc_worse"]:
        assert "RRBC worse" in next(line for line in lines if line.strip().startswith(pid + " "))
    assert main(["diagnose", str(EXAMPLE_CSV), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["check_statistics"] == cs
    assert main(["diagnose", str(EXAMPLE_CSV)]) == 0
    dtext = capsys.readouterr().out
    table = text[text.index("errors at ") :].splitlines()
    assert "\n".join(table) in dtext  # the same table, line for line
    app = serve(EXAMPLE_CSV, port=0)
    try:
        panel = app.controls.checks
        assert panel.folder.visible and panel.stats.to_json() == cs
        shown = panel.text.content
        for line in table[1:]:
            assert line in shown
        centres, rigid, rrbc = panel.histogram.data
        assert rigid.sum() == pytest.approx(1.0) and rrbc.sum() == pytest.approx(1.0)
        # the per-point list: the checks with the largest RRBC errors, their errors as `rrbc correct --json` gives them
        by_id = {c["id"]: (c["error_rigid_mm"], c["error_rrbc_mm"]) for c in checks}
        block = panel.points.content.split("```")[1].strip().splitlines()
        assert block[0].split() == ["check", "rigid", "mm", "RRBC", "mm"]
        listed = block[1:]
        top = sorted(by_id, key=lambda i: -by_id[i][1])[: len(listed)]
        assert len(listed) == min(len(by_id), 15) and [ln.split()[0] for ln in listed] == top
        for ln in listed:
            pid, a, b = ln.split()[:3]
            assert (float(a), float(b)) == pytest.approx(by_id[pid], abs=5e-4)
            assert ("RRBC worse" in ln) == (pid in cs["rrbc_worse"])
        assert "<table" not in panel.points.content and "| " not in panel.points.content  # one table: the targets'
    finally:
        app.stop()


def test_the_checks_rrbc_made_worse_are_listed_as_wide_as_the_table():
    """The app shows these lines in its side panel: the ids of the checks RRBC made worse are wrapped at the
    table's width (the first 20, then "…"), every one listed once."""
    from rrbc_core.correction.check_statistics import TABLE_WIDTH

    rng = np.random.default_rng(4)
    n = 60
    ids = [f"check_{i:03d}" for i in range(n)]
    truth = rng.normal(size=(n, 3))
    stats = check_statistics(ids, truth + 0.1 * rng.normal(size=(n, 3)), truth + rng.normal(size=(n, 3)), truth)
    lines = stats.lines()
    assert len(stats.worse) > 20 and max(len(line) for line in lines) <= TABLE_WIDTH
    at = next(k for k, line in enumerate(lines) if "RRBC worse than rigid at" in line)
    listed = " ".join(lines[at + 1 :]).replace(",", " ").split()
    assert listed == list(stats.worse[:20]) + ["…"]
