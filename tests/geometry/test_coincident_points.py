"""Registration points that coincide are refused, naming the pair (`geometry.points.check_registration_points`): the
same answer from the all-pairs test of a small set and the k-d tree of a large one (`SMALL_SET`)."""

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.geometry.points import COINCIDENT_MM, SMALL_SET, check_registration_points


@pytest.mark.parametrize("n", [6, SMALL_SET, SMALL_SET + 1, 5000])
@pytest.mark.parametrize("seed", range(2))
def test_a_coincident_pair_is_named_whatever_the_sets_size(n, seed):
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 1000, (n, 3))
    check_registration_points(p)  # distinct: accepted
    i, j = sorted(rng.choice(n, 2, replace=False))
    p[j] = p[i] + rng.normal(size=3) * COINCIDENT_MM / 10  # within the tolerance
    with pytest.raises(InputError, match=f"points {i + 1} and {j + 1} coincide"):
        check_registration_points(p)
    p[j] = p[i] + np.array([3 * COINCIDENT_MM, 0.0, 0.0])  # three tolerances apart: distinct
    check_registration_points(p)


@pytest.mark.parametrize(
    "shape",
    ["volume", "dense", "plane", "grid", "crowded"],
)
def test_the_sweep_finds_the_same_pairs_as_a_k_d_tree(shape):
    """Above `SMALL_SET` the sort-and-sweep (`coincident_pairs`) finds every pair a k-d tree finds, none more: in a
    volume, where points lie about a tolerance apart along the sweep, on a plane, on a grid (points equally spaced
    along axes and diagonals), and where so many crowd along the sweep that the tree answers."""
    from scipy.spatial import cKDTree

    from rrbc_core.geometry.points import SWEEP_WINDOW, coincident_pairs

    rng = np.random.default_rng(7)
    if shape == "volume":
        p = rng.uniform(0, 1000, (200_000, 3))
    elif shape == "dense":  # about one point per tolerance along the sweep: many to look at; 20 pairs planted
        p = rng.uniform(0, [200, 5, 1], (100_000, 3))
        p[50_000:50_020] = p[:20] + rng.normal(size=(20, 3)) * COINCIDENT_MM / 4
    elif shape == "plane":
        p = np.column_stack([rng.uniform(0, 30, (50_000, 2)), np.zeros(50_000)])
    elif shape == "grid":
        p = np.stack(np.meshgrid(*[np.arange(40) * COINCIDENT_MM * 1.5] * 3), -1).reshape(-1, 3)
    else:  # crowded: more than the window within a tolerance along the sweep
        p = rng.uniform(0, 0.05, (20_000, 3))
    found = coincident_pairs(p)
    tree = cKDTree(p).query_pairs(COINCIDENT_MM, output_type="ndarray")
    assert set(map(tuple, found.tolist())) == set(map(tuple, np.sort(tree, axis=1).tolist()))
    if shape == "dense":
        assert len(tree) >= 20  # (the case has pairs to find)
    assert SWEEP_WINDOW >= 8
