"""Where things can go in a user's cell: its mesh loaded and checked, points inside solids, the arm's reach, what
the sensor sees, marker locations sampled on the mesh's surfaces, points spread out.

Frames and units: robot base frame, mm (the mesh, the targets and everything placed are in the robot frame; the
robot's base is at the origin). Visibility and inside tests are `models.visibility`'s (open3d ray casting).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.io.mesh_file import (
    MESH_MAX_FACES,
    check_mesh_file,
)
from rrbc_core.models.kinematics import ROBOT_DH, UR5_TOOL_DOWN_SEED, reachable, tool_down
from rrbc_core.models.visibility import inside_solids, visible_points

METRES_BELOW_MM = 20.0  # a mesh whose whole extent is below this looks like metres
ON_SURFACE_LIFT_MM = 1.0  # a point on a surface is tested for "inside a solid" this far above it


def load_cell_mesh(path):
    """The cell's mesh (one Trimesh with its parts, robot frame, mm), or InputError: missing, unreadable, empty,
    too large, or looking like metres."""
    from rrbc_core.io.scene import _load_mesh_file

    p = Path(path)
    check_mesh_file(p)  # refused from its size and header, before it is parsed
    try:
        mesh = _load_mesh_file(p)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types for unreadable files
        msg = " ".join(str(exc).split())[:160]
        raise InputError(
            f"{p}: cannot read it as a mesh (STL, OBJ, PLY, GLB, 3MF): {type(exc).__name__}: {msg}"
        ) from None
    if len(mesh.faces) == 0:
        raise InputError(f"{p}: the mesh holds no triangles")
    if len(mesh.faces) > MESH_MAX_FACES:
        raise InputError(f"{p}: {len(mesh.faces)} triangles; at most {MESH_MAX_FACES} (decimate it first)")
    if not np.all(np.isfinite(mesh.vertices)):
        raise InputError(f"{p}: the mesh has non-finite vertex coordinates")
    extent = float(np.max(mesh.bounds[1] - mesh.bounds[0]))
    if extent < METRES_BELOW_MM:
        raise InputError(
            f"{p}: the whole mesh spans {extent:.3g} units: that looks like metres; export it in millimetres "
            "(scale by 1000)"
        )
    return mesh


def inside(mesh, points) -> np.ndarray:
    """(P,) bool: points (P, 3) inside a closed part of the mesh, tested `ON_SURFACE_LIFT_MM` above them (a marker
    on a surface is outside)."""
    p = np.asarray(points, float).reshape(-1, 3)
    if not len(p):
        return np.zeros(0, bool)
    return inside_solids(mesh, p + [0.0, 0.0, ON_SURFACE_LIFT_MM])


def reach(robot: str, tool_mm: float, points, joint_seed=UR5_TOOL_DOWN_SEED) -> np.ndarray:
    """(P,) bool: points the arm reaches with its tool pointing down (all True for a robot without kinematics)."""
    p = np.asarray(points, float).reshape(-1, 3)
    if robot not in ROBOT_DH:
        return np.ones(len(p), bool)
    return reachable(ROBOT_DH[robot].with_tool(tool_mm), p, tool_down(0.0), joint_seed)


def seen(mesh, sensor, points, tol_mm: float = 1.0) -> np.ndarray:
    """(P,) bool: points the sensor at `sensor` (3,) sees (visibility.visible_points)."""
    p = np.asarray(points, float).reshape(-1, 3)
    return visible_points(mesh, sensor, p, tol_mm) if len(p) else np.zeros(0, bool)


def spread(points, k: int, first: int = 0) -> np.ndarray:
    """Indices of `k` of `points` (P, 3) chosen far apart (farthest-point sampling from `first`)."""
    p = np.asarray(points, float).reshape(-1, 3)
    k = min(int(k), len(p))
    if k <= 0:
        return np.zeros(0, int)
    chosen = [int(first)]
    d = np.linalg.norm(p - p[first], axis=1)
    while len(chosen) < k:
        i = int(np.argmax(d))
        chosen.append(i)
        d = np.minimum(d, np.linalg.norm(p - p[i], axis=1))
    return np.array(chosen, int)


def surface_samples(mesh, lo, hi, spacing_mm: float, seed: int, up_min: float = 0.7, max_count: int = 200_000):
    """Points (S, 3) on the mesh's upward-facing surfaces (face normal z ≥ up_min) inside the box [lo, hi] (3,)
    each, about `spacing_mm` apart: trimesh.sample.sample_surface (seeded) over the upward faces that reach into
    the box, clipped to it, then one sample per spacing-sized cell."""
    import trimesh

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    normals = np.asarray(mesh.face_normals)
    tri = np.asarray(mesh.triangles)
    t_lo, t_hi = tri.min(axis=1), tri.max(axis=1)
    keep = (normals[:, 2] >= up_min) & np.all((t_hi >= lo) & (t_lo <= hi), axis=1)
    if not np.any(keep):
        return np.zeros((0, 3))
    sub = mesh.submesh([np.flatnonzero(keep)], append=True)
    if not isinstance(sub, trimesh.Trimesh) or sub.area <= 0:
        return np.zeros((0, 3))
    count = int(np.clip(8.0 * sub.area / spacing_mm**2, 64, max_count))
    pts, _ = trimesh.sample.sample_surface(sub, count, seed=seed)
    pts = np.asarray(pts, float)
    pts = pts[np.all((pts >= lo - 1e-6) & (pts <= hi + 1e-6), axis=1)]
    if not len(pts):
        return pts
    # one point per spacing-sized cell (the sample nearest the cell's centre): about `spacing_mm` apart
    cell = np.floor(pts / spacing_mm).astype(np.int64)
    off = np.linalg.norm(pts - (cell + 0.5) * spacing_mm, axis=1)
    order = np.lexsort((off, cell[:, 2], cell[:, 1], cell[:, 0]))
    c = cell[order]
    first = np.ones(len(c), bool)
    first[1:] = np.any(c[1:] != c[:-1], axis=1)
    return pts[order[first]]


def marker_candidates(
    mesh,
    targets,
    sensor,
    robot: str = "none",
    tool_mm: float = 0.0,
    margin_mm: float = 150.0,
    spacing_mm: float = 40.0,
    seed: int = 0,
    max_count: int = 250,
    clear_mm: float = 15.0,
) -> np.ndarray:
    """Places (C, 3) where a marker can go around `targets` (T, 3): on upward-facing surfaces within the targets'
    box widened by `margin_mm` sideways and 200 mm up and down (`surface_samples`, ~`spacing_mm` apart), more than
    `clear_mm` (in x-y) from every target, reachable (`reach`), seen from `sensor` and outside solids; at most
    `max_count`, spread out."""
    t = np.asarray(targets, float).reshape(-1, 3)
    lo = t.min(0) - [margin_mm, margin_mm, 200.0]
    hi = t.max(0) + [margin_mm, margin_mm, 200.0]
    cand = surface_samples(mesh, lo, hi, spacing_mm, seed)
    if len(cand) and clear_mm > 0:
        cand = cand[np.linalg.norm(cand[:, None, :2] - t[None, :, :2], axis=2).min(axis=1) > clear_mm]
    if len(cand):
        cand = cand[reach(robot, tool_mm, cand)]
    if len(cand):
        cand = cand[seen(mesh, sensor, cand) & ~inside(mesh, cand)]
    if len(cand) > max_count:
        cand = cand[np.sort(spread(cand, max_count))]
    return cand
