"""Composable, switchable, seeded error terms for simulating robot and sensor measurements (docs/theory.md §5).

A `PointSet` holds P physical points: their true positions in the robot base frame and in the sensor frame (mm),
measurement times (s) and, for the robot, the tool orientation and IK seed used to reach them. An error term
returns displacements (trials, P, 3) in mm that are *added to a reading*, in the frame of the side it acts on:

* side "robot":  robot frame, added to what the robot reports;
* side "sensor": sensor frame, added to what the sensor reports (the sensor sits at the origin of its frame and
  looks along its +z; the viewing direction of a point is the unit vector from the origin to it).

Random terms (`random = True`: noise, outliers) are redrawn from the given generator in every trial.
Deterministic terms (`random = False`: scale, affine, smooth field, kinematic, drift, warm-up) are the same in every
trial and return shape (1, P, 3), which broadcasts. An `ErrorModel` is two tuples of terms, one per side; it
sums them, switches them on and off by `kind`, and round-trips through a TOML-like table
(`error_model_from_dict` / `error_model_to_dict`).

No term keeps state: the same inputs and generator state give the same output.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

from rrbc_core.errors import InputError

SIDES = ("robot", "sensor")


# --- parameter validation (shared by direct construction and by error_model_from_dict) ----------------------
VALUE_LIMIT = 1e9  # an error term's parameters are at most this in size (1e300 overflowed into numpy warnings)


def _number(
    name: str, value, *, minimum: float | None = None, positive: bool = False, unit: str = "", limit: float = 0.0
) -> float:
    """A finite number within `limit` (default `VALUE_LIMIT`) in size."""
    limit = limit or VALUE_LIMIT
    unit_txt = f" ({unit})" if unit else ""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{name} must be a number{unit_txt}, got {value!r}")
    v = float(value)
    if not np.isfinite(v):
        raise InputError(f"{name} must be finite, got {value!r}")
    if abs(v) > limit:
        raise InputError(f"{name} must be at most {limit:g} in size{unit_txt}, got {value!r}")
    if positive and v <= 0:
        raise InputError(f"{name} must be > 0{unit_txt}, got {value!r}")
    if minimum is not None and v < minimum:
        raise InputError(f"{name} must be >= {minimum:g}{unit_txt}, got {value!r}")
    return v


def _integer(name: str, value, *, minimum: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InputError(f"{name} must be an integer, got {value!r}")
    if value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _vector(name: str, value, n: int, *, minimum: float | None = None, unit: str = "") -> tuple[float, ...]:
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__") or len(value) != n:
        raise InputError(f"{name} must be a list of {n} numbers{f' ({unit})' if unit else ''}, got {value!r}")
    return tuple(_number(f"{name}[{i}]", v, minimum=minimum, unit=unit) for i, v in enumerate(value))


def _matrix3(name: str, value) -> tuple[tuple[float, ...], ...]:
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__") or len(value) != 3:
        raise InputError(f"{name} must be a 3x3 matrix (3 rows of 3 numbers), got {value!r}")
    return tuple(_vector(f"{name}[{i}]", row, 3) for i, row in enumerate(value))


def _set(obj, name: str, value) -> None:
    object.__setattr__(obj, name, value)


def _check_side(side) -> str:
    if side not in SIDES:
        raise InputError(f"side must be 'robot' or 'sensor', got {side!r}")
    return side


def _check_trials(trials) -> int:
    return _integer("trials", trials, minimum=1)


# --- the points --------------------------------------------------------------------------------------------
def _points_array(name: str, value, shape: tuple) -> np.ndarray:
    a = np.array(value, dtype=float)
    if a.shape != shape:
        raise InputError(f"PointSet.{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"PointSet.{name} must be finite")
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class PointSet:
    """P physical points and how they are measured.

    robot: (P, 3) true positions, robot base frame, mm. sensor: (P, 3) the same points in the sensor frame, mm
    (sensor at the origin of its frame, viewing along +z). time: (P,) measurement times, s.
    tool_rotation: (P, 3, 3) (or one (3, 3) for all) tool orientation the robot uses at each point, robot
    frame; needed by the kinematic term. joint_seed: (6,) rad, IK seed that picks the configuration branch.
    joints: (P, I) the arm's joint values a file recorded at each point (the chain's inputs, rad or mm), or None:
    the `arm_errors` term then solves them.
    """

    robot: np.ndarray
    sensor: np.ndarray
    time: np.ndarray
    tool_rotation: np.ndarray | None = None
    joint_seed: np.ndarray | None = None
    joints: np.ndarray | None = None

    def __post_init__(self):
        r = np.asarray(self.robot, dtype=float)
        if r.ndim != 2 or r.shape[1] != 3:
            raise InputError(f"PointSet.robot must be a (P, 3) array in mm, got shape {r.shape}")
        p = len(r)
        _set(self, "robot", _points_array("robot", r, (p, 3)))
        _set(self, "sensor", _points_array("sensor", self.sensor, (p, 3)))
        _set(self, "time", _points_array("time", self.time, (p,)))
        if self.tool_rotation is not None:
            rot = np.asarray(self.tool_rotation, dtype=float)
            if rot.shape == (3, 3):
                rot = np.broadcast_to(rot, (p, 3, 3))
            _set(self, "tool_rotation", _points_array("tool_rotation", rot, (p, 3, 3)))
        if self.joint_seed is not None:
            _set(self, "joint_seed", _points_array("joint_seed", self.joint_seed, (6,)))
        if self.joints is not None:
            q = np.asarray(self.joints, dtype=float)
            _set(self, "joints", _points_array("joints", q, (p, q.shape[-1] if q.ndim == 2 else -1)))

    def __len__(self) -> int:
        return len(self.robot)

    def frame(self, side: str) -> np.ndarray:
        """The points (P, 3) mm in the frame of `side` ("robot" or "sensor")."""
        return self.robot if _check_side(side) == "robot" else self.sensor

    def subset(self, i: int) -> PointSet:
        """The one point `i` as a PointSet of length 1."""
        return self.take(np.arange(i, i + 1))

    def take(self, idx) -> PointSet:
        """The points `idx` (an index array) as a PointSet, in that order."""
        rot = None if self.tool_rotation is None else self.tool_rotation[idx]
        q = None if self.joints is None else self.joints[idx]
        return PointSet(self.robot[idx], self.sensor[idx], self.time[idx], rot, self.joint_seed, q)


# --- the protocol ------------------------------------------------------------------------------------------
@runtime_checkable
class ErrorTerm(Protocol):
    """One error source. `sample` returns displacements (trials, P, 3) mm (deterministic terms may return
    (1, P, 3)) in the frame of `side`, to be added to that side's reading."""

    kind: ClassVar[str]
    random: ClassVar[bool]

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray: ...


