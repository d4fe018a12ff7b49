"""Fiducial planning: coverage of the targets' regions of variability, predicted RMS target error (RMST), and
suggested fiducial locations (issue 7; theory notes §7; `rrbc plan`).

Frames and units
----------------
Every position passed in or returned is in the SCENE frame, the frame scene TOML files use: the ROBOT BASE frame,
in millimetres (`scene.py`, `scenes/README.md`). Errors are in mm. Internally the sensor readings are in the
sensor frame, as everywhere in the library.

Coverage
--------
`coverage(fiducials, regions)`: per region, the fraction of its volume inside the convex hull of the fiducials,
estimated from `samples_per_region` seeded uniform samples (`Region.sample`) tested with
`interpolation.hull_flags` (the same hull RRBC uses for its extrapolation flags). For a coplanar (or collinear)
fiducial set the hull is the polygon in the fiducials' plane: a sample counts as covered when its projection is
inside the polygon AND it lies within `COPLANAR_TOL_MM` (1 mm) of the plane — the same 1 mm within which the
library treats a point as lying on a surface (the visibility tolerance, `visibility.visible_points`), so a
shallow region on a plate of fiducials is covered and a region 100 mm above the plate is not.

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
* Noise: first order about the bias-only readings (theory notes §0 error budget, §2.3). With J_q,j = ∂T̂(s_q)/∂b_j
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
  the first-order truncation, which theory notes §2.3 measured at 1–2 % of the noise term.

Prediction (trials > 0: "monte-carlo")
--------------------------------------
`simulation.work_cell_from_scene` + `simulation.measure` + `simulation.trial_errors` (vectorised `batch`
kernels) on the same check points, noise redrawn per trial, bias fixed. std: the Monte Carlo standard error of
the RMST, from the spread of the per-trial mean squared error (σ_MSE = sd_t / √T, propagated as above). The
finite region sample is common to both modes and is not part of this std.

Candidates and the optimiser
----------------------------
`usable_candidates(scene)` rejects candidates that are inside solid geometry (inside a closed mesh part, open3d
occupancy, and more than `SURFACE_TOL_MM` below that part's surface, so markers on a surface stay usable), hidden from the sensor (ray cast
against the cell mesh, `visibility.occluded_by`), or out of the arm's reach (the kinematic error model cannot
evaluate them). `plan(scene, add=K)` chooses K of the usable candidates by greedy forward selection followed by
exchange (swap a chosen candidate for an unused one while the objective improves), every step evaluating all
candidates at once (vectorised). The objective is lexicographic: first NIST's rule — the fraction of the region
samples inside the fiducials' hull, larger is better — then the fast predicted RMST with RRBC. Where the
current fiducials already cover every region (the shipped demo and peg-in-hole scenes) it is the predicted RMST
alone; where they do not, coverage comes first even at some cost in predicted RMST (an IDW prediction outside
the hull does not blow up, so RMST alone can leave a region uncovered). Baselines for the same K: "hull-corners" (the usable candidates
nearest the corners of the targets' bounding box, corners taken in farthest-first order) and "random" (the mean
over `RANDOM_DRAWS` seeded random K-subsets).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from rrbc_core.simulation import batch
from rrbc_core.errors import InputError
from rrbc_core.geometry.points import as_points
from rrbc_core.interpolation import hull_flags
from rrbc_core.runtime.threads import thread_limited

#: A sample within this distance (mm) of a coplanar fiducial set's plane (and inside its polygon) is covered.
COPLANAR_TOL_MM = 1.0
#: A candidate inside a solid but within this distance (mm) of a surface lies on that surface (usable).
SURFACE_TOL_MM = 1.0
#: Check points sampled per target region for the prediction (the app calls it on every drag: keep it small).
SAMPLES_PER_TARGET = 32
#: Random K-subsets averaged for the "random" baseline.
RANDOM_DRAWS = 32
#: IDW options of the RRBC prediction (the defaults of `rrbc simulate`, `rrbc correct` and the explorer).
IDW_K = 4
IDW_POWER = 2.0
#: Central-difference step (mm) for the registration sensitivities.
_FD_STEP_MM = 1e-3
#: Positions closer than this (mm) are the same physical point (as `scene.SAME_POINT_TOL_MM`).
_SAME_MM = 1e-6
#: Exchange passes of the optimiser (each pass tries every swap once); it stops earlier when nothing improves.
_MAX_EXCHANGE_PASSES = 20
#: Fiducial sets evaluated per vectorised call (keeps the temporaries in cache).
_SETS_PER_CHUNK = 16
#: Relative improvement below which an exchange is not worth taking (guards against rounding cycles).
_IMPROVE_REL = 1e-9


# ------------------------------------------------------------------------------------------------------
# Results
# ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RmstPrediction:
    """Predicted RMS target error (mm) over the targets' regions of variability, rigid and with RRBC.

    rigid_mm: RMST with rigid (least-squares) registration only; rigid_std_mm its 1-sigma uncertainty.
    rrbc_mm: RMST after RRBC with IDW (k=4, p=2); rrbc_std_mm its 1-sigma uncertainty.
    method: "first-order" (noise by first-order formulas + the exact deterministic bias) or "monte-carlo".
    Meaning of the std: module docstring.
    """

    rigid_mm: float
    rigid_std_mm: float
    rrbc_mm: float
    rrbc_std_mm: float
    method: str

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


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
            "predicted": self.predicted.to_json(),
            "predicted_after": self.predicted_after.to_json(),
            "suggested_ids": list(self.suggested_ids),
            "baselines": {k: v.to_json() for k, v in self.baselines.items()},
            "rejected": dict(self.rejected),
            "usable_candidates": self.n_usable,
            "evaluations": self.evaluations,
            "seconds": self.seconds,
        }


# ------------------------------------------------------------------------------------------------------
# Coverage
# ------------------------------------------------------------------------------------------------------
def _points(x, what: str) -> np.ndarray:
    return as_points(x, what, single=True, frame="scene frame, mm")


def _covered(fiducials: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """Bool per sample: inside the fiducials' hull (coplanar: inside the polygon and within COPLANAR_TOL_MM)."""
    if len(fiducials) < 3 or len(samples) == 0:
        return np.zeros(len(samples), dtype=bool)
    extrapolated, off = hull_flags(fiducials, samples)
    return ~extrapolated & (off <= COPLANAR_TOL_MM)


