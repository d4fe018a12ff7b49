"""Scenes: the work cell a simulation, a plan or the browser app works on, read from a TOML file.

A scene file (format: `scenes/README.md`) holds, in the ROBOT BASE frame and in millimetres, a mesh of the cell,
the robot, the true pose of the sensor, the registration points, fiducials, candidate fiducial locations, named
sites, the targets with their regions of variability, named alternative layouts and the error model. The scene
frame IS the robot frame.

`load_scene(path)` validates everything it reads. Every problem raises `InputError` with ONE line of the form

    <file>: <key path>: <what is wrong>

for example `demo.toml: target[2].region.size: must be 3 positive numbers, got [10, -5, 3]`. Indices in key
paths count from 0 in file order (`target[0]` is the first `[[target]]` block).

The sensor pose follows the camera convention: sensor frame origin at `sensor.position`, +z along the viewing
direction (towards `sensor.look_at`), +y roughly along −`sensor.up` (x right, y down, z forward). It is exposed
as `Scene.sensor_to_robot` (robot = R @ sensor + t).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rrbc_core.geometry import points as geometry
from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform

#: Robot models the scene format accepts (the kinematics module implements these).
ROBOT_MODELS = ("ur5",)
#: Sensor kinds: labels only (they name what the error model stands for; the error model does the work).
#: "ground_truth" is for scenes whose "sensor" is a reference artefact (the Van Wyk & Marvel breadboard).
SENSOR_KINDS = ("stereo", "mocap", "laser_tracker", "ground_truth")
REGION_KINDS = ("box", "sphere", "ellipsoid")
#: Default IK branch seed for a UR5 working on a table with the tool pointing down (degrees).
DEFAULT_JOINT_SEED_DEG = (0.0, -90.0, 90.0, -90.0, -90.0, 0.0)
DEFAULT_CHECK_POINTS_PER_TARGET = 20
DEFAULT_MEASUREMENT_INTERVAL_S = 5.0
#: Two definitions of one point id (e.g. a site reused as a registration point) must agree this closely.
SAME_POINT_TOL_MM = 1e-6
#: Largest candidate grid the loader will generate.
MAX_GRID_POINTS = 100_000

_TOP_KEYS = (
    "scene",
    "robot",
    "sensor",
    "registration",
    "fiducial",
    "candidate",
    "candidates",
    "site",
    "target",
    "layouts",
    "error_model",
    "simulation",
)
_REQUIRED_TOP = ("scene", "robot", "sensor", "registration", "target")
_POINT_KINDS = ("registration", "fiducial", "site", "candidate", "target")


# ------------------------------------------------------------------------------------------------------
# Result types
# ------------------------------------------------------------------------------------------------------
def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Region:
    """A target's region of variability, axis-aligned in the robot frame (mm).

    kind: "box", "sphere" or "ellipsoid". center: (3,). size: (3,) — the full extents for a box, the radii for an
    ellipsoid, (r, r, r) for a sphere.
    """

    kind: str
    center: np.ndarray
    size: np.ndarray

    def __post_init__(self):
        if self.kind not in REGION_KINDS:
            raise InputError(f"region kind must be one of {', '.join(REGION_KINDS)}, got {self.kind!r}")
        c = _frozen(self.center).reshape(-1)
        s = _frozen(self.size).reshape(-1)
        if c.shape != (3,) or s.shape != (3,) or not (np.all(np.isfinite(c)) and np.all(np.isfinite(s))):
            raise InputError("a region needs a finite 3-vector center and a finite 3-vector size")
        if np.any(s <= 0):
            raise InputError(f"region size must be positive, got {s.tolist()}")
        if self.kind == "sphere" and not np.allclose(s, s[0]):
            raise InputError(f"a sphere region has one radius, got sizes {s.tolist()}")
        object.__setattr__(self, "center", c)
        object.__setattr__(self, "size", s)

    @property
    def half_extents(self) -> np.ndarray:
        """Half extents of the axis-aligned bounding box (= radii for spheres and ellipsoids)."""
        return self.size / 2.0 if self.kind == "box" else self.size

    def contains(self, points, tol_mm: float = 1e-9) -> np.ndarray:
        """Bool array: which points (…, 3) lie inside the region (boundary included, within tol_mm)."""
        p = np.asarray(points, dtype=float)
        d = p - self.center
        if self.kind == "box":
            return np.all(np.abs(d) <= self.size / 2.0 + tol_mm, axis=-1)
        # sphere / ellipsoid: scale to the unit ball; tolerance applied along the smallest radius
        q = np.sum((d / self.size) ** 2, axis=-1)
        return q <= (1.0 + tol_mm / float(self.size.min())) ** 2

    def sample(self, rng, n: int) -> np.ndarray:
        """n points uniformly distributed inside the region, (n, 3)."""
        rng = np.random.default_rng(rng)
        n = int(n)
        if n < 0:
            raise InputError(f"number of samples must be >= 0, got {n}")
        if self.kind == "box":
            return self.center + (rng.random((n, 3)) - 0.5) * self.size
        # uniform in the unit ball (direction x radius^(1/3)), then stretched: a linear map keeps uniformity
        g = rng.standard_normal((n, 3))
        g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
        r = rng.random(n) ** (1.0 / 3.0)
        return self.center + g * r[:, None] * self.size

    def volume(self) -> float:
        """Volume in mm³."""
        if self.kind == "box":
            return float(np.prod(self.size))
        return float(4.0 / 3.0 * math.pi * np.prod(self.size))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min (3,), max (3,)) of the axis-aligned bounding box."""
        h = self.half_extents
        return self.center - h, self.center + h

    def as_dict(self) -> dict:
        d = {"kind": self.kind, "center": self.center.tolist()}
        if self.kind == "box":
            d["size"] = self.size.tolist()
        elif self.kind == "sphere":
            d["radius"] = float(self.size[0])
        else:
            d["radii"] = self.size.tolist()
        return d


