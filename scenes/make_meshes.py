"""Generate the meshes of the shipped scenes (deterministic; run from anywhere):

    .venv/bin/python scenes/make_meshes.py

writes scenes/meshes/demo_workcell.glb, breadboard_vanwyk2018.glb and peg_in_hole_cell.glb (robot frame, mm).

The static geometry (tables, plates, blocks, the robot base) is defined here. Everything whose position the
scene file states is read from the TOML, so mesh and scene cannot drift apart:
- the sensor body is placed BEHIND the sensor origin (negative sensor z), so rays from the origin never hit it;
- every fiducial gets an orange marker disc; a fiducial above the surface below it gets a post up to it;
- targets get dark discs (holes: booleans are unavailable, so holes are drawn as thin dark cylinders whose top
  lies 0.1 mm above the surface), except where the scene's geometry already carries them (peg tops).
Marker discs are 0.2 mm thick and half embedded in the surface they sit on, so a point on the surface is at
most 0.1 mm under a marker's top: visible with the default 1 mm tolerance of `visible_points`.
"""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from rrbc_core.io.scene import sensor_pose  # noqa: E402

MESHES = HERE / "meshes"

WOOD = (205, 170, 125, 255)
DARK_GREY = (90, 90, 90, 255)
UR_BLUE = (70, 120, 175, 255)
ALUMINIUM = (178, 182, 190, 255)
HOLE = (25, 25, 25, 255)
POST = (225, 225, 225, 255)
MARKER = (255, 140, 0, 255)
SENSOR = (35, 35, 40, 255)
GREEN = (70, 140, 70, 255)
STEEL = (150, 155, 165, 255)
BREADBOARD = (60, 62, 68, 255)


# ------------------------------------------------------------------------------------------------------
# primitives
# ------------------------------------------------------------------------------------------------------
def coloured(mesh: trimesh.Trimesh, rgba) -> trimesh.Trimesh:
    mesh.visual.face_colors = np.tile(np.array(rgba, dtype=np.uint8), (len(mesh.faces), 1))
    return mesh


def box(lo, hi, rgba) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    m = trimesh.creation.box(extents=hi - lo)
    m.apply_translation((lo + hi) / 2)
    return coloured(m, rgba)


def cyl(xy, z0, z1, radius, rgba, sections=32) -> trimesh.Trimesh:
    m = trimesh.creation.cylinder(radius=radius, height=z1 - z0, sections=sections)
    m.apply_translation([xy[0], xy[1], (z0 + z1) / 2])
    return coloured(m, rgba)


def disc(point, radius, rgba, sections=24, thickness=0.2) -> trimesh.Trimesh:
    """A thin cylinder centred on `point` (half embedded in the surface the point lies on)."""
    return cyl(point[:2], point[2] - thickness / 2, point[2] + thickness / 2, radius, rgba, sections)


def merge(meshes) -> trimesh.Trimesh:
    return trimesh.util.concatenate(list(meshes))


def table(x0, x1, y0, y1, thickness=40.0, height=750.0):
    top = box([x0, y0, -thickness], [x1, y1, 0.0], WOOD)
    legs = merge(
        box([x - 30, y - 30, -height], [x + 30, y + 30, -thickness], DARK_GREY)
        for x in (x0 + 50, x1 - 50)
        for y in (y0 + 50, y1 - 50)
    )
    return {"table": top, "table_legs": legs}


def robot_base():
    # UR5 base: 149 mm diameter; height up to the shoulder axis d1 = 89.159 mm
    return {"robot_base": cyl([0, 0], 0.0, 89.159, 74.5, UR_BLUE, sections=48)}


def sensor_body(sensor: dict, extents=(180.0, 50.0, 80.0), rgba=SENSOR) -> trimesh.Trimesh:
    """A box behind the sensor origin (sensor frame z in [-extents_z - 5, -5])."""
    pose = sensor_pose(sensor["position"], sensor["look_at"], sensor.get("up", [0, 0, 1]))
    ex = np.asarray(extents, float)
    m = trimesh.creation.box(extents=ex)
    m.apply_translation([0, 0, -ex[2] / 2 - 5.0])
    m.apply_transform(pose.as_matrix())
    return coloured(m, rgba)


def surface_below(static: list, point, floor=-1000.0) -> float:
    """Height of the first surface straight below `point` among the static meshes (floor if none)."""
    m = merge(static)
    origin = np.array([[point[0], point[1], point[2] + 0.5]])
    locs, _, _ = m.ray.intersects_location(origin, np.array([[0.0, 0.0, -1.0]]), multiple_hits=True)
    below = [loc[2] for loc in locs if loc[2] <= point[2] + 0.5]
    return max(below) if below else floor


