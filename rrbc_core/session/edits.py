"""Editing a scene session: add and delete points, move the sensor, undo and redo, and write what was made — the
scene file (File → Save scene) and the measurement plan (File → Measurement plan). Part of `ExplorerSession`.

Frames and units: robot base frame, mm. Edits apply to scene sessions (measured data are what was measured).
Every edit can be undone (a drag is not an edit: it is not in the history); a new edit clears the redo list.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.session.evaluation import Evaluation, Group

if TYPE_CHECKING:
    from rrbc_core.session.explorer import ExplorerSession

KINDS = ("registration", "fiducials", "targets", "candidates")
PREFIX = {"registration": "R", "fiducials": "F", "targets": "T", "candidates": "C"}
MAX_HISTORY = 200
MAX_POINTS = 2000  # per kind: an edited cell stays within what the app redraws at once


# ------------------------------------------------------------------------------------------- history
def _state(session: ExplorerSession) -> tuple:
    return (session.layout, dict(session.regions), session.candidates, session.sensor_to_robot, dict(session._readings))


def _restore(session: ExplorerSession, state) -> None:
    session.layout, session.regions, session.candidates, session.sensor_to_robot, session._readings = state
    session.regions, session._readings = dict(session.regions), dict(session._readings)
    session._heat_cache.clear()


def fingerprint(session: ExplorerSession) -> str:
    """A digest of what a saved scene holds of the session: every point's id and position, the targets' regions,
    the candidates and the sensor's pose (equal digests: nothing to save)."""
    import hashlib

    h = hashlib.sha256()
    for kind in ("registration", "fiducials", "targets"):
        g = session.layout[kind]
        h.update(repr((kind, tuple(g.ids))).encode())
        h.update(np.ascontiguousarray(np.asarray(g.positions, float)).tobytes())
    h.update(repr(tuple(session.candidates.ids)).encode())
    h.update(np.ascontiguousarray(np.asarray(session.candidates.positions, float)).tobytes())
    for pid in sorted(session.regions):
        r = session.regions[pid]
        h.update(repr((pid, r.kind)).encode())
        h.update(np.ascontiguousarray(np.asarray(getattr(r, "size", np.zeros(3)), float)).tobytes())
    pose = session.sensor_to_robot
    if pose is not None:
        h.update(np.ascontiguousarray(np.asarray(pose.rotation, float)).tobytes())
        h.update(np.ascontiguousarray(np.asarray(pose.translation, float)).tobytes())
    return h.hexdigest()


def mark_saved(session: ExplorerSession) -> None:
    """The session as it is now is saved (opened from its file, or downloaded as a scene)."""
    session.saved_fingerprint = fingerprint(session)


def has_unsaved_edits(session: ExplorerSession) -> bool:
    """Whether a scene session differs from what was last opened or saved (measured data are never edited)."""
    if session.kind != "scene":
        return False
    saved = getattr(session, "saved_fingerprint", None)
    return saved is not None and saved != fingerprint(session)


def edit(session: ExplorerSession, change) -> Evaluation:
    if session.kind != "scene":
        raise InputError("measured data cannot be edited (load a scene to author a cell)")
    before = _state(session)
    try:
        change()
        ev = session.evaluate()
    except InputError:
        _restore(session, before)
        raise
    session.history.undo.append(before)
    del session.history.undo[:-MAX_HISTORY]
    session.history.redo.clear()
    return ev


def undo(session: ExplorerSession) -> Evaluation:
    """Go back one edit (InputError if there is none)."""
    if not session.history.undo:
        raise InputError("nothing to undo")
    session.history.redo.append(_state(session))
    _restore(session, session.history.undo.pop())
    return session.evaluate()


def redo(session: ExplorerSession) -> Evaluation:
    """Redo the last undone edit (InputError if there is none)."""
    if not session.history.redo:
        raise InputError("nothing to redo")
    session.history.undo.append(_state(session))
    _restore(session, session.history.redo.pop())
    return session.evaluate()


