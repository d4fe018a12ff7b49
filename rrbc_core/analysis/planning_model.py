"""The planner's prediction model (`planning.predict_rmst`): a planned cell's bias-only readings through the measurement
model, the least-squares fit and its sensitivities, IDW weights, and the predicted RMST — bias exact, noise to first
order — evaluated for many fiducial sets at once; and the Monte Carlo check of it. The method: `planning`."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.points import as_points
from rrbc_core.geometry.transforms import map_points
from rrbc_core.simulation import batch

#: A sample within this distance (mm) of a coplanar fiducial set's plane (and inside its polygon) is covered.


#: Check points sampled per target region for the prediction (the app calls it on every drag: keep it small).
SAMPLES_PER_TARGET = 32


#: IDW options of the RRBC prediction (the defaults of `rrbc simulate`, `rrbc correct` and the explorer).
IDW_K = 4


IDW_POWER = 2.0


#: Central-difference step (mm) for the registration sensitivities.
_FD_STEP_MM = 1e-3


#: Perturbed fits per vectorised call when differentiating the registration (memory: this x points x 48 bytes).
_FD_CHUNK = 256


#: Positions closer than this (mm) are the same physical point (as `scene.SAME_POINT_TOL_MM`).
_SAME_MM = 1e-6


#: Fiducial sets evaluated per vectorised call (keeps the temporaries in cache).
_SETS_PER_CHUNK = 16


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


# ------------------------------------------------------------------------------------------------------
# Coverage
# ------------------------------------------------------------------------------------------------------
def _points(x, what: str) -> np.ndarray:
    return as_points(x, what, single=True, frame="scene frame, mm")


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
            raise InputError(
                f"two {kind} positions coincide at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) mm; "
                "give each physical point once"
            )
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
    the registration points, as one affine map per reading: T̂(x) moves by Σ_β d_affine[j, c, :, β] h_β for a unit
    change of b_jc, h = (x, 1) (sensor frame, homogeneous); ``reg_var`` K (4, 4) with var = hᵀ K h the variance
    of T̂(x) from the registration points' noise, and ``shared`` v (Nr, 4) with tr(∂T̂(x)/∂b_j Σ_j) = h · v_j —
    both summed over the registration points once, so nothing later grows with their number."""

    rot: np.ndarray
    trans: np.ndarray
    d_affine: np.ndarray  # (Nr, 3, 3, 4): [j, c, a, β]
    net_cov: np.ndarray  # (Nr, 3, 3)
    reg_var: np.ndarray  # (4, 4)
    shared: np.ndarray  # (Nr, 4)

    @classmethod
    def fit(cls, sensor: np.ndarray, robot: np.ndarray, net_cov: np.ndarray) -> _Registration:
        """Fit, then central differences of the fit for each robot coordinate of each registration point, in
        chunks of _FD_CHUNK perturbations: memory linear in the number of points."""
        n = len(sensor)
        a0, t0 = batch.least_squares_batch(sensor[None], robot[None])
        h = _FD_STEP_MM
        d_rot = np.empty((n * 3, 3, 3))
        d_trans = np.empty((n * 3, 3))
        for start in range(0, n * 3, _FD_CHUNK):
            k = np.arange(start, min(start + _FD_CHUNK, n * 3))
            r = np.broadcast_to(robot, (2, len(k), n, 3)).copy()
            r[0, np.arange(len(k)), k // 3, k % 3] += h
            r[1, np.arange(len(k)), k // 3, k % 3] -= h
            a, t = batch.least_squares_batch(np.broadcast_to(sensor, (2 * len(k), n, 3)), r.reshape(-1, n, 3))
            a, t = a.reshape(2, len(k), 3, 3), t.reshape(2, len(k), 3)
            d_rot[k] = (a[0] - a[1]) / (2 * h)
            d_trans[k] = (t[0] - t[1]) / (2 * h)
        d_aff = np.concatenate([d_rot.reshape(n, 3, 3, 3), d_trans.reshape(n, 3, 3, 1)], axis=3)  # [j,c,a,β]
        reg_var = np.einsum("jcab,jcd,jdae->be", d_aff, net_cov, d_aff)
        shared = np.einsum("jcab,jca->jb", d_aff, net_cov)
        return cls(a0[0], t0[0], d_aff, net_cov, reg_var, shared)

    def apply(self, x: np.ndarray) -> np.ndarray:
        return map_points(x, self.rot, self.trans)

    def variance(self, h: np.ndarray) -> np.ndarray:
        """tr Cov of Σ_β h_β (δA, δt)_β for homogeneous combinations h (..., 4): hᵀ K h (mm²)."""
        return np.einsum("...b,bc,...c->...", h, self.reg_var, h)


def _homogeneous(x: np.ndarray) -> np.ndarray:
    return np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1)


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
    q_h: np.ndarray  # (M,4) check points, homogeneous sensor coordinates
    q_target_var: np.ndarray  # (M,) tr R Σ_s(q) Rᵀ
    q_rigid_noise_var: np.ndarray  # (M,)
    n_targets: int

    @classmethod
    def from_cell(cls, cell) -> tuple[_Model, _Readings]:
        rd = _readings(cell)
        ri = cell.index("registration", "both")
        qi = cell.index("check")
        reg = _Registration.fit(rd.sensor[ri], rd.robot[ri], rd.net_cov[ri])
        qs = rd.sensor[qi]
        hq = _homogeneous(qs)
        var_t = np.trace(rd.sensor_cov[qi], axis1=1, axis2=2)
        n_t = len({t for t in (cell.check_target[i] for i in qi)})
        model = cls(reg, cell.robot[ri], qs, reg.apply(qs) - rd.truth[qi], hq, var_t, reg.variance(hq) + var_t, n_t)
        return model, rd

    def rmst(self, sq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """RMST and its sampling std from squared errors (..., M) with M = n_targets x n per target."""
        per: np.ndarray = sq.reshape(sq.shape[:-1] + (self.n_targets, -1))
        n = per.shape[-1]
        mse = per.mean(axis=(-1, -2))
        var_mse = (per.var(axis=-1, ddof=1) / n).sum(axis=-1) / self.n_targets**2 if n > 1 else 0 * mse
        rmst = np.sqrt(mse)
        with np.errstate(divide="ignore", invalid="ignore"):
            std = np.where(rmst > 0, np.sqrt(var_mse) / (2 * rmst), 0.0)
        return rmst, std

    def rigid(self) -> tuple[float, float]:
        sq = np.sum(self.q_rigid_err**2, axis=1) + self.q_rigid_noise_var
        r, s = self.rmst(sq)
        return float(r), float(s)

    def rrbc_sq(self, f_sensor, f_corr, f_cov, shared) -> np.ndarray:
        """Squared RRBC errors (T, M) for T fiducial sets (stacked): f_sensor (T,N,3) bias-only sensor readings,
        f_corr (T,N,3) robot-frame corrections b − T̂(s), f_cov (T,N,3,3) net FLE covariance, shared (T,N) index
        of the registration point a fiducial is (−1: none). The registration's share of the noise is
        Var(T̂(x_q) − Σ_i w_qi T̂(x_i)) = hᵀ K h with h = h_q − Σ_i w_qi h_i (`_Registration`)."""
        if f_sensor.shape[1] == 0:
            sq = np.sum(self.q_rigid_err**2, axis=1) + self.q_rigid_noise_var
            return np.broadcast_to(sq, (f_sensor.shape[0], len(sq))).copy()
        w = _idw_weights(f_sensor, self.q_sensor)  # (T,M,N)
        bias = self.q_rigid_err[None] + np.matmul(w, f_corr)
        hh = self.q_h[None] - np.matmul(w, _homogeneous(f_sensor))  # (T,M,4)
        var = self.reg.variance(hh)
        var += np.einsum("tmn,tn->tm", w**2, np.trace(f_cov, axis1=2, axis2=3))
        if np.any(shared >= 0):
            ti, ni = np.nonzero(shared >= 0)
            tr = np.einsum("smb,sb->sm", hh[ti], self.reg.shared[shared[ti, ni]])
            np.add.at(var, ti, 2.0 * w[ti, :, ni] * tr)
        var += self.q_target_var[None]
        return np.sum(bias**2, axis=2) + var

    def shared_index(self, positions: np.ndarray) -> np.ndarray:
        d = np.linalg.norm(positions[:, None] - self.reg_pos[None], axis=2)
        j = np.argmin(d, axis=1) if len(self.reg_pos) else np.zeros(len(positions), int)
        return np.where(d[np.arange(len(positions)), j] <= _SAME_MM, j, -1)


def _fid_arrays(model: _Model, rd: _Readings, idx: np.ndarray):
    s = rd.sensor[idx]
    return s, rd.robot[idx] - model.reg.apply(s), rd.net_cov[idx]


def _predict_fast(scene, fid: np.ndarray, registration, samples_per_target: int, seed: int) -> RmstPrediction:
    cell, fi = _cell(scene, fid, registration, samples_per_target, seed)
    model, rd = _Model.from_cell(cell)
    rigid, rigid_std = model.rigid()
    s, corr, cov = _fid_arrays(model, rd, fi)
    shared = model.shared_index(cell.robot[fi])
    sq = model.rrbc_sq(s[None], corr[None], cov[None], shared[None])
    r, st = model.rmst(sq)
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
