"""What `rrbc calibrate` claims on data like the real stationing files (docs/real_data.md): a load term identified
below zero is taken out (no arm stiffens under its load), and a recommendation for checks beyond the fiducials is made
from folds that test extrapolation as extrapolation (docs/recommendation_study.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from rrbc_core.analysis.saved_model import load_model
from rrbc_core.analysis.vec_compare import compare, drop_unphysical_terms
from rrbc_core.models.urdf import load_urdf
from rrbc_core.studies.recommendation_study import board_fiducials, far_checks
from rrbc_core.studies.vec_study import joint_measurements
from tests.support.urdf_arms import chain_measurements


@dataclass
class _Term:
    name: str
    unit: str = "rad/Nm"


@dataclass
class _Cal:
    terms: tuple
    coef: np.ndarray
    coef_se: np.ndarray


@dataclass
class _Fit:
    cal: _Cal


def test_the_most_negative_term_goes_first_and_the_rest_is_refitted():
    a, b, c = _Term("a"), _Term("b"), _Term("c")
    fits = {
        ("a", "b", "c"): _Fit(_Cal((a, b, c), np.array([2e-5, -1e-5, -3e-6]), np.array([1e-6, 5e-6, 1e-6]))),
        ("a", "b"): _Fit(_Cal((a, b), np.array([2e-5, -8e-6]), np.array([1e-6, 5e-6]))),
        ("a",): _Fit(_Cal((a,), np.array([2e-5]), np.array([1e-6]))),
    }
    calls = []

    def refit(rest):
        calls.append(tuple(t.name for t in rest))
        return fits[calls[-1]], rest

    fit, terms, refused = drop_unphysical_terms(fits[("a", "b", "c")], (a, b, c), refit)
    # c is 3 standard errors below zero, b only 2: c goes first; b is still below zero in the refit and goes next
    assert calls == [("a", "b"), ("a",)]
    assert [r["name"] for r in refused] == ["c", "b"]
    assert [t.name for t in terms] == ["a"] and fit is fits[("a",)]
    assert all(r["value"] < 0 and r["unit"] == "rad/Nm" for r in refused)


def test_a_planted_stiffening_is_not_entered_as_a_compliance():
    """An arm whose upper arm 'stiffens' under load (a negative compliance planted, which no arm has) beside a real
    forearm compliance: the impossible term is named as taken out, and no term below zero enters (what is left enters
    only if it still beats the geometric arm)."""
    chain = load_urdf("lift_arm")
    plant = {"upper_arm_joint.compliance": -4e-5, "forearm_joint.compliance": 4e-5}
    mset = chain_measurements(chain, 31, n_fid=40, n_chk=30, noise_mm=0.05, kin_size=0.0, compliance=plant)
    res = compare(mset, urdf="lift_arm", compliance=True)
    entered = {p["name"]: p["error"] for p in res["parameters"] if "kind" in p}
    assert "upper_arm_joint.compliance" not in entered
    assert "upper_arm_joint.compliance" in [r["name"] for r in res["compliance"]["refused"]]
    assert all(v >= 0 for v in entered.values()), entered


def _within(res, factor: float = 1.1) -> bool:
    rm = res["rmst_mm"]
    return rm[res["recommended"]] <= factor * min(rm.values())


@pytest.mark.parametrize("robot", ["lift_arm", "ur5"])
def test_checks_far_beyond_hundreds_of_poses_get_the_arm_that_extrapolates(tmp_path, robot):
    """Hundreds of poses, the checks the farthest third of them, the fiducials the 300 nearest one corner, an arm
    whose errors are kinematic (the shape of the hidden real arms' files): the identified arm carries to the checks
    and the buffered leave-out folds see it (issue 38: the former distance rule recommended rigid, 10-18x worse than
    VEC there). Chosen without the checks, the recommendation is within 10 % of the best at them."""
    if robot == "ur5":
        full, kw = joint_measurements(1, n_fid=400, n_chk=200, n_tgt=0), {"robot": "ur5", "tool": 100.0}
    else:
        chain = load_urdf("lift_arm")
        full = chain_measurements(chain, 1, n_fid=400, n_chk=200, n_tgt=0, noise_mm=0.05, kin_size=1.0, arm_seed=3)
        kw = {"urdf": "lift_arm"}
    far = far_checks(full, 300)
    res = compare(far, **kw)
    assert res["extrapolated_share"] > 0.5 and res["extrapolation_folds"] >= 10
    assert "folds that leave out every fiducial" in res["recommendation_basis"]
    assert _within(res), (res["recommended"], res["rmst_mm"], res["extrapolation_cv_rmst_mm"])
    assert res["rmst_mm"]["vec"] < res["rmst_mm"]["rigid"] / 3, res["rmst_mm"]
    if robot == "ur5":
        return
    # an arm identified on data covering its configurations and reused: only the transforms are fitted
    model = tmp_path / "arm.json"
    compare(full, **kw, save_model=str(model))
    reused = compare(far_checks(full, 20), **kw, model=load_model(str(model)))
    assert reused["extrapolated_share"] > 0.5
    assert reused["recommended"] in ("vec", "vec_rrbc"), (reused["cv_rmst_mm"], reused["extrapolation_cv_rmst_mm"])
    assert _within(reused), reused["rmst_mm"]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [3, 4])
def test_the_recommendation_beyond_the_fiducials_follows_what_the_error_is(seed):
    """Hundreds of poses, the checks the farthest third: with a smooth sensor field alone nothing learnt from the
    fiducials carries there and rigid (or what is within 10 % of the best) is recommended; with kinematic errors
    alone VEC is, within 10 % of the best at the checks; both chosen without the checks.

    With the field alone, an arm fitted to it can by chance do better than rigid at the far checks (seed 4: VEC 1.016
    against rigid 1.154 mm once calibrate reaches the least-squares fit); rigid, which corrects nothing the field
    made, is the answer that follows the error there."""
    chain = load_urdf("lift_arm")
    for kin, field in ((0.0, 1.0), (1.0, 0.0)):
        full = chain_measurements(
            chain, seed, n_fid=150, n_chk=80, n_tgt=0, noise_mm=0.05, kin_size=kin, field_mm=field
        )
        res = compare(far_checks(full, 100), urdf="lift_arm")
        assert res["extrapolated_share"] > 0.5 and res["extrapolation_folds"] >= 2
        follows = res["recommended"] == "rigid" if kin == 0.0 else res["recommended"] in ("vec", "vec_rrbc")
        assert follows or _within(res), (
            kin,
            field,
            res["recommended"],
            res["rmst_mm"],
            res["extrapolation_cv_rmst_mm"],
        )
        if kin:
            assert _within(res), (res["recommended"], res["rmst_mm"], res["extrapolation_cv_rmst_mm"])


def test_checks_off_the_plane_of_coplanar_fiducials_get_no_interpolated_correction(tmp_path):
    """A board of coplanar fiducials and checks far off its plane (the stationing data's shape): no held-out
    fiducial can test a direction the fiducials do not span, so no correction interpolated from them (rrbc,
    vec_rrbc) is recommended there; the arm's model, a function of the joints, may be (chosen against rigid)."""
    chain = load_urdf("lift_arm")
    full = chain_measurements(chain, 7, n_fid=4000, n_chk=0, n_tgt=0, noise_mm=0.05, kin_size=1.0, field_mm=0.5)
    board = board_fiducials(full)
    n_fid = sum(r == "fiducial" for r in board.roles)
    assert 15 <= n_fid <= 120, n_fid
    res = compare(board, urdf="lift_arm")
    assert res["extrapolated_share"] > 0.5 and res["extrapolation_folds"] == 0
    assert res["recommended"] in ("rigid", "vec")
    assert "off the fiducials' plane" in res["recommendation_basis"]
    # the same board with an arm saved and reused (the stationing study's "calibrate once"): every check beyond and
    # none testable, so the ordinary cross-validation is all the evidence there is (it divided by zero before)
    model = tmp_path / "arm.json"
    compare(board, urdf="lift_arm", save_model=str(model))
    reused = compare(board_fiducials(full, off_mm=900.0), urdf="lift_arm", model=load_model(str(model)))
    assert reused["extrapolated_share"] == 1.0 and reused["recommended"] in ("rigid", "vec")
    assert "the saved arm's vec" in reused["recommendation_basis"]
