"""Find what is hidden in measured point pairs (`rrbc diagnose`; contract: shared/spec/cli.md, theory notes §6).

Starting from a rigid sensor→robot fit plus isotropic noise, the diagnosis tests, in this order:
outliers (generalised ESD on deleted studentised residuals of a rigid+affine(+drift) model), uniform scale
(similarity vs rigid), affine beyond scale (full linear map vs similarity; only the identifiable terms), drift
(residuals vs time), smooth field (Moran's I of the residuals, k-nearest-neighbour weights, parametric bootstrap)
and anisotropic noise (sphericity likelihood ratio of the noise covariance). All model tests are nested F-tests
of the linearised residual model (theory §6.1). False alarms are controlled family-wise: each of the m tests
run is judged at alpha/m (Bonferroni).

Conventions: residual r_i = robot_i − (R sensor_i + t), robot frame, mm. `scale.ppm` is the scale of the
sensor→robot map minus one (robot ≈ (1 + ppm·1e-6)·R·sensor + t); `affine.matrix` G is the symmetric (non-rigid)
linear part in the robot frame: robot ≈ R sensor + t + G (x − x̄); `drift.rate_mm_per_s` is the rate of change of
the residual (robot frame); `anisotropic_noise.axis` is in the sensor frame; `noise_sigma_mm` is per robot axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats
from scipy.linalg import eigh as _geigh
from scipy.spatial import cKDTree

from rrbc_core.errors import InputError
from rrbc_core.registration.strategies import least_squares
from rrbc_core.runtime.threads import thread_limited

__all__ = ["Effect", "Diagnosis", "diagnose"]

_PLANAR_RATIO = 1e-2  # smallest/largest principal spread below this: the points are treated as coplanar
_BOOTSTRAP = 1999  # parametric bootstrap replicates for Moran's I
_KNN = 6  # neighbours in Moran's I weights
_BOOTSTRAP_CHUNK_ELEMENTS = 1 << 20  # bootstrap draws held at once (8 MiB): memory stays linear in N
_SMALL_N = 40  # below this many paired points the smooth-field test's reach is stated as a limit (power study)


@dataclass(frozen=True)
class Effect:
    name: str
    parameters: dict
    p_value: float
    evidence: str
    magnitude_mm: float = 0.0  # RMS of the effect's contribution at the points; orders the list

    def to_json(self) -> dict:
        return {"name": self.name, "parameters": self.parameters, "p_value": float(self.p_value),
                "evidence": self.evidence}


@dataclass(frozen=True)
class Diagnosis:
    effects: tuple[Effect, ...]
    noise_sigma_mm: tuple[float, float, float]
    noise_source: str  # "repeats" or "fit"
    bias_rms_mm: float
    rrbc_recommended: bool
    expected_rmst_change: float
    loo_rms_rigid_mm: float
    loo_rms_rrbc_mm: float
    n_points: int
    alpha: float
    tests: dict = field(default_factory=dict)  # test name -> p-value (all tests run)
    limits: tuple[str, ...] = ()

    @property
    def names(self) -> list[str]:
        return [e.name for e in self.effects]

    def to_json(self) -> dict:
        return {
            "effects": [e.to_json() for e in self.effects],
            "noise_sigma_mm": [float(v) for v in self.noise_sigma_mm],
            "noise_source": self.noise_source,
            "bias_rms_mm": float(self.bias_rms_mm),
            "rrbc": {"recommended": bool(self.rrbc_recommended),
                     "expected_rmst_change": float(self.expected_rmst_change),
                     "loo_rms_rigid_mm": float(self.loo_rms_rigid_mm),
                     "loo_rms_rrbc_mm": float(self.loo_rms_rrbc_mm)},
            "n_points": int(self.n_points),
            "alpha": float(self.alpha),
            "tests": {k: float(v) for k, v in self.tests.items()},
            "limits": list(self.limits),
        }


# ------------------------------------------------------------------------------------------------ data
@dataclass
class _Data:
    ids: list
    sensor: np.ndarray  # (N, 3) per-id means
    robot: np.ndarray
    count: np.ndarray  # (N,)
    time: np.ndarray | None  # (N,) per-id mean time, None when absent
    row_point: np.ndarray  # (R,) index of each paired row's point
    row_sensor: np.ndarray
    row_robot: np.ndarray


def _paired(mset) -> _Data:
    robot = np.asarray(mset.robot, float)
    sensor = np.asarray(mset.sensor, float)
    rows = [i for i, role in enumerate(mset.roles) if role != "target" and np.all(np.isfinite(robot[i]))
            and np.all(np.isfinite(sensor[i]))]
    order: dict[str, int] = {}
    row_point = []
    for i in rows:
        row_point.append(order.setdefault(mset.ids[i], len(order)))
    row_point = np.asarray(row_point, int)
    n = len(order)
    if n < 5:
        raise InputError(f"{mset.source}: diagnose needs at least 5 distinct points with sensor and robot values, "
                         f"got {n}")
    count = np.bincount(row_point, minlength=n).astype(float)
    rs, rr = sensor[rows], robot[rows]
    s = np.zeros((n, 3))
    r = np.zeros((n, 3))
    np.add.at(s, row_point, rs)
    np.add.at(r, row_point, rr)
    s /= count[:, None]
    r /= count[:, None]
    t = np.asarray(mset.time, float)[rows] if len(mset.time) == len(mset.roles) else np.full(len(rows), np.nan)
    time = None
    if len(rows) and np.all(np.isfinite(t)):
        tm = np.zeros(n)
        np.add.at(tm, row_point, t)
        tm /= count
        if np.ptp(tm) > 0:
            time = tm
    return _Data(list(order), s, r, count, time, row_point, rs, rr)


# ------------------------------------------------------------------------------------------ linear model
class _Geometry:
    """Design columns of the linearised residual model at mapped points p (robot frame)."""

    def __init__(self, p: np.ndarray, time: np.ndarray | None, weights: np.ndarray, white: np.ndarray | None = None):
        self.white = np.eye(3) if white is None else white
        self.center = p.mean(axis=0)
        c = p - self.center
        _, sv, vt = np.linalg.svd(c, full_matrices=False)
        self.axes = vt  # rows: principal directions
        self.planar = bool(sv[-1] <= _PLANAR_RATIO * sv[0])
        self.normal = vt[2]
        self.scale = float(np.sqrt(np.mean(np.sum(c**2, axis=1)))) or 1.0
        u = c / self.scale
        if self.planar:  # exact rank deficiency on coplanar points: drop the normal coordinate
            u = u - np.outer(u @ self.normal, self.normal)
        self.u = u
        self.n = len(p)
        self.sw = np.repeat(np.sqrt(weights), 3)
        self.time = time
        self.tscale = float(np.std(time)) if time is not None else 1.0

    def vec(self, arr: np.ndarray) -> np.ndarray:
        """(N, 3) robot-frame vectors -> whitened, weighted (3N,)."""
        return (arr @ self.white.T).reshape(-1) * self.sw

    def _cols(self, fields) -> np.ndarray:  # fields (k, N, 3) -> whitened, weighted (3N, k)
        a = (np.asarray(fields) @ self.white.T).reshape(len(fields), -1).T
        return a * self.sw[:, None]

    def rigid(self):
        e = np.eye(3)
        trans = [np.tile(e[k], (self.n, 1)) for k in range(3)]
        rot = [np.cross(e[k], self.u) for k in range(3)]
        return self._cols(trans + rot)

    def scale_col(self):
        return self._cols([self.u])

    def linear(self):  # full 3x3 linear map: E_ab u
        out = []
        for a in range(3):
            for b in range(3):
                f = np.zeros((self.n, 3))
                f[:, a] = self.u[:, b]
                out.append(f)
        return self._cols(out)

    def drift(self):
        tt = (self.time - self.time.mean()) / self.tscale
        e = np.eye(3)
        return self._cols([np.outer(tt, e[k]) for k in range(3)])


def _rank(x: np.ndarray) -> int:
    if x.shape[1] == 0:
        return 0
    norms = np.linalg.norm(x, axis=0)
    xs = x[:, norms > 0] / norms[norms > 0]
    if xs.shape[1] == 0:
        return 0
    sv = np.linalg.svd(xs, compute_uv=False)
    return int(np.sum(sv > 1e-8 * sv[0]))


def _fit(y: np.ndarray, x: np.ndarray):
    coef, *_ = np.linalg.lstsq(x, y, rcond=1e-10)
    res = y - x @ coef
    return coef, res, float(res @ res), _rank(x)


def _ftest(y, x0, x1):
    """Nested F-test of x1 ⊃ x0 on y. Returns (p, q, nu, F, rss0, rss1, coef1)."""
    _, _, rss0, k0 = _fit(y, x0)
    coef1, _, rss1, k1 = _fit(y, x1)
    q, nu = k1 - k0, len(y) - k1
    if q <= 0 or nu <= 0 or rss1 <= 0:
        return 1.0, q, nu, 0.0, rss0, rss1, coef1
    f = ((rss0 - rss1) / q) / (rss1 / nu)
    return float(stats.f.sf(f, q, nu)), q, nu, float(f), rss0, rss1, coef1


def _orth(x: np.ndarray) -> np.ndarray:
    u, sv, _ = np.linalg.svd(x, full_matrices=False)
    return u[:, sv > 1e-8 * (sv[0] if len(sv) else 1.0)]


_DRIFT_KEPT = 0.1  # drift directions keeping less than this fraction of their energy beside the model: not testable


def _usable_drift(base: np.ndarray, dcol: np.ndarray):
    """Drift columns restricted to the directions not (almost) absorbed by the columns `base`.

    In raster order time is (nearly) linear in the coordinates, so some drift directions equal a rotation or linear
    term up to the noise in the mapped points; fitting them would fit noise patterns (false drift and anisotropy).
    Returns (columns, fraction of drift energy kept per direction)."""
    qx = _orth(base)
    kept = dcol - qx @ (qx.T @ dcol)
    frac, vec = _geigh(kept.T @ kept, dcol.T @ dcol)
    return dcol @ vec[:, frac >= _DRIFT_KEPT], frac


# ----------------------------------------------------------------------------------------------- outliers
def _outliers(d: _Data, use_time: bool, alpha: float, white: np.ndarray):
    """Generalised ESD on deleted (mean-shift) studentised residuals of a rigid + linear (+ drift) model.

    Returns (outlier indices in order found, Bonferroni-adjusted p of the last accepted, statistics)."""
    n = len(d.ids)
    active = np.ones(n, bool)
    kmax = max(0, min(n // 5, n - 8, 10))
    steps = []
    for _ in range(kmax):
        idx = np.flatnonzero(active)
        reg = least_squares(d.sensor[idx], d.robot[idx], weights=d.count[idx])
        p = reg.mapping.apply(d.sensor[idx])
        g = _Geometry(p, d.time[idx] if use_time else None, d.count[idx], white)
        x = np.hstack([g.rigid(), g.linear()])
        if use_time:
            x = np.hstack([x, _usable_drift(x, g.drift())[0]])
        q = _orth(x)
        y = g.vec(d.robot[idx] - p)
        res = y - q @ (q.T @ y)
        rss = float(res @ res)
        k = q.shape[1]
        nu = len(y) - k - 3
        if nu < 3:
            break
        qb = q.reshape(len(idx), 3, k)
        m = np.eye(3)[None] - np.einsum("nak,nbk->nab", qb, qb)
        rb = res.reshape(len(idx), 3)
        try:
            dss = np.einsum("na,na->n", rb, np.linalg.solve(m, rb[..., None])[..., 0])
        except np.linalg.LinAlgError:
            break
        s2 = (rss - dss) / nu
        fj = np.where(s2 > 0, (dss / 3) / np.where(s2 > 0, s2, 1.0), np.inf)
        best_i = int(np.argmax(fj))
        best = float(fj[best_i])
        if best_i < 0:
            break
        padj = min(1.0, float(stats.f.sf(best, 3, nu)) * len(idx))
        steps.append((int(idx[best_i]), padj))
        active[idx[best_i]] = False
    found = 0
    for i, (_, padj) in enumerate(steps):
        if padj < alpha:
            found = i + 1
    out = [s[0] for s in steps[:found]]
    p = max([s[1] for s in steps[:found]]) if found else (steps[0][1] if steps else 1.0)
    return out, p


# ---------------------------------------------------------------------------------------------- Moran's I
def _moran_weights(p: np.ndarray):
    """Indices (N, k) of each point's k nearest other points (k = min(_KNN, N - 1))."""
    k = min(_KNN, len(p) - 1)
    _, nb = cKDTree(p).query(p, k=k + 1)
    return nb[:, 1:]


