"""Fitting candidate error models to published per-method statistics, and choosing between them.

Each model's statistics come from `reproduction.simulate_model` at unit scale on a grid of directions phi:
for every simulated experiment, the 28 statistics (mean, variance, max, r of 7 methods). For parameters
(rho, phi) the joint sampling distribution of a published table is approximated as multivariate Gaussian:

    mean = D mu(phi),   covariance = D C(phi) D,   D = diag(rho^k),

mu and C the mean and covariance over simulated experiments (linearly interpolated in phi), k each
statistic's scale power (mean, max: 1; variance: 2; r: 0). The statistics of one table are strongly
correlated (mean and max of a method ~0.96; a method and its SA refinement share their readings), so the
FULL covariance is used: C is the sample covariance with its correlations shrunk towards zero by the
Schäfer–Strimmer estimate (28 statistics from a few hundred experiments), and a floor of (1 % of mu)² +
0.001² on each variance (model tolerance and the published 3-decimal rounding).

Misfit = deviance = (y − mean)ᵀ Σ⁻¹ (y − mean) + ln det Σ over the statistics used (−2 log-likelihood up to a
constant). `chi2` is the quadratic form alone. Cross-validation leaves one METHOD out: fit (rho, phi) on the
other six methods' 24 statistics and score the left-out method's 4 by their CONDITIONAL distribution given the
other six (they share readings and the random field); no parameter is ever tuned per method.

Choosing an extension: it must beat the baseline in sample by more than the chi-square(1) quantile at
0.01 / (number of extensions) (the nested likelihood-ratio test with a Bonferroni correction) AND have a
lower cross-validated misfit than the baseline. Among those, the lowest cross-validated misfit wins; if the
runner-up is within CV_SEPARATION of it, the data do not separate the two and the result says so.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy import interpolate, optimize, stats

from rrbc_core.studies.reproduction import METHODS, SCALE_POWER, STATISTICS, DirectionStats

FAMILY_ALPHA = 0.01
#: Cross-validated deviance difference below which two extensions are reported as not separated
#: (2 units of deviance = a likelihood ratio of e ≈ 2.7 on held-out data).
CV_SEPARATION = 2.0
FLOOR_REL = 0.01
FLOOR_ABS = 0.001
_LOG_RHO = np.linspace(np.log(0.01), np.log(20.0), 240)
_N = len(STATISTICS) * len(METHODS)


def measured_matrix(rows) -> np.ndarray:
    """(4, 7) published values of STATISTICS, methods in reproduction.METHODS order."""
    by = {row.method: row for row in rows}
    return np.array([[getattr(by[m], s) for m in METHODS] for s in STATISTICS])


def stat_index(methods_mask) -> np.ndarray:
    """Indices into the flattened (4 x 7, statistic-major) vector of the methods in the mask."""
    mask = np.asarray(methods_mask, dtype=bool)
    return np.array([s * len(METHODS) + m for s in range(len(STATISTICS)) for m in range(len(METHODS)) if mask[m]])


def shrunk_covariance(x: np.ndarray) -> np.ndarray:
    """Covariance of the rows of x (R, p), correlations shrunk towards 0 (Schäfer & Strimmer 2005, target D)."""
    r = x.shape[0]
    sd = x.std(axis=0, ddof=1)
    ok = sd > 0
    z = np.zeros_like(x)
    z[:, ok] = (x[:, ok] - x[:, ok].mean(axis=0)) / sd[ok]
    corr = z.T @ z / (r - 1)
    w = z[:, :, None] * z[:, None, :]
    var_c = r / (r - 1) ** 3 * np.sum((w - w.mean(axis=0)) ** 2, axis=0)
    off = ~np.eye(x.shape[1], dtype=bool)
    denom = np.sum(corr[off] ** 2)
    lam = 1.0 if denom <= 0 else float(np.clip(np.sum(var_c[off]) / denom, 0.0, 1.0))
    corr_s = (1 - lam) * corr
    np.fill_diagonal(corr_s, 1.0)
    return corr_s * np.outer(sd, sd)


@dataclass(frozen=True)
class Moments:
    """Unit-scale moments of every statistic on the phi grid: mu, sd (Φ, 4, 7); cov (Φ, 28, 28)."""

    phis: np.ndarray
    mu: np.ndarray
    sd: np.ndarray
    cov: np.ndarray
    power: np.ndarray  # (4,)

    @classmethod
    def of(cls, ds: DirectionStats) -> Moments:
        x = np.stack([ds.values[s] for s in STATISTICS], axis=2)  # (Φ, R, 4, 7)
        flat = x.reshape(x.shape[0], x.shape[1], _N)
        mu = flat.mean(axis=1)
        cov = np.stack([shrunk_covariance(f) for f in flat])
        floor = (FLOOR_REL * mu) ** 2 + FLOOR_ABS**2
        idx = np.arange(_N)
        cov[:, idx, idx] += floor
        sd = np.sqrt(cov[:, idx, idx])
        shape = (len(mu), len(STATISTICS), len(METHODS))
        return cls(
            np.asarray(ds.phis, dtype=float),
            mu.reshape(shape),
            sd.reshape(shape),
            cov,
            np.array([SCALE_POWER[s] for s in STATISTICS]),
        )

    @property
    def power_flat(self) -> np.ndarray:
        return np.repeat(self.power, len(METHODS))

    @cached_property
    def _splines(self) -> tuple:
        """(mu, sd) as functions of phi, built once: cubic splines (linear with fewer than 4 directions)."""
        return self._interpolant(self.mu), self._interpolant(self.sd)

    @cached_property
    def _corr(self) -> np.ndarray:
        """(Φ, 28, 28) correlation matrices on the grid."""
        sd = self.sd.reshape(len(self.sd), _N)
        return self.cov / np.einsum("pi,pj->pij", sd, sd)

    def _interpolant(self, values: np.ndarray):
        """values (Φ, ...) as a function of phi (P,) -> (P, ...)."""
        phis = self.phis
        if len(phis) == 1:
            return lambda phi: np.repeat(values, len(phi), axis=0)
        if len(phis) < 4:

            def linear(phi):
                i = np.clip(np.searchsorted(phis, phi) - 1, 0, len(phis) - 2)
                f = ((phi - phis[i]) / (phis[i + 1] - phis[i])).reshape((-1,) + (1,) * (values.ndim - 1))
                return (1 - f) * values[i] + f * values[i + 1]

            return linear
        return interpolate.CubicSpline(phis, values, axis=0)

    def _clip(self, phi) -> np.ndarray:
        return np.clip(np.atleast_1d(np.asarray(phi, dtype=float)), self.phis[0], self.phis[-1])

    def at(self, phi):
        """Interpolated (mu, sd) at phi (scalar or (P,)): (P, 4, 7); cubic splines in phi built once per Moments."""
        phi = self._clip(phi)
        mu, sd = self._splines
        return mu(phi), np.maximum(sd(phi), FLOOR_ABS)

    def cov_at(self, phi) -> np.ndarray:
        """Interpolated unit-scale covariance (P, 28, 28): spline-interpolated sd, linearly interpolated
        correlations (a convex combination of correlation matrices is one)."""
        phi = np.atleast_1d(np.asarray(phi, dtype=float))
        sd = self.at(phi)[1].reshape(len(phi), _N)
        corr = self._corr
        if len(self.phis) == 1:
            c = np.repeat(corr, len(phi), axis=0)
        else:
            pc = np.clip(phi, self.phis[0], self.phis[-1])
            i = np.clip(np.searchsorted(self.phis, pc) - 1, 0, len(self.phis) - 2)
            f = ((pc - self.phis[i]) / (self.phis[i + 1] - self.phis[i]))[:, None, None]
            c = (1 - f) * corr[i] + f * corr[i + 1]
        return c * np.einsum("pi,pj->pij", sd, sd)

    def predict(self, log_rho, phi):
        """Predicted (mean, marginal sd) (P, 4, 7) for parameter vectors log_rho, phi of length P."""
        mu, s = self.at(phi)
        scale = np.exp(np.asarray(log_rho, dtype=float))[:, None, None] ** self.power[None, :, None]
        return mu * scale, s * scale

    def deviance_grid(self, y: np.ndarray, idx: np.ndarray, log_rho: np.ndarray, phis: np.ndarray):
        """Deviance (len(log_rho), len(phis)) of the statistics idx (flat indices) of table y (4, 7)."""
        yf = np.asarray(y, dtype=float).reshape(-1)[idx]
        k = self.power_flat[idx]
        log_rho = np.asarray(log_rho, dtype=float)
        mu_all = self.at(phis)[0].reshape(len(np.atleast_1d(phis)), _N)[:, idx]
        covs = self.cov_at(phis)[:, idx][:, :, idx]
        chol = np.linalg.cholesky(covs)  # (Φ, p, p), one LAPACK call per matrix as before, in one numpy call
        logdet = 2 * np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)  # (Φ,)
        scaled = yf[None] * np.exp(-np.outer(log_rho, k))  # D⁻¹ y, (nρ, p)
        z = scaled[None] - mu_all[:, None, :]  # (Φ, nρ, p)
        w = np.linalg.solve(chol, np.swapaxes(z, 1, 2))  # (Φ, p, nρ)
        out = np.sum(w**2, axis=1) + logdet[:, None] + (2 * log_rho * k.sum())[None]
        return out.T


@dataclass(frozen=True)
class Fit:
    model: str
    log_rho: float
    phi: float
    params: dict
    deviance: float
    chi2: float  # Mahalanobis quadratic form of the statistics used
    mean: np.ndarray  # (4, 7) predicted at the fit
    sd: np.ndarray  # (4, 7) marginal sd
    z: np.ndarray  # (4, 7) marginal z = (y − mean) / sd

    def outside(self, k: float = 2.0) -> int:
        return int(np.sum(np.abs(self.z) > k))


def _phi_grid(moments: Moments, n: int) -> np.ndarray:
    return np.zeros(1) if len(moments.phis) == 1 else np.linspace(moments.phis[0], moments.phis[-1], n)


def fit(moments: Moments, y: np.ndarray, model, mask=None) -> Fit:
    """Best (rho, phi) for the methods in `mask` (default all): coarse grid, then a bounded local search."""
    mask = np.ones(len(METHODS), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    idx = stat_index(mask)
    phis = _phi_grid(moments, 91)
    dev = moments.deviance_grid(y, idx, _LOG_RHO, phis)
    a, b = np.unravel_index(int(np.argmin(dev)), dev.shape)
    x0 = np.array([_LOG_RHO[a], phis[b]])

    def f(x):
        return float(moments.deviance_grid(y, idx, x[:1], x[1:2])[0, 0])

    if len(moments.phis) == 1:
        res = optimize.minimize_scalar(
            lambda v: f(np.array([v, 0.0])), bounds=(x0[0] - 0.05, x0[0] + 0.05), method="bounded"
        )
        best = np.array([res.x, 0.0]) if res.fun < dev[a, b] else x0
    else:
        res = optimize.minimize(
            f, x0, method="L-BFGS-B", bounds=[(_LOG_RHO[0], _LOG_RHO[-1]), (moments.phis[0], moments.phis[-1])]
        )
        best = res.x if res.fun < dev[a, b] else x0
    m, s = moments.predict(best[:1], best[1:])
    z = (y - m[0]) / s[0]
    d = f(best)
    cov = moments.cov_at(best[1:])[0][np.ix_(idx, idx)]
    logdet = np.linalg.slogdet(cov)[1] + 2 * best[0] * moments.power_flat[idx].sum()
    return Fit(
        model=model.name,
        log_rho=float(best[0]),
        phi=float(best[1]),
        params=model.params(float(np.exp(best[0])), float(best[1])),
        deviance=d,
        chi2=float(d - logdet),
        mean=m[0],
        sd=s[0],
        z=z,
    )


def predictive(moments: Moments, log_rho: float, phi: float) -> tuple[np.ndarray, np.ndarray]:
    """Full predicted (mean (28,), covariance (28, 28)) of a table at (rho, phi)."""
    mu = moments.at(phi)[0].reshape(_N)
    scale = np.exp(log_rho) ** moments.power_flat
    return mu * scale, moments.cov_at(phi)[0] * np.outer(scale, scale)


def conditional_deviance(
    y: np.ndarray, mean: np.ndarray, cov: np.ndarray, held: np.ndarray, given: np.ndarray
) -> float:
    """Deviance of y[held] under the Gaussian (mean, cov) conditioned on y[given] (flat indices)."""
    yf = np.asarray(y, dtype=float).reshape(-1)
    s_gg = cov[np.ix_(given, given)]
    s_hg = cov[np.ix_(held, given)]
    gain = np.linalg.solve(s_gg, s_hg.T).T
    m = mean[held] + gain @ (yf[given] - mean[given])
    c = cov[np.ix_(held, held)] - gain @ s_hg.T
    r = yf[held] - m
    sign, logdet = np.linalg.slogdet(c)
    return float(r @ np.linalg.solve(c, r) + logdet)


def cross_validate(moments: Moments, y: np.ndarray, model) -> tuple[float, np.ndarray, list]:
    """Leave-one-method-out: (total held-out deviance, per-method held-out deviance (7,), the 7 fits)."""
    per = np.empty(len(METHODS))
    fits = []
    for m in range(len(METHODS)):
        train = np.ones(len(METHODS), dtype=bool)
        train[m] = False
        fm = fit(moments, y, model, train)
        mean, cov = predictive(moments, fm.log_rho, fm.phi)
        per[m] = conditional_deviance(y, mean, cov, stat_index(~train), stat_index(train))
        fits.append(fm)
    return float(per.sum()), per, fits


def profile_interval(moments: Moments, y: np.ndarray, model, best: Fit, label: str, level: float = 1.0):
    """Range of parameter `label` over (rho, phi) whose deviance is within `level` of the best (1: ~1 sigma)."""
    phis = _phi_grid(moments, 181)
    lrs = np.linspace(best.log_rho - 1.5, best.log_rho + 1.5, 301)
    dev = moments.deviance_grid(y, stat_index(np.ones(len(METHODS), dtype=bool)), lrs, phis)
    ok = dev <= best.deviance + level
    lr, ph = np.meshgrid(lrs, phis, indexing="ij")
    vals = np.array([model.params(float(np.exp(a)), float(b))[label] for a, b in zip(lr[ok], ph[ok])])
    if vals.size == 0:
        v = best.params[label]
        return v, v
    return float(vals.min()), float(vals.max())


@dataclass(frozen=True)
class Assessment:
    model: str
    fit: Fit
    cv_deviance: float
    cv_per_method: np.ndarray
    cv_fits: list


@dataclass(frozen=True)
class Selection:
    assessments: dict  # model name -> Assessment
    chosen: str  # "baseline" when no extension is claimed
    threshold: float  # in-sample deviance gain an extension needs
    separated: bool  # chosen clearly ahead of the runner-up (or nothing claimed)
    runner_up: str | None


def assess(moments_by_model: dict, models, y: np.ndarray) -> dict:
    out = {}
    for model in models:
        mo = moments_by_model[model.name]
        f = fit(mo, y, model)
        cv, per, fits = cross_validate(mo, y, model)
        out[model.name] = Assessment(model.name, f, cv, per, fits)
    return out


def select(assessments: dict) -> Selection:
    """Apply the rule in the module docstring."""
    base = assessments["baseline"]
    extensions = [a for name, a in assessments.items() if name != "baseline"]
    threshold = float(stats.chi2.ppf(1 - FAMILY_ALPHA / max(len(extensions), 1), 1))
    claimed = [
        a for a in extensions if base.fit.deviance - a.fit.deviance > threshold and a.cv_deviance < base.cv_deviance
    ]
    if not claimed:
        return Selection(assessments, "baseline", threshold, True, None)
    claimed.sort(key=lambda a: a.cv_deviance)
    runner = claimed[1] if len(claimed) > 1 else None
    separated = runner is None or runner.cv_deviance - claimed[0].cv_deviance >= CV_SEPARATION
    return Selection(assessments, claimed[0].model, threshold, separated, None if runner is None else runner.model)
