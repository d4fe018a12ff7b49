"""The session's data as a measurement file holds it: what the Diagnose tab diagnoses and the CSV download writes.

One data set, so that `rrbc diagnose` and `rrbc correct` on the app's download give what the app shows:

- **Measured data, as opened**: the file itself, every row kept (repeated readings, times, check rows, joint and
  other columns).
- **Measured data, edited** (a fiducial excluded, a target or check point moved): the file's rows with the edits
  applied — an excluded fiducial's `fiducial` rows dropped and its `both` rows kept as `registration`; a moved target
  or check point becomes one `target` row with its new sensor position (a moved check point has no truth there).
- **A scene**: the simulated data set as `rrbc simulate --out` writes it (`simulation.datasets.measured_data`):
  registration points, the included fiducials (a fiducial at a registration point's id and place is one `both`
  row), the targets (sensor readings only) and `check_points_per_target` check points sampled in each target's
  region (seeded by the session's seed, as `work_cell_from_scene` samples them) with their truth; each row's time;
  the joint columns with a kinematic arm. The points are where the session has them, with its tool orientations and
  noise and bias sizes; each point's noise comes from its own seeded generator, so the registration points,
  fiducials and targets carry exactly the readings the app evaluates. For the scene as loaded (seed, sizes 1) the
  rows are those of `rrbc simulate SCENE --seed SEED --out`, except where the scene gives points their own tool yaw
  or the sensor cannot see a point (the simulation drops it; the app measures every point).

Positions: robot frame, mm; sensor readings sensor frame, mm; times s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.session import planning_view

if TYPE_CHECKING:
    from rrbc_core.session.explorer import ExplorerSession

__all__ = ["SessionData", "check_statistics", "data_key", "session_data"]


@dataclass(frozen=True, eq=False)
class SessionData:
    """The session's data set (module docstring).

    Attributes
    ----------
    measurements : MeasurementSet
        The rows.
    edited : bool
        Measured data changed in the app (excluded fiducials, moved points); False for a file as opened and for
        scenes (whose data are always simulated for the layout as it is).
    what : str
        One sentence saying which data these are.
    robot, tool_mm : str or None, float
        The arm's model and tool length (mm) that read the joint columns (a scene's kinematic arm); None and 0
        otherwise (`rrbc diagnose`'s defaults: q1..q6 columns are tried as a UR5 and left untested if it does not
        describe them).
    """

    measurements: MeasurementSet
    edited: bool
    what: str
    robot: str | None = None
    tool_mm: float = 0.0

    def diagnose_command(self, path: str) -> str:
        """The command line that diagnoses these data, written to `path`, as the app does."""
        opts = ""
        if self.robot not in (None, "ur5"):
            opts += f" --robot {self.robot}"
        if self.tool_mm:
            opts += f" --tool {self.tool_mm:g}"
        return f"rrbc diagnose {path}{opts}"

    def diagnose(self, alpha: float = 0.01, seed: int = 0):
        """`analysis.diagnosis.diagnose` of these data with the arm's model: what `diagnose_command` prints."""
        from rrbc_core.analysis.diagnosis import diagnose
        from rrbc_core.io.joints import file_tool

        robot = None if self.robot == "ur5" else self.robot  # as the printed command says it (ur5 is the default)
        tool = self.tool_mm if self.tool_mm else file_tool(self.measurements)  # as the command reads the file's
        return diagnose(self.measurements, alpha=alpha, seed=seed, robot=robot, tool_mm=tool)


def session_data(session: ExplorerSession) -> SessionData:
    """The session's data set (module docstring). Cached on `data_key`."""
    if session.kind == "scene":
        return _scene_data(session)
    return session.cached("data_set", data_key(session), lambda: _file_data(session))


def data_key(session: ExplorerSession) -> tuple:
    """What the data set depends on: equal keys, equal data (the Diagnose tab's verdict is current while the key
    is the one it was computed for)."""
    s = session.settings
    if session.kind != "scene":
        tg = session.layout["targets"]
        return ("file", id(session.mset), tuple(sorted(s.excluded)), tg.ids, tg.positions.tobytes())
    return (
        "scene",
        s.seed,
        s.noise_scale,
        s.bias_scale,
        tuple(sorted(s.excluded)),
        planning_view.planning_key(session),
        tuple(session.layout["fiducials"].ids),
        session.layout["fiducials"].positions.tobytes(),
        tuple(sorted(session.target_tools.items())),
        session.varied_registration,
    )


# ------------------------------------------------------------------------------------------------ measured data
def _file_data(session: ExplorerSession) -> SessionData:
    mset = session.mset
    excluded = set(session.settings.excluded)
    moved = _moved_points(session)
    if not excluded and not moved:
        return SessionData(mset, False, f"the file {mset.source} as opened ({len(mset)} rows)")
    keep, roles = [], []
    for i, (pid, role) in enumerate(zip(mset.ids, mset.roles)):
        if pid in excluded and role == "fiducial":
            continue
        if pid in moved and role in ("target", "check"):
            continue
        keep.append(i)
        roles.append("registration" if (pid in excluded and role == "both") else role)
    ids = [mset.ids[i] for i in keep]
    sensor = [mset.sensor[i] for i in keep]
    robot = [mset.robot[i] for i in keep]
    time = [mset.time[i] for i in keep]
    lines = [mset.lines[i] if i < len(mset.lines) else 0 for i in keep]
    extra = {k: [v[i] for i in keep] for k, v in mset.extra.items()}
    for pid, s in moved.items():
        ids.append(pid)
        roles.append("target")
        sensor.append(s)
        robot.append(np.full(3, np.nan))
        time.append(np.nan)
        lines.append(0)
        for v in extra.values():
            v.append("")
    n = len(ids)
    edits = []
    if excluded:
        edits.append(f"fiducial{'s' if len(excluded) > 1 else ''} {', '.join(sorted(excluded))} excluded")
    if moved:
        edits.append(f"{', '.join(moved)} moved (now target rows)")
    out = MeasurementSet(
        ids=tuple(ids),
        roles=tuple(roles),
        sensor=np.array(sensor, float).reshape(n, 3),
        robot=np.array(robot, float).reshape(n, 3),
        time=np.array(time, float).reshape(n),
        lines=tuple(lines),
        source=mset.source,
        extra={k: tuple(v) for k, v in extra.items()},
    )
    return SessionData(out, True, f"the file {mset.source} as edited here: {'; '.join(edits)} ({n} rows)")