@dataclass(frozen=True, eq=False)
class NamedPoints:
    """Named points in the robot frame: ids (K,) and positions (K, 3) in mm.

    tool_yaw_deg (K,): the tool yaw about the vertical the robot uses at each point (the scene's
    `robot.tool_yaw_deg` unless the point sets its own). Keep it consistent between fiducials and targets: the
    robot's kinematic error depends on the joint configuration, not only on the Cartesian point.
    """

    ids: tuple
    positions: np.ndarray
    tool_yaw_deg: np.ndarray | None = None

    def __post_init__(self):
        ids = tuple(str(i) for i in self.ids)
        p = _frozen(self.positions).reshape(-1, 3) if len(ids) else _frozen(np.zeros((0, 3)))
        if len(p) != len(ids):
            raise InputError(f"NamedPoints: {len(ids)} ids but {len(p)} positions")
        yaw = np.zeros(len(ids)) if self.tool_yaw_deg is None else self.tool_yaw_deg
        yaw = _frozen(yaw).reshape(-1)
        if len(yaw) != len(ids):
            raise InputError(f"NamedPoints: {len(ids)} ids but {len(yaw)} tool yaw angles")
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "positions", p)
        object.__setattr__(self, "tool_yaw_deg", yaw)

    def __len__(self) -> int:
        return len(self.ids)

    def index(self, point_id: str) -> int:
        return self.ids.index(point_id)

    def position(self, point_id: str) -> np.ndarray:
        return self.positions[self.index(point_id)]

    def subset(self, ids) -> "NamedPoints":
        idx = [self.index(i) for i in ids]
        return NamedPoints(tuple(self.ids[i] for i in idx), self.positions[idx], self.tool_yaw_deg[idx])

    def as_dict(self) -> dict:
        return {"ids": list(self.ids), "positions": self.positions.tolist()}


@dataclass(frozen=True, eq=False)
class Target:
    """A target: centre `position` (3,) of a region of variability `region`, robot frame, mm."""

    id: str
    position: np.ndarray
    region: Region
    tool_yaw_deg: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "position", _frozen(self.position).reshape(3))


