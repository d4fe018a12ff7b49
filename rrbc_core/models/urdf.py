"""Robot models from URDF files: the chain from a base link to a measured tip link (`load_urdf` → `chain.Chain`),
parsed by yourdfpy (the parser viser's own URDF support uses; meshes are not loaded).

Joints: fixed, revolute, continuous and prismatic (floating and planar joints on the measured chain are refused);
`<origin xyz rpy>` (metres, radians) and `<axis>`; `<limit lower upper>`; `<mimic joint multiplier offset>`, also
when the master joint is off the measured chain (its value is then a column of the file all the same). Lengths are
converted from metres to millimetres.

Which chain: `tip` names the measured link (default: the end of the longest chain — the leaf link with the most
joints above it, the first in the file on a tie); `base` the link whose frame the robot columns are in (default:
the root of the tree). `PACKAGED` names robot descriptions that ship with the `example-robot-data` package
(`packaged_urdf`): `--urdf ur5` uses that file when no file of that name exists; `BUNDLED` names the ones rrbc
ships itself (`--urdf lift_arm`: a six-axis arm on a lift column, with a mimic joint).
"""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.models.chain import Chain, Input, MovingJoint

#: Robot descriptions shipped by the `example-robot-data` package (BSD-3-Clause), by a short name.
PACKAGED = {
    "ur5": "robots/ur_description/urdf/ur5_robot.urdf",
    "ur10": "robots/ur_description/urdf/ur10_robot.urdf",
    "panda": "robots/panda_description/urdf/panda.urdf",
}
#: Robot descriptions bundled with rrbc (rrbc_core/data/robots/), by name: examples, tests and benchmarks.
BUNDLED = ("lift_arm",)
_SCALE = {"revolute": 1.0, "continuous": 1.0, "prismatic": 1000.0}  # SI value × scale = rad or mm
_UNIT = {"revolute": "rad", "continuous": "rad", "prismatic": "m"}


def packaged_urdf(name: str) -> Path:
    """The path of a packaged robot description (`PACKAGED`)."""
    if name not in PACKAGED:
        raise InputError(f"no packaged robot {name!r}: packaged are {', '.join(PACKAGED)}")
    try:
        files = importlib.metadata.files("example-robot-data") or []
    except importlib.metadata.PackageNotFoundError:
        raise InputError("the example-robot-data package is not installed (run scripts/setup.sh)") from None
    for f in files:
        if str(f).endswith(PACKAGED[name]):
            return Path(str(f.locate()))
    raise InputError(f"example-robot-data has no {PACKAGED[name]}")


def bundled_urdf(name: str) -> Path:
    """The path of a robot description bundled with rrbc (`BUNDLED`)."""
    if name not in BUNDLED:
        raise InputError(f"no bundled robot {name!r}: bundled are {', '.join(BUNDLED)}")
    return Path(__file__).resolve().parents[1] / "data" / "robots" / f"{name}.urdf"


def _parse(path: Path):
    import yourdfpy

    try:
        return yourdfpy.URDF.load(
            str(path),
            build_scene_graph=False,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
        )
    except Exception as exc:  # noqa: BLE001 - lxml, yourdfpy and OS errors alike: one line for the user
        hint = (
            " (a xacro file: expand it first, `xacro robot.urdf.xacro > robot.urdf`)" if ".xacro" in path.name else ""
        )
        raise InputError(f"{path}: cannot read as a URDF{hint}: {' '.join(str(exc).split())[:200]}") from None


def resolve_urdf(urdf) -> Path:
    """The URDF file of `urdf`: a path, or a packaged or bundled name; InputError when neither."""
    p = Path(urdf)
    if p.exists():
        return p
    if str(urdf) in PACKAGED:
        return packaged_urdf(str(urdf))
    if str(urdf) in BUNDLED:
        return bundled_urdf(str(urdf))
    raise InputError(f"{urdf}: no such URDF file (packaged robots: {', '.join((*PACKAGED, *BUNDLED))})")


def _matrix(joint) -> np.ndarray:
    m = np.eye(4) if joint.origin is None else np.array(joint.origin, float)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise InputError(f"joint {joint.name}: its origin is not a finite transform")
    m = m.copy()
    m[:3, 3] *= 1000.0  # metres -> mm
    return m


def _depths(robot, parent_joint: dict) -> dict:
    """Link -> number of joints between it and its tree's root."""
    out: dict = {}
    for link in (lk.name for lk in robot.links):
        n, cur, seen = 0, link, set()
        while cur in parent_joint:
            if cur in seen:
                raise InputError(f"the URDF's joints form a loop at link {cur}")
            seen.add(cur)
            cur = parent_joint[cur].parent
            n += 1
        out[link] = n
    return out


