"""The measurement model: how a physical point is read by the sensor and by the robot, and what its truth is.

One model for the whole library: the Monte Carlo (`montecarlo.measure`), the app's session (each point measured
where it is dragged) and the planner's prediction (`analysis.planning`) all read points through it.

For a physical point p (robot base frame, mm) reached with tool orientation R_p at time τ, with T the true
sensor→robot transform (robot = R @ sensor + t):

    sensor reading   s = T⁻¹(p) + b·β_s(p) + n·ε       sensor frame
    robot reading    r = p + b·β_r(p) + n·η            robot frame
    truth            c = p + b·β_r(p)                  robot frame: the command that really reaches p

β_s, β_r are the error model's deterministic terms (bias: kinematic error, scale, smooth fields, drift; the same
in every trial), ε, η its random terms (noise, outliers; drawn from a seeded generator, sensor side first, then
robot side), and b, n the bias and noise sizes (1: the model as given; the app's sliders). The robot carries its
bias to the target, so the truth includes β_r; its noise is not part of the truth. See docs/method.md.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rrbc_core.geometry.transforms import RigidTransform
from rrbc_core.models.errormodels import ErrorModel, PointSet


def point_seed(seed: int, pid: str) -> list[int]:
    """The seed of one point's noise draw: (the data set's seed, CRC32 of the point's id). A point keeps its draw
    wherever it is moved, a new seed redraws every point, and the app and `rrbc simulate --out` draw the same noise
    for the same point."""
    return [int(seed) & 0x7FFFFFFF, zlib.crc32(str(pid).encode("utf-8"))]


@dataclass(frozen=True, eq=False)
class Readings:
    """Readings of P points over T trials: sensor (T, P, 3) sensor frame, robot (T, P, 3) robot frame, and the
    truth (P, 3) robot frame, mm."""

    sensor: np.ndarray
    robot: np.ndarray
    truth: np.ndarray


@dataclass(frozen=True, eq=False)
class MeasurementModel:
    """A cell's sensor pose and error model, with the sizes of its bias and noise (module docstring).

    Parameters
    ----------
    sensor_to_robot : RigidTransform
        The true registration T (robot = R @ sensor + t).
    error_model : ErrorModel
        The robot- and sensor-side error terms.
    joint_seed : (6,) array or None
        The inverse-kinematics seed (rad) that picks the arm's configuration branch (kinematic terms).
    bias_scale, noise_scale : float
        b and n of the module docstring.
    """

    sensor_to_robot: RigidTransform
    error_model: ErrorModel
    joint_seed: np.ndarray | None = None
    bias_scale: float = 1.0
    noise_scale: float = 1.0

    def points(self, robot, tool_rotation, time=None) -> PointSet:
        """The physical points robot (P, 3) mm, reached with tool_rotation (P, 3, 3) or (3, 3), at time (P,) s
        (default 0), as the error terms see them."""
        robot = np.asarray(robot, float).reshape(-1, 3)
        time = np.zeros(len(robot)) if time is None else time
        return PointSet(
            robot=robot,
            sensor=self.sensor_to_robot.apply_inverse(robot),
            time=time,
            tool_rotation=tool_rotation,
            joint_seed=self.joint_seed,
        )

    def reachable(self, pts: PointSet) -> np.ndarray:
        """(P,) bool: the points every kinematic term of the error model can reach (all True without one). Points
        outside are refused by `bias` and `read` (InputError); mask them out first when sampling a volume."""
        from rrbc_core.models.kinematics import UR5_TOOL_DOWN_SEED, reachable

        ok = np.ones(len(pts), bool)
        for side in ("robot", "sensor"):
            for term in self.error_model.terms(side):
                if hasattr(term, "true_robot") and len(pts):
                    seed = UR5_TOOL_DOWN_SEED if pts.joint_seed is None else pts.joint_seed
                    rot = pts.tool_rotation if pts.tool_rotation is not None else np.eye(3)
                    ok &= reachable(term.true_robot(), pts.robot, rot, seed)
        return ok

    def bias(self, pts: PointSet) -> tuple[np.ndarray, np.ndarray]:
        """(β_s (P, 3) sensor frame, β_r (P, 3) robot frame), mm, unscaled. Draws nothing."""
        det = self.error_model.deterministic()
        n = len(pts)
        unused = np.random.default_rng(0)  # deterministic terms draw nothing
        sensor = det.sample(pts, "sensor", unused, 1)[0] if det.sensor else np.zeros((n, 3))
        robot = det.sample(pts, "robot", unused, 1)[0] if det.robot else np.zeros((n, 3))
        return sensor, robot

    def noise(self, pts: PointSet, rng: np.random.Generator, trials: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """(ε (T, P, 3) sensor frame, η (T, P, 3) robot frame), mm, unscaled: the random terms drawn from `rng`,
        the sensor side first."""
        rnd = self.error_model.random_terms()
        return rnd.sample(pts, "sensor", rng, trials), rnd.sample(pts, "robot", rng, trials)

    def noise_covariance(self, pts: PointSet) -> tuple[np.ndarray, np.ndarray]:
        """Covariances (P, 3, 3) mm² of ε (sensor frame) and η (robot frame), scaled by n²."""
        rnd = self.error_model.random_terms()
        f = self.noise_scale**2
        return f * rnd.covariance(pts, "sensor"), f * rnd.covariance(pts, "robot")

    def read(self, pts: PointSet, bias=None, noise=None) -> Readings:
        """The readings of the points from their bias (`bias(pts)` unless given) and noise (ε, η as from
        `noise`, (T, P, 3) each; None: noise-free, T = 1), scaled by b and n."""
        bias_s, bias_r = self.bias(pts) if bias is None else bias
        b, n = self.bias_scale, self.noise_scale
        truth = pts.robot + b * bias_r
        sensor = pts.sensor + b * bias_s
        if noise is None:
            return Readings(sensor[None], truth[None], truth)
        noise_s, noise_r = noise
        return Readings(sensor[None] + n * noise_s, truth[None] + n * noise_r, truth)

    def read_each(self, pts: PointSet, ids: Sequence[str], seed: int, bias=None) -> Readings:
        """One reading of each point (T = 1), its noise drawn from its own generator seeded by `point_seed(seed,
        id)` (sensor side first, then robot side): the readings of a measured data set, the same for a point
        whatever else is in the set (`rrbc simulate --out`, the app's session and its download).

        Parameters
        ----------
        pts : PointSet
            P physical points (robot frame, mm) with their tool orientations and times.
        ids : sequence of str
            (P,) the points' ids.
        seed : int
            The data set's seed.
        bias : tuple of ndarray, optional
            (β_s, β_r) as `bias(pts)` returns them, when already known (the explorer keeps them across seeds).

        Returns
        -------
        Readings
            sensor (1, P, 3) sensor frame, robot (1, P, 3) robot frame, truth (P, 3) robot frame, mm.
        """
        n = len(pts)
        if len(ids) != n:
            raise ValueError(f"read_each: {len(ids)} ids for {n} points")
        noise_s, noise_r = np.zeros((1, n, 3)), np.zeros((1, n, 3))
        rnd = self.error_model.random_terms()
        if rnd.robot or rnd.sensor:
            for i, pid in enumerate(ids):
                rng = np.random.default_rng(point_seed(seed, pid))
                e_s, e_r = self.noise(pts.subset(i), rng, 1)
                noise_s[0, i], noise_r[0, i] = e_s[0, 0], e_r[0, 0]
        return self.read(pts, bias=bias, noise=(noise_s, noise_r))
