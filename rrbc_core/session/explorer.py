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

Planning (scene mode; thin wrappers over `rrbc_core.planning`): `planning_state()` gives each target's coverage
(fraction of its region of variability inside the INCLUDED fiducials' hull, at their current, possibly dragged,
positions) and the fast predicted RMST, cached on the fiducials, targets and noise/bias sizes;
`suggest_fiducials(k)` asks the planner for K more fiducials from the scene's candidates (kept as `suggestion`);
`accept_suggestions()` adds them as fiducials (measured from the error model like moved fiducials: stable ids,
noise seeded by id). The scene frame is the robot frame here, so layout positions go to the planner as they are.
"""

from __future__ import annotations

import dataclasses
import zlib

import numpy as np

from rrbc_core import interpolation
from rrbc_core.correction.rrbc import correct_points
from rrbc_core.errors import InputError
from rrbc_core.runtime.threads import thread_limited
from rrbc_core.session.evaluation import Evaluation, Group, Readings, Settings, evaluate
from rrbc_core.session.results import HeatMap, MonteCarloPlots, PlanningState, _scaled
from rrbc_core.simulation.measurement import MeasurementModel

#: Seed of the planner's region samples (coverage, predicted RMST, suggestions): fixed, so the tab's numbers,
#: a suggestion's "after" and the numbers after accepting it are the same computation.
PLANNING_SEED = 0


def _seed_for(seed: int, pid: str) -> list[int]:
    return [int(seed) & 0x7FFFFFFF, zlib.crc32(pid.encode("utf-8"))]


class ExplorerSession:
    """The interactive session behind the browser app: a layout of points, the settings, and everything shown.

    Make one with `from_scene(scene)` (points measured through the scene's measurement model wherever they are
    moved) or `from_measurements(mset)` (readings as measured). Every method that changes it (`move`, `update`,
    `set_excluded`, `accept_suggestions`) returns the new `Evaluation` and leaves the session unchanged when it
    raises `InputError`. Views: `evaluate()` / `last`, `heat_map()`, `planning_state()`, `suggest_fiducials()`,
    `monte_carlo()`, `export_measurements()`, `export_json()`. Positions are robot frame, mm.
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
        self.suggestion = None  # the last planning.PlanResult from suggest_fiducials (None: none pending)
        self._suggestion_key = None  # planning key of the layout the suggestion was made for
        self.accepted: tuple = ()  # ids of fiducials added by accept_suggestions, in order

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
    def from_measurements(cls, mset, mesh_path=None, settings: Settings | None = None) -> ExplorerSession:
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

    def _measure_scene(self, kind: str, ids, positions, noise: bool = True) -> Readings:
        """Scene mode: readings of points at `positions` (robot frame) through the measurement model, the noise of
        each point drawn from a generator seeded by (seed, kind, id) (noise=False: the expected readings, bias
        only)."""
        from rrbc_core.simulation.errormodels import PointSet
        from rrbc_core.simulation.kinematics import tool_down

        model = self.measurement_model()
        positions = np.asarray(positions, float).reshape(-1, 3)
        n = len(positions)
        pts = model.points(positions, np.array([tool_down(self.scene.tool_yaw_deg)] * n).reshape(n, 3, 3))
        noise_s, noise_r = np.zeros((1, n, 3)), np.zeros((1, n, 3))
        rnd = model.error_model.random_terms()
        if noise and (rnd.robot or rnd.sensor):
            for i, pid in enumerate(ids):
                one = PointSet(
                    robot=positions[i : i + 1],
                    sensor=pts.sensor[i : i + 1],
                    time=np.zeros(1),
                    tool_rotation=pts.tool_rotation[i : i + 1],
                    joint_seed=pts.joint_seed,
                )
                rng = np.random.default_rng(_seed_for(self.settings.seed, f"{kind}:{pid}"))
                e_s, e_r = model.noise(one, rng, 1)
                noise_s[0, i], noise_r[0, i] = e_s[0, 0], e_r[0, 0]
        r = model.read(pts, noise=(noise_s, noise_r))
        return Readings(r.sensor[0], r.robot[0], r.truth)

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
        for i, pid in enumerate(g.ids):
            key = (kind, pid)
            cached = self._readings.get(key)
            if cached is None or cached[0] != (key_settings, tuple(g.positions[i])):
                missing.append(i)
        if missing:
            fresh = self._measure_scene(kind, [g.ids[i] for i in missing], g.positions[missing])
            for j, i in enumerate(missing):
                self._readings[(kind, g.ids[i])] = (
                    (key_settings, tuple(g.positions[i])),
                    fresh.sensor[j],
                    fresh.robot[j],
                    fresh.truth[j],
                )
        for pid in g.ids:
            _, a, b, c = self._readings[(kind, pid)]
            out_s.append(a), out_r.append(b), out_t.append(c)
        n = len(g.ids)
        return Readings(np.array(out_s).reshape(n, 3), np.array(out_r).reshape(n, 3), np.array(out_t).reshape(n, 3))

    # -------------------------------------------------------------------------------------------- editing
    @thread_limited
    def move(self, kind: str, pid: str, position) -> Evaluation:
        """Move a point (robot frame, mm) and re-evaluate. kind: registration, fiducials or targets."""
        if kind not in self.layout:
            raise InputError(f"unknown point kind '{kind}': registration, fiducials or targets")
        p = np.asarray(position, float).reshape(3)
        if not np.all(np.isfinite(p)):
            raise InputError("a position must be 3 finite numbers (mm)")
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
            return self.evaluate()
        except InputError:  # e.g. out of the arm's reach: keep the last good layout
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
        new = dataclasses.replace(self.settings, **changes)
        if self.kind == "measurements" and (new.noise_scale != 1.0 or new.bias_scale != 1.0):
            raise InputError("noise and bias sizes apply to scenes; measured data are what they are")
        old = self.settings
        self.settings = new
        try:
            return self.evaluate()
        except InputError:
            self.settings = old
            raise

    # ----------------------------------------------------------------------------------------- evaluating
    @thread_limited
    def evaluate(self) -> Evaluation:
        """Measure what changed (scene mode) and run `evaluation.evaluate` on the layout as it is now."""
        readings = {kind: self._readings_for(kind) for kind in ("registration", "fiducials", "targets")}
        self._last = evaluate(self.settings, self.layout, readings, self._cached)
        return self._last

    def _cached(self, name: str, key, compute):
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

    # ---------------------------------------------------------------------------------------------- planning
    def _require_planning(self) -> None:
        if self.kind != "scene" or self.scene is None:
            raise InputError(
                "planning needs a scene (an error model and candidate fiducial locations); measured "
                "data have none: load a scene (File tab, or `rrbc view SCENE.toml`)"
            )

    def _planning_key(self) -> tuple:
        """What planning depends on: included fiducials, targets and registration points where they are now, and
        the noise/bias sizes."""
        s = self.settings
        fid = self.layout["fiducials"]
        inc = np.array([pid not in s.excluded for pid in fid.ids], dtype=bool)
        return (
            fid.positions[inc].tobytes(),
            self.layout["targets"].positions.tobytes(),
            self.layout["registration"].positions.tobytes(),
            float(s.noise_scale),
            float(s.bias_scale),
        )

    def planning_fiducials(self) -> tuple[tuple, np.ndarray]:
        """(ids, (N,3) robot-frame positions) of the included fiducials where they are now."""
        fid = self.layout["fiducials"]
        inc = [i for i, pid in enumerate(fid.ids) if pid not in self.settings.excluded]
        return tuple(fid.ids[i] for i in inc), fid.positions[inc].reshape(-1, 3)

    def planning_regions(self) -> tuple[tuple, list]:
        """(target ids, their regions of variability centred where each target is now)."""
        tg = self.layout["targets"]
        ids, regions = [], []
        for pid, p in zip(tg.ids, tg.positions):
            region = self.regions.get(pid)
            if region is not None:
                ids.append(pid)
                regions.append(dataclasses.replace(region, center=np.asarray(p, float)))
        return tuple(ids), regions

    def planning_scene(self):
        """The scene as the session has it now: fiducials = the included ones at their current positions,
        targets (and their regions) where they are now, the error model with the noise/bias sizes applied."""
        from rrbc_core.io.scene import NamedPoints, Target

        self._require_planning()
        sc = self.scene
        key = ("planning_scene",) + self._planning_key()

        def build():
            ids, pos = self.planning_fiducials()
            t_ids, regions = self.planning_regions()
            by_id = dict(zip(t_ids, regions))
            tg = self.layout["targets"]
            yaw = {t.id: t.tool_yaw_deg for t in sc.targets}
            targets = tuple(
                Target(pid, np.asarray(p, float), by_id[pid], yaw.get(pid, sc.tool_yaw_deg))
                for pid, p in zip(tg.ids, tg.positions)
                if pid in by_id
            )
            s = self.settings
            reg = self.layout["registration"]
            return dataclasses.replace(
                sc,
                fiducials=NamedPoints(ids, pos, np.full(len(ids), sc.tool_yaw_deg)),
                registration=NamedPoints(reg.ids, reg.positions, np.full(len(reg.ids), sc.tool_yaw_deg)),
                targets=targets,
                error_model=_scaled(sc.error_model, s.noise_scale, s.bias_scale),
            )

        return self._cached("planning_scene", key, build)

    @thread_limited
    def planning_state(self) -> PlanningState:
        """Coverage per target and the fast predicted RMST (rigid and RRBC, with their std) for the fiducials as
        they are now (dragged, excluded or accepted ones included as the session has them). Cached: a call with
        nothing changed returns the same object. InputError in measurement mode."""
        from rrbc_core.analysis import planning

        self._require_planning()
        key = self._planning_key()

        def compute():
            scene = self.planning_scene()
            ids, fids = self.planning_fiducials()
            t_ids, regions = self.planning_regions()
            cov = planning.coverage(fids, regions, seed=PLANNING_SEED) if regions else np.zeros(0)
            pred = planning.predict_rmst(
                scene, fids, registration_mm=self.layout["registration"].positions, seed=PLANNING_SEED
            )
            return PlanningState(t_ids, np.asarray(cov, float).reshape(-1), pred, len(ids))

        return self._cached("planning_state", key, compute)

    @thread_limited
    def suggest_fiducials(self, k: int, seed: int | None = None, progress=None):
        """Ask the planner for `k` more fiducials from the scene's candidates, given the included fiducials as
        they are now; keeps the result as `suggestion` and returns it (a planning.PlanResult). seed: the
        planner's (default PLANNING_SEED, the seed of `planning_state`, so its "before" is the tab's numbers)."""
        from rrbc_core.analysis import planning

        self._require_planning()
        try:
            k = int(k)
        except (TypeError, ValueError):
            raise InputError(f"the number of fiducials to add must be a whole number, got {k!r}") from None
        if k < 1:
            raise InputError(f"the number of fiducials to add must be at least 1, got {k}")
        key = self._planning_key()
        scene = self.planning_scene()
        _, fids = self.planning_fiducials()
        result = planning.plan(
            scene, add=k, fiducials_mm=fids, seed=PLANNING_SEED if seed is None else int(seed), progress=progress
        )
        self.suggestion, self._suggestion_key = result, key
        return result

    @property
    def suggestion_current(self) -> bool:
        """Whether the pending suggestion was made for the fiducials and targets as they are now."""
        return self.suggestion is not None and self._suggestion_key == self._planning_key()

    def adopt_suggestion(self, snapshot: ExplorerSession) -> None:
        """Take the pending suggestion that `snapshot` (a `copy.copy` of this session, planned outside the app's lock)
        computed, with the layout it was made for (`suggestion_current` says whether that is still this one's)."""
        self.suggestion, self._suggestion_key = snapshot.suggestion, snapshot._suggestion_key

    def clear_suggestion(self) -> None:
        self.suggestion, self._suggestion_key = None, None

    @thread_limited
    def accept_suggestions(self, which=None) -> Evaluation:
        """Add fiducials and re-evaluate. `which`: None = every fiducial of the pending suggestion; a list of
        candidate ids (of the scene's candidates); or (K,3) robot-frame positions (mm). New fiducials get the
        candidate's id (or P1, P2, … for bare positions; a suffix if taken), are included, and are measured from
        the error model with noise seeded by their id. Refused with InputError (session unchanged) if there is
        nothing to add or a point is not usable."""
        self._require_planning()
        ids, pos = self._new_fiducials(which)
        fid = self.layout["fiducials"]
        taken = set(fid.ids) | set(self.layout["registration"].ids) | set(self.layout["targets"].ids)
        new_ids = []
        for pid in ids:
            base, n, name = pid, 1, pid
            while name in taken:
                n += 1
                name = f"{base}-{n}"
            taken.add(name)
            new_ids.append(name)
        old_layout, old_settings = self.layout, self.settings
        self.layout = {**self.layout, "fiducials": Group(fid.ids + tuple(new_ids), np.vstack([fid.positions, pos]))}
        self.settings = dataclasses.replace(self.settings, excluded=self.settings.excluded - set(new_ids))
        try:
            ev = self.evaluate()
        except InputError:
            self.layout, self.settings = old_layout, old_settings
            raise
        self.clear_suggestion()
        self.accepted = self.accepted + tuple(new_ids)
        return ev

    def _new_fiducials(self, which) -> tuple[list, np.ndarray]:
        cands = self.scene.candidates
        if which is None:
            if self.suggestion is None:
                raise InputError("no suggestion to accept: press Suggest first")
            sug = self.suggestion
            ids = [str(x) for x in sug.suggested_ids]
            pos = np.asarray(sug.suggested, float).reshape(-1, 3)
            if len(ids) != len(pos):
                ids = [f"P{i + 1}" for i in range(len(pos))]
        else:
            arr = np.asarray(which, dtype=object)
            if arr.size and all(isinstance(x, str) for x in arr.reshape(-1)):
                ids = [str(x) for x in arr.reshape(-1)]
                unknown = [x for x in ids if x not in cands.ids]
                if unknown:
                    raise InputError(f"not a candidate location of this scene: {', '.join(unknown[:5])}")
                pos = np.array([cands.position(x) for x in ids], float).reshape(-1, 3)
            else:
                try:
                    pos = np.asarray(which, float).reshape(-1, 3)
                except (TypeError, ValueError):
                    raise InputError("fiducials to add: candidate ids or (K,3) positions in mm") from None
                ids = [f"P{i + 1}" for i in range(len(pos))]
        if not len(pos):
            raise InputError("nothing to add: the suggestion is empty")
        if not np.all(np.isfinite(pos)):
            raise InputError("a fiducial position must be 3 finite numbers (mm)")
        return ids, pos

    # ---------------------------------------------------------------------------------------------- heat map
    @thread_limited
    def heat_map(self, samples_per_target: int = 200) -> HeatMap:
        """Predicted error over the targets' regions of variability (scene mode): samples (seeded, fixed per
        target id) inside each region, each measured noise-free (expected sensor reading incl. sensor bias) and
        corrected with the current fiducials; errors against the truth, rigid and RRBC. In measurement mode
        (no truth) samples around each target report the interpolated correction's size and, for gp, its
        standard deviation instead (error fields NaN)."""
        ev = self.last
        s = self.settings
        tg = self.layout["targets"]
        stacked_key = (tg.ids, tg.positions.tobytes(), s.bias_scale, samples_per_target, s.seed, self.kind)
        stacked = self._heat_cache.get(None)
        if stacked is not None and stacked[0] == stacked_key and self.kind == "scene":
            _, pos, owner, sensor, truth = stacked  # no target moved: only the correction changes
            return self._heat_values(ev, pos, owner, sensor, truth)
        pos, owner, sens, truth = [], [], [], []
        for i, pid in enumerate(tg.ids):
            key = (tuple(tg.positions[i]), s.bias_scale, samples_per_target, s.seed)
            cached = self._heat_cache.get(pid)
            if cached is None or cached[0] != key:
                region = self.regions.get(pid)
                rng = np.random.default_rng(_seed_for(0, f"heat:{pid}"))
                if region is not None:
                    local = region.sample(rng, samples_per_target) - region.center
                else:
                    local = rng.normal(0.0, 5.0, (samples_per_target, 3))
                p = tg.positions[i] + local
                if self.kind == "scene":
                    r = self._measure_scene("heat", [f"{pid}.{k}" for k in range(len(p))], p, noise=False)
                    cached = (key, p, r.sensor, r.truth)
                else:
                    cached = (key, p, None, np.full_like(p, np.nan))
                self._heat_cache[pid] = cached
            _, p, sensor_i, truth_i = cached
            if sensor_i is None:  # measurement mode: the sample's sensor position under the current registration
                sensor_i = ev.registration.mapping.apply_inverse(p)
            pos.append(p), sens.append(sensor_i), truth.append(truth_i)
            owner += [pid] * len(p)
        pos = np.vstack(pos) if pos else np.zeros((0, 3))
        sensor = np.vstack(sens) if sens else np.zeros((0, 3))
        truth = np.vstack(truth) if truth else np.zeros((0, 3))
        owner = tuple(owner)
        self._heat_cache[None] = (stacked_key, pos, owner, sensor, truth)
        return self._heat_values(ev, pos, owner, sensor, truth)

    def _heat_values(self, ev: Evaluation, pos, owner, sensor, truth) -> HeatMap:
        """The heat map's values at samples pos (S,3) robot frame with their sensor readings and truth."""
        fitted = self._fitted(ev)
        cp = correct_points(ev.registration.mapping, fitted, sensor)
        e_rigid = np.linalg.norm(cp.robot_rigid - truth, axis=1)
        e_rrbc = np.linalg.norm(cp.robot_rrbc - truth, axis=1)
        std = None if cp.correction_std is None else np.linalg.norm(cp.correction_std, axis=1)
        return HeatMap(pos, owner, e_rigid, e_rrbc, np.linalg.norm(cp.correction, axis=1), std, cp.extrapolated)

    def _fitted(self, ev: Evaluation):
        inc = ev.included
        if np.any(inc):
            key = (
                self.settings.interpolator(),
                ev.fiducial_readings.sensor[inc].tobytes(),
                ev.corrections[inc].tobytes(),
            )
            return self._cached(
                "fitted",
                key,
                lambda: self.settings.interpolator().fit(ev.fiducial_readings.sensor[inc], ev.corrections[inc]),
            )
        return interpolation.NoCorrection().fit(
            ev.registration_readings.sensor, np.zeros_like(ev.registration_readings.sensor)
        )

    # ----------------------------------------------------------------------------------------- Monte Carlo
    @thread_limited
    def monte_carlo(self, trials: int = 200, checks_per_target: int = 10, seed: int | None = None) -> MonteCarloPlots:
        """Scene mode: Monte Carlo of the current layout and settings (noise redrawn, bias fixed, both scaled);
        errors at check points sampled in the targets' regions, rigid vs RRBC, and their distance from the
        scene's distance origin. Uses the current registration strategy and interpolation."""
        from rrbc_core.simulation.montecarlo import WorkCell, measure, trial_errors

        if self.kind != "scene":
            raise InputError("Monte Carlo needs a scene (an error model); measured data have none")
        from rrbc_core.simulation.kinematics import tool_down

        s = self.settings
        sc = self.scene
        rng = np.random.default_rng(s.seed if seed is None else seed)
        ids, roles, pos = [], [], []
        reg_ids = set(self.layout["registration"].ids)
        fid = self.layout["fiducials"]
        for pid, p in zip(self.layout["registration"].ids, self.layout["registration"].positions):
            both = pid in fid.ids and pid not in s.excluded
            ids.append(pid), roles.append("both" if both else "registration"), pos.append(p)
        for pid, p in zip(fid.ids, fid.positions):
            if pid not in reg_ids and pid not in s.excluded:
                ids.append(pid), roles.append("fiducial"), pos.append(p)
        for pid, p in zip(self.layout["targets"].ids, self.layout["targets"].positions):
            region = self.regions.get(pid)
            for k in range(checks_per_target):
                q = p if region is None else p + region.sample(rng, 1)[0] - region.center
                ids.append(f"{pid}.c{k}"), roles.append("check"), pos.append(q)
        robot = np.array(pos, float).reshape(-1, 3)
        cell = WorkCell(
            name=sc.name,
            sensor_to_robot=sc.sensor_to_robot,
            ids=tuple(ids),
            roles=tuple(roles),
            robot=robot,
            time=np.arange(len(ids)) * float(sc.measurement_interval_s),
            tool_rotation=np.broadcast_to(tool_down(sc.tool_yaw_deg), (len(ids), 3, 3)).copy(),
            error_model=_scaled(sc.error_model, s.noise_scale, s.bias_scale),
            joint_seed=sc.joint_seed,
            distance_origin=np.asarray(sc.distance_origin, float),
        )
        m = measure(cell, rng, trials)
        opts = s.method.interpolation_kwargs()
        e = trial_errors(cell, m, s.registration, s.interpolation, seeds=rng.integers(0, 2**31 - 1, trials), **opts)
        chk = cell.index("check")
        dist = np.linalg.norm(cell.robot[chk] - cell.distance_origin, axis=1)
        return MonteCarloPlots(e.rigid, e.rrbc, dist, trials)

    # -------------------------------------------------------------------------------------------- exporting
    def export_measurements(self):
        """The current data as a MeasurementSet (scene mode: targets become `check` rows with their truth, so
        `rrbc correct` on the export reproduces the app's numbers)."""
        from rrbc_core.io.measurements import MeasurementSet

        ev = self.last
        ids, roles, sensor, robot = [], [], [], []
        fid_ids = set(ev.fiducial_ids)
        for i, pid in enumerate(ev.registration_ids):
            both = pid in fid_ids and pid not in self.settings.excluded
            ids.append(pid), roles.append("both" if both else "registration")
            sensor.append(ev.registration_readings.sensor[i]), robot.append(ev.registration_readings.robot[i])
        reg_ids = set(ev.registration_ids)
        for i, pid in enumerate(ev.fiducial_ids):
            if pid in reg_ids or not ev.included[i]:
                continue
            ids.append(pid), roles.append("fiducial")
            sensor.append(ev.fiducial_readings.sensor[i]), robot.append(ev.fiducial_readings.robot[i])
        t = ev.targets
        for i, pid in enumerate(t.ids):
            known = np.all(np.isfinite(t.truth[i]))
            ids.append(pid), roles.append("check" if known else "target")
            sensor.append(t.sensor[i]), robot.append(t.truth[i] if known else np.full(3, np.nan))
        n = len(ids)
        return MeasurementSet(
            ids=tuple(ids),
            roles=tuple(roles),
            sensor=np.array(sensor).reshape(n, 3),
            robot=np.array(robot).reshape(n, 3),
            time=np.full(n, np.nan),
            lines=tuple(0 for _ in ids),
            source=f"<{self.name}>",
        )

    @thread_limited
    def export_json(self) -> dict:
        """Results as `rrbc correct --json` would give them for `export_measurements()`, plus the settings."""
        from rrbc_core.correction.pipeline import correct_measurements

        s = self.settings
        opts = s.method
        out = correct_measurements(self.export_measurements(), opts).to_json()
        out["settings"] = {**dataclasses.asdict(s), "excluded": sorted(s.excluded)}
        out["source"] = {"kind": self.kind, "name": self.name}
        return out
