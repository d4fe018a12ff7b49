"""Simulated work cells: from a true cell to measured data, and Monte Carlo statistics over trials.

Frames and units: the scene frame is the robot base frame (mm); the sensor frame has the sensor at its origin
(z along the view). The true registration is `cell.sensor_to_robot` (robot = R @ sensor + t).

Generative model (docs/theory.md §5.3). For a physical point p (robot frame) reached with tool orientation R_p
at time τ:
- the sensor reports  s = T⁻¹(p) + δ_s          (δ_s: the error model's sensor terms, sensor frame)
- the robot reports   b = p + δ_r               (δ_r: the robot terms, robot frame: kinematic bias, noise, …)
- a check point's truth is the robot command that really reaches p: c = p + β_r(p), with β_r the
  deterministic robot terms only (the robot carries its bias to the target; its noise is not part of truth).
Deterministic terms (bias, drift) are the same in every trial; random terms (noise, outliers) are redrawn.
Points the sensor cannot see (ray cast against the cell's mesh, `visibility.py`) are not measured.
"""

from __future__ import annotations

import dataclasses
import time as _time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from rrbc_core import interpolation, registration
from rrbc_core.correction import metrics
from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform
from rrbc_core.models.errormodels import ErrorModel, PointSet
from rrbc_core.models.measurement import MeasurementModel
from rrbc_core.runtime.threads import thread_limited
from rrbc_core.simulation import batch

if TYPE_CHECKING:
    from rrbc_core.io.scene import Scene

STRATEGY_NAMES = tuple(registration.STRATEGIES)  # the registries' names, in their order
#: every fixed method (`auto` re-chooses per trial by cross-validation: run it through `rrbc correct` on a file)
INTERPOLATION_NAMES = tuple(name for name in interpolation.METHODS if name != "auto")
MAX_TRIALS = 100_000  # Monte Carlo trials `simulate` runs at most (issue 16: a stated limit)
MAX_ICP_TRIALS = 1000  # ICP trials (`simulate --icp`) at most: each registers a point cloud against the mesh


@dataclass(frozen=True, eq=False)
class WorkCell:
    """The truth of a work cell, ready to be measured.

    ids/roles: one entry per physical point; roles are measurement-file roles (registration, fiducial, both,
    target, check). robot: (P, 3) true physical positions, robot frame, mm. time: (P,) s. tool_rotation:
    (P, 3, 3) robot-frame tool orientation used at each point. occluded: ids dropped because the sensor cannot
    see them. distance_origin: the point (robot frame) from which "distance from the frame origin" is measured.
    """

    name: str
    sensor_to_robot: RigidTransform
    ids: tuple[str, ...]
    roles: tuple[str, ...]
    robot: np.ndarray
    time: np.ndarray
    tool_rotation: np.ndarray
    error_model: ErrorModel
    joint_seed: np.ndarray | None = None
    occluded: tuple[str, ...] = ()
    distance_origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    check_target: tuple[str, ...] = ()  # per point: the target a check point belongs to ('' otherwise)

    def index(self, *roles: str) -> np.ndarray:
        return np.array([i for i, r in enumerate(self.roles) if r in roles], dtype=int)

    @property
    def sensor_truth(self) -> np.ndarray:
        """(P, 3) the true points in the sensor frame, mm."""
        return self.sensor_to_robot.apply_inverse(self.robot)

    def measurement_model(self) -> MeasurementModel:
        return MeasurementModel(self.sensor_to_robot, self.error_model, self.joint_seed)

    def point_set(self) -> PointSet:
        return self.measurement_model().points(self.robot, self.tool_rotation, self.time)


