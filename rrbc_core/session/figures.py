"""The session's views besides its evaluation: the heat map over the targets' regions, the Monte Carlo plots, and
the exports (a measurement file, the JSON of `rrbc correct`, its corrected targets and checks, the acceptance report
of `rrbc report`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from rrbc_core import interpolation
from rrbc_core.correction.bounds import bound_points
from rrbc_core.correction.rrbc import correct_points
from rrbc_core.errors import Cancelled, InputError
from rrbc_core.models.measurement import point_seed
from rrbc_core.runtime.threads import thread_limited
from rrbc_core.session.data_set import session_data
from rrbc_core.session.evaluation import Evaluation
from rrbc_core.session.results import HeatMap, MonteCarloPlots, _scaled
from rrbc_core.session.slices import VALUES as SLICE_VALUES
from rrbc_core.session.slices import ErrorSlice, SlicePlane

if TYPE_CHECKING:
    from rrbc_core.session.explorer import ExplorerSession

SESSION_TRIALS_MAX = 5000  # the app's background Monte Carlo (issue 16: bounded, whatever a client sends)
MC_CHUNK_TRIALS = 50  # trials between two questions "still wanted?" of the app's Monte Carlo


# ---------------------------------------------------------------------------------------------- heat map
@thread_limited
def heat_map(session: ExplorerSession, samples_per_target: int = 200) -> HeatMap:
    """Predicted error over the targets' regions of variability (scene mode): samples (seeded, fixed per
    target id) inside each region, each measured noise-free (expected sensor reading incl. sensor bias) and
    corrected with the current fiducials; errors against the truth, rigid and RRBC. In measurement mode
    (no truth) samples around each target report the interpolated correction's size and, for gp, its
    standard deviation instead (error fields NaN)."""
    ev = session.last
    s = session.settings
    tg = session.layout["targets"]
    stacked_key = (tg.ids, tg.positions.tobytes(), s.bias_scale, samples_per_target, s.seed, session.kind)
    stacked = session._heat_cache.get(None)
    if stacked is not None and stacked[0] == stacked_key and session.kind == "scene":
        _, pos, owner, sensor, truth = stacked  # no target moved: only the correction changes
        return _heat_values(session, ev, pos, owner, sensor, truth)
    pos, owner, sens, truth = [], [], [], []
    for i, pid in enumerate(tg.ids):
        key = (tuple(tg.positions[i]), s.bias_scale, samples_per_target, s.seed)
        cached = session._heat_cache.get(pid)
        if cached is None or cached[0] != key:
            region = session.regions.get(pid)
            rng = np.random.default_rng(point_seed(0, f"heat:{pid}"))
            if region is not None:
                local = region.sample(rng, samples_per_target) - region.center
            else:
                local = rng.normal(0.0, 5.0, (samples_per_target, 3))
            p = tg.positions[i] + local
            if session.kind == "scene":
                r = session.measure_points("heat", [f"{pid}.{k}" for k in range(len(p))], p, noise=False)
                cached = (key, p, r.sensor, r.truth)
            else:
                cached = (key, p, None, np.full_like(p, np.nan))
            session._heat_cache[pid] = cached
        _, p, sensor_i, truth_i = cached
        if sensor_i is None:  # measurement mode: the sample's sensor position under the current registration
            sensor_i = ev.registration.mapping.apply_inverse(p)
        pos.append(p)
        sens.append(sensor_i)
        truth.append(truth_i)
        owner += [pid] * len(p)
    pos = np.vstack(pos) if pos else np.zeros((0, 3))
    sensor = np.vstack(sens) if sens else np.zeros((0, 3))
    truth = np.vstack(truth) if truth else np.zeros((0, 3))
    owner = tuple(owner)
    session._heat_cache[None] = (stacked_key, pos, owner, sensor, truth)
    return _heat_values(session, ev, pos, owner, sensor, truth)


# ------------------------------------------------------------------------------------------- error slice
@thread_limited
def error_slice(session: ExplorerSession, plane: SlicePlane, bound: bool = True) -> ErrorSlice:
    """Predicted error over a plane through the work volume (`slices`): every grid point measured noise-free
    (scene mode: expected sensor reading with the scene's bias; cached per plane and bias size, so a drag only
    re-corrects) and corrected with the current fiducials. Unreachable grid points and unknown values are NaN.
    Values (n, n) mm: rigid and RRBC error against the truth, the 95 % bound a target there would get (RRBC's, or
    rigid's without interpolation; `correction.bounds`, as `rrbc correct` and the targets' bounds), |ê|, and gp's std
    of ê. `bound`: False leaves the bound NaN (it costs about 9 ms a 48 x 48 plane; the app asks for it only
    while the slice shows it)."""
    from rrbc_core.models.kinematics import tool_down

    ev = session.last
    grid = plane.grid().reshape(-1, 3)
    key = (plane.key(), session.settings.bias_scale, session.kind)
    cached = session._heat_cache.get(("slice",))
    if cached is None or cached[0] != key:
        if session.kind == "scene":
            model = session.measurement_model()
            rot = np.array([tool_down(session.scene.tool_yaw_deg)] * len(grid))
            ok = model.reachable(model.points(grid, rot))
            sensor = np.full_like(grid, np.nan)
            truth = np.full_like(grid, np.nan)
            if np.any(ok):
                r = session.measure_points("slice", [str(i) for i in np.flatnonzero(ok)], grid[ok], noise=False)
                sensor[ok], truth[ok] = r.sensor, r.truth
        else:
            ok = np.ones(len(grid), bool)
            sensor, truth = None, np.full_like(grid, np.nan)
        cached = (key, ok, sensor, truth)
        session._heat_cache[("slice",)] = cached
    _, ok, sensor, truth = cached
    if sensor is None:  # measured data: the grid point's sensor position under the current registration
        sensor = ev.registration.mapping.apply_inverse(grid)
    values = {name: np.full(len(grid), np.nan) for name in SLICE_VALUES}
    inside = np.zeros(len(grid), bool)
    if np.any(ok):
        hm = _heat_values(session, ev, grid[ok], ("slice",) * int(ok.sum()), sensor[ok], truth[ok])
        values["rigid"][ok], values["rrbc"][ok] = hm.error_rigid, hm.error_rrbc
        values["correction"][ok] = hm.correction_mm
        if hm.std_mm is not None:
            values["std"][ok] = hm.std_mm
        inside[ok] = ~np.asarray(hm.extrapolated, bool)
        if bound and ev.bounds is not None and ev.bounds.basis is not None:  # what `rrbc correct` would bound there
            b = bound_points(
                ev.bounds.basis,
                {"targets": (sensor[ok], np.ones(int(ok.sum())), np.asarray(hm.off_plane_mm, float))},
            ).targets
            if b is not None:
                values["bound95"][ok] = b.bound95_mm
    n = plane.n
    return ErrorSlice(
        plane, grid.reshape(n, n, 3), {k: v.reshape(n, n) for k, v in values.items()}, inside.reshape(n, n)
    )


def _heat_values(session: ExplorerSession, ev: Evaluation, pos, owner, sensor, truth) -> HeatMap:
    """The heat map's values at samples pos (S,3) robot frame with their sensor readings and truth."""
    fitted = _fitted(session, ev)
    cp = correct_points(ev.registration.mapping, fitted, sensor)
    e_rigid = np.linalg.norm(cp.robot_rigid - truth, axis=1)
    e_rrbc = np.linalg.norm(cp.robot_rrbc - truth, axis=1)
    std = None if cp.correction_std is None else np.linalg.norm(cp.correction_std, axis=1)
    return HeatMap(
        pos, owner, e_rigid, e_rrbc, np.linalg.norm(cp.correction, axis=1), std, cp.extrapolated, cp.off_plane_mm
    )


