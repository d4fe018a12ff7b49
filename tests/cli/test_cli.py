"""`rrbc correct` end to end against docs/cli.md: the installed console script itself (a fresh interpreter, its entry
point) in `test_the_console_script_corrects_and_refuses`, every other case through `rrbc_core.cli.main` in this
process (`tests.support.cli_run`: the same exit code, stdout and stderr without a second of imports per call)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.paths import EXAMPLE_CSV
from tests.support.cli_run import rrbc
from tests.support.synth import BiasField, measure, random_transform

RRBC = str(Path(sys.executable).with_name("rrbc"))
EXAMPLE = EXAMPLE_CSV
HEADER = "id,role,sensor_x,sensor_y,sensor_z,robot_x,robot_y,robot_z,time"


def run_script(*args):
    """The installed console script in a new process."""
    return subprocess.run([RRBC, *map(str, args)], capture_output=True, text=True, timeout=120)


run = rrbc


def _fmt(v):
    return "" if not np.isfinite(v) else repr(float(v))


def write_cell(path, seed, bias_rms=0.5, sigma=0.01, n_targets=5, n_checks=40):
    """A fresh seeded data set nobody has seen: 3-D fiducial grid (3x3x2), 6 registration points, targets and
    checks inside; a smooth robot bias field. Returns the arrays used."""
    rng = np.random.default_rng(seed)
    true = random_transform(rng)
    field = BiasField.random(rng, bias_rms) if bias_rms else None
    gx, gy, gz = np.meshgrid(np.linspace(0, 500, 3), np.linspace(0, 400, 3), np.linspace(0, 150, 2))
    fid = np.c_[gx.ravel(), gy.ravel(), gz.ravel()] + rng.normal(0, 5, (18, 3))
    regp = np.array(
        [[-100, -100, -20], [600, -80, 0], [620, 480, 30], [-90, 500, 200], [250, 200, 300], [300, -120, 250.0]]
    )
    tgt = rng.uniform([30, 30, 10], [470, 370, 140], (n_targets, 3))
    chk = rng.uniform([30, 30, 10], [470, 370, 140], (n_checks, 3))
    rows = [HEADER]
    data = {}
    for role, pts in (("registration", regp), ("fiducial", fid), ("target", tgt), ("check", chk)):
        s, b, truth = measure(rng, true, field, pts, sigma)
        if role == "check":
            b = truth
        if role == "target":
            b = np.full_like(b, np.nan)
        data[role] = (s, b)
        for k in range(len(pts)):
            rows.append(",".join([f"{role[0].upper()}{k}", role, *map(_fmt, s[k]), *map(_fmt, b[k]), _fmt(float(k))]))
    path.write_text("\n".join(rows) + "\n")
    return data


def reference_rrbc(data, k=4, p=2.0):
    """Independent implementation of the published method: scipy's Kabsch (align_vectors on centred points)
    and a plain loop for inverse-distance weights over the k nearest fiducials."""
    rs, rb = data["registration"]
    rot, _ = Rotation.align_vectors(rb - rb.mean(0), rs - rs.mean(0))
    rmat = rot.as_matrix()
    t = rb.mean(0) - rmat @ rs.mean(0)
    fs, fb = data["fiducial"]
    e = np.array([rmat.T @ (b - t) - s for s, b in zip(fs, fb)])
    out = {}
    for role in ("target", "check"):
        xs, _ = data[role]
        corr = []
        for x in xs:
            d = np.linalg.norm(fs - x, axis=1)
            idx = np.argsort(d)[:k]
            w = 1.0 / d[idx] ** p
            corr.append((w[:, None] * e[idx]).sum(0) / w.sum())
        corr = np.array(corr)
        out[role] = (corr, (xs + corr) @ rmat.T + t, xs @ rmat.T + t)
    return rmat, t, e, out


@pytest.mark.parametrize("seed", [101, 202])
@pytest.mark.parametrize("k, p", [(4, 2.0), (6, 1.5)])
def test_idw_correct_matches_an_independent_implementation_to_1e_6_mm(tmp_path, seed, k, p):
    f = tmp_path / "cell.csv"
    data = write_cell(f, seed)
    res = run("correct", f, "--neighbors", k, "--power", p, "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    rmat, t, e, ref = reference_rrbc(data, k, p)
    np.testing.assert_allclose(out["registration"]["rotation"], rmat, atol=1e-9)
    np.testing.assert_allclose(out["registration"]["translation"], t, atol=1e-6)
    np.testing.assert_allclose([f["correction_mm"] for f in out["fiducials"]], e, atol=1e-6)
    for role, key in (("target", "targets"), ("check", "checks")):
        corr, robot_rrbc, robot_rigid = ref[role]
        np.testing.assert_allclose([r["correction_mm"] for r in out[key]], corr, atol=1e-6)
        np.testing.assert_allclose([r["robot_rrbc"] for r in out[key]], robot_rrbc, atol=1e-6)
        np.testing.assert_allclose([r["robot_rigid"] for r in out[key]], robot_rigid, atol=1e-6)
    s = out["summary"]
    assert s["rmst_rrbc_mm"] < s["rmst_rigid_mm"]  # bias (0.5 mm RMS) dominates noise (0.01 mm)
    truth = data["check"][1]
    err = np.linalg.norm(ref["check"][1] - truth, axis=1)
    assert s["rmst_rrbc_mm"] == pytest.approx(np.sqrt(np.mean(err**2)), abs=1e-6)
    assert s["max_rrbc_mm"] == pytest.approx(err.max(), abs=1e-6)


REGS = ["least-squares", "three-point", "combinatorial", "annealing", "clustering"]
INTERPS = ["idw", "linear", "tps", "gp", "none"]


@pytest.fixture(scope="module")
def bias_cell(tmp_path_factory):
    f = tmp_path_factory.mktemp("cell") / "bias.csv"
    write_cell(f, 7, bias_rms=0.6, sigma=0.01)
    return f


@pytest.mark.parametrize("reg", REGS)
@pytest.mark.parametrize("interp", INTERPS)
def test_every_strategy_and_interpolation_works_from_the_cli(bias_cell, reg, interp):
    res = run("correct", bias_cell, "--registration", reg, "--interpolation", interp, "--json")
    assert res.returncode == 0, res.stderr
    assert res.stderr == ""
    out = json.loads(res.stdout)
    for key in ("method", "rotation", "translation", "fre_rms_mm"):
        assert key in out["registration"]
    assert out["registration"]["method"] == reg
    assert np.array(out["registration"]["rotation"]).shape == (3, 3)
    assert len(out["fiducials"]) == 18 and len(out["targets"]) == 5 and len(out["checks"]) == 40
    for row in out["checks"]:
        for key in ("id", "sensor", "correction_mm", "robot_rigid", "robot_rrbc", "error_rigid_mm", "error_rrbc_mm"):
            assert key in row
    s = out["summary"]
    if interp == "none":
        assert s["rmst_rrbc_mm"] == pytest.approx(s["rmst_rigid_mm"])
    else:
        assert s["rmst_rrbc_mm"] < 0.7 * s["rmst_rigid_mm"], s
    if interp == "gp":
        assert "correction_std_mm" in out["checks"][0]


def test_extrapolated_targets_are_flagged(tmp_path):
    f = tmp_path / "cell.csv"
    write_cell(f, 3)
    text = f.read_text().splitlines()
    text.append("FAR,target,2000,2000,2000,,,,")
    f.write_text("\n".join(text) + "\n")
    out = json.loads(run("correct", f, "--json").stdout)
    flags = {r["id"]: r["extrapolated"] for r in out["targets"]}
    assert flags["FAR"] is True
    assert not any(v for k, v in flags.items() if k != "FAR")


def test_readable_table_without_json():
    res = run("correct", EXAMPLE)
    assert res.returncode == 0, res.stderr
    assert "registration: least-squares" in res.stdout
    assert "summary over" in res.stdout and "RMST rigid" in res.stdout
    with pytest.raises(json.JSONDecodeError):
        json.loads(res.stdout)


def test_the_console_script_corrects_and_refuses():
    """The installed `rrbc` in a new process: the bundled example is corrected (RRBC helps on it, and the script
    prints what `main` prints in this process); no arguments is one line on stderr and exit 2."""
    res = run_script("correct", EXAMPLE, "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["summary"]["rmst_rrbc_mm"] < out["summary"]["rmst_rigid_mm"]
    assert res.stdout == run("correct", EXAMPLE, "--json").stdout
    bad = run_script()
    assert bad.returncode == 2 and bad.stdout == "" and len(bad.stderr.strip().splitlines()) == 1, bad.stderr


def _good_rows():
    return [
        HEADER,
        "A,registration,0,0,0,10,20,30,0",
        "B,registration,500,0,0,510,20,30,1",
        "C,registration,0,400,0,10,420,30,2",
        "D,both,500,400,100,510,420,130,3",
        "F1,fiducial,250,200,50,260,220,80,4",
        "T1,target,200,150,40,,,,5",
        "K1,check,300,250,60,310,270,90,6",
    ]


def _mutate(rows, line, new):
    rows = list(rows)
    rows[line - 1] = new
    return rows


BAD = {
    "missing column": (
        [r.replace(",sensor_z", "") if i == 0 else r for i, r in enumerate(_good_rows())],
        ["line 1", "sensor_z"],
    ),
    "non-numeric": (_mutate(_good_rows(), 3, "B,registration,500,abc,0,510,20,30,1"), ["line 3", "sensor_y"]),
    "non-finite": (_mutate(_good_rows(), 4, "C,registration,0,400,inf,10,420,30,2"), ["line 4", "sensor_z"]),
    "nan": (_mutate(_good_rows(), 6, "F1,fiducial,250,200,50,nan,220,80,4"), ["line 6", "robot_x"]),
    "bad time": (_mutate(_good_rows(), 7, "T1,target,200,150,40,,,,soon"), ["line 7", "time"]),
    "unknown role": (_mutate(_good_rows(), 6, "F1,fudicial,250,200,50,260,220,80,4"), ["line 6", "role"]),
    "robot missing": (_mutate(_good_rows(), 8, "K1,check,300,250,60,,270,90,6"), ["line 8", "robot_x"]),
    "too few registration": ([r for r in _good_rows() if not r.startswith(("B,", "C,"))], ["registration"]),
    "collinear": (
        _mutate(_mutate(_good_rows(), 4, "C,registration,1000,0,0,1010,20,30,2"), 5, "D,both,1500,0,0,1510,20,30,3"),
        ["collinear"],
    ),
    "coincident": (_mutate(_good_rows(), 4, "C,registration,500,0,0,510,20,30,2"), ["coincid"]),
    "mixed roles": (_good_rows() + ["A,fiducial,0,0,0,10,20,30,9"], ["line 9", "role"]),
    "wrong cell count": (_mutate(_good_rows(), 3, "B,registration,500,0,0,510,20"), ["line 3"]),
}


def test_good_rows_are_good(tmp_path):
    f = tmp_path / "good.csv"
    f.write_text("\n".join(_good_rows()) + "\n")
    res = run("correct", f, "--interpolation", "idw", "--json")
    assert res.returncode == 0, res.stderr


@pytest.mark.parametrize("case", list(BAD))
def test_bad_measurement_files_exit_2_with_one_line(tmp_path, case):
    rows, needles = BAD[case]
    f = tmp_path / "bad.csv"
    f.write_text("\n".join(rows) + "\n")
    res = run("correct", f, "--json")
    assert res.returncode == 2, (res.returncode, res.stderr)
    assert res.stdout == ""
    assert "Traceback" not in res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert "bad.csv" in lines[0]
    for needle in needles:
        assert needle in lines[0], lines[0]


@pytest.mark.parametrize(
    "args",
    [
        ["correct", "/nonexistent/file.csv"],
        ["correct", EXAMPLE, "--registration", "magic"],
        ["correct", EXAMPLE, "--interpolation", "cubic"],
        ["correct", EXAMPLE, "--neighbors", "0"],
        ["correct", EXAMPLE, "--neighbors", "x"],
        ["correct", EXAMPLE, "--power", "-1"],
        ["correct", EXAMPLE, "--interpolation", "tps", "--neighbors", "3"],
        ["correct"],
        ["frobnicate"],
        [],
    ],
)
def test_usage_errors_exit_2_with_one_line(args):
    res = run(*args)
    assert res.returncode == 2, (res.returncode, res.stderr)
    assert res.stdout == ""
    assert "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr


def test_combinatorial_on_too_many_registration_points_is_refused_in_one_line(tmp_path):
    from rrbc_core.registration.strategies import MAX_SUBSET_POINTS

    rng = np.random.default_rng(2)
    n = MAX_SUBSET_POINTS + 1
    s = rng.uniform(0, 500, (n, 3))
    rows = [HEADER] + [f"R{k},both,{s[k, 0]},{s[k, 1]},{s[k, 2]},{s[k, 0] + 5},{s[k, 1]},{s[k, 2]}," for k in range(n)]
    path = tmp_path / "many.csv"
    path.write_text("\n".join(rows) + "\n")
    out = run("correct", path, "--registration", "combinatorial")
    assert out.returncode == 2 and out.stdout == ""
    assert len(out.stderr.strip().splitlines()) == 1 and f"at most {MAX_SUBSET_POINTS} points" in out.stderr
