"""The arm's own errors as an error term a scene can hold (`arm_errors`, robot side; issue 36): the parameters of the
one robot model of calibration and diagnosis (`models.chain.Chain`: each joint's offset and its origin's position and
orientation errors, in `Chain.param_names`) and its load terms (`models.loads`: a joint's compliance under the
gravity torque, a column's bending), for the scene's arm: a URDF (`robot.urdf`, `robot.tip`: its link masses carry
the loads) or a DH arm (`robot.model` ur5/ur10; with their links' masses, `arm_masses`).

The true arm is the nominal chain with `parameters` and `loads`; the robot reports the nominal chain's forward
kinematics of the joints it reads. For a physical point p (robot frame, mm):

- with the joints the file recorded (`PointSet.joints`, the chain's inputs in rad or mm): displacement =
  FK_nominal(q) − FK_true(q): exactly what the arm reports less where it is;
- without them (a scene's own points): q solves FK_true(q) = p, by the nominal chain's position solver
  (`arm_description.reach`, the joints' limits kept) and two Gauss-Newton steps on the true chain; displacement =
  FK_nominal(q) − p. The joints found are the ones `rrbc simulate --out` writes (`joints`).

`rrbc check-model` writes this term from `rrbc calibrate`'s identification (`analysis.calibration.calibrate`) of what a
scene's model leaves unexplained; it can be written by hand (names as `rrbc calibrate --json` lists them).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.models.errormodels import PointSet, _check_trials, _Term, _vector

__all__ = ["ArmErrors", "arm_chain"]

GRAVITY = (0.0, 0.0, -9.80665)


def arm_chain(urdf: str = "", tip: str = "", robot: str = "", tool_mm=(0.0, 0.0, 0.0)):
    """The nominal chain of a URDF (a file, or a packaged/bundled name; `tip` the measured link) or a DH arm
    ("ur5", "ur10", with their links' masses), with the tool point (3,) mm in the tip link's frame."""
    from rrbc_core.models.arm_masses import dh_chain_with_masses
    from rrbc_core.models.kinematics import ROBOT_DH
    from rrbc_core.models.urdf import load_urdf

    tool = np.asarray(tool_mm, float).reshape(3)
    if urdf:
        return load_urdf(urdf, tip=tip or None, tool_mm=tool)
    if robot in ROBOT_DH:
        return dh_chain_with_masses(ROBOT_DH[robot]).with_tool(tool)
    raise InputError("an arm_errors term needs the scene's arm: robot.model ur5/ur10, or robot.urdf")


@dataclass(frozen=True)
class ArmErrors(_Term):
    """The arm's errors (module docstring). `parameters` {name: value} in rad or mm, `loads` {term name: coefficient}
    (rad/Nm, or rad per N m for bending), `gravity` (3,) m/s² in the base frame; `urdf`, `tip`, `robot`, `tool_mm`:
    the arm, filled in from the scene's robot when not given. Robot side only."""

    parameters: dict = field(default_factory=dict)
    loads: dict = field(default_factory=dict)
    urdf: str = ""
    tip: str = ""
    robot: str = ""
    tool_mm: tuple = (0.0, 0.0, 0.0)
    gravity: tuple = GRAVITY
    kind: ClassVar[str] = "arm_errors"
    random: ClassVar[bool] = False
    sides: ClassVar[tuple[str, ...]] = ("robot",)
    _model: tuple = field(init=False, repr=False, compare=False, default=())
    _solved: dict = field(init=False, repr=False, compare=False, default_factory=dict)  # points -> joints (few)

    def __post_init__(self):
        for name in ("parameters", "loads"):
            v = getattr(self, name)
            if not isinstance(v, dict) or not all(isinstance(k, str) for k in v):
                raise InputError(f"{name} must be a table of name = number")
            vals = {}
            for k, x in v.items():
                if isinstance(x, bool) or not isinstance(x, (int, float)) or not np.isfinite(x) or abs(x) > 1e6:
                    raise InputError(f"{name}.{k} must be a finite number, got {x!r}")
                vals[k] = float(x)
            object.__setattr__(self, name, vals)
        for name in ("urdf", "tip", "robot"):
            if not isinstance(getattr(self, name), str):
                raise InputError(f"{name} must be a string, got {getattr(self, name)!r}")
        object.__setattr__(self, "tool_mm", _vector("tool_mm", self.tool_mm, 3, unit="mm"))
        object.__setattr__(self, "gravity", _vector("gravity", self.gravity, 3, unit="m/s²"))
        if self.urdf or self.robot:
            object.__setattr__(self, "_model", self._build())

    def _build(self) -> tuple:
        from rrbc_core.models.loads import named_terms

        chain = arm_chain(self.urdf, self.tip, self.robot, self.tool_mm)
        names = chain.param_names
        unknown = sorted(set(self.parameters) - set(names))
        if unknown:
            raise InputError(
                f"parameters: {', '.join(unknown[:5])} not a parameter of {chain.name} (it has {', '.join(names[:6])}, …)"
            )
        delta = np.array([self.parameters.get(n, 0.0) for n in names])
        terms = named_terms(chain, list(self.loads)) if self.loads else ()
        return chain, delta, terms, np.array(list(self.loads.values()), float)

    @property
    def chain(self):
        """The nominal chain (`models.chain.Chain`) the term is on."""
        if not self._model:
            raise InputError("the arm_errors term has no arm: give the scene a robot (robot.model or robot.urdf)")
        return self._model[0]

    def on_arm(self, urdf: str = "", tip: str = "", robot: str = "", tool_mm=(0.0, 0.0, 0.0)) -> ArmErrors:
        """The term on the scene's arm when it names none itself."""
        import dataclasses

        if self.urdf or self.robot:
            return self
        return dataclasses.replace(
            self, urdf=str(urdf or ""), tip=str(tip or ""), robot=str(robot or ""), tool_mm=tuple(tool_mm)
        )

    def _true(self, q: np.ndarray, jacobians: bool = False):
        from rrbc_core.models.loads import deflections, gravity_loads

        chain, delta, terms, coef = self._model
        dv = drot = None
        if len(terms):
            dv, drot = deflections(chain, terms, coef, gravity_loads(chain, q, np.asarray(self.gravity)))
        return chain.kinematics(q, delta, jacobians=jacobians, dv=dv, drot=drot)

    def joints(self, points: PointSet) -> np.ndarray:
        """The joints (P, I) the arm reads at the physical points (module docstring)."""
        if not self._model:
            raise InputError("the arm_errors term has no arm: give the scene a robot (robot.model or robot.urdf)")
        if points.joints is not None:
            return np.asarray(points.joints, float)
        key = np.asarray(points.robot, float).tobytes()
        if key in self._solved:
            return self._solved[key]
        from rrbc_core.models.arm_description import ArmDescription, _limits, reach

        chain = self._model[0]
        desc = ArmDescription(Path(chain.source or "arm"), chain, np.eye(3), np.zeros(3))
        q = np.empty((len(points), len(chain.inputs)))
        seed = None
        for i, p in enumerate(points.robot):
            q[i] = seed = reach(desc, p, seed)
        for _ in range(2):  # onto the true arm: FK_true(q) = p
            p_true, _, jac = self._true(q, jacobians=True)
            assert jac is not None
            r = points.robot - p_true
            q = np.clip(q + np.einsum("nij,nj->ni", np.linalg.pinv(jac), r), *_limits(chain))
        q.setflags(write=False)
        if len(self._solved) >= 8:  # a few point sets (a scene's, a drag's) are asked for again and again
            self._solved.pop(next(iter(self._solved)))
        self._solved[key] = q
        return q

    def displacement(self, points: PointSet) -> np.ndarray:
        """Reported minus physical position (P, 3) mm, robot frame."""
        q = self.joints(points)
        chain = self._model[0]
        reported = chain.forward(q)
        if points.joints is not None:
            return reported - self._true(q)[0]
        return reported - points.robot

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        self._side(side)
        _check_trials(trials)
        return self.displacement(points)[None]
