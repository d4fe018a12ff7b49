"""The numbered examples in examples/ run as a user runs them (a fresh process, the README's interpreter) and say
what their docstrings promise."""

import re
import subprocess
import sys

from tests.paths import ROOT

EXAMPLES = ROOT / "examples"


def _run(name: str, *args: str, timeout: float = 300) -> str:
    out = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args], capture_output=True, text=True, timeout=timeout, cwd=ROOT
    )
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
    return out.stdout


def test_the_examples_are_numbered_and_each_is_tested():
    names = sorted(p.name for p in EXAMPLES.glob("*.py"))
    assert names == ["01_correct_a_file.py", "02_simulate_a_scene.py", "03_drive_the_app.py"]


def test_example_1_corrects_the_bundled_file_as_rrbc_correct_does():
    import json

    out = _run("01_correct_a_file.py")
    cli = subprocess.run(
        [sys.executable, "-m", "rrbc_core.cli", "correct", "rrbc_core/data/example_measurements.csv", "--json"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    summary = json.loads(cli.stdout)["summary"]
    line = next(ln for ln in out.splitlines() if ln.startswith("RMS error at the checks"))
    rigid, rrbc = (float(x) for x in re.findall(r"([\d.]+) mm", line))
    assert abs(rigid - summary["rmst_rigid_mm"]) < 5e-4 and abs(rrbc - summary["rmst_rrbc_mm"]) < 5e-4


def test_example_2_simulates_and_writes_a_file_example_1_reads(tmp_path):
    out = _run("02_simulate_a_scene.py", "--trials", "20", "--out", str(tmp_path / "sim.csv"))
    assert "least-squares: rigid RMS" in out and (tmp_path / "sim.csv").exists()
    corrected = _run("01_correct_a_file.py", str(tmp_path / "sim.csv"))
    assert corrected.startswith("sim.csv: ")


def test_example_3_drives_the_app_and_stops_it():
    out = _run("03_drive_the_app.py")
    assert re.search(r"the app is at http://127\.0\.0\.1:\d+/", out)
    assert re.search(r"F1 moved 200 mm: RMST rigid [\d.]+ mm, RRBC [\d.]+ mm", out)
    assert "  diagnose | " in out and re.search(r"diagnose \| RRBC (not )?recommended", out)
