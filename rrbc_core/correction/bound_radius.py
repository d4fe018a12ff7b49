"""The radius and region holding 95 % of a normal 3-D error: `bound95` (a scaled χ² matched in mean and variance to
the covariance's eigenvalues' χ²₁ terms, exact for an isotropic error) and `bound_ellipsoids` (the region's axes and
semi-axes, as the app draws it). docs/uncertainty.md; the bounds themselves are `correction.bounds`'s.
Units mm (covariances mm²).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.special import chdtri  # χ² quantiles as scipy.stats.chi2.ppf computes them, without its import

#: the bound's probability
LEVEL = 0.95


def bound95(cov: np.ndarray, level: float = LEVEL) -> np.ndarray:
    """(M,): the radius r with P(|e| ≤ r) = level for e ~ N(0, cov), cov (M, 3, 3) mm² (module docstring). The
    eigenvalues' sum and sum of squares are the trace and the squared Frobenius norm of the (symmetric) covariance;
    the χ² quantile at the matched degrees of freedom (between 1 and 3) is `chi2_quantile`'s."""
    c = np.asarray(cov, float).reshape(-1, 3, 3)
    s1 = np.trace(c, axis1=1, axis2=2)
    s2 = np.einsum("mij,mij->m", c, c)
    ok = (s1 > 0) & (s2 > 0)
    out = np.zeros(len(c))
    scale = s2[ok] / s1[ok]
    dof = s1[ok] ** 2 / s2[ok]
    out[ok] = np.sqrt(scale * chi2_quantile(dof, level))
    return out


@functools.cache
def _quantile_curve(level: float):
    from scipy.interpolate import CubicSpline

    nu = np.linspace(1.0, 3.0, 401)
    return CubicSpline(nu, chdtri(nu, 1.0 - level))


def chi2_quantile(dof: np.ndarray, level: float = LEVEL) -> np.ndarray:
    """χ²'s `level` quantile at degrees of freedom dof (M,) in [1, 3] (clipped there): a cubic spline through 401
    of scipy's quantiles, within 1e-10 of them relatively (tests/correction/test_bounds.py), at a thousandth of
    their cost for many points."""
    return np.asarray(_quantile_curve(float(level))(np.clip(np.asarray(dof, float), 1.0, 3.0)), float)


def bound_ellipsoids(cov: np.ndarray, level: float = LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """The `level` region of a normal error with covariance cov (M, 3, 3) mm², as ellipsoids: their axes' rotation
    (M, 3, 3; columns the axes, a proper rotation) and semi-axes (M, 3) mm, sqrt(λ χ²₃(level)) along eigenvector
    λ. For an isotropic error it is the sphere of radius `bound95` (level 0.95). Rows with a NaN covariance give
    NaN semi-axes (no bound: nothing to draw)."""
    c = np.asarray(cov, float).reshape(-1, 3, 3)
    ok = np.all(np.isfinite(c), axis=(1, 2))
    lam = np.full((len(c), 3), np.nan)
    rot = np.broadcast_to(np.eye(3), (len(c), 3, 3)).copy()
    if np.any(ok):
        w, v = np.linalg.eigh(c[ok])
        v[np.linalg.det(v) < 0, :, 2] *= -1  # a proper rotation
        lam[ok], rot[ok] = np.clip(w, 0.0, None), v
    return rot, np.sqrt(lam * chdtri(3.0, 1.0 - level))