def work_cell_from_scene(
    scene, seed: int | None = None, checks_per_target: int | None = None, visibility: bool = True
) -> WorkCell:
    """Build the true cell of a scene: registration points, fiducials, targets at their nominal positions,
    and check points sampled uniformly inside each target's region of variability (seeded).

    A point that is both a registration point and a fiducial (same id) gets role `both`. Points are measured
    in file order, `scene.measurement_interval_s` apart, each with the tool pointing down at its own yaw. With
    `visibility` (and a sensor with a line of sight, not `ground_truth`), points the sensor cannot see from its
    pose (ray cast against the scene mesh) are dropped and listed in `occluded`.
    """
    from rrbc_core.models.kinematics import tool_down

    rng = np.random.default_rng(scene.seed if seed is None else seed)
    n_checks = scene.check_points_per_target if checks_per_target is None else checks_per_target
    if n_checks < 0:
        raise InputError("checks per target must be >= 0")
    ids, roles, pos, owner, yaw = [], [], [], [], []

    def add(pid, role, p, y, of=""):
        ids.append(pid)
        roles.append(role)
        pos.append(p)
        yaw.append(y)
        owner.append(of)

    fid_ids = set(scene.fiducials.ids)
    reg_ids = set(scene.registration.ids)
    reg, fid = scene.registration, scene.fiducials
    for pid, p, y in zip(reg.ids, reg.positions, reg.tool_yaw_deg):
        add(pid, "both" if pid in fid_ids else "registration", p, y)
    for pid, p, y in zip(fid.ids, fid.positions, fid.tool_yaw_deg):
        if pid not in reg_ids:
            add(pid, "fiducial", p, y)
    for tgt in scene.targets:
        add(tgt.id, "target", tgt.position, tgt.tool_yaw_deg)
    for tgt in scene.targets:
        for k, p in enumerate(tgt.region.sample(rng, n_checks)):
            add(f"{tgt.id}.c{k:02d}", "check", p, tgt.tool_yaw_deg, tgt.id)
    robot = np.array(pos, dtype=float).reshape(-1, 3)
    yaws = np.array(yaw, dtype=float)
    occluded: tuple[str, ...] = ()
    if visibility and scene.line_of_sight:
        from rrbc_core.models.visibility import visible_points

        vis = visible_points(scene.load_mesh(), scene.sensor_to_robot.translation, robot)
        occluded = tuple(i for i, v in zip(ids, vis) if not v)
        keep = np.flatnonzero(vis)
        ids = [ids[i] for i in keep]
        roles = [roles[i] for i in keep]
        owner = [owner[i] for i in keep]
        robot, yaws = robot[keep], yaws[keep]
    times = np.arange(len(ids)) * float(scene.measurement_interval_s)
    rot = np.array([tool_down(y) for y in yaws]).reshape(-1, 3, 3)
    cell = WorkCell(
        name=scene.name,
        sensor_to_robot=scene.sensor_to_robot,
        ids=tuple(ids),
        roles=tuple(roles),
        robot=robot,
        time=times,
        tool_rotation=rot,
        error_model=scene.error_model,
        joint_seed=scene.joint_seed,
        occluded=occluded,
        distance_origin=np.asarray(scene.distance_origin, dtype=float),
        check_target=tuple(owner),
    )
    _check_cell(cell)
    return cell


def _check_cell(cell: WorkCell) -> None:
    n_reg = len(cell.index("registration", "both"))
    if n_reg < 3:
        hidden = (
            f" ({len(cell.occluded)} points are hidden from the sensor: {', '.join(cell.occluded[:6])})"
            if cell.occluded
            else ""
        )
        raise InputError(
            f"scene '{cell.name}': {n_reg} registration points are visible to the sensor; at least 3 are needed{hidden}"
        )


@dataclass(frozen=True, eq=False)
class Measured:
    """T simulated measurements of a cell. sensor: (T, P, 3) sensor readings (sensor frame); robot: (T, P, 3)
    robot readings (robot frame); truth: (P, 3) the robot command that reaches each physical point."""

    sensor: np.ndarray
    robot: np.ndarray
    truth: np.ndarray


@thread_limited
def measure(cell: WorkCell, rng: np.random.Generator, trials: int = 1) -> Measured:
    """Simulate `trials` independent measurement sessions of the cell (bias fixed, noise redrawn), through the
    measurement model (`measurement.MeasurementModel`)."""
    if trials < 1:
        raise InputError(f"trials must be >= 1, got {trials}")
    model = cell.measurement_model()
    pts = cell.point_set()
    r = model.read(pts, noise=model.noise(pts, rng, trials))
    return Measured(
        np.ascontiguousarray(np.broadcast_to(r.sensor, (trials,) + pts.sensor.shape)),
        np.ascontiguousarray(np.broadcast_to(r.robot, (trials,) + pts.robot.shape)),
        r.truth,
    )


@dataclass(frozen=True, eq=False)
class TrialErrors:
    """Per-trial check-point errors (T, M) in mm for one registration strategy and interpolation method."""

    registration: str
    interpolation: str
    rigid: np.ndarray
    rrbc: np.ndarray