def _moved_points(session: ExplorerSession) -> dict:
    """{id: new sensor reading (3,)} of the file's target and check points the user moved."""
    original: dict[str, np.ndarray] = {}
    for role in ("target", "check"):
        g = session.mset.points(role)
        for pid, s in zip(g.ids, g.sensor):
            original.setdefault(pid, s)
    moved = {}
    for pid in session.layout["targets"].ids:
        s = session.readings_of("targets", pid).sensor
        if pid in original and not np.array_equal(s, original[pid]):
            moved[pid] = np.asarray(s, float)
    return moved


# ------------------------------------------------------------------------------------------------------- scenes
def _scene_data(session: ExplorerSession) -> SessionData:
    from rrbc_core.simulation.datasets import measured_data
    from rrbc_core.simulation.montecarlo import WorkCell

    s = session.settings
    sc = session.scene
    key = data_key(session)

    def build() -> SessionData:
        ids, roles, pos, rot, time, owner = [], [], [], [], [], []
        order = session.row_order()
        dt = float(sc.measurement_interval_s)
        fid = session.layout["fiducials"]
        fid_at = dict(zip(fid.ids, fid.positions))
        reg = session.layout["registration"]

        def add(kind, pid, role, p, of=""):
            ids.append(pid)
            roles.append(role)
            pos.append(np.asarray(p, float))
            owner.append(of)
            rot.append(session.tool_rotations(kind, [pid])[0])
            time.append(session.row_times(kind, [pid])[0])

        for pid, p in zip(reg.ids, reg.positions):
            both = pid in fid_at and pid not in s.excluded and np.array_equal(fid_at[pid], p)
            add("registration", pid, "both" if both else "registration", p)
        reg_ids = set(reg.ids)
        for pid, p in zip(fid.ids, fid.positions):
            if pid in s.excluded or (pid in reg_ids and roles[reg.ids.index(pid)] == "both"):
                continue
            add("fiducials", pid, "fiducial", p)
        tg = session.layout["targets"]
        for pid, p in zip(tg.ids, tg.positions):
            add("targets", pid, "target", p)
        # check points in each target's region, sampled as work_cell_from_scene samples them for this seed
        rng = np.random.default_rng(s.seed)
        n_checks = int(sc.check_points_per_target)
        row = max(order.values(), default=-1) + 1
        t_ids, regions = planning_view.planning_regions(session)
        for pid, region in zip(t_ids, regions):
            tool = session.tool_rotations("targets", [pid])[0]
            for k, p in enumerate(region.sample(rng, n_checks)):
                ids.append(f"{pid}.c{k:02d}")
                roles.append("check")
                pos.append(p)
                owner.append(pid)
                rot.append(tool)
                time.append(row * dt)
                row += 1
        n = len(ids)
        cell = WorkCell(
            name=sc.name,
            sensor_to_robot=session.sensor_to_robot,
            ids=tuple(ids),
            roles=tuple(roles),
            robot=np.array(pos, float).reshape(n, 3),
            time=np.array(time, float).reshape(n),
            tool_rotation=np.array(rot, float).reshape(n, 3, 3),
            error_model=sc.error_model,
            joint_seed=sc.joint_seed,
            distance_origin=np.asarray(sc.distance_origin, float),
            check_target=tuple(owner),
        )
        mset = measured_data(cell, s.seed, s.bias_scale, s.noise_scale)
        mset = MeasurementSet(
            mset.ids, mset.roles, mset.sensor, mset.robot, mset.time, mset.lines, f"<{sc.name}>", mset.extra
        )
        sizes = f"noise x{s.noise_scale:g}, bias x{s.bias_scale:g}"
        what = (
            f"the simulated data set of {sc.name} as the app has it ({n} rows: {len(reg.ids)} registration points, "
            f"{sum(r in ('fiducial', 'both') for r in roles)} fiducials, {len(tg.ids)} targets, "
            f"{roles.count('check')} check points in their regions; seed {s.seed}, {sizes}), as `rrbc simulate "
            "--out` writes it"
        )
        arm = session.arm_term()
        if arm is None or sc.robot_model not in ("ur5", "ur10"):
            return SessionData(mset, False, what)
        return SessionData(mset, False, what, sc.robot_model, float(arm.dh.tool_mm))

    return session.cached("data_set", key, build)


def check_statistics(session: ExplorerSession):
    """Before/after statistics of the data set's check rows (`correction.check_statistics`) as `rrbc correct` with
    the session's method computes them on the CSV download; None without checks (or when correct refuses)."""
    from rrbc_core.correction.pipeline import correct_measurements
    from rrbc_core.errors import InputError

    method = session.settings.method

    def compute():
        data = session_data(session).measurements
        if "check" not in data.roles:
            return None
        try:
            return correct_measurements(data, method).statistics()
        except InputError:
            return None

    return session.cached("check_statistics", (data_key(session), method), compute)
