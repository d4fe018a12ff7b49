"""Model-based calibration (VEC) beside rigid and RRBC in the session (issue 15; docs/calibration.md).

Scene mode, a scene whose robot error model has a kinematic term: the arm reaches every point in a joint
configuration (the true arm's inverse kinematics at the point with its tool orientation). From the registration
points and the included fiducials — their readings and those configurations — `analysis.vec_compare.fit_methods`
identifies the arm's DH errors and the sensor-to-robot transform (what `rrbc calibrate` does), and each target gets
VEC's command: the joints that put the identified arm's tool on the target, sent through the nominal controller.

Tool orientation. Every point is reached with the tool pointing down (turned by the scene's tool yaw), unless a
target has been given a tilt: the tool axis leaned by `tilt_deg` from straight down towards the azimuth
`azimuth_deg` (degrees from the base x axis about z). An arm's kinematic error depends on the configuration, so a
target reached at another orientation has another error; RRBC corrects by position alone (its fiducials were
measured tool-down) and cannot follow, while VEC, knowing the arm, can.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from rrbc_core.errors import InputError
from rrbc_core.runtime.threads import thread_limited

TILT_MAX_DEG = 60.0
VARIED_TILT_DEG = 30.0


def tool_rotation(yaw_deg: float, tilt_deg: float = 0.0, azimuth_deg: float = 0.0) -> np.ndarray:
    """Tool rotation (3, 3), robot frame: tool-down turned by yaw (kinematics.tool_down), then its axis leaned by
    tilt_deg towards the azimuth azimuth_deg (degrees)."""
    from rrbc_core.models.kinematics import tool_down

    base = tool_down(yaw_deg)
    if tilt_deg == 0:
        return base
    a = np.radians(azimuth_deg)
    # about k = (sin a, −cos a, 0): the tool axis −z goes to (sin t cos a, sin t sin a, −cos t)
    axis = np.array([np.sin(a), -np.cos(a), 0.0])
    return Rotation.from_rotvec(axis * np.radians(tilt_deg)).as_matrix() @ base


@dataclass(frozen=True, eq=False)
class VecView:
    """VEC beside rigid and RRBC for the current layout: per target (M,) `robot_vec` (M, 3) the command, robot
    frame mm, `error_vec`, `error_rigid`, `error_rrbc` (M,) mm against the truth; `tools` (M, 2) tilt and azimuth
    (degrees); `rmst_mm` {rigid, rrbc, vec}; `rank` the number of arm/transform combinations identified; `poses`
    the number of poses used."""

    ids: tuple
    robot_vec: np.ndarray
    error_vec: np.ndarray
    error_rigid: np.ndarray
    error_rrbc: np.ndarray
    tools: np.ndarray
    rmst_mm: dict
    rank: int
    poses: int


class SessionVec:
    """Part of `ExplorerSession` (see there): the arm's joint configurations, target tool orientations, VEC."""

    def arm_term(self):
        """The scene's kinematic error term, or None (measured data; a scene without one)."""
        from rrbc_core.models.errorterms import Kinematic

        if self.kind != "scene":
            return None
        found = [t for t in self.scene.error_model.robot if isinstance(t, Kinematic)]
        return found[0] if found else None

    @property
    def has_arm(self) -> bool:
        return self.arm_term() is not None

    def tool_of(self, kind: str, pid: str) -> tuple[float, float]:
        """(tilt, azimuth) degrees of a point's tool; (0, 0): tool down. With `varied_registration` the i-th
        registration point is reached leaned `VARIED_TILT_DEG` towards azimuth 360·i/n + 45·(i mod 2)."""
        if kind == "targets":
            return self.target_tools.get(pid, (0.0, 0.0))
        if kind == "registration" and self.varied_registration:
            ids = self.layout["registration"].ids
            i = ids.index(pid) if pid in ids else 0
            return (VARIED_TILT_DEG, float(360.0 * i / max(len(ids), 1) + 45.0 * (i % 2)))
        return (0.0, 0.0)

    @thread_limited
    def set_varied_registration(self, varied: bool):
        """Measure the registration points with the tool leaned in varied directions (True) or pointing down, and
        re-evaluate. A pose the arm cannot reach: InputError, the session unchanged."""
        if self.arm_term() is None:
            raise InputError("tool orientation matters only for a scene with a kinematic arm error")
        old = self.varied_registration
        self.varied_registration = bool(varied)
        return self._evaluate_or_restore(
            "varied_registration", old, f"the arm cannot reach every registration point leaned {VARIED_TILT_DEG:g}°"
        )

    def _evaluate_or_restore(self, attr: str, old, refused: str):
        """Re-evaluate after `attr` changed; on any failure put `old` back (InputError says `refused: why`)."""
        try:
            return self.evaluate()
        except Exception as e:
            setattr(self, attr, old)
            if not isinstance(e, InputError):
                raise
            raise InputError(f"{refused}: {e}") from None

    def tool_rotations(self, kind: str, ids) -> np.ndarray:
        yaw = float(getattr(self.scene, "tool_yaw_deg", 0.0) or 0.0)
        return np.array([tool_rotation(yaw, *self.tool_of(kind, pid)) for pid in ids]).reshape(-1, 3, 3)

    def joints(self, kind: str, ids, positions) -> np.ndarray:
        """(P, 6) rad: the configurations in which the (true) arm reaches the points."""
        term = self.arm_term()
        if term is None:
            raise InputError("joint configurations need a scene whose robot error model has a kinematic term")
        pts = self.measurement_model().points(np.asarray(positions, float), self.tool_rotations(kind, ids))
        return term.joints(pts)

    @thread_limited
    def set_target_tool(self, pid: str, tilt_deg: float, azimuth_deg: float = 0.0):
        """Reach target `pid` with its tool leaned tilt_deg (0..TILT_MAX_DEG) towards azimuth_deg and re-evaluate.
        Out of range, or a pose the arm cannot reach: InputError, the session unchanged."""
        if self.arm_term() is None:
            raise InputError("tool orientation matters only for a scene with a kinematic arm error")
        self.layout["targets"].index(pid)
        tilt, az = float(tilt_deg), float(azimuth_deg)
        if not (np.isfinite(tilt) and np.isfinite(az)) or not 0.0 <= tilt <= TILT_MAX_DEG or abs(az) > 360.0:
            raise InputError(
                f"tool tilt must be 0 to {TILT_MAX_DEG:g} degrees and azimuth -360 to 360, got {tilt}, {az}"
            )
        old = dict(self.target_tools)
        if tilt == 0:
            self.target_tools.pop(pid, None)
        else:
            self.target_tools[pid] = (tilt, az)
        return self._evaluate_or_restore(
            "target_tools", old, f"target {pid}: the arm cannot reach it with the tool leaned {tilt:g}°"
        )

    @thread_limited
    def vec_view(self) -> VecView | None:
        """VEC beside rigid and RRBC for the current layout (module docstring); None without a kinematic arm."""
        from rrbc_core.analysis.vec_compare import fit_methods, predict_methods

        term = self.arm_term()
        if term is None:
            return None
        ev = self.last
        reg_ids, reg_pos = ev.registration_ids, ev.registration_positions
        inc = np.flatnonzero(ev.included)
        fid_ids = tuple(ev.fiducial_ids[i] for i in inc)
        fid_pos = ev.fiducial_positions[inc]
        s = np.vstack([ev.registration_readings.sensor, ev.fiducial_readings.sensor[inc]])
        b = np.vstack([ev.registration_readings.robot, ev.fiducial_readings.robot[inc]])
        q = np.vstack([self.joints("registration", reg_ids, reg_pos), self.joints("fiducials", fid_ids, fid_pos)])
        nr = len(reg_ids)
        if len(s) < 8:
            raise InputError(f"VEC needs at least 8 registration points and fiducials, got {len(s)}")
        key = (s.tobytes(), b.tobytes(), q.tobytes())
        nominal = term.dh
        fit = self._cached("vec", key, lambda: fit_methods(np.arange(nr), np.arange(nr, len(s)), s, b, q, nominal))
        t = ev.targets
        m = len(t.ids)
        if m:
            q_t = self.joints("targets", t.ids, t.positions)
            vec = predict_methods(fit, nominal, t.sensor, q_t)["vec"]
            err_vec = np.linalg.norm(vec - t.truth, axis=1)
        else:
            vec, err_vec = np.zeros((0, 3)), np.zeros(0)

        def rms(e):
            return float(np.sqrt(np.mean(e**2))) if len(e) and np.all(np.isfinite(e)) else None

        return VecView(
            t.ids,
            vec,
            err_vec,
            t.error_rigid,
            t.error_rrbc,
            np.array([self.tool_of("targets", pid) for pid in t.ids], float).reshape(-1, 2),
            {"rigid": rms(t.error_rigid), "rrbc": rms(t.error_rrbc), "vec": rms(err_vec)},
            int(fit.cal.rank),
            int(len(s)),
        )
