"""A scene's error model simulated at a measured file's own points (`rrbc check-model`'s *predict*;
docs/check_model.md).

The file gives the points, their roles, times, stations (`group`) and, with q1..q6 columns, the arm's joints; the
scene gives the error model. Each station's true sensor→robot transform is taken as the rigid fit of its own
registration rows (robot = R @ sensor + t): the scene's sensor pose is where the scene's designer put the sensor,
the fit is where the file's sensor was. A row's physical point is its robot reading (a target row: its sensor
reading mapped by the fit); its tool points down at the scene's yaw, or, with joint columns and a UR5/UR10 scene,
is the orientation those joints give. The measurement model (`models.measurement`) reads every point `trials`
times; check rows keep the truth as their robot value (the measurement-file format), target rows none.

Every trial, and the file itself, is scored by one function (`figures`): per station (rows repeated under one id
averaged into one point, as `rrbc correct` does) the least-squares registration of its registration rows, RRBC (IDW k = 4, p = 2) from its fiducial rows to its check rows
(`simulation.batch.rrbc_batch`, equal to `rrbc correct`'s pipeline), the rigid residual of every row with a robot
value, and the pooled FRE and check RMS. So a measured figure and its predicted distribution are computed alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform
from rrbc_core.io.groups import GROUP_COLUMN, has_groups
from rrbc_core.io.measurements import MeasurementSet, select_rows
from rrbc_core.models.errormodels import ErrorModel, PointSet
from rrbc_core.models.measurement import MeasurementModel
from rrbc_core.registration.strategies import least_squares

__all__ = [
    "Figures",
    "Interval",
    "Station",
    "at_physical_points",
    "figures",
    "file_stations",
    "measured_figures",
    "predict",
]

MAX_WORK = 20_000_000  # trials x rows x 3: the largest simulation a command will hold in memory (about 0.5 GB)
REGISTRATION_ROLES = ("registration", "both")
FIDUCIAL_ROLES = ("fiducial", "both")


@dataclass(frozen=True)
class Interval:
    """A predicted figure: its mean over the trials and the 2.5 % and 97.5 % quantiles (mm)."""

    mean: float
    lo95: float
    hi95: float

    @classmethod
    def of(cls, samples: np.ndarray) -> Interval:
        s = np.asarray(samples, float)
        lo, hi = np.quantile(s, [0.025, 0.975])
        return cls(float(np.mean(s)), float(lo), float(hi))

    def contains(self, value: float) -> bool:
        return self.lo95 <= value <= self.hi95

    def to_json(self) -> dict:
        return {"mean": self.mean, "lo95": self.lo95, "hi95": self.hi95}


@dataclass(frozen=True, eq=False)
class Station:
    """One station of the file: `rows` (its row indices in the file), `transform` (the fit of its registration rows,
    robot = R @ sensor + t), `points` (its rows' physical points as the error terms see them) and `joint_seed`."""

    name: str
    rows: np.ndarray
    transform: RigidTransform
    points: PointSet
    joint_seed: np.ndarray | None

    def model(self, error_model: ErrorModel) -> MeasurementModel:
        return MeasurementModel(self.transform, error_model, self.joint_seed)


@dataclass(frozen=True, eq=False)
class Figures:
    """What one reading of the file (or each of T trials) shows: `residual` (T, R, 3) mm, robot frame, the rigid
    residual robot − (R sensor + t) of every row with a robot value (NaN for target rows); `fre` (T,) the pooled RMS of
    the registration rows' residuals; `rmst_rigid`, `rmst_rrbc` (T,) the pooled RMS check error rigid and with RRBC
    (None without check rows; RRBC None without fiducial rows); `mapped` (T, R, 3) every row's sensor reading mapped
    by its station's registration."""

    residual: np.ndarray
    fre: np.ndarray
    rmst_rigid: np.ndarray | None
    rmst_rrbc: np.ndarray | None
    mapped: np.ndarray


def _roles(mset: MeasurementSet) -> np.ndarray:
    return np.asarray(mset.roles, dtype=object)


def _station_rows(mset: MeasurementSet) -> list[tuple[str, np.ndarray]]:
    if not has_groups(mset):
        return [("", np.arange(len(mset)))]
    values = np.asarray(mset.extra[GROUP_COLUMN], dtype=object)
    return [(str(g), np.flatnonzero(values == g)) for g in dict.fromkeys(values.tolist())]


def _tool_rotations(
    mset: MeasurementSet, robot_model: str, tool_yaw_deg: float
) -> tuple[np.ndarray, np.ndarray | None]:
    """(R, 3, 3) the tool orientation at each row and the rows' joints (R, 6) rad, or None without q1..q6 columns."""
    from rrbc_core.io.joints import joint_angles
    from rrbc_core.models.kinematics import UR5, UR10, forward, tool_down

    q = joint_angles(mset) if any(c in mset.extra for c in ("q1", "q2")) else None
    if q is not None and robot_model in ("ur5", "ur10"):
        return forward(UR5 if robot_model == "ur5" else UR10, q)[1], q
    return np.broadcast_to(tool_down(tool_yaw_deg), (len(mset), 3, 3)).copy(), q


def _physical(reading: np.ndarray, st: Station, error_model: ErrorModel, exact: np.ndarray) -> np.ndarray:
    """The physical points whose biased robot reading is `reading` (R, 3): p = reading − β_r(p), two fixed-point
    steps from p = reading (a rough field evaluated at a reading's place instead of the point's would look like
    noise). Rows where `exact` is False (targets: a mapped sensor reading) are kept."""
    if not error_model.deterministic().robot:
        return reading
    p = reading
    for _ in range(2):
        pts = PointSet(
            p, st.transform.apply_inverse(p), st.points.time, st.points.tool_rotation, st.joint_seed, st.points.joints
        )
        bias_r = st.model(error_model).bias(pts)[1]
        p = np.where(exact[:, None], reading - bias_r, reading)
    return p


def at_physical_points(mset: MeasurementSet, stations: list[Station], error_model: ErrorModel) -> list[Station]:
    """The stations with each row's physical point solved for under `error_model`'s robot-side bias (`_physical`)."""
    roles = _roles(mset)
    out = []
    for st in stations:
        exact = roles[st.rows] != "target"
        p = _physical(st.points.robot, st, error_model, exact)
        pts = PointSet(
            p, st.transform.apply_inverse(p), st.points.time, st.points.tool_rotation, st.joint_seed, st.points.joints
        )
        out.append(Station(st.name, st.rows, st.transform, pts, st.joint_seed))
    return out


def file_stations(
    mset: MeasurementSet, robot_model: str = "none", tool_yaw_deg: float = 0.0, joints: np.ndarray | None = None
) -> list[Station]:
    """The file's stations with their fitted transforms and physical points (module docstring); `joints` (R, I): the
    arm's joint values the file recorded (the chain's inputs, rad or mm), carried to the points for `arm_errors`.

    Raises
    ------
    InputError
        A station with fewer than 3 registration rows (roles registration or both) with robot values.
    """
    roles = _roles(mset)
    paired = (roles != "target") & np.all(np.isfinite(mset.robot), axis=1)
    time = np.asarray(mset.time, float)
    time = np.where(np.isfinite(time), time, np.nanmean(time) if np.any(np.isfinite(time)) else 0.0)
    rotations, q = _tool_rotations(mset, robot_model, tool_yaw_deg)
    out = []
    for name, rows in _station_rows(mset):
        where = f"{mset.source}" + (f", group {name!r}" if name else "")
        reg_pts = select_rows(mset, rows).points("registration")  # repeated rows averaged, as `rrbc correct` does
        if len(reg_pts.ids) < 3:
            raise InputError(
                f"{where}: {len(reg_pts.ids)} registration points (role registration or both) with robot values; "
                "the prediction needs at least 3 per station"
            )
        fit = least_squares(reg_pts.sensor, reg_pts.robot).mapping
        mapping = RigidTransform(fit.rotation, fit.translation)
        physical = np.where(paired[rows, None], mset.robot[rows], mapping.apply(mset.sensor[rows]))
        seed = None if q is None else q[rows[0]]
        pts = PointSet(
            physical,
            mapping.apply_inverse(physical),
            time[rows],
            rotations[rows],
            seed,
            None if joints is None else joints[rows],
        )
        out.append(Station(name, rows, mapping, pts, seed))
    return out


def figures(mset: MeasurementSet, stations: list[Station], sensor: np.ndarray, robot: np.ndarray) -> Figures:
    """Score readings of the file's rows (module docstring).

    Parameters
    ----------
    mset : MeasurementSet
        The file (its roles).
    stations : list of Station
        `file_stations(mset)`.
    sensor, robot : (T, R, 3) arrays
        Sensor readings (sensor frame) and robot values (robot frame; check rows the truth; NaN for targets), mm.

    Returns
    -------
    Figures
    """
    from rrbc_core.simulation.batch import rrbc_batch

    roles = _roles(mset)
    trials, n_rows = sensor.shape[:2]
    resid = np.full((trials, n_rows, 3), np.nan)
    mapped = np.full((trials, n_rows, 3), np.nan)
    fre_ss, n_reg = np.zeros(trials), 0
    rig_ss, rr_ss, n_chk, any_fid = np.zeros(trials), np.zeros(trials), 0, True
    ids = np.asarray(mset.ids, dtype=object)

    def by_id(arr: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """(T, K, 3): the rows' values averaged per distinct id (repeated rows are one point, as `rrbc correct`)."""
        _, inv = np.unique(ids[rows], return_inverse=True)
        k = int(inv.max()) + 1 if len(inv) else 0
        out = np.zeros((k, arr.shape[0], 3))  # point-major, so that add.at takes one index array
        np.add.at(out, inv, np.swapaxes(arr[:, rows], 0, 1))
        return np.swapaxes(out, 0, 1) / np.bincount(inv, minlength=k)[None, :, None]

    for st in stations:
        r = st.rows
        role = roles[r]
        ok = role != "target"
        reg, fid, chk = r[np.isin(role, REGISTRATION_ROLES)], r[np.isin(role, FIDUCIAL_ROLES)], r[role == "check"]
        any_fid &= len(fid) > 0
        reg_s, reg_b = by_id(sensor, reg), by_id(robot, reg)
        chk_s, chk_b = by_id(sensor, chk), by_id(robot, chk)
        out = rrbc_batch(
            "least-squares",
            "idw" if len(fid) else "none",
            reg_s,
            reg_b,
            by_id(sensor, fid),
            by_id(robot, fid),
            np.concatenate([sensor[:, r], reg_s, chk_s], axis=1),
            hull="none",
        )
        n, k = len(r), reg_s.shape[1]
        rigid = out["robot_rigid"]
        mapped[:, r] = rigid[:, :n]
        resid[:, r[ok]] = robot[:, r[ok]] - rigid[:, :n][:, ok]
        fre_ss += np.sum((reg_b - rigid[:, n : n + k]) ** 2, axis=(1, 2))
        n_reg += k
        if len(chk):
            rig_ss += np.sum((chk_b - rigid[:, n + k :]) ** 2, axis=(1, 2))
            rr_ss += np.sum((chk_b - out["robot_rrbc"][:, n + k :]) ** 2, axis=(1, 2))
            n_chk += chk_s.shape[1]
    return Figures(
        resid,
        np.sqrt(fre_ss / n_reg),
        np.sqrt(rig_ss / n_chk) if n_chk else None,
        np.sqrt(rr_ss / n_chk) if n_chk and any_fid else None,
        mapped,
    )


def measured_figures(mset: MeasurementSet, stations: list[Station]) -> Figures:
    """The file's own figures (T = 1)."""
    return figures(mset, stations, np.asarray(mset.sensor, float)[None], np.asarray(mset.robot, float)[None])


def predict(mset: MeasurementSet, stations: list[Station], error_model: ErrorModel, trials: int, seed: int) -> Figures:
    """`trials` readings of the file's points drawn from `error_model` (module docstring), scored by `figures`.

    Raises
    ------
    InputError
        trials x rows beyond `MAX_WORK` / 3 (say fewer trials), or an error term that cannot be evaluated at the
        file's points (a kinematic term at a point its arm cannot reach).
    """
    n_rows = len(mset)
    if trials * n_rows * 3 > MAX_WORK:
        raise InputError(
            f"{trials} trials of {n_rows} rows is more than this command simulates at once "
            f"({MAX_WORK // 3:,} point readings): use --trials {max(MAX_WORK // (3 * n_rows), 1)} or fewer"
        )
    roles = _roles(mset)
    rng = np.random.default_rng(seed)
    sensor = np.empty((trials, n_rows, 3))
    robot = np.empty((trials, n_rows, 3))
    for st in stations:
        model = st.model(error_model)
        readings = model.read(st.points, model.bias(st.points), model.noise(st.points, rng, trials))
        sensor[:, st.rows] = readings.sensor
        robot[:, st.rows] = readings.robot
        chk = roles[st.rows] == "check"
        robot[:, st.rows[chk]] = readings.truth[chk]
    robot[:, roles == "target"] = np.nan
    return figures(mset, stations, sensor, robot)