@dataclass(frozen=True, eq=False)
class Scene:
    """A validated scene (see the module docstring and scenes/README.md). Robot frame, mm."""

    name: str
    description: str
    path: Path
    mesh_path: Path
    robot_model: str
    tool_mm: float
    joint_seed: np.ndarray  # (6,) rad
    tool_yaw_deg: float
    sensor_kind: str
    sensor_to_robot: RigidTransform
    registration: NamedPoints
    fiducials: NamedPoints
    candidates: NamedPoints
    sites: NamedPoints
    targets: tuple
    layouts: dict
    error_model: object
    error_model_table: dict
    seed: int = 0
    check_points_per_target: int = DEFAULT_CHECK_POINTS_PER_TARGET
    measurement_interval_s: float = DEFAULT_MEASUREMENT_INTERVAL_S
    layout: str | None = None  # name of the layout applied by with_layout, None for the file's own points
    distance_origin: np.ndarray = field(default_factory=lambda: np.zeros(3))  # "distance from the frame origin" is from here
    sensor_look_at: np.ndarray | None = None
    _layout_points: dict = field(default_factory=dict, repr=False)
    _mesh: object = field(default=None, repr=False)

    # --- derived ------------------------------------------------------------------------------------------
    @property
    def sensor_position(self) -> np.ndarray:
        """Sensor origin in the robot frame (mm)."""
        return self.sensor_to_robot.translation

    @property
    def line_of_sight(self) -> bool:
        """Whether visibility from the sensor applies. False for a "ground_truth" sensor (a reference artefact
        such as the breadboard's frame N): it measures by construction, nothing can occlude it, and its origin
        lies on the plate surface, so ray casting from it would call every point hidden."""
        return self.sensor_kind != "ground_truth"

    @property
    def target_ids(self) -> tuple:
        return tuple(t.id for t in self.targets)

    @property
    def target_positions(self) -> np.ndarray:
        return np.array([t.position for t in self.targets]).reshape(-1, 3)

    def target(self, target_id: str) -> Target:
        for t in self.targets:
            if t.id == target_id:
                return t
        raise InputError(f"{self.path}: no target with id {target_id!r}; targets: {', '.join(self.target_ids)}")

    def sample_check_points(self, rng=None, n: int | None = None) -> tuple[tuple, np.ndarray]:
        """Check points sampled uniformly inside each target's region of variability.

        Returns (target id per point, (T*n, 3) points). n defaults to `check_points_per_target`; rng defaults to
        the scene's seed.
        """
        rng = np.random.default_rng(self.seed if rng is None else rng)
        n = self.check_points_per_target if n is None else int(n)
        ids, pts = [], []
        for t in self.targets:
            ids.extend([t.id] * n)
            pts.append(t.region.sample(rng, n))
        return tuple(ids), (np.concatenate(pts) if pts else np.zeros((0, 3)))

    def with_layout(self, name: str) -> "Scene":
        """The scene with registration points and/or fiducials replaced by layout `name` (a `[layouts.NAME]`
        table); what the layout does not name stays as it is."""
        if name not in self._layout_points:
            valid = ", ".join(sorted(self._layout_points)) or "(none defined)"
            raise InputError(f"{self.path}: layouts.{name}: no such layout; layouts: {valid}")
        pts = self._layout_points[name]
        return dataclasses.replace(
            self,
            registration=pts.get("registration", self.registration),
            fiducials=pts.get("fiducials", self.fiducials),
            layout=name,
        )

    def load_mesh(self):
        """The scene mesh as ONE trimesh.Trimesh in the robot frame (a copy; parts concatenated).

        `mesh.metadata["parts"]` lists (name, first_face, end_face) per part, so a face index (from a ray cast)
        can be named.
        """
        mesh = self._mesh if self._mesh is not None else _load_mesh_file(self.mesh_path)
        out = mesh.copy()
        out.metadata["parts"] = list(mesh.metadata.get("parts", []))
        return out

    def points_by_kind(self) -> dict:
        """{"registration", "fiducials", "candidates", "sites", "targets"} -> (ids, (K,3) positions)."""
        return {
            "registration": (self.registration.ids, self.registration.positions),
            "fiducials": (self.fiducials.ids, self.fiducials.positions),
            "candidates": (self.candidates.ids, self.candidates.positions),
            "sites": (self.sites.ids, self.sites.positions),
            "targets": (self.target_ids, self.target_positions),
        }


# ------------------------------------------------------------------------------------------------------
# Sensor pose
# ------------------------------------------------------------------------------------------------------
def sensor_pose(position, look_at, up=(0.0, 0.0, 1.0)) -> RigidTransform:
    """Sensor→robot transform of a sensor at `position` looking at `look_at` (robot frame, mm).

    Camera convention: +z towards look_at, +y along the component of −up perpendicular to z, x = y × z
    (x right, y down, z forward). Raises InputError if look_at == position or up is parallel to the view.
    """
    p = np.asarray(position, dtype=float)
    z = np.asarray(look_at, dtype=float) - p
    n = np.linalg.norm(z)
    if not n > 1e-9:
        raise InputError("look_at equals position: the sensor needs a viewing direction")
    z = z / n
    u = np.asarray(up, dtype=float)
    un = np.linalg.norm(u)
    if not un > 1e-12:
        raise InputError("up must be a non-zero vector")
    u = u / un
    y = -(u - np.dot(u, z) * z)
    yn = np.linalg.norm(y)
    if yn < 1e-6:
        raise InputError("up is parallel to the viewing direction (look_at − position)")
    y = y / yn
    x = np.cross(y, z)
    return RigidTransform(np.column_stack([x, y, z]), p)