def _fitted(session: ExplorerSession, ev: Evaluation):
    inc = ev.included
    if np.any(inc):
        key = (
            session.settings.interpolator(),
            ev.fiducial_readings.sensor[inc].tobytes(),
            ev.corrections[inc].tobytes(),
        )
        return session.cached(
            "fitted",
            key,
            lambda: session.settings.interpolator().fit(ev.fiducial_readings.sensor[inc], ev.corrections[inc]),
        )
    return interpolation.NoCorrection().fit(
        ev.registration_readings.sensor, np.zeros_like(ev.registration_readings.sensor)
    )


# ----------------------------------------------------------------------------------------- Monte Carlo
@thread_limited
def monte_carlo(
    session,
    trials: int = 200,
    checks_per_target: int = 10,
    seed: int | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> MonteCarloPlots:
    """Scene mode: Monte Carlo of the current layout and settings (noise redrawn, bias fixed, both scaled);
    errors at check points sampled in the targets' regions, rigid vs RRBC, and their distance from the
    scene's distance origin. Uses the current registration strategy and interpolation.

    The trials run in chunks of `MC_CHUNK_TRIALS` (the same numbers as one batch: the noise and the trials'
    seeds are drawn first); `should_stop`, when given, is asked before each chunk and a True answer raises
    `errors.Cancelled` — how the app stops a run that the user stopped or a newer request superseded."""
    from rrbc_core.simulation.montecarlo import Measured, WorkCell, measure, trial_errors

    if session.kind != "scene":
        raise InputError("Monte Carlo needs a scene (an error model); measured data have none")
    if not (1 <= int(trials) <= SESSION_TRIALS_MAX and 1 <= int(checks_per_target) <= 100):
        raise InputError(
            f"the app's Monte Carlo takes 1 to {SESSION_TRIALS_MAX} trials and 1 to 100 check points per target, "
            f"got {trials} and {checks_per_target} (larger studies: rrbc simulate)"
        )
    from rrbc_core.models.kinematics import tool_down

    s = session.settings
    sc = session.scene
    rng = np.random.default_rng(s.seed if seed is None else seed)
    ids, roles, pos = [], [], []
    reg_ids = set(session.layout["registration"].ids)
    fid = session.layout["fiducials"]
    for pid, p in zip(session.layout["registration"].ids, session.layout["registration"].positions):
        both = pid in fid.ids and pid not in s.excluded
        ids.append(pid)
        roles.append("both" if both else "registration")
        pos.append(p)
    for pid, p in zip(fid.ids, fid.positions):
        if pid not in reg_ids and pid not in s.excluded:
            ids.append(pid)
            roles.append("fiducial")
            pos.append(p)
    for pid, p in zip(session.layout["targets"].ids, session.layout["targets"].positions):
        region = session.regions.get(pid)
        for k in range(checks_per_target):
            q = p if region is None else p + region.sample(rng, 1)[0] - region.center
            ids.append(f"{pid}.c{k}")
            roles.append("check")
            pos.append(q)
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
    seeds = rng.integers(0, 2**31 - 1, trials)
    rigid, rrbc = [], []
    for a in range(0, trials, MC_CHUNK_TRIALS):
        if should_stop is not None and should_stop():
            raise Cancelled(f"Monte Carlo stopped after {a} of {trials} trials")
        b = min(trials, a + MC_CHUNK_TRIALS)
        part = Measured(m.sensor[a:b], m.robot[a:b], m.truth)
        e = trial_errors(cell, part, s.registration, s.interpolation, seeds=seeds[a:b], **opts)
        rigid.append(e.rigid)
        rrbc.append(e.rrbc)
    chk = cell.index("check")
    dist = np.linalg.norm(cell.robot[chk] - cell.distance_origin, axis=1)
    return MonteCarloPlots(np.concatenate(rigid), np.concatenate(rrbc), dist, trials)


# -------------------------------------------------------------------------------------------- exporting
def export_measurements(session: ExplorerSession):
    """The session's data set as a MeasurementSet (`data_set.session_data`): the file as opened (or as edited) in
    measurement mode, the simulated data set as `rrbc simulate --out` writes it in scene mode (targets as
    `target` rows, check points in their regions with their truth). `rrbc correct` and `rrbc diagnose` on it
    reproduce the app's numbers."""
    return session_data(session).measurements


@thread_limited
def export_json(session: ExplorerSession) -> dict:
    """Results as `rrbc correct --json` would give them for `export_measurements()`, plus the settings."""
    from rrbc_core.correction.pipeline import correct_measurements

    s = session.settings
    opts = s.method
    out = correct_measurements(export_measurements(session), opts).to_json()
    out["settings"] = s.to_json()
    out["source"] = {"kind": session.kind, "name": session.name}
    return out


@thread_limited
def export_corrected(session: ExplorerSession) -> str:
    """The corrected targets and checks as `rrbc correct FILE --out corrected.csv` writes them (`io.corrected_write`),
    for FILE = `export_measurements(session)` with the session's method (registration, interpolation, options)."""
    from rrbc_core.correction.stations import correct_stations
    from rrbc_core.io.corrected_write import corrected_csv

    return corrected_csv(correct_stations(export_measurements(session), session.settings.method).to_json())


def report_options(session: ExplorerSession):
    """The `MethodOptions` `rrbc report FILE --interpolation NAME` uses for the session's interpolation NAME: least
    squares and the method's default options (the command has no other flags)."""
    from rrbc_core.methods import MethodOptions

    return MethodOptions.named("least-squares", session.settings.interpolation)


@thread_limited
def export_report(mset, options, tolerance_mm: float | None = None) -> dict:
    """`rrbc report FILE --interpolation NAME [--tolerance T] --json` (`analysis.acceptance`) for a measurement set
    taken from the session (`export_measurements`) and `report_options(session)`; the file's tool as the command
    reads it. Taken as values so the app computes it outside its lock."""
    from rrbc_core.analysis.acceptance import acceptance
    from rrbc_core.io.joints import file_tool

    return acceptance(mset, tolerance_mm=tolerance_mm, options=options, tool=file_tool(mset))
