"""What `rrbc check-model` writes beyond the named effects (issue 36, docs/check_model.md): the uncertainty of the
linear terms it fits (`linear_uncertainty`) and the rest the named terms leave (`_rest_tables`)."""

import numpy as np
import pytest

from rrbc_core.analysis.diagnosis import Effect
from rrbc_core.analysis.scene_extension import extension_terms
from rrbc_core.errors import InputError
from rrbc_core.io.measurements import MeasurementSet
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


# ---------------------------------------------------------------------------------------------- the rest
SIGMA = 0.05  # mm per axis, the remainder's noise


def _remainder(rng, systematic):
    pts = rng.uniform(-300, 300, (200, 3))
    pts[:6] = rng.uniform(-40, 40, (6, 3)) + [200.0, 200.0, 0.0]  # six registration rows, close together
    resid = systematic(pts) + rng.normal(0, SIGMA, pts.shape)
    n = len(pts)
    mset = MeasurementSet(
        ids=tuple(f"P{i}" for i in range(n)),
        roles=tuple("both" if i < 6 else "check" for i in range(n)),
        sensor=pts,
        robot=pts + resid,
        time=np.linspace(0.0, 900.0, n),
        lines=tuple(range(2, n + 2)),
        source="remainder",
    )
    anchors = np.arange(n) < 6
    return mset, anchors


def _affine(pts):
    g = np.array([[2e-4, -1e-4, 0.0], [1e-4, 3e-4, 0.0], [0.0, 0.0, -2e-4]])
    return pts @ g.T


AFFINE = [Effect("affine", {}, 1e-6, "", magnitude_mm=0.1)]


@pytest.mark.parametrize("seed", range(4))
def test_a_rest_the_named_terms_leave_is_written_as_a_field(seed):
    """An affine named, and beside it a bump of 0.2-0.4 mm at the registration rows (seeded size and direction) that
    no named effect holds: the rest is written (a field through it with its uncertainty), and the field gives back
    the bump at those rows within a third."""
    rng = np.random.default_rng(seed)
    size = rng.uniform(0.2, 0.4)  # 4-8 times the noise per axis
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    centre = np.array([200.0, 200.0, 0.0])

    def bump(p):
        return _affine(p) + size * direction * np.exp(-np.sum((p - centre) ** 2, axis=1) / (2 * 60.0**2))[:, None]

    mset, anchors = _remainder(rng, bump)
    added, _ = extension_terms(AFFINE, mset, noise_var=SIGMA**2, alpha=0.01, anchors=anchors)
    rest = [t for t in added if t.effect == "remainder"]
    assert [t.table["type"] for t in rest][:2] == ["sampled_field", "field_uncertainty"], [t.table for t in added]
    field = rest[0].term.field(mset.sensor[:6])
    want = size * direction * np.exp(-np.sum((mset.sensor[:6] - centre) ** 2, axis=1) / (2 * 60.0**2))[:, None]
    # the field is relative to a rigid motion (the registration takes that): compare what is not rigid
    from rrbc_core.analysis.scene_extension import _rigid_free

    miss = _rigid_free(mset.sensor[:6], field - want)
    assert np.sqrt(np.mean(np.sum(miss**2, axis=1))) < np.sqrt(np.mean(np.sum(want**2, axis=1))) / 3


def test_no_rest_is_written_where_the_named_terms_hold_everything():
    """The affine is the whole systematic part: over 40 seeded remainders at alpha 0.01 the rest is written at most
    as often as two tests at alpha / 2 allow (binomial 99.9 % quantile of 40 at 0.01: 3)."""
    written = 0
    for seed in range(40):
        mset, anchors = _remainder(np.random.default_rng(100 + seed), _affine)
        added, _ = extension_terms(AFFINE, mset, noise_var=SIGMA**2, alpha=0.01, anchors=anchors)
        written += any(t.effect == "remainder" for t in added)
        assert "linear_uncertainty" in [t.table["type"] for t in added]
    assert written <= 3, written
