"""The reproduction's orchestration: registrations per experiment, RRBC on the plate, the cause sentence."""

import numpy as np
import pytest

from rrbc_core.studies import reproduction as rp


def test_each_repetition_uses_its_own_registration_in_layout_d():
    """Layout D registers once per repetition: a perturbation of ONE registration's readings must move exactly
    the check samples of that repetition (and nothing else) for every method that uses those readings."""
    geo = rp.geometry_for(rp.layout_by_name("D"))
    pert = np.zeros((1, len(geo.slot_point), 3))
    g = 2
    pert[0, geo.reg_slots["large3"][g]] = [[0.3, -0.2, 0.1], [0.0, 0.25, -0.2], [-0.1, 0.0, 0.3]]
    err = np.linalg.norm(rp.method_errors(geo, pert), axis=-1)[0]  # (7, 80)
    moved = err > 1e-9
    m = rp.METHODS.index("Large 3-point")
    assert np.array_equal(moved[m], geo.check_reg == g)
    assert np.array_equal(moved[rp.METHODS.index("SA Large 3-point")], geo.check_reg == g)
    for other in ("Small 3-point", "Large 5-point", "Clustering"):
        assert not moved[rp.METHODS.index(other)].any(), other


def test_layout_a_uses_one_registration_for_all_80_samples():
    geo = rp.geometry_for(rp.layout_by_name("A"))
    assert geo.reg_slots["large5"].shape == (1, 5)
    assert np.all(geo.check_reg == 0)
    assert geo.check_slots.shape == (7, 80)


def test_rrbc_gain_helps_against_bias_more_than_against_noise():
    """Noise-free smooth bias (flatness field): RRBC must lower the held-out RMS error (what is left is IDW's
    interpolation error on a 250 x 175 mm grid, large at the edge sites); with noise of the same rigid RMS the
    change must be clearly less favourable, because each correction then carries a fiducial's noise."""
    geo = rp.geometry_for(rp.layout_by_name("A"))
    biased = rp.rrbc_gain(geo, rp.model_by_name("flatness"), 0.3, np.pi / 2, 40, 3)
    assert biased["change"] < -0.1
    noisy = rp.rrbc_gain(geo, rp.model_by_name("baseline"), 0.2, 0.0, 40, 3)
    assert noisy["change"] > biased["change"] + 0.1
    assert noisy["rmst_rigid_mm"] > 0.2 * np.sqrt(3) * 0.9  # the fresh reading's own noise is in the error


@pytest.mark.slow
def test_run_reports_progress_up_to_its_total_and_closes_the_bar():
    from rrbc_core.studies import vanwyk2018

    class Recorder:
        def __init__(self, total):
            self.total, self.done, self.closed = total, 0, False

        def update(self, n=1, label=None):
            self.done += n

        def close(self):
            self.closed = True

    bars = []

    def factory(total):
        bars.append(Recorder(total))
        return bars[-1]

    rep = vanwyk2018.run(replicates=6, layout_names=["A"], confusion=False, progress_factory=factory)
    assert len(bars) == 1 and bars[0].closed
    assert bars[0].done == bars[0].total == 2 * len(rp.MODELS)  # a simulation and an assessment per model
    assert rep.samples_per_method == 80


def test_the_studys_batched_clustering_is_the_registration_applied_one_by_one():
    """`reproduction._clustering_inverse` computes every registration's pieces in one batch; it must give exactly
    what `registration.clustering` gives registration by registration, also where a robot triple is collinear
    (that registration is made by `clustering` itself, without the subset)."""
    from rrbc_core import registration
    from rrbc_core.registration.strategies import clustering_sets
    from rrbc_core.studies import reproduction

    rng = np.random.default_rng(7)
    sensor = rng.uniform(-300.0, 300.0, (6, 3))
    r_count, g_count, n_query = 4, 2, 10
    readings = sensor[None, None] + rng.normal(0.0, 0.2, (r_count, g_count, 6, 3))
    readings[2, 1, 2] = 0.5 * (readings[2, 1, 1] + readings[2, 1, 3])  # a collinear robot triple here
    _, _, members = clustering_sets(sensor, 2, 3)
    assert any({1, 2, 3} <= set(m) for m in members)  # ... in a cluster's point set: that registration drops it
    sites = rng.uniform(-300.0, 300.0, (n_query, 3))
    check_reg = np.arange(n_query) % g_count
    queries = sites[None] + rng.normal(0.0, 0.5, (r_count, n_query, 3))
    got = reproduction._clustering_inverse(sensor, readings, queries, sites, check_reg, seed=3)
    for k in range(r_count):
        for g in range(g_count):
            use = check_reg == g
            mapping = registration.clustering(sensor, readings[k, g], clusters=2, seed=3).mapping
            want = mapping.apply_inverse(queries[k, use], mapping.piece_of(sites[use]))
            assert np.array_equal(got[k, use], want), (k, g)
