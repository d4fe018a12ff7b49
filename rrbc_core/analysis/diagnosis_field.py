"""The smooth field as a model, not only a test (`rrbc diagnose`, docs/theory.md §6.4): once Moran's I has found a
field, everything else is judged on what remains beside it.

Model. The residuals after the accepted low-order terms, r_a (N,) per robot axis a (mm), are a zero-mean Gaussian
process plus noise: r_a ~ N(0, v_a K + σ² I), K_ij = exp(−|p_i − p_j|² / 2ℓ²) at the mapped points p (mm), with
one length ℓ, one field variance v_a = λ_a σ² per axis and one isotropic noise variance σ². `fit_field` finds them
by maximum likelihood (ℓ on a grid searched coarse to fine, λ_a by coordinate search, σ² profiled out), with K's eigendecomposition
K = U diag(D) Uᵀ so that every quantity below is a diagonal operation in that basis.

Uses:
- `gls_whiten`: the generalised least-squares whitening (v_a K + σ² I)^−½ of design columns and data, so that the
  nested F-tests of scale, affine, drift and kinematic terms can be repeated with the field as part of the error:
  a field's own linear part is not a separate effect;
- `krige_outliers`: a point the first outlier pass flagged is kept as an outlier only if its residual is far
  from what the field predicts there from the other points (χ² with 3 dof of the standardised prediction error);
- `noise_beside_field`: the noise covariance from the smoother's residuals e_a = (I − S_a) r_a, S_a = λ_a K
  (λ_a K + I)⁻¹, with the field's expected leakage removed, and a parametric bootstrap of the sphericity
  statistic under the fitted null (the same field, isotropic noise): anisotropy is claimed only beyond what the
  field's own unevenness over the axes produces.

At most `MAX_POINTS` points enter the model (a seeded subsample beyond): the work is O(MAX_POINTS³) at most.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from scipy import special  # the χ² tail as scipy.stats computes it, without its import

MAX_POINTS = 500
_LAMBDAS = np.concatenate([[0.0], np.geomspace(1e-3, 1e5, 49)])
_NOISE_BOOTSTRAP = 999


@dataclass(frozen=True, eq=False)
class FieldModel:
    """A fitted field: `points` (M, 3) mm, `length_mm`, `lam` (3,) field-to-noise variance ratios per axis,
    `sigma2` the noise variance (mm²), `u`, `d` the eigendecomposition of K at the points, `z` (M, 3) the residuals
    in that basis (Uᵀ r), `index` (M,) which of the caller's points were used."""

    points: np.ndarray
    length_mm: float
    lam: np.ndarray
    sigma2: float
    u: np.ndarray
    d: np.ndarray
    z: np.ndarray
    index: np.ndarray


def _subsample(n: int, seed: int = 0) -> np.ndarray:
    if n <= MAX_POINTS:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, MAX_POINTS, replace=False))


def _nll(z2: np.ndarray, d: np.ndarray, lam: np.ndarray) -> tuple[float, float]:
    """Profile negative log likelihood (up to constants) and σ̂² for ratios lam (3,)."""
    m = len(d)
    den = lam[None, :] * d[:, None] + 1.0  # (M, 3)
    s2 = float(np.sum(z2 / den)) / (3 * m)
    if s2 <= 0:
        return np.inf, 0.0
    return 3 * m * np.log(s2) + float(np.sum(np.log(den))), s2


