"""gp at the sizes users reach (issue 41, item 2): above `FIT_SUBSAMPLE` fiducials the hyper-parameters are fitted on
a fixed-seed random subset and the kriging on all of them. The predictions agree with the full-data fit to within
a stated tolerance: at every query within the predictive standard deviation, and in RMS within a tenth of the
fiducials' noise (seeded smooth fields with noise, twice the subset's size)."""

import numpy as np
import pytest

import rrbc_core.interpolation.gp as gp_module
from rrbc_core.interpolation.gp import FIT_SUBSAMPLE, GP

NOISE = 0.02  # mm per axis


def _data(seed, n):
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 1000, (n, 3))
    p[:, 2] *= 0.2
    ell = rng.uniform(150, 400)
    phase = rng.uniform(0, np.pi, 3)
    v = 0.3 * np.column_stack(
        [np.sin(p[:, 0] / ell + phase[0]), np.cos(p[:, 1] / ell + phase[1]), np.sin((p[:, 0] + p[:, 1]) / ell)]
    )
    q = rng.uniform(0, 1000, (400, 3))
    q[:, 2] *= 0.2
    return p, v + rng.normal(0, NOISE, v.shape), q


@pytest.mark.parametrize("seed", range(3))
def test_a_subset_fit_predicts_as_the_full_fit_within_its_own_uncertainty(seed, monkeypatch):
    p, v, q = _data(seed, 2 * FIT_SUBSAMPLE)
    fitted = GP().fit(p, v)
    assert fitted.fit_points == FIT_SUBSAMPLE
    sub = fitted.predict(q)
    monkeypatch.setattr(gp_module, "FIT_SUBSAMPLE", 10**6)
    full_fit = GP().fit(p, v)
    assert full_fit.fit_points == len(p)
    full = full_fit.predict(q)
    d = np.abs(sub.values - full.values)
    assert np.all(d <= full.std), float(np.max(d / full.std))
    assert np.sqrt(np.mean(d**2)) <= 0.1 * NOISE


def test_up_to_max_fiducials_are_taken_and_small_sets_are_fitted_on_all():
    p, v, _ = _data(7, 50)
    assert GP().fit(p, v).fit_points == 50
    assert gp_module.MAX_FIDUCIALS >= 5000
