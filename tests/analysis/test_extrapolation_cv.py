"""The buffered leave-out folds and the weighted one-standard-error rule behind `rrbc calibrate`'s recommendation
for checks beyond the fiducials (rrbc_core/analysis/extrapolation_cv.py)."""

from __future__ import annotations

import numpy as np

from rrbc_core.analysis.extrapolation_cv import beyond_points, extrapolation_folds, mixture_choice


def _cloud(seed: int):
    """40 fiducials in a 400 mm cube (rows 0..39; the first 8 also registration rows), 30 points to predict
    spread over a cube three times as large (rows 40..69), mm."""
    rng = np.random.default_rng(seed)
    s = np.vstack([rng.uniform(0, 400, (40, 3)), rng.uniform(-400, 800, (30, 3))])
    return s, np.arange(8), np.arange(40), np.arange(40, 70)


def test_every_fold_predicts_its_anchor_from_no_nearer_than_the_point_it_stands_for():
    for seed in range(5):
        s, reg, fid, pred = _cloud(seed)
        beyond = beyond_points(s, fid, pred)
        assert 0 < beyond.share < 1 and not beyond.untestable.any()  # a volume of fiducials: all testable
        folds = extrapolation_folds(s, reg, fid, beyond, max_folds=10, min_poses=0)
        assert 2 <= len(folds) <= 10
        tested = set()
        for held, scored in folds:
            [a] = scored
            assert a in held
            train = np.setdiff1d(np.arange(len(fid)), held)
            gap = np.linalg.norm(s[fid[train]] - s[fid[a]], axis=1).min()
            # the point this fold stands for: one beyond whose nearest fiducial is the anchor
            mine = [p for p in np.flatnonzero(beyond.mask) if beyond.anchor[p] == a]
            assert mine and gap > min(beyond.distance_mm[p] for p in mine)
            tested.add(a)
        assert len(tested) >= 2


def test_a_fold_that_would_leave_a_station_too_few_registration_rows_is_dropped():
    s, _, fid, pred = _cloud(1)
    beyond = beyond_points(s, fid, pred)
    reg_all = fid.copy()  # every fiducial a registration row: a fold leaves what it does not hold out
    kept = extrapolation_folds(s, reg_all, fid, beyond, min_registration=3, min_poses=0)
    assert all(len(fid) - len(h) >= 3 for h, _ in kept)
    few = extrapolation_folds(s, reg_all, fid, beyond, min_registration=len(fid), min_poses=0)
    assert few == []


def test_points_off_the_plane_of_coplanar_fiducials_are_untestable_but_not_those_beside_it():
    rng = np.random.default_rng(3)
    board = np.column_stack([rng.uniform(0, 500, 30), rng.uniform(0, 500, 30), np.zeros(30)])
    pts = np.array([[250.0, 250.0, 400.0], [1500.0, 250.0, 0.0], [250.0, 250.0, 0.0]])
    s = np.vstack([board, pts])
    beyond = beyond_points(s, np.arange(30), np.arange(30, 33))
    assert beyond.mask.tolist() == [True, True, False]
    assert beyond.untestable.tolist() == [True, False, False]
    assert beyond.untestable_share == 1 / 3


def test_the_weighted_rule_follows_the_part_that_speaks_for_most_points():
    rng = np.random.default_rng(0)
    n = 40
    base = rng.chisquare(3, n)
    inside = {"rigid": 4 * base, "rrbc": base, "vec": 1.5 * base, "vec_rrbc": 1.2 * base}  # rrbc best inside
    far = {"rigid": base, "rrbc": 2 * base, "vec": 0.2 * base, "vec_rrbc": 3 * base}  # vec best beyond
    assert mixture_choice([(0.9, inside), (0.1, far)]) == "rrbc"
    assert mixture_choice([(0.1, inside), (0.9, far)]) == "vec"
    assert mixture_choice([(1.0, inside)], ("rigid", "vec")) == "vec"
    # a difference within one standard error of the paired differences: the simpler method
    noise = rng.normal(0, 1, n)
    close = {"rigid": base + 0.01 * noise, "rrbc": base, "vec": base, "vec_rrbc": base}
    assert mixture_choice([(1.0, close)]) == "rigid"