def can_undo(session: ExplorerSession) -> bool:
    return bool(session.history.undo)


def can_redo(session: ExplorerSession) -> bool:
    return bool(session.history.redo)


# ------------------------------------------------------------------------------------------- edits
def _group(session: ExplorerSession, kind: str) -> Group:
    if kind not in KINDS:
        raise InputError(f"unknown point kind '{kind}': {', '.join(KINDS)}")
    return session.candidates if kind == "candidates" else session.layout[kind]


def _set_group(session: ExplorerSession, kind: str, group: Group) -> None:
    if kind == "candidates":
        session.candidates = group
    else:
        session.layout = {**session.layout, kind: group}


def new_id(session: ExplorerSession, kind: str) -> str:
    """The next free id of a kind (R7, F13, T9, C001…)."""
    used = set(_group(session, kind).ids)
    k = len(used) + 1
    while True:
        pid = f"{PREFIX[kind]}{k:03d}" if kind == "candidates" else f"{PREFIX[kind]}{k}"
        if pid not in used:
            return pid
        k += 1


def add_point(
    session: ExplorerSession, kind: str, position, pid: str | None = None, region_mm: float = 4.0
) -> Evaluation:
    """Add a registration point, fiducial, target (with a cubic region of `region_mm`, mm) or candidate at
    `position` (3,) robot frame, mm. Returns the new Evaluation; InputError leaves the session unchanged."""
    from rrbc_core.io.scene import Region

    p = np.asarray(position, float).reshape(-1)
    if p.shape != (3,) or not np.all(np.isfinite(p)) or np.abs(p).max() > 1e7:
        raise InputError("a position must be 3 finite numbers (mm)")
    g = _group(session, kind)
    if len(g.ids) >= MAX_POINTS:
        raise InputError(f"at most {MAX_POINTS} {kind} in a cell")
    pid = new_id(session, kind) if pid is None else str(pid)
    if not pid or not pid.isprintable() or len(pid) > 64:
        raise InputError("an id must be 1-64 printable characters")
    taken = set().union(*(_group(session, k).ids for k in KINDS))
    if pid in taken:
        raise InputError(f"id {pid!r} is taken")
    if kind == "targets" and not (np.isfinite(region_mm) and 0 < region_mm <= 1000):
        raise InputError("a target's region must be a cube edge from 0 to 1000 mm")

    def change():
        _set_group(session, kind, Group(g.ids + (pid,), np.vstack([g.positions.reshape(-1, 3), p])))
        if kind == "targets":
            session.regions = {**session.regions, pid: Region("box", p, np.full(3, float(region_mm)))}

    return edit(session, change)


def remove_point(session: ExplorerSession, kind: str, pid: str) -> Evaluation:
    """Delete a point (at least 3 registration points and 1 target stay)."""
    g = _group(session, kind)
    i = g.index(pid)
    least = {"registration": 3, "targets": 1}.get(kind, 0)
    if len(g.ids) - 1 < least:
        raise InputError(f"a cell needs at least {least} {kind}; add one before deleting {pid}")

    def change():
        keep = [k for k in range(len(g.ids)) if k != i]
        _set_group(session, kind, Group(tuple(g.ids[k] for k in keep), g.positions.reshape(-1, 3)[keep]))
        if kind == "targets":
            session.regions = {k: v for k, v in session.regions.items() if k != pid}
        if kind == "fiducials" and pid in session.settings.excluded:
            session.settings = session.settings.replace(excluded=session.settings.excluded - {pid})

    return edit(session, change)


def move_sensor(session: ExplorerSession, position, look_at=None) -> Evaluation:
    """Put the sensor at `position` (3,) looking at `look_at` (default: the targets' centre); every point is
    measured again from there."""
    from rrbc_core.io.scene import sensor_pose

    look = session.layout["targets"].positions.mean(0) if look_at is None else np.asarray(look_at, float)
    pose = sensor_pose(np.asarray(position, float).reshape(3), look)

    def change():
        session.sensor_to_robot = pose
        session._readings = {}
        session._heat_cache.clear()

    return edit(session, change)


