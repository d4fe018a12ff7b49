"""The identified arm as a URDF (`rrbc calibrate --urdf ... --export-urdf CALIBRATED.urdf`).

The chain (`models.chain`) applies moving joint k's errors after its folded origin, before its motion:
G_k = F_(k-1) · origin_k · E_k(δ), then M_k(v_k + δ_offset). A URDF joint's own `<origin>` is the last factor of
the folded origin, and a rotation (or shift) about (along) the joint's own axis commutes with its motion, so the
identified arm is the same URDF with each moving joint's origin replaced by

    origin'_k = origin_k · E_k(δ) · M_k(δ_offset)

(translations in metres, rotations as URDF's fixed-axis roll-pitch-yaw). Its forward kinematics are then the
identified chain's, to rounding. The tool point with its identified error is written as a fixed joint
`rrbc_tool_joint` from the tip link to a new link `rrbc_tool` (the point the sensor measured). Load terms
(compliance, bending, backlash) have no URDF element: they are written in a comment with their values, units and
standard errors; the sensor-to-robot transform is not part of the arm and is left out. Everything else (links,
meshes, limits, mimic joints, inertials, comments) is written back as read.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform
from rrbc_core.models.chain import Chain

TOOL_LINK = "rrbc_tool"
TOOL_JOINT = "rrbc_tool_joint"


def _numbers(text: str | None, what: str) -> np.ndarray:
    try:
        v = np.array([float(x) for x in (text or "0 0 0").split()], float)
    except ValueError:
        v = np.zeros(0)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise InputError(f"a joint origin's {what} is not 3 numbers: {text!r}")
    return v


def calibrated_urdf(urdf_path: Path, chain: Chain, delta, notes: list[str]) -> str:
    """The URDF text of the identified arm (module docstring). `urdf_path` the URDF `chain` was read from, `delta`
    (P,) its identified errors (`chain.param_names` order, mm and rad), `notes` lines for the header comment. The
    file is edited in place (Python's XML tree, comments kept): only the moving joints' `<origin>` change and the
    tool's link and joint are added, so mimic joints, limits, meshes and the rest stay as written."""
    import xml.etree.ElementTree as ET

    from scipy.spatial.transform import Rotation

    delta = np.asarray(delta, float).reshape(chain.n_params)
    try:
        tree = ET.parse(urdf_path, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    except (ET.ParseError, OSError) as exc:
        raise InputError(f"{urdf_path}: cannot read as XML: {exc}") from None
    root = tree.getroot()
    joints = {j.get("name"): j for j in root.findall("joint")}
    for k, mj in enumerate(chain.joints):
        if mj.name not in joints:
            raise InputError(f"{urdf_path}: joint {mj.name!r} of the chain is not in the URDF")
        el = joints[mj.name].find("origin")
        if el is None:
            el = ET.SubElement(joints[mj.name], "origin")
        origin = np.eye(4)
        origin[:3, :3] = Rotation.from_euler("xyz", _numbers(el.get("rpy"), "rpy")).as_matrix()
        origin[:3, 3] = _numbers(el.get("xyz"), "xyz")
        err = chain.joint_error(k, delta)
        err[:3, 3] /= 1000.0  # mm -> m
        new = origin @ err
        el.set("xyz", " ".join(repr(float(x)) for x in new[:3, 3]))
        el.set("rpy", " ".join(repr(float(x)) for x in RigidTransform(new[:3, :3], new[:3, 3]).rpy()))
    links = {link.get("name") for link in root.findall("link")}
    if TOOL_LINK in links or TOOL_JOINT in joints:
        raise InputError(f"{urdf_path}: already has a {TOOL_LINK!r} link or {TOOL_JOINT!r} joint")
    ET.SubElement(root, "link", {"name": TOOL_LINK})
    tj = ET.SubElement(root, "joint", {"name": TOOL_JOINT, "type": "fixed"})
    ET.SubElement(tj, "parent", {"link": chain.tip})
    ET.SubElement(tj, "child", {"link": TOOL_LINK})
    tool = (chain.tool + delta[-3:]) / 1000.0
    ET.SubElement(tj, "origin", {"xyz": " ".join(repr(float(x)) for x in tool), "rpy": "0 0 0"})
    root.insert(0, ET.Comment("\n" + "\n".join("  " + n.replace("--", "- -") for n in notes) + "\n"))
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
