"""The field model's kernel eigendecompositions are made once per point set and length scale
(`diagnosis_field._kernels`): a diagnosis fits the field several times on the same points; what it finds is the same
as computing them afresh. The length scale is searched coarse to fine: it finds the grid's best."""

import numpy as np

from rrbc_core.analysis import diagnosis_field as F
from rrbc_core.analysis.diagnosis import diagnose
from rrbc_core.studies.vec_study import joint_measurements


def test_a_cached_field_fit_is_the_fit_made_afresh_and_the_cache_stays_small():
    rng = np.random.default_rng(4)
    p = rng.uniform(-300, 300, (80, 3))
    fits = []
    for r in (rng.normal(size=(80, 3)), rng.normal(size=(80, 3))):
        F._EIGS.clear()
        fresh = F.fit_field(p, r)
        cached = F.fit_field(p, r)  # the second fit on these points takes the stored decompositions
        assert cached.length_mm == fresh.length_mm and np.array_equal(cached.lam, fresh.lam)
        assert cached.sigma2 == fresh.sigma2 and np.array_equal(cached.z, fresh.z)
        fits.append(cached)
    for k in range(F._EIGS_KEPT + 2):  # other point sets push the oldest out
        F.fit_field(p + k + 1.0, rng.normal(size=(80, 3)))
    assert len(F._EIGS) == F._EIGS_KEPT
    assert not fits[0].u.flags.writeable  # shared: no caller can change another's


def test_a_diagnosis_names_the_same_with_and_without_the_stored_decompositions(monkeypatch):
    m = joint_measurements(3, dh_size=1.0, field_mm=0.3, n_reg=8, n_fid=60, n_chk=40, n_tgt=0)
    with_cache = diagnose(m, robot="ur5", tool_mm=100.0).to_json()
    monkeypatch.setattr(F, "_EIGS_KEPT", 0)
    F._EIGS.clear()
    without = diagnose(m, robot="ur5", tool_mm=100.0).to_json()
    assert with_cache == without


def test_the_tabulated_ratio_search_chooses_what_evaluating_the_likelihood_at_every_trial_chooses():
    """`_ratios` tabulates the likelihood's per-axis sums over the grid once; the coordinate search it makes (three
    rounds over the axes, from 1) must choose the same grid ratios as one evaluating `_nll` at every trial, on
    residuals from pure noise to a field many times it, per axis and at every length scale of random point sets."""
    rng = np.random.default_rng(12)
    for _ in range(6):
        p = rng.uniform(-400, 400, (int(rng.integers(20, 120)), 3))
        size = 10.0 ** rng.uniform(-2, 2, 3)  # per axis: from far below the noise to far above it
        r = np.sin(p / rng.uniform(80, 400)) * size + rng.normal(size=p.shape)
        kernels = F._kernels(np.ascontiguousarray(p))
        for i in range(F.N_LENGTHS):
            d, u = kernels.at(i)
            z2 = (u.T @ r) ** 2
            lam = np.ones(3)
            for _ in range(3):
                for a in range(3):
                    trials = []
                    for value in F._LAMBDAS:
                        trial = lam.copy()
                        trial[a] = value
                        trials.append(F._nll(z2, d, trial)[0])
                    lam[a] = F._LAMBDAS[int(np.argmin(trials))]
            assert np.array_equal(F._ratios(z2, d), lam)


def _full_grid_length(p: np.ndarray, r: np.ndarray) -> float:
    """The length scale a fit evaluating the likelihood at every length of the grid chooses (the first of equals)."""
    kernels = F._kernels(np.ascontiguousarray(p))
    nlls = []
    for i in range(F.N_LENGTHS):
        d, u = kernels.at(i)
        z2 = (u.T @ r) ** 2
        nlls.append(F._nll(z2, d, F._ratios(z2, d))[0])
    return float(kernels.lengths[int(np.argmin(nlls))])


def test_the_coarse_to_fine_length_search_finds_the_best_length_of_the_whole_grid():
    """On seeded residuals shaped like diagnose's (pure noise; one smooth field of a random length from 30 to 3000 mm
    and a random size against the noise; two fields of different lengths at once; a linear trend; points in a volume,
    on a plane, in clusters), the fit's length is the one a search over every length of the grid chooses."""
    rng = np.random.default_rng(31)
    for case in range(24):
        n = int(rng.integers(15, 400))
        shape = case % 3
        if shape == 0:
            p = rng.uniform(-400, 400, (n, 3))
        elif shape == 1:
            p = np.c_[rng.uniform(-400, 400, (n, 2)), rng.normal(0, 0.5, n)]  # a board
        else:
            p = rng.normal(0, 30, (n, 3)) + rng.uniform(-500, 500, (4, 3))[rng.integers(0, 4, n)]  # stations
        kind = case % 4
        noise = rng.normal(size=(n, 3))
        size = 10.0 ** rng.uniform(-1, 1.5)
        if kind == 0:
            r = noise
        elif kind == 1:
            r = noise + size * np.sin(p @ rng.normal(size=(3, 3)) / 10.0 ** rng.uniform(1.5, 3.5))
        elif kind == 2:
            r = noise + size * (
                np.sin(p @ rng.normal(size=(3, 3)) / 60.0) + np.sin(p @ rng.normal(size=(3, 3)) / 900.0)
            )
        else:
            r = noise + size * p @ rng.normal(size=(3, 3)) / 400.0
        assert F.fit_field(p, r).length_mm == _full_grid_length(p, r), case
