"""Example 1: correct a measurement file with RRBC, as `rrbc correct FILE` does, from Python.

Run: .venv/bin/python examples/01_correct_a_file.py [FILE]   (default: the bundled example file)

The file holds points measured in both frames (sensor and robot, mm); its `registration` rows register the sensor
to the robot, its `fiducial` rows give RRBC's corrections, its `check` rows score the result (docs/formats/).
"""

import sys
from pathlib import Path

import rrbc_core as rrbc

path = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(rrbc.__file__).parent / "data" / "example_measurements.csv"
data = rrbc.read_measurements(path)  # validated rows; bad input raises rrbc.InputError with a one-line message
method = rrbc.MethodOptions(registration="least-squares", interpolation="idw")
result = rrbc.correct_measurements(data, method)

summary = result.summary()
print(f"{path.name}: {len(data.ids)} rows, method {method.describe()}")
print(f"RMS error at the checks: rigid {summary['rmst_rigid_mm']:.3f} mm, RRBC {summary['rmst_rrbc_mm']:.3f} mm")
stats = result.statistics()  # the same numbers `rrbc correct` and the app's Explore tab show
if stats is not None:
    print(f"95th percentile at the checks: rigid {stats.rigid['p95']:.3f} mm, RRBC {stats.rrbc['p95']:.3f} mm")
    print(f"checks RRBC made worse: {len(stats.worse)} of {stats.n}")
corrected = result.checks_corrected  # None when the file has no checks
if corrected is not None:
    for pid, (x, y, z) in list(zip(result.checks.ids, corrected.robot_rrbc))[:5]:
        print(f"  {pid}: robot frame after RRBC ({x:.3f}, {y:.3f}, {z:.3f}) mm")
