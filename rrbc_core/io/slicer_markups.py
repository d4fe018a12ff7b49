"""3D Slicer markups JSON (`.mrk.json`) for measurement files: one point list for the sensor frame and one for
the robot frame (docs/formats/slicer-markups.md).

Each row of a measurement file becomes a control point: `label` = its id, `position` = its coordinates (mm),
`description` = `role=<role>` (and `; time=<s>` when the row has a time). The robot list holds the rows that have
robot readings (not targets). Files are written with `coordinateSystem` "LPS" and rrbc's coordinates unchanged
(rrbc's frames are a sensor's and a robot's, not a patient's; LPS is what Slicer writes to files); a file in
"RAS" is read with x and y negated into LPS, which is how Slicer itself converts. Numbers are written with
Python's shortest round-trip repr, so a round trip is exact.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import ROLES, MeasurementSet, validate

SCHEMA = (
    "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/Schema/"
    "markups-schema-v1.0.3.json#"
)
MAX_BYTES = 50 << 20
MAX_POINTS = 100_000


def _point(i: int, pid: str, xyz, role: str, time: float) -> dict:
    desc = f"role={role}" + ("" if not math.isfinite(time) else f"; time={float(time)!r}")
    return {
        "id": str(i + 1),
        "label": pid,
        "description": desc,
        "associatedNodeID": "",
        "position": [float(v) for v in xyz],
        "orientation": [-1.0, -0.0, -0.0, -0.0, -1.0, -0.0, 0.0, 0.0, 1.0],
        "selected": True,
        "locked": False,
        "visibility": True,
        "positionStatus": "defined",
    }


def _document(name: str, points: list[dict]) -> dict:
    return {
        "@schema": SCHEMA,
        "markups": [
            {
                "type": "Fiducial",
                "coordinateSystem": "LPS",
                "coordinateUnits": "mm",
                "locked": False,
                "fixedNumberOfControlPoints": False,
                "labelFormat": "%N-%d",
                "lastUsedControlPointNumber": len(points),
                "controlPoints": points,
                "measurements": [],
                "display": {"visibility": True, "glyphType": "Sphere3D", "glyphScale": 1.0, "textScale": 3.0},
                "name": name,
            }
        ],
    }


def to_markups(mset: MeasurementSet) -> tuple[dict, dict]:
    """(sensor document, robot document) for a measurement set."""
    sensor: list[dict] = []
    robot: list[dict] = []
    for i, (pid, role) in enumerate(zip(mset.ids, mset.roles)):
        t = float(mset.time[i])
        sensor.append(_point(len(sensor), pid, mset.sensor[i], role, t))
        if np.all(np.isfinite(mset.robot[i])):
            robot.append(_point(len(robot), pid, mset.robot[i], role, t))
    return _document("sensor", sensor), _document("robot", robot)


def write_markups(mset: MeasurementSet, out_dir, stem: str) -> tuple[Path, Path]:
    """Write `<stem>_sensor.mrk.json` and `<stem>_robot.mrk.json` into `out_dir` (created if needed), each
    atomically."""
    from rrbc_core.io.measurements_write import atomic_write_text, make_output_dir

    d = make_output_dir(out_dir)  # created when it does not exist yet
    sensor, robot = to_markups(mset)
    paths = (d / f"{stem}_sensor.mrk.json", d / f"{stem}_robot.mrk.json")
    for p, doc in zip(paths, (sensor, robot)):
        atomic_write_text(p, json.dumps(doc, indent=1) + "\n")
    return paths


def _read(path) -> list[tuple[str, np.ndarray, str, float]]:
    """(label, position (3,) LPS mm, role, time) of each defined point of a markups file's one point list, in
    order (a label may repeat: a point measured more than once)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: markups file not found")
    if p.stat().st_size > MAX_BYTES:
        raise InputError(f"{p}: larger than {MAX_BYTES >> 20} MiB")
    try:
        doc = json.loads(p.read_bytes().decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise InputError(f"{p}: not a JSON file ({type(exc).__name__})") from None
    lists = doc.get("markups") if isinstance(doc, dict) else None
    if not isinstance(lists, list) or len(lists) != 1 or not isinstance(lists[0], dict):
        raise InputError(f"{p}: expected a Slicer markups file with exactly one point list ('markups': [{{...}}])")
    m = lists[0]
    units = m.get("coordinateUnits", "mm")
    if units != "mm":
        raise InputError(f"{p}: coordinateUnits {str(units)[:20]!r}; only mm is read")
    system = m.get("coordinateSystem", "LPS")
    if system not in ("LPS", "RAS"):
        raise InputError(f"{p}: coordinateSystem {str(system)[:20]!r}; expected LPS or RAS")
    pts = m.get("controlPoints", [])
    if not isinstance(pts, list) or len(pts) > MAX_POINTS:
        raise InputError(f"{p}: controlPoints must be a list of at most {MAX_POINTS} points")
    out = []
    for k, cp in enumerate(pts):
        where = f"{p}: control point {k + 1}"
        if not isinstance(cp, dict):
            raise InputError(f"{where}: not an object")
        label = cp.get("label")
        if not isinstance(label, str) or not label.strip() or not label.isprintable() or len(label) > 64:
            raise InputError(f"{where}: its label (the point's id) must be 1-64 printable characters")
        if cp.get("positionStatus", "defined") != "defined":
            continue
        pos = cp.get("position")
        if (
            not isinstance(pos, list)
            or len(pos) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in pos)
        ):
            raise InputError(f"{where} ({label}): position must be 3 finite numbers (mm)")
        xyz = np.array(pos, float)
        if system == "RAS":
            xyz[:2] *= -1.0
        role, time = "fiducial", float("nan")
        for part in str(cp.get("description", "")).split(";"):
            key, _, value = part.strip().partition("=")
            if key == "role":
                role = value.strip()
            elif key == "time":
                try:
                    time = float(value)
                except ValueError:
                    raise InputError(f"{where} ({label}): time {value[:20]!r} is not a number (s)") from None
        if role not in ROLES:
            raise InputError(f"{where} ({label}): role {role[:20]!r} in its description; roles: {', '.join(ROLES)}")
        out.append((label, xyz, role, time))
    return out


