"""The session's planning (scene mode; thin wrappers over `rrbc_core.analysis.planning`): coverage and predicted RMST
for the fiducials as they are now, suggested fiducials, accepting them."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.runtime.threads import thread_limited
from rrbc_core.session import edits
from rrbc_core.session.evaluation import Evaluation, Group
from rrbc_core.session.results import PlanningState, _scaled

if TYPE_CHECKING:
    from rrbc_core.session.explorer import ExplorerSession

#: Seed of the planner's region samples (coverage, predicted RMST, suggestions): fixed, so the tab's numbers,
#: a suggestion's "after" and the numbers after accepting it are the same computation.
PLANNING_SEED = 0


# ---------------------------------------------------------------------------------------------- planning
def require_planning(session: ExplorerSession) -> None:
    if session.kind != "scene" or session.scene is None:
        raise InputError(
            "planning needs a scene (an error model and candidate fiducial locations); measured "
            "data have none: load a scene (File tab, or `rrbc view SCENE.toml`)"
        )


def planning_key(session: ExplorerSession) -> tuple:
    """What planning depends on: included fiducials, targets and registration points where they are now, and
    the noise/bias sizes."""
    s = session.settings
    fid = session.layout["fiducials"]
    inc = np.array([pid not in s.excluded for pid in fid.ids], dtype=bool)
    return (
        fid.positions[inc].tobytes(),
        session.layout["targets"].positions.tobytes(),
        session.layout["registration"].positions.tobytes(),
        float(s.noise_scale),
        float(s.bias_scale),
        session.layout["targets"].ids,
        session.candidates.ids,
        session.candidates.positions.tobytes(),
        np.asarray(session.sensor_to_robot.translation).tobytes() if session.sensor_to_robot is not None else b"",
        np.asarray(session.sensor_to_robot.rotation).tobytes() if session.sensor_to_robot is not None else b"",
    )


def planning_fiducials(session: ExplorerSession) -> tuple[tuple, np.ndarray]:
    """(ids, (N,3) robot-frame positions) of the included fiducials where they are now."""
    fid = session.layout["fiducials"]
    inc = [i for i, pid in enumerate(fid.ids) if pid not in session.settings.excluded]
    return tuple(fid.ids[i] for i in inc), fid.positions[inc].reshape(-1, 3)


def planning_regions(session: ExplorerSession) -> tuple[tuple, list]:
    """(target ids, their regions of variability centred where each target is now)."""
    tg = session.layout["targets"]
    ids, regions = [], []
    for pid, p in zip(tg.ids, tg.positions):
        region = session.regions.get(pid)
        if region is not None:
            ids.append(pid)
            regions.append(dataclasses.replace(region, center=np.asarray(p, float)))
    return tuple(ids), regions


def planning_scene(session: ExplorerSession):
    """The scene as the session has it now: fiducials = the included ones at their current positions,
    targets (and their regions) where they are now, the error model with the noise/bias sizes applied."""
    from rrbc_core.io.scene import NamedPoints, Target

    require_planning(session)
    sc = session.scene
    key = ("planning_scene",) + planning_key(session)

    def build():
        ids, pos = planning_fiducials(session)
        t_ids, regions = planning_regions(session)
        by_id = dict(zip(t_ids, regions))
        tg = session.layout["targets"]
        yaw = {t.id: t.tool_yaw_deg for t in sc.targets}
        targets = tuple(
            Target(pid, np.asarray(p, float), by_id[pid], yaw.get(pid, sc.tool_yaw_deg))
            for pid, p in zip(tg.ids, tg.positions)
            if pid in by_id
        )
        s = session.settings
        reg = session.layout["registration"]
        return dataclasses.replace(
            sc,
            fiducials=NamedPoints(ids, pos, np.full(len(ids), sc.tool_yaw_deg)),
            registration=NamedPoints(reg.ids, reg.positions, np.full(len(reg.ids), sc.tool_yaw_deg)),
            targets=targets,
            candidates=NamedPoints(
                session.candidates.ids,
                session.candidates.positions,
                np.full(len(session.candidates.ids), sc.tool_yaw_deg),
            ),
            sensor_to_robot=session.sensor_to_robot,
            error_model=_scaled(sc.error_model, s.noise_scale, s.bias_scale),
        )

    return session.cached("planning_scene", key, build)


@thread_limited
def planning_state(session: ExplorerSession) -> PlanningState:
    """Coverage per target and the fast predicted RMST (rigid and RRBC, with their std) for the fiducials as
    they are now (dragged, excluded or accepted ones included as the session has them). Cached: a call with
    nothing changed returns the same object. InputError in measurement mode."""
    from rrbc_core.analysis import planning

    require_planning(session)
    key = planning_key(session)

    def compute():
        scene = planning_scene(session)
        ids, fids = planning_fiducials(session)
        t_ids, regions = planning_regions(session)
        cov = planning.coverage(fids, regions, seed=PLANNING_SEED) if regions else np.zeros(0)
        pred = planning.predict_rmst(
            scene, fids, registration_mm=session.layout["registration"].positions, seed=PLANNING_SEED
        )
        return PlanningState(t_ids, np.asarray(cov, float).reshape(-1), pred, len(ids))

    return session.cached("planning_state", key, compute)


@thread_limited
def suggest_fiducials(session: ExplorerSession, k: int, seed: int | None = None, progress=None):
    """Ask the planner for `k` more fiducials from the scene's candidates, given the included fiducials as
    they are now; keeps the result as `suggestion` and returns it (a planning.PlanResult). seed: the
    planner's (default PLANNING_SEED, the seed of `planning_state`, so its "before" is the tab's numbers)."""
    from rrbc_core.analysis import planning

    require_planning(session)
    try:
        k = int(k)
    except (TypeError, ValueError):
        raise InputError(f"the number of fiducials to add must be a whole number, got {k!r}") from None
    if k < 1:
        raise InputError(f"the number of fiducials to add must be at least 1, got {k}")
    key = planning_key(session)
    scene = planning_scene(session)
    _, fids = planning_fiducials(session)
    result = planning.plan(
        scene, add=k, fiducials_mm=fids, seed=PLANNING_SEED if seed is None else int(seed), progress=progress
    )
    session.suggestion, session._suggestion_key = result, key
    return result


def suggestion_current(session: ExplorerSession) -> bool:
    """Whether the pending suggestion was made for the fiducials and targets as they are now."""
    return session.suggestion is not None and session._suggestion_key == planning_key(session)


def adopt_suggestion(session: ExplorerSession, snapshot: ExplorerSession) -> None:
    """Take the pending suggestion that `snapshot` (a `copy.copy` of this session, planned outside the app's lock)
    computed, with the layout it was made for (`suggestion_current` says whether that is still this one's)."""
    session.suggestion, session._suggestion_key = snapshot.suggestion, snapshot._suggestion_key


def clear_suggestion(session: ExplorerSession) -> None:
    session.suggestion, session._suggestion_key = None, None


@thread_limited
def accept_suggestions(session: ExplorerSession, which=None) -> Evaluation:
    """Add fiducials and re-evaluate. `which`: None = every fiducial of the pending suggestion; a list of
    candidate ids (of the scene's candidates); or (K,3) robot-frame positions (mm). New fiducials get the
    candidate's id (or P1, P2, … for bare positions; a suffix if taken), are included, and are measured from
    the error model with noise seeded by their id. One step of the edit history (`undo` removes them). Refused
    with InputError (session unchanged) if there is nothing to add or a point is not usable."""
    require_planning(session)
    ids, pos = _new_fiducials(session, which)
    fid = session.layout["fiducials"]
    taken = set(fid.ids) | set(session.layout["registration"].ids) | set(session.layout["targets"].ids)
    new_ids = []
    for pid in ids:
        base, n, name = pid, 1, pid
        while name in taken:
            n += 1
            name = f"{base}-{n}"
        taken.add(name)
        new_ids.append(name)
    old_settings = session.settings

    def change():
        session.layout = {
            **session.layout,
            "fiducials": Group(fid.ids + tuple(new_ids), np.vstack([fid.positions, pos])),
        }
        session.settings = session.settings.replace(excluded=session.settings.excluded - set(new_ids))

    try:
        ev = edits.edit(session, change)  # one step of the edit history: `undo` takes the accepted fiducials away again
    except InputError:
        session.settings = old_settings
        raise
    clear_suggestion(session)
    session.accepted = session.accepted + tuple(new_ids)
    return ev


def _new_fiducials(session: ExplorerSession, which) -> tuple[list, np.ndarray]:
    cands = session.candidates  # the session's (authoring may have added or deleted some)
    if which is None:
        if session.suggestion is None:
            raise InputError("no suggestion to accept: press Suggest first")
        sug = session.suggestion
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
            pos = np.array([cands.positions[cands.index(x)] for x in ids], float).reshape(-1, 3)
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


def coverage_plan(session: ExplorerSession, k: int = 0, seed: int = 0):
    """Coverage of each target's region (a DEFAULT_REGION_MM cube: measured targets carry none) by the included
    fiducials, and `k` suggested places to measure more fiducials (0: coverage only). Candidates: the cell
    mesh's upward surfaces around the targets seen from the sensor (when the data came with a mesh), else a
    grid in free space around them. Returns a planning_coverage.CoveragePlan."""
    from rrbc_core.analysis import planning_coverage as pc
    from rrbc_core.analysis.planning import coverage

    if session.kind != "measurements":
        raise InputError("coverage planning is for measured data; a scene plans with its error model (Suggest)")
    ev = session.last
    tg = session.layout["targets"]
    regions = pc.cube_regions(tg.positions)
    fids = ev.fiducial_positions[ev.included]
    cov = (
        coverage(fids, regions, samples_per_region=pc.COVERAGE_SAMPLES, seed=seed)
        if len(fids) >= 4
        else np.zeros(len(regions))
    )
    if not k:
        return pc.CoveragePlan(tg.ids, cov, (), np.zeros((0, 3)), cov, "", 0)
    cands, source = _coverage_candidates(session, tg.positions, ev, seed)
    idx, after = pc.suggest_by_coverage(fids, regions, cands, k, seed)
    return pc.CoveragePlan(
        tg.ids, cov, tuple(f"M{i + 1}" for i in range(len(idx))), cands[idx], after, source, len(cands)
    )


def _coverage_candidates(session: ExplorerSession, targets, ev, seed: int):
    from rrbc_core.analysis import planning_coverage as pc
    from rrbc_core.authoring import cell_geometry as cg

    if session.mesh_path:
        mesh = cg.load_cell_mesh(session.mesh_path)
        sensor = np.asarray(ev.registration.mapping.translation, float)  # the sensor's origin, robot frame
        pts = cg.marker_candidates(mesh, targets, sensor, seed=seed, max_count=pc.MAX_CANDIDATES, clear_mm=0.0)
        if len(pts):
            return pts, f"{len(pts)} places on the cell mesh's upward surfaces seen from the sensor"
    g = pc.grid_candidates(targets)
    return g, f"{len(g)} grid points around the targets (no mesh: free space, check that markers fit there)"


def use_fiducials(session: ExplorerSession, ids, positions) -> Evaluation:
    """Replace the cell's fiducials by `ids` at `positions` (K, 3) robot frame, mm (a plan to a tolerance,
    `tolerance_plan.plan_to_tolerance`), all included, measured from the error model. One step of the edit history
    (`undo` brings the former fiducials back). InputError (session unchanged) for an empty or mismatched set, or an
    id already a registration point's or a target's."""
    require_planning(session)
    ids = tuple(str(i) for i in ids)
    pos = np.asarray(positions, float).reshape(-1, 3)
    if not ids or len(ids) != len(pos) or len(set(ids)) != len(ids):
        raise InputError("a plan's fiducials need one distinct id per position")
    taken = (set(session.layout["registration"].ids) | set(session.layout["targets"].ids)) & set(ids)
    if taken:
        raise InputError(f"{', '.join(sorted(taken))}: already a registration point's or a target's id")
    old_settings = session.settings

    def change():
        session.layout = {**session.layout, "fiducials": Group(ids, pos)}
        session.settings = session.settings.replace(excluded=session.settings.excluded - set(ids))

    try:
        ev = edits.edit(session, change)
    except InputError:
        session.settings = old_settings
        raise
    clear_suggestion(session)
    return ev
