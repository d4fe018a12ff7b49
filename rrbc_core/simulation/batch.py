"""Monte Carlo kernels: registration and RRBC for T trials of one work cell at once.

A Monte Carlo run simulates T trials of the same cell (same point layout, new noise each trial), so every
point set is an array of shape (T, N, 3) (trial, point, xyz; mm; the project's convention robot = A @ sensor
+ t with points as rows). The functions here give the SAME numbers as calling the per-trial core functions in
a loop (`registration`, `rrbc`, `interpolation`) -- to rounding, ~1e-12 mm, well inside the 1e-9 mm that the
tests check -- but they work on all trials with a few numpy calls instead of one Python loop per trial.

Vectorised over trials:

- `least_squares_batch`: Kabsch/Umeyama with the reflection fix (batched `np.linalg.svd` on (T, 3, 3)),
  optional per-point weights shared by the trials, (N,), or per trial, (T, N). The per-trial function also
  projects its (already orthonormal) rotation onto SO(3) once more; that changes it by ~1e-16 and is skipped.
- `three_point_batch`: the 3-point frame of the first three points (Van Wyk & Marvel eqs. 1-5), using
  `registration.three_point_matrices`, which already works on a stack.
- `combinatorial_batch`: every 3-point subset of every trial at once (trials x subsets). Which subsets are
  rejected as nearly collinear is decided PER TRIAL with the same test as `registration.combinatorial`
  (sigma2/sigma1 >= degeneracy_ratio in both frames): a closed form classifies the clear cases and the
  borderline ones (within 0.1 % of the threshold) are decided by the same SVD the core uses. Element-wise
  (published) or chordal averaging.
- `annealing_batch`: T independent simulated-annealing chains advanced in lockstep. Chain k draws its
  proposals from `np.random.default_rng(seeds[k])` in exactly the order `registration.annealing(seed=seeds[k])`
  does (all normal steps, then all uniforms), and evaluates the cost with the same floating-point operations
  (stacked `matmul` runs the same BLAS kernel per trial as the 3x3 products of the core), so every
  accept/reject decision, and hence the result, matches the per-trial function. (A decision could only differ
  if a cost difference sat within one rounding error of a threshold, which needs noise-free data where the
  cost is itself rounding noise; tests and benchmark find the results bit-identical, noise-free data included.)
  Chains run in groups of up to 1024 and draw their proposals in blocks, so memory does not grow with T or
  `iterations`. seeds=None means seed k for trial k.
- `apply_batch` / `apply_inverse_batch`: A @ x + t and its inverse; the inverse solves A x = q - t (A may be
  an element-wise average, not a rotation) unless the caller flags A as rigid, then it uses Aᵀ like
  `RigidTransform.apply_inverse`.
- `idw_batch`: the rule of `interpolation.IDW` -- the k nearest fiducials by 3-D distance in each trial,
  weights 1/d^p, a query within `interpolation.EXACT_MM` of a fiducial takes its correction (the mean if
  several) -- on the (T, M, N) distances: `np.partition` finds each query's k-th nearest, the weights form a
  sparse (M, N) matrix per trial and one stacked matmul applies them. (As in the core, a tie for the k-th
  nearest fiducial is broken arbitrarily -- exactly k are used; with measured coordinates ties do not happen.)
- `rrbc_batch` with registration least-squares / three-point / combinatorial / annealing and interpolation
  idw / none: the whole RRBC chain (register, corrections e_i = mapping⁻¹(b_i) − s_i, ê at the queries,
  b̂ = mapping(x + ê)) is vectorised.

Falls back to a per-trial loop over the core functions (correct first, fast where it matters):

- registration 'clustering' (a piecewise map with per-trial k-means): `registration.clustering`,
  `rrbc.fiducial_corrections`, the interpolator's fit/predict and `rrbc.correct_points`, trial by trial;
- interpolation 'linear', 'tps', 'gp' (Delaunay / RBF / REML fits per trial): the registration, the
  corrections at the fiducials and the mapping of the targets stay vectorised; only the interpolator is
  fitted and evaluated per trial (`interpolation.make_interpolator(...).fit(...).predict(...)`).
- the extrapolation flags with hull='trial' (a Delaunay hull per trial, `interpolation.hull_flags`). The
  default hull='mean' flags the queries once against the hull of the trial-mean fiducial layout, shape (M,).

Large T is processed in chunks of trials, so temporary arrays stay small (bounded memory, cache friendly).
Inputs are validated like the core does (bad shapes, non-finite values, fewer than 3 registration points,
coincident or nearly collinear registration points in any trial, bad weights / seeds / options); every
problem raises `InputError`, naming the trial where it is a per-trial problem.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
from scipy.spatial import cKDTree

from rrbc_core.geometry import points as geometry
from rrbc_core import registration
from rrbc_core.registration import STRATEGY_OPTIONS
from rrbc_core import interpolation as interp_mod
from rrbc_core.errors import InputError
from rrbc_core.interpolation import EXACT_MM
from rrbc_core.correction.rrbc import correct_points, fiducial_corrections
from rrbc_core.runtime.threads import thread_limited
from rrbc_core.geometry.transforms import project_to_so3

#: Elements per temporary array: trials are processed in chunks so memory stays bounded (and in cache).
_CHUNK_ELEMENTS = 250_000
#: Annealing chains advanced in lockstep per group (bounds memory; larger groups amortise Python overhead).
_ANNEALING_GROUP = 1024
_HULL_MODES = ("mean", "trial", "none")


# ------------------------------------------------------------------------------------------------------
# Input checks
# ------------------------------------------------------------------------------------------------------
def _as_float(x, what: str) -> np.ndarray:
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be numbers (mm)") from None


def _stack(points, what: str, trials: int | None = None, shared: bool = False, finite: bool = True) -> np.ndarray:
    """(T, N, 3) finite float array; with shared=True a (N, 3) array is broadcast to all `trials`. finite=False:
    the caller checks the values (the compiled kernel reports them, `_raise_non_finite`)."""
    p = _as_float(points, what)
    if shared and p.ndim == 2 and trials is not None:
        p = np.broadcast_to(p, (trials,) + p.shape)
    if p.ndim != 3 or p.shape[2] != 3:
        form = "T x N x 3 (or N x 3, shared by every trial)" if shared else "T x N x 3"
        raise InputError(f"{what} must be a {form} array of coordinates (trial, point, xyz; mm), got shape {p.shape}")
    if p.shape[0] == 0:
        raise InputError(f"{what}: no trials given (the first axis is empty)")
    if trials is not None and p.shape[0] != trials:
        raise InputError(f"{what} have {p.shape[0]} trials, expected {trials} like the registration points")
    if not finite:
        return p
    with np.errstate(over="ignore", invalid="ignore"):
        maybe_bad = not np.isfinite(p.sum())  # one pass; finite values can only overflow the sum (then look)
    if maybe_bad:
        _raise_non_finite(np.isfinite(p).all(axis=(1, 2)), what)
    return p


def _raise_non_finite(finite: np.ndarray, what: str) -> None:
    """InputError naming the first trial whose `what` hold a non-finite coordinate (finite: (T,) bool)."""
    if not finite.all():
        raise InputError(f"trial {int(np.argmin(finite))}: {what} contain a non-finite coordinate (NaN or infinity)")


def _check_registration_batch(points: np.ndarray, what: str, minimum: int = 3, deviation=None) -> None:
    """`geometry.check_registration_points` for every trial of a validated (T, N, 3) stack.

    Screens find the trials that might fail; the core check then decides those trials, so the decision and the
    message are the core's. First screen (Monte Carlo trials scatter around one layout): against the trial-mean
    layout, with f_t = ‖p_t − p̄‖_F the trial's deviation from it, every pair of points is at least d̄_min − 2 f_t
    apart and each singular value of the centred points moves by at most f_t (Weyl), so a trial whose bounds
    clear 2x the coincidence distance and the collinearity ratio (with a rounding margin) passes. The trials it
    cannot clear go through closed-form per-trial screens (closest pair from the Gram matrix; a lower bound on
    sigma2/sigma1), then the core check. deviation (T,): f_t measured from trial 0's layout instead (the bounds
    hold for any reference layout; the compiled kernel reports it), which saves the pass over the data.
    """
    trials, n = points.shape[:2]
    if n < minimum:
        raise InputError(f"{what}: {n} given, at least {minimum} distinct points are needed")
    if deviation is None:
        mean = points.mean(axis=0)
        dev = points - mean
        f = np.sqrt(np.einsum("tnc,tnc->t", dev, dev))
    else:
        mean, f = points[0], np.asarray(deviation, float)
    f = f * (1 + 1e-9) + 1e-9
    sv = np.linalg.svd(mean - mean.mean(axis=0), compute_uv=False)
    dmin = float(cKDTree(mean).query(mean, k=2)[0][:, 1].min())
    clear = (dmin - 2 * f >= 2 * geometry.COINCIDENT_MM) & (sv[1] - f >= 1.5 * geometry.COLLINEAR_RATIO * (sv[0] + f))
    rest = np.flatnonzero(~clear)
    if len(rest) == 0:
        return
    sub = points[rest]
    c = sub - sub.mean(axis=1, keepdims=True)
    # closest pair: |ci - cj|² = |ci|² + |cj|² - 2 ci·cj (a screen: rounding ~1e-16 |c|² is covered by the margin)
    sq = np.einsum("tnc,tnc->tn", c, c)
    d2 = np.matmul(c, np.swapaxes(c, 1, 2))
    d2 *= -2.0
    d2 += sq[:, :, None]
    d2 += sq[:, None, :]
    d2 += np.diag(np.full(n, np.inf))
    margin = (2 * geometry.COINCIDENT_MM) ** 2 + 1e-13 * sq.max(axis=1)
    suspicious = ~(d2.reshape(len(rest), n * n).min(axis=1) >= margin)
    # collinearity: with S = CᵀC (eigenvalues l1 >= l2 >= l3), c2 = sum of principal 2x2 minors <= 3 l1 l2 and
    # trace >= l1, so l2 / l1 >= c2 / (3 trace²).
    tr, c2 = _trace_and_minors(c)
    with np.errstate(invalid="ignore", divide="ignore"):
        bound = c2 / (3.0 * tr * tr)
    suspicious |= ~(bound >= (1.5 * geometry.COLLINEAR_RATIO) ** 2)
    for k in rest[suspicious]:
        try:
            geometry.check_registration_points(points[k], what, minimum)
        except InputError as exc:
            raise InputError(f"trial {k}: {exc}") from None


def _check_pair_batch(sensor, robot, minimum: int = 3) -> tuple[np.ndarray, np.ndarray]:
    s = _stack(sensor, "sensor registration points")
    r = _stack(robot, "robot registration points", trials=s.shape[0])
    if s.shape != r.shape:
        raise InputError(
            f"sensor and robot registration points must pair up: {s.shape[1]} sensor vs {r.shape[1]} robot points"
        )
    _check_registration_batch(s, "sensor registration points", minimum)
    _check_registration_batch(r, "robot registration points", minimum)
    return s, r


def _check_transform(matrix, translation) -> tuple[np.ndarray, np.ndarray]:
    a = _as_float(matrix, "mapping matrices")
    t = _as_float(translation, "mapping translations")
    if a.ndim != 3 or a.shape[1:] != (3, 3) or a.shape[0] == 0 or t.shape != (a.shape[0], 3):
        raise InputError(
            f"a batch of mappings is a T x 3 x 3 matrix stack and a T x 3 translation stack, got {a.shape} and {t.shape}"
        )
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(t))):
        raise InputError("the mapping matrices and translations must be finite")
    return a, t


def _check_weights(weights, trials: int, n: int) -> np.ndarray | None:
    if weights is None:
        return None
    w = _as_float(weights, "weights")
    if w.shape == (n,):
        w = np.broadcast_to(w, (trials, n))
    if w.shape != (trials, n) or not np.all(np.isfinite(w)) or np.any(w < 0) or np.any(np.count_nonzero(w, axis=1) < 3):
        raise InputError(
            "weights must be one finite non-negative number per point (shape N, or T x N for per-trial weights), "
            "at least 3 positive in every trial"
        )
    return w


def _check_seeds(seeds, trials: int) -> np.ndarray:
    """One non-negative integer seed per trial; None means seed k for trial k."""
    if seeds is None:
        return np.arange(trials)
    a = np.asarray(seeds)
    if a.shape != (trials,) or not np.issubdtype(a.dtype, np.integer):
        raise InputError(f"seeds must be one integer per trial, shape ({trials},); got {a.dtype} of shape {a.shape}")
    if np.any(a < 0):
        raise InputError("seeds must be non-negative integers")
    return a


def _ratio_option(value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not (0.0 <= v < 1.0) or isinstance(value, bool):
        raise InputError(f"degeneracy_ratio must be a number in [0, 1), got {value!r}")
    return v


def _finite(method: str, a: np.ndarray, t: np.ndarray):
    """The core's last check (`registration._finish`): no NaN / infinite mapping in any trial."""
    with np.errstate(over="ignore", invalid="ignore"):
        if np.isfinite(a.sum() + t.sum()):
            return a, t
    ok = np.isfinite(a).all(axis=(1, 2)) & np.isfinite(t).all(axis=1)
    if not ok.all():
        k = int(np.argmin(ok))
        raise InputError(f"trial {k}: {method}: the registration is numerically degenerate for these points")
    return a, t