# ------------------------------------------------------------------------------------------------------
# Mesh loading
# ------------------------------------------------------------------------------------------------------
def _load_mesh_file(path: Path):
    """Load any file trimesh reads and concatenate it into one Trimesh (scene graph transforms applied).

    Raises ValueError/OSError-derived exceptions from trimesh; the loader wraps them."""
    import trimesh

    loaded = trimesh.load(str(path), force="scene")
    parts, meshes = [], []
    start = 0
    graph = loaded.graph
    for node in graph.nodes_geometry:
        transform, geom_name = graph[node]
        geom = loaded.geometry.get(geom_name)
        if not isinstance(geom, trimesh.Trimesh) or len(geom.faces) == 0:
            continue
        m = geom.copy()
        m.apply_transform(transform)
        meshes.append(m)
        parts.append((str(node), start, start + len(m.faces)))
        start += len(m.faces)
    if not meshes:
        raise ValueError("the file holds no triangles")
    mesh = trimesh.util.concatenate(meshes) if len(meshes) > 1 else meshes[0]
    mesh.metadata["parts"] = parts
    return mesh


# ------------------------------------------------------------------------------------------------------
# Validation helpers
# ------------------------------------------------------------------------------------------------------
def _fmt(v, limit: int = 80) -> str:
    """A TOML-like rendering of a value for error messages."""

    def r(x):
        if isinstance(x, bool):
            return "true" if x else "false"
        if isinstance(x, str):
            return '"' + x.replace('"', '\\"') + '"'
        if isinstance(x, float):
            if math.isnan(x):
                return "nan"
            if math.isinf(x):
                return "inf" if x > 0 else "-inf"
            return repr(x)
        if isinstance(x, (list, tuple)):
            return "[" + ", ".join(r(e) for e in x) + "]"
        if isinstance(x, dict):
            return "{" + ", ".join(f"{k} = {r(e)}" for k, e in x.items()) + "}"
        return str(x)

    s = r(v)
    return s if len(s) <= limit else s[: limit - 3] + "..."


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


class _Checker:
    """Builds one-line errors `<file>: <key>: <what>` and validates TOML values."""

    def __init__(self, source: str):
        self.source = source

    def error(self, key: str, what: str) -> InputError:
        what = " ".join(str(what).split())  # one line, whatever the cause said
        return InputError(f"{self.source}: {key}: {what}" if key else f"{self.source}: {what}")

    def table(self, v, key: str) -> dict:
        if not isinstance(v, dict):
            raise self.error(key, f"must be a table, got {_fmt(v)}")
        return v

    def keys(self, d: dict, key: str, allowed, required=(), where: str | None = None) -> None:
        allowed = tuple(allowed)
        for k in d:
            if k not in allowed:
                where = where or (f"[{key}]" if key else "the top level")
                raise self.error(
                    f"{key}.{k}" if key else k,
                    f"unknown key; valid keys in {where}: {', '.join(allowed)}",
                )
        for k in required:
            if k not in d:
                raise self.error(f"{key}.{k}" if key else k, "missing required key")

    def string(self, v, key: str, choices=None, nonempty: bool = True) -> str:
        if not isinstance(v, str):
            raise self.error(key, f"must be a string, got {_fmt(v)}")
        if nonempty and not v.strip():
            raise self.error(key, "must not be empty")
        if choices is not None and v not in choices:
            raise self.error(key, f"must be one of {', '.join(repr(c) for c in choices)}, got {_fmt(v)}")
        return v

    def number(self, v, key: str, *, positive=False, nonneg=False) -> float:
        if not _is_number(v):
            raise self.error(key, f"must be a number, got {_fmt(v)}")
        x = float(v)
        if not math.isfinite(x):
            raise self.error(key, f"must be a finite number, got {_fmt(v)}")
        if positive and not x > 0:
            raise self.error(key, f"must be a positive number, got {_fmt(v)}")
        if nonneg and not x >= 0:
            raise self.error(key, f"must be a number >= 0, got {_fmt(v)}")
        return x

    def integer(self, v, key: str, minimum=None) -> int:
        if isinstance(v, bool) or not (isinstance(v, int) or (isinstance(v, float) and v.is_integer())):
            raise self.error(key, f"must be an integer, got {_fmt(v)}")
        i = int(v)
        if minimum is not None and i < minimum:
            raise self.error(key, f"must be an integer >= {minimum}, got {_fmt(v)}")
        return i

    def vector(self, v, key: str, n: int = 3, *, positive=False, what=None) -> np.ndarray:
        desc = what or (f"{n} positive numbers" if positive else f"{n} finite numbers")
        ok = isinstance(v, list) and len(v) == n and all(_is_number(e) for e in v)
        if ok:
            a = np.array([float(e) for e in v])
            ok = bool(np.all(np.isfinite(a))) and (not positive or bool(np.all(a > 0)))
        if not ok:
            raise self.error(key, f"must be {desc}, got {_fmt(v)}")
        return a

    def array_of_tables(self, v, key: str) -> list:
        if isinstance(v, dict):
            raise self.error(key, f"must be an array of tables ([[{key}]] blocks), got a single table [{key}]")
        if not isinstance(v, list) or not all(isinstance(e, dict) for e in v):
            raise self.error(key, f"must be an array of tables ([[{key}]] blocks), got {_fmt(v)}")
        return v


