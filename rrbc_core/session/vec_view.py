"""Model-based calibration (VEC) beside rigid and RRBC in the session (issue 15; docs/calibration.md).

Scene mode, a scene whose robot error model has a kinematic term: the arm reaches every point in a joint
configuration (the true arm's inverse kinematics at the point with its tool orientation). From the registration
points and the included fiducials — their readings and those configurations — `analysis.vec_compare.fit_methods`
identifies the arm's kinematic errors (its chain, `models.chain.Chain.from_dh`) and the sensor-to-robot transform (what `rrbc calibrate` does), and each target gets
VEC's command: the joints that put the identified arm's tool on the target, sent through the nominal controller.

Tool orientation. Every point is reached with the tool pointing down (turned by the scene's tool yaw), unless a
target has been given a tilt: the tool axis leaned by `tilt_deg` from straight down towards the azimuth
`azimuth_deg` (degrees from the base x axis about z). An arm's kinematic error depends on the configuration, so a
target reached at another orientation has another error; RRBC corrects by position alone (its fiducials were
measured tool-down) and cannot follow, while VEC, knowing the arm, can.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.runtime.threads import thread_limited
from rrbc_core.session.tools import TILT_MAX_DEG, VARIED_TILT_DEG

if TYPE_CHECKING:
    from rrbc_core.session.explorer import ExplorerSession


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


@thread_limited
def set_varied_registration(session: ExplorerSession, varied: bool):
    """Measure the registration points with the tool leaned in varied directions (True) or pointing down, and
    re-evaluate. A pose the arm cannot reach: InputError, the session unchanged."""
    if session.arm_term() is None:
        raise InputError("tool orientation matters only for a scene with a kinematic arm error")
    old = session.varied_registration
    session.varied_registration = bool(varied)
    return _evaluate_or_restore(
        session,
        "varied_registration",
        old,
        f"the arm cannot reach every registration point leaned {VARIED_TILT_DEG:g}°",
    )


def _evaluate_or_restore(session: ExplorerSession, attr: str, old, refused: str):
    """Re-evaluate after `attr` changed; on any failure put `old` back (InputError says `refused: why`)."""
    try:
        return session.evaluate()
    except Exception as e:
        setattr(session, attr, old)
        if not isinstance(e, InputError):
            raise
        raise InputError(f"{refused}: {e}") from None


def joints(session: ExplorerSession, kind: str, ids, positions) -> np.ndarray:
    """(P, 6) rad: the configurations in which the (true) arm reaches the points."""
    term = session.arm_term()
    if term is None:
        raise InputError("joint configurations need a scene whose robot error model has a kinematic term")
    pts = session.measurement_model().points(np.asarray(positions, float), session.tool_rotations(kind, ids))
    return term.joints(pts)


@thread_limited
def set_target_tool(session: ExplorerSession, pid: str, tilt_deg: float, azimuth_deg: float = 0.0):
    """Reach target `pid` with its tool leaned tilt_deg (0..TILT_MAX_DEG) towards azimuth_deg and re-evaluate.
    Out of range, or a pose the arm cannot reach: InputError, the session unchanged."""
    if session.arm_term() is None:
        raise InputError("tool orientation matters only for a scene with a kinematic arm error")
    session.layout["targets"].index(pid)
    tilt, az = float(tilt_deg), float(azimuth_deg)
    if not (np.isfinite(tilt) and np.isfinite(az)) or not 0.0 <= tilt <= TILT_MAX_DEG or abs(az) > 360.0:
        raise InputError(f"tool tilt must be 0 to {TILT_MAX_DEG:g} degrees and azimuth -360 to 360, got {tilt}, {az}")
    old = dict(session.target_tools)
    if tilt == 0:
        session.target_tools.pop(pid, None)
    else:
        session.target_tools[pid] = (tilt, az)
    return _evaluate_or_restore(
        session, "target_tools", old, f"target {pid}: the arm cannot reach it with the tool leaned {tilt:g}°"
    )


@thread_limited
def vec_view(session: ExplorerSession) -> VecView | None:
    """VEC beside rigid and RRBC for the current layout (module docstring); None without a kinematic arm."""
    from rrbc_core.analysis.vec_compare import fit_methods, predict_methods
    from rrbc_core.models.chain import Chain

    term = session.arm_term()
    if term is None:
        return None
    ev = session.last
    reg_ids, reg_pos = ev.registration_ids, ev.registration_positions
    inc = np.flatnonzero(ev.included)
    fid_ids = tuple(ev.fiducial_ids[i] for i in inc)
    fid_pos = ev.fiducial_positions[inc]
    s = np.vstack([ev.registration_readings.sensor, ev.fiducial_readings.sensor[inc]])
    b = np.vstack([ev.registration_readings.robot, ev.fiducial_readings.robot[inc]])
    q = np.vstack([joints(session, "registration", reg_ids, reg_pos), joints(session, "fiducials", fid_ids, fid_pos)])
    nr = len(reg_ids)
    if len(s) < 8:
        raise InputError(f"VEC needs at least 8 registration points and fiducials, got {len(s)}")
    key = (s.tobytes(), b.tobytes(), q.tobytes())
    chain = Chain.from_dh(term.dh, "arm")
    fit = session.cached("vec", key, lambda: fit_methods(np.arange(nr), np.arange(nr, len(s)), s, b, q, chain))
    t = ev.targets
    m = len(t.ids)
    if m:
        q_t = joints(session, "targets", t.ids, t.positions)
        vec = predict_methods(fit, t.sensor, q_t)["vec"]
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
        np.array([session.tool_of("targets", pid) for pid in t.ids], float).reshape(-1, 2),
        {"rigid": rms(t.error_rigid), "rrbc": rms(t.error_rrbc), "vec": rms(err_vec)},
        int(fit.cal.rank),
        int(len(s)),
    )
