"""scripts/hostile_probe.py (issue 16): every named hostile case and seeded random mutations keep the command line's
contract (exit 2 and one line, or exit 0 and a quiet stderr; never exit 1), and the probe's own judge catches a
broken contract (so a green run means something)."""

import sys

from tests.paths import ROOT

sys.path.insert(0, str(ROOT / "scripts"))

import hostile_probe


def test_the_judge_catches_each_broken_contract():
    ok = "rrbc: error: m.csv: line 3: field sensor_x: 'x' is not a number\n"
    assert hostile_probe.judge(2, "", ok, 0.1, 60) is None
    assert hostile_probe.judge(0, "table\n", "", 0.1, 60) is None
    assert "exit 1" in hostile_probe.judge(1, "", "rrbc: internal error: ValueError\n", 0.1, 60)
    assert "2 stderr lines" in hostile_probe.judge(2, "", ok + "RuntimeWarning: overflow\n", 0.1, 60)
    assert "stdout" in hostile_probe.judge(2, "partial", ok, 0.1, 60)
    assert "stderr" in hostile_probe.judge(0, "table", "RuntimeWarning: overflow\n", 0.1, 60)
    assert "control" in hostile_probe.judge(2, "", "rrbc: error: \x1b[2J\n", 0.1, 60)
    assert "longer" in hostile_probe.judge(-1, "", "", 61, 60)


def test_every_hostile_case_keeps_the_contract():
    res = hostile_probe.probe(in_process=True, n_random=20, seed=7, timeout=60, log=lambda s: None)
    assert res["broken"] == [], res["broken"]
    assert res["exit_2"] > 100 and res["runs"] == res["exit_0"] + res["exit_2"]
