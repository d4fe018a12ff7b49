"""The arm and the sensors in the scene, drawn as what they are.

The arm: the scene's robot posed to reach the selected target (`rrbc_core.session.arm.arm_pose`: a DH arm by the
nominal controller's inverse kinematics, a URDF robot by damped least squares), drawn from its URDF with its own
meshes (`rrbc_core.session.arm.arm_description`: a UR5 or UR10 from the description the `example-robot-data`
package ships, a scene's `robot.urdf` otherwise; viser's `ViserUrdf`, metres scaled to mm), with a thin stylus from
the flange to the tool point — and, at its tool, where the real (biased) arm lands: a short line from the
commanded place to the landing, drawn ×magnification like the arrows. Where no description can be loaded, generated
links stand in (a cylinder between successive DH frame origins, a joint housing about each joint axis).

The sensors: a stereo head as two cameras on a bar at the sensor's pose with their viewing frusta reaching the
work; a motion-capture system as four cameras around the cell looking at what the sensor looks at (placement
illustrative: the scene models the system as one sensor frame, drawn as such by the frames layer); a laser
tracker as one instrument with its frustum; a reference artefact ("ground_truth") as nothing. Robot frame, mm.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import viser
import viser.transforms as vtf

from rrbc_core.session.arm import arm_description

from .node_values import draws_sensor

LINK_RGB = (150, 160, 175)
JOINT_RGB = (70, 110, 160)
TOOL_RGB = (60, 60, 60)
SENSOR_RGB = (40, 40, 40)
FRUSTUM_RGB = (90, 90, 90)
SIGHT_RGB = FRUSTUM_RGB  # lines of sight (a lesson's step 7): the sensor's own colour
STEREO_BASELINE_MM = 120.0
CAMERA_FOV = np.deg2rad(50.0)


def _z_to(direction) -> np.ndarray:
    """wxyz of the rotation taking +z to `direction`."""
    d = np.asarray(direction, float)
    n = np.linalg.norm(d)
    if n == 0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    d = d / n
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    s, c = np.linalg.norm(axis), float(z @ d)
    if s < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0]) if c > 0 else np.array([0.0, 1.0, 0.0, 0.0])
    return np.asarray(vtf.SO3.exp(axis / s * np.arctan2(s, c)).wxyz, float)


def arm_segments(frames: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Link segments (start, end) between successive distinct frame origins of `frames` (8, 4, 4), the last one
    (flange to tool point) excluded: it is the stylus."""
    o = frames[:7, :3, 3]
    return [(o[i], o[i + 1]) for i in range(6) if np.linalg.norm(o[i + 1] - o[i]) > 1e-6]


