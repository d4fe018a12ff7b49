"""Camera with intent: views framed on what they are about, with the control panel's width allowed for.

A view is a set of points that must be on screen and a viewing direction (`View`); `CameraDirector` frames it
for each browser tab's own image size (`rrbc_core.geometry.framing.frame_points`: the closest camera that shows
every point inside the part of the image the floating panel leaves free) and moves that tab's camera, or sets the
initial camera of tabs still to come. Frames and units: robot frame, mm (the scene frame).

Presets (View tab → Camera): the whole cell (mesh, robot, sensor; measured data: the data and their mesh), the work area (the point sets, looked at
from their far side with the arm behind them: the opening view), a close-up from above on the targets and fiducials, the sensor's view, the selected point. The Learn tab's steps frame what each step talks about (`teaching.Step.focus`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.framing import DEFAULT_MARGIN, CameraPose, frame_points, in_view

if TYPE_CHECKING:
    from .stage import Stage

#: The floating control panel's width (theme control_width="large": 24 em × 16 px; set explicitly by
#: `controls.Controls.apply_theme`), and in presentation mode (its text is larger); the gap to the window's edge.
PANEL_WIDTH_PX = 24 * 16
PRESENTATION_PANEL_WIDTH_PX = 560
PANEL_GAP_PX = 24
PANEL_PX = PANEL_WIDTH_PX + PANEL_GAP_PX


def panel_px(presentation: bool) -> float:
    """What the panel takes of a view's width (its width and a gap, CSS px): a framed view leaves it free."""
    return float((PRESENTATION_PANEL_WIDTH_PX if presentation else PANEL_WIDTH_PX) + PANEL_GAP_PX)


#: The free border of a framed view (a fraction of the free area's half-size): in presentation mode the labels are
#: larger (`nodes` label scale), and a label centred over a point at the frame's edge needs the room.
PRESENTATION_MARGIN = 0.2


def frame_margin(presentation: bool) -> float:
    """The free border a framed view keeps (`geometry.framing.frame_points`' margin)."""
    return PRESENTATION_MARGIN if presentation else DEFAULT_MARGIN


#: The image the initial camera is framed for (tabs report their own size once connected).
DEFAULT_IMAGE = (1280, 800)
FOV_Y = np.deg2rad(50.0)

#: Viewing directions (camera → scene), robot frame.
OBLIQUE = np.array([-0.25, 1.0, -0.75])  # from the front (−y) left, looking down at ~35°
STEEP = np.array([-0.15, 0.55, -1.0])  # a close-up from above the work area
TOP = np.array([0.0, 0.05, -1.0])

PRESETS = ("whole cell", "work area", "close-up", "sensor's view", "selected point")
#: The view a scene opens with.
OPENING = "work area"


@dataclass(frozen=True)
class View:
    """What a camera must show: `points` (N, 3) robot frame, mm; `direction` (3,) camera → scene; `position`
    (3,) a fixed camera position (the sensor's view) or None to frame from `direction`."""

    points: np.ndarray
    direction: np.ndarray
    position: np.ndarray | None = None


#: Room kept above the framed points for a label drawn over its point (the selected point's: one line of text lifted
#: above the sphere), CSS px, besides the margin: a point at the top of the view keeps its label in it.
LABEL_ROOM_PX = 32.0


def _pose_from(
    view: View, fov_y: float, aspect: float, width_px: float, panel_px: float = PANEL_PX, margin: float = DEFAULT_MARGIN
) -> CameraPose:
    panel = float(np.clip(panel_px / max(width_px, 1.0), 0.0, 0.6))
    half_height_px = 0.5 * max(width_px, 1.0) / aspect
    top = min(margin + LABEL_ROOM_PX / half_height_px, 0.5)
    if view.position is not None:  # from a fixed place: look at the points' centre, framed by the fov alone
        centre = 0.5 * (view.points.min(0) + view.points.max(0))
        up = np.array([0.0, 0.0, 1.0])
        return CameraPose(np.asarray(view.position, float), centre, up, fov_y, aspect)
    return frame_points(view.points, view.direction, fov_y, aspect, panel_fraction=panel, margin=margin, top_margin=top)


#: how far in from a view's edges (a fraction of its half-size) a dragged target and its bullseye must lie to count
#: as seen (`CameraDirector.keep_in_view`)
KEEP_MARGIN = 0.1


