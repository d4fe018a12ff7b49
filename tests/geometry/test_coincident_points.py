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