@thread_limited
def trial_errors(
    cell: WorkCell,
    measured: Measured,
    registration: str = "least-squares",
    interpolation: str = "idw",
    seeds=None,
    **interp_options,
) -> TrialErrors:
    """Run registration + RRBC on every trial (vectorised where `batch` can) and score the check points."""
    reg = cell.index("registration", "both")
    fid = cell.index("fiducial", "both")
    chk = cell.index("check")
    if len(chk) == 0:
        raise InputError(f"scene '{cell.name}': no check points to score (sample some inside the target regions)")
    if len(fid) == 0 and interpolation != "none":
        raise InputError(f"scene '{cell.name}': no fiducials visible to the sensor; RRBC needs fiducials")
    out = batch.rrbc_batch(
        registration,
        interpolation,
        measured.sensor[:, reg],
        measured.robot[:, reg],
        measured.sensor[:, fid],
        measured.robot[:, fid],
        measured.sensor[:, chk],
        seeds=seeds,
        **interp_options,
    )
    truth = measured.truth[chk][None]
    rigid = np.linalg.norm(out["robot_rigid"] - truth, axis=-1)
    rrbc = np.linalg.norm(out["robot_rrbc"] - truth, axis=-1)
    return TrialErrors(registration, interpolation, rigid, rrbc)


@dataclass(frozen=True)
class StrategyStats:
    """Monte Carlo statistics of one registration strategy over all trials and check points (mm).

    tre_*: rigid registration only; r_distance: Pearson correlation of the rigid error with the distance of
    the check point from the cell's distance origin; rmst_rrbc_mm / max_rrbc_mm: after RRBC with IDW (k=4, p=2).
    """

    name: str
    tre_mean_mm: float
    tre_rms_mm: float
    tre_max_mm: float
    r_distance: float
    rmst_rrbc_mm: float
    max_rrbc_mm: float


@dataclass(frozen=True)
class InterpolationStats:
    """RRBC after least-squares registration, by interpolation method (mm)."""

    name: str
    rmst_mm: float
    max_mm: float
    mean_mm: float


@dataclass(frozen=True)
class MonteCarloResult:
    """The outcome of `monte_carlo` / `simulate`: per registration strategy (`strategies`, `StrategyStats`) the
    rigid TRE mean, RMS and max (mm) at the check points, its correlation with distance, and the RMST after RRBC
    (IDW); per interpolation (`interpolations`, `InterpolationStats`) the RMST after least squares + RRBC; the scene,
    trials, seed and seconds. `to_json()` is the JSON of `rrbc simulate --json`.
    """

    scene: str
    trials: int
    seconds: float
    seed: int
    strategies: tuple[StrategyStats, ...]
    interpolations: tuple[InterpolationStats, ...]
    n_registration: int
    n_fiducials: int
    n_checks: int
    occluded: tuple[str, ...]
    icp_trials: int = 0  # trials behind an "icp" strategy row (point-cloud registration is ~1 s per trial)

    def to_json(self) -> dict:
        """JSON of `rrbc simulate --json` (NaN, e.g. a correlation of constant errors, becomes null). A function of
        the inputs only - no wall time - so the same command prints the same bytes wherever its tasks ran."""
        return _nan_to_none(
            {
                "scene": self.scene,
                "trials": self.trials,
                "seed": self.seed,
                "strategies": [
                    {**s.__dict__, **({"trials": self.icp_trials} if s.name == "icp" else {})} for s in self.strategies
                ],
                "interpolations": [s.__dict__ for s in self.interpolations],
                "points": {
                    "registration": self.n_registration,
                    "fiducials": self.n_fiducials,
                    "checks": self.n_checks,
                    "occluded": list(self.occluded),
                },
            }
        )


def _nan_to_none(obj):
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_nan_to_none(v) for v in obj]
    return obj


def _strategy_stats(name: str, rigid: np.ndarray, rrbc: np.ndarray, dist: np.ndarray) -> StrategyStats:
    """Statistics of errors (T, C) at C check points over T trials; dist (C,) from the distance origin."""
    return StrategyStats(
        name=name,
        tre_mean_mm=float(rigid.mean()),
        tre_rms_mm=metrics.rmst(rigid.ravel()),
        tre_max_mm=float(rigid.max()),
        r_distance=_pearson(rigid.ravel(), np.broadcast_to(dist, rigid.shape).ravel()),
        rmst_rrbc_mm=metrics.rmst(rrbc.ravel()),
        max_rrbc_mm=float(rrbc.max()),
    )


def _pearson(a: np.ndarray, b: np.ndarray) -> float:
    if np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])


@thread_limited
@dataclass(frozen=True)
class _Chunk:
    """One independent task of a Monte Carlo: `n` trials of `cell` with their own seed sequence."""

    cell: WorkCell
    n: int
    seed: np.random.SeedSequence
    strategies: tuple
    interpolations: tuple


