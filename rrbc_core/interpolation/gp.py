"""Gaussian-process interpolation (`GP`, universal kriging): a linear mean by generalised least squares, a
Matérn 5/2 or squared-exponential kernel and a white-noise term, hyper-parameters by restricted likelihood; it
reports the predictive standard deviation."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.interpolation.base import (
    CHUNK_ELEMENTS,
    Fitted,
    FittedInterpolator,
    Hull,
    check_data,
    check_float,
    dim_words,
    too_few,
)
from rrbc_core.option_specs import check_options, option
from rrbc_core.runtime.threads import thread_limited

# ---------------------------------------------------------------------------------------------------------------
# Gaussian process with a linear mean (universal kriging)

_GP_KERNELS = ("matern52", "se")
_GP_ELL_BOUNDS = (0.05, 20.0)  # length scale, local units (RMS fiducial distance from centroid = 1)
_GP_G_BOUNDS = (1e-8, 1e2)  # g = noise variance / signal variance
_GP_ELL_STARTS = (0.1, 0.3, 1.0, 3.0, 10.0)
_GP_G_STARTS = (1e-6, 1e-3, 1e-1)
_GP_REFINE = 3  # number of best grid starts refined by L-BFGS-B
_GP_FIXED_JITTER = 1e-8  # added to g when the noise is fixed by the user (keeps the Cholesky well posed)
FIT_SUBSAMPLE = 300  # the hyper-parameters are fitted on at most this many fiducials (issue 41)
_GP_FLOOR_REL = 1e-9  # residual RMS below this fraction of the correction size counts as zero (clean data)


def _corr(dist: np.ndarray, ell: float, kernel: str) -> tuple[np.ndarray, np.ndarray]:
    """Correlation k(r) for unit signal variance and its derivative with respect to log(ell)."""
    if kernel == "matern52":
        s = np.sqrt(5.0) * dist / ell
        e = np.exp(-s)
        k = (1.0 + s + s * s / 3.0) * e
        dk = (s * s / 3.0) * (1.0 + s) * e
    else:
        u = (dist / ell) ** 2
        k = np.exp(-0.5 * u)
        dk = u * k
    return k, dk


def _design(x: np.ndarray) -> np.ndarray:
    return np.hstack([np.ones((len(x), 1)), x])


def _neg_reml(c: np.ndarray, dcs: list[np.ndarray], f: np.ndarray, y: np.ndarray, s2_fixed: float | None, floor: float):
    """Negative restricted log-likelihood (up to a constant) of Y (N x 3) ~ N(F beta_c, s2_c C), and gradient.

    s2_fixed None: s2_c profiled out per component (floored at `floor`); otherwise s2_c = s2_fixed for all c,
    and `c`, `dcs` already include that factor (C is then the full covariance).
    dcs: derivatives of C with respect to the optimised parameters. Returns (value, grad) or None when a
    Cholesky factorisation fails.
    """
    from scipy.linalg import LinAlgError, cho_solve, cholesky
    from scipy.linalg.lapack import dpotri

    n, q = f.shape
    try:
        lc = cholesky(c, lower=True)
        ci, info = dpotri(lc, lower=1)  # C⁻¹ from the factor (a third of a solve against the identity)
        if info != 0:
            return None
        ci = np.tril(ci) + np.tril(ci, -1).T
        cif = ci @ f
        a = f.T @ cif
        la = cholesky(a, lower=True)
    except (LinAlgError, np.linalg.LinAlgError, ValueError):
        return None
    p = ci - cif @ cho_solve((la, True), cif.T)
    py = p @ y
    ypy = np.einsum("ic,ic->c", y, py)
    logdet = 2.0 * np.sum(np.log(np.diag(lc))) + 2.0 * np.sum(np.log(np.diag(la)))
    if s2_fixed is None:
        s2 = ypy / (n - q)
        live = s2 > floor
        s2 = np.where(live, s2, floor)
        value = 0.5 * (n - q) * np.sum(np.log(s2)) + 1.5 * logdet
        w = np.where(live, 1.0 / s2, 0.0)
    else:
        value = 0.5 * np.sum(ypy) + 1.5 * logdet
        w = np.ones(y.shape[1])
    grad = np.array([-0.5 * float(np.sum((dc @ py) * py, axis=0) @ w) + 1.5 * float(np.vdot(p, dc)) for dc in dcs])
    if not (np.isfinite(value) and np.all(np.isfinite(grad))):
        return None
    return float(value), grad


class _FittedGP(Fitted):
    """A fitted GP. Attributes for reports: length_scale (local units) and length_scale_mm, noise_ratio
    g = sigma_n^2 / sigma_f^2, signal_var (3,) sigma_f^2 per component (mm^2), signal_std_mm and noise_std_mm (3,),
    beta ((dim+1) x 3 trend coefficients in local coordinates), fit_points (how many fiducials the
    hyper-parameters were fitted on). The hyper-parameters cost O(M^3) per likelihood evaluation (about sixty), M
    = min(N, FIT_SUBSAMPLE): above FIT_SUBSAMPLE fiducials a fixed-seed random subset of them; the kriging itself
    one O(N^3) factorisation on all N; prediction O(N^2) per query.
    """

    method = "gp"

    def __init__(self, points, values, kernel: str, noise_mm: float | None):
        from scipy.linalg import cholesky, solve_triangular
        from scipy.optimize import minimize
        from scipy.spatial.distance import cdist

        self.hull = Hull(points)
        n = len(points)
        self.n_fiducials = n
        dim = self.hull.frame.dim
        if dim == 0 or n < dim + 2:
            raise too_few("gp", max(dim, 1) + 2, dim, n, f"for fiducials {dim_words(dim)}")
        self.kernel = kernel
        x = self.hull.local
        f = _design(x)
        q = f.shape[1]
        # Residual size after an ordinary least-squares plane fit: sets the variance floor and scales.
        resid = values - f @ np.linalg.lstsq(f, values, rcond=None)[0]
        size = float(np.max(np.abs(values))) if np.any(values) else 1.0
        floor = max((_GP_FLOOR_REL * size) ** 2, 1e-300)
        self._x = x
        # the hyper-parameters from at most FIT_SUBSAMPLE fiducials (a fixed-seed random subset: each likelihood
        # evaluation is cubic in their number), then one factorisation on all of them
        self.fit_points = min(n, FIT_SUBSAMPLE)
        sub = np.sort(np.random.default_rng(0).choice(n, FIT_SUBSAMPLE, replace=False)) if n > FIT_SUBSAMPLE else None
        xs, fs, ys = (x, f, values) if sub is None else (x[sub], f[sub], values[sub])
        dist = cdist(xs, xs)
        eye = np.eye(len(xs))

        if noise_mm is None:
            lb = np.log([_GP_ELL_BOUNDS[0], _GP_G_BOUNDS[0]])
            ub = np.log([_GP_ELL_BOUNDS[1], _GP_G_BOUNDS[1]])

            def objective(theta):
                ell, g = np.exp(theta)
                r, dr = _corr(dist, ell, kernel)
                return _neg_reml(r + g * eye, [dr, g * eye], fs, ys, None, floor)

            starts = [np.log([ell, g]) for ell in _GP_ELL_STARTS for g in _GP_G_STARTS]
        else:
            v = max(float(np.sum(resid**2)) / (3.0 * max(n - q, 1)), noise_mm**2, floor)
            lb = np.log([_GP_ELL_BOUNDS[0], v * 1e-6])
            ub = np.log([_GP_ELL_BOUNDS[1], v * 1e4])
            sn2 = noise_mm**2

            def objective(theta):
                ell, sf2 = np.exp(theta)
                r, dr = _corr(dist, ell, kernel)
                c = sf2 * r + (sn2 + _GP_FIXED_JITTER * sf2) * eye
                return _neg_reml(c, [sf2 * dr, sf2 * (r + _GP_FIXED_JITTER * eye)], fs, ys, 0.0, floor)

            starts = [np.log([ell, v * r]) for ell in _GP_ELL_STARTS for r in (0.1, 1.0, 10.0)]

        def fun(theta):
            out = objective(theta)
            return (1e300, np.zeros(2)) if out is None else out

        clean = noise_mm is None and np.all(np.sum(resid**2, axis=0) / max(n - q, 1) <= floor)
        if clean:
            # The data are an exact linear field: the likelihood carries no information on (ell, g) and the
            # prediction is the trend whatever they are; keep a well-conditioned deterministic choice.
            best_theta = np.log([1.0, 1e-6])
        else:
            # Deterministic multi-start: evaluate a grid of starts, refine the best few with L-BFGS-B.
            scored = sorted(((fun(t0)[0], i) for i, t0 in enumerate(starts)))
            best_theta, best_val = None, np.inf
            for val0, i in scored[:_GP_REFINE]:
                if val0 >= 1e300:
                    continue
                res = minimize(fun, starts[i], jac=True, method="L-BFGS-B", bounds=list(zip(lb, ub)))
                val = float(res.fun)
                if np.isfinite(val) and val < best_val:
                    best_theta, best_val = np.clip(res.x, lb, ub), val
            if best_theta is None or best_val >= 1e300:  # pragma: no cover - every start failed
                raise InputError(
                    "gp: the covariance matrix could not be factorised for these fiducials; "
                    "check for duplicated fiducials or use method 'idw'"
                )

        assert best_theta is not None  # at least one start converged (else InputError above)
        ell, h = np.exp(best_theta)
        if noise_mm is None:
            g = h
        else:
            sf2 = h
            g = noise_mm**2 / sf2 + _GP_FIXED_JITTER
        self.length_scale = float(ell)  # local units
        self.length_scale_mm = float(ell * self.hull.frame.scale)
        self.noise_ratio = float(g)  # noise variance / signal variance
        self.fixed_noise = noise_mm is not None

        r = np.empty((n, n))
        for i in range(0, n, 256):  # by blocks of rows: one N x N array, not the kernel's temporaries
            r[i : i + 256] = _corr(cdist(x[i : i + 256], x), ell, kernel)[0]
        r[np.diag_indices(n)] += g
        lc = cholesky(r, lower=True, overwrite_a=True)
        del r
        fi = solve_triangular(lc, f, lower=True)  # L^-1 F
        yi = solve_triangular(lc, values, lower=True)  # L^-1 Y
        qf, rf = np.linalg.qr(fi)
        beta = solve_triangular(rf, qf.T @ yi)  # GLS trend coefficients (q x 3)
        wres = yi - fi @ beta  # whitened residuals
        if noise_mm is None:
            s2 = np.maximum(np.sum(wres**2, axis=0) / (n - q), floor)
        else:
            s2 = np.full(3, sf2)
        self.signal_var = s2  # (3,) mm^2, per component
        self.signal_std_mm = np.sqrt(s2)
        self.noise_std_mm = np.sqrt(g * s2)
        self.beta = beta
        self._lc, self._rf, self._fi = lc, rf, fi
        self._alpha = solve_triangular(lc.T, wres, lower=False)  # C^-1 (Y - F beta)

    def _predict(self, q, local_q):
        from scipy.linalg import solve_triangular
        from scipy.spatial.distance import cdist

        m = len(q)
        values = np.empty((m, 3))
        base = np.empty(m)
        n = len(self._x)
        chunk = max(1, CHUNK_ELEMENTS // max(n, 1))
        for start in range(0, m, chunk):
            xq = local_q[start : start + chunk]
            kq, _ = _corr(cdist(xq, self._x), self.length_scale, self.kernel)  # (c, N)
            fq = _design(xq)
            values[start : start + chunk] = fq @ self.beta + kq @ self._alpha
            v = solve_triangular(self._lc, kq.T, lower=True)  # (N, c)
            u = fq.T - self._fi.T @ v  # (q, c)
            w = solve_triangular(self._rf, u, trans="T")  # R_f^-T u
            base[start : start + chunk] = 1.0 - np.sum(v * v, axis=0) + np.sum(w * w, axis=0)
        std = np.sqrt(np.maximum(base, 0.0)[:, None] * self.signal_var[None, :])
        return values, std, None


MAX_FIDUCIALS = (
    5000  # fiducials gp fits at most: one O(N³) factorisation and a few N x N arrays (N = 5000: 200 MB each)
)


@dataclass(frozen=True)
class GP:
    """Gaussian process (universal kriging) with a linear mean, fitted by REML; hyper-parameters shared by x, y, z.

    kernel: 'matern52' (default) or 'se' (squared exponential), length scale in local units.
    noise_mm: None -> the noise-to-signal variance ratio is estimated (REML); a number >= 0 -> the white-noise
    standard deviation (mm per axis) is fixed to it (e.g. from repeatability measurements) and the signal
    variance, shared by the 3 components, is estimated instead.
    The predictive std is that of the latent correction (without the white noise), in mm.
    """

    name: ClassVar[str] = "gp"
    #: fitted to ones, it predicts ones everywhere (weights that sum to one; tests/interpolation/test_interpolation.py)
    reproduces_constants: ClassVar[bool] = True
    kernel: str = option(
        "matern52",
        label="GP kernel",
        help="gp: covariance kernel, matern52 (default) or se (squared exponential)",
        choices=("matern52", "se"),
    )
    noise_mm: float | None = option(
        None,
        flag="noise-mm",
        label="GP noise (mm)",
        help="gp: the white-noise standard deviation per axis, mm (default: estimated by REML)",
        bounds=(0.0, 1e3),
        kind=float,
    )

    def __post_init__(self):
        kern = str(self.kernel).strip().lower()
        if kern not in _GP_KERNELS:
            raise InputError(f"unknown gp kernel {self.kernel!r}; valid kernels: {', '.join(_GP_KERNELS)}")
        object.__setattr__(self, "kernel", kern)
        if self.noise_mm is not None:
            object.__setattr__(self, "noise_mm", check_float("gp noise_mm", self.noise_mm, positive=False))
        check_options(self, "gp")

    @thread_limited
    def fit(self, points, values) -> FittedInterpolator:
        p, v = check_data(points, values)
        if len(p) > MAX_FIDUCIALS:
            raise InputError(
                f"gp interpolates at most {MAX_FIDUCIALS} fiducials (its fit factorises an N x N matrix, O(N³)), got "
                f"{len(p)}: "
                "use idw, linear or tps for more"
            )
        return _FittedGP(p, v, self.kernel, self.noise_mm)
