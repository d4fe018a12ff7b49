"""Whether the scored points show RRBC's change (`correction.check_statistics.gain_test`): the one decision behind
rrbc diagnose's recommendation and the app's headline colour. Its level is checked by simulation: with no change in
expectation a gain is shown in about alpha of the draws (binomial bound), and a real change is shown."""

from __future__ import annotations

import numpy as np
from scipy.stats import binom

from rrbc_core.correction.check_statistics import gain_from_differences, gain_test


def _errors(rng, n: int, gain: float):
    """3-D error norms of n points, rigid and RRBC; RRBC's mean squared error (1 - gain) times rigid's."""
    rigid = np.linalg.norm(rng.normal(0.0, 1.0, (n, 3)), axis=1)
    rrbc = np.linalg.norm(rng.normal(0.0, np.sqrt(1.0 - gain), (n, 3)), axis=1)
    return rigid, rrbc


def test_no_change_is_shown_about_alpha_of_the_time_and_a_real_gain_is_shown():
    rng = np.random.default_rng(7)
    trials, alpha = 2000, 0.05
    shown = sum(gain_test(*_errors(rng, 30, 0.0), alpha).verdict == "gain" for _ in range(trials))
    # the t-test's level on chi-square differences: within a binomial 0.999 interval of alpha (or below it)
    assert shown <= binom.ppf(0.999, trials, alpha), shown
    strong = sum(gain_test(*_errors(rng, 30, 0.5), alpha).verdict == "gain" for _ in range(200))
    # a halved mean squared error over 30 points is shown with power above 0.8 (binomial 0.001 bound)
    assert strong >= binom.ppf(0.001, 200, 0.8), strong


def test_a_few_percent_over_few_points_is_unclear_and_said_so():
    rng = np.random.default_rng(3)
    rigid = rng.uniform(5.0, 15.0, 20)
    rrbc = rigid * rng.uniform(0.7, 1.26, 20)  # a few % on average, spread widely both ways
    g = gain_test(rigid, rrbc)
    assert g.change < 0 and g.verdict == "unclear"
    assert "do not show the change at the 0.05 level" in g.words()
    assert gain_test(rigid, rigid * 0.5).verdict == "gain" and gain_test(rigid, rigid * 2).verdict == "loss"


def test_degenerate_inputs_decide_without_a_test():
    assert gain_test([1.0, 2.0], [0.5, 1.0]).verdict == "unclear"  # too few points
    assert gain_test([1.0, 1.0, 1.0], [0.5, 0.5, 0.5]).verdict == "gain"  # the same gain at every point
    assert gain_test([1.0, np.nan, 1.0, 1.0], [1.0, 0.2, 1.0, 1.0]).verdict == "unclear"  # NaN pair left out
    pooled = gain_from_differences(np.concatenate([np.full(5, 1.0), np.full(5, 1.2)]), -0.3)
    assert pooled.verdict == "gain" and pooled.n == 10


def test_the_t_tails_are_scipys_one_sample_t_test():
    """`gain_from_differences` computes the one-sided paired t-test itself (it runs on every drag update): the same
    p-values as scipy.stats.ttest_1samp each way, over seeded samples of many sizes and signs."""
    import numpy as np
    from scipy.stats import ttest_1samp

    from rrbc_core.correction.check_statistics import gain_from_differences

    rng = np.random.default_rng(17)
    for _ in range(200):
        d = rng.normal(rng.normal(0, 1), rng.uniform(0.05, 3), int(rng.integers(3, 400)))
        g = gain_from_differences(d, 0.0)
        assert np.isclose(g.p_gain, ttest_1samp(d, 0.0, alternative="greater").pvalue, rtol=1e-9, atol=1e-300)
        assert np.isclose(g.p_loss, ttest_1samp(d, 0.0, alternative="less").pvalue, rtol=1e-9, atol=1e-300)
