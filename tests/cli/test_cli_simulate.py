"""`rrbc simulate` end to end through the console script (docs/cli.md)."""

import json

import pytest

from tests.paths import ROOT
from tests.support.cli_run import rrbc

SCENES = ["demo_workcell", "breadboard_vanwyk2018", "peg_in_hole_cell"]


def run(*args, timeout=300):
    return rrbc(*args, timeout=timeout)  # in this process (tests/support/cli_run.py)


@pytest.mark.parametrize("scene", [SCENES[0], *(pytest.param(s, marks=pytest.mark.slow) for s in SCENES[1:])])
def test_scene_simulates_and_its_data_pass_through_correct(tmp_path, scene):
    out = tmp_path / f"{scene}.csv"
    res = run("simulate", ROOT / "scenes" / f"{scene}.toml", "--trials", 30, "--seed", 5, "--out", out, "--json")
    assert res.returncode == 0, res.stderr
    js = json.loads(res.stdout)
    assert js["trials"] == 30 and "seconds" not in js  # the JSON is a function of the inputs (issue 18)
    names = [s["name"] for s in js["strategies"]]
    assert names == ["least-squares", "three-point", "combinatorial", "annealing", "clustering"]
    for s in js["strategies"]:
        for key in ("tre_mean_mm", "tre_rms_mm", "tre_max_mm", "r_distance", "rmst_rrbc_mm"):
            assert key in s
        assert 0 < s["tre_mean_mm"] <= s["tre_rms_mm"] <= s["tre_max_mm"]
    corrected = run("correct", out, "--json")
    assert corrected.returncode == 0, corrected.stderr
    cj = json.loads(corrected.stdout)
    assert len(cj["checks"]) > 0
    assert cj["summary"]["rmst_rigid_mm"] > 0


def test_default_scene_bias_dominates_so_rrbc_visibly_helps():
    res = run("simulate", ROOT / "scenes" / "demo_workcell.toml", "--trials", 50, "--json")
    assert res.returncode == 0, res.stderr
    ls = json.loads(res.stdout)["strategies"][0]
    assert ls["rmst_rrbc_mm"] < 0.7 * ls["tre_rms_mm"], ls


@pytest.mark.slow
def test_simulate_is_seeded():
    a = run("simulate", ROOT / "scenes" / "peg_in_hole_cell.toml", "--trials", 10, "--seed", 9, "--json")
    b = run("simulate", ROOT / "scenes" / "peg_in_hole_cell.toml", "--trials", 10, "--seed", 9, "--json")
    ja, jb = json.loads(a.stdout), json.loads(b.stdout)
    assert ja["strategies"] == jb["strategies"] and ja["interpolations"] == jb["interpolations"]


def test_readable_table_without_json():
    res = run("simulate", ROOT / "scenes" / "demo_workcell.toml", "--trials", 10)
    assert res.returncode == 0, res.stderr
    assert "least-squares" in res.stdout and "rmst_rrbc" in res.stdout


def _scene_text():
    return (ROOT / "scenes" / "demo_workcell.toml").read_text()


def _write_variant(tmp_path, text):
    f = tmp_path / "bad.toml"
    (tmp_path / "meshes").mkdir(exist_ok=True)
    for mesh in (ROOT / "scenes" / "meshes").iterdir():
        (tmp_path / "meshes" / mesh.name).write_bytes(mesh.read_bytes())
    f.write_text(text)
    return f


@pytest.mark.parametrize(
    "case",
    ["missing key", "bad number", "missing mesh", "negative region", "syntax"],
)
def test_malformed_scene_exits_2_with_one_line(tmp_path, case):
    text = _scene_text()
    if case == "missing key":
        import re

        text = re.sub(r"(?m)^look_at\s*=.*$", "", text, count=1)
    elif case == "bad number":
        text = text.replace("tool_mm =", 'tool_mm = "long"\nold_tool_mm =', 1)
    elif case == "missing mesh":
        import re

        text = re.sub(r'(?m)^mesh\s*=\s*".*"$', 'mesh = "meshes/nowhere.glb"', text, count=1)
    elif case == "negative region":
        import re

        text = re.sub(r"size\s*=\s*\[\s*([0-9.]+)", r"size = [-\1", text, count=1)
    elif case == "syntax":
        text = text + "\n[[target]\n"
    f = _write_variant(tmp_path, text)
    out = tmp_path / "never.csv"
    res = run("simulate", f, "--trials", 5, "--out", out)
    assert res.returncode == 2, (case, res.returncode, res.stderr)
    assert res.stdout == ""
    assert "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert "bad.toml" in res.stderr
    assert not out.exists()


