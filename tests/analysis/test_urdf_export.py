"""`rrbc calibrate --export-urdf` (issue 40, item 2): the identified arm as a URDF whose forward kinematics, loaded
with the project's URDF reader (yourdfpy), are the identified chain's to within 0.01 mm; mimic joints, limits and
the rest kept; refusals in one line with nothing written."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from rrbc_core.analysis.vec_compare import compare
from rrbc_core.io.joints import joint_values
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.models.urdf import load_urdf
from rrbc_core.models.urdf_export import TOOL_LINK
from rrbc_core.simulation.arm_data import chain_measurements
from rrbc_core.studies.vec_study import joint_measurements

RRBC = str(Path(sys.executable).with_name("rrbc"))


def test_the_exported_urdf_reproduces_the_identified_arm(tmp_path):
    chain = load_urdf("lift_arm")  # a prismatic lift, revolute joints and a spindle mimicking a joint off the chain
    mset = chain_measurements(chain, 3, n_fid=60, n_chk=20, kin_size=1.0, noise_mm=0.02)
    out = tmp_path / "calibrated.urdf"
    res = compare(mset, urdf="lift_arm", export_urdf=str(out))
    assert res["exported_urdf"] == str(out)
    named = {p["name"]: p["error"] for p in res["parameters"] if "kind" not in p}
    delta = np.array([named[n] for n in chain.param_names])
    assert np.abs(delta).max() > 0.1  # the planted errors were identified: the test is not of a nominal arm
    exported = load_urdf(str(out), tip=TOOL_LINK)
    assert exported.columns == chain.columns  # the mimic joint still follows its master
    q = joint_values(mset, chain)
    gap = np.linalg.norm(exported.forward(q) - chain.forward(q, delta), axis=1)
    assert gap.max() < 0.01, gap.max()
    # against the nominal arm the exported one differs by the identified errors (mm, not rounding)
    assert np.linalg.norm(exported.forward(q) - chain.forward(q), axis=1).max() > 0.5
    text = out.read_text()
    assert "<mimic" in text and "<limit" in text and "Calibrated by rrbc calibrate" in text


def test_the_cli_exports_and_refuses_a_dh_arm(tmp_path):
    data = tmp_path / "ur5.csv"
    write_measurements(data, joint_measurements(1, n_fid=20, n_chk=10))
    out = tmp_path / "ur5.urdf"
    r = subprocess.run(
        [RRBC, "calibrate", str(data), "--robot", "ur5", "--tool", "100", "--export-urdf", str(out)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--urdf" in r.stderr
    assert not out.exists()
    chain = load_urdf("lift_arm")
    data = tmp_path / "lift.csv"
    write_measurements(data, chain_measurements(chain, 4, n_fid=40, n_chk=10))
    r = subprocess.run(
        [RRBC, "calibrate", str(data), "--urdf", "lift_arm", "--export-urdf", str(out), "--json"],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["exported_urdf"] == str(out) and out.is_file()
