"""What `rrbc calibrate` claims on data like the real stationing files (docs/real_data.md): a load term identified
below zero is taken out (no arm stiffens under its load), and a recommendation is not made from cross-validation over
fiducials that lie far from the checks."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest

from rrbc_core.analysis.saved_model import load_model
from rrbc_core.analysis.vec_compare import compare, drop_unphysical_terms
from rrbc_core.models.urdf import load_urdf
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


def _far_checks(mset, n_fid: int):
    """The same rows with new roles: the fiducials the n_fid rows nearest one corner of the data (sensor frame), the
    checks the farthest third; registration rows kept."""
    s = np.asarray(mset.sensor)
    roles = np.array(mset.roles, dtype=object)
    free = np.flatnonzero(np.isin(roles, ("fiducial", "check")))
    corner = s[free].min(axis=0)
    order = free[np.argsort(np.linalg.norm(s[free] - corner, axis=1))]
    roles[free] = "target"  # not used
    roles[order[:n_fid]] = "fiducial"
    roles[order[-len(order) // 3 :]] = "check"
    keep = np.flatnonzero(roles != "target")
    pick = lambda a: np.asarray(a)[keep]
    return replace(
        mset,
        ids=tuple(pick(mset.ids)),
        roles=tuple(pick(roles)),
        sensor=pick(mset.sensor),
        robot=pick(mset.robot),
        time=pick(mset.time),
        lines=tuple(0 for _ in keep),
        extra={k: tuple(pick(v)) for k, v in mset.extra.items()},
    )


@pytest.mark.parametrize("seed", [41, 42])
def test_checks_far_beyond_the_fiducials_get_no_correction_recommended(tmp_path, seed):
    chain = load_urdf("lift_arm")
    full = chain_measurements(chain, seed, n_fid=60, n_chk=60, n_tgt=0, noise_mm=0.05, kin_size=1.0, arm_seed=3)
    inside = compare(full, urdf="lift_arm")
    assert inside["extrapolated_share"] <= 0.5
    assert inside["recommendation_basis"].startswith("the one-standard-error rule")
    far = _far_checks(full, 20)
    res = compare(far, urdf="lift_arm")
    assert res["extrapolated_share"] > 0.5
    assert res["recommended"] == "rigid"
    assert "outside the fiducials' hull" in res["recommendation_basis"]
    # an arm identified on data covering its configurations and reused: vec may be chosen there
    model = tmp_path / "arm.json"
    compare(full, urdf="lift_arm", save_model=str(model))
    reused = compare(far, urdf="lift_arm", model=load_model(str(model)))
    assert reused["extrapolated_share"] > 0.5
    # the arm's errors are several times the noise: the saved arm wins over rigid, at the fiducials and the checks
    assert reused["recommended"] == "vec", reused["cv_rmst_mm"]
    assert reused["rmst_mm"]["vec"] < reused["rmst_mm"]["rigid"] / 3, reused["rmst_mm"]