@thread_limited
def coverage(fiducials_mm, regions, *, samples_per_region: int = 512, seed: int = 0) -> np.ndarray:
    """Per region, the fraction (R,) of its volume inside the convex hull of the fiducials.

    fiducials_mm: (N, 3) scene frame (robot base frame), mm. regions: `scene.Region` objects (or targets with a
    `.region`). Estimated from `samples_per_region` uniform samples per region (seed `seed`; standard error
    ≤ 0.5/√samples). Coplanar fiducials: a sample counts as covered when its projection is inside the planar
    hull AND it lies within COPLANAR_TOL_MM (1 mm) of the plane; fewer than 3 fiducials or collinear ones cover
    nothing of a volume (a line has no area).
    """
    f = _points(fiducials_mm, "fiducial positions")
    n = int(samples_per_region)
    if n < 1:
        raise InputError(f"samples_per_region must be >= 1, got {samples_per_region}")
    regs = [getattr(r, "region", r) for r in regions]
    if not regs:
        return np.zeros(0)
    rng = np.random.default_rng(seed)
    samples = np.concatenate([r.sample(rng, n) for r in regs])
    return _covered(f, samples).reshape(len(regs), n).mean(axis=1)


# ------------------------------------------------------------------------------------------------------
# The prediction model
# ------------------------------------------------------------------------------------------------------
def _named(scene, positions: np.ndarray, kind: str):
    """NamedPoints for planned positions: the id of a registration point / fiducial / candidate at the same
    place (so a fiducial on a registration point is ONE physical point, role `both`), else PLAN-<k>."""
    from rrbc_core.io.scene import NamedPoints

    pools = [scene.registration] + ([scene.fiducials, scene.candidates] if kind == "fiducial" else [])
    ids = []
    for k, p in enumerate(positions):
        pid = f"{'PLAN' if kind == 'fiducial' else 'REG'}-{k + 1}"
        for pool in pools:
            if len(pool):
                d = np.linalg.norm(pool.positions - p, axis=1)
                j = int(np.argmin(d))
                if d[j] <= _SAME_MM:
                    pid = pool.ids[j]
                    break
        if pid in ids:
            raise InputError(f"two {kind} positions coincide at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) mm; "
                             "give each physical point once")
        ids.append(pid)
    return NamedPoints(tuple(ids), positions, np.full(len(positions), float(scene.tool_yaw_deg)))


def _planned_scene(scene, fiducials: np.ndarray, registration=None):
    reg = scene.registration if registration is None else _named(scene, registration, "registration")
    sc = dataclasses.replace(scene, registration=reg)
    return dataclasses.replace(sc, fiducials=_named(sc, fiducials, "fiducial"))


