"""`rrbc scene new`: a complete, documented scene from a cell mesh and a list of targets (docs/scene-new.md).

Frames and units: the mesh and the targets are in the robot base frame, mm; the robot's base is at the origin.
What is chosen, in order (each choice is written as a comment into the scene):

1. Checks: the mesh loads and is in mm; every target lies outside the solids and within the arm's reach (tool
   pointing down; not checked for a robot without kinematics).
2. The sensor: `--sensor X,Y,Z` or the first of eight places around the targets (1.2 m above them, 0.9 m out)
   that sees the most targets; it looks at the targets' centre.
3. Candidate fiducial locations: points on the mesh's upward-facing surfaces around the targets (their box
   widened by `margin`), ~`spacing` apart, reachable, seen by the sensor, outside solids and clear of the targets.
4. Registration points: up to 6 well-spread points in free space over the work (80 and 280 mm above the
   targets' top), reachable, seen and outside solids.
5. A default error model for the robot and sensor type (stated in the file).
6. The initial fiducials: the planner (`analysis.planning.plan`, `cover_targets=True`) picks `fiducials` of the
   candidates, preferring sets that hold the targets inside their hull (`interpolation.hull`, the one coverage
   test), then the lowest predicted RMST; which targets are inside is reported and written into the scene.

The file is written atomically (a temporary file in the output directory, loaded back with `load_scene` as a
check, then renamed): a refusal or a failure leaves nothing behind.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rrbc_core.authoring import cell_geometry as cg
from rrbc_core.authoring.targets_file import read_targets
from rrbc_core.errors import InputError

ROBOTS = ("ur5", "ur10", "none")
SENSOR_HEIGHT_MM = 1200.0
SENSOR_OUT_MM = 900.0
MAX_CANDIDATES = 250
MIN_CANDIDATES = 4


@dataclass(frozen=True)
class NewSceneOptions:
    """Choices of `rrbc scene new` (module docstring). Lengths in mm."""

    robot: str = "ur5"
    sensor: tuple | None = None
    sensor_kind: str = "stereo"
    tool_mm: float = 100.0
    fiducials: int = 6
    spacing_mm: float = 40.0
    margin_mm: float = 150.0
    seed: int = 0
    name: str | None = None
    urdf: str | None = None  # the robot's URDF (a file in the scene's folder or below, or a packaged name)
    tip: str | None = None  # ... its tool link

    def __post_init__(self):
        if self.robot not in ROBOTS:
            raise InputError(f"--robot must be one of {', '.join(ROBOTS)}, got {self.robot!r}")
        if self.urdf is not None and self.robot != "none":
            raise InputError(
                f"--urdf is for a robot the {self.robot.upper()}'s kinematics do not model: leave --robot out (or "
                "give --robot none); a UR5 or UR10 is drawn from its own description"
            )
        if self.tip is not None and self.urdf is None:
            raise InputError("--tip names a link of the robot's URDF: give --urdf")
        if self.sensor is not None:
            s = np.asarray(self.sensor, float).reshape(-1)
            if s.shape != (3,) or not np.all(np.isfinite(s)) or np.abs(s).max() > 1e6:
                raise InputError("--sensor must be three finite numbers X,Y,Z in mm (robot frame)")
        if not (1 <= int(self.fiducials) <= 50):
            raise InputError(f"--fiducials must be from 1 to 50, got {self.fiducials}")


@dataclass(frozen=True, eq=False)
class NewScene:
    """What was written: the scene file, the TOML text, and counts and choices for the summary line."""

    path: Path
    text: str
    summary: dict = field(default_factory=dict)


def _fmt(v) -> str:
    return "[" + ", ".join(f"{float(x):.3f}".rstrip("0").rstrip(".") for x in np.asarray(v).reshape(-1)) + "]"


def _choose_sensor(mesh, targets: np.ndarray, given) -> tuple[np.ndarray, str]:
    centre = 0.5 * (targets.min(0) + targets.max(0))
    if given is not None:
        return np.asarray(given, float), "given with --sensor"
    best, best_n = None, -1
    for k in range(8):
        a = -np.pi / 4 + k * np.pi / 4
        p = centre + np.array([SENSOR_OUT_MM * np.cos(a), SENSOR_OUT_MM * np.sin(a), SENSOR_HEIGHT_MM])
        if cg.inside(mesh, p[None])[0]:
            continue
        n = int(cg.seen(mesh, p, targets).sum())
        if n > best_n:
            best, best_n = p, n
    if best is None:
        raise InputError("found no place for the sensor outside the mesh's solids; give one with --sensor X,Y,Z")
    return (
        best,
        f"chosen: of eight places {SENSOR_HEIGHT_MM:.0f} mm above and {SENSOR_OUT_MM:.0f} mm out from the targets, the one seeing the most ({best_n} of {len(targets)})",
    )


def _mesh_beside(mesh_path: Path, folder: Path) -> str:
    """The scene's relative mesh path. A scene opens only meshes in its own folder or below (scene_toml), so a mesh
    elsewhere is copied beside the scene (atomically); an existing different file of that name is refused."""
    src, folder = mesh_path.resolve(), folder.resolve()
    if src.is_relative_to(folder):
        return src.relative_to(folder).as_posix()
    dst = folder / src.name
    if dst.exists():
        if dst.is_file() and dst.read_bytes() == src.read_bytes():
            return dst.name
        raise InputError(
            f"{mesh_path}: the scene's folder already holds another {src.name}; put the mesh beside --out, or rename it"
        )
    fd, tmp = tempfile.mkstemp(prefix=".rrbc-mesh-", dir=str(folder))
    os.close(fd)
    try:
        shutil.copyfile(src, tmp)
        os.replace(tmp, dst)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return dst.name


def new_scene(mesh_path, targets_path, out_path, options: NewSceneOptions | None = None) -> NewScene:
    """Write a complete scene for the cell (module docstring); returns what was written. InputError for bad
    input, with nothing written."""
    opt = options or NewSceneOptions()
    out = _checked_out(out_path)
    urdf_rel = _urdf_beside(opt.urdf, out.parent)  # checked before anything is written
    tl = read_targets(targets_path)
    mesh = cg.load_cell_mesh(mesh_path)
    t = tl.positions
    bad = np.flatnonzero(cg.inside(mesh, t))
    if len(bad):
        names = ", ".join(f"{tl.ids[i]} at {_fmt(t[i])}" for i in bad[:5])
        raise InputError(f"{tl.source}: target(s) inside a solid of the mesh: {names}; targets sit on surfaces")
    bad = np.flatnonzero(~cg.reach(opt.robot, opt.tool_mm, t))
    if len(bad):
        names = ", ".join(f"{tl.ids[i]} at {_fmt(t[i])}" for i in bad[:5])
        raise InputError(
            f"{tl.source}: target(s) outside the {opt.robot.upper()}'s reach from its base at the origin (tool "
            f"{opt.tool_mm:g} mm pointing down): {names}; give targets in the robot's base frame, mm"
        )
    return _compose(mesh, Path(mesh_path), tl, out, opt, urdf_rel, plan_fiducials=True)


def empty_scene(mesh_path, out_path, options: NewSceneOptions | None = None) -> NewScene:
    """An empty start on a cell mesh (the app's *New cell from this mesh*): no fiducials, one target where the arm
    can work - the reachable point on an upward-facing surface nearest the middle of those points, outside solids
    - and, as `new_scene` chooses them, the sensor, registration points over it and candidate fiducial locations
    around it (none needed). The user then adds, moves and deletes points. Same checks and atomic write as
    `new_scene`; InputError (nothing written) when no upward surface lies within the arm's reach."""
    from rrbc_core.authoring.targets_file import DEFAULT_REGION_MM, TargetList

    opt = options or NewSceneOptions()
    out = _checked_out(out_path)
    urdf_rel = _urdf_beside(opt.urdf, out.parent)
    mesh = cg.load_cell_mesh(mesh_path)
    lo, hi = np.asarray(mesh.bounds, float)
    spacing = float(np.clip(np.linalg.norm(hi - lo) / 60.0, 5.0, 100.0))
    pts = cg.surface_samples(mesh, lo - 1.0, hi + 1.0, spacing, opt.seed, max_count=20_000)
    if len(pts):  # the point sits on the surface: its marker centre a hair above it, in free space
        pts = pts + [0.0, 0.0, 1.0]
        pts = pts[cg.reach(opt.robot, opt.tool_mm, pts)]
    if len(pts):
        pts = pts[~cg.inside(mesh, pts)]
    if not len(pts):
        raise InputError(
            f"{mesh_path}: no upward-facing surface of the mesh lies within the {opt.robot.upper()}'s reach from its "
            f"base at the origin (tool {opt.tool_mm:g} mm pointing down); give the mesh in the robot's base frame, mm"
        )
    middle = np.median(pts, axis=0)
    target = pts[int(np.argmin(np.linalg.norm(pts[:, :2] - middle[:2], axis=1)))]
    tl = TargetList(("T1",), target[None], np.array([DEFAULT_REGION_MM]), str(mesh_path))
    return _compose(mesh, Path(mesh_path), tl, out, opt, urdf_rel, plan_fiducials=False)


def _checked_out(out_path) -> Path:
    out = Path(out_path)
    if not out.name.endswith(".toml"):
        raise InputError(f"--out {out}: the scene file must end in .toml")
    if not out.parent.is_dir():
        raise InputError(f"--out {out}: directory {out.parent} does not exist")
    if out.exists() and not out.is_file():
        raise InputError(f"--out {out}: exists and is not a regular file")
    return out


def _compose(mesh, mesh_path: Path, tl, out: Path, opt: NewSceneOptions, urdf_rel, plan_fiducials: bool) -> NewScene:
    """The sensor, candidates and registration points for the targets `tl`, then (`plan_fiducials`) the planned
    first fiducials; the scene written atomically to `out`."""
    from rrbc_core.analysis.planning import plan
    from rrbc_core.io.scene_toml import load_scene

    t = tl.positions
    sensor, sensor_why = _choose_sensor(mesh, t, opt.sensor)
    look = 0.5 * (t.min(0) + t.max(0))
    hidden = [tl.ids[i] for i in np.flatnonzero(~cg.seen(mesh, sensor, t))]

    # candidates on surfaces around the targets
    cand = cg.marker_candidates(
        mesh, t, sensor, opt.robot, opt.tool_mm, opt.margin_mm, opt.spacing_mm, opt.seed, MAX_CANDIDATES
    )
    if plan_fiducials and len(cand) < MIN_CANDIDATES:
        raise InputError(
            f"{mesh_path}: found only {len(cand)} usable fiducial locations on upward-facing surfaces within "
            f"{opt.margin_mm:g} mm of the targets (reachable, seen by the sensor at {_fmt(sensor)}, outside solids); "
            "move the sensor (--sensor) or check the mesh and the targets' frame"
        )

    # registration points in free space over the work
    top = float(t[:, 2].max())
    lo, hi = t.min(0) - opt.margin_mm, t.max(0) + opt.margin_mm
    xs = np.linspace(lo[0], hi[0], 3)
    ys = np.linspace(lo[1], hi[1], 3)
    grid = np.array([[x, y, top + h] for h in (80.0, 280.0) for x in xs for y in ys])
    ok = cg.reach(opt.robot, opt.tool_mm, grid) & cg.seen(mesh, sensor, grid) & ~cg.inside(mesh, grid)
    grid = grid[ok]
    if len(grid) < 4:
        raise InputError(
            f"{mesh_path}: only {len(grid)} places for registration points over the work are reachable, seen and "
            "free (at least 4 needed); move the sensor (--sensor) or the targets"
        )
    reg = grid[cg.spread(grid, 6)]

    # write a scene without fiducials, plan the first fiducials from the candidates, write the scene
    fd, tmp = tempfile.mkstemp(prefix=".rrbc-scene-", suffix=".toml", dir=str(out.parent))
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        mesh_rel = _mesh_beside(Path(mesh_path), out.parent)
        parts = dict(
            urdf_rel=urdf_rel,
            opt=opt,
            tl=tl,
            mesh_rel=mesh_rel,
            sensor=sensor,
            look=look,
            sensor_why=sensor_why,
            hidden=hidden,
            reg=reg,
            cand=cand,
            name=opt.name or out.stem,
            fiducials_planned=plan_fiducials,
        )
        tmp_path.write_text(_toml(**parts, fiducials=np.zeros((0, 3)), plan_note=""), encoding="utf-8")
        scene = load_scene(tmp_path)
        fids, note, planned = np.zeros((0, 3)), "", {}
        if plan_fiducials:
            result = plan(scene, add=int(opt.fiducials), seed=opt.seed, cover_targets=True)
            fids = np.asarray(result.suggested, float).reshape(-1, 3)
            chosen = set(result.suggested_ids)
            rest = np.array([p for i, p in zip(scene.candidates.ids, scene.candidates.positions) if i not in chosen])
            parts["cand"] = rest.reshape(-1, 3)
            pr = result.predicted_after
            inside = np.asarray(result.inside_after, bool)
            covered_ids = [pid for pid, ok in zip(scene.target_ids, inside) if ok]
            outside_ids = [pid for pid, ok in zip(scene.target_ids, inside) if not ok]
            note = (
                f"planned by `rrbc plan` (seed {opt.seed}) from {len(cand)} candidates, targets inside their hull "
                f"first, then the predicted RMST: {len(covered_ids)} of {len(inside)} targets inside their hull"
                + (f" (outside: {', '.join(outside_ids)})" if outside_ids else "")
                + f"; predicted RMST over the targets' regions rigid {pr.rigid_mm:.3f} mm, RRBC {pr.rrbc_mm:.3f} mm "
                "(first-order prediction)"
            )
            planned = {
                "predicted_rmst_mm": {"rigid": float(pr.rigid_mm), "rrbc": float(pr.rrbc_mm)},
                "targets_inside_hull": covered_ids,
                "targets_outside_hull": outside_ids,
                "region_coverage": {pid: float(c) for pid, c in zip(scene.target_ids, result.coverage_after)},
            }
        text = _toml(**parts, fiducials=fids, plan_note=note)
        tmp_path.write_text(text, encoding="utf-8")
        load_scene(tmp_path)  # the file we hand over loads
        os.replace(tmp_path, out)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()
    summary = {
        "scene": str(out),
        "targets": len(tl.ids),
        "registration": len(reg),
        "fiducials": len(fids),
        "candidates": len(parts["cand"]),
        "sensor": [float(v) for v in sensor],
        "hidden_targets": hidden,
        **planned,
    }
    return NewScene(out, text, summary)


def _error_model(robot: str, kind: str, seed: int) -> tuple[dict, list[str]]:
    """The default [error_model] table for the robot and sensor, and the comment stating it."""
    noise = {"type": "isotropic_noise", "sigma_mm": 0.03}
    if robot in ("ur5", "ur10"):
        robot_terms = [{"type": "kinematic", "seed": int(seed)}, noise]
        said = [
            f"Robot: the {robot.upper()}'s kinematic (DH-parameter) error - joint offsets 0.1 deg, link lengths 0.2 mm,",
            "twists 0.05 deg, one random robot drawn with this seed - and repeatability noise 0.03 mm (1 sigma per axis).",
        ]
    else:
        robot_terms = [{"type": "smooth_field", "rms_mm": 0.5, "length_mm": 300.0, "seed": int(seed)}, noise]
        said = [
            "Robot without kinematics: its bias is a smooth random field, 0.5 mm RMS, correlation length 300 mm,",
            "plus repeatability noise 0.03 mm (1 sigma per axis).",
        ]
    if kind == "stereo":
        sensor_terms = [{"type": "anisotropic_noise", "sigma_perp_mm": 0.02, "sigma_along_mm": 0.06}]
        said.append("Sensor (stereo): noise 0.02 mm across the line of sight, 0.06 mm along it (1 sigma).")
    else:
        sensor_terms = [{"type": "isotropic_noise", "sigma_mm": 0.05}]
        said.append(f"Sensor ({kind}): isotropic noise 0.05 mm (1 sigma per axis).")
    return {"robot": robot_terms, "sensor": sensor_terms}, said


def _urdf_beside(urdf: str | None, folder: Path) -> str | None:
    """How the scene names the robot's URDF: a packaged name as it is, a file by its path from the scene's folder
    (it must lie there or below, with its meshes). InputError otherwise."""
    from rrbc_core.models.urdf import PACKAGED

    if urdf is None or urdf in PACKAGED:
        return urdf
    p = Path(urdf).resolve()
    if not p.is_file():
        raise InputError(f"--urdf {urdf}: no such file")
    base = folder.resolve()
    if base not in p.parents:
        raise InputError(
            f"--urdf {urdf}: the scene names its robot by a path inside its own folder: write the scene (--out) in "
            f"{p.parent} or above it, where the URDF's meshes are"
        )
    return p.relative_to(base).as_posix()


def _toml(
    opt,
    tl,
    mesh_rel,
    sensor,
    look,
    sensor_why,
    hidden,
    reg,
    cand,
    name,
    fiducials,
    plan_note,
    urdf_rel=None,
    fiducials_planned=True,
) -> str:
    from rrbc_core.io.scene_write import SceneSpec, scene_toml

    error_model, em_said = _error_model(opt.robot, opt.sensor_kind, opt.seed)
    sensor_said = [f"Sensor: {sensor_why}; it looks at the targets' centre."]
    if hidden:
        sensor_said.append(f"Hidden from it by the mesh: {', '.join(hidden)} (move it with --sensor).")
    spec = SceneSpec(
        name=name,
        description=(
            f"{len(tl.ids)} targets from {Path(tl.source).name}; generated by rrbc scene new"
            if fiducials_planned
            else f"a new cell on {Path(mesh_rel).name}: add fiducials and targets"
        ),
        mesh=mesh_rel,
        seed=int(opt.seed),
        robot_model=opt.robot,
        tool_mm=float(opt.tool_mm),
        robot_urdf=urdf_rel,
        robot_tip=opt.tip,
        sensor_kind=opt.sensor_kind,
        sensor_position=sensor,
        sensor_look_at=look,
        registration=(tuple(f"R{i + 1}" for i in range(len(reg))), reg),
        fiducials=(tuple(f"F{i + 1}" for i in range(len(fiducials))), fiducials),
        candidates=(tuple(f"C{i + 1:03d}" for i in range(len(cand))), cand),
        targets=[
            (pid, p, {"kind": "box", "size": [float(r)] * 3}) for pid, p, r in zip(tl.ids, tl.positions, tl.region_mm)
        ],
        error_model=error_model,
        comments={
            "header": [
                (
                    f"Written by `rrbc scene new` from {Path(tl.source).name} and {Path(mesh_rel).name}. Robot base "
                    "frame, mm;"
                    if fiducials_planned
                    else f"Written by rrbc (a new cell on {Path(mesh_rel).name}). Robot base frame, mm;"
                ),
                "the robot's base is at the origin. Format: scenes/README.md; how each part was chosen: "
                "docs/scene-new.md.",
            ],
            "sensor": sensor_said,
            "registration": [
                "Registration points: well-spread points in free space 80 and 280 mm above the targets' top,",
                "reachable, seen by the sensor, outside solids.",
            ],
            "fiducial": [f"Fiducials: {plan_note}."] if len(fiducials) else [],
            "candidate": [
                f"Candidate fiducial locations: on upward-facing surfaces within {opt.margin_mm:g} mm of the "
                f"targets, ~{opt.spacing_mm:g} mm apart,",
                "reachable, seen by the sensor, outside solids, clear of the targets.",
            ],
            "target": (
                ["Targets: from the targets file; region of variability: a cube of region_mm (default 4 mm)."]
                if fiducials_planned
                else [
                    "Target: an empty start - one target on the reachable upward-facing surface nearest the middle",
                    "of the cell (move it, add your own); region of variability: a 4 mm cube.",
                ]
            ),
            "error_model": em_said,
        },
    )
    return scene_toml(spec)