#: kind string -> term class (the `type` names of `errorterms.error_model_from_dict`): every `_Term` subclass with
#: a `kind` registers itself here when it is defined (the terms live in `errorterms`).
TERM_TYPES: dict[str, type[_Term]] = {}


class _Term:
    """Shared behaviour: which sides a term may act on; a subclass with a `kind` is registered in TERM_TYPES."""

    kind: ClassVar[str]
    random: ClassVar[bool]
    sides: ClassVar[tuple[str, ...]] = SIDES

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "kind" in cls.__dict__:
            TERM_TYPES[cls.kind] = cls

    def _side(self, side) -> str:
        _check_side(side)
        if side not in self.sides:
            raise InputError(f"{self.kind} is a {self.sides[0]}-side term; it cannot act on the {side} side")
        return side


def _check_kinds(kinds) -> tuple[str, ...]:
    for k in kinds:
        if k not in TERM_TYPES:
            raise InputError(f"unknown error term kind {k!r}; valid kinds: {', '.join(TERM_TYPES)}")
    return tuple(kinds)


# --- the model ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ErrorModel:
    """Error terms acting on the robot's readings (robot frame) and on the sensor's readings (sensor frame)."""

    robot: tuple[ErrorTerm, ...] = ()
    sensor: tuple[ErrorTerm, ...] = ()

    def __post_init__(self):
        for side in SIDES:
            terms = getattr(self, side)
            if isinstance(terms, (str, bytes)) or not hasattr(terms, "__iter__"):
                raise InputError(f"ErrorModel.{side} must be a sequence of error terms, got {terms!r}")
            terms = tuple(terms)
            for i, t in enumerate(terms):
                if not isinstance(t, ErrorTerm):
                    raise InputError(f"ErrorModel.{side}[{i}] is not an error term (needs kind, random, sample): {t!r}")
                allowed = getattr(t, "sides", SIDES)
                if side not in allowed:
                    raise InputError(
                        f"ErrorModel.{side}[{i}] ({t.kind}) is a {allowed[0]}-side term; "
                        f"move it to the {allowed[0]} side"
                    )
            _set(self, side, terms)

    def terms(self, side: str) -> tuple[ErrorTerm, ...]:
        return getattr(self, _check_side(side))

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        """Sum of `side`'s terms: displacements (trials, P, 3) mm in that side's frame. Terms draw from `rng` in
        order; deterministic terms draw nothing."""
        terms = self.terms(side)
        if any(t.random for t in terms) and not isinstance(rng, np.random.Generator):
            raise InputError(
                f"sampling random error terms needs a seeded numpy Generator (np.random.default_rng(seed)), got {rng!r}"
            )
        out = np.zeros((_check_trials(trials), len(points), 3))
        for t in terms:
            out += t.sample(points, side, rng, trials)
        return out

    def covariance(self, points: PointSet, side: str) -> np.ndarray:
        """Summed covariance (P, 3, 3) mm² of `side`'s random terms (all of which expose `covariance`), in that
        side's frame: the noise the registration sees. Deterministic terms contribute nothing."""
        x = points.frame(side)
        cov = np.zeros((len(points), 3, 3))
        for t in self.terms(side):
            if t.random:
                if not hasattr(t, "covariance"):
                    raise InputError(f"the random error term {t.kind!r} has no covariance method")
                cov += t.covariance(x)
        return cov

    def deterministic(self) -> ErrorModel:
        """Only the random=False terms: the bias the robot/sensor carries (the same in every trial)."""
        return ErrorModel(tuple(t for t in self.robot if not t.random), tuple(t for t in self.sensor if not t.random))

    def random_terms(self) -> ErrorModel:
        """Only the random=True terms: noise and outliers (redrawn every trial)."""
        return ErrorModel(tuple(t for t in self.robot if t.random), tuple(t for t in self.sensor if t.random))

    def without(self, *kinds: str) -> ErrorModel:
        """The model with every term of the given kinds switched off."""
        ks = _check_kinds(kinds)
        return ErrorModel(
            tuple(t for t in self.robot if t.kind not in ks), tuple(t for t in self.sensor if t.kind not in ks)
        )

    def only(self, *kinds: str) -> ErrorModel:
        """The model with only the terms of the given kinds."""
        ks = _check_kinds(kinds)
        return ErrorModel(tuple(t for t in self.robot if t.kind in ks), tuple(t for t in self.sensor if t.kind in ks))

    def extended(self, robot=(), sensor=()) -> ErrorModel:
        """The model with more terms after its own on each side."""
        return ErrorModel(self.robot + tuple(robot), self.sensor + tuple(sensor))

    @property
    def kinds(self) -> tuple[str, ...]:
        return tuple(t.kind for t in self.robot + self.sensor)