def _moran(res: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """Vector Moran's I with k-NN weights: res (..., N, 3) -> (...).

    I = (1/k) Σ_i Σ_{j ∈ nb(i)} r_i·r_j / Σ_i |r_i|², the neighbour sums taken with a sparse (N, N) weight
    matrix (k non-zeros per row), so memory is O(N·k) per residual field, not a gathered (..., N, k, 3) array."""
    from scipy.sparse import csr_matrix

    n, k = nb.shape
    w = csr_matrix((np.ones(n * k), nb.reshape(-1), np.arange(0, n * k + 1, k)), shape=(n, n))
    lead = res.shape[:-2]
    r = res.reshape(-1, n, 3)
    x = np.moveaxis(r, 1, 0).reshape(n, -1)  # (N, B*3)
    num = np.einsum("nb,nb->b", x, w @ x).reshape(-1, 3).sum(axis=1)
    den = np.einsum("bic,bic->b", r, r)
    return (num / (k * den)).reshape(lead)


def _moran_bootstrap(rng, qa: np.ndarray, nb: np.ndarray, replicates: int = _BOOTSTRAP) -> np.ndarray:
    """Moran's I of `replicates` white-noise residual fields with the accepted model's columns (orthonormal qa,
    (3N, q)) projected out. Drawn and evaluated in chunks of _BOOTSTRAP_CHUNK_ELEMENTS: memory is linear in N and
    the draws are those of one rng.standard_normal((replicates, 3N)) call (a Generator fills rows in order)."""
    n3 = qa.shape[0]
    out = np.empty(replicates)
    step = max(1, _BOOTSTRAP_CHUNK_ELEMENTS // n3)
    for start in range(0, replicates, step):
        b = min(step, replicates - start)
        eps = rng.standard_normal((b, n3))
        eps -= (eps @ qa) @ qa.T
        out[start : start + b] = _moran(eps.reshape(b, n3 // 3, 3), nb)
    return out


def _length_scale(p: np.ndarray, r: np.ndarray) -> tuple[float, float]:
    """Fit r_i·r_j ≈ v exp(−d²/2ℓ²) (i ≠ j) over a grid of ℓ; returns (ℓ, v)."""
    n = len(p)
    if n > 400:
        sel = np.random.default_rng(0).choice(n, 400, replace=False)
        p, r = p[sel], r[sel]
    d2 = np.sum((p[:, None] - p[None]) ** 2, axis=-1)
    prod = r @ r.T
    iu = np.triu_indices(len(p), 1)
    d2, prod = d2[iu], prod[iu]
    dmin = np.sqrt(max(np.min(d2[d2 > 0]) if np.any(d2 > 0) else 1.0, 1e-12))
    dmax = np.sqrt(np.max(d2)) if len(d2) else 1.0
    best = (np.inf, dmax, 0.0)
    for ell in np.geomspace(dmin * 0.5, dmax * 2, 60):
        k = np.exp(-d2 / (2 * ell**2))
        v = max(0.0, float(k @ prod) / float(k @ k)) if k @ k > 0 else 0.0
        sse = float(np.sum((prod - v * k) ** 2))
        if sse < best[0]:
            best = (sse, ell, v)
    return float(best[1]), float(best[2])


# ---------------------------------------------------------------------------------------------- anisotropy
def _sphericity(s: np.ndarray, nu: float):
    """LR test of Σ = σ²I for a 3x3 covariance estimate s with nu dof (Mauchly, Bartlett-corrected)."""
    p = 3
    ev = np.clip(np.linalg.eigvalsh(s), 1e-300, None)
    lam = p * np.log(np.mean(ev)) - np.sum(np.log(ev))
    corr = 1 - (2 * p * p + p + 2) / (6 * p * nu)
    stat = max(0.0, nu * corr * lam)
    return float(stats.chi2.sf(stat, p * (p + 1) // 2 - 1))


# ------------------------------------------------------------------------------------------------- LOO
def _loo_rotations(sensor: np.ndarray, robot: np.ndarray, weights: np.ndarray):
    """Weighted least-squares fits (R (N,3,3), t (N,3)) of all points but i, for every i at once: the weighted
    sums of the full set minus point i's share (a rank-one downdate of the cross-covariance), then one batched
    SVD with the reflection fix — the same fit as `registration.kabsch` on the N−1 points (to rounding), in O(N)
    memory and time. Points are centred on the full set's weighted centroid first, so the downdates do not
    cancel large numbers."""
    w = np.asarray(weights, float)
    c_s = (w @ sensor) / w.sum()
    c_r = (w @ robot) / w.sum()
    s, r = sensor - c_s, robot - c_r
    wt = w.sum() - w  # (N,) weight of the others
    ms = ((w @ s)[None] - w[:, None] * s) / wt[:, None]  # centroid of the others (centred frame)
    mr = ((w @ r)[None] - w[:, None] * r) / wt[:, None]
    full = np.einsum("n,ni,nj->ij", w, s, r)
    h = full[None] - w[:, None, None] * s[:, :, None] * r[:, None, :] - wt[:, None, None] * ms[:, :, None] * mr[:, None, :]
    u, _, vt = np.linalg.svd(h)
    v = np.swapaxes(vt, 1, 2).copy()
    d = np.sign(np.linalg.det(np.matmul(v, np.swapaxes(u, 1, 2))))
    v[:, :, 2] *= np.where(d >= 0, 1.0, -1.0)[:, None]
    rot = np.matmul(v, np.swapaxes(u, 1, 2))
    t = (mr + c_r) - np.einsum("nij,nj->ni", rot, ms + c_s)
    return rot, t


def _loo(sensor, robot, weights, k: int = 4, power: float = 2.0):
    """Leave-one-out prediction error at each point: rigid only, and rigid + IDW correction from its k nearest
    others (sensor frame), with the registration of the others. Returns the two RMS values (mm)."""
    n = len(sensor)
    kk = min(k, n - 1)
    dist, nb = cKDTree(sensor).query(sensor, k=kk + 1)
    dist, nb = dist.reshape(n, -1), nb.reshape(n, -1)
    # drop each point itself (it is its own nearest unless another point coincides with it)
    self_col = nb == np.arange(n)[:, None]
    drop = np.where(self_col.any(axis=1), np.argmax(self_col, axis=1), kk)
    keep = np.ones_like(nb, bool)
    keep[np.arange(n), drop] = False
    nb, dj = nb[keep].reshape(n, kk), dist[keep].reshape(n, kk)
    rot, t = _loo_rotations(sensor, robot, weights)
    e_rigid = robot - (np.einsum("nij,nj->ni", rot, sensor) + t)
    corr = robot[nb] - (np.einsum("nij,nkj->nki", rot, sensor[nb]) + t[:, None, :])  # (N, k, 3)
    on = dj <= 1e-12
    with np.errstate(divide="ignore"):
        w = np.where(on.any(axis=1, keepdims=True), on.astype(float), 1.0 / dj**power)
    c = np.einsum("nk,nkc->nc", w, corr) / w.sum(axis=1, keepdims=True)
    e_rrbc = e_rigid - c
    rms = lambda e: float(np.sqrt(np.mean(np.sum(e**2, axis=1))))  # noqa: E731
    return rms(e_rigid), rms(e_rrbc)


# --------------------------------------------------------------------------------------------- diagnose
def _fmt_p(p: float) -> str:
    return f"{p:.2g}"


def _noise_cov(d: _Data, inl: np.ndarray, use_time: bool):
    """Noise covariance (3x3, robot frame, per single measurement) and its degrees of freedom.

    From repeated measurements (pure error) when present, else from the residuals of a rigid + linear (+ drift)
    fit, corrected per axis for what the fit absorbs: E[Σ r rᵀ] = B^½ Σ B^½ approximately, B = Σ (I − H)_ii."""
    s, r, w = d.sensor[inl], d.robot[inl], d.count[inl]
    reg = least_squares(s, r, weights=w)
    rot = reg.mapping.rotation
    if np.any(d.count > 1):
        dev = d.row_robot - d.row_sensor @ rot.T  # the translation cancels within an id
        mean_dev = np.zeros((len(d.ids), 3))
        np.add.at(mean_dev, d.row_point, dev)
        mean_dev /= d.count[:, None]
        e = dev - mean_dev[d.row_point]
        nu = float(np.sum(d.count - 1))
        return e.T @ e / nu, nu, "repeats"
    p = reg.mapping.apply(s)
    g = _Geometry(p, d.time[inl] if use_time else None, w)
    x = np.hstack([g.rigid(), g.linear()])
    if use_time:
        x = np.hstack([x, _usable_drift(x, g.drift())[0]])
    q = _orth(x)
    y = g.vec(r - p)
    rr = (y - q @ (q.T @ y)).reshape(len(inl), 3)
    qb = q.reshape(len(inl), 3, -1)
    blocks = len(inl) * np.eye(3) - np.einsum("nak,nbk->ab", qb, qb)
    ev, vec = np.linalg.eigh(blocks)
    bi = vec @ np.diag(1 / np.sqrt(np.clip(ev, 1e-12, None))) @ vec.T
    nu = (3 * len(inl) - q.shape[1]) / 3.0
    return bi @ (rr.T @ rr) @ bi, nu, "fit"


def _whitener(cov: np.ndarray) -> np.ndarray:
    ev, vec = np.linalg.eigh(cov)
    ev = np.clip(ev, 1e-12 * max(ev.max(), 1e-300), None)
    return vec @ np.diag(np.sqrt(ev.mean() / ev)) @ vec.T


@thread_limited
def diagnose(mset, alpha: float = 0.01, seed: int = 0) -> Diagnosis:
    """Diagnose a MeasurementSet: which effects beyond rigid + isotropic noise are present, and will RRBC help."""
    if not (0 < float(alpha) < 1):
        raise InputError(f"alpha must be between 0 and 1, got {alpha!r}")
    d = _paired(mset)
    rng = np.random.default_rng(seed)
    use_time = d.time is not None
    limits: list[str] = []
    if not use_time:
        limits.append("no usable time column: drift was not tested")
    repeats = bool(np.any(d.count > 1))
    # the family: outliers, scale, affine, [drift], smooth_field, anisotropic_noise, each at alpha/m
    m_tests = 5 + int(use_time)
    a_each = alpha / m_tests
    tests: dict[str, float] = {}
    effects: list[Effect] = []
    all_idx = np.arange(len(d.ids))

    # 1-2. outliers first (isotropic), then the noise covariance; if the noise is anisotropic, whiten and redo
    white = np.eye(3)
    out_idx, p_out = _outliers(d, use_time, a_each, white)
    cov, nu_pe, noise_source = _noise_cov(d, np.setdiff1d(all_idx, out_idx), use_time)
    p_an = _sphericity(cov, nu_pe) if nu_pe >= 3 else 1.0
    if p_an < a_each:
        white = _whitener(cov)
        out_idx, p_out = _outliers(d, use_time, a_each, white)
        cov, nu_pe, noise_source = _noise_cov(d, np.setdiff1d(all_idx, out_idx), use_time)
        p_an = _sphericity(cov, nu_pe) if nu_pe >= 3 else 1.0
    tests["outliers"] = p_out
    inl = np.setdiff1d(all_idx, out_idx)
    s, r, w = d.sensor[inl], d.robot[inl], d.count[inl]
    n = len(inl)
    reg = least_squares(s, r, weights=w)
    p = reg.mapping.apply(s)
    rot = reg.mapping.rotation
    resid = r - p
    g = _Geometry(p, d.time[inl] if use_time else None, w, white)
    y = g.vec(resid)
    if out_idx:
        ids = [d.ids[i] for i in out_idx]
        full_reg = least_squares(d.sensor, d.robot, weights=d.count)
        big = np.linalg.norm(d.robot[out_idx] - reg.mapping.apply(d.sensor[out_idx]), axis=1)
        effects.append(Effect("outliers", {"ids": ids}, p_out,
                              f"{len(ids)} point(s) deviate from a rigid+linear fit of the others by "
                              f"{', '.join(f'{b:.3g}' for b in big)} mm (deleted studentised residual, generalised "
                              f"ESD, Bonferroni-adjusted p {_fmt_p(p_out)} < {a_each:.2g}); they were removed "
                              f"before the other tests (FRE with them {full_reg.fre_rms_mm:.3g} mm, without "
                              f"{reg.fre_rms_mm:.3g} mm).",
                              magnitude_mm=float(np.sqrt(np.sum(big**2) / len(d.ids)))))

    x_rigid = g.rigid()
    if g.planar:
        limits.append(
            "the paired points are coplanar (normal " + ", ".join(f"{v:.3f}" for v in g.normal) + "): only the 3 "
            "in-plane affine terms (two in-plane scales, in-plane shear) are testable; out-of-plane scale, shear and "
            "errors that depend on the distance from the plane are invisible to these points")

    # 3a. scale: similarity vs rigid
    x_scale = np.hstack([x_rigid, g.scale_col()])
    p_sc, q_sc, nu_sc, f_sc, rss0, rss_sc, _ = _ftest(y, x_rigid, x_scale)
    tests["scale"] = p_sc
    sim = least_squares(s, r, weights=w, with_scale=True)
    ppm = (float(sim.details["scale"]) - 1.0) * 1e6
    wsum = float(np.sum(w))
    # 3b. affine beyond scale
    x_aff = np.hstack([x_rigid, g.linear()])
    p_af, q_af, nu_af, f_af, _, rss_af, _ = _ftest(y, x_scale, x_aff)
    tests["affine"] = p_af
    accepted = [x_rigid]
    if p_af < a_each:
        # the linear map in unwhitened coordinates: residual ≈ L (p − p̄)
        ga = _Geometry(p, None, w)
        coef, *_ = np.linalg.lstsq(np.hstack([ga.rigid(), ga.linear()]), ga.vec(resid), rcond=1e-10)
        lin = coef[6:].reshape(3, 3) / ga.scale
        if ga.planar:  # the in-plane part, in-plane coordinates only
            proj = np.eye(3) - np.outer(ga.normal, ga.normal)
            lin = lin @ proj
        gm = 0.5 * (lin + lin.T)
        if ga.planar:
            gm = proj @ gm @ proj
        mag = float(np.sqrt(max(0.0, rss0 - rss_af) / wsum))
        effects.append(Effect("affine", {"matrix": gm.tolist()}, p_af,
                              f"a linear map beyond rigid + uniform scale reduces the residual sum of squares from "
                              f"{rss_sc:.3g} to {rss_af:.3g} (F({q_af}, {nu_af}) = {f_af:.3g}, p {_fmt_p(p_af)}); the "
                              f"matrix is its symmetric part (rotations absorb the rest)"
                              + ("; only the in-plane terms are identifiable on these coplanar points" if g.planar
                                 else "") + ".", magnitude_mm=mag))
        accepted = [x_aff]
    elif p_sc < a_each:
        se = np.sqrt(rss_sc / max(nu_sc, 1) / float(np.sum(g.scale_col() ** 2))) / g.scale * 1e6
        mag = float(np.sqrt(max(0.0, rss0 - rss_sc) / wsum))
        effects.append(Effect("scale", {"ppm": ppm, "ppm_standard_error": float(se)}, p_sc,
                              f"a uniform scale of {ppm:+.4g} ± {se:.2g} ppm between the frames reduces the residual "
                              f"sum of squares from {rss0:.3g} to {rss_sc:.3g} (F(1, {nu_sc}) = {f_sc:.3g}, "
                              f"p {_fmt_p(p_sc)}); no significant non-uniform part (p {_fmt_p(p_af)}).",
                              magnitude_mm=mag))
        accepted = [x_scale]
    x_acc = np.hstack(accepted)

    # 4. drift
    if use_time:
        dcol = g.drift()
        dcol_ok, surviving = _usable_drift(x_acc, dcol)  # fraction of drift energy kept per direction
        x_dr = np.hstack([x_acc, dcol_ok])
        p_dr, q_dr, nu_dr, f_dr, rss_a, rss_d, _ = _ftest(y, x_acc, x_dr)
        tests["drift"] = p_dr
        lost = int(np.sum(surviving < _DRIFT_KEPT))
        if lost:
            limits.append(f"with this measurement order, drift along {lost} of 3 directions is (almost) absorbed by "
                          f"the fitted transform (least fraction kept {max(surviving.min(), 0):.2g}) and cannot be "
                          "detected; randomise the order")
        if p_dr < a_each:
            # the rate from the full drift columns (the absorbed directions are poorly determined: see the limit)
            coef_dr = _fit(y, np.hstack([x_acc, dcol]))[0]
            rate = coef_dr[-3:] / g.tscale  # the columns carry the whitening: coefficients are in mm
            mag = float(np.sqrt(max(0.0, rss_a - rss_d) / wsum))
            effects.append(Effect("drift", {"rate_mm_per_s": rate.tolist()}, p_dr,
                                  f"the residuals change linearly with measurement time at "
                                  f"{np.linalg.norm(rate):.3g} mm/s (F({q_dr}, {nu_dr}) = {f_dr:.3g}, "
                                  f"p {_fmt_p(p_dr)}).", magnitude_mm=mag))
            x_acc = x_dr

    # 5. smooth field: Moran's I of the residuals after the accepted model, parametric bootstrap under white noise
    qa = _orth(x_acc)
    res_acc = y - qa @ (qa.T @ y)
    nb = _moran_weights(p)
    i_obs = float(_moran(res_acc.reshape(n, 3), nb))
    i_boot = _moran_bootstrap(rng, qa, nb)
    exceed = int(np.sum(i_boot >= i_obs))
    if exceed:
        p_sm = (1 + exceed) / (_BOOTSTRAP + 1)
    else:
        z = (i_obs - i_boot.mean()) / max(float(i_boot.std()), 1e-300)
        p_sm = float(min(1.0 / (_BOOTSTRAP + 1), stats.norm.sf(z)))
    tests["smooth_field"] = p_sm
    smooth = p_sm < a_each
    if n < _SMALL_N:
        # Moran's I only sees a field whose correlation reaches the k-th neighbour; with few points that distance
        # approaches the extent, and a longer field is mostly absorbed by the rigid/linear fit (power study,
        # docs/diagnosis_power.md: 12 points found a field of length half the extent in few sets at any size).
        reach = float(np.median(cKDTree(p).query(p, k=nb.shape[1] + 1)[0][:, -1]))
        limits.append(
            f"only {n} paired points: a smooth field with correlation length below about {reach:.0f} mm (the median "
            f"distance to the {nb.shape[1]}th nearest neighbour) cannot be detected reliably; longer fields are largely "
            "absorbed by the fitted transform" + ("" if smooth else
                                                  "; an empty or low-order verdict does not rule out a smooth field")
            + ("; the reported affine/scale term may be the linear part of a smooth field" if
               any(e.name in ("affine", "scale") for e in effects) else ""))
    if smooth:
        res_pts = (res_acc / g.sw).reshape(n, 3) @ np.linalg.inv(white).T  # back to mm, robot frame
        ell, v = _length_scale(p, res_pts)
        nn = nb[:, 0]
        nug = 0.5 * np.mean((res_pts - res_pts[nn]) ** 2, axis=0)  # ≈ σ² per axis + a little of the field
        # the field's RMS over the points: all of the rigid residual beyond the noise (its linear part included)
        field_var = float(np.mean(np.sum(resid**2, axis=1))) - float(np.sum(nug)) * (3 * n - 6) / (3 * n)
        rms = float(np.sqrt(max(field_var, v, 0.0)))
        effects.append(Effect("smooth_field", {"rms_mm": rms, "length_scale_mm": ell}, p_sm,
                              f"neighbouring residuals point the same way (Moran's I = {i_obs:.3g} with {nb.shape[1]} "
                              f"nearest neighbours; white-noise bootstrap mean {i_boot.mean():.3g}, p {_fmt_p(p_sm)}) "
                              f"after removing the accepted lower-order terms; rms_mm is the RMS of the whole non-rigid bias "
                              f"at the points (its linear part included).", magnitude_mm=rms))
        if not repeats:  # the fit residuals hold the field: noise from nearest-neighbour differences instead
            diff = (res_pts - res_pts[nn]) / np.sqrt(2)
            cov = diff.T @ diff / n
            nu_pe = n / 2.0
            p_an = _sphericity(cov, nu_pe) if nu_pe >= 3 else 1.0
    sigma = np.sqrt(np.clip(np.diag(cov), 0, None))

    # 6. anisotropic noise
    if nu_pe >= 3:
        tests["anisotropic_noise"] = p_an
        cov_s = rot.T @ cov @ rot  # sensor frame
        ev, evec = np.linalg.eigh(cov_s)
        ratio = float(np.sqrt(ev[2] / max(np.mean(ev[:2]), 1e-300)))
        if p_an < a_each and ratio > 1:
            axis = evec[:, 2] * (1 if evec[np.argmax(np.abs(evec[:, 2])), 2] > 0 else -1)
            effects.append(Effect("anisotropic_noise", {"axis": axis.tolist(), "ratio": ratio}, p_an,
                                  f"the noise ({'repeated measurements' if repeats else 'fit residuals'}) is "
                                  f"{ratio:.3g} times larger along the sensor axis "
                                  f"({', '.join(f'{a:.3f}' for a in axis)}) than across it (sphericity likelihood "
                                  f"ratio, p {_fmt_p(p_an)}); the other tests used noise-whitened residuals.",
                                  magnitude_mm=float(np.sqrt(ev[2]))))
    else:
        limits.append("too few degrees of freedom to test noise anisotropy")

    # 8. bias and RRBC by leave-one-out
    noise_pp = float(np.sum(sigma**2)) * float(np.mean(1.0 / w)) * (3 * n - 6) / (3 * n)
    bias = float(np.sqrt(max(0.0, float(np.mean(np.sum(resid**2, axis=1))) - noise_pp)))
    loo_rigid, loo_rrbc = _loo(s, r, w)
    change = loo_rrbc / loo_rigid - 1.0 if loo_rigid > 0 else 0.0

    effects.sort(key=lambda e: -e.magnitude_mm)
    return Diagnosis(tuple(effects), tuple(float(v) for v in sigma), noise_source, bias, bool(loo_rrbc < loo_rigid),
                     float(change), loo_rigid, loo_rrbc, n, float(alpha), tests, tuple(limits))
