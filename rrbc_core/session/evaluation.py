"""The session's pure evaluation: what the user controls (`Settings`), a layout of points (`Group`), their readings
(`Readings`), and the nine RRBC steps on them (`evaluate` -> `Evaluation`: registration, corrections, each target's
correction, landing and error, the fiducials' hull). Display positions are robot frame, mm; readings as the
measurement model (scene) or the file (measured data) give them."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from rrbc_core import interpolation, registration
from rrbc_core.correction import metrics
from rrbc_core.correction.bounds import Bounds, BoundsBasis, PointBounds, bound_points, bounds_basis
from rrbc_core.correction.check_statistics import gain_test
from rrbc_core.correction.rrbc import correct_points, fiducial_corrections
from rrbc_core.correction.warnings import Corrected, correction_warnings
from rrbc_core.errors import InputError
from rrbc_core.interpolation.auto import AutoChoice
from rrbc_core.interpolation.hull import Coverage, assess_coverage
from rrbc_core.io.id_sets import member_of
from rrbc_core.methods import MethodOptions, method_flags

#: Bounds of the noise and bias sizes a user controls (issue 16: a value sent by a client cannot push the session
#: into overflow; the app's sliders go to 3). The method's options carry their own bounds (`option_specs`).
SCALE_MAX = 100.0


@dataclass(frozen=True, init=False)
class Settings:
    """What the user controls: the method (names of the registration strategy and the interpolation, and the
    options the user set, by flag), the noise and bias sizes (multipliers of the scene's random and deterministic
    error terms), the seed (the session's noise draws and a seeded strategy's) and the excluded fiducials.

    ``Settings(interpolation="tps", smoothing=0.1, noise_scale=2.0)``: options are keyed by their flags
    (`methods.method_flags`: ``neighbors``, ``power``, ``smoothing``, ``kernel``, ``noise_mm``, ``clusters``,
    ``average``, …) and checked against their one spec each; an option of a method not chosen is kept (the app's
    widgets keep their values) and applies when that method is chosen. `method` is the `MethodOptions` in force;
    ``settings.neighbors`` (any flag) reads an option, its default when not set.
    """

    registration: str
    interpolation: str
    noise_scale: float
    bias_scale: float
    seed: int
    excluded: frozenset
    options: tuple  # ((flag, value), ...) sorted: the method options the user set

    def __init__(
        self,
        registration: str = "least-squares",
        interpolation: str = "idw",
        noise_scale: float = 1.0,
        bias_scale: float = 1.0,
        seed: int = 0,
        excluded=frozenset(),
        options=(),
        **flagged,
    ):
        flags = method_flags()
        merged = dict(options)
        for k, v in flagged.items():
            merged[k.replace("_", "-") if k.replace("_", "-") in flags else k] = v
        for k in list(merged):
            if k not in flags:
                raise InputError(f"unknown setting '{k}'")
            merged[k] = flags[k][0][2].check(merged[k], "setting")
        set_ = lambda name, value: object.__setattr__(self, name, value)
        set_("registration", str(registration).strip().lower())
        set_("interpolation", str(interpolation).strip().lower())
        for name, v, top in (("noise_scale", noise_scale, SCALE_MAX), ("bias_scale", bias_scale, SCALE_MAX)):
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not np.isfinite(v):
                raise InputError(f"{name} must be a number from 0 to {top:g}, got {v!r}")
            if not 0 <= v <= top:
                raise InputError(f"{name} must be a number from 0 to {top:g}, got {v}")
            set_(name, float(v))
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise InputError(f"seed must be an integer, got {seed!r}")
        set_("seed", int(seed))
        set_("excluded", frozenset(excluded))
        set_("options", tuple(sorted(merged.items())))
        self.method  # noqa: B018 - validates the names and the chosen methods' options

    def replace(self, **changes) -> Settings:
        """A copy with fields or flag-named options changed (what `ExplorerSession.update` applies)."""
        base: dict[str, Any] = {
            "registration": self.registration,
            "interpolation": self.interpolation,
            "noise_scale": self.noise_scale,
            "bias_scale": self.bias_scale,
            "seed": self.seed,
            "excluded": self.excluded,
        }
        opts = dict(self.options)
        for k, v in changes.items():
            if k in base:
                base[k] = v
            else:
                opts[k.replace("_", "-") if k.replace("_", "-") in method_flags() else k] = v
        return Settings(**base, options=tuple(opts.items()))

    @cached_property
    def method(self) -> MethodOptions:
        """The registration and interpolation in force, with the options the user set for them (and the session's
        seed for a seeded strategy). Made once per Settings (frozen: its fields never change)."""
        flags = method_flags()
        chosen = {self.registration, self.interpolation}
        given = {k: v for k, v in self.options if any(name in chosen for _, name, _ in flags[k])}
        return MethodOptions.named(self.registration, self.interpolation, seed=self.seed, **given)

    def __getattr__(self, name: str):
        """An option by its flag (``settings.neighbors``): the value set, else its default."""
        flags = method_flags()
        flag = name.replace("_", "-") if name.replace("_", "-") in flags else name
        if flag not in flags:
            raise AttributeError(name)
        given = dict(object.__getattribute__(self, "options"))
        return given.get(flag, flags[flag][0][2].default)

    def to_json(self) -> dict:
        """The settings as JSON: names, sizes, seed, excluded fiducials and every option of the chosen methods."""
        m = self.method
        return {
            "registration": self.registration,
            "interpolation": self.interpolation,
            **m.registration_json(),
            **{k: v for k, v in m.interpolation_json().items() if k != "method"},
            "noise_scale": self.noise_scale,
            "bias_scale": self.bias_scale,
            "seed": self.seed,
            "excluded": sorted(self.excluded),
        }

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
    #: one-line warnings (`correction.warnings.correction_warnings`, as `rrbc correct` prints them)
    warnings: tuple[str, ...] = ()
    #: with interpolation "auto": what cross-validation over the fiducials chose (`interpolation.auto.AutoChoice`)
    choice: AutoChoice | None = None
    #: the targets that are a measurement file's check rows (scored against their robot values)
    check_ids: frozenset = frozenset()
    #: each target's 95 % bound, covariance and budget, RRBC's and rigid's, in the targets' order
    #: (`correction.bounds`, as `rrbc correct` gives them); None without targets
    bounds: TargetBounds | None = None


@dataclass(frozen=True, eq=False)
class TargetBounds:
    """The targets' bounds in the layout's order: `rrbc` and `rigid` (`correction.bounds.PointBounds`, (M,) each)
    and what they rest on (`correction.bounds.Bounds`: the instrument, the cross-validation profile)."""

    rrbc: PointBounds
    rigid: PointBounds
    source: Bounds
    #: the registration's and fiducials' part (`correction.bounds.bound_points` bounds any other points with it:
    #: the error slice's grid)
    basis: BoundsBasis | None = None


ROLES_COUNTED = ("registration", "fiducial", "target", "check")


def row_counts(data) -> dict[str, dict[str, int]]:
    """{role: {id: rows}}: how many of `data`'s rows of each role (`MeasurementSet.rows`) each id has."""
    out: dict[str, dict[str, int]] = {}
    for role in ROLES_COUNTED:
        n: dict[str, int] = {}
        for i in data.rows(role).tolist():
            n[data.ids[i]] = n.get(data.ids[i], 0) + 1
        out[role] = n
    return out


