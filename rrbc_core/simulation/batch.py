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
- `annealing_batch`: T independent simulated-annealing chains, each run by a compiled loop
  (`compiled_annealing.anneal_chain`, numba). Chain k draws its proposals from `np.random.default_rng(seeds[k])`
  in exactly the order `registration.annealing(seed=seeds[k])` does (all normal steps, then all uniforms), and
  forms each rotation entry and each cost with the arithmetic of the core's 3x3 products, so every
  accept/reject decision, and hence the result, matches the per-trial function. (A decision could only differ
  if a cost difference sat within one rounding error of a threshold, which needs noise-free data where the
  cost is itself rounding noise; tests find the results equal to the core's, and `rrbc reproduce vanwyk2018`
  prints the same JSON as before the loop was compiled: benchmarks/reproduce_speed.py.) Memory per chain is
  its own proposals. seeds=None means seed k for trial k.
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

from typing import Any

import numpy as np

from rrbc_core import interpolation as interp_mod
from rrbc_core import registration
from rrbc_core.correction.rrbc import correct_points, fiducial_corrections
from rrbc_core.errors import InputError
from rrbc_core.geometry import points as geometry
from rrbc_core.interpolation import EXACT_MM
from rrbc_core.registration import STRATEGY_OPTIONS
from rrbc_core.runtime.threads import thread_limited
from rrbc_core.simulation.batch_checks import (
    _average_name,
    _check_pair_batch,
    _check_registration_batch,
    _check_seeds,
    _check_weights,
    _chunks,
    _finite,
    _raise_non_finite,
    _ratio_option,
    _stack,
)
from rrbc_core.simulation.batch_registration import (
    _annealing,
    _annealing_options,
    _apply,
    _apply_inverse,
    _combinatorial,
    _kabsch,
    _three_point,
    annealing_batch,
    apply_batch,
    apply_inverse_batch,
    combinatorial_batch,
    least_squares_batch,
    three_point_batch,
)

__all__ = [
    "annealing_batch",
    "apply_batch",
    "apply_inverse_batch",
    "combinatorial_batch",
    "idw_batch",
    "least_squares_batch",
    "rrbc_batch",
    "three_point_batch",
]

_HULL_MODES = ("mean", "trial", "none")


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
    a0, t0 = _finite(
        "combinatorial",
        *_combinatorial(
            s, r, "elementwise", geometry.SUBSET_DEGENERACY_RATIO, "annealing (from the combinatorial average)"
        ),
    )
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
    method: Any = interp_mod.make_interpolator(interp_name, **interp_options)  # validates name and options
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

    names = (
        "sensor registration points",
        "robot registration points",
        "fiducial sensor points",
        "fiducial robot points",
        "target sensor points",
    )
    s = _stack(reg_s, names[0], finite=False)
    trials = s.shape[0]
    r = _stack(reg_b, names[1], trials=trials, finite=False)
    if s.shape != r.shape:
        raise InputError(
            f"sensor and robot registration points must pair up: {s.shape[1]} sensor vs {r.shape[1]} robot points"
        )
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
    finite = (
        out["finite"]
        if out is not None
        else np.stack([np.isfinite(x).all(axis=(1, 2)) for x in (s, r, fs, fb, q)], axis=1)
    )
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
    extrapolated: np.ndarray | None
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
