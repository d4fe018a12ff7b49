"""Fiducial planning: coverage of the targets' regions of variability, predicted RMS target error (RMST), and
suggested fiducial locations (issue 7; docs/theory.md §7; `rrbc plan`).

Frames and units
----------------
Every position passed in or returned is in the SCENE frame, the frame scene TOML files use: the ROBOT BASE frame,
in millimetres (`scene.py`, `scenes/README.md`). Errors are in mm. Internally the sensor readings are in the
sensor frame, as everywhere in the library.

Coverage
--------
`coverage(fiducials, regions)` (from `interpolation.hull`, the one coverage every caller uses): per region, the
fraction of its volume inside the fiducials' hull, estimated from seeded uniform samples tested with
`interpolation.hull_flags` (the same test RRBC's extrapolation flags use). For a coplanar (or collinear) fiducial set
a sample is inside when its projection is inside their polygon AND it lies within `plane_tol_mm` of their plane —
`OFF_PLANE_TOL_MM` (1 mm, the tolerance within which the library treats a point as on a surface), or the fiducials'
own largest distance from their plane if that is more — so a shallow region on a plate of fiducials is covered and a
region 100 mm above the plate is not.

Prediction (`predict_rmst`, trials=0: "first-order")
---------------------------------------------------
The model is the simulation's (`simulation.py`): a point p is read by the sensor as s = T⁻¹(p) + β_s + ε and by
the robot as b = p + β_r + η; a check point's truth is p + β_r; β are the error model's deterministic terms
(`ErrorModel.deterministic()`), ε, η its random terms (`ErrorModel.random_terms()`, covariances from
`ErrorModel.covariance`). Registration: least squares on the registration points; RRBC: IDW (k=4, p=2, the
scene default of `rrbc simulate` and of the explorer) over the fiducials. The RMST is taken over
`samples_per_target` check points sampled uniformly in each target's region of variability (seeded; the same
points `simulation.work_cell_from_scene` samples for the same seed), all targets weighted equally:

    RMST² = mean over check points q of ( |bias(q)|² + E|noise(q)|² ).

* Bias: EXACT, not linearised: the noise-free pipeline is run on the bias-only readings (registration
  `batch.least_squares_batch`, corrections e_i = T̂⁻¹(b_i) − s_i, IDW weights from `batch.idw_batch`).
  Rigid: T̂(s_q) − truth_q; RRBC: that plus R̂ Σ_i w_qi e_i.
* Noise: first order about the bias-only readings (docs/theory.md §0 error budget, §2.3). With J_q,j = ∂T̂(s_q)/∂b_j
  the sensitivity of the mapped point to registration point j (central differences of the vectorised
  least-squares fit; exact to ~1e-9 relative) and δ = R ε − η the net FLE (covariance Σ = R Σ_s Rᵀ + Σ_b):
      rigid:  err_q = −Σ_j J_q,j δ_j + R ε_q                    (Danilchenko & Fitzpatrick, any FLE covariance)
      RRBC:   err_q = −Σ_j G_q,j δ_j − Σ_i w_qi δ_i + R ε_q,    G_q,j = J_q,j − Σ_i w_qi J_i,j
  (a point that is both registration point and fiducial carries one δ in both sums). The noise of the target's
  own sensor reading, R Σ_s(q) Rᵀ, is included; robot noise is not part of the truth.
  Approximations: the dependence of the IDW weights on the noisy fiducial positions and the difference between
  R̂ and R in R̂ ê are dropped (both are products of the noise with the correction field's gradient, ~σ·|e|/d,
  with d the fiducial spacing: ~5e-4 of σ for the shipped scenes); cross terms bias × noise have zero mean to
  first order. Time-dependent terms (drift, warm-up; none in the shipped scenes) are evaluated at the times
  `simulation.work_cell_from_scene` gives (in `plan`'s optimiser: at the times of the full candidate cell).
* Uncertainty (rigid_std_mm, rrbc_std_mm): the standard error of the RMST from the finite sample of region points
  (stratified per target: var(MSE) = Σ_t s_t² / n_t / T², propagated as σ_MSE / (2 RMST)). It does not include
  the first-order truncation, which docs/theory.md §2.3 measured at 1–2 % of the noise term.

Prediction (trials > 0: "monte-carlo")
--------------------------------------
`simulation.work_cell_from_scene` + `simulation.measure` + `simulation.trial_errors` (vectorised `batch`
kernels) on the same check points, noise redrawn per trial, bias fixed. std: the Monte Carlo standard error of
the RMST, from the spread of the per-trial mean squared error (σ_MSE = sd_t / √T, propagated as above). The
finite region sample is common to both modes and is not part of this std.

Candidates and the optimiser
----------------------------
`usable_candidates(scene)` rejects candidates that are inside solid geometry (inside a closed mesh part, open3d
occupancy, and more than `SURFACE_TOL_MM` below that part's surface, so markers on a surface stay usable), hidden from
the sensor (ray cast against the cell mesh, `visibility.occluded_by`), or out of the arm's reach (the kinematic error
model cannot evaluate them). `plan(scene, add=K)` chooses up to K of the usable candidates. **The objective is the
fast predicted RMST with RRBC**, smaller is better; coverage only breaks ties. Greedy forward selection gives one set;
the simple rules give others — "hull-corners" (the usable candidates nearest the corners of the targets' bounding box,
corners taken in farthest-first order) and "random" (`RANDOM_DRAWS` seeded random K-subsets; the baseline reported is
their mean) — and exchange (swap a chosen candidate for an unused one while the prediction falls) starts from the best
of these. So a suggestion is never predicted worse than either rule's set. Adding fiducials can make RRBC worse (each
carries its noise into the targets near it): if no set of K is predicted to lower the RMST of the current fiducials
by more than `MIN_GAIN` (2 %, the first-order prediction's own accuracy), the best shorter prefix of the greedy path
that does is suggested, or nothing, and `PlanResult.note` says so.
(Coverage first, as an earlier version ranked, made cells worse: a hull-filling candidate can raise the RMST.)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from rrbc_core.analysis.planning_model import (
    _SAME_MM,
    IDW_K,
    IDW_POWER,
    SAMPLES_PER_TARGET,
    RmstPrediction,
    _points,
    _predict_fast,
    _predict_mc,
)
from rrbc_core.analysis.planning_search import (
    MIN_GAIN,
    SURFACE_TOL_MM,
    _corner_choice,
    _optimise,
    _pool,
    usable_candidates,
)
from rrbc_core.errors import InputError
from rrbc_core.interpolation.hull import OFF_PLANE_TOL_MM, assess_coverage, coverage, covered
from rrbc_core.runtime.threads import thread_limited

if TYPE_CHECKING:
    from rrbc_core.io.scene import Scene

__all__ = [
    "MIN_GAIN",
    "OFF_PLANE_TOL_MM",
    "IDW_K",
    "IDW_POWER",
    "RANDOM_DRAWS",
    "SAMPLES_PER_TARGET",
    "SURFACE_TOL_MM",
    "PlanResult",
    "RmstPrediction",
    "coverage",
    "plan",
    "predict_rmst",
    "usable_candidates",
]

#: At most this many fiducials suggested at once (`rrbc plan --add`): the search's work grows with K (each added
#: fiducial is chosen against every usable candidate and then exchanged), so a larger K is asked for in steps
MAX_ADD = 30
#: Random K-subsets averaged for the "random" baseline.
RANDOM_DRAWS = 32


@dataclass(frozen=True, eq=False)
class PlanResult:
    """The outcome of `plan` (positions: scene frame = robot base frame, mm).

    target_ids: in scene order. coverage / coverage_after: (T,) fraction of each target's region of variability
    inside the fiducials' hull before / after adding the suggestions. predicted / predicted_after: RMST before /
    after. suggested_ids, suggested (K, 3): the chosen candidates. rejected: candidate id -> reason.
    baselines: "hull-corners" / "random" -> RmstPrediction of the same K added by that rule (random: rrbc_mm is
    the mean over the draws, rrbc_std_mm their standard deviation). volumes_mm3: (T,) region volumes (weights of
    the overall coverage). scene: the scene's name; fiducial_ids: the fiducials planned around.
    """

    target_ids: tuple
    coverage: np.ndarray
    predicted: RmstPrediction
    suggested_ids: tuple
    suggested: np.ndarray
    coverage_after: np.ndarray
    predicted_after: RmstPrediction
    rejected: dict
    baselines: dict
    volumes_mm3: np.ndarray | None = None
    scene: str = ""
    n_usable: int = 0
    seconds: float = 0.0
    evaluations: int = 0  # fiducial sets the optimiser evaluated
    requested: int = 0  # how many fiducials were asked for (`suggested_ids` may hold fewer: only those that help)
    note: str = ""  # what the suggestion does, in words (or why fewer or none are suggested)
    inside: np.ndarray | None = None  # (T,) bool: each target inside the fiducials' hull (`hull.assess_coverage`)
    inside_after: np.ndarray | None = None  # the same with the suggestions
    off_plane_mm: np.ndarray | None = None  # (T,) distance from the fiducials' plane (0: they span a volume)
    #: target id -> why its region is not wholly inside the hull after the suggestions and where a fiducial would
    #: be needed ({"reason", "candidates_could", "needed_mm"}: `uncovered_reasons`); fully covered targets are not
    #: listed
    uncovered: dict = field(default_factory=dict)

    def overall_coverage(self, after: bool = False) -> float:
        """Volume-weighted fraction of all regions inside the hull (before, or after the suggestions)."""
        c = np.asarray(self.coverage_after if after else self.coverage, float)
        v = np.ones_like(c) if self.volumes_mm3 is None else np.asarray(self.volumes_mm3, float)
        return float(np.sum(c * v) / np.sum(v)) if len(c) else 0.0

    def to_json(self) -> dict:
        """JSON of `rrbc plan --json` (cli.md fields first: coverage = overall volume-weighted fraction,
        predicted_rmst_mm and predicted_rmst_after_mm = RMST with RRBC, suggested [[x, y, z], ...])."""
        return {
            "coverage": self.overall_coverage(),
            "predicted_rmst_mm": self.predicted.rrbc_mm,
            "suggested": np.asarray(self.suggested, float).reshape(-1, 3).tolist(),
            "predicted_rmst_after_mm": self.predicted_after.rrbc_mm,
            "scene": self.scene,
            "add": len(self.suggested_ids),
            "coverage_after": self.overall_coverage(after=True),
            "coverage_per_target": {t: float(c) for t, c in zip(self.target_ids, self.coverage)},
            "coverage_per_target_after": {t: float(c) for t, c in zip(self.target_ids, self.coverage_after)},
            "inside_hull_per_target": _per_target(self.target_ids, self.inside),
            "inside_hull_per_target_after": _per_target(self.target_ids, self.inside_after),
            "off_plane_mm_per_target": _per_target(self.target_ids, self.off_plane_mm, float),
            "uncovered_after": dict(self.uncovered),
            "predicted": self.predicted.to_json(),
            "predicted_after": self.predicted_after.to_json(),
            "suggested_ids": list(self.suggested_ids),
            "baselines": {k: v.to_json() for k, v in self.baselines.items()},
            "rejected": dict(self.rejected),
            "requested": self.requested,
            "note": self.note,
            "usable_candidates": self.n_usable,
            "evaluations": self.evaluations,
            "seconds": self.seconds,
        }


def uncovered_reasons(fiducials, candidates, targets, target_ids, seed: int = 0, now=None) -> dict[str, dict]:
    """Per target whose region of variability is not wholly inside the hull of `fiducials` (N, 3): {"reason": in
    words, "candidates_could": bool, "needed_mm": [x, y, z] or None, where a fiducial would be needed}. Either the usable `candidates` (C, 3) could cover it (the hull of all of
    them with the fiducials covers more: ask for more or other fiducials), or no candidate lies beyond it (even all
    of them leave part of it outside): then the part left outside that lies farthest from the fiducials' centroid is
    named, a place a new candidate (a fiducial beyond it) would have to be. Robot frame, mm. `now`: the fiducials'
    coverage (T,) when the caller has it (`coverage(fiducials, targets, seed=seed)`)."""
    f = np.asarray(fiducials, float).reshape(-1, 3)
    c = np.asarray(candidates, float).reshape(-1, 3)
    if not len(targets):
        return {}
    if now is None:
        now = coverage(f, targets, seed=seed) if len(f) >= 4 else np.zeros(len(targets))
    everything = np.concatenate([f, c])
    best = coverage(everything, targets, seed=seed) if len(everything) >= 4 else np.zeros(len(targets))
    out = {}
    rng = np.random.default_rng([seed, 11])
    centre = everything.mean(axis=0) if len(everything) else np.zeros(3)
    for k, tid in enumerate(target_ids):
        if now[k] >= 1.0:
            continue
        if best[k] > now[k]:
            why = (
                f"{100 * (1 - now[k]):.0f} % of its region lies outside the fiducials' hull; the usable candidates "
                f"could bring it to {100 * best[k]:.0f} % (all of them together): ask for more or other fiducials "
                "(--add)"
            )
            out[tid] = {"reason": why, "candidates_could": True, "needed_mm": None}
            continue
        samples = getattr(targets[k], "region", targets[k]).sample(rng, 512)
        outside = samples[~covered(everything, samples)] if len(everything) >= 4 else samples
        far = outside[np.argmax(np.linalg.norm(outside - centre, axis=1))] if len(outside) else samples.mean(axis=0)
        where = ", ".join(f"{v + 0.0:.0f}" for v in far)
        off = float(assess_coverage(everything, far[None]).off_plane_mm[0]) if len(everything) >= 3 else 0.0
        need = (
            f"its uncovered part lies up to {off:.0f} mm off the plane the fiducials and candidates lie in: a "
            f"fiducial off that plane, beyond ({where}) mm, would be needed"
            if off > OFF_PLANE_TOL_MM
            else f"a fiducial beyond its farthest uncovered point ({where}) mm, away from the others, would be needed"
        )
        why = (
            f"{100 * (1 - now[k]):.0f} % of its region lies outside the fiducials' hull and no usable candidate lies "
            f"beyond it (all of them together leave {100 * (1 - best[k]):.0f} % outside); {need}: add a candidate "
            "there"
        )
        out[tid] = {"reason": why, "candidates_could": False, "needed_mm": [float(v) for v in far]}
    return out


def _per_target(ids, values, kind=bool) -> dict | None:
    return None if values is None else {t: kind(v) for t, v in zip(ids, values)}


def _centres(fiducials: np.ndarray, scene: Scene):
    """(inside (T,), off-plane mm (T,)) of the targets' own positions (`hull.assess_coverage`); all outside with
    no fiducials."""
    pos = scene.target_positions
    if len(fiducials) == 0:
        return np.zeros(len(pos), bool), np.zeros(len(pos))
    c = assess_coverage(fiducials, pos)
    return c.inside, c.off_plane_mm


@thread_limited
def predict_rmst(
    scene: Scene,
    fiducials_mm: ArrayLike,
    *,
    registration_mm: ArrayLike | None = None,
    trials: int = 0,
    seed: int = 0,
    samples_per_target: int = SAMPLES_PER_TARGET,
) -> RmstPrediction:
    """Predicted RMS target error (mm) over the targets' regions of variability, rigid and with RRBC (IDW).

    Parameters
    ----------
    scene : Scene
        A loaded scene.
    fiducials_mm : (N, 3) array_like
        The fiducials, robot frame, mm (a position equal to a registration point is one physical point).
    registration_mm : (Nr, 3) array_like, optional
        The registration points (default the scene's).
    trials : int
        0: the fast prediction (bias exact, noise to first order); > 1: Monte Carlo with that many trials.
    seed : int
        Seed of the region samples (and of the Monte Carlo).
    samples_per_target : int
        Check points sampled uniformly in each target's region.

    Returns
    -------
    RmstPrediction
        ``rigid_mm``, ``rrbc_mm`` and their 1-sigma uncertainties; ``method``.

    Raises
    ------
    InputError
        Bad positions, or a point out of the arm's reach.
    """
    fid = _points(fiducials_mm, "fiducial positions")
    reg = None if registration_mm is None else _points(registration_mm, "registration positions")
    trials = int(trials)
    if trials < 0:
        raise InputError(f"trials must be >= 0, got {trials}")
    if trials == 0:
        return _predict_fast(scene, fid, reg, samples_per_target, seed)
    if trials < 2:
        raise InputError("Monte Carlo needs trials >= 2 (for its standard error); use trials=0 for the fast prediction")
    return _predict_mc(scene, fid, reg, samples_per_target, trials, seed)


@thread_limited
def plan(
    scene: Scene,
    add: int = 0,
    *,
    fiducials_mm: ArrayLike | None = None,
    seed: int = 0,
    progress: Callable[[int, str], object] | None = None,
    samples_per_target: int = SAMPLES_PER_TARGET,
    cover_targets: bool = False,
) -> PlanResult:
    """Coverage, predicted RMST and `add` suggested fiducial locations for a scene (`rrbc plan`).

    Parameters
    ----------
    scene : Scene
        A loaded scene (its candidates, error model, targets and regions).
    add : int
        How many fiducials to suggest from the usable candidates (0: only coverage and prediction).
    fiducials_mm : (N, 3) array_like, optional
        The fiducials to plan around (robot frame, mm; default the scene's); they stay.
    seed : int
        Seed of the region samples and of the "random" baseline.
    progress : callable, optional
        ``progress(n, label)``, called as the search proceeds.
    samples_per_target : int
        Check points sampled in each target's region for the prediction.
    cover_targets : bool
        Rank sets first by how many targets lie inside their hull, then by the predicted RMST (`rrbc scene new`'s
        first fiducials, where candidates that surround the targets are preferred when the mesh offers them);
        default: the predicted RMST alone, never worse than either rule's set.

    Returns
    -------
    PlanResult
        Coverage per target before and after, the predicted RMST (rigid and RRBC, with their std) before and
        after, the suggestions (ids and robot-frame positions, mm), the baselines for the same K and the rejected
        candidates with their reasons; `to_json()` is the JSON of `rrbc plan --json`.

    Raises
    ------
    InputError
        `add` exceeds the usable candidates, or a point cannot be evaluated.
    """
    import time

    t0 = time.perf_counter()
    add = int(add)
    if add < 0:
        raise InputError(f"add must be >= 0, got {add}")
    base = scene.fiducials.positions if fiducials_mm is None else _points(fiducials_mm, "fiducial positions")
    mask, rejected = usable_candidates(scene) if add > 0 else (np.ones(len(scene.candidates), bool), {})
    cand_idx = np.flatnonzero(mask)
    if add > len(cand_idx):
        extra = (
            f" ({len(rejected)} of {len(scene.candidates)} rejected: hidden, inside solids or unreachable)"
            if rejected
            else ""
        )
        raise InputError(
            f"{scene.path}: --add {add} asks for more fiducials than the scene's {len(cand_idx)} usable "
            f"candidate locations{extra}; add candidates ([[candidate]] or [candidates] grid) or ask for fewer"
        )
    if add > 0:
        # candidates already at a base fiducial cannot be added again
        d = (
            np.min(np.linalg.norm(scene.candidates.positions[cand_idx][:, None] - base[None], axis=2), axis=1)
            if len(base)
            else np.full(len(cand_idx), np.inf)
        )
        cand_idx = cand_idx[d > _SAME_MM]
        if add > len(cand_idx):
            raise InputError(
                f"{scene.path}: --add {add}: only {len(cand_idx)} usable candidates are not already fiducials"
            )
    if add > MAX_ADD:
        raise InputError(
            f"--add {add}: at most {MAX_ADD} fiducials are suggested at once (the search grows with K); suggest "
            f"{MAX_ADD}, add them to the scene and plan again"
        )
    cand_pos = scene.candidates.positions[cand_idx]
    cov0 = coverage(base, scene.targets, seed=seed)
    pred0 = predict_rmst(scene, base, seed=seed, samples_per_target=samples_per_target)
    volumes = np.array([t.region.volume() for t in scene.targets])
    in0, off0 = _centres(base, scene)
    if add == 0:
        return PlanResult(
            scene.target_ids,
            cov0,
            pred0,
            (),
            np.zeros((0, 3)),
            cov0,
            pred0,
            rejected,
            {},
            volumes,
            scene.name,
            len(cand_idx),
            time.perf_counter() - t0,
            inside=in0,
            inside_after=in0,
            off_plane_mm=off0,
            uncovered=(
                uncovered_reasons(
                    base,
                    scene.candidates.positions[usable_candidates(scene)[0]],
                    scene.targets,
                    scene.target_ids,
                    seed,
                    cov0,
                )
                if np.any(cov0 < 1.0)
                else {}
            ),
        )
    pool = _pool(scene, base, cand_pos, samples_per_target, seed)
    rng = np.random.default_rng([seed, 7])
    rules = {
        "hull-corners": _corner_choice(scene, cand_pos, add),
        "random": np.array([rng.choice(len(cand_idx), size=add, replace=False) for _ in range(RANDOM_DRAWS)]),
    }
    found = _optimise(pool, len(cand_idx), add, rules, progress, cover_first=cover_targets)
    chosen = found.chosen
    suggested = cand_pos[chosen].reshape(-1, 3)
    ids = tuple(scene.candidates.ids[i] for i in cand_idx[chosen])
    after = np.concatenate([base, suggested])
    pred1 = predict_rmst(scene, after, seed=seed, samples_per_target=samples_per_target) if len(chosen) else pred0
    if pred1.rrbc_mm > pred0.rrbc_mm:  # the optimiser's and the report's predictions disagree: suggest nothing
        chosen, suggested, ids, after, pred1 = chosen[:0], suggested[:0], (), base, pred0
    cov1 = coverage(after, scene.targets, seed=seed)
    rigid, rigid_std = pool.model.rigid()
    cr, cs = pool.rrbc(rules["hull-corners"][None])
    rr = found.random_draws
    baselines = {
        "hull-corners": RmstPrediction(rigid, rigid_std, float(cr[0]), float(cs[0]), "first-order"),
        "random": RmstPrediction(rigid, rigid_std, float(rr.mean()), float(rr.std(ddof=1)), "first-order"),
    }
    if len(chosen) == add:
        note = (
            f"the {add} suggested are predicted to lower the RMST with RRBC from {pred0.rrbc_mm:.4f} to "
            f"{pred1.rrbc_mm:.4f} mm"
            + (
                f", no worse than either rule for {add}"
                if not cover_targets
                else f", with {int(np.sum(_centres(after, scene)[0]))} of {len(scene.targets)} targets inside their hull"
            )
        )
    elif len(chosen):
        note = (
            f"no set of {add} candidates is predicted to lower the RMST with RRBC ({pred0.rrbc_mm:.4f} mm now) by "
            f"more than {100 * MIN_GAIN:g} %, the prediction's accuracy; the best {len(chosen)} do "
            f"({pred1.rrbc_mm:.4f} mm), so only {len(chosen)} are suggested"
        )
    else:
        best = min(found.rmst, float(np.min(found.greedy_path)))
        note = (
            f"no candidate is predicted to lower the RMST with RRBC ({pred0.rrbc_mm:.4f} mm now; the best of up to "
            f"{add} found gives {best:.4f} mm, {100 * (best / pred0.rrbc_mm - 1):+.1f} %) by more than "
            f"{100 * MIN_GAIN:g} %, the prediction's accuracy: nothing is suggested - more fiducials here would carry "
            "about as much noise into the targets as bias they remove, or more"
        )
    return PlanResult(
        scene.target_ids,
        cov0,
        pred0,
        ids,
        suggested,
        cov1,
        pred1,
        rejected,
        baselines,
        volumes,
        scene.name,
        len(cand_idx),
        time.perf_counter() - t0,
        found.evaluated,
        add,
        note,
        in0,
        _centres(after, scene)[0],
        off0,
        uncovered_reasons(after, cand_pos, scene.targets, scene.target_ids, seed, cov1),
    )
