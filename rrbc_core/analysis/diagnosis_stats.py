"""The statistics behind `rrbc diagnose` (`diagnosis`): paired data per point, the linearised residual model and its
nested F-tests, outliers by generalised ESD, the sphericity test of the noise, the noise covariance, and
leave-one-out RRBC (Moran's I: `diagnosis_moran`). Memory is linear in the number of points."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg, special  # tails as scipy.stats computes them, without its import (about 1 s)
from scipy.spatial import cKDTree

from rrbc_core.analysis.diagnosis_columns import (  # noqa: F401 (Geometry, LazyColumns, as_array: this module's API)
    PLANAR_RATIO,
    Block,
    Columns,
    Geometry,
    LazyColumns,
    as_array,
    column_blocks,
    column_norms,
    gram,
    n_rows,
    times,
)
from rrbc_core.errors import InputError
from rrbc_core.registration.strategies import least_squares
from rrbc_core.runtime.threads import query_workers

MAX_POINTS = 1_000_000  # distinct paired points diagnose accepts (issue 16: a stated limit, not minutes or gigabytes)


# ------------------------------------------------------------------------------------------------ data
@dataclass
class Data:
    ids: list
    sensor: np.ndarray  # (N, 3) per-id means
    robot: np.ndarray
    count: np.ndarray  # (N,)
    time: np.ndarray | None  # (N,) per-id mean time, None when absent
    row_point: np.ndarray  # (R,) index of each paired row's point
    row_sensor: np.ndarray
    row_robot: np.ndarray
    rows: np.ndarray  # (R,) the paired rows' indices in the file
    row_time: np.ndarray  # (R,) NaN when absent


def paired(mset) -> Data:
    robot = np.asarray(mset.robot, float)
    sensor = np.asarray(mset.sensor, float)
    known = np.asarray(mset.roles, dtype=object) != "target"
    rows = np.flatnonzero(known & np.isfinite(robot).all(axis=1) & np.isfinite(sensor).all(axis=1)).tolist()
    order: dict[str, int] = {}
    ids = mset.ids
    row_point = np.asarray([order.setdefault(ids[i], len(order)) for i in rows], int)
    n = len(order)
    if n > MAX_POINTS:
        raise InputError(
            f"{mset.source}: diagnose takes at most {MAX_POINTS:,} distinct points (its work grows faster than the "
            f"data), got {n:,}: diagnose a sample of the file"
        )
    if n < 5:
        raise InputError(
            f"{mset.source}: diagnose needs at least 5 distinct points with sensor and robot values, got {n}"
        )
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
    return Data(list(order), s, r, count, time, row_point, rs, rr, np.asarray(rows, int), t)


# ------------------------------------------------------------------------------------------ linear model
TIME_FOLLOWS_POSITION = 0.5  # R² of the rows' times on their positions beyond which time and position are confounded


def time_on_position(points: np.ndarray, time: np.ndarray) -> float:
    """R² (0..1) of the rows' times (N,) on their positions (N, 3) mm (an affine fit); 0 without usable times. Beyond
    `TIME_FOLLOWS_POSITION` the measurement order follows position: an effect of time cannot be told from one of
    position."""
    t = np.asarray(time, float)
    if len(t) < 5 or not np.all(np.isfinite(t)) or np.ptp(t) <= 0:
        return 0.0
    x = np.column_stack([np.ones(len(t)), np.asarray(points, float)])
    coef, *_ = np.linalg.lstsq(x, t, rcond=None)
    return float(1.0 - np.sum((t - x @ coef) ** 2) / np.sum((t - t.mean()) ** 2))


def fit(y: np.ndarray, x: Columns):
    """Least squares of y on the columns x along the directions its rank counts (normalised columns, singular
    values above 1e-8 of the largest): the fit and the F-tests' degrees of freedom agree even for nearly dependent
    columns (the arm's Jacobian beside the rigid terms). x: a design (M, k), or a tuple of column blocks taken side
    by side (as np.hstack would, without its copy). Returns (coef, residual, RSS, rank).

    The triangle R of [x y]'s Householder QR (`_triangle`: row blocks at a time, memory one block however many
    rows), then the truncated SVD of the small triangle: x = Q R_x, so x's singular values (and the truncated
    solution) are R_x's, and RSS = |R_x c − Qᵀy|² + ρ² with ρ the part of y outside x's span."""
    blocks = column_blocks(x)
    norms = column_norms(blocks)
    coef = np.zeros(len(norms))
    ok = norms > 0
    rank = 0
    if ok.any():
        r = _triangle(blocks, y, ok)
        m = int(ok.sum())
        r_x, r_y = r[:m, :m], r[:m, m]
        u, sv, vt = np.linalg.svd(r_x / norms[ok], full_matrices=False)
        keep = sv > 1e-8 * sv[0]
        rank = int(keep.sum())
        coef[ok] = (vt[keep].T @ ((u[:, keep].T @ r_y) / sv[keep])) / norms[ok]
    res = y - times(blocks, coef[:, None])[:, 0] if blocks else y.copy()
    return coef, res, float(res @ res), rank


QR_BLOCK_ROWS = 1 << 15  # rows of [x y] factored at a time by `_triangle`


def _triangle(blocks: list[np.ndarray], y: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """R (c+1, c+1) of the QR of [x[:, cols] y] (x: the column blocks side by side; m rows), block by block: the R
    of each block of rows stacked under the R so far and factored again (a tall-skinny QR: the same R up to the
    signs of its rows, which the SVD and the RSS in `fit` do not see), so no copy of the whole of x is made."""
    c = int(cols.sum())
    r = np.zeros((0, c + 1))
    for start in range(0, len(y), QR_BLOCK_ROWS):
        stop = min(start + QR_BLOCK_ROWS, len(y))
        block = np.empty((stop - start + len(r), c + 1))
        block[: len(r)] = r
        at, to = 0, 0
        for b in blocks:
            keep = cols[at : at + b.shape[1]]
            block[len(r) :, to : to + int(keep.sum())] = b[start:stop][:, keep]
            at, to = at + b.shape[1], to + int(keep.sum())
        block[len(r) :, c] = y[start:stop]
        r = linalg.qr(block, mode="r", overwrite_a=True, check_finite=False)[0][: c + 1]
    return r


def ftest(y, x0: Columns, x1: Columns):
    """Nested F-test of x1 ⊃ x0 on y (each a design or a tuple of column blocks, as `fit` takes). Returns (p, q,
    nu, F, rss0, rss1, coef1)."""
    _, _, rss0, k0 = fit(y, x0)
    coef1, _, rss1, k1 = fit(y, x1)
    q, nu = k1 - k0, len(y) - k1
    if q <= 0 or nu <= 0 or rss1 <= 0:
        return 1.0, q, nu, 0.0, rss0, rss1, coef1
    f = ((rss0 - rss1) / q) / (rss1 / nu)
    return float(special.fdtrc(q, nu, f)), q, nu, float(f), rss0, rss1, coef1


RANK_RTOL = 1e-8  # a direction of a design's span counts if its singular value exceeds this fraction of the largest
_GRAM_SPLIT = 1e-10  # eigenvalues of xᵀx above this fraction of the largest (singular values 1e-5): taken from xᵀx


def orth_basis(x: Columns) -> tuple[np.ndarray, np.ndarray]:
    """An orthonormal basis q (m, r) of the span of x's (m, k) columns along its singular directions above RANK_RTOL
    of the largest singular value (the rank rule of an SVD), and to_q (k, r) with q = x @ to_q.

    Made without an SVD of the tall x (its cost dominated `rrbc diagnose` on many points): the directions whose
    singular values exceed 1e-5 of the largest come from the eigenvectors of xᵀx (one pass, then a second on the
    result to restore orthogonality, as Cholesky QR2 does); the rest of x, beside them, gets an SVD of its few
    columns, whose singular values decide the rank as the SVD of x would (both to rounding of order 1e-16 of the
    largest, far below the rule's 1e-8). The span and its projection equal the SVD's to rounding (a test holds it).
    x: a design or its column blocks (`fit`), never stacked."""
    blocks = column_blocks(x)
    m, k = n_rows(x), sum(b.shape[1] for b in blocks)
    lam, v = np.linalg.eigh(gram(blocks)) if k else (np.zeros(0), np.zeros((0, 0)))
    if k == 0 or not lam[-1] > 0:
        return np.zeros((m, 0)), np.zeros((k, 0))
    big = lam > _GRAM_SPLIT * lam[-1]
    to_q = v[:, big] / np.sqrt(lam[big])
    q = times(blocks, to_q)
    lam2, v2 = np.linalg.eigh(q.T @ q)  # ≈ I; its inverse square root makes q orthonormal to rounding
    fix = v2 / np.sqrt(lam2)
    to_q = to_q @ fix
    for start in range(0, m, QR_BLOCK_ROWS):  # q @ fix in place, a block of rows at a time: no second tall copy
        q[start : start + QR_BLOCK_ROWS] = q[start : start + QR_BLOCK_ROWS] @ fix
    if big.all():
        return q, to_q
    small = v[:, ~big]
    rest = times(blocks, small)
    c = q.T @ rest
    rest -= q @ c  # x's small directions beside q; twice, so rounding leaves nothing of q in them
    c2 = q.T @ rest
    rest -= q @ c2
    c += c2
    u, sv, wt = np.linalg.svd(rest, full_matrices=False)
    keep = sv > RANK_RTOL * np.sqrt(lam[-1])
    if not keep.any():
        return q, to_q
    to_rest = (small - to_q @ c) @ (wt[keep].T / sv[keep])
    return np.hstack([q, u[:, keep]]), np.hstack([to_q, to_rest])


def orth(x: Columns) -> np.ndarray:
    """An orthonormal basis (m, r) of the span of x's columns (`orth_basis`)."""
    return orth_basis(x)[0]


def usable(base: Columns, cols: Columns, kept: float = 0.1, base_basis: np.ndarray | None = None):
    """The directions of the span of `cols` that keep at least `kept` of their energy beside the span of `base`.
    A direction almost inside the base is, beside it, mostly the data's own noise carried by the columns (they are
    built from measured positions): fitting it fits that noise. Returns (columns (3N, j) = cols @ m, fraction
    kept per direction of cols' span, m (k, j)). `base_basis`: orth(base) when the caller has it. base and cols:
    designs or column blocks (`fit`)."""
    if not column_blocks(cols):
        return np.zeros((n_rows(cols), 0)), np.zeros(0), np.zeros((0, 0))
    qc, to_q = orth_basis(cols)  # qc = cols @ to_q, orthonormal
    qb = orth(base) if base_basis is None else base_basis
    beside = qc - qb @ (qb.T @ qc)
    frac, vec = np.linalg.eigh(beside.T @ beside)
    m = to_q @ vec[:, frac >= kept]
    return times(cols, m), frac, m


DRIFT_KEPT = 0.1  # drift directions keeping less than this fraction of their energy beside the model: not testable


def usable_drift(base: Columns, dcol: Columns):
    """Drift columns restricted to the directions not (almost) absorbed by the columns `base`.

    In raster order time is (nearly) linear in the coordinates, so some drift directions equal a rotation or linear
    term up to the noise in the mapped points; fitting them would fit noise patterns (false drift and anisotropy).
    Returns (columns, fraction of drift energy kept per direction): `usable` with the drift's threshold."""
    cols, frac, _ = usable(base, dcol, DRIFT_KEPT)
    return cols, frac


# ----------------------------------------------------------------------------------------------- outliers
def outliers(d: Data, use_time: bool, alpha: float, white: np.ndarray, extra: np.ndarray | None = None):
    """Generalised ESD on deleted (mean-shift) studentised residuals of a rigid + linear (+ drift) (+ `extra`:
    fields (k, N, 3) per point, e.g. the arm's kinematic columns) model.

    Each step refits the model without the points removed so far. The model is built once, on every point: the
    registration's change when points are removed is an affine map of the points, which lies in the model's
    translations and linear map, so the residuals beside the model do not depend on it; and the fit on the points
    left is a downdate of the full one (`_esd_steps`): no design is rebuilt per step.

    Returns (outlier indices in order found, Bonferroni-adjusted p of the last accepted)."""
    n = len(d.ids)
    kmax = max(0, min(n // 5, n - 8, 10))
    if kmax == 0:
        return [], 1.0
    reg = least_squares(d.sensor, d.robot, weights=d.count)
    p = reg.mapping.apply(d.sensor)
    g = Geometry(p, d.time if use_time and d.time is not None else None, d.count, white)
    # the rigid rotations lie in the linear map's span (a rotation's small-angle map is linear): translations
    # and the linear map span the same, without the exactly dependent columns
    x: tuple = (g.translations(), g.linear())  # column blocks (`fit`): no stacked copy
    q = orth(x)
    more = []
    if use_time:
        more.append(usable(x, g.drift(), DRIFT_KEPT, base_basis=q)[0])
    if extra is not None:
        more.append(g._cols(extra))
    if sum(c.shape[1] for c in more):
        x = (*x, *more)
        q = orth(x)
    del x
    steps = _esd_steps(q, g.vec(d.robot - p), kmax)
    found = 0
    for i, (_, padj) in enumerate(steps):
        if padj < alpha:
            found = i + 1
    out = [s[0] for s in steps[:found]]
    # the ESD's decision rests on the last significant step (earlier steps may lie above alpha: masking)
    p_value = float(steps[found - 1][1]) if found else (float(steps[0][1]) if steps else 1.0)
    return out, p_value


def _deleted_ss(zb: np.ndarray, rb: np.ndarray) -> np.ndarray:
    """Each point's deleted sum of squares rᵢᵀ (I - zᵢzᵢᵀ)⁻¹ rᵢ (N,), zb (N, 3, r) its rows of an orthonormal basis
    of the model, rb (N, 3) its residuals: the 3x3 blocks' six entries and the adjugate, no batched solve (a
    singular block gives inf or nan)."""
    h = {(a, b): np.einsum("nk,nk->n", zb[:, a], zb[:, b]) for a in range(3) for b in range(a, 3)}
    m00, m11, m22 = 1.0 - h[0, 0], 1.0 - h[1, 1], 1.0 - h[2, 2]
    m01, m02, m12 = -h[0, 1], -h[0, 2], -h[1, 2]
    c00, c11, c22 = m11 * m22 - m12 * m12, m00 * m22 - m02 * m02, m00 * m11 - m01 * m01
    c01, c02, c12 = m02 * m12 - m01 * m22, m01 * m12 - m02 * m11, m01 * m02 - m00 * m12
    det = m00 * c00 + m01 * c01 + m02 * c02
    x, y, z = rb[:, 0], rb[:, 1], rb[:, 2]
    quad = c00 * x * x + c11 * y * y + c22 * z * z + 2.0 * (c01 * x * y + c02 * x * z + c12 * y * z)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(det > 0, quad / np.where(det > 0, det, 1.0), np.inf)


def _esd_steps(q: np.ndarray, y: np.ndarray, kmax: int) -> list[tuple[int, float]]:
    """The ESD's steps: per step the point (index of the N points) with the largest deleted F statistic among the
    points left, and its Bonferroni-adjusted p; the point is then removed. q (3N, k): an orthonormal basis of the
    model over all points; y (3N,): the whitened residuals.

    Without the removed rows S the model's Gram matrix is M = I - Σ_S q_Sᵀ q_S, so q @ M^(-1/2) (its directions
    kept by the rank rule of `orth_basis`) is an orthonormal basis on the rows left: the fit, the residuals and each
    point's 3x3 leverage follow from it without rebuilding the design (a test holds them equal to a refit)."""
    n = len(y) // 3
    k = q.shape[1]
    qb = q.reshape(n, 3, k)
    yb = y.reshape(n, 3)
    active = np.ones(n, bool)
    gram_out = np.zeros((k, k))
    qty = q.T @ y
    steps: list[tuple[int, float]] = []
    for _ in range(kmax):
        left = int(active.sum())
        if k:
            lam, v = np.linalg.eigh(np.eye(k) - gram_out)
            keep = lam > RANK_RTOL**2 * lam[-1] if lam[-1] > 0 else np.zeros(k, bool)
            w = v[:, keep] / np.sqrt(lam[keep])
        else:
            w = np.zeros((0, 0))
        r = w.shape[1]
        nu = 3 * left - r - 3
        if nu < 3:
            break
        c = w.T @ qty
        rss, dss = 0.0, np.empty(n)
        for start in range(0, n, QR_BLOCK_ROWS):  # a block of points at a time: q @ w (orthonormal on the rows
            stop = min(start + QR_BLOCK_ROWS, n)  # left) is never held whole
            z = q[3 * start : 3 * stop] @ w
            rb = (y[3 * start : 3 * stop] - z @ c).reshape(-1, 3)
            rb[~active[start:stop]] = 0.0
            rss += float(np.einsum("na,na->", rb, rb))
            dss[start:stop] = _deleted_ss(z.reshape(-1, 3, r), rb)
        if not np.all(np.isfinite(dss[active])):
            break  # a point that alone carries a direction of the model: its deleted residual is not defined
        s2 = (rss - dss) / nu
        fj = np.where(s2 > 0, (dss / 3) / np.where(s2 > 0, s2, 1.0), np.inf)
        fj[~active] = -np.inf
        best_i = int(np.argmax(fj))
        padj = min(1.0, float(special.fdtrc(3, nu, float(fj[best_i]))) * left)
        steps.append((best_i, padj))
        active[best_i] = False
        gram_out += qb[best_i].T @ qb[best_i]
        qty -= qb[best_i].T @ yb[best_i]
    return steps


# ---------------------------------------------------------------------------------------------- anisotropy
def sphericity(s: np.ndarray, nu: float):
    """LR test of Σ = σ²I for a 3x3 covariance estimate s with nu dof (Mauchly, Bartlett-corrected)."""
    p = 3
    ev = np.clip(np.linalg.eigvalsh(s), 1e-300, None)
    lam = p * np.log(np.mean(ev)) - np.sum(np.log(ev))
    corr = 1 - (2 * p * p + p + 2) / (6 * p * nu)
    stat = max(0.0, nu * corr * lam)
    return float(special.chdtrc(p * (p + 1) // 2 - 1, stat))


# ------------------------------------------------------------------------------------------------- LOO
def loo_rotations(sensor: np.ndarray, robot: np.ndarray, weights: np.ndarray):
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
    h = (
        full[None]
        - w[:, None, None] * s[:, :, None] * r[:, None, :]
        - wt[:, None, None] * ms[:, :, None] * mr[:, None, :]
    )
    u, _, vt = np.linalg.svd(h)
    v = np.swapaxes(vt, 1, 2).copy()
    d = np.sign(np.linalg.det(np.matmul(v, np.swapaxes(u, 1, 2))))
    v[:, :, 2] *= np.where(d >= 0, 1.0, -1.0)[:, None]
    rot = np.matmul(v, np.swapaxes(u, 1, 2))
    t = (mr + c_r) - np.einsum("nij,nj->ni", rot, ms + c_s)
    return rot, t


def loo(sensor, robot, weights, k: int = 4, power: float = 2.0, evaluate=None):
    """Leave-one-out prediction error at each point: rigid only, and rigid + IDW correction from its k nearest
    others (sensor frame), with the registration of the others; the RMS is taken over the points `evaluate` (N,)
    bool (default all: a point left out of the RMS still takes part in the others' fits). Returns the two RMS
    values (mm)."""
    e_rigid, e_rrbc = loo_errors(sensor, robot, weights, k, power, evaluate)
    rms = lambda e: float(np.sqrt(np.mean(e**2)))
    return rms(e_rigid), rms(e_rrbc)


def loo_errors(sensor, robot, weights, k: int = 4, power: float = 2.0, evaluate=None):
    """`loo`'s 3-D errors (mm) at the points `evaluate` (default all): (rigid (E,), RRBC (E,))."""
    n = len(sensor)
    ev = np.ones(n, bool) if evaluate is None else np.asarray(evaluate, bool)
    kk = min(k, n - 1)
    dist, nb = cKDTree(sensor).query(sensor, k=kk + 1, workers=query_workers(n))
    dist, nb = dist.reshape(n, -1), nb.reshape(n, -1)
    # drop each point itself (it is its own nearest unless another point coincides with it)
    self_col = nb == np.arange(n)[:, None]
    drop = np.where(self_col.any(axis=1), np.argmax(self_col, axis=1), kk)
    keep = np.ones_like(nb, bool)
    keep[np.arange(n), drop] = False
    nb, dj = nb[keep].reshape(n, kk), dist[keep].reshape(n, kk)
    rot, t = loo_rotations(sensor, robot, weights)
    e_rigid = robot - (np.einsum("nij,nj->ni", rot, sensor) + t)
    corr = robot[nb] - (np.matmul(sensor[nb], np.swapaxes(rot, 1, 2)) + t[:, None, :])  # (N, k, 3)
    on = dj <= 1e-12
    with np.errstate(divide="ignore"):
        w = np.where(on.any(axis=1, keepdims=True), on.astype(float), 1.0 / dj**power)
    c = np.einsum("nk,nkc->nc", w, corr) / w.sum(axis=1, keepdims=True)
    e_rrbc = e_rigid - c
    return np.linalg.norm(e_rigid[ev], axis=1), np.linalg.norm(e_rrbc[ev], axis=1)


def noise_cov(
    d: Data, inl: np.ndarray, use_time: bool, extra: np.ndarray | None = None, row_systematic: np.ndarray | None = None
):
    """Noise covariance (3x3, robot frame, per single measurement) and its degrees of freedom.

    From repeated measurements (pure error) when present — the rows' deviations from their point's mean, less
    `row_systematic` (R, 3) mm, what the accepted systematic effects (drift, the arm) predict for each row — else
    from the residuals of a rigid + linear (+ drift) (+ the usable directions of `extra` fields (k, N, 3), unless
    they would leave fewer than max(6, N/2) degrees of freedom: never a saturated fit) fit, corrected per axis for
    what the fit absorbs: E[Σ r rᵀ] = B^½ Σ B^½ approximately, B = Σ (I − H)_ii."""
    s, r, w = d.sensor[inl], d.robot[inl], d.count[inl]
    reg = least_squares(s, r, weights=w)
    rot = reg.mapping.rotation
    if np.any(d.count > 1):
        dev = d.row_robot - d.row_sensor @ rot.T  # the translation cancels within an id
        if row_systematic is not None:
            dev = dev - row_systematic
        mean_dev = np.zeros((len(d.ids), 3))
        np.add.at(mean_dev, d.row_point, dev)
        mean_dev /= d.count[:, None]
        e = dev - mean_dev[d.row_point]
        nu = float(np.sum(d.count - 1))
        return e.T @ e / nu, nu, "repeats"
    p = reg.mapping.apply(s)
    g = Geometry(p, d.time[inl] if use_time and d.time is not None else None, w)
    x: tuple = (g.rigid(), g.linear())  # column blocks (`fit`): no stacked copy
    if use_time:
        x = (*x, usable_drift(x, g.drift())[0])
    if extra is not None:
        # only the directions of the arm's columns that stand beside the rigid + linear ones: a direction almost
        # inside them is, beside them, the measured positions' own noise, and fitting it fits the noise (the
        # estimate fell to 0.6 of the truth; `usable`)
        wide = (*x, usable(x, g._cols(extra[:, inl]), kept=1e-4)[0])
        if 3 * len(inl) - np.linalg.matrix_rank(as_array(wide)) >= max(6, len(inl) // 2):
            x = wide  # else the arm's columns would leave too few degrees of freedom: rigid + linear (+ drift) only
    q = orth(x)
    y = g.vec(r - p)
    rr = (y - q @ (q.T @ y)).reshape(len(inl), 3)
    qb = q.reshape(len(inl), 3, -1)
    blocks = len(inl) * np.eye(3) - np.einsum("nak,nbk->ab", qb, qb)
    ev, vec = np.linalg.eigh(blocks)
    bi = vec @ np.diag(1 / np.sqrt(np.clip(ev, 1e-12, None))) @ vec.T
    nu = (3 * len(inl) - q.shape[1]) / 3.0
    return bi @ (rr.T @ rr) @ bi, nu, "fit"


def whitener(cov: np.ndarray) -> np.ndarray:
    ev, vec = np.linalg.eigh(cov)
    ev = np.clip(ev, 1e-12 * max(ev.max(), 1e-300), None)
    return vec @ np.diag(np.sqrt(ev.mean() / ev)) @ vec.T