def _cell(scene, fiducials: np.ndarray, registration, samples_per_target: int, seed: int):
    """(work cell without visibility, indices (N,) of the planned fiducials in the cell, in the given order)."""
    from rrbc_core.simulation.montecarlo import work_cell_from_scene

    if int(samples_per_target) < 1:
        raise InputError(f"samples_per_target must be >= 1, got {samples_per_target}")
    sc = _planned_scene(scene, fiducials, registration)
    cell = work_cell_from_scene(sc, seed=seed, checks_per_target=int(samples_per_target), visibility=False)
    where = {pid: i for i, pid in enumerate(cell.ids)}
    return cell, np.array([where[pid] for pid in sc.fiducials.ids], dtype=int)


@dataclass(frozen=True, eq=False)
class _Readings:
    """Bias-only readings of points: sensor (P,3) sensor frame, robot (P,3) and truth (P,3) robot frame, mm;
    net FLE covariance (P,3,3) robot frame (R Σ_s Rᵀ + Σ_b), and the sensor part alone R Σ_s Rᵀ (P,3,3)."""

    sensor: np.ndarray
    robot: np.ndarray
    truth: np.ndarray
    net_cov: np.ndarray
    sensor_cov: np.ndarray


def _readings(cell) -> _Readings:
    """Bias-only readings of the cell's points and their noise covariances, through the measurement model."""
    model = cell.measurement_model()
    pts = cell.point_set()
    r = model.read(pts)
    rot = cell.sensor_to_robot.rotation
    sensor_cov, robot_cov = model.noise_covariance(pts)
    cov_s = np.einsum("ab,pbc,dc->pad", rot, sensor_cov, rot)
    return _Readings(r.sensor[0], r.robot[0], r.truth, cov_s + robot_cov, cov_s)


@dataclass(frozen=True, eq=False)
class _Registration:
    """The bias-only least-squares fit T̂ (rot (3,3), trans (3,)) and its sensitivities to the robot readings of
    the registration points: dA (Nr, 3, 3, 3) = ∂R̂/∂b_jc and dt (Nr, 3, 3) = ∂t̂/∂b_jc ([j, c, ...])."""

    rot: np.ndarray
    trans: np.ndarray
    d_rot: np.ndarray
    d_trans: np.ndarray
    net_cov: np.ndarray  # (Nr,3,3)

    @property
    def net_cov_chol(self) -> np.ndarray:
        """L (Nr,3,3) with L Lᵀ = net_cov (symmetric square root: also fine for a singular covariance)."""
        evals, evecs = np.linalg.eigh(self.net_cov)
        return evecs * np.sqrt(np.clip(evals, 0.0, None))[:, None, :]

    @classmethod
    def fit(cls, sensor: np.ndarray, robot: np.ndarray, net_cov: np.ndarray) -> "_Registration":
        n = len(sensor)
        a0, t0 = batch.least_squares_batch(sensor[None], robot[None])
        h = _FD_STEP_MM
        pert = np.zeros((2, n, 3, n, 3))
        for j in range(n):
            for c in range(3):
                pert[0, j, c, j, c] = h
                pert[1, j, c, j, c] = -h
        r = robot[None] + pert.reshape(2 * n * 3, n, 3)
        s = np.broadcast_to(sensor, r.shape)
        a, t = batch.least_squares_batch(s, r)
        a = a.reshape(2, n, 3, 3, 3)
        t = t.reshape(2, n, 3, 3)
        return cls(a0[0], t0[0], (a[0] - a[1]) / (2 * h), (t[0] - t[1]) / (2 * h), net_cov)

    def apply(self, x: np.ndarray) -> np.ndarray:
        return x @ self.rot.T + self.trans

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """J (..., Nr, 3, 3): J[..., j, :, c] = ∂T̂(x)/∂b_jc for sensor-frame points x (..., 3)."""
        da = np.einsum("jcab,...b->...jac", self.d_rot, x)
        return da + np.swapaxes(self.d_trans, 1, 2)


def _idw_weights(fid_sensor: np.ndarray, query: np.ndarray) -> np.ndarray:
    """IDW weights W (T, M, N) with Σ_n W = 1 such that batch.idw_batch(fid, e, query) = W @ e, for stacks of
    fiducial sets fid_sensor (T, N, 3) and shared queries (M, 3) (sensor frame, mm). Obtained by probing the
    library's IDW with unit corrections (3 columns per call), so the rule (k nearest, 1/d^p, exact hits) is the
    library's own."""
    t, n = fid_sensor.shape[:2]
    w = np.empty((t, len(query), n))
    eye = np.eye(n)
    for start in range(0, n, 3):
        cols = list(range(start, min(start + 3, n)))
        probe = np.zeros((n, 3))
        probe[:, : len(cols)] = eye[:, cols]
        out = batch.idw_batch(fid_sensor, np.broadcast_to(probe, (t, n, 3)), query, k=IDW_K, power=IDW_POWER)
        w[:, :, cols] = out[:, :, : len(cols)]
    return w


