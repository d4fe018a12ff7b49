"""The session's pure evaluation: what the user controls (`Settings`), a layout of points (`Group`), their readings
(`Readings`), and the nine RRBC steps on them (`evaluate` -> `Evaluation`: registration, corrections, each target's
correction, landing and error, the fiducials' hull). Display positions are robot frame, mm; readings as the
measurement model (scene) or the file (measured data) give them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core import interpolation, registration
from rrbc_core.correction import metrics
from rrbc_core.correction.rrbc import correct_points, fiducial_corrections
from rrbc_core.errors import InputError
from rrbc_core.interpolation.hull import Coverage, assess_coverage
from rrbc_core.methods import MethodOptions

#: Bounds of what a user controls (issue 16: a value sent by a client cannot push the session into overflow).
SCALE_MAX = 100.0  # noise and bias sizes (the app's sliders go to 3)
SMOOTHING_MAX = 1e6
NEIGHBORS_MAX = 1000
POWER_MAX = 50.0


@dataclass(frozen=True)
class Settings:
    """What the user controls. noise_scale/bias_scale multiply the scene's random/deterministic error terms."""

    registration: str = "least-squares"
    interpolation: str = "idw"
    neighbors: int = 4
    power: float = 2.0
    smoothing: float = 0.0
    noise_scale: float = 1.0
    bias_scale: float = 1.0
    seed: int = 0
    excluded: frozenset = frozenset()

    def __post_init__(self):
        for name, top in (("noise_scale", SCALE_MAX), ("bias_scale", SCALE_MAX), ("smoothing", SMOOTHING_MAX)):
            v = getattr(self, name)
            if not np.isfinite(v) or not 0 <= v <= top:
                raise InputError(f"{name} must be a number from 0 to {top:g}, got {v}")
        if not 1 <= int(self.neighbors) <= NEIGHBORS_MAX or not 0 < self.power <= POWER_MAX:
            raise InputError(
                f"neighbors must be 1 to {NEIGHBORS_MAX} and power in (0, {POWER_MAX:g}], got {self.neighbors}, "
                f"{self.power}"
            )
        object.__setattr__(self, "excluded", frozenset(self.excluded))
        self.method  # noqa: B018 - validates the names and the chosen method's options

    @property
    def method(self) -> MethodOptions:
        """The registration and interpolation chosen, with the options of the chosen interpolation only."""
        idw, tps = self.interpolation == "idw", self.interpolation == "tps"
        return MethodOptions(
            registration=self.registration,
            interpolation=self.interpolation,
            neighbors=int(self.neighbors) if idw else None,
            power=float(self.power) if idw else None,
            smoothing=float(self.smoothing) if tps else None,
            seed=int(self.seed),
        )

    def interpolator(self):
        return self.method.interpolator()


@dataclass(frozen=True, eq=False)
class Group:
    """Points of one kind: ids and robot-frame display positions (M, 3) mm."""

    ids: tuple
    positions: np.ndarray

    def index(self, pid: str) -> int:
        try:
            return self.ids.index(pid)
        except ValueError:
            raise InputError(f"no point '{pid}' here; known: {', '.join(self.ids[:12])}") from None


@dataclass(frozen=True, eq=False)
class Readings:
    """Measurements of M points: sensor (M,3) sensor frame, robot (M,3) robot frame (NaN if none), truth (M,3)
    robot-frame command that reaches the point (NaN if unknown)."""

    sensor: np.ndarray
    robot: np.ndarray
    truth: np.ndarray