def fiducial_markers(static: list, points, post_radius=8.0, marker_radius=5.0):
    posts, markers = [], []
    for p in points:
        base = surface_below(static, p)
        if p[2] - base > 1.0:
            posts.append(cyl(p[:2], base, p[2], post_radius, POST, sections=24))
        markers.append(disc(p, marker_radius, MARKER))
    out = {"fiducial_markers": merge(markers)}
    if posts:
        out["fiducial_posts"] = merge(posts)
    return out


def write(name: str, parts: dict) -> Path:
    scene = trimesh.Scene()
    for part, mesh in parts.items():
        scene.add_geometry(mesh, node_name=part, geom_name=part)
    MESHES.mkdir(exist_ok=True)
    path = MESHES / f"{name}.glb"
    path.write_bytes(scene.export(file_type="glb"))
    return path


# ------------------------------------------------------------------------------------------------------
# scene files
# ------------------------------------------------------------------------------------------------------
def read_scene(toml_name: str):
    doc = tomllib.loads((HERE / toml_name).read_text(encoding="utf-8"))
    sites = {s["id"]: np.array(s["position"], float) for s in doc.get("site", [])}

    def pos(block):
        if "position" in block:
            return np.array(block["position"], float)
        return sites[block.get("site", block["id"])]

    fid = [pos(b) for b in doc.get("fiducial", [])]
    tgt = {b["id"]: pos(b) for b in doc.get("target", [])}
    reg = {b["id"]: pos(b) for b in doc.get("registration", [])}
    return doc, sites, fid, tgt, reg


def demo_workcell() -> Path:
    doc, _, fid, tgt, _ = read_scene("demo_workcell.toml")
    parts = {}
    parts.update(table(-250.0, 950.0, -400.0, 400.0))
    parts.update(robot_base())
    # fixture plate 300 x 400 x 15 mm, top at z = 15
    parts["fixture_plate"] = box([325.0, -200.0, 0.0], [625.0, 200.0, 15.0], ALUMINIUM)
    # a parts feeder beside the robot (gives ICP more structure)
    parts["feeder"] = box([70.0, 220.0, 0.0], [230.0, 340.0, 80.0], GREEN)
    static = list(parts.values())
    parts["holes"] = merge(disc(p, 6.5, HOLE, sections=32) for p in tgt.values())
    parts.update(fiducial_markers(static, fid))
    # sensor on a mast standing on the floor behind the table corner; the arm and the sensor body lie above
    # and behind the sensor origin, where no ray of the sensor's field of view goes
    s = doc["sensor"]
    sx, sy, sz = s["position"]
    mast_xy = (sx + 80.0, sy - 70.0)
    parts["sensor_mast"] = cyl(mast_xy, -750.0, sz + 60.0, 30.0, DARK_GREY, sections=24)
    parts["sensor_arm"] = box(
        [min(sx, mast_xy[0]) - 15, min(sy, mast_xy[1]) - 15, sz + 40.0],
        [max(sx, mast_xy[0]) + 15, max(sy, mast_xy[1]) + 15, sz + 60.0],
        DARK_GREY,
    )
    parts["sensor_body"] = sensor_body(s)
    return write("demo_workcell", parts)


