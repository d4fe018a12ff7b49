"""What `rrbc check-model` writes beyond the named effects (issue 36, docs/check_model.md): the uncertainty of the
linear terms it fits (`linear_uncertainty`)."""

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.models.errormodels import PointSet
from rrbc_core.models.errorterms import error_model_from_dict, error_model_to_dict
from rrbc_core.models.fieldterms import LinearUncertainty


def _points(rng, n=300):
    pts = rng.uniform(-300, 300, (n, 3))
    time = np.sort(rng.uniform(0, 900, n))
    return PointSet(pts, pts, time)


def _term(basis="position_time", var=(0.01, 0.02, 0.005)):
    rng = np.random.default_rng(0)
    x = rng.uniform(-300, 300, (50, 3))
    t = rng.uniform(0, 900, 50)
    cols = [np.ones((50, 1))]
    if basis != "time":
        cols.append(x)
    if basis != "position":
        cols.append(t[:, None] - 450.0)
    design = np.hstack(cols)
    return LinearUncertainty(basis, (0.0, 0.0, 0.0), 450.0, np.linalg.inv(design.T @ design).tolist(), var)


@pytest.mark.parametrize("basis", ["position", "time", "position_time"])
def test_linear_uncertainty_draws_have_the_fits_covariance(basis):
    """Each point's drawn variance per axis equals φᵀ (var · (ΦᵀΦ)⁻¹) φ: within 5 standard errors of a sample
    variance of T draws (√(2/T) relative), and one draw is shared by the points (the draws are linear in φ)."""
    term = _term(basis)
    pts = _points(np.random.default_rng(1), 40)
    trials = 4000
    draws = term.sample(pts, "robot", np.random.default_rng(2), trials)
    assert draws.shape == (trials, 40, 3)
    want = np.diagonal(term.covariance(pts), axis1=1, axis2=2)
    got = np.var(draws, axis=0)
    assert np.all(np.abs(got / want - 1) < 5 * np.sqrt(2 / trials)), np.max(np.abs(got / want - 1))
    # a linear function of the columns: a draw at a point is a combination of the draws at the first k points
    phi = term.design(pts, "robot")
    k = phi.shape[1]
    combo = np.linalg.lstsq(phi[:k].T, phi[k].T, rcond=None)[0]
    assert np.allclose(draws[:, k], np.einsum("j,tja->ta", combo, draws[:, :k]), atol=1e-9)


def test_linear_uncertainty_reads_and_writes_as_a_table():
    term = _term()
    table = error_model_to_dict(error_model_from_dict({"robot": [{"type": "linear_uncertainty", **_table(term)}]}))
    again = error_model_from_dict(table).robot[0]
    assert again == term


def _table(term):
    return {
        "basis": term.basis,
        "center_mm": list(term.center_mm),
        "t0_s": term.t0_s,
        "design_inverse": [list(r) for r in term.design_inverse],
        "var_mm2": list(term.var_mm2),
    }


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"basis": "space"}, "basis must be one of"),
        ({"design_inverse": [[1.0]]}, "5x5"),
        ({"design_inverse": (np.eye(5) + np.diag([1.0] * 4, 1)).tolist()}, "symmetric"),
        ({"design_inverse": (-np.eye(5)).tolist()}, "positive semi-definite"),
        ({"var_mm2": [0.1, -0.1, 0.1]}, "var_mm2"),
        ({"design_inverse": [[float("nan")] * 5] * 5}, "finite"),
    ],
)
def test_a_bad_linear_uncertainty_is_refused_with_its_reason(change, words):
    table = {"type": "linear_uncertainty", **_table(_term()), **change}
    with pytest.raises(InputError, match=words):
        error_model_from_dict({"robot": [table]})


def _covs(rng, n):
    """n random SPD covariances (mm²), eigenvalues 0.05-1 mm², random axes."""
    from scipy.spatial.transform import Rotation

    rot = Rotation.random(n, random_state=rng).as_matrix()
    lam = rng.uniform(0.05, 1.0, (n, 3))
    return np.einsum("nij,nj,nkj->nik", rot, lam, rot)


def _draw(rng, cov):
    return np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((len(cov), 3)))


@pytest.mark.parametrize("seed", range(4))
def test_the_missing_spread_is_sized_within_its_standard_error_and_restores_coverage(seed):
    """Rows that scatter as N(0, Cᵢ + s²I) about the extended model's means: the missing s² is found within 4 of the
    estimator's delta-method standard errors (mean z² has variance 6/n at the truth), and fresh rows of the same law
    fall inside their widened 95 % regions at 95 % within the binomial's 4 standard errors."""
    from scipy import stats

    from rrbc_core.analysis.scene_extension import spread_effect

    rng = np.random.default_rng([seed, 36])
    n = 400
    cov = _covs(rng, n)
    s2 = rng.uniform(0.25, 2.0)
    eff = spread_effect(_draw(rng, cov + s2 * np.eye(3)), cov, alpha=0.01)
    assert eff is not None and eff.name == "isotropic_noise"
    est = eff.parameters["sigma_mm"] ** 2
    lam = np.linalg.eigvalsh(cov)
    slope = np.mean(np.sum(1.0 / (lam + est), axis=1))  # |d E[mean z²] / d s²| at the estimate (E proj² = λ + s²)
    assert abs(est - s2) < 4 * np.sqrt(6.0 / n) / slope, (est, s2)
    fresh = _draw(rng, cov + s2 * np.eye(3))
    z2 = np.einsum("ni,nij,nj->n", fresh, np.linalg.inv(cov + est * np.eye(3)), fresh)
    inside = np.mean(z2 <= stats.chi2.ppf(0.95, 3))
    assert abs(inside - 0.95) < 4 * np.sqrt(0.95 * 0.05 / n) + 0.02, inside  # + the estimate's own error


def test_no_spread_is_added_where_the_model_predicts_it_more_often_than_alpha():
    """Rows drawn from the predicted covariances themselves: Σz² is χ²(3n) exactly, so the test rejects in a share
    alpha of files; 300 files at alpha 0.05 lie within the binomial's 99.9 % range."""
    from scipy import stats

    from rrbc_core.analysis.scene_extension import spread_effect

    rng = np.random.default_rng(3636)
    hits = 0
    for _ in range(300):
        cov = _covs(rng, 60)
        hits += spread_effect(_draw(rng, cov), cov, alpha=0.05) is not None
    lo, hi = stats.binom.ppf([0.0005, 0.9995], 300, 0.05)
    assert lo <= hits <= hi, hits


def test_the_spread_is_added_in_quadrature_to_the_noise_already_written():
    from rrbc_core.analysis.diagnosis import Effect
    from rrbc_core.analysis.scene_extension import AddedTerm, with_spread

    table = {"type": "isotropic_noise", "sigma_mm": 0.3}
    noise = error_model_from_dict({"robot": [table]}, "test").robot[0]
    out = with_spread(
        [AddedTerm("isotropic_noise", table, "", noise)], Effect("isotropic_noise", {"sigma_mm": 0.4}, 0.0, "")
    )
    assert [a.table["type"] for a in out] == ["isotropic_noise"]
    assert out[0].table["sigma_mm"] == pytest.approx(0.5)