def read_markups(sensor_path, robot_path) -> MeasurementSet:
    """A measurement set from a sensor-frame and a robot-frame markups file: the sensor file's rows (order, ids =
    labels, roles); the robot file holds, in the same order, one point for each row that is not a target."""
    s = _read(sensor_path)
    r = _read(robot_path)
    ids, roles, sensor, robot, time = [], [], [], [], []
    k = 0
    for pid, xyz, role, t in s:
        if role == "target":
            rob = np.full(3, np.nan)
        else:
            if k >= len(r):
                raise InputError(f"{robot_path}: no robot point for {pid!r} ({role}); only targets may lack one")
            if r[k][0] != pid:
                raise InputError(
                    f"{robot_path}: point {k + 1} is {r[k][0]!r} where the sensor file's next non-target row is "
                    f"{pid!r}; the robot list must follow the sensor list's order"
                )
            rob = r[k][1]
            k += 1
        ids.append(pid)
        roles.append(role)
        sensor.append(xyz)
        robot.append(rob)
        time.append(t)
    if k < len(r):
        raise InputError(f"{robot_path}: {len(r) - k} point(s) from {r[k][0]!r} on have no row in {sensor_path}")
    mset = MeasurementSet(
        ids=tuple(ids),
        roles=tuple(roles),
        sensor=np.array(sensor, float).reshape(-1, 3),
        robot=np.array(robot, float).reshape(-1, 3),
        time=np.array(time, float),
        lines=tuple(0 for _ in ids),
        source=f"{sensor_path} + {robot_path}",
    )
    validate(mset)
    return mset
