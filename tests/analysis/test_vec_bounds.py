"""`rrbc calibrate`'s per-point bounds (issue 37, item 1): each target and check gets a 95 % bound for every method
(rigid, RRBC, VEC, VEC+RRBC) with its budget (VEC's with the arm model's part), and the bounds hold on held-out
checks of seeded arm files with kinematic errors and sensor fields."""

import numpy as np
import pytest

from rrbc_core.analysis.vec_compare import compare
from rrbc_core.correction.bounds import bound95
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
