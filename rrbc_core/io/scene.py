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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform
from rrbc_core.models.errormodels import ErrorModel

#: Robot models the scene format accepts: arms the kinematics module implements (kinematics.ROBOT_DH), and "none",
#: a robot without kinematics (its bias is then given as a field, e.g. smooth_field; no kinematic term allowed).
ROBOT_MODELS = ("ur5", "ur10", "none")
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

    def subset(self, ids) -> NamedPoints:
        idx = [self.index(i) for i in ids]
        yaw = None if self.tool_yaw_deg is None else self.tool_yaw_deg[idx]
        return NamedPoints(tuple(self.ids[i] for i in idx), self.positions[idx], yaw)

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
    error_model: ErrorModel
    error_model_table: dict
    seed: int = 0
    check_points_per_target: int = DEFAULT_CHECK_POINTS_PER_TARGET
    measurement_interval_s: float = DEFAULT_MEASUREMENT_INTERVAL_S
    layout: str | None = None  # name of the layout applied by with_layout, None for the file's own points
    distance_origin: np.ndarray = field(
        default_factory=lambda: np.zeros(3)
    )  # "distance from the frame origin" is from here
    sensor_look_at: np.ndarray | None = None
    #: `robot.urdf` (a path, or a packaged name) and `robot.tip`: the robot drawn for `robot_model` "none"
    robot_urdf: Path | str | None = None
    robot_tip: str | None = None
    _layout_points: dict = field(default_factory=dict, repr=False)
    _mesh: Any = field(default=None, repr=False)  # a trimesh.Trimesh given in memory, else read from mesh_path

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

    def with_layout(self, name: str) -> Scene:
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
    """Load any file trimesh reads and concatenate it into one Trimesh (scene graph transforms applied). A binary
    STL, an OBJ, an OFF and a 3MF are read by rrbc's own readers where they take the file (`io.mesh_file`,
    `io.mesh_text`, `io.mesh_3mf`: bounded memory), the rest by trimesh without its processing.

    Raises ValueError/OSError-derived exceptions from trimesh; the loader wraps them."""
    import trimesh

    from rrbc_core.io.mesh_file import check_mesh_file, read_binary_stl

    check_mesh_file(path)  # too large, or declaring too many triangles: refused before it is parsed
    if Path(path).suffix.lower() == ".stl":  # binary STL: read in bounded memory (issue 42), one part
        stl = read_binary_stl(path)
        if stl is not None:
            if not len(stl[1]):
                raise ValueError("the file holds no triangles")
            single = trimesh.Trimesh(stl[0], stl[1], process=False)
            single.metadata["parts"] = [(Path(path).name, 0, len(stl[1]))]
            return single
    suffix = Path(path).suffix.lower()
    if suffix in (".obj", ".off", ".3mf"):  # read in bounded memory where our reader takes the file (issue 42)
        from rrbc_core.io.mesh_3mf import read_3mf
        from rrbc_core.io.mesh_text import read_obj, read_off

        read = {".obj": read_obj, ".off": read_off, ".3mf": read_3mf}[suffix](path)
        if read is not None:
            if not len(read[1]):
                raise ValueError("the file holds no triangles")
            single = trimesh.Trimesh(read[0], read[1], process=False)
            single.metadata["parts"] = read[2] if len(read) == 3 else [(Path(path).name, 0, len(read[1]))]
            return single
    # process=False: the file's own vertices, not merged or checked by trimesh (whose processing held several
    # copies of the mesh and its derived arrays at once: a GLB peaked at 8x its size, issue 42)
    loaded: Any = trimesh.load(str(path), force="scene", process=False)  # a trimesh.Scene (force="scene")
    parts, meshes = [], []
    start = 0
    graph = loaded.graph
    nodes = list(graph.nodes_geometry)
    for node in nodes:
        transform, geom_name = graph[node]
        geom = loaded.geometry.get(geom_name)
        if not isinstance(geom, trimesh.Trimesh) or len(geom.faces) == 0:
            continue
        identity = np.array_equal(transform, np.eye(4))
        m = geom if (len(nodes) == 1 and identity) else geom.copy()  # the one instance as it is: no copy
        if not identity:
            m.apply_transform(transform)
        m._cache.clear()  # normals and the like computed while reading: recomputed when asked for
        meshes.append(m)
        parts.append((str(node), start, start + len(m.faces)))
        start += len(m.faces)
    if not meshes:
        raise ValueError("the file holds no triangles")
    mesh = trimesh.util.concatenate(meshes) if len(meshes) > 1 else meshes[0]
    mesh.metadata["parts"] = parts
    return mesh


def default_scene_path() -> Path:
    """The bundled default scene, scenes/demo_workcell.toml in the repository.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        The file is missing (the package was installed without its repository).
    """
    p = Path(__file__).resolve().parents[2] / "scenes" / "demo_workcell.toml"
    if not p.is_file():
        raise InputError(f"{p}: the default scene is missing (expected scenes/demo_workcell.toml in the repository)")
    return p