# ------------------------------------------------------------------------------------------- writing
def _urdf_ref(sc) -> str | None:
    """The scene's `robot.urdf` as a saved file names it: a packaged name, or the path from the scene's folder (keep
    the saved scene there, as its mesh)."""
    u = getattr(sc, "robot_urdf", None)
    if u is None or isinstance(u, str):
        return u
    try:
        return Path(u).relative_to(Path(sc.path).resolve().parent).as_posix()
    except ValueError:
        return Path(u).name


def scene_spec(session: ExplorerSession, mesh: str | None = None):
    """The session as a scene file's content (`io.scene_write.SceneSpec`): the scene it came from with its
    points, targets' regions, candidates and sensor as they are now. `mesh`: the path to write for the mesh
    (default: the scene's mesh file name: a scene opens only meshes in its own folder, so keep the mesh beside it)."""
    from rrbc_core.io.scene_write import SceneSpec, region_table

    if session.kind != "scene":
        raise InputError("only a scene session can be saved as a scene (measured data: download the CSV)")
    sc = session.scene
    T = session.sensor_to_robot
    r = np.asarray(T.rotation, float)
    pos = np.asarray(T.translation, float)
    look = session.layout["targets"].positions.mean(0)
    depth = max(float((look - pos) @ r[:, 2]), 1.0)
    s = session.settings
    return SceneSpec(
        name=session.name,
        description=sc.description,
        mesh=Path(sc.mesh_path).name if mesh is None else mesh,
        seed=int(s.seed),
        robot_model=sc.robot_model,
        tool_mm=float(sc.tool_mm),
        robot_urdf=_urdf_ref(sc),
        robot_tip=sc.robot_tip,
        joint_seed_deg=np.rad2deg(np.asarray(sc.joint_seed, float)),
        tool_yaw_deg=float(sc.tool_yaw_deg),
        sensor_kind=sc.sensor_kind,
        sensor_position=pos,
        sensor_look_at=pos + depth * r[:, 2],
        sensor_up=-r[:, 1],
        registration=(session.layout["registration"].ids, session.layout["registration"].positions),
        fiducials=(session.layout["fiducials"].ids, session.layout["fiducials"].positions),
        candidates=(session.candidates.ids, session.candidates.positions),
        targets=[
            (pid, p, region_table(session.regions[pid]))
            for pid, p in zip(session.layout["targets"].ids, session.layout["targets"].positions)
        ],
        error_model=sc.error_model_table,
        simulation={
            "check_points_per_target": int(sc.check_points_per_target),
            "measurement_interval_s": float(sc.measurement_interval_s),
            "distance_origin_mm": [float(v) for v in sc.distance_origin],
        },
        comments={
            "header": [
                f"Saved from the rrbc explorer: {sc.name}. Robot base frame, mm. Session settings not stored "
                f"here: noise x{s.noise_scale:g}, bias x{s.bias_scale:g},",
                f"registration {s.registration}, interpolation {s.interpolation}"
                + (f", excluded fiducials {', '.join(sorted(s.excluded))}" if s.excluded else "")
                + ".",
            ]
        },
    )


def scene_toml(session: ExplorerSession, mesh: str | None = None) -> str:
    """The session as scene-file text (`scene_spec`); loading it gives the same points and numbers."""
    from rrbc_core.io.scene_write import scene_toml

    return scene_toml(scene_spec(session, mesh))


def measurement_plan(session: ExplorerSession) -> str:
    """The points to measure, in order, as a measurement file with empty readings (io.measurement_plan)."""
    from rrbc_core.io.measurement_plan import plan_csv

    groups = {k: (session.layout[k].ids, session.layout[k].positions) for k in ("registration", "fiducials", "targets")}
    return plan_csv(
        groups,
        comments=[
            f"Measurement plan for {session.name}: measure each point at its planned place (robot base frame, mm),",
            "fill sensor_* (sensor frame) and robot_* (robot frame; not for targets), then: rrbc correct THIS.csv",
        ],
    )