def _run_chunk(c: _Chunk) -> tuple[dict, dict]:
    """Per strategy (rigid, rrbc) errors and per interpolation rrbc errors, (n, C) mm, for one chunk."""
    rng = np.random.default_rng(c.seed)
    measured = measure(c.cell, rng, c.n)
    seeds = rng.integers(0, 2**31 - 1, c.n)
    by_s = {}
    for name in c.strategies:
        e = trial_errors(c.cell, measured, name, "idw", seeds=seeds)
        by_s[name] = (e.rigid, e.rrbc)
    by_i = {name: trial_errors(c.cell, measured, "least-squares", name, seeds=seeds).rrbc for name in c.interpolations}
    return by_s, by_i


def monte_carlo(
    cell: WorkCell,
    trials: int,
    seed: int = 0,
    strategies=STRATEGY_NAMES,
    interpolations=INTERPOLATION_NAMES,
    chunk: int = 2000,
    progress=None,
    scheduler: str | None = None,
) -> MonteCarloResult:
    """Monte Carlo over `trials` sessions: per strategy, rigid TRE mean/RMS/max, correlation of the error with
    distance from the origin, and RMST after RRBC (IDW); per interpolation method, RMST after least-squares
    registration + RRBC. Trials run in chunks of `chunk` (memory bound), each an independent task with its own
    seed sequence (`runtime.tasks.spawn_seeds(seed, chunks)`), run where `scheduler` says (`runtime.tasks`: in
    this process by default) and reduced in chunk order: the same seed gives the same numbers on one process or
    on any cluster. `progress(n, label)` is called as chunks complete.
    """
    from rrbc_core.runtime.tasks import run_tasks, spawn_seeds

    if not 1 <= trials <= MAX_TRIALS:
        raise InputError(
            f"trials must be 1 to {MAX_TRIALS:,} (per-trial errors are kept for every check point), got {trials:,}"
        )
    for name in strategies:
        if name not in STRATEGY_NAMES:
            raise InputError(f"unknown registration strategy '{name}': choose from {', '.join(STRATEGY_NAMES)}")
    for name in interpolations:
        if name not in INTERPOLATION_NAMES:
            raise InputError(f"unknown interpolation '{name}': choose from {', '.join(INTERPOLATION_NAMES)}")
    t0 = _time.perf_counter()
    chk = cell.index("check")
    dist = np.linalg.norm(cell.robot[chk] - cell.distance_origin, axis=1)
    sizes = [min(chunk, trials - a) for a in range(0, trials, chunk)]
    tasks = [
        _Chunk(cell, n, sq, tuple(strategies), tuple(interpolations))
        for n, sq in zip(sizes, spawn_seeds(seed, len(sizes)))
    ]
    per_task = (len(strategies) + len(interpolations)) * chunk
    done = run_tasks(
        _run_chunk, tasks, scheduler, progress=(lambda k: progress(per_task * k, "trials")) if progress else None
    )
    acc_s = {name: ([r[0][name][0] for r in done], [r[0][name][1] for r in done]) for name in strategies}
    acc_i = {name: [r[1][name] for r in done] for name in interpolations}
    stats = [
        _strategy_stats(name, np.concatenate(acc_s[name][0]), np.concatenate(acc_s[name][1]), dist)
        for name in strategies
    ]
    istats = []
    for name in interpolations:
        e = np.concatenate(acc_i[name])
        istats.append(InterpolationStats(name, metrics.rmst(e.ravel()), float(e.max()), float(e.mean())))
    return MonteCarloResult(
        scene=cell.name,
        trials=trials,
        seconds=_time.perf_counter() - t0,
        seed=seed,
        strategies=tuple(stats),
        interpolations=tuple(istats),
        n_registration=len(cell.index("registration", "both")),
        n_fiducials=len(cell.index("fiducial", "both")),
        n_checks=len(chk),
        occluded=cell.occluded,
    )