@dataclass(frozen=True, eq=False)
class TargetResult:
    """Per target (M,): robot-frame arrays (M,3) mm unless noted."""

    ids: tuple
    positions: np.ndarray  # display position
    sensor: np.ndarray  # sensor reading (sensor frame)
    correction: np.ndarray  # interpolated correction (sensor frame)
    correction_robot: np.ndarray  # the same vector in the robot frame (R @ correction), for drawing
    correction_std: np.ndarray | None  # (M,3) sensor frame, gp only
    robot_rigid: np.ndarray
    robot_rrbc: np.ndarray
    truth: np.ndarray  # NaN where unknown
    error_rigid: np.ndarray  # (M,) NaN where unknown
    error_rrbc: np.ndarray
    extrapolated: np.ndarray  # (M,) bool


@dataclass(frozen=True, eq=False)
class Evaluation:
    """The result of the nine RRBC steps for the current layout and settings (see the module docstring)."""

    settings: Settings
    registration: registration.Registration
    registration_ids: tuple
    registration_positions: np.ndarray
    registration_readings: Readings
    fiducial_ids: tuple
    fiducial_positions: np.ndarray
    fiducial_readings: Readings
    included: np.ndarray  # (N,) bool
    corrections: np.ndarray  # (N,3) sensor frame; NaN rows for excluded fiducials
    corrections_robot: np.ndarray  # (N,3) robot frame, for drawing
    targets: TargetResult
    hull_edges: np.ndarray  # (E,2,3) robot frame: edges of the included fiducials' convex hull
    summary: dict
    #: each target inside the included fiducials' hull or not, and how far from their plane (sensor readings, as
    #: RRBC sees them; `interpolation.hull.assess_coverage`, the one coverage); None without included fiducials
    coverage: Coverage | None = None


def hull_edges(points) -> np.ndarray:
    """Edges (E, 2, 3) of the convex hull of points (robot frame, mm): 3-D hull facets' edges, or the polygon
    in the best-fit plane for (nearly) coplanar points, or the segment for collinear ones."""
    from scipy.spatial import ConvexHull, QhullError

    from rrbc_core.geometry.points import LocalFrame

    p = np.asarray(points, float)
    if len(p) < 2:
        return np.zeros((0, 2, 3))
    frame = LocalFrame.of(p)
    if frame.dim == 3:
        try:
            hull = ConvexHull(p)
            edges = set()
            for simplex in hull.simplices:
                for a, b in ((0, 1), (1, 2), (0, 2)):
                    i, j = sorted((simplex[a], simplex[b]))
                    edges.add((i, j))
            # drop edges inside coplanar facets (shared by two facets with the same normal)
            keep = _feature_edges(hull, edges)
            return np.array([[p[i], p[j]] for i, j in keep]).reshape(-1, 2, 3)
        except QhullError:
            pass
    if frame.dim >= 2:
        try:
            hull = ConvexHull(frame.to_local(p)[:, :2])
            v = hull.vertices
            return np.array([[p[v[k]], p[v[(k + 1) % len(v)]]] for k in range(len(v))])
        except QhullError:
            pass
    local = frame.to_local(p)[:, 0] if frame.dim >= 1 else np.zeros(len(p))
    return np.array([[p[np.argmin(local)], p[np.argmax(local)]]])


def _feature_edges(hull, edges):
    normals = hull.equations[:, :3]
    owners: dict = {}
    for f, simplex in enumerate(hull.simplices):
        for a, b in ((0, 1), (1, 2), (0, 2)):
            owners.setdefault(tuple(sorted((simplex[a], simplex[b]))), []).append(f)
    keep = []
    for e in edges:
        fs = owners.get(e, [])
        if len(fs) == 2 and float(np.dot(normals[fs[0]], normals[fs[1]])) > 1 - 1e-9:
            continue
        keep.append(e)
    return sorted(keep)


def _display_rotation(mapping) -> np.ndarray:
    return np.asarray(mapping.rotation, float)


