"""The baseline script of the benchmark row `correct_1000000_rows` (benchmarks/correct_baseline.py) computes the
command's own numbers: the same corrected positions and check errors as `rrbc correct --json` on the same file, so
the row compares like with like."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from rrbc_core.correction.stations import correct_stations
from rrbc_core.io.measurements import MeasurementSet, read_measurements
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.simulation.field_data import field_measurements

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from correct_baseline import baseline


def test_the_baseline_script_computes_the_commands_numbers(tmp_path):
    m = field_measurements(9, n_fiducials=80, n_checks=300)
    roles = tuple("target" if k % 5 == 0 and r == "check" else r for k, r in enumerate(m.roles))
    m = MeasurementSet(m.ids, roles, m.sensor, m.robot, m.time, m.lines, m.source)
    path = tmp_path / "f.csv"
    write_measurements(path, m)
    ours = json.loads(json.dumps(correct_stations(read_measurements(path)).to_json()))
    theirs = baseline(str(path))
    for key in ("targets", "checks"):
        assert [r["id"] for r in ours[key]] == [r["id"] for r in theirs[key]] and ours[key]
        with_truth = ("robot_truth", "error_rigid_mm", "error_rrbc_mm", "rrbc_worse") if key == "checks" else ()
        for field in ("sensor", "correction_mm", "robot_rigid", "robot_rrbc") + with_truth:
            a = np.array([r[field] for r in ours[key]], dtype=float)
            b = np.array([r[field] for r in theirs[key]], dtype=float)
            assert np.max(np.abs(a - b)) < 1e-9, (key, field)
    a = np.array([r["correction_mm"] for r in ours["fiducials"]])
    assert np.max(np.abs(a - np.array([r["correction_mm"] for r in theirs["fiducials"]]))) < 1e-9