@thread_limited
def icp_statistics(
    scene,
    cell: WorkCell,
    trials: int,
    seed: int = 0,
    start_error_deg: float = 2.0,
    start_error_mm: float = 10.0,
    progress=None,
) -> StrategyStats:
    """Point-cloud registration as the alternative step 2: per trial, the sensor's view of the cell's mesh is
    ray cast from its true pose (open3d), perturbed by the scene's random sensor terms, and registered to the
    mesh by ICP from the true pose perturbed by a seeded random rotation of `start_error_deg` and shift of
    `start_error_mm`; the check points (measured in the same trial) are then mapped with that transform
    (rigid) and corrected by RRBC with IDW over the fiducials. About 1 s per trial."""
    from rrbc_core.correction.rrbc import correct_points, fiducial_corrections
    from rrbc_core.geometry.transforms import rotation_from_rotvec
    from rrbc_core.interpolation import IDW
    from rrbc_core.models.cloud_registration import icp_registration, simulate_cloud

    if trials < 1:
        raise InputError(f"ICP trials must be >= 1, got {trials}")
    mesh = scene.load_mesh()
    truth_pose = cell.sensor_to_robot
    rnd = cell.error_model.random_terms()
    rng = np.random.default_rng([seed, 2])
    fid, chk = cell.index("fiducial", "both"), cell.index("check")
    dist = np.linalg.norm(cell.robot[chk] - cell.distance_origin, axis=1)

    def noise(points_sensor, gen):
        ps = PointSet(robot=truth_pose.apply(points_sensor), sensor=points_sensor, time=np.zeros(len(points_sensor)))
        return (
            rnd.only(*[t.kind for t in rnd.sensor]).sample(ps, "sensor", gen, 1)[0] if rnd.sensor else 0 * points_sensor
        )

    rigid, rrbc = [], []
    for _ in range(trials):
        m = measure(cell, rng, 1)
        cloud = simulate_cloud(mesh, truth_pose, rng=rng, noise=noise)
        axis = rng.normal(size=3)
        shift = rng.normal(size=3)
        start = RigidTransform(
            rotation_from_rotvec(axis / np.linalg.norm(axis) * np.radians(start_error_deg)) @ truth_pose.rotation,
            truth_pose.translation + shift / np.linalg.norm(shift) * start_error_mm,
        )
        reg = icp_registration(cloud, mesh, start, seed=int(rng.integers(2**31 - 1)))
        corr = fiducial_corrections(reg.mapping, m.sensor[0, fid], m.robot[0, fid])
        out = correct_points(reg.mapping, IDW().fit(m.sensor[0, fid], corr), m.sensor[0, chk])
        rigid.append(np.linalg.norm(out.robot_rigid - m.truth[chk], axis=1))
        rrbc.append(np.linalg.norm(out.robot_rrbc - m.truth[chk], axis=1))
        if progress:
            progress(1, "icp")
    return _strategy_stats("icp", np.array(rigid), np.array(rrbc), dist)


@thread_limited
def simulate(
    scene: Scene,
    trials: int = 200,
    *,
    seed: int = 0,
    layout: str | None = None,
    icp: int = 0,
    progress: Callable[[int, str], object] | None = None,
    scheduler: str | None = None,
) -> MonteCarloResult:
    """Monte Carlo of a scene's robot and sensor with its error model: what `rrbc simulate` reports.

    Parameters
    ----------
    scene : Scene
        A loaded scene (`load_scene`).
    trials : int
        Monte Carlo trials (noise redrawn in each, bias fixed by the scene's seeds).
    seed : int
        Seed of the noise, of the check points sampled in the targets' regions and of annealing.
    layout : str, optional
        A named layout of the scene (its registration points and fiducials) to simulate instead.
    icp : int
        Also register by ICP of a simulated depth-sensor point cloud against the cell mesh, over this many trials.
    progress : callable, optional
        ``progress(n, label)``, called as work completes.
    scheduler : str, optional
        Where the trial chunks run (`runtime.tasks.run_tasks`): None (then $RRBC_SCHEDULER, else this process),
        "local" or a dask scheduler's address. The numbers do not depend on it.

    Returns
    -------
    MonteCarloResult
        Per registration strategy the rigid TRE (mean, RMS, max, mm) at the check points and its correlation
        with distance, and the RMST after RRBC (IDW); per interpolation method the RMST after least squares +
        RRBC; `to_json()` gives the command's JSON.
    """
    if not 0 <= int(icp) <= MAX_ICP_TRIALS:
        raise InputError(
            f"--icp must be 0 to {MAX_ICP_TRIALS:,} trials (each registers a point cloud against the mesh), got "
            f"{int(icp):,}"
        )
    if layout:
        scene = scene.with_layout(layout)
    cell = work_cell_from_scene(scene, seed=seed)
    start = _time.perf_counter()
    res = monte_carlo(cell, trials, seed=seed, progress=progress, scheduler=scheduler)
    if icp:
        icp_row = icp_statistics(scene, cell, icp, seed=seed, progress=progress)
        res = dataclasses.replace(
            res, strategies=res.strategies + (icp_row,), icp_trials=icp, seconds=_time.perf_counter() - start
        )
    return res