@dataclass(frozen=True, eq=False)
class _Model:
    """Everything the fast prediction needs that does not depend on the choice of fiducials."""

    reg: _Registration
    reg_pos: np.ndarray  # (Nr,3) robot frame (nominal)
    q_sensor: np.ndarray  # (M,3) check points, bias-only sensor readings
    q_rigid_err: np.ndarray  # (M,3) rigid bias error T̂(s_q) − truth_q
    q_jac: np.ndarray  # (M,Nr,3,3)
    q_target_var: np.ndarray  # (M,) tr R Σ_s(q) Rᵀ
    q_rigid_noise_var: np.ndarray  # (M,)
    n_targets: int

    @classmethod
    def from_cell(cls, cell) -> tuple["_Model", "_Readings"]:
        rd = _readings(cell)
        ri = cell.index("registration", "both")
        qi = cell.index("check")
        reg = _Registration.fit(rd.sensor[ri], rd.robot[ri], rd.net_cov[ri])
        qs = rd.sensor[qi]
        jac = reg.jacobian(qs)
        var_t = np.trace(rd.sensor_cov[qi], axis1=1, axis2=2)
        gl = np.matmul(jac, reg.net_cov_chol)
        var_reg = np.sum(gl * gl, axis=(1, 2, 3))
        n_t = len({t for t in (cell.check_target[i] for i in qi)})
        model = cls(reg, cell.robot[ri], qs, reg.apply(qs) - rd.truth[qi], jac, var_t, var_reg + var_t, n_t)
        return model, rd

    def _rmst(self, sq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """RMST and its sampling std from squared errors (..., M) with M = n_targets x n per target."""
        per = sq.reshape(sq.shape[:-1] + (self.n_targets, -1))
        n = per.shape[-1]
        mse = per.mean(axis=(-1, -2))
        var_mse = (per.var(axis=-1, ddof=1) / n).sum(axis=-1) / self.n_targets**2 if n > 1 else 0 * mse
        rmst = np.sqrt(mse)
        with np.errstate(divide="ignore", invalid="ignore"):
            std = np.where(rmst > 0, np.sqrt(var_mse) / (2 * rmst), 0.0)
        return rmst, std

    def rigid(self) -> tuple[float, float]:
        sq = np.sum(self.q_rigid_err**2, axis=1) + self.q_rigid_noise_var
        r, s = self._rmst(sq)
        return float(r), float(s)

    def rrbc_sq(self, f_sensor, f_corr, f_jac, f_cov, shared) -> np.ndarray:
        """Squared RRBC errors (T, M) for T fiducial sets (stacked): f_sensor (T,N,3) bias-only sensor readings,
        f_corr (T,N,3) robot-frame corrections b − T̂(s), f_jac (T,N,Nr,3,3), f_cov (T,N,3,3) net FLE
        covariance, shared (T,N) index of the registration point a fiducial is (−1: none)."""
        if f_sensor.shape[1] == 0:
            sq = np.sum(self.q_rigid_err**2, axis=1) + self.q_rigid_noise_var
            return np.broadcast_to(sq, (f_sensor.shape[0], len(sq))).copy()
        w = _idw_weights(f_sensor, self.q_sensor)  # (T,M,N)
        bias = self.q_rigid_err[None] + np.matmul(w, f_corr)
        t, n = f_jac.shape[:2]
        nr = self.q_jac.shape[1]
        g = np.matmul(w, f_jac.reshape(t, n, nr * 9)).reshape(t, -1, nr, 3, 3)
        np.subtract(self.q_jac[None], g, out=g)  # G = J_q − Σ_i w_qi J_i
        gl = np.matmul(g, self.reg.net_cov_chol)  # tr(G Σ Gᵀ) = ‖G L‖², Σ = L Lᵀ
        var = np.sum(gl * gl, axis=(2, 3, 4))
        var += np.einsum("tmn,tn->tm", w**2, np.trace(f_cov, axis1=2, axis2=3))
        if np.any(shared >= 0):
            ti, ni = np.nonzero(shared >= 0)
            ji = shared[ti, ni]
            gs = g[ti, :, ji]  # (S, M, 3, 3)
            tr = np.einsum("smab,sba->sm", gs, self.reg.net_cov[ji])
            np.add.at(var, ti, 2.0 * w[ti, :, ni] * tr)
        var += self.q_target_var[None]
        return np.sum(bias**2, axis=2) + var

    def shared_index(self, positions: np.ndarray) -> np.ndarray:
        d = np.linalg.norm(positions[:, None] - self.reg_pos[None], axis=2)
        j = np.argmin(d, axis=1) if len(self.reg_pos) else np.zeros(len(positions), int)
        return np.where(d[np.arange(len(positions)), j] <= _SAME_MM, j, -1)


def _fid_arrays(model: _Model, rd: _Readings, idx: np.ndarray):
    s = rd.sensor[idx]
    return s, rd.robot[idx] - model.reg.apply(s), model.reg.jacobian(s), rd.net_cov[idx]


def _predict_fast(scene, fid: np.ndarray, registration, samples_per_target: int, seed: int) -> RmstPrediction:
    cell, fi = _cell(scene, fid, registration, samples_per_target, seed)
    model, rd = _Model.from_cell(cell)
    rigid, rigid_std = model.rigid()
    s, corr, jac, cov = _fid_arrays(model, rd, fi)
    shared = model.shared_index(cell.robot[fi])
    sq = model.rrbc_sq(s[None], corr[None], jac[None], cov[None], shared[None])
    r, st = model._rmst(sq)
    return RmstPrediction(rigid, rigid_std, float(r[0]), float(st[0]), "first-order")


def _mc_rmst(err: np.ndarray) -> tuple[float, float]:
    """RMST and its Monte Carlo standard error from errors (T, M)."""
    per_trial = np.mean(err**2, axis=1)
    mse = float(per_trial.mean())
    se = float(per_trial.std(ddof=1) / np.sqrt(len(per_trial))) if len(per_trial) > 1 else float("nan")
    r = float(np.sqrt(mse))
    return r, (se / (2 * r) if r > 0 else 0.0)


def _predict_mc(scene, fid, registration, samples_per_target, trials, seed, chunk: int = 1000) -> RmstPrediction:
    from rrbc_core.simulation.montecarlo import measure, trial_errors

    cell, _ = _cell(scene, fid, registration, samples_per_target, seed)
    interp = "idw" if len(cell.index("fiducial", "both")) else "none"
    opts = {"k": IDW_K, "power": IDW_POWER} if interp == "idw" else {}
    rng = np.random.default_rng([seed, 3])
    rig, rr = [], []
    done = 0
    while done < trials:
        n = min(chunk, trials - done)
        e = trial_errors(cell, measure(cell, rng, n), "least-squares", interp, **opts)
        rig.append(e.rigid)
        rr.append(e.rrbc)
        done += n
    a, sa = _mc_rmst(np.concatenate(rig))
    b, sb = _mc_rmst(np.concatenate(rr))
    return RmstPrediction(a, sa, b, sb, "monte-carlo")


@thread_limited
def predict_rmst(scene, fiducials_mm, *, registration_mm=None, trials: int = 0, seed: int = 0,
                 samples_per_target: int = SAMPLES_PER_TARGET) -> RmstPrediction:
    """Predicted RMS target error (mm) over the targets' regions of variability, rigid and with RRBC (IDW).

    scene: a loaded `Scene`. fiducials_mm: (N, 3) fiducial positions, scene frame (= robot base frame), mm; N may
    be 0 (then RRBC = rigid). registration_mm: (Nr, 3) registration points, scene frame, mm (default: the scene's).
    A fiducial at a registration point's position is the same physical point (one reading, role `both`).
    trials=0: the fast first-order prediction (bias exact, noise first order; see the module docstring; ~10 ms
    on the shipped scenes); trials>0: Monte Carlo over the scene's error model with that many trials.
    samples_per_target check points are sampled uniformly in each region (seeded by `seed`). Visibility is not
    checked here (use `usable_candidates`). Unreachable points raise InputError.
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


# ------------------------------------------------------------------------------------------------------
# Candidates
# ------------------------------------------------------------------------------------------------------
def _buried(mesh, points: np.ndarray) -> dict:
    """{index: part name} for points inside a closed part of the mesh and deeper than SURFACE_TOL_MM below that
    part's surface. `visibility.inside_solids` screens; each flagged point is then tested part by part (open3d
    occupancy + unsigned distance to that part's surface), so a marker on a surface — even a surface of another
    part passing through it, like a table top through a block standing on it — stays usable."""
    import open3d as o3d

    from rrbc_core.simulation.visibility import inside_solids, raycasting_scene

    flagged = np.flatnonzero(inside_solids(mesh, points))
    if len(flagged) == 0:
        return {}
    v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces)
    p = points[flagged]
    shift = p.mean(axis=0)
    q = o3d.core.Tensor(np.ascontiguousarray(p - shift, dtype=np.float32))
    out: dict = {}
    for name, start, stop in (mesh.metadata.get("parts") or [("mesh", 0, len(f))]):
        if stop <= start:
            continue
        used, local = np.unique(f[start:stop], return_inverse=True)
        rc = raycasting_scene(v[used], local.reshape(-1, 3), shift)
        deep = rc.compute_occupancy(q, nsamples=3).numpy().astype(bool) & (
            rc.compute_distance(q).numpy().astype(float) > SURFACE_TOL_MM)
        for k in np.flatnonzero(deep):
            out.setdefault(int(flagged[k]), str(name))
    return out


def _unreachable(scene, positions: np.ndarray) -> dict:
    """{index: message} for points the error model cannot evaluate (e.g. out of the arm's reach)."""
    from rrbc_core.simulation.errormodels import PointSet
    from rrbc_core.simulation.kinematics import tool_down

    det = scene.error_model.deterministic()
    if not det.robot and not det.sensor:
        return {}

    def check(p):
        n = len(p)
        ps = PointSet(robot=p, sensor=scene.sensor_to_robot.apply_inverse(p), time=np.zeros(n),
                      tool_rotation=np.broadcast_to(tool_down(scene.tool_yaw_deg), (n, 3, 3)),
                      joint_seed=scene.joint_seed)
        det.sample(ps, "robot", np.random.default_rng(0), 1)
        det.sample(ps, "sensor", np.random.default_rng(0), 1)

    try:
        check(positions)
        return {}
    except InputError:
        pass
    bad = {}
    for i, p in enumerate(positions):
        try:
            check(p[None])
        except InputError as exc:
            bad[i] = " ".join(str(exc).split())
    return bad


@thread_limited
def usable_candidates(scene) -> tuple[np.ndarray, dict]:
    """(mask (C,) over scene.candidates, {candidate id: reason}) — which candidate locations can hold a fiducial.

    Rejected: inside solid geometry (inside a closed mesh part, open3d occupancy, and more than SURFACE_TOL_MM
    below that part's surface — a marker on a surface is fine); hidden from the sensor (a ray
    from the sensor position is blocked by the mesh, `visibility.occluded_by`, 1 mm tolerance; skipped for a
    `ground_truth` sensor, which has no line of sight); not evaluable by the error model (e.g. out of the arm's
    reach). Positions: scene frame (robot base frame), mm.
    """
    from rrbc_core.simulation.visibility import occluded_by

    c = scene.candidates
    mask = np.ones(len(c), dtype=bool)
    reasons: dict = {}
    if len(c) == 0:
        return mask, reasons
    pos = c.positions
    mesh = scene.load_mesh()
    for i, part in _buried(mesh, pos).items():
        mask[i] = False
        reasons[c.ids[i]] = f"inside solid geometry ({part})"
    if scene.line_of_sight:
        occ = occluded_by(mesh, scene.sensor_position, pos)
        for i, o in enumerate(occ):
            if o is not None and mask[i]:
                mask[i] = False
                reasons[c.ids[i]] = f"hidden from the sensor by {o[0]} ({o[1]:.0f} mm from the sensor)"
    idx = np.flatnonzero(mask)
    for i, msg in _unreachable(scene, pos[idx]).items():
        mask[idx[i]] = False
        reasons[c.ids[idx[i]]] = f"cannot be evaluated: {msg}"
    return mask, reasons


# ------------------------------------------------------------------------------------------------------
# The optimiser
# ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Pool:
    """The base fiducials (always kept) and the usable candidates, with everything the fast objective needs.
    base_pos (B,3), cand_pos (C,3), query_pos (M,3): nominal positions, scene frame, mm (for the coverage)."""

    model: _Model
    base: tuple  # arrays for the base fiducials: sensor (B,3), corr, jac, cov, shared (B,)
    cand: tuple  # the same for the candidates (C, ...)
    base_pos: np.ndarray
    cand_pos: np.ndarray
    query_pos: np.ndarray

    def stack(self, choices: np.ndarray) -> tuple:
        """Arrays for T fiducial sets: base + candidates `choices` (T, K) (indices into the candidates)."""
        t = choices.shape[0]
        out = []
        for b, c in zip(self.base, self.cand):
            picked = c[choices]
            out.append(np.concatenate([np.broadcast_to(b, (t,) + b.shape), picked], axis=1))
        return tuple(out)

    def rrbc(self, choices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted RRBC RMST and its std (T,) for T sets of candidate indices (T, K)."""
        choices = np.asarray(choices, int).reshape(len(choices), -1)
        sq = np.concatenate([self.model.rrbc_sq(*self.stack(choices[i : i + _SETS_PER_CHUNK]))
                             for i in range(0, len(choices), _SETS_PER_CHUNK)])
        return self.model._rmst(sq)

    def covered(self, choices: np.ndarray) -> np.ndarray:
        """Fraction (T,) of the region samples (all targets weighted equally) inside the hull of each set."""
        choices = np.asarray(choices, int).reshape(len(choices), -1)
        return np.array([_covered(np.concatenate([self.base_pos, self.cand_pos[c]]), self.query_pos).mean()
                         for c in choices])

    def score(self, choices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(coverage, RRBC RMST) per set: the optimiser's lexicographic objective (more coverage first)."""
        return self.covered(choices), self.rrbc(choices)[0]


def _pool(scene, base: np.ndarray, cand: np.ndarray, samples_per_target: int, seed: int) -> _Pool:
    cell, fi = _cell(scene, np.concatenate([base, cand]), None, samples_per_target, seed)
    model, rd = _Model.from_cell(cell)  # fi: the base fiducials, then the candidates
    pos = cell.robot[fi]
    arrays = _fid_arrays(model, rd, fi) + (model.shared_index(pos),)
    nb = len(base)
    return _Pool(model, tuple(a[:nb] for a in arrays), tuple(a[nb:] for a in arrays), pos[:nb], pos[nb:],
                 cell.robot[cell.index("check")])


def _best(cov: np.ndarray, rmst: np.ndarray) -> int:
    """Index of the best set: the largest coverage (to 1e-12), then the smallest RMST."""
    top = cov >= cov.max() - 1e-12
    return int(np.flatnonzero(top)[np.argmin(rmst[top])])


def _better(cov: float, rmst: float, cov0: float, rmst0: float) -> bool:
    if cov > cov0 + 1e-12:
        return True
    return cov >= cov0 - 1e-12 and rmst < rmst0 * (1 - _IMPROVE_REL)


def _optimise(pool: _Pool, n_cand: int, add: int, progress=None) -> tuple[np.ndarray, int]:
    """Greedy forward selection, then exchange (Fedorov-style swaps of one chosen candidate for an unused one
    while the objective improves), on the lexicographic objective (coverage of the region samples by the hull,
    then predicted RRBC RMST). Returns (candidate indices (add,), number of sets evaluated)."""
    chosen: list[int] = []
    evaluated = 0
    for step in range(add):
        rest = np.array([i for i in range(n_cand) if i not in chosen], dtype=int)
        trial = np.column_stack([np.tile(chosen, (len(rest), 1)).reshape(len(rest), len(chosen)), rest])
        j = _best(*pool.score(trial))
        evaluated += len(trial)
        chosen.append(int(rest[j]))
        if progress:
            progress(1, f"greedy {step + 1}/{add}")
    if add == 0:
        return np.zeros(0, dtype=int), 0
    c0, r0 = pool.score(np.array([chosen]))
    best = (float(c0[0]), float(r0[0]))
    for _ in range(_MAX_EXCHANGE_PASSES):
        improved = False
        for slot in range(add):
            rest = np.array([i for i in range(n_cand) if i not in chosen], dtype=int)
            if len(rest) == 0:
                break
            trial = np.tile(chosen, (len(rest), 1))
            trial[:, slot] = rest
            cov, val = pool.score(trial)
            evaluated += len(trial)
            j = _best(cov, val)
            if _better(float(cov[j]), float(val[j]), *best):
                chosen[slot] = int(rest[j])
                best = (float(cov[j]), float(val[j]))
                improved = True
        if progress:
            progress(1, "exchange")
        if not improved:
            break
    return np.array(chosen, dtype=int), evaluated


def _corner_choice(scene, cand_pos: np.ndarray, add: int) -> np.ndarray:
    """The "hull-corners" rule: the candidates nearest the 8 corners of the targets' bounding box, corners in
    farthest-first order (then, beyond 8, farthest-first over the remaining candidates)."""
    lo = np.min([t.region.bounds()[0] for t in scene.targets], axis=0)
    hi = np.max([t.region.bounds()[1] for t in scene.targets], axis=0)
    corners = np.array([[(lo, hi)[(k >> a) & 1][a] for a in range(3)] for k in range(8)])
    order = [0]
    while len(order) < 8:
        d = np.min(np.linalg.norm(corners[:, None] - corners[order][None], axis=2), axis=1)
        d[order] = -1
        order.append(int(np.argmax(d)))
    chosen: list[int] = []
    for k in order[: min(add, 8)]:
        d = np.linalg.norm(cand_pos - corners[k], axis=1)
        d[chosen] = np.inf
        chosen.append(int(np.argmin(d)))
    while len(chosen) < add:
        d = np.min(np.linalg.norm(cand_pos[:, None] - cand_pos[chosen][None], axis=2), axis=1)
        d[chosen] = -1
        chosen.append(int(np.argmax(d)))
    return np.array(chosen, dtype=int)


@thread_limited
def plan(scene, add: int = 0, *, fiducials_mm=None, seed: int = 0, progress=None,
         samples_per_target: int = SAMPLES_PER_TARGET) -> PlanResult:
    """Coverage, predicted RMST and `add` suggested fiducial locations for a scene.

    fiducials_mm: (N, 3) the fiducials to plan around (scene frame = robot base frame, mm; default the scene's
    fiducials); they stay. The `add` suggestions come from the usable candidates (`usable_candidates`), chosen by
    greedy forward selection + exchange on the fast predicted RMST with RRBC (module docstring). Baselines of the
    same K: "hull-corners" and "random" (mean over RANDOM_DRAWS draws seeded by `seed`). progress(n, label), if
    given, is called as the work proceeds. Raises InputError when add exceeds the usable candidates.
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
        extra = f" ({len(rejected)} of {len(scene.candidates)} rejected: hidden, inside solids or unreachable)" \
            if rejected else ""
        raise InputError(f"{scene.path}: --add {add} asks for more fiducials than the scene's {len(cand_idx)} usable "
                         f"candidate locations{extra}; add candidates ([[candidate]] or [candidates] grid) or ask for fewer")
    if add > 0:
        # candidates already at a base fiducial cannot be added again
        d = np.min(np.linalg.norm(scene.candidates.positions[cand_idx][:, None] - base[None], axis=2), axis=1) \
            if len(base) else np.full(len(cand_idx), np.inf)
        cand_idx = cand_idx[d > _SAME_MM]
        if add > len(cand_idx):
            raise InputError(f"{scene.path}: --add {add}: only {len(cand_idx)} usable candidates are not already fiducials")
    cand_pos = scene.candidates.positions[cand_idx]
    cov0 = coverage(base, scene.targets, seed=seed)
    pred0 = predict_rmst(scene, base, seed=seed, samples_per_target=samples_per_target)
    volumes = np.array([t.region.volume() for t in scene.targets])
    if add == 0:
        return PlanResult(scene.target_ids, cov0, pred0, (), np.zeros((0, 3)), cov0, pred0, rejected, {},
                          volumes, scene.name, len(cand_idx), time.perf_counter() - t0)
    pool = _pool(scene, base, cand_pos, samples_per_target, seed)
    chosen, evaluated = _optimise(pool, len(cand_idx), add, progress)
    suggested = cand_pos[chosen]
    ids = tuple(scene.candidates.ids[i] for i in cand_idx[chosen])
    after = np.concatenate([base, suggested])
    cov1 = coverage(after, scene.targets, seed=seed)
    pred1 = predict_rmst(scene, after, seed=seed, samples_per_target=samples_per_target)
    rigid, rigid_std = pool.model.rigid()
    corner = _corner_choice(scene, cand_pos, add)
    cr, cs = pool.rrbc(corner[None])
    rng = np.random.default_rng([seed, 7])
    draws = np.array([rng.choice(len(cand_idx), size=add, replace=False) for _ in range(RANDOM_DRAWS)])
    rr, _ = pool.rrbc(draws)
    baselines = {
        "hull-corners": RmstPrediction(rigid, rigid_std, float(cr[0]), float(cs[0]), "first-order"),
        "random": RmstPrediction(rigid, rigid_std, float(rr.mean()), float(rr.std(ddof=1)), "first-order"),
    }
    return PlanResult(scene.target_ids, cov0, pred0, ids, suggested, cov1, pred1, rejected, baselines, volumes,
                      scene.name, len(cand_idx), time.perf_counter() - t0, evaluated)
