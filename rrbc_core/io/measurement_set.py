"""A measurement file's rows in memory (`MeasurementSet`) and one role's points per distinct id (`PointGroup`).

The readers and the validator are `io.measurements`'s; the format is docs/formats/measurement-file.md. Units mm
and s; sensor_* values in the sensor frame, robot_* in the robot frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.io.measurement_format import FIDUCIAL_ROLES, REGISTRATION_ROLES, ROLES
from rrbc_core.io.measurement_messages import error as _error


@dataclass(frozen=True, eq=False)
class PointGroup:
    """Points of one role aggregated per distinct id, in order of first appearance (units mm).

    `sensor` (K, 3) sensor frame and `robot` (K, 3) robot frame are the means of the id's rows (`robot` is NaN for
    targets); `count` is the number of rows averaged and `first_line` the line of the id's first row.
    """

    ids: tuple[str, ...]
    sensor: np.ndarray
    robot: np.ndarray
    count: np.ndarray
    first_line: tuple[int, ...]

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True, eq=False)
class MeasurementSet:
    """Rows of a measurement file, in file order. Units mm and s. Frames: sensor_* sensor frame, robot_* robot frame.

    Arrays are stored as read-only float copies. Robot values of `target` rows are ignored and stored as NaN.
    Construction does not validate; call `validate` (the readers and the writer do).
    """

    ids: tuple[str, ...]  # per row
    roles: tuple[str, ...]  # per row
    sensor: np.ndarray  # (R, 3)
    robot: np.ndarray  # (R, 3), NaN where the file has no robot values (targets)
    time: np.ndarray  # (R,), NaN where absent
    lines: tuple[int, ...]  # 1-based physical line of each row in the source file; 0 for rows built in memory
    source: str = "<memory>"  # file name used in messages
    extra: dict[str, tuple[str, ...]] = field(default_factory=dict)  # other columns kept verbatim, per row

    def __post_init__(self) -> None:
        src = str(self.source)
        set_ = lambda name, value: object.__setattr__(self, name, value)
        set_("source", src)
        set_("ids", tuple(self.ids))
        set_("roles", tuple(self.roles))
        set_("lines", tuple(map(int, self.lines)))
        set_("extra", {str(k): tuple(v) for k, v in dict(self.extra).items()})
        for name in ("sensor", "robot", "time"):
            try:
                arr = np.array(getattr(self, name), dtype=float)
            except (TypeError, ValueError) as exc:
                raise _error(src, None, None, f"{name} is not a numeric array ({exc})") from None
            set_(name, arr)
        robot = self.robot
        if robot.ndim == 2 and robot.shape[1:] == (3,) and len(robot) == len(self.roles):
            is_target = self._role_codes() == ROLES.index("target")
            if is_target.any():
                robot[is_target] = np.nan
        for name in ("sensor", "robot", "time"):
            getattr(self, name).flags.writeable = False

    def __len__(self) -> int:
        return len(self.ids)

    def _role_codes(self) -> np.ndarray:
        """(R,) each row's role as its index in `ROLES` (-1: not a role), computed once."""
        codes = self.__dict__.get("_codes")
        if codes is None:
            index = {r: k for k, r in enumerate(ROLES)}
            try:
                codes = np.fromiter(map(index.__getitem__, self.roles), dtype=int, count=len(self.roles))
            except (KeyError, TypeError):  # a set not yet validated: a row without a valid role is -1
                codes = np.fromiter((index.get(r, -1) for r in self.roles), dtype=int, count=len(self.roles))
            object.__setattr__(self, "_codes", codes)
        return codes

    def _known(self, role_codes: np.ndarray, ids_distinct: bool) -> None:
        """What a reader already computed about the rows: each row's role code (`_role_codes`) and whether no id is
        on two rows (`_ids_distinct`); a million-row file is not walked again for them."""
        object.__setattr__(self, "_codes", np.asarray(role_codes, dtype=int))
        object.__setattr__(self, "_distinct", bool(ids_distinct))

    def _ids_distinct(self) -> bool:
        """Whether no id is on two rows, computed once."""
        distinct = self.__dict__.get("_distinct")
        if distinct is None:
            distinct = len(set(self.ids)) == len(self.ids)
            object.__setattr__(self, "_distinct", distinct)
        return distinct

    def rows(self, role: str) -> np.ndarray:
        """Indices of the rows selected by `role` (registration: registration or both; fiducial: fiducial or both)."""
        wanted = [ROLES.index(r) for r in _selected_roles(role)]
        return np.flatnonzero(np.isin(self._role_codes(), wanted))

    def points(self, role: str) -> PointGroup:
        """Points of a role aggregated per distinct id, in order of first appearance; repeated rows are averaged.

        "registration" selects rows whose role is registration or both, "fiducial" rows whose role is fiducial or
        both; "both", "target" and "check" select their own rows.
        """
        rows = self.rows(role)
        at = rows.tolist()
        ids = tuple(self.ids) if len(at) == len(self.ids) else tuple(map(self.ids.__getitem__, at))
        if self._ids_distinct() or len(set(ids)) == len(ids):  # every id once (most files): no averaging to do
            n_lines = len(self.lines)
            if n_lines == len(self.ids):
                lines = tuple(self.lines) if len(at) == n_lines else tuple(map(self.lines.__getitem__, at))
            else:
                lines = tuple(self.lines[i] if i < n_lines else 0 for i in at)
            # + 0.0: the sum the averaging makes (a -0.0 reads back as 0.0 either way)
            return PointGroup(ids, self.sensor[rows] + 0.0, self.robot[rows] + 0.0, np.ones(len(ids), int), lines)
        index: dict[str, int] = {}
        point = np.fromiter((index.setdefault(self.ids[i], len(index)) for i in rows), dtype=int, count=len(rows))
        order = list(index)
        k = len(order)
        count = np.bincount(point, minlength=k).astype(int)
        sensor = np.zeros((k, 3))
        robot = np.zeros((k, 3))
        np.add.at(sensor, point, self.sensor[rows])
        np.add.at(robot, point, self.robot[rows])
        sensor /= count[:, None]  # every id has at least one row
        robot /= count[:, None]
        first = rows[np.unique(point, return_index=True)[1]]  # ids are numbered in order of first appearance
        n_lines = len(self.lines)
        first_line = [self.lines[i] if i < n_lines else 0 for i in first.tolist()]
        return PointGroup(tuple(order), sensor, robot, count, tuple(first_line))


def select_rows(mset: MeasurementSet, rows, source: str | None = None) -> MeasurementSet:
    """The rows `rows` (indices, in the order given) of a set as a set of their own; extra columns follow the rows;
    `source` names it in messages (default: the set's)."""
    rows = np.asarray(rows, dtype=int)
    take = lambda seq: tuple(seq[i] for i in rows.tolist())
    return MeasurementSet(
        ids=take(mset.ids),
        roles=take(mset.roles),
        sensor=mset.sensor[rows],
        robot=mset.robot[rows],
        time=mset.time[rows],
        lines=take(mset.lines) if len(mset.lines) == len(mset.ids) else tuple(0 for _ in rows),
        source=mset.source if source is None else source,
        extra={k: take(v) for k, v in mset.extra.items()},
    )


def _selected_roles(role: str) -> tuple[str, ...]:
    if role == "registration":
        return REGISTRATION_ROLES
    if role == "fiducial":
        return FIDUCIAL_ROLES
    if role in ROLES:
        return (role,)
    raise InputError(f"unknown role {role!r}; valid roles: {', '.join(ROLES)}")
