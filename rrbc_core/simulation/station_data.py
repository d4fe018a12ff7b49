"""Real-like measurement files with several stationings (a `group` column): what a long-chain robot measured by an
external instrument gives (issue 28), seeded, for tests, benchmarks and examples.

Physics. The instrument (the sensor) stays put; its frame is the world frame. The robot's coordinates are its base
frame's (a lift column is part of its chain), but every station is another stationing: the arm at another height and
configuration, re-registered — so each station has its own sensor-to-robot transform, the common one moved by
`shift_mm` (per axis, sd) and turned by `yaw_deg` (sd). The robot's position error is a smooth field of position in
its frame, different at every station (`models.errorterms.SmoothField` seeded per station, `bias_mm` RMS, plus a
station-wide offset of 0.3 × `bias_mm` per axis), so one registration over all stations fits worse than one per
station, and the same place reached at two stations carries two different corrections. At each station, `n_reg` stationing points
lie on a board (a plane in the world, the same places at every station), and `n_eval` evaluation points lie in a box
`above_mm` over the board. Readings: sensor = world position + `sensor_noise_mm`; robot = the point in the station's
robot frame + the robot's error there + `robot_noise_mm`.

Roles: the stationing points are `both` (registration and fiducial); the evaluation points are `check`, or, with
`eval_fiducials` = f, a fraction f of each station's evaluation points are `fiducial` (spread over the box: every
other point) and the rest `check`.
"""

from __future__ import annotations

import numpy as np

from rrbc_core.io.measurements import MeasurementSet


def _rot_z(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


def station_measurements(
    seed: int,
    *,
    stations: int = 5,
    n_reg: int = 8,
    n_eval: int = 30,
    bias_mm: float = 5.0,
    length_mm: float = 350.0,
    sensor_noise_mm: float = 0.02,
    robot_noise_mm: float = 0.05,
    above_mm: tuple[float, float] = (160.0, 420.0),
    yaw_deg: float = 0.15,
    shift_mm: float = 2.0,
    eval_fiducials: float = 0.0,
    group_column: bool = True,
    source: str = "<stations>",
) -> MeasurementSet:
    """A multi-station measurement set (module docstring). `group_column` False writes the same rows without the
    `group` column (a pooled file, as a user who does not split stations would have it)."""
    from rrbc_core.models.errormodels import PointSet
    from rrbc_core.models.errorterms import SmoothField

    rng = np.random.default_rng(seed)
    # the board: n_reg points on a 700 x 500 mm plate in the world's z = 0 plane, the same at every station
    board = np.column_stack([rng.uniform(-350, 350, n_reg), rng.uniform(-250, 250, n_reg), np.zeros(n_reg)])
    ids, roles, groups, sensor, robot = [], [], [], [], []
    for g in range(stations):
        rot = _rot_z(30.0 + rng.normal(0, yaw_deg))  # robot frame -> world
        base = np.array([0.0, 600.0, -300.0]) + rng.normal(0, shift_mm, 3)
        world_eval = np.column_stack(
            [
                rng.uniform(-300, 300, n_eval),
                rng.uniform(-200, 200, n_eval),
                rng.uniform(above_mm[0], above_mm[1], n_eval),
            ]
        )
        world = np.vstack([board, world_eval])
        p_robot = (world - base) @ rot  # robot = Rᵀ (world − base)
        field = SmoothField(rms_mm=bias_mm, length_mm=length_mm, seed=seed * 1000 + g)
        pts = PointSet(robot=p_robot, sensor=world, time=np.zeros(len(world)), tool_rotation=None, joint_seed=None)
        bias = field.sample(pts, "robot", rng, 1)[0] + rng.normal(0, 0.3 * bias_mm, 3)
        s = world + rng.normal(0, sensor_noise_mm, world.shape)
        b = p_robot + bias + rng.normal(0, robot_noise_mm, world.shape)
        n_fid = int(round(eval_fiducials * n_eval))
        fid_rows = set(np.linspace(0, n_eval - 1, n_fid).round().astype(int).tolist()) if n_fid else set()
        for i in range(len(world)):
            if i < n_reg:
                ids.append(f"S{g + 1}.{i + 1}")
                roles.append("both")
            else:
                k = i - n_reg
                ids.append(f"E{g + 1}.{k + 1}")
                roles.append("fiducial" if k in fid_rows else "check")
            groups.append(f"station{g + 1}")
        sensor.append(s)
        robot.append(b)
    n = len(ids)
    return MeasurementSet(
        ids=tuple(ids),
        roles=tuple(roles),
        sensor=np.vstack(sensor),
        robot=np.vstack(robot),
        time=np.full(n, np.nan),
        lines=tuple(0 for _ in ids),
        source=source,
        extra={"group": tuple(groups)} if group_column else {},
    )


def drawn_stations(seed: int, sizes_seed: int | None = None) -> MeasurementSet:
    """Two stations with half of each station's evaluation points as fiducials around the others, their sizes drawn
    as real cells have them (30-80 evaluation points, bias 0.5, 2 or 5 mm, correlation length 150-600 mm, robot
    noise 0.02, 0.1 or 0.3 mm) from `sizes_seed` (default `seed`): the bounds' coverage files
    (`studies.bounds_study`, tests/correction/test_bounds.py)."""
    rng = np.random.default_rng(seed if sizes_seed is None else sizes_seed)
    return station_measurements(
        seed,
        stations=2,
        n_eval=int(rng.integers(30, 80)),
        bias_mm=float(rng.choice([0.5, 2.0, 5.0])),
        length_mm=float(rng.uniform(150, 600)),
        robot_noise_mm=float(rng.choice([0.02, 0.1, 0.3])),
        eval_fiducials=0.5,
    )
