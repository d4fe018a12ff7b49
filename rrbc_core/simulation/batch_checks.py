"""Input checks of the batch kernels (`batch`, `batch_registration`): (T, N, 3) stacks, registration sets in every
trial (screened, then decided by the core check so the decision and the message are the core's), mappings,
weights, seeds and options; and the chunking of trials. Every problem raises `InputError`, naming the trial."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from rrbc_core.errors import InputError
from rrbc_core.geometry import points as geometry

#: Elements per temporary array: trials are processed in chunks so memory stays bounded (and in cache).
_CHUNK_ELEMENTS = 250_000


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
# Combinatorial averaging
# ------------------------------------------------------------------------------------------------------
def _trace_and_minors(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For centred stacks c (K, n, 3): trace and sum of principal 2x2 minors of S = cᵀc, per stack."""
    s = np.matmul(np.swapaxes(c, 1, 2), c)
    tr = s[:, 0, 0] + s[:, 1, 1] + s[:, 2, 2]
    c2 = (
        s[:, 0, 0] * s[:, 1, 1]
        - s[:, 0, 1] ** 2
        + s[:, 0, 0] * s[:, 2, 2]
        - s[:, 0, 2] ** 2
        + s[:, 1, 1] * s[:, 2, 2]
        - s[:, 1, 2] ** 2
    )
    return tr, c2