def test_out_into_missing_directory_is_bad_input_and_writes_nothing(tmp_path):
    out = tmp_path / "no" / "such" / "dir.csv"
    res = run("simulate", ROOT / "scenes" / "peg_in_hole_cell.toml", "--trials", 5, "--out", out)
    assert res.returncode == 2, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_icp_alternative_registration_row():
    """ICP registers the sensor to the mesh, i.e. to the TRUE geometry, so the robot's kinematic bias stays in
    the rigid error at the checks; RRBC over the fiducials removes most of it."""
    res = run("simulate", ROOT / "scenes" / "demo_workcell.toml", "--trials", 10, "--icp", 2, "--json")
    assert res.returncode == 0, res.stderr
    rows = {s["name"]: s for s in json.loads(res.stdout)["strategies"]}
    icp = rows["icp"]
    assert icp["trials"] == 2
    assert icp["rmst_rrbc_mm"] < 0.5 * icp["tre_rms_mm"]


def test_out_carries_the_arms_joint_angles_and_diagnose_tests_the_arm(tmp_path, capsys):
    """A scene whose robot error is kinematic writes q1..q6 (degrees): the configuration each point is reached in;
    FK of the scene's nominal arm at those joints is the robot's reported position (the file's robot columns)."""
    from rrbc_core.cli import main
    from rrbc_core.io.joints import joint_angles
    from rrbc_core.io.measurements import read_measurements
    from rrbc_core.models.kinematics import UR5, forward

    out = tmp_path / "m.csv"
    assert main(["simulate", str(ROOT / "scenes" / "demo_workcell.toml"), "--trials", "2", "--out", str(out)]) == 0
    capsys.readouterr()
    m = read_measurements(out)
    q = joint_angles(m)
    rows = [i for i, r in enumerate(m.roles) if r in ("registration", "fiducial")]
    reported, _ = forward(UR5.with_tool(100.0), q[rows])
    # the robot columns hold the reading: the nominal FK at these joints plus the scene's 0.03 mm repeatability noise
    assert abs(float(((m.robot[rows] - reported) ** 2).mean()) ** 0.5 - 0.03) < 0.012
    assert main(["diagnose", str(out), "--tool", "100", "--json"]) == 0
    assert "kinematic" in json.loads(capsys.readouterr().out)["tests"]


@pytest.mark.slow
def test_a_simulated_arm_file_is_read_as_it_is_by_diagnose_and_calibrate(tmp_path):
    """Issue 36: `simulate --out` writes the joints and the tool (tool_x, tool_y, tool_z) of a scene whose UR5 bends
    under its own weight; `diagnose --robot ur5` then tests compliance (the packaged UR5 carries its masses) and
    `calibrate --robot ur5 --compliance` identifies the planted stiffnesses within four standard errors."""
    import shutil

    (tmp_path / "meshes").mkdir()
    shutil.copy(ROOT / "scenes" / "meshes" / "demo_workcell.glb", tmp_path / "meshes")
    text = (ROOT / "scenes" / "demo_workcell.toml").read_text()
    head, rest = text.split("[[error_model.robot]]", 1)
    tail = rest[rest.index("[simulation]") :] if "[simulation]" in rest else ""
    planted = {"joint2.compliance": 1e-4, "joint3.compliance": 8e-5}
    model = """[[error_model.robot]]
type = "compliance"
joints_rad_per_Nm = [0, 1e-4, 8e-5, 0, 0, 0]

[[error_model.robot]]
type = "isotropic_noise"
sigma_mm = 0.02

[[error_model.sensor]]
type = "isotropic_noise"
sigma_mm = 0.02

"""
    (tmp_path / "scene.toml").write_text(head + model + tail)
    data = tmp_path / "d.csv"
    assert run("simulate", tmp_path / "scene.toml", "--trials", 20, "--out", data).returncode == 0
    header = next(line for line in data.read_text().splitlines() if not line.startswith("#")).split(",")
    assert {"q1", "q6", "tool_x", "tool_y", "tool_z"} <= set(header)
    dg = run("diagnose", data, "--robot", "ur5", "--json")
    assert dg.returncode == 0, dg.stderr
    tests = json.loads(dg.stdout)["tests"]
    assert "kinematic" in tests and "compliance" in tests  # the arm was tested with the file's own tool
    cal = run("calibrate", data, "--robot", "ur5", "--compliance", "--json")
    assert cal.returncode == 0, cal.stderr
    cj = json.loads(cal.stdout)
    assert set(cj["compliance"]["entered"]) == set(planted)
    terms = {p["name"]: p for p in cj["parameters"] if p.get("kind") == "compliance"}
    for name, value in planted.items():
        assert abs(terms[name]["error"] - value) <= 4 * terms[name]["std_error"], terms[name]
