"""Issue 38: RRBC silently worse than rigid where checks and targets are reached in other joint configurations than
the fiducials around them. `rrbc calibrate` warns (`analysis.configuration_check`: a one-sided Mann-Whitney test of
the points' configuration change against the fiducials' own, at ALPHA); on files whose checks are drawn like the
fiducials it stays silent."""

from __future__ import annotations

import pytest

from rrbc_core.analysis.configuration_check import ALPHA
from rrbc_core.analysis.vec_compare import compare
from rrbc_core.cli_authoring import calibrate_text
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
    assert len(out["warnings"]) == 1 and "RRBC interpolates by position only" in out["warnings"][0]
    # the situation the warning is about: RRBC no better than rigid at these checks, VEC far better
    rm = out["rmst_mm"]
    assert rm["rrbc"] > 0.9 * rm["rigid"] and rm["vec"] < 0.2 * rm["rigid"], rm
    assert "warning: " + out["warnings"][0] in calibrate_text(out)
