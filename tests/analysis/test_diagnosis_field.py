"""The field model's kernel eigendecompositions are made once per point set (`diagnosis_field._kernel_eigs`): a
diagnosis fits the field several times on the same points; what it finds is the same as computing them afresh."""

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
