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