def breadboard_vanwyk2018() -> Path:
    """The test plate, the adjacent plate carrying the robot, the M6 hole grid, site markers and frame N.

    The "sensor" of this scene is frame N (ground truth), whose origin is the centre of the plate's corner hole
    at the plate surface. That hole is modelled as a real 6 mm square hole, 12 mm deep, so the sensor origin is
    in free space and straight lines from it to the sites (11 mm above the plate) touch nothing: everything
    drawn on the plate stays below those lines (hole and site markers at most 0.2 mm high; the frame N axes
    lie outside the quadrant of the plate that holds the sites)."""
    doc, sites, _, _, reg = read_scene("breadboard_vanwyk2018.toml")
    s = doc["sensor"]
    pose = sensor_pose(s["position"], s["look_at"], s.get("up", [0, 0, 1]))
    r, o = pose.rotation, pose.translation

    def n_box(lo_n, hi_n, rgba):  # an axis-aligned box given in frame N (N is axis-aligned with the robot frame)
        cc = np.array([lo_n, hi_n], float) @ r.T + o
        return box(cc.min(0), cc.max(0), rgba)

    parts = {}
    # test plate 900 x 600 x 60 mm: in N, x in [-12.5, 887.5], y in [-12.5, 587.5], top at z = 0; the corner
    # hole at the N origin is open (5 boxes around and under a 6 x 6 x 12 mm hole)
    h, x0, x1, y0, y1, zb = 3.0, -12.5, 887.5, -12.5, 587.5, -60.0
    parts["breadboard_plate"] = merge(
        [
            n_box([h, y0, zb], [x1, y1, 0.0], BREADBOARD),
            n_box([x0, y0, zb], [-h, y1, 0.0], BREADBOARD),
            n_box([-h, h, zb], [h, y1, 0.0], BREADBOARD),
            n_box([-h, y0, zb], [h, -h, 0.0], BREADBOARD),
            n_box([-h, -h, zb], [h, h, -12.0], BREADBOARD),
        ]
    )
    # the adjacent plate the robot is mounted on (same size, beside the test plate's long side)
    lo = (np.array([[x0, y0, zb], [x1, y1, 0.0]]) @ r.T + o).min(0)
    hi = (np.array([[x0, y0, zb], [x1, y1, 0.0]]) @ r.T + o).max(0)
    parts["adjacent_plate"] = box([lo[0] - 600.0 - 1.0, lo[1], zb], [lo[0] - 1.0, hi[1], 0.0], BREADBOARD)
    parts.update(robot_base())
    # M6 holes on the 25 mm grid: thin dark hexagonal prisms (the open corner hole excepted)
    grid = np.array([[i * 25.0, j * 25.0, 0.0] for i in range(36) for j in range(24) if i or j]) @ r.T + o
    parts["m6_holes"] = merge(disc(p, 3.0, HOLE, sections=6) for p in grid)
    # site markers: orange rings on the plate around the sites' holes (the site point itself is the seated
    # stylus tip, 11 mm above the plate); registration points that are not sites get the same ring
    seats = {tuple(np.round(p, 6)) for p in list(sites.values()) + list(reg.values())}
    parts["site_markers"] = merge(
        coloured(trimesh.creation.annulus(4.0, 8.0, 0.2, sections=24), MARKER).apply_translation([p[0], p[1], 0.0])
        for p in map(np.array, sorted(seats))
    )
    # frame N axes, 100 mm, x red / y green / z blue, drawn beside the origin on the side away from the sites
    parts["frame_N_axes"] = merge(
        [
            n_box([0.0, -10.0, 0.0], [100.0, -6.0, 0.2], (220, 40, 40, 255)),
            n_box([-10.0, 0.0, 0.0], [-6.0, 100.0, 0.2], (40, 180, 40, 255)),
            n_box([-10.0, -10.0, 0.0], [-6.0, -6.0, 100.0], (40, 80, 220, 255)),
        ]
    )
    return write("breadboard_vanwyk2018", parts)


def peg_in_hole_cell() -> Path:
    doc, _, fid, tgt, _ = read_scene("peg_in_hole_cell.toml")
    parts = {}
    parts.update(table(-250.0, 950.0, -400.0, 400.0))
    parts.update(robot_base())
    # receiving block with 4 holes (top z = 50) and a peg tray (top z = 20) with 4 pegs (tops z = 80)
    parts["hole_block"] = box([400.0, -225.0, 0.0], [600.0, -75.0, 50.0], ALUMINIUM)
    parts["peg_tray"] = box([400.0, 75.0, 0.0], [600.0, 225.0, 20.0], GREEN)
    peg_r = 12.675 / 2  # NISTIR 8198r1 peg, 12.675 mm (0.499 in)
    pegs = {k: p for k, p in tgt.items() if k.startswith("PEG")}
    holes = {k: p for k, p in tgt.items() if not k.startswith("PEG")}
    parts["pegs"] = merge(cyl(p[:2], 20.0, p[2], peg_r, STEEL, sections=32) for p in pegs.values())
    static = list(parts.values())
    parts["holes"] = merge(disc(p, peg_r + 0.1, HOLE, sections=32) for p in holes.values())
    parts.update(fiducial_markers(static, fid))
    # motion-capture "sensor": body behind its origin, hung from an overhead beam
    s = doc["sensor"]
    sx, sy, sz = s["position"]
    parts["sensor_body"] = sensor_body(s, extents=(120.0, 120.0, 90.0))
    parts["overhead_beam"] = box([-300.0, sy - 40.0, sz + 160.0], [1100.0, sy + 40.0, sz + 220.0], DARK_GREY)
    parts["sensor_hanger"] = box([sx - 10.0, sy - 10.0, sz + 110.0], [sx + 10.0, sy + 10.0, sz + 160.0], DARK_GREY)
    return write("peg_in_hole_cell", parts)


def main() -> None:
    for make in (demo_workcell, breadboard_vanwyk2018, peg_in_hole_cell):
        path = make()
        print(f"{path.relative_to(HERE.parent)}: {path.stat().st_size / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