def _average_name(average: str) -> str:
    if average not in ("elementwise", "chordal"):
        raise InputError(f"unknown averaging '{average}': use 'elementwise' (as published) or 'chordal'")
    return average


def _chunks(trials: int, per_trial_elements: int):
    size = max(1, _CHUNK_ELEMENTS // max(per_trial_elements, 1))
    for start in range(0, trials, size):
        yield slice(start, min(start + size, trials))


# ------------------------------------------------------------------------------------------------------
# Mapping points
# ------------------------------------------------------------------------------------------------------
def _apply(a, t, p):
    return np.matmul(p, np.swapaxes(a, 1, 2)) + t[:, None, :]


def _apply_inverse(a, t, p, rigid):
    q = p - t[:, None, :]
    if rigid:
        return np.matmul(q, a)
    return np.swapaxes(np.linalg.solve(a, np.swapaxes(q, 1, 2)), 1, 2)


def apply_batch(matrix, translation, points) -> np.ndarray:
    """Sensor → robot for every trial: points (T, M, 3) (or (M, 3) shared) → A_k @ x + t_k, (T, M, 3) mm."""
    a, t = _check_transform(matrix, translation)
    p = _stack(points, "points", trials=a.shape[0], shared=True)
    return _apply(a, t, p)


def apply_inverse_batch(matrix, translation, points, rigid: bool = False) -> np.ndarray:
    """Robot → sensor for every trial: solves A_k x = q − t_k (A may be a non-orthogonal element-wise average).

    rigid=True: the caller guarantees every A_k is a rotation; then x = A_kᵀ (q − t_k), as
    `RigidTransform.apply_inverse` computes it.
    """
    a, t = _check_transform(matrix, translation)
    p = _stack(points, "points", trials=a.shape[0], shared=True)
    return _apply_inverse(a, t, p, rigid)


# ------------------------------------------------------------------------------------------------------
# Least squares
# ------------------------------------------------------------------------------------------------------
def _det3(m):
    """Determinants of a (T, 3, 3) stack, by cofactors."""
    return (
        m[:, 0, 0] * (m[:, 1, 1] * m[:, 2, 2] - m[:, 1, 2] * m[:, 2, 1])
        - m[:, 0, 1] * (m[:, 1, 0] * m[:, 2, 2] - m[:, 1, 2] * m[:, 2, 0])
        + m[:, 0, 2] * (m[:, 1, 0] * m[:, 2, 1] - m[:, 1, 1] * m[:, 2, 0])
    )


def _kabsch(s, r, w=None):
    """Batched `registration.kabsch` (no scale). s, r (T, N, 3); w None or (T, N) non-negative."""
    n = s.shape[1]
    w = np.full(s.shape[:2], 1.0 / n) if w is None else w / w.sum(axis=1, keepdims=True)
    ps = np.matmul(w[:, None, :], s)  # (T, 1, 3)
    pr = np.matmul(w[:, None, :], r)
    sc = s - ps
    rc = r - pr
    h = np.matmul(np.swapaxes(sc * w[:, :, None], 1, 2), rc)  # H = Σ w p' q'ᵀ
    u, _, vt = np.linalg.svd(h)
    v = np.swapaxes(vt, 1, 2)
    ut = np.swapaxes(u, 1, 2)
    # the core's sign of det(V Uᵀ) = det(V) det(U) = ±1 (orthogonal factors: never near the 0 threshold)
    d = np.where(_det3(u) * _det3(vt) >= 0, 1.0, -1.0)
    v = v.copy()
    v[:, :, 2] *= d[:, None]
    rot = np.matmul(v, ut)
    t = pr[:, 0, :] - np.matmul(rot, ps[:, 0, :, None])[:, :, 0]
    return rot, t


def least_squares_batch(sensor, robot, weights=None) -> tuple[np.ndarray, np.ndarray]:
    """`registration.least_squares` for every trial: (R (T, 3, 3) proper rotations, t (T, 3) mm).

    sensor, robot: (T, N, 3) paired registration points. weights: None, (N,) shared or (T, N) per trial.
    """
    s, r = _check_pair_batch(sensor, robot)
    w = _check_weights(weights, s.shape[0], s.shape[1])
    return _finite("least-squares", *_kabsch(s, r, w))


# ------------------------------------------------------------------------------------------------------
# Three-point frame
# ------------------------------------------------------------------------------------------------------
def _three_point(s, r):
    h = registration.three_point_matrices(s[:, :3], r[:, :3])
    return project_to_so3(h[:, :3, :3]), h[:, :3, 3].copy()


def three_point_batch(sensor, robot) -> tuple[np.ndarray, np.ndarray]:
    """`registration.three_point` for every trial (first three points): (R (T, 3, 3), t (T, 3))."""
    s, r = _check_pair_batch(sensor, robot)
    _check_registration_batch(s[:, :3], "the first three sensor registration points")
    _check_registration_batch(r[:, :3], "the first three robot registration points")
    return _finite("three-point", *_three_point(s, r))


# ------------------------------------------------------------------------------------------------------
# Combinatorial averaging
# ------------------------------------------------------------------------------------------------------
def _trace_and_minors(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For centred stacks c (K, n, 3): trace and sum of principal 2x2 minors of S = cᵀc, per stack."""
    s = np.matmul(np.swapaxes(c, 1, 2), c)
    tr = s[:, 0, 0] + s[:, 1, 1] + s[:, 2, 2]
    c2 = (
        s[:, 0, 0] * s[:, 1, 1] - s[:, 0, 1] ** 2
        + s[:, 0, 0] * s[:, 2, 2] - s[:, 0, 2] ** 2
        + s[:, 1, 1] * s[:, 2, 2] - s[:, 1, 2] ** 2
    )
    return tr, c2


def _subset_ok(triples: np.ndarray, ratio: float) -> np.ndarray:
    """collinear_ratio_batch(triples) >= ratio for a (K, 3, 3) stack, deciding borderline cases by the SVD.

    A triple's centred points span at most a plane, so the eigenvalues of S = CᵀC are l1 >= l2 (and l3 = 0):
    l1 = tr/2 + sqrt(tr²/4 − c2), l2 = c2 / l1, sigma2/sigma1 = sqrt(l2/l1). Clear cases (more than 0.1 %
    from the threshold) are decided by this closed form, the rest by `geometry.collinear_ratio_batch`.
    """
    c = triples - triples.mean(axis=1, keepdims=True)
    tr, c2 = _trace_and_minors(c)
    with np.errstate(invalid="ignore", divide="ignore"):
        l1 = 0.5 * tr + np.sqrt(np.maximum(0.25 * tr * tr - c2, 0.0))
        est = np.sqrt(np.maximum(c2, 0.0) / l1) / np.sqrt(l1)
    ok = est >= ratio * (1 + 1e-3)
    unsure = ~ok & ~(est < ratio * (1 - 1e-3))
    if np.any(unsure):
        ok[unsure] = geometry.collinear_ratio_batch(triples[unsure]) >= ratio
    return ok


def _combinatorial(s, r, average, degeneracy_ratio, method="combinatorial"):
    """Batched `registration.combinatorial`: (A (T, 3, 3), t (T, 3)); A is a rotation for 'chordal'."""
    trials, n = s.shape[:2]
    registration.check_subset_count(n, method)
    combos = np.array(list(combinations(range(n), 3)))
    k = len(combos)
    a_out = np.empty((trials, 3, 3))
    t_out = np.empty((trials, 3))
    for sl in _chunks(trials, k * 48):
        st = s[sl][:, combos].reshape(-1, 3, 3)  # (Tc*K, 3, 3)
        rt = r[sl][:, combos].reshape(-1, 3, 3)
        tc = len(st) // k
        ok = (_subset_ok(st, degeneracy_ratio) & _subset_ok(rt, degeneracy_ratio)).reshape(tc, k)
        n_ok = ok.sum(axis=1)
        if np.any(n_ok == 0):
            bad = sl.start + int(np.argmin(n_ok))
            raise InputError(
                f"trial {bad}: combinatorial registration: every 3-point subset is nearly collinear "
                f"(sigma2/sigma1 < {degeneracy_ratio}); spread the registration points"
            )
        with np.errstate(invalid="ignore", divide="ignore"):
            mats = registration.three_point_matrices(st, rt).reshape(tc, k, 4, 4)
        mats = np.where(ok[:, :, None, None], mats, 0.0)
        if average == "elementwise":
            m = mats.sum(axis=1) / n_ok[:, None, None]
            a_out[sl] = m[:, :3, :3]
            t_out[sl] = m[:, :3, 3]
        else:
            wts = ok / n_ok[:, None]
            rot = project_to_so3(np.einsum("tk,tkij->tij", wts, mats[:, :, :3, :3]))
            origin = s[sl].mean(axis=1)
            images = np.einsum("tkij,tj->tki", mats[:, :, :3, :3], origin) + mats[:, :, :3, 3]
            a_out[sl] = rot
            t_out[sl] = images.sum(axis=1) / n_ok[:, None] - np.einsum("tij,tj->ti", rot, origin)
    return a_out, t_out


def combinatorial_batch(
    sensor, robot, average: str = "elementwise", degeneracy_ratio: float = geometry.SUBSET_DEGENERACY_RATIO
) -> tuple[np.ndarray, np.ndarray]:
    """`registration.combinatorial` for every trial: (A (T, 3, 3), t (T, 3)).

    The subsets kept are chosen per trial exactly as the core does. average='elementwise' (published): A is
    the element-wise mean, close to but not exactly a rotation (invert with `apply_inverse_batch(...,
    rigid=False)`); average='chordal': A is a rotation.
    """
    average = _average_name(average)
    ratio = _ratio_option(degeneracy_ratio)
    s, r = _check_pair_batch(sensor, robot)
    return _finite("combinatorial", *_combinatorial(s, r, average, ratio))


# ------------------------------------------------------------------------------------------------------
# Simulated annealing
# ------------------------------------------------------------------------------------------------------
class _Euler:
    """Stacks of R = Rz(α) Ry(β) Rx(γ) built with the same operations as `rotation_from_euler_zyx`."""

    def __init__(self, trials):
        self.rz = np.zeros((trials, 3, 3))
        self.ry = np.zeros((trials, 3, 3))
        self.rx = np.zeros((trials, 3, 3))
        self.rz[:, 2, 2] = 1.0
        self.ry[:, 1, 1] = 1.0
        self.rx[:, 0, 0] = 1.0

    def __call__(self, alpha, beta, gamma):
        ca, sa = np.cos(alpha), np.sin(alpha)
        cb, sb = np.cos(beta), np.sin(beta)
        cg, sg = np.cos(gamma), np.sin(gamma)
        rz, ry, rx = self.rz, self.ry, self.rx
        rz[:, 0, 0] = ca
        rz[:, 0, 1] = -sa
        rz[:, 1, 0] = sa
        rz[:, 1, 1] = ca
        ry[:, 0, 0] = cb
        ry[:, 0, 2] = sb
        ry[:, 2, 0] = -sb
        ry[:, 2, 2] = cb
        rx[:, 1, 1] = cg
        rx[:, 1, 2] = -sg
        rx[:, 2, 1] = sg
        rx[:, 2, 2] = cg
        return np.matmul(np.matmul(rz, ry), rx)


def _annealing(s, r, a0, t0, seeds, iterations, cooling_c):
    """Batched `registration.annealing` from the initial mappings (a0, t0); returns (A, t).

    The chains are independent: they are run in groups of at most _ANNEALING_GROUP trials, each group in
    lockstep, with the proposals drawn in blocks of iterations so that memory stays bounded."""
    a_out = np.empty(a0.shape)
    t_out = np.empty(t0.shape)
    for start in range(0, len(s), _ANNEALING_GROUP):
        sl = slice(start, start + _ANNEALING_GROUP)
        a_out[sl], t_out[sl] = _annealing_group(s[sl], r[sl], a0[sl], t0[sl], seeds[sl], iterations, cooling_c)
    return a_out, t_out


def _annealing_group(s, r, a0, t0, seeds, iterations, cooling_c):
    trials, n = s.shape[:2]
    mapped = _apply(a0, t0, s)
    res = r - mapped
    fre0 = np.maximum(np.sqrt(np.mean(np.sum(res**2, axis=2), axis=1)), 1e-6)
    radius = np.sqrt(np.mean(np.sum((s - s.mean(axis=1, keepdims=True)) ** 2, axis=2), axis=1))
    step = np.empty((trials, 6))
    step[:, :3] = (fre0 / 4)[:, None]
    step[:, 3:] = (fre0 / (4 * radius))[:, None]
    euler = _Euler(trials)

    def cost(theta):  # theta (6, T), rows contiguous; the core's float(np.sum((r - mod.apply(mapped)) ** 2))
        rot = euler(theta[3], theta[4], theta[5])
        moved = np.matmul(mapped, np.swapaxes(rot, 1, 2)) + theta[:3].T[:, None, :]
        return ((r - moved) ** 2).reshape(trials, 3 * n).sum(axis=1)

    # Each chain's generator: normals first (iterations x 6), then uniforms (iterations), as in the core;
    # a second generator per chain is advanced past the normals to deliver the uniforms block by block.
    gen_normal = [np.random.default_rng(int(sd)) for sd in seeds]
    gen_uniform = []
    for sd in seeds:
        g = np.random.default_rng(int(sd))
        for done in range(0, iterations, 65536):
            g.normal(size=(min(65536, iterations - done), 6))
        gen_uniform.append(g)

    theta = np.zeros((6, trials))
    c_cur = cost(theta)
    best, c_best = theta.copy(), c_cur.copy()
    block = max(1, min(iterations, 4 * _CHUNK_ELEMENTS // (7 * trials)))
    for start in range(0, iterations, block):
        b = min(block, iterations - start)
        steps = np.stack([g.normal(size=(b, 6)) for g in gen_normal]) * step[:, None, :]  # (T, b, 6)
        steps = np.ascontiguousarray(np.transpose(steps, (1, 2, 0)))  # (b, 6, T)
        uniforms = np.ascontiguousarray(np.stack([g.random(b) for g in gen_uniform]).T)  # (b, T)
        for j in range(b):
            tau = start + j + 2
            temp = 1.0 / (cooling_c * np.log(tau))
            cand = theta + steps[j]
            c_new = cost(cand)
            delta = c_new - c_cur
            with np.errstate(over="ignore"):
                acc = (delta < 0) | (uniforms[j] < np.exp(-delta / temp))
            if not np.any(acc):
                continue
            theta = np.where(acc, cand, theta)
            c_cur = np.where(acc, c_new, c_cur)
            better = acc & (c_cur < c_best)
            if np.any(better):
                best = np.where(better, theta, best)
                c_best = np.where(better, c_cur, c_best)
    rot = euler(best[3], best[4], best[5])  # the core: _compose_modifier(_modifier(best), initial mapping)
    return np.matmul(rot, a0), np.matmul(rot, t0[:, :, None])[:, :, 0] + best[:3].T


def annealing_batch(
    sensor, robot, seeds=None, iterations: int = 5000, cooling_c: float = 2.0, initial=None
) -> tuple[np.ndarray, np.ndarray]:
    """`registration.annealing(seed=seeds[k])` for every trial k, chains advanced in lockstep: (A, t).

    seeds: (T,) non-negative integers (None: seed k for trial k). initial: None (the core's default, the
    element-wise combinatorial registration of each trial; A is then not exactly a rotation) or a pair
    (A0 (T, 3, 3), t0 (T, 3)) to refine, e.g. from `least_squares_batch` (the result is then rigid).
    """
    s, r = _check_pair_batch(sensor, robot)
    seeds = _check_seeds(seeds, s.shape[0])
    iterations, cooling_c = _annealing_options(iterations, cooling_c)
    if initial is None:
        a0, t0 = _finite("combinatorial", *_combinatorial(s, r, "elementwise", geometry.SUBSET_DEGENERACY_RATIO,
                                                      "annealing (from the combinatorial average)"))
    else:
        try:
            a0, t0 = initial
        except (TypeError, ValueError):
            raise InputError("initial must be None or a pair (A (T, 3, 3), t (T, 3))") from None
        a0, t0 = _check_transform(a0, t0)
        if a0.shape[0] != s.shape[0]:
            raise InputError(f"initial has {a0.shape[0]} trials, the points have {s.shape[0]}")
    return _finite("annealing", *_annealing(s, r, a0, t0, seeds, iterations, cooling_c))


def _annealing_options(iterations, cooling_c):
    numbers = (int, float, np.integer, np.floating)
    if (
        isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 1
        or isinstance(cooling_c, bool) or not isinstance(cooling_c, numbers)
        or not np.isfinite(cooling_c) or cooling_c <= 0
    ):
        raise InputError("annealing needs iterations >= 1 and cooling constant C > 0")
    return int(iterations), cooling_c


# ------------------------------------------------------------------------------------------------------
# Inverse distance weighting
# ------------------------------------------------------------------------------------------------------
def _sq_distances(q, f):
    """Squared distances (T, M, N) between queries (T, M, 3) and fiducials (T, N, 3), each a sum of three
    squared coordinate differences (the core's np.linalg.norm / cKDTree arithmetic). Computed with the trials
    on the last axis, where numpy's loops are long, then laid out (T, M, N)."""
    qt = np.transpose(q, (2, 1, 0)).copy()  # (3, M, T)
    ft = np.transpose(f, (2, 1, 0)).copy()  # (3, N, T)
    d2 = np.subtract(qt[0][:, None, :], ft[0][None, :, :])
    d2 *= d2
    diff = np.empty_like(d2)
    for c in (1, 2):
        np.subtract(qt[c][:, None, :], ft[c][None, :, :], out=diff)
        diff *= diff
        d2 += diff
    return np.ascontiguousarray(np.transpose(d2, (2, 0, 1)))


def _idw(fid, corr, query, k, power):
    """Batched `interpolation.IDW(k, power)` predictions (T, M, 3); inputs validated, k >= 1, power > 0.

    Per trial and query, the k-th smallest squared distance (np.partition over the (T, M, N) distances)
    selects the k nearest fiducials; rows with a tie at the k-th place (where the core keeps k of the tied
    fiducials, arbitrarily) are cut back to exactly k with np.argpartition. The weights d_j^-p of the chosen
    fiducials form a sparse (M, N) matrix per trial, applied with one matmul to [corrections | 1], which also
    gives the normaliser. For power > 2 the weights are written (d_min / d_j)^p, as in the core, so that they
    never overflow. Queries with a weight above (2 EXACT_MM)^-p are checked against every fiducial: those
    within EXACT_MM of one take its correction (the mean if several), as in the core.
    """
    trials, n = fid.shape[:2]
    m = query.shape[1]
    k = min(k, n)
    out = np.empty((trials, m, 3))
    if m == 0:
        return out
    half_power = 0.5 * power
    near_weight = (2 * EXACT_MM) ** -power
    for sl in _chunks(trials, m * n * 8):
        f, e, q = fid[sl], corr[sl], query[sl]
        tc = f.shape[0]
        d2 = _sq_distances(q, f)
        if k < n:
            part = np.partition(d2, k - 1, axis=2)
            chosen = d2 <= part[:, :, k - 1 : k]
            if np.count_nonzero(chosen) > tc * m * k:  # a tie at the k-th place somewhere
                tied = np.count_nonzero(chosen, axis=2) > k
                ti, mi = np.nonzero(tied)
                idx = np.argpartition(d2[ti, mi], k - 1, axis=1)[:, :k]
                chosen[ti, mi] = False
                chosen[ti[:, None], mi[:, None], idx] = True
        else:
            part = d2
            chosen = None
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if power == 2.0:
                w = (1.0 / d2) if chosen is None else chosen / d2
                scale = 1.0
            elif power <= 2.0:
                w = np.power(d2, -half_power)
                scale = 1.0
            else:  # (d_min / d_j)^p: in (0, 1], no overflow
                d2min = part[:, :, :k].min(axis=2, keepdims=True)
                w = np.power(d2min / d2, half_power)
                scale = np.power(d2min[:, :, 0], -half_power)  # back to d^-p, only for the near test
            if chosen is not None and power != 2.0:
                w *= chosen
            e1 = np.concatenate([e, np.ones((tc, n, 1))], axis=2)
            acc = np.matmul(w, e1)  # (Tc, M, 4): Σ w_j e_j and Σ w_j
            res = acc[:, :, :3] / acc[:, :, 3:]
            near = ~(acc[:, :, 3] * scale <= near_weight)  # nearest fiducial closer than 2 EXACT_MM (or d = 0)
        if np.any(near):
            ti, mi = np.nonzero(near)
            on = np.sqrt(d2[ti, mi]) < EXACT_MM  # (P, N)
            cnt = on.sum(axis=1)
            hit = cnt > 0
            sums = np.einsum("pn,pnc->pc", on.astype(float), e[ti])
            res[ti[hit], mi[hit]] = sums[hit] / cnt[hit, None]
            if not np.all(hit):  # within 2 EXACT_MM but none within EXACT_MM: the core's weights (d0/dj)^p
                ti, mi = ti[~hit], mi[~hit]
                dd = np.sqrt(d2[ti, mi])
                sel = chosen[ti, mi] if chosen is not None else np.ones(dd.shape, dtype=bool)
                wr = np.where(sel, np.power(dd.min(axis=1, keepdims=True) / dd, power), 0.0)
                wr /= wr.sum(axis=1, keepdims=True)
                res[ti, mi] = np.einsum("pn,pnc->pc", wr, e[ti])
        out[sl] = res
    return out


def idw_batch(fid, corr, query, k: int = 4, power: float = 2.0) -> np.ndarray:
    """`interpolation.IDW(k, power).fit(fid[t], corr[t]).predict(query[t]).values` for every trial t.

    fid, corr: (T, N, 3) fiducial sensor positions and corrections (mm); query: (T, M, 3) or (M, 3) shared.
    Returns (T, M, 3) interpolated corrections, mm.
    """
    method = interp_mod.IDW(k=k, power=power)  # validates the options
    f = _stack(fid, "fiducial positions")
    e = _stack(corr, "fiducial corrections", trials=f.shape[0])
    if e.shape != f.shape:
        raise InputError(f"{f.shape[1]} fiducial positions but {e.shape[1]} correction vectors: give one per fiducial")
    if f.shape[1] == 0:
        raise InputError("no fiducials given: at least 1 is needed to interpolate corrections")
    q = _stack(query, "query points", trials=f.shape[0], shared=True)
    return _idw(f, e, q, method.k, method.power)


# ------------------------------------------------------------------------------------------------------
# The whole RRBC chain
# ------------------------------------------------------------------------------------------------------
def _register(method, s, r, seeds, options):
    """Vectorised registration: (A, t, rigid)."""
    if method == "least-squares":
        w = _check_weights(options.get("weights"), s.shape[0], s.shape[1])
        return (*_finite("least-squares", *_kabsch(s, r, w)), True)
    if method == "three-point":
        _check_registration_batch(s[:, :3], "the first three sensor registration points")
        _check_registration_batch(r[:, :3], "the first three robot registration points")
        return (*_finite("three-point", *_three_point(s, r)), True)
    if method == "combinatorial":
        average = _average_name(options.get("average", "elementwise"))
        ratio = _ratio_option(options.get("degeneracy_ratio", geometry.SUBSET_DEGENERACY_RATIO))
        return (*_finite("combinatorial", *_combinatorial(s, r, average, ratio)), average == "chordal")
    # annealing from the core's default start (element-wise combinatorial): a LinearMap
    iterations, cooling_c = _annealing_options(options.get("iterations", 5000), options.get("cooling_c", 2.0))
    a0, t0 = _finite("combinatorial", *_combinatorial(s, r, "elementwise", geometry.SUBSET_DEGENERACY_RATIO,
                                                      "annealing (from the combinatorial average)"))
    return (*_finite("annealing", *_annealing(s, r, a0, t0, seeds, iterations, cooling_c)), False)


@thread_limited
def rrbc_batch(
    registration: str,
    interpolation: str,
    reg_s,
    reg_b,
    fid_s,
    fid_b,
    query_s,
    seeds=None,
    registration_options: dict | None = None,
    hull: str = "mean",
    **interp_options,
) -> dict:
    """Registration + RRBC for T trials; equal to the per-trial pipeline (register, fiducial_corrections,
    make_interpolator(...).fit, correct_points) run on each trial.

    registration: 'least-squares', 'three-point', 'combinatorial', 'annealing' or 'clustering';
    interpolation: 'idw', 'linear', 'tps', 'gp' or 'none'; interp_options: the interpolator's options
    (idw: k, power; tps: smoothing; gp: kernel, noise_mm). registration_options: the strategy's options
    (least-squares: weights; combinatorial: average, degeneracy_ratio; annealing: iterations, cooling_c;
    clustering: clusters, average). seeds: (T,) integers for annealing / clustering (None: seed k for trial k).
    reg_s, reg_b: (T, Nr, 3) registration points (sensor, robot frame); fid_s, fid_b: (T, Nf, 3) fiducials
    (Nf may be 0 with interpolation 'none'); query_s: (T, M, 3) or (M, 3) targets / check points, sensor frame.
    hull: 'mean' (extrapolation flags of the queries against the hull of the trial-mean fiducials, shape (M,)),
    'trial' (per trial, exactly the core's flags, (T, M); a Delaunay hull per trial, slow) or 'none' (None).

    Returns a dict of arrays (mm): robot_rigid (T, M, 3) = mapping(x); robot_rrbc (T, M, 3) = mapping(x + ê);
    corrections (T, M, 3) = ê at the queries (sensor frame); fiducial_corrections (T, Nf, 3) = e_i;
    extrapolated (M,) or (T, M) bool, or None; matrix (T, 3, 3) and translation (T, 3) of the mapping
    (None for the piecewise 'clustering'); rigid: whether `matrix` is a rotation in every trial.
    """
    reg_name = str(registration).strip().lower()
    if reg_name not in STRATEGY_OPTIONS:
        raise InputError(f"unknown registration '{registration}': choose one of {', '.join(STRATEGY_OPTIONS)}")
    interp_name = str(interpolation).strip().lower()
    method = interp_mod.make_interpolator(interp_name, **interp_options)  # validates name and options
    options = dict(registration_options or {})
    unknown = sorted(set(options) - set(STRATEGY_OPTIONS[reg_name]))
    if unknown:
        takes = ", ".join(STRATEGY_OPTIONS[reg_name]) or "no options"
        raise InputError(f"registration '{reg_name}' does not take option(s) {', '.join(unknown)}; it takes: {takes}")
    if hull not in _HULL_MODES:
        raise InputError(f"unknown hull mode {hull!r}: choose one of {', '.join(_HULL_MODES)}")

    if reg_name == "least-squares" and interp_name == "idw" and options.get("weights") is None:
        return _ls_idw_compiled(reg_s, reg_b, fid_s, fid_b, query_s, method, hull)
    s, r = _check_pair_batch(reg_s, reg_b)
    trials = s.shape[0]
    fs = _stack(fid_s, "fiducial sensor points", trials=trials)
    fb = _stack(fid_b, "fiducial robot points", trials=trials)
    if fs.shape != fb.shape:
        raise InputError(f"fiducials must pair up: {fs.shape[1]} sensor vs {fb.shape[1]} robot points")
    if fs.shape[1] == 0 and interp_name != "none":
        raise InputError("no fiducials given: RRBC needs at least 1 fiducial (or use interpolation 'none')")
    q = _stack(query_s, "target sensor points", trials=trials, shared=True)
    seeds = _check_seeds(seeds, trials) if reg_name in ("annealing", "clustering") else None
    hull_points = fs if fs.shape[1] else s  # as the pipeline: no fiducials -> hull of the registration points

    if reg_name == "clustering":
        return _rrbc_per_trial(s, r, fs, fb, q, seeds, options, method, hull, hull_points)

    a, t, rigid = _register(reg_name, s, r, seeds, options)
    e_fid = _apply_inverse(a, t, fb, rigid) - fs
    extrapolated = None
    if interp_name == "idw":
        ehat = _idw(fs, e_fid, q, method.k, method.power)
    elif interp_name == "none":
        ehat = np.zeros(q.shape)
    else:
        ehat = np.empty(q.shape)
        flags = np.empty(q.shape[:2], dtype=bool)
        for k in range(trials):
            pred = method.fit(fs[k], e_fid[k]).predict(q[k])
            ehat[k] = pred.values
            flags[k] = pred.extrapolated
        if hull == "trial":
            extrapolated = flags
    if extrapolated is None:
        extrapolated = _hull_flags(hull, hull_points, q)
    robot_rigid = _apply(a, t, q)
    robot_rrbc = np.matmul(ehat, np.swapaxes(a, 1, 2))  # mapping(x + ê) = mapping(x) + A ê
    robot_rrbc += robot_rigid
    return {
        "robot_rigid": robot_rigid,
        "robot_rrbc": robot_rrbc,
        "corrections": ehat,
        "fiducial_corrections": e_fid,
        "extrapolated": extrapolated,
        "matrix": a,
        "translation": t,
        "rigid": rigid,
    }


def _ls_idw_compiled(reg_s, reg_b, fid_s, fid_b, query_s, method, hull) -> dict:
    """rrbc_batch for least squares (unweighted) + IDW: the compiled kernel (`compiled.ls_idw`), with the same
    checks and messages as the general path, made on the kernel's by-products in the general path's order."""
    from rrbc_core.simulation.compiled import ls_idw

    names = ("sensor registration points", "robot registration points", "fiducial sensor points",
             "fiducial robot points", "target sensor points")
    s = _stack(reg_s, names[0], finite=False)
    trials = s.shape[0]
    r = _stack(reg_b, names[1], trials=trials, finite=False)
    if s.shape != r.shape:
        raise InputError(
            f"sensor and robot registration points must pair up: {s.shape[1]} sensor vs {r.shape[1]} robot points")
    if s.shape[1] < 3:
        _raise_non_finite(np.isfinite(s).all(axis=(1, 2)), names[0])
        _raise_non_finite(np.isfinite(r).all(axis=(1, 2)), names[1])
        _check_registration_batch(s, names[0])
    fs = _stack(fid_s, names[2], trials=trials, finite=False)
    fb = _stack(fid_b, names[3], trials=trials, finite=False)
    if fs.shape != fb.shape:
        raise InputError(f"fiducials must pair up: {fs.shape[1]} sensor vs {fb.shape[1]} robot points")
    q = _stack(query_s, names[4], trials=trials, shared=True, finite=False)
    out = ls_idw(s, r, fs, fb, q, method.k, method.power, EXACT_MM) if fs.shape[1] else None
    finite = out["finite"] if out is not None else np.stack(
        [np.isfinite(x).all(axis=(1, 2)) for x in (s, r, fs, fb, q)], axis=1)
    _raise_non_finite(finite[:, 0], names[0])
    _raise_non_finite(finite[:, 1], names[1])
    _check_registration_batch(s, names[0], deviation=None if out is None else out["deviation"][:, 0])
    _check_registration_batch(r, names[1], deviation=None if out is None else out["deviation"][:, 1])
    for i in (2, 3, 4):
        _raise_non_finite(finite[:, i], names[i])
    if out is None:
        raise InputError("no fiducials given: RRBC needs at least 1 fiducial (or use interpolation 'none')")
    _finite("least-squares", out["matrix"], out["translation"])
    if hull == "mean":
        out["extrapolated"] = interp_mod.hull_flags(out["fiducial_mean"], out["query_mean"])[0]
    else:
        out["extrapolated"] = _hull_flags(hull, fs, q)
    for key in ("finite", "deviation", "fiducial_mean", "query_mean"):
        del out[key]
    out["rigid"] = True
    return out


def _hull_flags(hull: str, hull_points: np.ndarray, q: np.ndarray):
    """Extrapolation flags: 'trial' (T, M), 'mean' (M,) against the trial-mean hull, 'none' None."""
    if hull == "trial":
        return np.array([interp_mod.hull_flags(hull_points[k], q[k])[0] for k in range(len(q))], dtype=bool)
    if hull == "mean":
        return interp_mod.hull_flags(hull_points.mean(axis=0), q.mean(axis=0))[0]
    return None


def _rrbc_per_trial(s, r, fs, fb, q, seeds, options, method, hull, hull_points) -> dict:
    """The per-trial loop over the core functions (clustering: one piecewise map per trial)."""
    trials, m = q.shape[:2]
    rigid_out = np.empty((trials, m, 3))
    rrbc_out = np.empty((trials, m, 3))
    ehat = np.empty((trials, m, 3))
    e_fid = np.empty(fs.shape)
    flags = np.empty((trials, m), dtype=bool)
    for k in range(trials):
        reg = registration.clustering(s[k], r[k], seed=int(seeds[k]), **options)
        if fs.shape[1]:
            e_fid[k] = fiducial_corrections(reg.mapping, fs[k], fb[k])
            fitted = method.fit(fs[k], e_fid[k])
        else:
            fitted = interp_mod.NoCorrection().fit(s[k], np.zeros_like(s[k]))
        out = correct_points(reg.mapping, fitted, q[k])
        rigid_out[k], rrbc_out[k], ehat[k], flags[k] = out.robot_rigid, out.robot_rrbc, out.correction, out.extrapolated
    if hull == "mean":
        extrapolated = interp_mod.hull_flags(hull_points.mean(axis=0), q.mean(axis=0))[0]
    else:
        extrapolated = flags if hull == "trial" else None
    return {
        "robot_rigid": rigid_out,
        "robot_rrbc": rrbc_out,
        "corrections": ehat,
        "fiducial_corrections": e_fid,
        "extrapolated": extrapolated,
        "matrix": None,
        "translation": None,
        "rigid": False,
    }