def _ratios(z2: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The field-to-noise ratios lam (3,) on the grid _LAMBDAS minimising `_nll` by coordinate search (three rounds
    over the axes, from 1). `_nll` is a sum over the axes of Σ_m z2/(λ d + 1) (inside the log) and Σ_m log(λ d + 1):
    both are tabulated once per axis over the grid (T, 3) and (T,), so each step is a look-up."""
    m = len(d)
    den = _LAMBDAS[:, None] * d[None, :] + 1.0  # (T, M)
    s_tab = (1.0 / den) @ z2  # (T, 3): Σ_m z2[m, a] / (λ_t d_m + 1)
    l_tab = np.sum(np.log(den), axis=1)  # (T,)
    lam = np.ones(3)
    at: list[int | None] = [None, None, None]  # each axis's grid index (None: its start value 1)

    def parts(a: int) -> tuple[float, float]:
        if at[a] is not None:
            return float(s_tab[at[a], a]), float(l_tab[at[a]])
        return float(np.sum(z2[:, a] / (lam[a] * d + 1.0))), float(np.sum(np.log(lam[a] * d + 1.0)))

    for _ in range(3):
        for a in range(3):
            fixed = [parts(b) for b in range(3) if b != a]
            s2 = (s_tab[:, a] + sum(f[0] for f in fixed)) / (3 * m)
            with np.errstate(divide="ignore", invalid="ignore"):
                nll = np.where(s2 > 0, 3 * m * np.log(s2) + l_tab + sum(f[1] for f in fixed), np.inf)
            at[a] = int(np.argmin(nll))
            lam[a] = _LAMBDAS[at[a]]
    return lam


_EIGS_LOCK = threading.Lock()
_EIGS: OrderedDict[bytes, _Kernels] = OrderedDict()  # the points' bytes -> their kernels' eigendecompositions
_EIGS_KEPT = 2  # point sets kept (at most 18 x 2 MB each at MAX_POINTS)
N_LENGTHS = 18  # the grid of length scales ℓ (geometric, from half the points' spacing to three times their extent)
_COARSE = 3  # the search first tries every third length of the grid (and the last), then the best one's neighbours


class _Kernels:
    """The grid of length scales for points p (M, 3) mm and K's eigendecomposition at each, made when first asked
    for (`at`) and kept: they depend on the points alone."""

    def __init__(self, p: np.ndarray):
        eye = np.eye(len(p), dtype=bool)
        self.d2 = np.sum((p[:, None] - p[None]) ** 2, axis=-1)
        nn = float(np.sqrt(np.median(np.min(np.where(eye, np.inf, self.d2), axis=1))))
        ext = float(np.sqrt(self.d2.max())) or 1.0
        self.lengths = np.geomspace(max(nn, 1e-6) * 0.5, max(ext, nn) * 3.0, N_LENGTHS)
        self._eigs: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._lock = threading.Lock()

    def at(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """(D clipped at 0, U) of K at the i-th length scale; computed once, read-only (shared by every model)."""
        with self._lock:
            if i not in self._eigs:
                d, u = np.linalg.eigh(np.exp(-self.d2 / (2 * self.lengths[i] ** 2)))
                d = np.clip(d, 0.0, None)
                d.flags.writeable = u.flags.writeable = False
                self._eigs[i] = (d, u)
            return self._eigs[i]


def _kernels(p: np.ndarray) -> _Kernels:
    """The kernels of points p (M, 3) mm. A diagnosis fits the field several times on the same points with other
    residuals (the accepted terms change, the arm is judged beside it): the decompositions, which depend on the
    points alone, are made once (the last `_EIGS_KEPT` point sets are kept); the results are the same as computing
    them again."""
    key = p.tobytes()
    with _EIGS_LOCK:
        if key in _EIGS:
            _EIGS.move_to_end(key)
            return _EIGS[key]
    kernels = _Kernels(p)
    with _EIGS_LOCK:
        kernels = _EIGS.setdefault(key, kernels)
        while len(_EIGS) > _EIGS_KEPT:
            _EIGS.popitem(last=False)
    return kernels


def _length_search(nll_at) -> int:
    """The index on the grid of N_LENGTHS length scales where `nll_at(i)` is least (the lowest index among equals),
    evaluated at every _COARSE-th index and the last, then at the best one's neighbours up to the coarse points beside
    it: the grid's minimum wherever the likelihood has one minimum over the grid (on every file tried, a single
    valley), at about 11 eigendecompositions of K instead of 18."""
    seen: dict[int, float] = {}
    for i in sorted({*range(0, N_LENGTHS, _COARSE), N_LENGTHS - 1}):
        seen[i] = nll_at(i)
    best = min(seen, key=lambda i: (seen[i], i))
    for i in range(max(0, best - _COARSE + 1), min(N_LENGTHS, best + _COARSE)):
        if i not in seen:
            seen[i] = nll_at(i)
    return min(seen, key=lambda i: (seen[i], i))


def fit_field(points: np.ndarray, residuals: np.ndarray) -> FieldModel:
    """Maximum-likelihood field at points (N, 3) mm for residuals (N, 3) mm (module docstring)."""
    idx = _subsample(len(points))
    p, r = np.ascontiguousarray(np.asarray(points, float)[idx]), np.asarray(residuals, float)[idx]
    kernels = _kernels(p)
    fits: dict[int, tuple] = {}

    def nll_at(i: int) -> float:
        d, u = kernels.at(i)
        z = u.T @ r
        z2 = z**2
        lam = _ratios(z2, d)
        nll, s2 = _nll(z2, d, lam)
        fits[i] = (lam, s2, u, d, z)
        return nll

    best = _length_search(nll_at)
    lam, s2, u, d, z = fits[best]
    return FieldModel(p, float(kernels.lengths[best]), lam, float(s2), u, d, z, idx)


def gls_whiten(model: FieldModel, cols: np.ndarray, at_points: bool = False) -> np.ndarray:
    """Whiten (3N, k) point-major columns (or a (3N,) vector) by (v_a K + σ² I)^−½ per axis, on the model's
    points: returns (3M, k) (or (3M,)), M = len(model.index). `at_points`: cols hold only the model's points' rows
    (3M, k), in the order of model.index."""
    vec = cols.ndim == 1
    c = cols.reshape(-1, 3, 1) if vec else cols.reshape(-1, 3, cols.shape[1])
    if not at_points:
        c = c[model.index]
    out = np.empty_like(c)
    for a in range(3):
        scale = 1.0 / np.sqrt(model.lam[a] * model.d + 1.0)
        out[:, a, :] = model.u @ (scale[:, None] * (model.u.T @ c[:, a, :]))
    out = out.reshape(-1, out.shape[-1])
    return out[:, 0] if vec else out


def krige_outliers(
    model: FieldModel, candidates: np.ndarray, residuals: np.ndarray, n_tested: int, alpha: float
) -> np.ndarray:
    """Which candidate points (C, 3) mm with residuals (C, 3) mm are outliers beside the field: the error of the
    field's prediction from the model's points, standardised by its variance, χ²(3), Bonferroni over n_tested.
    Returns a boolean (C,)."""
    cand = np.asarray(candidates, float).reshape(-1, 3)
    if len(cand) == 0:
        return np.zeros(0, bool)
    d2 = np.sum((cand[:, None] - model.points[None]) ** 2, axis=-1)
    kt = np.exp(-d2 / (2 * model.length_mm**2)) @ model.u  # (C, M) in the eigenbasis
    z2 = np.zeros(len(cand))
    for a in range(3):
        lam = model.lam[a]
        den = lam * model.d + 1.0
        mean = lam * (kt / den) @ model.z[:, a]
        var = model.sigma2 * (1.0 + lam - lam * lam * np.sum(kt**2 / den, axis=1))
        z2 += (np.asarray(residuals, float)[:, a] - mean) ** 2 / np.maximum(var, 1e-300)
    p = np.minimum(1.0, special.chdtrc(3, z2) * n_tested)
    return p < alpha


def _beside(z: np.ndarray, d: np.ndarray, lam: np.ndarray, sigma2: float):
    """Noise covariance estimates (..., 3, 3) from eigenbasis residuals z (..., M, 3) (module docstring)."""
    inv = 1.0 / (lam[None, :] * d[:, None] + 1.0)  # (M, 3)
    e = z * inv
    raw = np.einsum("...ma,...mb->...ab", e, e)
    leak = lam * sigma2 * np.sum(d[:, None] * inv**2, axis=0)  # (3,)
    den = np.einsum("ma,mb->ab", inv, inv)
    return (raw - np.diag(leak)) / den, float(np.mean(np.diag(den)))


def _spher_stat(cov: np.ndarray) -> np.ndarray:
    ev = np.linalg.eigvalsh(cov)
    ev = np.clip(ev, 1e-12 * np.maximum(ev[..., -1:], 1e-300), None)
    return 3 * np.log(np.mean(ev, axis=-1)) - np.sum(np.log(ev), axis=-1)


def noise_beside_field(model: FieldModel, rng: np.random.Generator) -> tuple[np.ndarray, float, float]:
    """(noise covariance (3, 3) mm², its effective degrees of freedom, bootstrap p-value of sphericity) with the
    field's leakage removed (module docstring)."""
    cov, nu = _beside(model.z, model.d, model.lam, model.sigma2)
    stat = float(_spher_stat(cov))
    sd = np.sqrt(model.sigma2 * (model.lam[None, :] * model.d[:, None] + 1.0))  # (M, 3)
    exceed = 0
    for start in range(0, _NOISE_BOOTSTRAP, 100):
        b = min(100, _NOISE_BOOTSTRAP - start)
        zb = rng.standard_normal((b,) + sd.shape) * sd
        exceed += int(np.sum(_spher_stat(_beside(zb, model.d, model.lam, model.sigma2)[0]) >= stat))
    return cov, nu, (1 + exceed) / (_NOISE_BOOTSTRAP + 1)