# ------------------------------------------------------------------------------------------------------
# The loader
# ------------------------------------------------------------------------------------------------------
_TOML_POS = re.compile(r"\s*\(at line (\d+), column (\d+)\)\s*$")
_TOML_EOF = re.compile(r"\s*\(at end of document\)\s*$")


def _read_toml(path, source: str, c: _Checker) -> dict:
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise c.error("", f"cannot read the scene file: {exc.strerror or exc.__class__.__name__}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise c.error(f"line {line}", "not UTF-8 text; save the scene file as UTF-8") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = _TOML_POS.search(msg)
        if m:
            raise c.error(
                f"line {m.group(1)}, column {m.group(2)}", f"TOML syntax error: {msg[: m.start()]}"
            ) from None
        m = _TOML_EOF.search(msg)
        if m:
            raise c.error("end of file", f"TOML syntax error: {msg[: m.start()]}") from None
        raise c.error("", f"TOML syntax error: {msg}") from None


def load_scene(path) -> Scene:
    """Read and validate a scene TOML file. Every problem raises InputError with one line
    `<file>: <key path>: <what is wrong>`."""
    source = os.fspath(path)
    if isinstance(source, bytes):
        source = os.fsdecode(source)
    c = _Checker(source)
    doc = _read_toml(path, source, c)
    toml_path = Path(source).resolve()

    c.keys(doc, "", _TOP_KEYS, _REQUIRED_TOP)

    # [scene] -----------------------------------------------------------------------------------------------
    sc = c.table(doc["scene"], "scene")
    c.keys(sc, "scene", ("name", "description", "units", "mesh", "seed"), ("name", "units", "mesh"))
    name = c.string(sc["name"], "scene.name")
    description = c.string(sc.get("description", ""), "scene.description", nonempty=False)
    units = c.string(sc["units"], "scene.units")
    if units != "mm":
        raise c.error("scene.units", f'only "mm" is supported (all coordinates in millimetres), got {_fmt(units)}')
    mesh_rel = c.string(sc["mesh"], "scene.mesh")
    mesh_path = (toml_path.parent / mesh_rel).resolve()
    seed = c.integer(sc.get("seed", 0), "scene.seed", minimum=0)

    # [robot] -----------------------------------------------------------------------------------------------
    rb = c.table(doc["robot"], "robot")
    c.keys(rb, "robot", ("model", "tool_mm", "joint_seed_deg", "tool_yaw_deg"), ("model", "tool_mm"))
    robot_model = c.string(rb["model"], "robot.model", choices=ROBOT_MODELS)
    tool_mm = c.number(rb["tool_mm"], "robot.tool_mm", nonneg=True)
    joint_seed_deg = (
        c.vector(rb["joint_seed_deg"], "robot.joint_seed_deg", 6) if "joint_seed_deg" in rb
        else np.array(DEFAULT_JOINT_SEED_DEG)
    )
    tool_yaw = c.number(rb.get("tool_yaw_deg", 0.0), "robot.tool_yaw_deg")

    # [sensor] ----------------------------------------------------------------------------------------------
    sn = c.table(doc["sensor"], "sensor")
    c.keys(sn, "sensor", ("kind", "position", "look_at", "up"), ("kind", "position", "look_at"))
    sensor_kind = c.string(sn["kind"], "sensor.kind", choices=SENSOR_KINDS)
    s_pos = c.vector(sn["position"], "sensor.position")
    s_look = c.vector(sn["look_at"], "sensor.look_at")
    s_up = c.vector(sn.get("up", [0.0, 0.0, 1.0]), "sensor.up")
    if np.linalg.norm(s_look - s_pos) <= 1e-9:
        raise c.error(
            "sensor.look_at", f"equals sensor.position {_fmt(sn['position'])}; the sensor needs a viewing direction"
        )
    if np.linalg.norm(s_up) <= 1e-12:
        raise c.error("sensor.up", "must be a non-zero vector")
    try:
        sensor_to_robot = sensor_pose(s_pos, s_look, s_up)
    except InputError:
        up_text = _fmt(sn.get("up", [0.0, 0.0, 1.0])) + ("" if "up" in sn else " (the default)")
        raise c.error(
            "sensor.up",
            f"{up_text} is parallel to the viewing direction (look_at − position); choose another up vector",
        ) from None

    # points --------------------------------------------------------------------------------------------------
    # One id names one place: the same id may appear in several kinds (a site reused as a registration point
    # or fiducial) only at the same position; a point whose id is a site's may omit its position.
    sites_raw = _points(c, doc, "site", tool_yaw, {})
    site_pos = {pid: (pos, key) for pid, pos, _, key, _ in sites_raw}
    registration_raw = _points(c, doc, "registration", tool_yaw, site_pos)
    fiducial_raw = _points(c, doc, "fiducial", tool_yaw, site_pos)
    candidate_raw = _points(c, doc, "candidate", tool_yaw, site_pos)
    candidate_raw += _grid(c, doc, tool_yaw)
    target_raw = _points(c, doc, "target", tool_yaw, site_pos, with_region=True)

    measured = {pid: key for group in (registration_raw, fiducial_raw) for pid, _, _, key, _ in group}
    for pid, _, _, key, _ in target_raw:
        if pid in measured:
            raise c.error(
                f"{key}.id",
                f"{pid!r} is also the id of {measured[pid]}; a target needs an id of its "
                "own (a measurement file gives each id one role); use site = \"<id>\" to put it at a site",
            )

    placed: dict[str, tuple[np.ndarray, str]] = {}
    for group in (sites_raw, registration_raw, fiducial_raw, candidate_raw, target_raw):
        for pid, pos, _, key, _ in group:
            if pid in placed and np.linalg.norm(placed[pid][0] - pos) > SAME_POINT_TOL_MM:
                other_pos, other_key = placed[pid]
                raise c.error(
                    f"{key}.position",
                    f"id {pid!r} is also {other_key} at {_fmt(other_pos.tolist())}; one id names one place "
                    f"(use another id or the same position)",
                )
            placed.setdefault(pid, (pos, key))

    def named(raw) -> NamedPoints:
        return NamedPoints(
            tuple(r[0] for r in raw),
            np.array([r[1] for r in raw]).reshape(-1, 3),
            np.array([r[2] for r in raw], dtype=float),
        )

    registration = named(registration_raw)
    fiducials = named(fiducial_raw)
    candidates = named(candidate_raw)
    sites = named(sites_raw)
    targets = tuple(Target(pid, pos, region, yaw) for pid, pos, yaw, _, region in target_raw)
    if len(registration) < 3:
        raise c.error("registration", f"{len(registration)} [[registration]] points given, at least 3 are needed")
    _check_spread(c, "registration", registration.positions)
    if not targets:
        raise c.error("target", "at least one [[target]] is needed")

    # [layouts.NAME] ----------------------------------------------------------------------------------------
    pool: dict[str, tuple[np.ndarray, float]] = {}
    for group in (sites_raw, registration_raw, fiducial_raw):
        for pid, pos, yaw, _, _ in group:
            pool.setdefault(pid, (pos, yaw))
    layouts, layout_points = _layouts(c, doc, pool)

    # [simulation] ------------------------------------------------------------------------------------------
    sim = c.table(doc.get("simulation", {}), "simulation")
    c.keys(sim, "simulation", ("check_points_per_target", "measurement_interval_s", "distance_origin_mm"))
    n_check = c.integer(
        sim.get("check_points_per_target", DEFAULT_CHECK_POINTS_PER_TARGET),
        "simulation.check_points_per_target",
        minimum=1,
    )
    interval = c.number(
        sim.get("measurement_interval_s", DEFAULT_MEASUREMENT_INTERVAL_S),
        "simulation.measurement_interval_s",
        nonneg=True,
    )
    distance_origin = c.vector(sim.get("distance_origin_mm", [0.0, 0.0, 0.0]), "simulation.distance_origin_mm")

    # [error_model] -----------------------------------------------------------------------------------------
    em_table = c.table(doc.get("error_model", {}), "error_model")
    error_model = _with_tool(_error_model(c, em_table), em_table, tool_mm)

    # mesh (last: the most expensive check) -------------------------------------------------------------------
    if not mesh_path.is_file():
        raise c.error("scene.mesh", f"mesh file not found: {mesh_path}")
    try:
        mesh = _load_mesh_file(mesh_path)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise c.error("scene.mesh", f"cannot load {mesh_rel!r} as a mesh: {exc.__class__.__name__}: {exc}") from None

    return Scene(
        name=name,
        description=description,
        path=toml_path,
        mesh_path=mesh_path,
        robot_model=robot_model,
        tool_mm=tool_mm,
        joint_seed=_frozen(np.radians(joint_seed_deg)),
        tool_yaw_deg=tool_yaw,
        sensor_kind=sensor_kind,
        sensor_to_robot=sensor_to_robot,
        registration=registration,
        fiducials=fiducials,
        candidates=candidates,
        sites=sites,
        targets=targets,
        layouts=layouts,
        error_model=error_model,
        error_model_table=em_table,
        seed=seed,
        check_points_per_target=n_check,
        measurement_interval_s=interval,
        distance_origin=_frozen(distance_origin),
        sensor_look_at=_frozen(s_look),
        _layout_points=layout_points,
        _mesh=mesh,
    )


def _points(c: _Checker, doc: dict, kind: str, default_yaw: float, site_pos: dict, with_region=False) -> list:
    """Parse `[[kind]]` blocks -> list of (id, position, yaw, key, region|None)."""
    if kind not in doc:
        return []
    blocks = c.array_of_tables(doc[kind], kind)
    allowed = ("id", "position", "tool_yaw_deg", "note") + (("site",) if kind != "site" else ()) + (
        ("region",) if with_region else ()
    )
    required = ("id",) + (("region",) if with_region else ())
    out, seen = [], {}
    for i, b in enumerate(blocks):
        key = f"{kind}[{i}]"
        c.keys(b, key, allowed, required, where=f"[[{kind}]]")
        pid = c.string(b["id"], f"{key}.id")
        if pid in seen:
            raise c.error(f"{key}.id", f"duplicate id {pid!r} (also {kind}[{seen[pid]}])")
        seen[pid] = i
        if "site" in b:
            ref = c.string(b["site"], f"{key}.site")
            if "position" in b:
                raise c.error(f"{key}.site", "give either position or site, not both")
            if ref not in site_pos:
                valid = ", ".join(site_pos) or "(no [[site]] defined)"
                raise c.error(f"{key}.site", f"unknown site {ref!r}; sites: {_fmt(valid, 60)[1:-1]}")
            pos = site_pos[ref][0]
        elif "position" in b:
            pos = c.vector(b["position"], f"{key}.position")
        elif kind != "site" and pid in site_pos:
            pos = site_pos[pid][0]
        else:
            hint = "" if kind == "site" else " (it may be omitted only when the id or a site key names a [[site]])"
            raise c.error(f"{key}.position", f"missing required key{hint}")
        if "note" in b:
            c.string(b["note"], f"{key}.note", nonempty=False)
        yaw = c.number(b["tool_yaw_deg"], f"{key}.tool_yaw_deg") if "tool_yaw_deg" in b else default_yaw
        region = _region(c, b["region"], f"{key}.region", pos) if with_region else None
        out.append((pid, pos, yaw, key, region))
    return out


def _region(c: _Checker, v, key: str, center: np.ndarray) -> Region:
    r = c.table(v, key)
    if "kind" not in r:
        raise c.error(f"{key}.kind", f"missing required key (one of {', '.join(REGION_KINDS)})")
    kind = c.string(r["kind"], f"{key}.kind")
    if kind not in REGION_KINDS:
        raise c.error(f"{key}.kind", f"unknown region kind {_fmt(kind)}; valid kinds: {', '.join(REGION_KINDS)}")
    if kind == "box":
        c.keys(r, key, ("kind", "size"), ("size",), where="a box region")
        size = c.vector(r["size"], f"{key}.size", positive=True)
    elif kind == "sphere":
        c.keys(r, key, ("kind", "radius"), ("radius",), where="a sphere region")
        size = np.full(3, c.number(r["radius"], f"{key}.radius", positive=True))
    else:
        c.keys(r, key, ("kind", "radii"), ("radii",), where="an ellipsoid region")
        size = c.vector(r["radii"], f"{key}.radii", positive=True)
    return Region(kind, center, size)


def _grid(c: _Checker, doc: dict, default_yaw: float) -> list:
    """`[candidates] grid = {min, max, step}` -> candidate points with ids grid-0001, grid-0002, ..."""
    if "candidates" not in doc:
        return []
    t = c.table(doc["candidates"], "candidates")
    c.keys(t, "candidates", ("grid", "tool_yaw_deg"), ("grid",))
    g = c.table(t["grid"], "candidates.grid")
    c.keys(g, "candidates.grid", ("min", "max", "step"), ("min", "max", "step"))
    lo = c.vector(g["min"], "candidates.grid.min")
    hi = c.vector(g["max"], "candidates.grid.max")
    step = c.vector(g["step"], "candidates.grid.step", positive=True)
    if np.any(hi < lo):
        raise c.error("candidates.grid.max", f"must be >= candidates.grid.min on every axis, got {_fmt(g['max'])}")
    yaw = c.number(t["tool_yaw_deg"], "candidates.tool_yaw_deg") if "tool_yaw_deg" in t else default_yaw
    counts = np.floor((hi - lo) / step + 1e-9).astype(int) + 1
    total = int(np.prod(counts))
    if total > MAX_GRID_POINTS:
        raise c.error(
            "candidates.grid.step", f"the grid would have {total} points (limit {MAX_GRID_POINTS}); use a larger step"
        )
    axes = [lo[k] + step[k] * np.arange(counts[k]) for k in range(3)]
    gx, gy, gz = np.meshgrid(*axes, indexing="ij")
    pts = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    width = max(4, len(str(total)))
    return [(f"grid-{i + 1:0{width}d}", p, yaw, f"candidates.grid (point {i})", None) for i, p in enumerate(pts)]


def _check_spread(c: _Checker, key: str, positions: np.ndarray) -> None:
    try:
        geometry.check_registration_points(positions, "points")
    except InputError as exc:
        raise c.error(key, str(exc)) from None


def _layouts(c: _Checker, doc: dict, pool: dict) -> tuple[dict, dict]:
    if "layouts" not in doc:
        return {}, {}
    lt = c.table(doc["layouts"], "layouts")
    layouts, points = {}, {}
    for name, body in lt.items():
        key = f"layouts.{name}"
        b = c.table(body, key)
        c.keys(b, key, ("registration", "fiducials", "description"))
        if "description" in b:
            c.string(b["description"], f"{key}.description", nonempty=False)
        if "registration" not in b and "fiducials" not in b:
            raise c.error(key, "a layout needs a registration list, a fiducials list or both")
        layouts[name] = {}
        points[name] = {}
        for part in ("registration", "fiducials"):
            if part not in b:
                continue
            pkey = f"{key}.{part}"
            ids = b[part]
            if not isinstance(ids, list) or not ids or not all(isinstance(i, str) for i in ids):
                raise c.error(pkey, f"must be a non-empty list of point ids (strings), got {_fmt(ids)}")
            for j, pid in enumerate(ids):
                if pid not in pool:
                    raise c.error(
                        f"{pkey}[{j}]",
                        f"unknown id {pid!r}; ids come from [[registration]], [[fiducial]] and [[site]]",
                    )
                if pid in ids[:j]:
                    raise c.error(f"{pkey}[{j}]", f"duplicate id {pid!r}")
            np_ = NamedPoints(
                tuple(ids), np.array([pool[i][0] for i in ids]), np.array([pool[i][1] for i in ids])
            )
            if part == "registration":
                if len(ids) < 3:
                    raise c.error(pkey, f"{len(ids)} ids given, a registration needs at least 3 points")
                _check_spread(c, pkey, np_.positions)
            layouts[name][part] = tuple(ids)
            points[name][part] = np_
    return layouts, points


def _with_tool(model, table: dict, tool_mm: float):
    """The scene's `robot.tool_mm` is the tool of every kinematic robot term that does not give its own `dh`:
    the simulated arm then reaches the scene's points with its tool tip, as the scene describes."""
    import dataclasses

    from rrbc_core.simulation.errormodels import ErrorModel, Kinematic

    rows = table.get("robot", []) if isinstance(table, dict) else []
    terms = []
    for k, term in enumerate(model.robot):
        own_dh = k < len(rows) and isinstance(rows[k], dict) and "dh" in rows[k]
        if isinstance(term, Kinematic) and not own_dh:
            term = dataclasses.replace(term, dh=term.dh.with_tool(tool_mm))
        terms.append(term)
    return ErrorModel(robot=tuple(terms), sensor=model.sensor)


def _error_model(c: _Checker, table: dict):
    """Build the error model with the error-model module (imported lazily: it is optional for loading)."""
    try:
        from rrbc_core.simulation.errormodels import error_model_from_dict
    except ImportError as exc:  # pragma: no cover - only while the module is being written
        raise c.error("error_model", f"the error-model module is not available ({exc})") from None
    try:
        return error_model_from_dict(table, f"{c.source}: error_model")
    except InputError as exc:
        msg = " ".join(str(exc).split())
        if not msg.startswith(c.source):
            msg = f"{c.source}: error_model: {msg}"
        raise InputError(msg) from None


def default_scene_path() -> Path:
    """scenes/demo_workcell.toml in the repository (next to this package)."""
    p = Path(__file__).resolve().parents[2] / "scenes" / "demo_workcell.toml"
    if not p.is_file():
        raise InputError(f"{p}: the default scene is missing (expected scenes/demo_workcell.toml in the repository)")
    return p