def load_urdf(urdf, tip: str | None = None, base: str | None = None, tool_mm=None) -> Chain:
    """The chain of a URDF from `base` to `tip` (module docstring).

    Parameters
    ----------
    urdf : str or Path
        A URDF file, or a name in `PACKAGED`.
    tip, base : str, optional
        The measured link and the base link (defaults: the end of the longest chain, the tree's root).
    tool_mm : array_like, (3,), optional
        A tool point in the tip link's frame, mm (default: the tip link's origin).

    Raises
    ------
    InputError
        Unreadable file, unknown links, a tip not below the base, a floating or planar joint on the chain, a mimic
        joint whose master does not exist, or no moving joint between base and tip.
    """
    path = resolve_urdf(urdf)
    robot = _parse(path).robot
    links = [lk.name for lk in robot.links]
    joints = {j.name: j for j in robot.joints}
    parent_joint = {j.child: j for j in robot.joints}
    depth = _depths(robot, parent_joint)
    children = {j.parent for j in robot.joints}
    if tip is None:
        leaves = [lk for lk in links if lk not in children]
        if not leaves:
            raise InputError(f"{path}: no links")
        tip = max(leaves, key=lambda lk: (depth[lk], -links.index(lk)))
    if tip not in depth:
        raise InputError(f"{path}: no link {tip!r} (--tip); links: {', '.join(links)}")
    path_joints = []
    cur = tip
    while cur in parent_joint and cur != base:
        j = parent_joint[cur]
        path_joints.append(j)
        cur = j.parent
    if base is None:
        base = cur
    elif cur != base:
        raise InputError(f"{path}: link {base!r} (--base) is not above {tip!r}; links: {', '.join(links)}")
    path_joints.reverse()

    inputs: list[Input] = []
    index: dict[str, int] = {}

    def input_of(j) -> int:
        if j.name not in index:
            lim = j.limit
            scale = _SCALE[j.type]
            bounded = j.type != "continuous" and lim is not None and lim.lower is not None and lim.upper is not None
            lower = float(lim.lower) * scale if bounded else None
            upper = float(lim.upper) * scale if bounded else None
            index[j.name] = len(inputs)
            inputs.append(Input(j.name, j.type, lower, upper, j.name, scale, _UNIT[j.type]))
        return index[j.name]

    moving: list[MovingJoint] = []
    acc = np.eye(4)
    link_of = {lk.name: lk for lk in robot.links}
    segments: list[list[tuple[float, np.ndarray]]] = []  # per moving joint: (mass kg, centre mm in F_k)
    for j in path_joints:
        if j.type == "fixed":
            acc = acc @ _matrix(j)
            if segments:
                segments[-1] += _inertial(link_of[j.child], acc, path)
            continue
        if j.type not in _SCALE:
            raise InputError(
                f"{path}: joint {j.name} is {j.type}: only fixed, revolute, continuous and prismatic joints"
            )
        axis = np.array([1.0, 0.0, 0.0] if j.axis is None else j.axis, float)
        if not np.all(np.isfinite(axis)) or np.linalg.norm(axis) < 1e-12:
            raise InputError(f"{path}: joint {j.name} has no usable axis")
        multiplier, offset, master = 1.0, 0.0, j
        seen = {j.name}
        while master.mimic is not None:  # follow mimic joints to the actuated master (values in SI units)
            m = master.mimic
            if m.joint not in joints:
                raise InputError(f"{path}: joint {master.name} mimics {m.joint!r}, which the URDF does not have")
            mult = 1.0 if m.multiplier is None else float(m.multiplier)
            off = 0.0 if m.offset is None else float(m.offset)
            multiplier, offset = multiplier * mult, offset + multiplier * off
            master = joints[m.joint]
            if master.name in seen or master.type not in _SCALE:
                raise InputError(f"{path}: joint {j.name}'s mimic chain does not end at an actuated joint")
            seen.add(master.name)
        own, theirs = _SCALE[j.type], _SCALE[master.type]
        moving.append(
            MovingJoint(
                j.name,
                j.type,
                acc @ _matrix(j),
                axis / np.linalg.norm(axis),
                input_of(master),
                multiplier * own / theirs,
                offset * own,
            )
        )
        acc = np.eye(4)
        segments.append(_inertial(link_of[j.child], acc, path))
    tool = np.zeros(3) if tool_mm is None else np.asarray(tool_mm, float)
    name = robot.name or path.stem
    return Chain(name, base, tip, tuple(moving), tuple(inputs), acc, tool, str(path), _segment_inertia(segments))


def _inertial(link, frame: np.ndarray, path: Path) -> list[tuple[float, np.ndarray]]:
    """[(mass kg, centre of mass (3,) mm in the segment's frame)] of a link whose frame is `frame` (4, 4) mm in its
    segment's frame; [] without `<inertial>`."""
    inertial = getattr(link, "inertial", None)
    if inertial is None or inertial.mass is None:
        return []
    mass = float(inertial.mass)
    origin = np.eye(4) if inertial.origin is None else np.array(inertial.origin, float)
    if not np.isfinite(mass) or mass < 0 or origin.shape != (4, 4) or not np.all(np.isfinite(origin)):
        raise InputError(f"{path}: link {link.name}: its <inertial> mass or origin is not usable")
    centre = frame[:3, :3] @ (origin[:3, 3] * 1000.0) + frame[:3, 3]
    return [(mass, centre)]


def _segment_inertia(segments: list[list[tuple[float, np.ndarray]]]) -> np.ndarray | None:
    """(K, 4): each segment's mass (kg) and centre of mass (mm), or None when no link on the chain has a mass."""
    if not any(m > 0 for seg in segments for m, _ in seg):
        return None
    out = np.zeros((len(segments), 4))
    for k, seg in enumerate(segments):
        mass = sum(m for m, _ in seg)
        if mass > 0:
            out[k, 0] = mass
            out[k, 1:] = sum(m * c for m, c in seg) / mass
    return out


def describe(chain: Chain) -> str:
    """One line: the robot, base → tip, its moving joints and the file's columns with units."""
    cols = ", ".join(f"{i.column} ({i.unit})" for i in chain.inputs)
    return f"{chain.name}: {chain.base} → {chain.tip}, {len(chain.joints)} moving joints; joint columns {cols}"


__all__ = ["BUNDLED", "PACKAGED", "bundled_urdf", "describe", "load_urdf", "packaged_urdf", "resolve_urdf"]
