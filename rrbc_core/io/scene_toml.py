"""Reading a scene TOML file (`load_scene`): every table and value checked, with a one-line message naming the file,
the key and, for TOML syntax errors, the line. The format: scenes/README.md; the model it builds: `scene`."""

from __future__ import annotations

import os
from os import PathLike
from pathlib import Path

import numpy as np

from rrbc_core.errors import InputError, excerpt
from rrbc_core.geometry import points as geometry
from rrbc_core.io.scene import (
    DEFAULT_CHECK_POINTS_PER_TARGET,
    DEFAULT_JOINT_SEED_DEG,
    DEFAULT_MEASUREMENT_INTERVAL_S,
    MAX_GRID_POINTS,
    REGION_KINDS,
    ROBOT_MODELS,
    SAME_POINT_TOL_MM,
    SENSOR_KINDS,
    NamedPoints,
    Region,
    Scene,
    Target,
    _frozen,
    _load_mesh_file,
    sensor_pose,
)
from rrbc_core.io.toml_checks import Checker, fmt_value, read_toml
from rrbc_core.models.errormodels import ErrorModel
from rrbc_core.models.errorterms import Compliance, Kinematic, error_model_from_dict
from rrbc_core.models.kinematics import ROBOT_DH, reachable, tool_down

MAX_CHECK_POINTS_PER_TARGET = 10_000  # a scene's simulated check points per target (issue 16: bounded work)

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
# Validation helpers
# ------------------------------------------------------------------------------------------------------
def load_scene(path: str | PathLike) -> Scene:
    """Read and validate a scene TOML file (format: scenes/README.md).

    Parameters
    ----------
    path : str or Path
        The scene file; a mesh it names is read relative to it.

    Returns
    -------
    Scene
        Robot, sensor pose, registration points, fiducials, targets with their regions, candidates, error model;
        robot base frame, mm.

    Raises
    ------
    InputError
        One line ``<file>: <key path>: <problem>`` (with the line for TOML syntax errors).
    """
    source = os.fspath(path)
    if isinstance(source, bytes):
        source = os.fsdecode(source)
    c = Checker(source)
    doc = read_toml(path, source, c)
    toml_path = Path(source).resolve()

    c.keys(doc, "", _TOP_KEYS, _REQUIRED_TOP)

    # [scene] -----------------------------------------------------------------------------------------------
    sc = c.table(doc["scene"], "scene")
    c.keys(sc, "scene", ("name", "description", "units", "mesh", "seed"), ("name", "units", "mesh"))
    name = c.string(sc["name"], "scene.name")
    description = c.string(sc.get("description", ""), "scene.description", nonempty=False)
    units = c.string(sc["units"], "scene.units")
    if units != "mm":
        raise c.error("scene.units", f'only "mm" is supported (all coordinates in millimetres), got {fmt_value(units)}')
    mesh_rel = c.string(sc["mesh"], "scene.mesh")
    try:
        mesh_path = (toml_path.parent / mesh_rel).resolve(strict=False)
    except (RuntimeError, OSError) as exc:  # a symlink loop
        why = (
            "a loop of symbolic links" if isinstance(exc, RuntimeError) or "loop" in str(exc).lower() else "an OS error"
        )
        raise c.error("scene.mesh", f"cannot resolve {excerpt(mesh_rel, 80)!r}: {why}") from None
    folder = toml_path.parent.resolve()
    if not mesh_path.is_relative_to(folder):
        # a scene opens only files in its own folder (or below): a scene from elsewhere cannot make the app read
        # /etc/shadow or a user's files (issue 16)
        raise c.error(
            "scene.mesh",
            f"{mesh_rel[:80]!r} leaves the scene's folder: put the mesh in the scene's folder or a folder below it",
        )
    seed = c.integer(sc.get("seed", 0), "scene.seed", minimum=0)

    # [robot] -----------------------------------------------------------------------------------------------
    rb = c.table(doc["robot"], "robot")
    c.keys(rb, "robot", ("model", "tool_mm", "joint_seed_deg", "tool_yaw_deg", "urdf", "tip"), ("model", "tool_mm"))
    robot_model = c.string(rb["model"], "robot.model", choices=ROBOT_MODELS)
    tool_mm = c.number(rb["tool_mm"], "robot.tool_mm", nonneg=True)
    robot_urdf, robot_tip = _robot_urdf(c, rb, robot_model, toml_path, tool_mm)
    joint_seed_deg = (
        c.vector(rb["joint_seed_deg"], "robot.joint_seed_deg", 6)
        if "joint_seed_deg" in rb
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
            "sensor.look_at",
            f"equals sensor.position {fmt_value(sn['position'])}; the sensor needs a viewing direction",
        )
    if np.linalg.norm(s_up) <= 1e-12:
        raise c.error("sensor.up", "must be a non-zero vector")
    try:
        sensor_to_robot = sensor_pose(s_pos, s_look, s_up)
    except InputError:
        up_text = fmt_value(sn.get("up", [0.0, 0.0, 1.0])) + ("" if "up" in sn else " (the default)")
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
                'own (a measurement file gives each id one role); use site = "<id>" to put it at a site',
            )

    placed: dict[str, tuple[np.ndarray, str]] = {}
    for group in (sites_raw, registration_raw, fiducial_raw, candidate_raw, target_raw):
        for pid, pos, _, key, _ in group:
            if pid in placed and np.linalg.norm(placed[pid][0] - pos) > SAME_POINT_TOL_MM:
                other_pos, other_key = placed[pid]
                raise c.error(
                    f"{key}.position",
                    f"id {pid!r} is also {other_key} at {fmt_value(other_pos.tolist())}; one id names one place "
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
        maximum=MAX_CHECK_POINTS_PER_TARGET,
    )
    interval = c.number(
        sim.get("measurement_interval_s", DEFAULT_MEASUREMENT_INTERVAL_S),
        "simulation.measurement_interval_s",
        nonneg=True,
    )
    distance_origin = c.vector(sim.get("distance_origin_mm", [0.0, 0.0, 0.0]), "simulation.distance_origin_mm")

    # [error_model] -----------------------------------------------------------------------------------------
    em_table = c.table(doc.get("error_model", {}), "error_model")
    error_model = _with_tool(_error_model(c, em_table), em_table, tool_mm, robot_model, c.source)
    error_model = _on_arm(c, error_model, robot_model, robot_urdf, robot_tip, tool_mm)

    # every point within the arm's reach, said here by file, field and id (issue 16: the kinematic term's own
    # message could only give point indices, later, with no file)
    arm = [t for t in error_model.terms("robot") if hasattr(t, "true_robot")]
    if arm:
        groups = (
            ("registration", registration.ids, registration.positions),
            ("fiducial", fiducials.ids, fiducials.positions),
            ("target", [t.id for t in targets], [t.position for t in targets]),
        )
        for kind, ids, positions in groups:
            pos = np.asarray(positions, float).reshape(-1, 3)
            if not len(pos):
                continue
            ok = reachable(arm[0].true_robot(), pos, tool_down(tool_yaw), np.radians(joint_seed_deg))
            if not ok.all():
                i = int(np.flatnonzero(~ok)[0])
                where = ", ".join(f"{v:.1f}" for v in pos[i])
                more = f" (and {int((~ok).sum()) - 1} more {kind} points)" if (~ok).sum() > 1 else ""
                raise c.error(
                    f"{kind}[{i}].position",
                    f"{ids[i]} at ({where}) mm is out of the arm's reach with its tool pointing down{more}; move it "
                    "closer to the robot, or change robot.joint_seed_deg",
                )

    # mesh (last: the most expensive check) -------------------------------------------------------------------
    if not mesh_path.is_file():
        raise c.error("scene.mesh", f"mesh file not found: {mesh_path}")
    try:
        mesh = _load_mesh_file(mesh_path)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types for unreadable files
        raise c.error("scene.mesh", f"cannot load {mesh_rel!r} as a mesh: {exc.__class__.__name__}: {exc}") from None

    return Scene(
        name=name,
        description=description,
        path=toml_path,
        mesh_path=mesh_path,
        robot_model=robot_model,
        tool_mm=tool_mm,
        robot_urdf=robot_urdf,
        robot_tip=robot_tip,
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


def _robot_urdf(c: Checker, rb: dict, robot_model: str, toml_path: Path, tool_mm: float):
    """`robot.urdf` (a file beside the scene or below its folder, or a packaged name) and `robot.tip`: the robot the
    app draws and poses (models.arm_description). Only for `model = "none"`: a DH arm is drawn from its own packaged
    description. Returns (the URDF's path or packaged name, the tip link) or (None, None)."""
    if "urdf" not in rb:
        if "tip" in rb:
            raise c.error("robot.tip", "names a link of robot.urdf: give robot.urdf too")
        return None, None
    if robot_model != "none":
        raise c.error(
            "robot.urdf",
            f"a {robot_model} is drawn from its own packaged description; a URDF is for a robot the scene's "
            'kinematics do not model (set robot.model = "none")',
        )
    from rrbc_core.models.arm_description import urdf_arm_description
    from rrbc_core.models.urdf import BUNDLED, PACKAGED

    ref = c.string(rb["urdf"], "robot.urdf")
    tip = c.string(rb["tip"], "robot.tip") if "tip" in rb else None
    if ref in PACKAGED or ref in BUNDLED:
        where: str | Path = ref
    else:
        where = (toml_path.parent / ref).resolve()
        if toml_path.parent.resolve() not in where.parents:
            raise c.error("robot.urdf", f"{ref[:80]!r} leaves the scene's folder: put the URDF in it or below it")
    try:
        desc = urdf_arm_description(where, tip=tip, tool_mm=(0.0, 0.0, tool_mm))
    except InputError as exc:
        raise c.error("robot.urdf", str(exc)) from None
    return where, desc.chain.tip


def _points(c: Checker, doc: dict, kind: str, default_yaw: float, site_pos: dict, with_region=False) -> list:
    """Parse `[[kind]]` blocks -> list of (id, position, yaw, key, region|None)."""
    if kind not in doc:
        return []
    blocks = c.array_of_tables(doc[kind], kind)
    allowed = (
        ("id", "position", "tool_yaw_deg", "note")
        + (("site",) if kind != "site" else ())
        + (("region",) if with_region else ())
    )
    required = ("id",) + (("region",) if with_region else ())
    out: list = []
    seen: dict = {}
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
                raise c.error(f"{key}.site", f"unknown site {ref!r}; sites: {fmt_value(valid, 60)[1:-1]}")
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


def _region(c: Checker, v, key: str, center: np.ndarray) -> Region:
    r = c.table(v, key)
    if "kind" not in r:
        raise c.error(f"{key}.kind", f"missing required key (one of {', '.join(REGION_KINDS)})")
    kind = c.string(r["kind"], f"{key}.kind")
    if kind not in REGION_KINDS:
        raise c.error(f"{key}.kind", f"unknown region kind {fmt_value(kind)}; valid kinds: {', '.join(REGION_KINDS)}")
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


def _grid(c: Checker, doc: dict, default_yaw: float) -> list:
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
        raise c.error("candidates.grid.max", f"must be >= candidates.grid.min on every axis, got {fmt_value(g['max'])}")
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


def _check_spread(c: Checker, key: str, positions: np.ndarray) -> None:
    try:
        geometry.check_registration_points(positions, "points")
    except InputError as exc:
        raise c.error(key, str(exc)) from None


def _layouts(c: Checker, doc: dict, pool: dict) -> tuple[dict, dict]:
    if "layouts" not in doc:
        return {}, {}
    lt = c.table(doc["layouts"], "layouts")
    layouts: dict = {}
    points: dict = {}
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
                raise c.error(pkey, f"must be a non-empty list of point ids (strings), got {fmt_value(ids)}")
            for j, pid in enumerate(ids):
                if pid not in pool:
                    raise c.error(
                        f"{pkey}[{j}]",
                        f"unknown id {pid!r}; ids come from [[registration]], [[fiducial]] and [[site]]",
                    )
                if pid in ids[:j]:
                    raise c.error(f"{pkey}[{j}]", f"duplicate id {pid!r}")
            np_ = NamedPoints(tuple(ids), np.array([pool[i][0] for i in ids]), np.array([pool[i][1] for i in ids]))
            if part == "registration":
                if len(ids) < 3:
                    raise c.error(pkey, f"{len(ids)} ids given, a registration needs at least 3 points")
                _check_spread(c, pkey, np_.positions)
            layouts[name][part] = tuple(ids)
            points[name][part] = np_
    return layouts, points


def _with_tool(model, table: dict, tool_mm: float, robot_model: str = "ur5", source: str = "scene"):
    """The scene's arm (`robot.model`) with its `robot.tool_mm` is the arm of every kinematic or compliance term that does
    not give its own `dh`: the simulated arm then reaches the scene's points with its tool tip, as the scene
    describes. A robot without kinematics ("none") cannot carry a kinematic term."""
    import dataclasses

    rows = table.get("robot", []) if isinstance(table, dict) else []
    terms = []
    for k, term in enumerate(model.robot):
        own_dh = k < len(rows) and isinstance(rows[k], dict) and "dh" in rows[k]
        if isinstance(term, (Kinematic, Compliance)) and robot_model not in ROBOT_DH:
            raise InputError(
                f"{source}: error_model.robot[{k}]: a {term.kind} error term needs an arm model (robot.model "
                f"{', '.join(ROBOT_DH)}), not {robot_model!r}; give a robot without kinematics a smooth_field bias"
            )
        if isinstance(term, (Kinematic, Compliance)) and not own_dh:
            term = dataclasses.replace(term, dh=ROBOT_DH[robot_model].with_tool(tool_mm))
        terms.append(term)
    return ErrorModel(robot=tuple(terms), sensor=model.sensor)


def _on_arm(c: Checker, model, robot_model: str, urdf, tip, tool_mm: float):
    """Every `arm_errors` term that names no arm of its own is on the scene's (robot.urdf, else robot.model)."""
    from rrbc_core.models.armterms import ArmErrors

    terms = []
    for k, term in enumerate(model.robot):
        if isinstance(term, ArmErrors):
            try:
                term = term.on_arm(
                    urdf="" if urdf is None else str(urdf),
                    tip=tip or "",
                    robot=robot_model if robot_model in ROBOT_DH else "",
                    tool_mm=(0.0, 0.0, float(tool_mm)),
                )
            except InputError as exc:
                raise c.error(f"error_model.robot[{k}] (arm_errors)", str(exc)) from None
            if not term.urdf and not term.robot:
                raise c.error(
                    f"error_model.robot[{k}] (arm_errors)", "needs an arm: robot.model ur5/ur10, or robot.urdf"
                )
        terms.append(term)
    return ErrorModel(robot=tuple(terms), sensor=model.sensor)


def _error_model(c: Checker, table: dict):
    """Build the error model (`models.errorterms.error_model_from_dict`), its errors named after the file."""
    try:
        return error_model_from_dict(table, f"{c.source}: error_model")
    except InputError as exc:
        msg = " ".join(str(exc).split())
        if not msg.startswith(c.source):
            msg = f"{c.source}: error_model: {msg}"
        raise InputError(msg) from None