def _counts(counts: dict | None, role: str, ids) -> np.ndarray:
    """(M,): each id's rows of `role` (`row_counts`; 1 without data or rows)."""
    n = counts.get(role, {}) if counts is not None else {}
    return np.array([max(n.get(pid, 1), 1) for pid in ids], float)


def _target_bounds(
    cached,
    data,
    T_robot_sensor,
    reg,
    reg_ids,
    reg_r,
    fid_ids,
    fid_r,
    e_sensor,
    included,
    method,
    s,
    tg,
    tgt_r,
    coverage,
    check_ids,
    instrument=None,
    previous=None,
):
    """`correction.bounds.correction_bounds` on the session's points, the file's check rows bounded as checks and
    the rest as targets (as `rrbc correct` splits them), then put back in the targets' order. The registration's and
    fiducials' part (`bounds_basis`) is `cached`: a target's drag recomputes only the points' part. During a
    fiducial's drag (`previous` given) the basis keeps the cross-validation profile of the layout before the drag
    (the folds' error against distance: a statistic of all the fiducials, not of the one moving) and computes the
    rest for the layout as it is; the drag's end computes it all (what `rrbc correct` gives)."""
    fid_in = [pid for pid, k in zip(fid_ids, included) if k]
    is_check = np.array([pid in check_ids for pid in tg.ids], bool)
    off = coverage.off_plane_mm if coverage is not None else np.zeros(len(tg.ids))
    counts = cached("row_counts", id(data), lambda: row_counts(data)) if data is not None else None
    tgt_counts = _counts(counts, "target", tg.ids)
    if counts is not None:
        tgt_counts[is_check] = _counts(counts, "check", [pid for pid, c in zip(tg.ids, is_check) if c])
    points = {
        kind: (tgt_r.sensor[sel], tgt_counts[sel], np.asarray(off, float)[sel])
        for kind, sel in (("targets", ~is_check), ("checks", is_check))
    }
    fid_counts = _counts(counts, "fiducial", fid_in)
    reg_counts = _counts(counts, "registration", reg_ids)
    key = (
        repr(method),
        s.interpolation,
        reg_r.sensor.tobytes(),
        reg_r.robot.tobytes(),
        fid_r.sensor[included].tobytes(),
        e_sensor[included].tobytes(),
        fid_counts.tobytes(),
        reg_counts.tobytes(),
        id(data),
        s.noise_scale,
        None if instrument is None else instrument.name,
    )

    def basis_of(profile=None):
        return bounds_basis(
            data,
            T_robot_sensor,
            reg_r.sensor,
            reg_counts,
            fid_r.sensor[included],
            fid_counts,
            e_sensor[included],
            method,
            s.interpolation != "none",
            instrument,
            np.asarray(reg.residuals, float).reshape(-1, 3),
            member_of(fid_in, reg_ids),
            profile,
        )

    last = previous("bounds") if previous is not None else None
    live, kept = False, None
    if last is not None and last[1].profile is not None:
        last_key, last_basis = last
        kept = last_basis.profile
        live = (
            last_key != key
            and last_key[:2] == key[:2]  # the same method and interpolation
            and len(last_basis.fid_sensor) == int(np.count_nonzero(included))
        )
    if live:  # a drag's update: the profile from before the drag, the rest for this layout (never cached as exact)
        basis = cached("bounds", key + ("live",), lambda: basis_of(kept))
    else:
        basis = cached("bounds", key, basis_of)
    b = bound_points(basis, points)
    m = len(tg.ids)

    def merged(a: PointBounds | None, c: PointBounds | None) -> PointBounds:
        bound, cov = np.full(m, np.nan), np.full((m, 3, 3), np.nan)
        budget: dict[str, np.ndarray] = {}
        for part, sel in ((a, ~is_check), (c, is_check)):
            if part is None:
                continue
            bound[sel], cov[sel] = part.bound95_mm, part.cov_mm2
            for k, v in part.budget_mm.items():
                budget.setdefault(k, np.full(m, np.nan))[sel] = v
        return PointBounds(bound, cov, budget)

    return TargetBounds(merged(b.targets, b.checks), merged(b.targets_rigid, b.checks_rigid), b, basis)


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


