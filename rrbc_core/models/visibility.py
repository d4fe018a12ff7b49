"""Line-of-sight checks against a scene mesh with open3d's RaycastingScene.

`visible_points(mesh, sensor_origin, points)` casts one ray from the sensor origin towards each point (one
vectorised `cast_rays` call) and calls a point visible when the first hit along its ray is not closer than the
point's distance minus `tol_mm`: a point sitting on a surface that faces the sensor is visible, a point behind
(or inside) a solid is not. `occluded_by` names the part that blocks each point. `inside_solids` tells which
points lie inside a closed part (open3d `compute_occupancy`, part by part, so overlapping parts do not break the
inside test).

Precision: open3d casts in float32. The mesh and rays are shifted so that the sensor sits at the origin before
the conversion, which keeps hit distances accurate to ~1e-4 mm over a few metres.
"""

from __future__ import annotations

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.points import as_points


def _mesh_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(getattr(mesh, "vertices", None) if mesh is not None else None, dtype=float)
    f = np.asarray(getattr(mesh, "faces", None) if mesh is not None else None)
    if v.ndim != 2 or v.shape[-1:] != (3,) or f.ndim != 2 or f.shape[-1:] != (3,) or len(f) == 0:
        raise InputError("visibility: the mesh must be a triangle mesh with at least one face (trimesh.Trimesh)")
    return v, f


def _points(points, what: str = "points") -> np.ndarray:
    return as_points(points, f"visibility: {what}", single=True, frame="robot frame, mm")


def _origin(sensor_origin) -> np.ndarray:
    o = np.asarray(sensor_origin, dtype=float).reshape(-1)
    if o.shape != (3,) or not np.all(np.isfinite(o)):
        raise InputError("visibility: the sensor origin must be 3 finite coordinates (robot frame, mm)")
    return o


def raycasting_scene(vertices: np.ndarray, faces: np.ndarray, shift: np.ndarray):
    """An open3d RaycastingScene of the triangles (vertices − shift), float32."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.ascontiguousarray(vertices - shift, dtype=np.float32)),
        o3d.core.Tensor(np.ascontiguousarray(faces, dtype=np.uint32)),
    )
    return scene


def cast_from(mesh, origin, directions) -> tuple[np.ndarray, np.ndarray]:
    """First hits of rays from one origin along unit `directions` (R, 3): (distance (R,), face index (R,)).

    Distance is inf and face index -1 where a ray hits nothing.
    """
    import open3d as o3d

    v, f = _mesh_arrays(mesh)
    o = _origin(origin)
    d = np.asarray(directions, dtype=float).reshape(-1, 3)
    scene = raycasting_scene(v, f, o)
    rays = np.zeros((len(d), 6), dtype=np.float32)
    rays[:, 3:] = d
    ans = scene.cast_rays(o3d.core.Tensor(rays))
    t = ans["t_hit"].numpy().astype(float)
    prim = ans["primitive_ids"].numpy().astype(np.int64)
    miss = ~np.isfinite(t)
    prim[miss] = -1
    return t, prim


def _cast_to_points(mesh, sensor_origin, points, tol_mm):
    o = _origin(sensor_origin)
    p = _points(points)
    tol = float(tol_mm)
    if not np.isfinite(tol) or tol < 0:
        raise InputError(f"visibility: tol_mm must be a finite number >= 0, got {tol_mm!r}")
    delta = p - o
    dist = np.linalg.norm(delta, axis=1)
    at_origin = dist < 1e-9
    dirs = np.where(at_origin[:, None], np.array([0.0, 0.0, 1.0]), delta / np.where(at_origin, 1.0, dist)[:, None])
    t, prim = cast_from(mesh, o, dirs)
    blocked = (t < dist - tol) & ~at_origin
    return blocked, t, prim, dist


def visible_points(mesh, sensor_origin, points, tol_mm: float = 1.0) -> np.ndarray:
    """Bool (P,): True where the straight line from `sensor_origin` to the point is free of the mesh, except
    for the last `tol_mm` before the point (so points on a surface facing the sensor count as visible).

    mesh: trimesh.Trimesh (robot frame, mm); sensor_origin (3,) and points (P, 3) in the robot frame.
    """
    blocked, _, _, _ = _cast_to_points(mesh, sensor_origin, points, tol_mm)
    return ~blocked


def part_of_face(mesh, face_index: int) -> str:
    """Name of the part holding a face, from `mesh.metadata["parts"]` ((name, first, end) triples, as written
    by `Scene.load_mesh`); "face <i>" when the mesh carries no part list."""
    for name, start, stop in (getattr(mesh, "metadata", None) or {}).get("parts", []):
        if start <= face_index < stop:
            return str(name)
    return f"face {face_index}"


def occluded_by(mesh, sensor_origin, points, tol_mm: float = 1.0) -> list:
    """Per point: None if visible, else (part name, distance in mm from the sensor to the blocking surface)."""
    blocked, t, prim, _ = _cast_to_points(mesh, sensor_origin, points, tol_mm)
    return [(part_of_face(mesh, int(prim[i])), float(t[i])) if blocked[i] else None for i in range(len(blocked))]


def inside_solids(mesh, points, nsamples: int = 3) -> np.ndarray:
    """Bool (P,): which points lie inside a closed part of the mesh.

    Uses open3d `compute_occupancy` (ray-parity with `nsamples` rays, majority vote) per part listed in
    `mesh.metadata["parts"]` (the whole mesh if there is no list). Parts must be closed surfaces; overlapping
    parts are fine because each part is tested alone. Open parts (single-sided decals) give unreliable answers.
    """
    import open3d as o3d

    v, f = _mesh_arrays(mesh)
    p = _points(points)
    parts = (getattr(mesh, "metadata", None) or {}).get("parts") or [("mesh", 0, len(f))]
    shift = p.mean(axis=0) if len(p) else np.zeros(3)
    q = o3d.core.Tensor(np.ascontiguousarray(p - shift, dtype=np.float32))
    inside = np.zeros(len(p), dtype=bool)
    n = int(nsamples) if int(nsamples) % 2 == 1 else int(nsamples) + 1
    for _, start, stop in parts:
        if stop <= start:
            continue
        pf = f[start:stop]
        used, local = np.unique(pf, return_inverse=True)
        scene = raycasting_scene(v[used], local.reshape(-1, 3), shift)
        inside |= scene.compute_occupancy(q, nsamples=n).numpy().astype(bool)
    return inside
