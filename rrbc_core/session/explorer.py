"""The interactive RRBC session behind the browser app: everything the app shows is computed (and tested) here.

A session holds an editable layout (registration points, fiducials, targets: ids and positions) and settings
(registration strategy, interpolation and its parameters, noise and bias sizes, seed, excluded fiducials).
`evaluate()` runs the nine RRBC steps on the current layout and returns an `Evaluation`: the registration,
fiducial corrections, each target's correction, where it lands rigid-only and with RRBC, its error against
the truth (scene mode), whether it is extrapolated, and the fiducials' hull.

Two sources:
- a scene (`from_scene`): positions are PHYSICAL points in the robot frame (mm). Each point is "measured"
  from the scene's error model: sensor s = T⁻¹(p) + b·β_s(p) + n·ν_s, robot b = p + b·β_r(p) + n·η_r, truth
  (the command that reaches p) = p + b·β_r(p), with b, n the bias and noise sizes (multipliers, 1 = the
  scene's model). Bias is re-evaluated wherever a point moves; a point's noise is drawn from a generator seeded
  by (seed, point id), so dragging a point keeps its noise draw and a new seed redraws every point.
- a measurement file (`from_measurements`): readings as measured, no error model. Registration points and
  fiducials cannot be re-measured elsewhere (moving them is refused); a target can be moved: its new robot-frame
  position is taken to the sensor frame with the current registration, and the interpolated correction and
  (for `gp`) its standard deviation there are reported. Check rows keep their truth while not moved.

Display positions are robot-frame (mm): scene mode shows physical points, measurement mode shows robot
readings (registration, fiducials) and rigidly mapped sensor readings (targets).

The session holds state and measures; what is computed from it lives in small modules of functions that take the
session as their first argument (no mixins): `planning_view` (coverage, predicted RMST, suggestions), `views`
(heat map, error slice, Monte Carlo, the JSON export), `data_set` (the data as a measurement file holds them, what
the Diagnose tab diagnoses), `authoring` (edits and their history) and `vec_view` (the arm's joints, leaned tools,
VEC). They read the session's public state and its one-entry caches (`cached`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import COORDINATE_LIMIT_MM
from rrbc_core.models.errorterms import Kinematic
from rrbc_core.models.measurement import MeasurementModel
from rrbc_core.runtime.threads import thread_limited
from rrbc_core.session.evaluation import Evaluation, Group, Readings, Settings, evaluate
from rrbc_core.session.tools import VARIED_TILT_DEG, tool_rotation

#: points whose bias an explorer session keeps (`ExplorerSession._bias_of`); past it the store starts again
BIAS_KEPT = 20_000


@dataclass
class History:
    """The edit history of a session (`edits.undo`, `edits.redo`): states before each edit, newest last."""

    undo: list = field(default_factory=list)
    redo: list = field(default_factory=list)


class ExplorerSession:
    """The interactive session behind the browser app: a layout of points, the settings, and everything shown.

    Make one with `from_scene(scene)` (points measured through the scene's measurement model wherever they are
    moved) or `from_measurements(mset)` (readings as measured). Every method that changes it (`move`, `update`,
    `set_excluded`) returns the new `Evaluation` and leaves the session unchanged when it raises `InputError`;
    `evaluate()` / `last` give the current one. Positions are robot frame, mm. The functions over a session are in
    `planning_view`, `views`, `data_set`, `authoring` and `vec_view` (module docstring).
    """

    def __init__(
        self,
        *,
        kind,
        name,
        layout,
        settings,
        scene=None,
        mset=None,
        readings=None,
        regions=None,
        mesh_path=None,
        sensor_to_robot=None,
    ):
        self.kind = kind  # "scene" or "measurements"
        self.name = name
        self.layout = layout  # dict: "registration"/"fiducials"/"targets" -> Group
        self.settings = settings
        self.scene = scene
        self.mset = mset
        self.regions = regions or {}  # target id -> Region (scene mode)
        self.mesh_path = mesh_path
        self.sensor_to_robot = sensor_to_robot  # true pose (scene mode) or None
        self._readings = readings or {}  # (kind, id) -> (position key, sensor, robot, truth) at scale 1 parts
        self._last: Evaluation | None = None
        self._heat_cache: dict = {}
        self._cache: dict = {}
        self._bias: dict = {}  # (pose, position, tool, time) -> a point's unscaled bias (β_s, β_r): seed-free
        self.suggestion = None  # the last planning.PlanResult from suggest_fiducials (None: none pending)
        self._suggestion_key = None  # planning key of the layout the suggestion was made for
        self.accepted: tuple = ()  # ids of fiducials added by accept_suggestions, in order
        # candidate fiducial locations (scene mode; authoring edits them) and the edit history (authoring)
        cands = getattr(scene, "candidates", None)
        self.candidates = Group(
            tuple(cands.ids) if cands is not None else (),
            np.array(cands.positions, float).reshape(-1, 3) if cands is not None else np.zeros((0, 3)),
        )
        self.history = History()  # the edits (authoring.undo / redo)
        self.target_tools: dict = {}  # target id -> (tilt, azimuth) degrees of its tool (vec_view); absent: tool down
        self.varied_registration = False  # registration points measured with the tool leaned (vec_view)
        self.stations: tuple[str, ...] = ()  # a file with a group column: its stations (from_measurements)
        self.station: str | None = None  # ... the one open
        self.file_mset = None  # ... and the whole file
        self.saved_fingerprint: str | None = None  # edits.fingerprint of what was last opened or saved
        self.arm = None  # measured data: the robot's URDF description (session.arm.attach_arm), else None
        self.arm_joints: dict = {}  # ... each point's joint values, (kind, id) -> (I,) rad or mm
        self.arm_spec: tuple | None = None  # ... (urdf, tip, base, tool), kept when another station opens

    # ------------------------------------------------------------------------------------------------ sources
    @classmethod
    @thread_limited
    def from_scene(cls, scene, settings: Settings | None = None) -> ExplorerSession:
        layout = {
            "registration": Group(tuple(scene.registration.ids), np.array(scene.registration.positions, float)),
            "fiducials": Group(tuple(scene.fiducials.ids), np.array(scene.fiducials.positions, float)),
            "targets": Group(tuple(t.id for t in scene.targets), np.array([t.position for t in scene.targets], float)),
        }
        return cls(
            kind="scene",
            name=scene.name,
            layout=layout,
            settings=settings or Settings(seed=scene.seed),
            scene=scene,
            regions={t.id: t.region for t in scene.targets},
            mesh_path=scene.mesh_path,
            sensor_to_robot=scene.sensor_to_robot,
        )

    @classmethod
    @thread_limited
    def from_measurements(
        cls, mset, mesh_path=None, settings: Settings | None = None, station: str | None = None
    ) -> ExplorerSession:
        """A session on measured data. A file with stations (a `group` column, `io.groups`) opens one station —
        `station`, default the first — as a file of its own: its registration, fiducials, targets and checks;
        ``stations`` lists them all, ``station`` is the one open and ``file_mset`` the whole file (for the pooled
        figures, `stations_summary`)."""
        from rrbc_core.io.groups import group_names, has_groups, split_groups

        if has_groups(mset):
            parts = dict(split_groups(mset))
            names = group_names(mset)
            chosen = names[0] if station is None else str(station)
            if chosen not in parts:
                raise InputError(f"{mset.source}: no station {chosen!r}; its stations: {', '.join(names[:20])}")
            session = cls._from_rows(parts[chosen], mesh_path, settings)
            session.stations, session.station, session.file_mset = names, chosen, mset
            session.name = f"{mset.source}, station {chosen!r}"
            return session
        if station is not None:
            raise InputError(f"{mset.source}: has no group column, so no station {station!r}")
        return cls._from_rows(mset, mesh_path, settings)

    def stations_summary(self) -> dict | None:
        """With stations: `rrbc correct`'s pooled summary over all stations' checks with this session's method
        (`correction.stations.StationsResult.summary`), cached per method; None without stations or when a station
        cannot be corrected."""
        if not self.stations:
            return None
        from rrbc_core.correction.stations import correct_stations

        def compute():
            if self.file_mset is None:
                return None
            try:
                return correct_stations(self.file_mset, self.settings.method).summary()
            except InputError:
                return None

        return self.cached("stations_summary", self.settings.method, compute)

    @classmethod
    def _from_rows(cls, mset, mesh_path=None, settings: Settings | None = None) -> ExplorerSession:
        reg = mset.points("registration")
        fid = mset.points("fiducial")
        tgt = mset.points("target")
        chk = mset.points("check")
        settings = settings or Settings()
        readings = {}
        for kind, g in (("registration", reg), ("fiducials", fid)):
            for i, pid in enumerate(g.ids):
                readings[(kind, pid)] = (g.sensor[i], g.robot[i], np.full(3, np.nan))
        ids = tuple(tgt.ids) + tuple(chk.ids)
        sensor = np.vstack([tgt.sensor.reshape(-1, 3), chk.sensor.reshape(-1, 3)])
        truth = np.vstack([np.full((len(tgt.ids), 3), np.nan), chk.robot.reshape(-1, 3)])
        for i, pid in enumerate(ids):
            readings[("targets", pid)] = (sensor[i], np.full(3, np.nan), truth[i])
        reg_map = settings.method.register(reg.sensor, reg.robot)
        layout = {
            "registration": Group(tuple(reg.ids), np.array(reg.robot, float)),
            "fiducials": Group(tuple(fid.ids), np.array(fid.robot, float)),
            "targets": Group(ids, reg_map.mapping.apply(sensor) if len(ids) else np.zeros((0, 3))),
        }
        return cls(
            kind="measurements",
            name=mset.source,
            layout=layout,
            settings=settings,
            mset=mset,
            readings=readings,
            mesh_path=mesh_path,
        )

    # ------------------------------------------------------------------------------------------- measuring
    def measurement_model(self) -> MeasurementModel:
        """Scene mode: the scene's measurement model with the bias and noise sizes of the settings."""
        sc, s = self.scene, self.settings
        return MeasurementModel(self.sensor_to_robot, sc.error_model, sc.joint_seed, s.bias_scale, s.noise_scale)

    def measure_points(self, kind: str, ids, positions, noise: bool = True) -> Readings:
        """Scene mode: readings of points at `positions` (robot frame) through the measurement model at their times
        in the data set (`row_times`), each point's noise drawn from its own generator seeded by (seed, id)
        (`MeasurementModel.read_each`, as `rrbc simulate --out` draws it); noise=False: the expected readings, bias
        only."""
        model = self.measurement_model()
        positions = np.asarray(positions, float).reshape(-1, 3)
        pts = model.points(positions, self.tool_rotations(kind, ids), self.row_times(kind, ids))
        if not noise:  # heat-map and slice samples (thousands, their own cache): computed, not kept point by point
            r = model.read(pts)
        else:
            r = model.read_each(pts, list(ids), self.settings.seed, self._bias_of(model, pts))
        return Readings(r.sensor[0], r.robot[0], r.truth)

    def _bias_of(self, model: MeasurementModel, pts) -> tuple[np.ndarray, np.ndarray]:
        """(β_s, β_r) (P, 3) of the points, unscaled: a point's bias does not depend on the seed or on the other
        points (each is solved from the same joint seed), so it is kept and reused when only the seed or the noise
        changes (a new seed in the app, the tolerance planner's fresh draws). At most `BIAS_KEPT` points are kept."""
        pose = (self.sensor_to_robot.rotation.tobytes(), self.sensor_to_robot.translation.tobytes())
        rot = np.broadcast_to(np.eye(3) if pts.tool_rotation is None else pts.tool_rotation, (len(pts.robot), 3, 3))
        keys = [(pose, pts.robot[i].tobytes(), rot[i].tobytes(), float(pts.time[i])) for i in range(len(pts.robot))]
        # read into a dict of this call's own (a planner's copy of the session shares the store, and may start it
        # again meanwhile)
        got = {k: v for k in keys if (v := self._bias.get(k)) is not None}
        missing = [i for i, k in enumerate(keys) if k not in got]
        if missing:
            bs, br = model.bias(pts.take(np.array(missing)))
            if len(self._bias) + len(missing) > BIAS_KEPT:
                self._bias.clear()
            for j, i in enumerate(missing):
                got[keys[i]] = self._bias[keys[i]] = (bs[j], br[j])
        n = len(keys)
        return (
            np.array([got[k][0] for k in keys], dtype=np.float64).reshape(n, 3),
            np.array([got[k][1] for k in keys], dtype=np.float64).reshape(n, 3),
        )

    def row_times(self, kind: str, ids) -> np.ndarray:
        """(P,) s: when each point is measured in the session's data set — the rows in the order `rrbc simulate`
        writes them (registration points, then the fiducials that are not also registration points, then the
        targets), `measurement_interval_s` apart (0 for other kinds: heat map and slice samples)."""
        order = self.row_order()
        dt = float(getattr(self.scene, "measurement_interval_s", 0.0) or 0.0)
        return np.array([order.get((kind, pid), 0) * dt for pid in ids], float)

    def row_order(self) -> dict:
        """{(kind, id): row index} of the registration points, fiducials (a fiducial with a registration point's id
        shares its row: role both) and targets."""
        reg = self.layout["registration"].ids
        order = {("registration", pid): i for i, pid in enumerate(reg)}
        n = len(reg)
        for pid in self.layout["fiducials"].ids:
            if ("registration", pid) in order:
                order[("fiducials", pid)] = order[("registration", pid)]
            else:
                order[("fiducials", pid)] = n
                n += 1
        for pid in self.layout["targets"].ids:
            order[("targets", pid)] = n
            n += 1
        return order

    def _readings_for(self, kind: str) -> Readings:
        g = self.layout[kind]
        if self.kind == "measurements":
            rows = [self._readings[(kind, pid)] for pid in g.ids]
            if not rows:
                return Readings(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))
            return Readings(*(np.array([r[k] for r in rows], float).reshape(-1, 3) for k in range(3)))
        key_settings = (self.settings.seed, self.settings.noise_scale, self.settings.bias_scale)
        out_s, out_r, out_t = [], [], []
        missing = []
        times = self.row_times(kind, g.ids)
        for i, pid in enumerate(g.ids):
            key = (kind, pid)
            cached = self._readings.get(key)
            if cached is None or cached[0] != (
                key_settings,
                tuple(g.positions[i]),
                self.tool_of(kind, pid),
                float(times[i]),
            ):
                missing.append(i)
        if missing:
            fresh = self.measure_points(kind, [g.ids[i] for i in missing], g.positions[missing])
            for j, i in enumerate(missing):
                self._readings[(kind, g.ids[i])] = (
                    (key_settings, tuple(g.positions[i]), self.tool_of(kind, g.ids[i]), float(times[i])),
                    fresh.sensor[j],
                    fresh.robot[j],
                    fresh.truth[j],
                )
        for pid in g.ids:
            _, a, b, c = self._readings[(kind, pid)]
            out_s.append(a)
            out_r.append(b)
            out_t.append(c)
        n = len(g.ids)
        return Readings(np.array(out_s).reshape(n, 3), np.array(out_r).reshape(n, 3), np.array(out_t).reshape(n, 3))

    def readings_of(self, kind: str, pid: str) -> Readings:
        """The current readings of one point (sensor (3,), robot (3,), truth (3,))."""
        i = self.layout[kind].index(pid)
        r = self._readings_for(kind)
        return Readings(r.sensor[i], r.robot[i], r.truth[i])

    # ---------------------------------------------------------------------------------- the arm and its tool
    def arm_term(self) -> Kinematic | None:
        """The scene's kinematic error term, or None (measured data; a scene without one)."""
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

    def tool_rotations(self, kind: str, ids) -> np.ndarray:
        """(P, 3, 3) the tool orientations the points of `kind` are reached with (robot frame)."""
        yaw = float(getattr(self.scene, "tool_yaw_deg", 0.0) or 0.0)
        return np.array([tool_rotation(yaw, *self.tool_of(kind, pid)) for pid in ids]).reshape(-1, 3, 3)

    # -------------------------------------------------------------------------------------------- editing
    @thread_limited
    def move(self, kind: str, pid: str, position, live: bool = False) -> Evaluation:
        """Move a point (robot frame, mm) and re-evaluate. kind: registration, fiducials or targets. `live`: a drag's
        update, whose bounds keep the fiducials' cross-validation from before the drag (`evaluation.evaluate`'s
        `previous`); the drag's end moves it without `live` (everything computed for the layout)."""
        if kind not in self.layout:
            raise InputError(f"unknown point kind '{kind}': registration, fiducials or targets")
        p = np.asarray(position, float).reshape(3)
        if not np.all(np.isfinite(p)):
            raise InputError("a position must be 3 finite numbers (mm)")
        if np.abs(p).max() > COORDINATE_LIMIT_MM:  # the measurement reader's own limit: a unit or format slip
            raise InputError(f"a position must lie within {COORDINATE_LIMIT_MM:g} mm of the origin")
        g = self.layout[kind]
        i = g.index(pid)
        old_layout, old_readings = self.layout, dict(self._readings)
        if self.kind == "measurements":
            if kind != "targets":
                raise InputError(
                    "measured registration points and fiducials cannot be moved: there is no error model to "
                    "re-measure them elsewhere (load a scene to experiment with placement)"
                )
            mapping = (self._last or self.evaluate()).registration.mapping
            sensor = mapping.apply_inverse(p[None])[0]
            self._readings[(kind, pid)] = (sensor, np.full(3, np.nan), np.full(3, np.nan))
        positions = g.positions.copy()
        positions[i] = p
        self.layout = {**self.layout, kind: Group(g.ids, positions)}
        try:
            return self.evaluate(live)
        except Exception:  # out of the arm's reach, or anything else: keep the last good layout
            self.layout, self._readings = old_layout, old_readings
            raise

    @thread_limited
    def set_excluded(self, pid: str, excluded: bool) -> Evaluation:
        self.layout["fiducials"].index(pid)
        ex = set(self.settings.excluded)
        (ex.add if excluded else ex.discard)(pid)
        return self.update(excluded=frozenset(ex))

    @thread_limited
    def update(self, **changes) -> Evaluation:
        """Change settings (names as in Settings) and re-evaluate; invalid values raise InputError and leave
        the session unchanged."""
        new = self.settings.replace(**changes)
        if self.kind == "measurements" and (new.noise_scale != 1.0 or new.bias_scale != 1.0):
            raise InputError("noise and bias sizes apply to scenes; measured data are what they are")
        old = self.settings
        self.settings = new
        try:
            return self.evaluate()
        except Exception:  # any failure of an update: the last good settings stay (issue 16)
            self.settings = old
            raise

    # ----------------------------------------------------------------------------------------- evaluating
    @thread_limited
    def evaluate(self, live: bool = False) -> Evaluation:
        """Measure what changed (scene mode) and run `evaluation.evaluate` on the layout as it is now (`live`: a
        drag's update, `move`)."""
        readings = {kind: self._readings_for(kind) for kind in ("registration", "fiducials", "targets")}
        checks = frozenset(self.mset.points("check").ids) if self.mset is not None else frozenset()
        instrument = None
        if self.kind == "scene":  # the scene's own noise terms are the instrument
            from rrbc_core.models.instrument import scene_instrument

            instrument = scene_instrument(self.measurement_model(), self.sensor_to_robot)
        previous = self._cache.get if live else None
        self._last = evaluate(
            self.settings, self.layout, readings, self.cached, checks, self.mset, instrument, previous
        )
        return self._last

    def cached(self, name: str, key, compute):
        """One-entry cache per name: a drag that leaves the registration points (or the fiducials) unchanged
        reuses the registration (or the fitted interpolator) instead of recomputing it."""
        hit = self._cache.get(name)
        if hit is not None and hit[0] == key:
            return hit[1]
        value = compute()
        self._cache[name] = (key, value)
        return value

    @property
    def last(self) -> Evaluation:
        return self._last or self.evaluate()
