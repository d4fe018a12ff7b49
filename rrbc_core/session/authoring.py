"""Editing a scene session: add and delete points, move the sensor, undo and redo, and write what was made — the
scene file (File → Save scene) and the measurement plan (File → Measurement plan). Part of `ExplorerSession`.

Frames and units: robot base frame, mm. Edits apply to scene sessions (measured data are what was measured).
Every edit, and every drag that calls `checkpoint()` first, can be undone; a new edit clears the redo list.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.session.evaluation import Evaluation, Group

KINDS = ("registration", "fiducials", "targets", "candidates")
PREFIX = {"registration": "R", "fiducials": "F", "targets": "T", "candidates": "C"}
MAX_HISTORY = 200
MAX_POINTS = 2000  # per kind: an edited cell stays within what the app redraws at once


class SessionAuthoring:
    """Part of `ExplorerSession` (see there); split out to keep modules short."""

    # ------------------------------------------------------------------------------------------- history
    def _state(self) -> tuple:
        return (self.layout, dict(self.regions), self.candidates, self.sensor_to_robot, dict(self._readings))

    def _restore(self, state) -> None:
        self.layout, self.regions, self.candidates, self.sensor_to_robot, self._readings = state
        self.regions, self._readings = dict(self.regions), dict(self._readings)
        self._heat_cache.clear()

    def checkpoint(self) -> None:
        """Remember the session as it is now, so the next change can be undone (the app calls this when a drag
        starts)."""
        self._undo.append(self._state())
        del self._undo[:-MAX_HISTORY]
        self._redo.clear()

    def _edit(self, change) -> Evaluation:
        if self.kind != "scene":
            raise InputError("measured data cannot be edited (load a scene to author a cell)")
        before = self._state()
        try:
            change()
            ev = self.evaluate()
        except InputError:
            self._restore(before)
            raise
        self._undo.append(before)
        del self._undo[:-MAX_HISTORY]
        self._redo.clear()
        return ev

    def undo(self) -> Evaluation:
        """Go back one edit (InputError if there is none)."""
        if not self._undo:
            raise InputError("nothing to undo")
        self._redo.append(self._state())
        self._restore(self._undo.pop())
        return self.evaluate()

    def redo(self) -> Evaluation:
        """Redo the last undone edit (InputError if there is none)."""
        if not self._redo:
            raise InputError("nothing to redo")
        self._undo.append(self._state())
        self._restore(self._redo.pop())
        return self.evaluate()

    @property
    def can_undo(self) -> bool:
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        return bool(self._redo)

    # ------------------------------------------------------------------------------------------- edits
    def _group(self, kind: str) -> Group:
        if kind not in KINDS:
            raise InputError(f"unknown point kind '{kind}': {', '.join(KINDS)}")
        return self.candidates if kind == "candidates" else self.layout[kind]

    def _set_group(self, kind: str, group: Group) -> None:
        if kind == "candidates":
            self.candidates = group
        else:
            self.layout = {**self.layout, kind: group}

    def new_id(self, kind: str) -> str:
        """The next free id of a kind (R7, F13, T9, C001…)."""
        used = set(self._group(kind).ids)
        k = len(used) + 1
        while True:
            pid = f"{PREFIX[kind]}{k:03d}" if kind == "candidates" else f"{PREFIX[kind]}{k}"
            if pid not in used:
                return pid
            k += 1

    def add_point(self, kind: str, position, pid: str | None = None, region_mm: float = 4.0) -> Evaluation:
        """Add a registration point, fiducial, target (with a cubic region of `region_mm`, mm) or candidate at
        `position` (3,) robot frame, mm. Returns the new Evaluation; InputError leaves the session unchanged."""
        from rrbc_core.io.scene import Region

        p = np.asarray(position, float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)) or np.abs(p).max() > 1e7:
            raise InputError("a position must be 3 finite numbers (mm)")
        g = self._group(kind)
        if len(g.ids) >= MAX_POINTS:
            raise InputError(f"at most {MAX_POINTS} {kind} in a cell")
        pid = self.new_id(kind) if pid is None else str(pid)
        if not pid or not pid.isprintable() or len(pid) > 64:
            raise InputError("an id must be 1-64 printable characters")
        taken = set().union(*(self._group(k).ids for k in KINDS))
        if pid in taken:
            raise InputError(f"id {pid!r} is taken")
        if kind == "targets" and not (np.isfinite(region_mm) and 0 < region_mm <= 1000):
            raise InputError("a target's region must be a cube edge from 0 to 1000 mm")

        def change():
            self._set_group(kind, Group(g.ids + (pid,), np.vstack([g.positions.reshape(-1, 3), p])))
            if kind == "targets":
                self.regions = {**self.regions, pid: Region("box", p, np.full(3, float(region_mm)))}

        return self._edit(change)

    def remove_point(self, kind: str, pid: str) -> Evaluation:
        """Delete a point (at least 3 registration points and 1 target stay)."""
        g = self._group(kind)
        i = g.index(pid)
        least = {"registration": 3, "targets": 1}.get(kind, 0)
        if len(g.ids) - 1 < least:
            raise InputError(f"a cell needs at least {least} {kind}; add one before deleting {pid}")

        def change():
            keep = [k for k in range(len(g.ids)) if k != i]
            self._set_group(kind, Group(tuple(g.ids[k] for k in keep), g.positions.reshape(-1, 3)[keep]))
            if kind == "targets":
                self.regions = {k: v for k, v in self.regions.items() if k != pid}
            if kind == "fiducials" and pid in self.settings.excluded:
                self.settings = dataclasses.replace(self.settings, excluded=self.settings.excluded - {pid})

        return self._edit(change)

    def move_sensor(self, position, look_at=None) -> Evaluation:
        """Put the sensor at `position` (3,) looking at `look_at` (default: the targets' centre); every point is
        measured again from there."""
        from rrbc_core.io.scene import sensor_pose

        look = self.layout["targets"].positions.mean(0) if look_at is None else np.asarray(look_at, float)
        pose = sensor_pose(np.asarray(position, float).reshape(3), look)

        def change():
            self.sensor_to_robot = pose
            self._readings = {}
            self._heat_cache.clear()

        return self._edit(change)

    # ------------------------------------------------------------------------------------------- writing
    def scene_spec(self, mesh: str | None = None):
        """The session as a scene file's content (`io.scene_write.SceneSpec`): the scene it came from with its
        points, targets' regions, candidates and sensor as they are now. `mesh`: the path to write for the mesh
        (default: the scene's mesh file name: a scene opens only meshes in its own folder, so keep the mesh beside it)."""
        from rrbc_core.io.scene_write import SceneSpec, region_table

        if self.kind != "scene":
            raise InputError("only a scene session can be saved as a scene (measured data: download the CSV)")
        sc = self.scene
        T = self.sensor_to_robot
        r = np.asarray(T.rotation, float)
        pos = np.asarray(T.translation, float)
        look = self.layout["targets"].positions.mean(0)
        depth = max(float((look - pos) @ r[:, 2]), 1.0)
        s = self.settings
        return SceneSpec(
            name=sc.name,
            description=sc.description,
            mesh=Path(sc.mesh_path).name if mesh is None else mesh,
            seed=int(s.seed),
            robot_model=sc.robot_model,
            tool_mm=float(sc.tool_mm),
            joint_seed_deg=np.rad2deg(np.asarray(sc.joint_seed, float)),
            tool_yaw_deg=float(sc.tool_yaw_deg),
            sensor_kind=sc.sensor_kind,
            sensor_position=pos,
            sensor_look_at=pos + depth * r[:, 2],
            sensor_up=-r[:, 1],
            registration=(self.layout["registration"].ids, self.layout["registration"].positions),
            fiducials=(self.layout["fiducials"].ids, self.layout["fiducials"].positions),
            candidates=(self.candidates.ids, self.candidates.positions),
            targets=[
                (pid, p, region_table(self.regions[pid]))
                for pid, p in zip(self.layout["targets"].ids, self.layout["targets"].positions)
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

    def scene_toml(self, mesh: str | None = None) -> str:
        """The session as scene-file text (`scene_spec`); loading it gives the same points and numbers."""
        from rrbc_core.io.scene_write import scene_toml

        return scene_toml(self.scene_spec(mesh))

    def measurement_plan(self) -> str:
        """The points to measure, in order, as a measurement file with empty readings (io.measurement_plan)."""
        from rrbc_core.io.measurement_plan import plan_csv

        groups = {k: (self.layout[k].ids, self.layout[k].positions) for k in ("registration", "fiducials", "targets")}
        return plan_csv(
            groups,
            comments=[
                f"Measurement plan for {self.name}: measure each point at its planned place (robot base frame, mm),",
                "fill sensor_* (sensor frame) and robot_* (robot frame; not for targets), then: rrbc correct THIS.csv",
            ],
        )
