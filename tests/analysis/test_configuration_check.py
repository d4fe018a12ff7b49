"""Issue 38: RRBC silently worse than rigid where checks and targets are reached in other joint configurations than
the fiducials around them. `rrbc calibrate` warns (`correction.configuration_check`: a one-sided Mann-Whitney test of
the points' configuration change against the fiducials' own, at ALPHA); on files whose checks are drawn like the
fiducials it stays silent."""

from __future__ import annotations

import pytest

from rrbc_core.analysis.vec_compare import compare
from rrbc_core.cli_authoring import calibrate_text
from rrbc_core.correction.configuration_check import ALPHA
from rrbc_core.studies.vec_study import joint_measurements

WRIST_TURNED = (0.0, 0.0, 0.0, 2.0, 0.0, 2.0)  # the checks' and targets' wrist joints turned by 2 rad (115°)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_checks_drawn_like_the_fiducials_give_no_warning(seed):
    out = compare(joint_measurements(seed, dh_size=1.0, n_fid=40, n_chk=30), "ur5", 100.0)
    assert not out["configuration"]["flagged"] and out["configuration"]["p_value"] >= ALPHA
    assert out["warnings"] == []


@pytest.mark.parametrize("seed", [1, 2])
def test_checks_reached_with_the_wrist_turned_are_warned_about(seed):
    out = compare(joint_measurements(seed, dh_size=1.0, n_fid=40, n_chk=30, point_shift_rad=WRIST_TURNED), "ur5", 100.0)
    c = out["configuration"]
    assert c["flagged"] and c["p_value"] < ALPHA and c["beyond"] > c["points"] // 2
    # the warning names what RRBC interpolated over (`configuration_rrbc`: position, or the joints where the
    # fiducials' cross-validation says so)
    space = out["interpolation_space"]["rrbc"]["space"]
    words = {
        "position": "RRBC interpolates by position only",
        "configuration": "RRBC interpolates over the fiducials' configurations, and none is near theirs",
    }[space]
    assert len(out["warnings"]) == 1 and words in out["warnings"][0]
    # the situation the warning is about: RRBC by position no better than rigid at these checks (over the joints
    # it carries corrections from other configurations: better than rigid here, far from VEC), VEC far better
    rm = out["rmst_mm"]
    assert rm["vec"] < 0.2 * rm["rigid"], rm
    if space == "position":
        assert rm["rrbc"] > 0.9 * rm["rigid"], rm
    else:
        assert rm["rrbc"] > 5 * rm["vec"], rm
    assert "warning: " + out["warnings"][0] in calibrate_text(out)


@pytest.mark.parametrize("seed", [1, 2])
def test_rrbc_correct_warns_on_a_file_with_q1_to_q6_where_the_configurations_differ(tmp_path, seed):
    """`rrbc correct` has no arm model, but a file with the DH arms' joint columns q1..q6 shows the configurations:
    the same warning as `calibrate` where the checks were reached with the wrist turned (RRBC is then worse than
    rigid at them, not silently), none where they were drawn like the fiducials, none without joint columns, and a
    file whose q columns are not degrees is corrected without it (correct does not need the joints)."""
    import dataclasses
    import json

    from rrbc_core.io.measurements_write import write_measurements
    from tests.support.cli_run import rrbc

    said = "reached in joint configurations farther"
    cases = {
        "turned": joint_measurements(seed, dh_size=1.0, n_fid=40, n_chk=30, point_shift_rad=WRIST_TURNED),
        "like": joint_measurements(seed, dh_size=1.0, n_fid=40, n_chk=30),
    }
    cases["no_joints"] = dataclasses.replace(cases["turned"], extra={})
    radians = {k: tuple(repr(float(v) / 57.29577951308232) for v in c) for k, c in cases["turned"].extra.items()}
    cases["radians"] = dataclasses.replace(cases["turned"], extra=radians)
    out = {}
    for name, m in cases.items():
        write_measurements(tmp_path / f"{name}.csv", m)
        r = rrbc("correct", tmp_path / f"{name}.csv", "--json")
        assert r.returncode == 0, r.stderr
        out[name] = json.loads(r.stdout)
    flagged = [w for w in out["turned"]["warnings"] if said in w]
    assert len(flagged) == 1 and "rrbc calibrate" in flagged[0], out["turned"]["warnings"]
    assert out["turned"]["summary"]["rmst_rrbc_mm"] > 0.9 * out["turned"]["summary"]["rmst_rigid_mm"]
    for name in ("like", "no_joints", "radians"):
        assert not any(said in w for w in out[name]["warnings"]), (name, out[name]["warnings"])
    assert rrbc("correct", tmp_path / "turned.csv").stdout.count(said) == 1  # the text says it too
