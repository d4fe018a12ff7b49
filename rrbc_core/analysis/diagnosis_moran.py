"""Moran's I of a residual field (vector form, k-nearest-neighbour weights) and its null distribution under white
noise with a model's columns projected out: exact moments (`moran_null`) and a parametric bootstrap
(`moran_bootstrap`). docs/theory.md §6.1. Positions mm, residuals whitened."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from rrbc_core.runtime.threads import query_workers

BOOTSTRAP = 1999  # parametric bootstrap replicates for Moran's I
# Above this many points the bootstrap's cost (replicates x N) would dominate: Moran's I is then a sum of N*k
# locally dependent terms, close to normal, so the p-value is the normal tail with its exact null mean and spread
# (`moran_null`, docs/theory.md §6.1). Below it the empirical tail of 1999 replicates is used.
BOOTSTRAP_EXACT_POINTS = 20_000

KNN = 6  # neighbours in Moran's I weights

BOOTSTRAP_CHUNK_ELEMENTS = 1 << 20  # bootstrap draws held at once (8 MiB): memory stays linear in N


# ---------------------------------------------------------------------------------------------- Moran's I
def moran_weights(p: np.ndarray):
    """Indices (N, k) of each point's k nearest other points (k = min(KNN, N - 1))."""
    return neighbours(p)[0]


def neighbours(p: np.ndarray) -> tuple[np.ndarray, float]:
    """`moran_weights` of p (N, 3) and the points' typical spacing from the same search: the median distance (mm)
    to the nearest other point (what `diagnosis_arm.short_field` compares a field's length with)."""
    k = min(KNN, len(p) - 1)
    dist, nb = cKDTree(p).query(p, k=k + 1, workers=query_workers(len(p)))
    return nb[:, 1:], float(np.median(dist[:, 1]))


def _weights(nb: np.ndarray):
    """The k-NN weights as a sparse (N, N) matrix, k ones per row."""
    from scipy.sparse import csr_matrix

    n, k = nb.shape
    return csr_matrix((np.ones(n * k), nb.reshape(-1), np.arange(0, n * k + 1, k)), shape=(n, n))


def _moran_sparse(res: np.ndarray, w, k: int) -> np.ndarray:
    """Moran's I of res (..., N, 3) with the sparse weights w (k per row)."""
    n = w.shape[0]
    lead = res.shape[:-2]
    r = res.reshape(-1, n, 3)
    x = np.moveaxis(r, 1, 0).reshape(n, -1)  # (N, B*3)
    num = np.einsum("nb,nb->b", x, w @ x).reshape(-1, 3).sum(axis=1)
    den = np.einsum("bic,bic->b", r, r)
    return (num / (k * den)).reshape(lead)


def moran(res: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """Vector Moran's I with k-NN weights: res (..., N, 3) -> (...).

    I = (1/k) Σ_i Σ_{j ∈ nb(i)} r_i·r_j / Σ_i |r_i|², the neighbour sums taken with a sparse (N, N) weight
    matrix (k non-zeros per row), so memory is O(N·k) per residual field, not a gathered (..., N, k, 3) array."""
    return _moran_sparse(res, _weights(nb), nb.shape[1])


def moran_null(qa: np.ndarray, nb: np.ndarray) -> tuple[float, float]:
    """The exact mean and standard deviation of Moran's I (`moran`, weights nb (N, k)) of white-noise residual fields
    with the model's columns (orthonormal qa, (3N, q)) projected out: what `moran_bootstrap` estimates by drawing.

    With M = I - qa qaᵀ (rank m = 3N - q) and S the symmetric part of the weights acting on each coordinate, kI =
    εᵀMSMε / εᵀMε for white ε; the ratio is independent of its denominator (ε's direction in M's span is uniform
    whatever its length), so E[kI] = tr(MS)/m and E[(kI)²] = (tr(MS)² + 2 tr(MSMS)) / (m(m + 2)), with
    tr(MS) = tr(S) - tr(qaᵀSqa) and tr(MSMS) = |S|² - 2|S qa|² + |qaᵀSqa|² (Frobenius norms). Cost O(N·k·q),
    memory one column of qa at a time."""
    n, k = nb.shape
    w = _weights(nb)
    w.sum_duplicates()
    wt = w.T  # S = (W + Wᵀ)/2 is applied as two products: no sparse copy of S (a million points: 12e6 entries)
    q = qa.shape[1]
    qb = qa.reshape(n, 3, q)
    m = 3 * n - q
    tr_s = 3.0 * float(w.diagonal().sum())
    s_f2 = 3.0 * 0.5 * (float(np.sum(w.data**2)) + float(w.multiply(wt).sum()))  # |S|² = (|W|² + Σ W_ij W_ji)/2
    qsq = np.empty((q, q))
    sq_f2 = 0.0
    for j in range(q):  # one column at a time, S applied to its (N, 3) field: memory three such fields
        col = np.ascontiguousarray(qb[:, :, j])
        sq = np.asarray(w @ col)
        sq += wt @ col
        sq *= 0.5
        sq = sq.reshape(3 * n)
        sq_f2 += float(sq @ sq)
        qsq[:, j] = qa.T @ sq
    tr_ms = tr_s - float(np.trace(qsq))
    tr_msms = s_f2 - 2.0 * sq_f2 + float(np.sum(qsq * qsq))
    mean = tr_ms / m
    second = (tr_ms**2 + 2.0 * tr_msms) / (m * (m + 2.0))
    return mean / k, float(np.sqrt(max(second - mean**2, 0.0))) / k


def moran_bootstrap(rng, qa: np.ndarray, nb: np.ndarray, replicates: int = BOOTSTRAP) -> np.ndarray:
    """Moran's I of `replicates` white-noise residual fields with the accepted model's columns (orthonormal qa,
    (3N, q)) projected out. Drawn and evaluated in chunks of BOOTSTRAP_CHUNK_ELEMENTS: memory is linear in N and
    the draws are those of one rng.standard_normal((replicates, 3N)) call (a Generator fills rows in order)."""
    n3 = qa.shape[0]
    n, k = nb.shape
    w = _weights(nb)
    qt = np.ascontiguousarray(qa.T)  # (q, 3N): the projection reads it row by row
    out = np.empty(replicates)
    step = max(1, BOOTSTRAP_CHUNK_ELEMENTS // n3)
    for start in range(0, replicates, step):
        b = min(step, replicates - start)
        eps = rng.standard_normal((b, n3))
        eps -= (eps @ qt.T) @ qt
        out[start : start + b] = _moran_sparse(eps.reshape(b, n, 3), w, k)
    return out