class CameraDirector:
    """Moves the cameras of the server's tabs (or one tab's) to a `View`."""

    def __init__(self, server: Stage):
        self.server = server
        self.last: dict[int, CameraPose] = {}  # client id -> the pose last sent to it
        self.initial: CameraPose | None = None
        self.panel_px = float(PANEL_PX)  # the panel's width and gap: what a framed view leaves free
        self.margin = float(DEFAULT_MARGIN)  # the free border it keeps (`frame_margin`)

    def set_initial(self, view: View, near: float, far: float) -> CameraPose:
        """The camera every newly opened tab starts with."""
        w, h = DEFAULT_IMAGE
        pose = _pose_from(view, FOV_Y, w / h, w, self.panel_px, self.margin)
        cam = self.server.initial_camera
        cam.fov = float(FOV_Y)
        cam.near = near
        cam.far = far
        cam.up = (0.0, 0.0, 1.0)
        cam.position = tuple(pose.position)
        cam.look_at = tuple(pose.look_at)
        self.initial = pose
        return pose

    def set_panel(self, px: float, margin: float = DEFAULT_MARGIN) -> None:
        """The panel's width and gap (`panel_px`): what views framed from now on leave free; and the free border they
        keep (`frame_margin`)."""
        self.panel_px = float(px)
        self.margin = float(margin)

    def reframe_initial(self, view: View) -> CameraPose | None:
        """The initial camera framed again for `view` (the panel's width changed), near and far kept; the pose, or
        None when there is no initial camera yet."""
        cam = self.server.initial_camera
        if self.initial is None:
            return None
        return self.set_initial(view, cam.near, cam.far)

    def show(self, view: View, clients=None) -> dict[int, CameraPose]:
        """Move the camera of each client in `clients` (default: every connected tab) to `view`, framed for that
        tab's image; tabs that have not reported their camera yet keep the initial one. Returns the poses sent."""
        if not len(view.points):
            raise InputError("nothing to show")
        out = {}
        targets = list(self.server.get_clients().values()) if clients is None else list(clients)
        for client in targets:
            cam = client.camera
            try:
                aspect, width = float(cam.aspect), float(cam.image_width)
            except AssertionError:  # no camera message from this tab yet
                continue
            if not (aspect > 0 and width > 0):
                continue
            pose = _pose_from(view, float(cam.fov), aspect, width, self.panel_px, self.margin)
            with client.atomic():
                cam.up_direction = (0.0, 0.0, 1.0)
                cam.position = tuple(pose.position)  # moves look_at along: set it after
                cam.look_at = tuple(pose.look_at)
            self.last[client.client_id] = pose
            out[client.client_id] = pose
        return out

    def keep_in_view(self, points, context: np.ndarray, clients=None) -> dict[int, CameraPose]:
        """Bring `points` (K, 3) robot frame, mm (a target dragged out of the frame, with its bullseye), back into the
        view of each tab (default: every connected one) that no longer sees them all beside the panel and
        `KEEP_MARGIN` in from its edges (a point at the very edge has its label and bullseye cut off): that tab's
        camera keeps its viewing direction and frames `context` (N, 3) with the points. Tabs that see them are left
        as they are. Returns the poses sent."""
        p = np.asarray(points, float).reshape(-1, 3)
        out = {}
        for client, now in self._reported(clients).items():
            width = float(client.camera.image_width)
            panel = float(np.clip(self.panel_px / width, 0.0, 0.6))
            if bool(np.all(in_view(p, now, panel, margin=KEEP_MARGIN))):
                continue
            view = View(np.vstack([np.asarray(context, float).reshape(-1, 3), p]), now.look_at - now.position)
            out.update(self.show(view, [client]))
        return out

    def current(self, clients=None) -> dict[int, CameraPose]:
        """client id -> the pose its camera reports now, for each of `clients` (default: every connected tab) that
        has reported a usable one."""
        return {client.client_id: pose for client, pose in self._reported(clients).items()}

    def _reported(self, clients=None) -> dict:
        out = {}
        targets = list(self.server.get_clients().values()) if clients is None else list(clients)
        for client in targets:
            cam = client.camera
            try:
                aspect, width, fov = float(cam.aspect), float(cam.image_width), float(cam.fov)
                position, look_at = np.asarray(cam.position, float), np.asarray(cam.look_at, float)
            except AssertionError:  # no camera message from this tab yet
                continue
            if not (aspect > 0 and width > 0) or np.allclose(position, look_at):
                continue
            out[client] = CameraPose(position, look_at, np.array([0.0, 0.0, 1.0]), fov, aspect)
        return out


