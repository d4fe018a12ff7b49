"""Exact interpolators on real-like data (issue 28): nearly coincident fiducials with conflicting corrections and a
spline pushed to swing must not predict corrections far beyond the fiducials'."""

import numpy as np
import pytest

from rrbc_core.interpolation.base import NEAR_FRACTION
from rrbc_core.interpolation.linear import Linear
from rrbc_core.interpolation.tps import BOUND_FACTOR, TPS


def _conflicting(seed: int):
    """Fiducials in a 600 mm box with a smooth correction field, plus twins 0.05-0.2 mm from some of them whose
    corrections differ by 2-6 mm (the same place reached in two arm configurations)."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-300, 300, (40, 3))
    corr = np.column_stack([np.sin(pts[:, 0] / 200), np.cos(pts[:, 1] / 250), 0.5 * np.sin(pts[:, 2] / 300)]) * 2
    twins = rng.choice(40, 8, replace=False)
    offsets = rng.normal(size=(8, 3))
    offsets *= rng.uniform(0.05, 0.2, (8, 1)) / np.linalg.norm(offsets, axis=1, keepdims=True)
    jumps = rng.normal(size=(8, 3))
    jumps *= rng.uniform(2, 6, (8, 1)) / np.linalg.norm(jumps, axis=1, keepdims=True)
    return np.vstack([pts, pts[twins] + offsets]), np.vstack([corr, corr[twins] + jumps]), rng


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("method", [TPS(), Linear()])
def test_conflicting_twins_do_not_blow_up(seed, method):
    pts, corr, rng = _conflicting(seed)
    fitted = method.fit(pts, corr)
    queries = rng.uniform(-300, 300, (2000, 3))
    pred = fitted.predict(queries).values
    largest = np.linalg.norm(corr, axis=1).max()
    assert np.linalg.norm(pred, axis=1).max() <= BOUND_FACTOR * largest + 1e-9


def test_the_unregularised_spline_does_blow_up_on_such_data():
    """The check above can fail: scipy's exact thin-plate spline on the same fiducials swings far beyond them."""
    from scipy.interpolate import RBFInterpolator

    pts, corr, rng = _conflicting(0)
    rbf = RBFInterpolator(pts, corr, kernel="thin_plate_spline", degree=1)
    grid = rng.uniform(-300, 300, (2000, 3))
    peak = np.linalg.norm(rbf(grid), axis=1).max()
    assert peak > BOUND_FACTOR * np.linalg.norm(corr, axis=1).max()


def test_twins_farther_apart_than_the_merge_tolerance_are_kept():
    """Fiducials 10 mm apart are two places: an exact spline still passes through both corrections."""
    rng = np.random.default_rng(3)
    pts = rng.uniform(-300, 300, (20, 3))
    pts = np.vstack([pts, pts[0] + [10.0, 0, 0]])
    corr = np.column_stack([np.sin(pts[:, 0] / 200), np.cos(pts[:, 1] / 250), np.sin(pts[:, 2] / 300)])
    assert 10.0 / np.sqrt((pts - pts.mean(0)) ** 2).sum(1).mean() > NEAR_FRACTION
    pred = TPS().fit(pts, corr).predict(pts).values
    np.testing.assert_allclose(pred, corr, atol=1e-6)
