"""Writing scenes: a `SceneSpec` (what a scene file holds) as TOML text in the format `scene_toml.load_scene` reads
(scenes/README.md), with optional comments per section. Used by `rrbc scene new` and by the app's File → Save
scene. Robot base frame, mm; numbers written with Python's shortest round-trip repr, so they read back exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rrbc_core.errors import InputError


@dataclass(frozen=True, eq=False)
class SceneSpec:
    """The content of a scene file. Points: `(ids, (K, 3) positions)` pairs; `targets`: (id, position (3,),
    region dict as the format writes it: {"kind": "box", "size": [...]}, {"kind": "sphere", "radius": r} or
    {"kind": "ellipsoid", "radii": [...]}); `error_model`: the [error_model] table as a dict (robot/sensor lists of
    term tables); `comments`: section name -> comment lines written above it."""

    name: str
    mesh: str
    robot_model: str
    tool_mm: float
    sensor_kind: str
    sensor_position: np.ndarray
    sensor_look_at: np.ndarray
    registration: tuple
    fiducials: tuple
    targets: list
    error_model: dict
    candidates: tuple = ((), np.zeros((0, 3)))
    description: str = ""
    seed: int = 0
    sensor_up: np.ndarray | None = None
    joint_seed_deg: np.ndarray | None = None
    tool_yaw_deg: float = 0.0
    robot_urdf: str | None = None
    robot_tip: str | None = None
    simulation: dict = field(default_factory=dict)
    comments: dict = field(default_factory=dict)


def _key(k: str) -> str:
    """A TOML key: bare when it can be, else a quoted string."""
    return k if k and all(c.isascii() and (c.isalnum() or c in "_-") for c in k) else _value(k)


def _value(v) -> str:
    """A TOML value: string, bool, integer, float (shortest round-trip repr), list or inline table."""
    if isinstance(v, str):
        if any(ord(c) < 32 for c in v):
            raise InputError(f"cannot write a control character in a scene file string: {v[:40]!r}")
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if not math.isfinite(f):
            raise InputError(f"cannot write a non-finite number in a scene file: {f}")
        r = repr(f)
        return r if any(c in r for c in ".en") else r + ".0"
    if isinstance(v, np.ndarray):
        return _value(v.tolist())
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):  # a key that is not bare (a dotted parameter name) is quoted, not nested
        return "{ " + ", ".join(f"{_key(str(k))} = {_value(x)}" for k, x in v.items()) + " }"
    raise InputError(f"cannot write {type(v).__name__} in a scene file")


def _comment(spec: SceneSpec, key: str) -> list[str]:
    return [f"# {line}" if line else "#" for line in spec.comments.get(key, ())]


def _points(spec: SceneSpec, table: str, pts) -> list[str]:
    ids, pos = pts
    out = _comment(spec, table)
    for pid, p in zip(ids, np.asarray(pos, float).reshape(-1, 3)):
        out += [f"[[{table}]]", f"id = {_value(str(pid))}", f"position = {_value([float(x) for x in p])}", ""]
    return out


def scene_toml(spec: SceneSpec) -> str:
    """The TOML text of a scene (module docstring)."""
    out = _comment(spec, "header")
    out += ["", "[scene]", f"name = {_value(spec.name)}"]
    if spec.description:
        out.append(f"description = {_value(spec.description)}")
    out += ['units = "mm"', f"mesh = {_value(spec.mesh)}", f"seed = {int(spec.seed)}", ""]
    out += _comment(spec, "robot")
    out += ["[robot]", f"model = {_value(spec.robot_model)}", f"tool_mm = {_value(float(spec.tool_mm))}"]
    if spec.joint_seed_deg is not None:
        out.append(f"joint_seed_deg = {_value([float(x) for x in spec.joint_seed_deg])}")
    if spec.tool_yaw_deg:
        out.append(f"tool_yaw_deg = {_value(float(spec.tool_yaw_deg))}")
    if spec.robot_urdf is not None:
        out.append(f"urdf = {_value(str(spec.robot_urdf))}")
    if spec.robot_tip is not None:
        out.append(f"tip = {_value(str(spec.robot_tip))}")
    out += [""] + _comment(spec, "sensor")
    out += [
        "[sensor]",
        f"kind = {_value(spec.sensor_kind)}",
        f"position = {_value([float(x) for x in spec.sensor_position])}",
        f"look_at = {_value([float(x) for x in spec.sensor_look_at])}",
    ]
    if spec.sensor_up is not None:
        out.append(f"up = {_value([float(x) for x in spec.sensor_up])}")
    out.append("")
    out += _points(spec, "registration", spec.registration)
    out += _points(spec, "fiducial", spec.fiducials)
    out += _points(spec, "candidate", spec.candidates)
    out += _comment(spec, "target")
    for pid, p, region in spec.targets:
        out += [
            "[[target]]",
            f"id = {_value(str(pid))}",
            f"position = {_value([float(x) for x in p])}",
            f"region = {_value(region)}",
            "",
        ]
    out += _comment(spec, "error_model")
    for side in ("robot", "sensor"):
        for term in spec.error_model.get(side, ()):
            out.append(f"[[error_model.{side}]]")
            out += [f"{k} = {_value(v)}" for k, v in term.items()]
            out.append("")
    if spec.simulation:
        out += ["[simulation]"] + [f"{k} = {_value(v)}" for k, v in spec.simulation.items()] + [""]
    return "\n".join(out)


def region_table(region) -> dict:
    """The format's table of an `io.scene.Region`."""
    size = [float(x) for x in np.asarray(region.size, float)]
    if region.kind == "box":
        return {"kind": "box", "size": size}
    if region.kind == "sphere":
        return {"kind": "sphere", "radius": size[0]}
    return {"kind": "ellipsoid", "radii": size}