def evaluate(settings: Settings, layout: dict, readings: dict, cached=None) -> Evaluation:
    """The nine RRBC steps on a layout: register, correct the included fiducials, interpolate, correct the targets,
    score them against their truth where known. A pure function of its inputs.

    Parameters
    ----------
    settings : Settings
    The method and the excluded fiducials.
    layout : dict
    "registration", "fiducials", "targets" -> `Group` (ids and robot-frame display positions, mm).
    readings : dict
    The same keys -> `Readings` of those points, in the layout's order.
    cached : callable, optional
        ``cached(name, key, compute)`` returns a stored value for an unchanged key (the session's one-entry
        caches for the registration and the fitted interpolator); default: compute every time.
    """
    cached = cached or (lambda name, key, compute: compute())
    s = settings
    reg_r, fid_r, tgt_r = readings["registration"], readings["fiducials"], readings["targets"]
    reg = cached(
        "registration",
        (s.registration, s.seed, reg_r.sensor.tobytes(), reg_r.robot.tobytes()),
        lambda: s.method.register(reg_r.sensor, reg_r.robot),
    )
    fids = layout["fiducials"]
    included = np.array([pid not in s.excluded for pid in fids.ids], dtype=bool)
    corr = np.full((len(fids.ids), 3), np.nan)
    if np.any(included):
        corr[included] = fiducial_corrections(reg.mapping, fid_r.sensor[included], fid_r.robot[included])
        key = (s.interpolator(), fid_r.sensor[included].tobytes(), corr[included].tobytes())
        fitted = cached("fitted", key, lambda: s.interpolator().fit(fid_r.sensor[included], corr[included]))
    elif s.interpolation != "none":
        raise InputError("every fiducial is excluded: include at least one, or choose interpolation 'none'")
    else:
        fitted = interpolation.NoCorrection().fit(reg_r.sensor, np.zeros_like(reg_r.sensor))
    rot = _display_rotation(reg.mapping)
    corr_robot = corr @ rot.T
    tg = layout["targets"]
    if len(tg.ids):
        cp = correct_points(reg.mapping, fitted, tgt_r.sensor)
        err_rigid = np.linalg.norm(cp.robot_rigid - tgt_r.truth, axis=1)
        err_rrbc = np.linalg.norm(cp.robot_rrbc - tgt_r.truth, axis=1)
        targets = TargetResult(
            tg.ids,
            tg.positions,
            tgt_r.sensor,
            cp.correction,
            cp.correction @ rot.T,
            cp.correction_std,
            cp.robot_rigid,
            cp.robot_rrbc,
            tgt_r.truth,
            err_rigid,
            err_rrbc,
            cp.extrapolated,
        )
    else:
        z = np.zeros((0, 3))
        targets = TargetResult((), z, z, z, z, None, z, z, z, np.zeros(0), np.zeros(0), np.zeros(0, bool))
    hull = hull_edges(fids.positions[included]) if np.count_nonzero(included) >= 3 else np.zeros((0, 2, 3))
    known = np.isfinite(targets.error_rigid)
    summary = {
        "fre_rms_mm": reg.fre_rms_mm,
        "targets": len(tg.ids),
        "scored": int(np.count_nonzero(known)),
        "rmst_rigid_mm": metrics.rmst(targets.error_rigid[known]) if np.any(known) else None,
        "rmst_rrbc_mm": metrics.rmst(targets.error_rrbc[known]) if np.any(known) else None,
        "max_rigid_mm": float(targets.error_rigid[known].max()) if np.any(known) else None,
        "max_rrbc_mm": float(targets.error_rrbc[known].max()) if np.any(known) else None,
        "extrapolated": [pid for pid, e in zip(tg.ids, targets.extrapolated) if e],
        "fiducials_used": int(np.count_nonzero(included)),
    }
    coverage = assess_coverage(fid_r.sensor[included], tgt_r.sensor) if np.any(included) else None
    return Evaluation(
        s,
        reg,
        layout["registration"].ids,
        layout["registration"].positions,
        reg_r,
        fids.ids,
        fids.positions,
        fid_r,
        included,
        corr,
        corr_robot,
        targets,
        hull,
        summary,
        coverage,
    )
