"""`rrbc calibrate`'s per-point bounds (issue 37, item 1): each target and check gets a 95 % bound for every method
(rigid, RRBC, VEC, VEC+RRBC) with its budget (VEC's with the arm model's part), and the bounds hold on held-out
checks of seeded arm files with kinematic errors and sensor fields."""

import numpy as np
import pytest

from rrbc_core.analysis.vec_compare import compare
from rrbc_core.correction.bound_radius import bound95
from rrbc_core.models.urdf import load_urdf
from rrbc_core.simulation.arm_data import chain_measurements

METHODS = ("rigid", "rrbc", "vec", "vec_rrbc")


@pytest.fixture(scope="module")
def ur5():
    return load_urdf("ur5", tip="tool0")


def test_every_target_and_check_has_a_bound_per_method_with_its_budget(ur5):
    out = compare(chain_measurements(ur5, 3, kin_size=1.0, field_mm=0.3, n_chk=20, n_tgt=4), urdf="ur5", tip="tool0")
    assert len(out["targets"]) == 4 and len(out["check_points"]) == 20
    assert out["bounds"]["instrument"]["source"]
    for row in out["targets"] + out["check_points"]:
        assert set(row["bound95_mm"]) == set(METHODS)
        for m in METHODS:
            b = row["bound95_mm"][m]
            if b is None:
                continue
            cov = np.array(row["cov_mm2"][m])
            assert b == pytest.approx(bound95(cov[None])[0])
            assert "arm" in row["budget_mm"][m] if m.startswith("vec") else "registration" in row["budget_mm"][m]
    # a check's error per method is the distance of its command from the robot's reading
    c = out["check_points"][0]
    assert set(c["error_mm"]) == set(METHODS)


def test_vecs_arm_share_is_the_identified_parameters_uncertainty(ur5):
    """More poses identify the arm better: VEC's arm share at the same targets shrinks."""
    few = compare(chain_measurements(ur5, 8, n_fid=20, n_chk=0, n_tgt=5), urdf="ur5", tip="tool0")
    many = compare(chain_measurements(ur5, 8, n_fid=120, n_chk=0, n_tgt=5), urdf="ur5", tip="tool0")
    arm = [
        np.median([r["budget_mm"]["vec"]["arm"] for r in o["targets"] if r["budget_mm"]["vec"]]) for o in (few, many)
    ]
    assert arm[1] < arm[0]


@pytest.mark.slow
def test_calibrates_bounds_hold_on_held_out_checks(ur5):
    pairs = {m: [] for m in METHODS}
    for seed in range(8):
        rng = np.random.default_rng(seed)
        m = chain_measurements(
            ur5,
            seed,
            kin_size=float(rng.uniform(0.5, 2)),
            field_mm=float(rng.choice([0.0, 0.3, 1.0])),
            n_chk=40,
            stations=int(rng.choice([1, 2])),
        )
        for c in compare(m, urdf="ur5", tip="tool0")["check_points"]:
            for k in METHODS:
                if c["bound95_mm"][k] is not None:
                    pairs[k].append((c["error_mm"][k], c["bound95_mm"][k]))
    for k, v in pairs.items():
        v = np.array(v)
        n = len(v)
        cover = float(np.mean(v[:, 0] <= v[:, 1]))
        se = np.sqrt(0.95 * 0.05 / n)
        assert n > 200 and 0.90 - 2 * se <= cover <= 0.99 + 2 * se, (k, cover, n)


def test_held_out_registration_points_do_not_make_the_profiles_when_enough_other_fiducials_were_held_out():
    """Registration points that are fiducials too (role `both`) are held out like the others, but their errors are
    fit residuals: with at least six other held-out fiducials, what they show does not move any bound (as in
    `rrbc correct`, `correction.bounds`); scaling their held-out errors a hundredfold leaves every bound as it was."""
    import dataclasses

    from rrbc_core.analysis.robot_model import robot_chain
    from rrbc_core.analysis.vec_bounds import method_bounds
    from rrbc_core.analysis.vec_compare import _cv_squared, _idw_by_group, cv_folds, fit_methods
    from rrbc_core.io.joints import joint_values
    from rrbc_core.studies.vec_study import TOOL_MM, joint_measurements

    m = joint_measurements(4, n_reg=12, n_fid=30, n_chk=10, n_tgt=0)
    m = dataclasses.replace(m, roles=tuple("both" if r == "registration" else r for r in m.roles))
    chain = robot_chain("ur5", None, None, None, TOOL_MM)
    q = joint_values(m, chain)
    roles = np.array(m.roles)
    s, b = np.asarray(m.sensor), np.asarray(m.robot)
    rows_reg = np.flatnonzero(roles == "both")
    rows_fid = np.flatnonzero(np.isin(roles, ("both", "fiducial")))
    rows_pts = np.flatnonzero(roles == "check")
    folds = cv_folds(rows_reg, rows_fid)
    held = np.concatenate([rows_fid[h] for h in folds])
    assert np.isin(held, rows_reg).any() and np.count_nonzero(~np.isin(held, rows_reg)) >= 6
    fit = fit_methods(rows_reg, rows_fid, s, b, q, chain)
    sq = _cv_squared(folds, rows_reg, rows_fid, s, b, q, chain, None)
    inflated = {k: np.where(np.isin(held, rows_reg), 100.0 * v, v) for k, v in sq.items()}
    args = (rows_reg, rows_fid, rows_pts, s, b, q, None, _idw_by_group)
    before, _, _ = method_bounds(m, fit, folds, sq, *args)
    after, _, _ = method_bounds(m, fit, folds, inflated, *args)
    for name in METHODS:
        assert np.allclose(before[name].bound95_mm, after[name].bound95_mm, equal_nan=True), name
