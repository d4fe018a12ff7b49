"""Registration vectorised over Monte Carlo trials: least squares (Kabsch), three-point frames, combinatorial
averaging and simulated annealing for T trials at once, and mapping points with a stack of mappings. The same
numbers as the per-trial core functions (`registration`), to rounding; see `batch` for the whole chain."""

from __future__ import annotations

from itertools import combinations

import numpy as np

from rrbc_core import registration
from rrbc_core.errors import InputError
from rrbc_core.geometry import points as geometry
from rrbc_core.geometry.transforms import project_to_so3
from rrbc_core.simulation.batch_checks import (
    _average_name,
    _check_pair_batch,
    _check_registration_batch,
    _check_seeds,
    _check_transform,
    _check_weights,
    _chunks,
    _finite,
    _ratio_option,
    _stack,
    _trace_and_minors,
)


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

    The chains are independent; each runs compiled (`compiled_annealing.anneal_chain`) on the proposals and
    uniforms its own generator draws, in the core's order (all normals, then all uniforms)."""
    from rrbc_core.simulation.compiled_annealing import anneal_chain

    trials = len(s)
    mapped = _apply(a0, t0, s)
    res = r - mapped
    fre0 = np.maximum(np.sqrt(np.mean(np.sum(res**2, axis=2), axis=1)), 1e-6)
    radius = np.sqrt(np.mean(np.sum((s - s.mean(axis=1, keepdims=True)) ** 2, axis=2), axis=1))
    step = np.empty((trials, 6))
    step[:, :3] = (fre0 / 4)[:, None]
    step[:, 3:] = (fre0 / (4 * radius))[:, None]
    best = np.empty((6, trials))
    c = float(cooling_c)
    for k in range(trials):
        g = np.random.default_rng(int(seeds[k]))
        steps = g.normal(size=(iterations, 6)) * step[k]
        best[:, k] = anneal_chain(mapped[k], r[k], steps, g.random(iterations), c)
    rot = _Euler(trials)(best[3], best[4], best[5])  # the core: _compose_modifier(_modifier(best), initial mapping)
    return np.matmul(rot, a0), np.matmul(rot, t0[:, :, None])[:, :, 0] + best[:3].T


def annealing_batch(
    sensor, robot, seeds=None, iterations: int = 5000, cooling_c: float = 2.0, initial=None
) -> tuple[np.ndarray, np.ndarray]:
    """`registration.annealing(seed=seeds[k])` for every trial k, each chain compiled: (A, t).

    seeds: (T,) non-negative integers (None: seed k for trial k). initial: None (the core's default, the
    element-wise combinatorial registration of each trial; A is then not exactly a rotation) or a pair
    (A0 (T, 3, 3), t0 (T, 3)) to refine, e.g. from `least_squares_batch` (the result is then rigid).
    """
    s, r = _check_pair_batch(sensor, robot)
    seeds = _check_seeds(seeds, s.shape[0])
    iterations, cooling_c = _annealing_options(iterations, cooling_c)
    if initial is None:
        a0, t0 = _finite(
            "combinatorial",
            *_combinatorial(
                s, r, "elementwise", geometry.SUBSET_DEGENERACY_RATIO, "annealing (from the combinatorial average)"
            ),
        )
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
        isinstance(iterations, bool)
        or not isinstance(iterations, (int, np.integer))
        or iterations < 1
        or isinstance(cooling_c, bool)
        or not isinstance(cooling_c, numbers)
        or not np.isfinite(cooling_c)
        or cooling_c <= 0
    ):
        raise InputError("annealing needs iterations >= 1 and cooling constant C > 0")
    return int(iterations), cooling_c