@dataclass(frozen=True)
class CellGeometry:
    """What the views are made of (robot frame, mm): the point sets, the mesh's bounds (2, 3) or None, the
    sensor's origin and what it looks at (None without a sensor pose) and its kind."""

    registration: np.ndarray
    fiducials: np.ndarray
    targets: np.ndarray
    mesh_bounds: np.ndarray | None
    sensor_position: np.ndarray | None
    sensor_kind: str | None

    def points(self, *names: str) -> np.ndarray:
        parts = {
            "registration": self.registration,
            "fiducials": self.fiducials,
            "targets": self.targets,
            "robot": np.zeros((1, 3)),
            "sensor": self.sensor_position.reshape(1, 3) if self.sensor_position is not None else np.zeros((0, 3)),
            "mesh": _corners(self.mesh_bounds) if self.mesh_bounds is not None else np.zeros((0, 3)),
        }
        out = np.vstack([parts[n].reshape(-1, 3) for n in names])
        if not len(out):
            out = np.vstack([self.registration, self.fiducials, self.targets, np.zeros((1, 3))])
        return out


def _corners(bounds) -> np.ndarray:
    b = np.asarray(bounds, float).reshape(2, 3)
    return np.array([[b[i, 0], b[j, 1], b[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])


def _halo(points: np.ndarray, radius: float) -> np.ndarray:
    """`points` and the 6 points ±radius along each axis around each of them."""
    d = np.vstack([np.eye(3), -np.eye(3)]) * radius
    return np.vstack([points, (points[:, None, :] + d[None]).reshape(-1, 3)])


#: how far the work-area view turns from the line through the work to the robot's base (a three-quarter view: the
#: arm stands behind the work, to one side, not in front of it nor hiding its far half)
ASIDE_RAD = np.deg2rad(35.0)


def facing_robot(work: np.ndarray, base=None, down: np.ndarray = OBLIQUE) -> np.ndarray:
    """The work-area view's direction (camera -> scene, robot frame): looking from the work's far side towards the
    robot's base `base` (3,) (default the origin), turned `ASIDE_RAD` to one side and tilted down as `down` (the
    close-up's: as `STEEP`), so the arm is context behind the work and never the wrist in front of it. `down` where
    the base lies under the work (no side to look from)."""
    pts = np.asarray(work, float).reshape(-1, 3)
    if not len(pts):
        return down
    base = np.zeros(3) if base is None else np.asarray(base, float)
    lo, hi = pts.min(0), pts.max(0)
    toward = (base - 0.5 * (lo + hi))[:2]
    reach = float(np.linalg.norm(toward))
    if reach <= 0.25 * float(np.linalg.norm((hi - lo)[:2])):
        return down
    c, s = np.cos(ASIDE_RAD), np.sin(ASIDE_RAD)
    h = np.array([c * toward[0] - s * toward[1], s * toward[0] + c * toward[1]]) / reach
    tilt = down[2] / np.linalg.norm(down[:2])
    return np.array([h[0], h[1], tilt])


def preset_view(name: str, cell: CellGeometry, selected=None, marker_mm: float = 8.0) -> View:
    """The View of a camera preset (`PRESETS`). `selected`: (M, 3) points the selected-point view must show (the
    point, its region, its landings), which the work area shows too (the bullseye beside the selected target stays
    beside the panel), or None."""
    work = cell.points("targets", "fiducials")
    if name == "whole cell":  # a modelled cell with its robot's base; measured data: the data (and their mesh)
        robot = ("robot",) if cell.sensor_kind is not None else ()
        return View(cell.points("mesh", "registration", "fiducials", "targets", "sensor", *robot), OBLIQUE)
    if name == "sensor's view":
        if cell.sensor_position is not None and cell.sensor_kind in ("stereo", "mocap", "laser_tracker"):
            return View(_halo(work, 2 * marker_mm), OBLIQUE, position=cell.sensor_position)
        return View(_halo(work, 2 * marker_mm), TOP)  # no camera to look through: straight down on the work
    if name == "work area":  # where the robot works: registration points, fiducials, targets; in a modelled cell
        # looked at from the work's far side, the arm behind it as context (not its base framed: issue 39)
        pts = cell.points("registration", "fiducials", "targets")
        direction = facing_robot(pts) if cell.sensor_kind is not None else OBLIQUE
        if selected is not None and len(selected):
            pts = np.vstack([pts, np.asarray(selected, float).reshape(-1, 3)])
        return View(_halo(pts, 2 * marker_mm), direction)
    if name == "close-up":  # the targets and fiducials from above (the fixture plate); in a modelled cell from the
        # work's far side as the work area is (issue 39: from the front the arm reaching a target filled a third of it)
        return View(
            _halo(work, 2 * marker_mm), facing_robot(work, down=STEEP) if cell.sensor_kind is not None else STEEP
        )
    if name == "selected point":
        pts = work if selected is None or not len(selected) else np.asarray(selected, float).reshape(-1, 3)
        return View(_halo(pts, 4 * marker_mm), STEEP)
    raise InputError(f"unknown camera preset '{name}': {', '.join(PRESETS)}")