def evaluate(
    settings: Settings,
    layout: dict,
    readings: dict,
    cached=None,
    check_ids: frozenset = frozenset(),
    data=None,
    instrument=None,
    previous=None,
) -> Evaluation:
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
    check_ids : frozenset of str, optional
        The targets that are a file's check rows: the warnings call them checks, as `rrbc correct` does.
    data : MeasurementSet, optional
        The file's rows when the session is a measured file: the bounds read its repeats (`correction.bounds`).
    instrument : Instrument, optional
        The bounds' reading noise (a scene's own, `models.instrument.scene_instrument`; default: estimated).
    previous : callable, optional
        A drag's live update: ``previous(name)`` gives the cache's last (key, value) whatever its key; the bounds
        then keep the fiducials' cross-validation from before the drag (`_target_bounds`). None (default): exact.
    """
    cached = cached or (lambda name, key, compute: compute())
    s = settings
    reg_r, fid_r, tgt_r = readings["registration"], readings["fiducials"], readings["targets"]
    reg = cached(
        "registration",
        (s.method.registration, reg_r.sensor.tobytes(), reg_r.robot.tobytes()),
        lambda: s.method.register(reg_r.sensor, reg_r.robot),
    )
    T_robot_sensor = reg.mapping  # frames in names: docs/architecture.md
    fids = layout["fiducials"]
    included = np.array([pid not in s.excluded for pid in fids.ids], dtype=bool)
    e_sensor = np.full((len(fids.ids), 3), np.nan)
    if np.any(included):
        e_sensor[included] = fiducial_corrections(T_robot_sensor, fid_r.sensor[included], fid_r.robot[included])
        key = (s.interpolator(), fid_r.sensor[included].tobytes(), e_sensor[included].tobytes())
        fitted = cached("fitted", key, lambda: s.interpolator().fit(fid_r.sensor[included], e_sensor[included]))
    elif s.interpolation != "none" and len(fids.ids):
        raise InputError("every fiducial is excluded: include at least one, or choose interpolation 'none'")
    else:
        fitted = interpolation.NoCorrection().fit(reg_r.sensor, np.zeros_like(reg_r.sensor))
    R_robot_sensor = _display_rotation(T_robot_sensor)
    e_robot = e_sensor @ R_robot_sensor.T
    tg = layout["targets"]
    if len(tg.ids):
        cp = correct_points(T_robot_sensor, fitted, tgt_r.sensor)
        err_rigid = np.linalg.norm(cp.robot_rigid - tgt_r.truth, axis=1)
        err_rrbc = np.linalg.norm(cp.robot_rrbc - tgt_r.truth, axis=1)
        targets = TargetResult(
            tg.ids,
            tg.positions,
            tgt_r.sensor,
            cp.correction,
            cp.correction @ R_robot_sensor.T,
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
        # whether the scored points show RRBC's change (the decision rrbc diagnose's recommendation makes)
        "gain": gain_test(targets.error_rigid[known], targets.error_rrbc[known]).verdict if np.any(known) else None,
        "extrapolated": [pid for pid, e in zip(tg.ids, targets.extrapolated) if e],
        "fiducials_used": int(np.count_nonzero(included)),
    }
    coverage = assess_coverage(fid_r.sensor[included], tgt_r.sensor) if np.any(included) else None
    warnings = _warnings(fids.ids, fid_r.sensor, e_sensor, included, targets, coverage, check_ids)
    if not len(fids.ids) and s.interpolation != "none":  # a new cell: nothing to interpolate yet
        warnings = (NO_FIDUCIALS_WARNING,) + warnings
    bounds = None
    if len(tg.ids):
        choice = getattr(fitted, "choice", None)
        method = choice.method if choice is not None else s.interpolator()
        bounds = _target_bounds(
            cached,
            data,
            T_robot_sensor,
            reg,
            layout["registration"].ids,
            reg_r,
            fids.ids,
            fid_r,
            e_sensor,
            included,
            method,
            s,
            tg,
            tgt_r,
            coverage,
            check_ids,
            instrument,
            previous,
        )
        warnings = warnings + bounds.source.warnings
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
        e_sensor,
        e_robot,
        targets,
        hull,
        summary,
        coverage,
        warnings,
        getattr(fitted, "choice", None),
        frozenset(check_ids),
        bounds,
    )


#: What a cell without fiducials says (a new cell, before the user adds them).
NO_FIDUCIALS_WARNING = "no fiducials yet: the RRBC corrections are zero (rigid registration only); add fiducials"


def _warnings(fid_ids, fid_sensor, e_sensor, included, targets: TargetResult, coverage, check_ids):
    """`correction_warnings` on the included fiducials and the targets, split into targets and checks as a file
    has them."""
    ids = [pid for pid, keep in zip(fid_ids, included) if keep]
    points = []
    for kind, wanted in (("target", False), ("check", True)):
        rows = [i for i, pid in enumerate(targets.ids) if (pid in check_ids) == wanted]
        if not rows:
            continue
        cov = None
        if coverage is not None:
            cov = Coverage(
                coverage.inside[rows],
                coverage.off_plane_mm[rows],
                coverage.plane_tol_mm,
                None if coverage.fraction is None else coverage.fraction[rows],
                coverage.dim,
            )
        points.append(Corrected(kind, [targets.ids[i] for i in rows], targets.correction[rows], cov))
    return correction_warnings(ids, fid_sensor[included], e_sensor[included], points)
