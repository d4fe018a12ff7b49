"""The diagnosis's design columns made when read (`diagnosis_columns.LazyColumns`): the same numbers as the columns
written whole (`Geometry._cols` of the same fields), read by any rows, and the same products, Gram matrices, fits
and bases as those arrays give."""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_core.analysis import diagnosis_columns, diagnosis_stats
from rrbc_core.analysis.diagnosis_columns import Geometry, LazyColumns, column_norms, gram, times


def _geometry(seed: int, n: int, white: bool, planar: bool = False) -> Geometry:
    rng = np.random.default_rng(seed)
    p = rng.uniform(-400, 400, (n, 3))
    if planar:
        p[:, 2] = 0.0
    w = np.array([[1.0, 0.2, 0.0], [0.0, 2.0, 0.3], [0.1, 0.0, 1.5]]) if white else None
    return Geometry(p, rng.uniform(0, 3600, n), rng.integers(1, 4, n).astype(float), w)


def _written(g: Geometry) -> dict[str, np.ndarray]:
    """The model's columns written whole from their fields, as the diagnosis wrote them before they were lazy."""
    e = np.eye(3)
    moves = [np.broadcast_to(e[k], (g.n, 3)) for k in range(3)]
    assert g.time is not None
    tt = (g.time - g.time.mean()) / g.tscale
    return {
        "translations": g._cols(moves),
        "rigid": g._cols(moves + [np.cross(e[k], g.u) for k in range(3)]),
        "linear": g._cols([np.outer(g.u[:, b], e[a]) for a in range(3) for b in range(3)]),
        "drift": g._cols([np.outer(tt, e[k]) for k in range(3)]),
    }


@pytest.mark.parametrize("white", [False, True])
@pytest.mark.parametrize("planar", [False, True])
def test_lazy_columns_read_by_any_rows_equal_the_columns_written_whole(white, planar):
    g = _geometry(3, 41, white, planar)
    rng = np.random.default_rng(4)
    for name, want in _written(g).items():
        lazy = getattr(g, name)()
        assert isinstance(lazy, LazyColumns) and lazy.shape == want.shape and len(lazy) == len(want)
        assert np.allclose(np.asarray(lazy), want, rtol=0, atol=1e-15 * np.abs(want).max()), name
        for _ in range(20):  # slices that start and end inside a point's three rows, empty ones and the whole
            a, b = sorted(rng.integers(0, len(want) + 1, 2))
            assert np.allclose(lazy[a:b], want[a:b], rtol=0, atol=1e-15 * np.abs(want).max()), (name, a, b)
        pts = rng.choice(g.n, 7, replace=False)
        rows = (3 * pts[:, None] + np.arange(3)).reshape(-1)
        assert np.allclose(lazy.at_points(pts), want[rows], rtol=0, atol=1e-15 * np.abs(want).max())
    with pytest.raises(TypeError):
        g.rigid()[np.arange(3)]


@pytest.mark.parametrize("block", [5, 8, 1 << 15])
def test_products_grams_fits_and_bases_of_lazy_columns_equal_those_of_the_arrays(block, monkeypatch):
    """Rows made `block` at a time (not whole points when 5 or 8): xᵀx, x @ a, the columns' norms, `fit`,
    `orth_basis` and `usable` on the lazy blocks beside an array block equal the same on the written arrays."""
    monkeypatch.setattr(diagnosis_columns, "ROW_BLOCK", block)
    monkeypatch.setattr(diagnosis_stats, "QR_BLOCK_ROWS", block)
    g = _geometry(9, 60, True)
    arrays = _written(g)
    rng = np.random.default_rng(10)
    extra = rng.normal(size=(3 * g.n, 2))
    lazy = (g.rigid(), g.linear(), extra)
    flat = np.hstack([arrays["rigid"], arrays["linear"], extra])
    tol = 1e-10 * np.abs(flat).max() ** 2
    assert np.allclose(gram(list(lazy)), flat.T @ flat, rtol=0, atol=tol)
    a = rng.normal(size=(flat.shape[1], 3))
    assert np.allclose(times(lazy, a), flat @ a, rtol=0, atol=1e-10 * np.abs(flat @ a).max())
    assert np.allclose(times(g.rigid(), a[:6]), arrays["rigid"] @ a[:6], rtol=0, atol=1e-10)
    assert np.allclose(column_norms(list(lazy)), np.linalg.norm(flat, axis=0), rtol=1e-12, atol=0)
    y = flat @ rng.normal(size=flat.shape[1]) + rng.normal(size=3 * g.n)
    c_lazy, r_lazy, rss_lazy, k_lazy = diagnosis_stats.fit(y, lazy)
    c_flat, r_flat, rss_flat, k_flat = diagnosis_stats.fit(y, flat)
    assert k_lazy == k_flat == 14  # 6 + 9 + 2 less the three rotations inside the linear map
    assert np.isclose(rss_lazy, rss_flat, rtol=1e-9) and np.allclose(r_lazy, r_flat, rtol=0, atol=1e-9)
    assert np.allclose(flat @ c_lazy, flat @ c_flat, rtol=0, atol=1e-8)  # the fit (coefficients: a null space)
    q_lazy, to_q = diagnosis_stats.orth_basis(lazy)
    q_flat = diagnosis_stats.orth_basis(flat)[0]
    assert q_lazy.shape == q_flat.shape
    assert np.allclose(q_lazy @ q_lazy.T, q_flat @ q_flat.T, rtol=0, atol=1e-10)  # the same span, projected
    assert np.allclose(times(lazy, to_q), q_lazy, rtol=0, atol=1e-10)
    u_lazy, frac_lazy, _ = diagnosis_stats.usable(g.rigid(), g.drift())
    u_flat, frac_flat, _ = diagnosis_stats.usable(arrays["rigid"], arrays["drift"])
    assert np.allclose(frac_lazy, frac_flat, rtol=0, atol=1e-10)
    assert np.allclose(u_lazy @ np.linalg.pinv(u_lazy), u_flat @ np.linalg.pinv(u_flat), rtol=0, atol=1e-9)