class ArmNodes:
    """Nodes of the arm (under /arm): its URDF's meshes (or generated links and joints), the stylus, the
    commanded-versus-landed marks. `description` (models.arm_description.ArmDescription) and `stage` (what
    ViserUrdf draws on: the server or one tab) draw the URDF."""

    def __init__(self, scene: viser.SceneApi, description=None, stage=None, meshes: bool = True):
        self.scene = scene
        self.description = description
        self.stage = stage
        self.meshes = meshes  # False: links and joints drawn as cylinders (`rrbc view --simple-arm`)
        self.urdf: Any = None  # viser.extras.ViserUrdf of the description
        self.urdf_names: tuple[str, ...] = ()  # the description's actuated joints, in ViserUrdf's order
        self.links: list = []
        self.joints: list = []
        self.stylus: viser.CylinderHandle | None = None
        self.marks: dict = {}
        self.pose = None
        self.compact = False  # short label text (presentation mode)
        self.magnification = 1.0  # of the last pose shown
        self.chain_links = False  # a URDF without geometry: drawn as links between its joints (`_show_chain`)

    def _build_urdf(self) -> bool:
        """The description's meshes under /arm/urdf, its root at the description's base pose; False if they cannot
        be loaded (a message on stderr, generated links then)."""
        import sys

        from viser.extras import ViserUrdf

        d = self.description
        visual, collision = d.has_geometry()
        if not visual and not collision:
            print(
                f"rrbc view: {Path(d.urdf).name} has neither visual nor collision geometry: the arm is drawn as "
                "links between its joints",
                file=sys.stderr,
            )
            self.chain_links = True
            return False
        if not visual:
            print(f"rrbc view: {Path(d.urdf).name} has no visual geometry: the arm is drawn from its collision "
                  "geometry", file=sys.stderr)  # fmt: skip
        try:
            self.scene.add_frame(
                "/arm/urdf",
                show_axes=False,
                wxyz=np.asarray(vtf.SO3.from_matrix(d.rotation).wxyz, float),
                position=np.asarray(d.translation, float),
            )
            self.urdf = ViserUrdf(
                self.stage,
                Path(d.urdf),
                scale=1000.0,
                root_node_name="/arm/urdf",
                load_meshes=visual,
                load_collision_meshes=not visual,
                collision_mesh_color_override=None
                if visual
                else (LINK_RGB[0] / 255, LINK_RGB[1] / 255, LINK_RGB[2] / 255),
            )
        except Exception as exc:  # noqa: BLE001 - a description whose meshes do not load: generated links instead
            print(f"rrbc view: {Path(d.urdf).name}: its meshes could not be drawn ({exc}); generated links instead",
                  file=sys.stderr)  # fmt: skip
            self.scene.remove_by_name("/arm/urdf")
            self.urdf = None
            return False
        self.urdf_names = tuple(self.urdf.get_actuated_joint_names())
        return True

    def build(self, radius_mm: float = 38.0) -> None:
        sc = self.scene
        self.radius = radius_mm
        if self.meshes and self.description is not None and self.stage is not None and self._build_urdf():
            self.stylus = sc.add_cylinder("/arm/stylus", radius=4.0, height=1.0, color=TOOL_RGB, cast_shadow=False)
            self._build_marks()
            return
        n_links = 6
        if self.chain_links and self.description is not None:  # one link per gap between its joints' origins
            n_links = len(self.description.chain.joints) + 1
            radius_mm = min(radius_mm, 20.0)
        self.links = [
            sc.add_cylinder(f"/arm/link{i}", radius=radius_mm, height=1.0, color=LINK_RGB, cast_shadow=False)
            for i in range(n_links)
        ]
        self.joints = [
            sc.add_cylinder(
                f"/arm/joint{i}", radius=1.15 * radius_mm, height=2.4 * radius_mm, color=JOINT_RGB, cast_shadow=False
            )
            for i in range(n_links if not self.chain_links else n_links - 1)
        ]
        self.stylus = sc.add_cylinder("/arm/stylus", radius=4.0, height=1.0, color=TOOL_RGB, cast_shadow=False)
        self._build_marks()

    def _build_marks(self) -> None:
        sc = self.scene
        self.marks["line"] = sc.add_line_segments(
            "/arm/landing", np.zeros((1, 2, 3), np.float32), (30, 30, 30), thickness=2.0, thickness_units="screen"
        )
        self.marks["label"] = sc.add_label(
            "/arm/label", "", font_size_mode="screen", font_screen_scale=0.75, anchor="bottom-left"
        )

    def show(self, pose, magnification: float) -> None:
        """Pose the arm (session.arm.ArmPose) and draw where its real tool lands, offset ×magnification."""
        self.pose = pose
        if self.urdf is not None:
            self._show_urdf(pose)
        elif self.chain_links:
            self._show_chain(pose)
        else:
            self._show_links(pose)
        self._show_marks(pose, magnification)

    def _set_stylus(self, a, b) -> None:
        assert self.stylus is not None  # built with the arm
        self.stylus.position = 0.5 * (a + b)
        self.stylus.wxyz = _z_to(b - a)
        self.stylus.height = max(float(np.linalg.norm(b - a)), 1.0)

    def _show_urdf(self, pose) -> None:
        """The URDF posed at the pose's joints (the description's inputs; joints off its chain at 0), the stylus from
        the tip link's origin to the tool point."""
        assert self.urdf is not None
        d = self.description
        values = d.joint_values_si(pose.joints)
        self.urdf.update_cfg(np.array([values.get(n, 0.0) for n in self.urdf_names], float))
        tip = d.tip_frame(pose.joints)
        self._set_stylus(tip[:3, 3], d.tool_point(pose.joints))

    def _show_chain(self, pose) -> None:
        """A URDF arm without geometry: a link between each pair of successive joint origins (root, joints, tip), a
        joint cylinder along each moving joint's axis, the stylus to the tool point."""
        d = self.description
        pts = d.joint_points(pose.joints)
        for i, link in enumerate(self.links):
            a, b = pts[i], pts[i + 1]
            length = float(np.linalg.norm(b - a))
            link.visible = length > 1e-6
            if link.visible:
                link.position, link.wxyz, link.height = 0.5 * (a + b), _z_to(b - a), length
        g_rot = d.chain.frames(np.asarray(pose.joints, float)[None])[0][0]  # (K, 3, 3) before each motion
        for k, joint in enumerate(self.joints):
            joint.position = pts[k + 1]
            joint.wxyz = _z_to(d.rotation @ g_rot[k] @ d.chain.joints[k].axis)
        self._set_stylus(pts[-1], d.tool_point(pose.joints))

    def _show_links(self, pose) -> None:
        f = pose.frames
        segs = arm_segments(f)
        for i, link in enumerate(self.links):
            if i < len(segs):
                a, b = segs[i]
                link.position = 0.5 * (a + b)
                link.wxyz = _z_to(b - a)
                link.height = float(np.linalg.norm(b - a))
                link.visible = True
            else:
                link.visible = False
        for i, joint in enumerate(self.joints):  # joint i+1 turns about z of frame i
            joint.position = f[i, :3, 3]
            joint.wxyz = _z_to(f[i, :3, 2])
        self._set_stylus(f[6, :3, 3], f[7, :3, 3])

    def set_marks_visible(self, on: bool) -> None:
        """Show or hide where the real tool lands (its line and label): a lesson hides them, as its text does not
        talk about the arm's model error and its label would cover what the step shows."""
        for h in self.marks.values():
            h.visible = bool(on)

    def refresh_label(self) -> None:
        """The landing label again (its text is shorter in presentation mode)."""
        if self.pose is not None and self.marks:
            self._show_marks(self.pose, self.magnification)

    def _show_marks(self, pose, magnification: float) -> None:
        self.magnification = magnification
        end = pose.commanded + magnification * (pose.landed - pose.commanded)
        self.marks["line"].points = np.array([[pose.commanded, end]], np.float32)
        off = float(np.linalg.norm(pose.landed - pose.commanded))
        self.marks["label"].position = end
        self.marks["label"].text = (
            f"real arm {off:.3f} mm ×{magnification:g}"
            if self.compact
            else f"nominal model → real arm's tool: {off:.3f} mm (×{magnification:g})"
        )


def _look_wxyz(position, look_at, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """wxyz of a camera at `position` looking at `look_at` (OpenCV: +z forward, +y down)."""
    z = np.asarray(look_at, float) - np.asarray(position, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, -np.asarray(up, float))
    if np.linalg.norm(x) < 1e-9:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.asarray(vtf.SO3.from_matrix(np.stack([x, y, z], axis=1)).wxyz, float)


def sensor_cameras(kind: str, rotation, position, look_at) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The cameras drawn for a sensor: (wxyz, position, frustum depth mm) each (module docstring)."""
    r = np.asarray(rotation, float)
    p = np.asarray(position, float)
    look = np.asarray(look_at, float)
    depth = 0.85 * float(np.linalg.norm(look - p))
    q = np.asarray(vtf.SO3.from_matrix(r).wxyz, float)
    if kind == "stereo":
        half = 0.5 * STEREO_BASELINE_MM * r[:, 0]
        return [(q, p - half, depth), (q, p + half, depth)]
    if kind == "laser_tracker":
        return [(q, p, depth)]
    if kind == "mocap":
        out = []
        radius = float(np.linalg.norm((p - look)[:2])) or 1000.0
        for k in range(4):
            a = np.pi / 4 + k * np.pi / 2
            c = look + np.array([radius * np.cos(a), radius * np.sin(a), p[2] - look[2]])
            out.append((_look_wxyz(c, look), c, 0.85 * float(np.linalg.norm(look - c))))
        return out
    return []


class SensorNodes:
    """Nodes of the sensor (under /sensor): a body and a viewing frustum per camera."""

    def __init__(self, scene: viser.SceneApi):
        self.scene = scene
        self.cameras: list = []
        self._sight: Any = None  # /sensor/sight: lines of sight to the points a lesson step measures
        self._sight_key: bytes | None = None

    def build(self, kind: str, rotation, position, look_at) -> None:
        sc = self.scene
        self.cameras = sensor_cameras(kind, rotation, position, look_at)
        for i, (q, p, depth) in enumerate(self.cameras):
            sc.add_box(
                f"/sensor/camera{i}/body",
                color=SENSOR_RGB,
                dimensions=(70.0, 50.0, 60.0),
                wxyz=q,
                position=p,
                cast_shadow=False,
            )
            sc.add_camera_frustum(
                f"/sensor/camera{i}/frustum",
                fov=float(CAMERA_FOV),
                aspect=4 / 3,
                scale=depth,
                thickness=1.5,
                thickness_units="screen",
                color=FRUSTUM_RGB,
                wxyz=q,
                position=p,
            )
        if kind == "mocap":
            sc.add_label(
                "/sensor/note",
                "motion-capture cameras (placement illustrative; modelled as one sensor frame)",
                position=self.cameras[0][1] if self.cameras else np.zeros(3),
                font_size_mode="screen",
                font_screen_scale=0.7,
                anchor="bottom-left",
            )

    def show_sight_lines(self, points) -> None:
        """Lines of sight from each camera to `points` (N, 3) robot frame mm (a lesson step where the sensor measures
        them); None or no points removes them. Unchanged points are not sent again."""
        pts = None if points is None else np.asarray(points, float).reshape(-1, 3)
        key = None if pts is None or not len(pts) or not self.cameras else pts.tobytes()
        if key == self._sight_key:
            return
        self._sight_key = key
        if self._sight is not None:
            self._sight.remove()
            self._sight = None
        if key is None or pts is None:
            return
        starts = np.array([c[1] for c in self.cameras], float)
        segments = np.stack([np.repeat(starts, len(pts), axis=0), np.tile(pts, (len(starts), 1))], axis=1)
        self._sight = self.scene.add_line_segments(
            "/sensor/sight", segments, colors=SIGHT_RGB, thickness=1.5, thickness_units="screen"
        )


#: While a drag is under way the arm is posed at most this often (s); always at the drag's end.
ARM_DRAG_INTERVAL_S = 0.25


class ArmPoser:
    """Poses an `ArmNodes` where the scene needs it: reaching the bullseye's target from the scene's arm model (its
    inverse kinematics, throttled to a few times a second during a drag: IK and meshes cost), or at a measured
    point's joint values. `set_visible(bool)` shows or hides the arm's group (hidden where it cannot reach)."""

    def __init__(self, arm: ArmNodes, set_visible: Callable[[bool], None]):
        self.arm = arm
        self._set_visible = set_visible
        self._key: tuple | None = None  # what the arm was last posed for
        self._time = -1e18  # when (time.monotonic)

    def reach(self, model, position, magnification: float, tool, bias: float, moving: bool) -> None:
        """Reach `position` (robot frame, mm) with the tool down or leaned (tool: (tilt, azimuth) degrees), the
        scene's arm errors at `bias` times their size."""
        from rrbc_core.errors import InputError
        from rrbc_core.session.arm import arm_pose
        from rrbc_core.session.tools import tool_rotation

        key = (tuple(np.round(position, 9)), bias, magnification, tool)
        if key == self._key:
            return
        now = time.monotonic()
        if moving and now - self._time < ARM_DRAG_INTERVAL_S:
            return
        self._key, self._time = key, now
        rot = None
        if tool is not None:
            rot = tool_rotation(float(getattr(model, "tool_yaw_deg", 0.0) or 0.0), *tool)
        try:
            pose = arm_pose(model, position, bias, rot)
        except InputError:
            self._set_visible(False)
            return
        self._set_visible(True)
        self.arm.show(pose, magnification)

    def at_joints(self, session, selected: tuple[str, str], magnification: float) -> None:
        """Measured data: the arm at point `selected`'s joint values (hidden where the file has none)."""
        from rrbc_core.errors import InputError
        from rrbc_core.session.arm import measured_arm_pose

        if selected == self._key:
            return
        self._key = selected
        try:
            pose = measured_arm_pose(session, *selected)
        except InputError:
            self._set_visible(False)
            return
        self._set_visible(True)
        self.arm.show(pose, magnification)


def build_robot_nodes(
    scene_api, server, session, ev, arm_meshes: bool, show_arm: Callable[[bool], None]
) -> tuple[ArmNodes | None, ArmPoser | None, SensorNodes | None]:
    """Create the arm and the sensor of a session as what they are: a scene's UR arm or URDF reaching its targets
    (or a measurement file's `--urdf` arm) and its sensor's cameras unless it is ground truth. Returns the arm's
    nodes and its poser (None without an arm) and the sensor's nodes (None without one); `show_arm(on)` is called
    when the poser shows or hides the arm."""
    scene = getattr(session, "scene", None) if session.kind == "scene" else None
    arm = poser = sensor = None
    has_arm = scene is not None and (scene.robot_model in ("ur5", "ur10") or scene.robot_urdf is not None)
    if has_arm and len(ev.targets.ids):
        arm = ArmNodes(scene_api, arm_description(scene), server, arm_meshes)
    elif session.kind == "measurements" and session.arm is not None:  # rrbc view data.csv --urdf
        arm = ArmNodes(scene_api, session.arm, server)
    if arm is not None:
        arm.build()
        poser = ArmPoser(arm, show_arm)
    if draws_sensor(session):
        assert scene is not None
        t = scene.sensor_to_robot
        look = scene.sensor_look_at if scene.sensor_look_at is not None else ev.targets.positions.mean(0)
        sensor = SensorNodes(scene_api)
        sensor.build(scene.sensor_kind, t.rotation, t.translation, look)
    return arm, poser, sensor
