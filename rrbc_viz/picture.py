"""What the 3-D scene shows, as one value: `scene_picture(session, state, ev)` is a pure function from the session,
the app's state (`state.AppState`) and an Evaluation to a `ScenePicture`, which the scene's nodes render
(`nodes.SceneNodes.show`). The presenter (`controllers.present`) computes it; nothing the scene needs is read back
from the scene. Robot frame, millimetres."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from rrbc_core.session.evaluation import Evaluation

from .node_values import (
    CheckErrors,
    Display,
    LandingDisplay,
    check_errors,
    frame_magnification,
    landing_display,
    registered_frame_pose,
)

if TYPE_CHECKING:
    from rrbc_core.session.explorer import ExplorerSession

    from .state import AppState

#: the frames' axes are this share of the point sets' extent long
AXES_SHARE = 0.12
#: how the 95 % bounds are drawn (`Display.bound_scale`): (label, value); at true size a bound of tenths of a mm is
#: hidden inside its target's marker, so by default it is magnified as the arrows and landing offsets are
BOUND_SCALES = {"arrows": "× arrow magnification", "true": "true size"}
#: which corrected position a check row's drawn error is of (`Display.check_error`): (value, label)
CHECK_ERROR_CHOICES = {"rrbc": "after RRBC", "rigid": "rigid only"}


@dataclass(frozen=True)
class ScenePicture:
    """One frame of the scene (module docstring).

    Attributes
    ----------
    ev : Evaluation
        The points, corrections, hull and targets' landings to draw.
    selected : (kind, id) or None
        The point carrying the drag gizmo (its label always shows).
    display : Display
        Magnification, marker size and the other display options.
    target_arrows : bool
        Draw the targets' correction arrows.
    landing : LandingDisplay or None
        The bullseye of the selected target (the first target while a fiducial or nothing is selected).
    extent_mm : float
        The point sets' extent (mm) the frames' axes are sized from (`state.AppState.extent_mm`).
    frame_mag : float
        The registered sensor frame's error is drawn this many times larger.
    registered_wxyz, registered_position : (4,), (3,)
        Where the registered sensor frame is drawn (its error magnified `frame_mag` times).
    bias_scale : float
        The session's bias size (the real arm's landing scales with it).
    tool : (tilt, azimuth) degrees or None
        The leaned tool of the bullseye's target (None: tool down).
    drag_active : bool
        A drag is under way (the arm follows at most a few times a second).
    check_errors : CheckErrors or None
        A measurement file's check rows' errors, as `Display.check_error` picks (None without check rows).
    bound_rotations, bound_axes : (M, 3, 3), (M, 3)
        Each target's 95 % bound ellipsoid (`rrbc_core.correction.bounds.PointBounds.ellipsoids` of its RRBC
        position's covariance): axes' rotation and semi-axes, mm (NaN: no bound).
    """

    ev: Evaluation
    selected: tuple[str, str] | None
    display: Display
    target_arrows: bool
    landing: LandingDisplay | None
    extent_mm: float
    frame_mag: float
    registered_wxyz: np.ndarray = field(repr=False)
    registered_position: np.ndarray = field(repr=False)
    bias_scale: float = 1.0
    tool: tuple[float, float] | None = None
    drag_active: bool = False
    changed: tuple = ()  # (id, change mm) of the targets the last fiducial drag changed most (`changed_targets`)
    check_errors: CheckErrors | None = None
    bound_rotations: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)), repr=False)
    bound_axes: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)


def scene_extent(ev: Evaluation) -> float:
    """The extent (diagonal of the bounding box, mm, at least 1) of the registration points, fiducials and targets."""
    pts = np.vstack(
        [
            ev.registration_positions.reshape(-1, 3),
            ev.fiducial_positions.reshape(-1, 3),
            ev.targets.positions.reshape(-1, 3),
        ]
    )
    return max(float(np.linalg.norm(pts.max(0) - pts.min(0))) if len(pts) else 1000.0, 1.0)


def changed_targets(state: AppState, ev: Evaluation) -> tuple[tuple[str, float], ...]:
    """(id, |ê change| mm) of the targets whose correction the last fiducial drag changed most, largest first
    (`rrbc_core.session.results.largest_changes` against `state.drag_baseline`); () without one."""
    from rrbc_core.session.results import correction_changes, largest_changes

    if state.drag_baseline is None:
        return ()
    t = ev.targets
    ids, before = state.drag_baseline
    return largest_changes(t.ids, correction_changes(ids, before, t.ids, t.correction_robot))


def scene_picture(session: ExplorerSession, state: AppState, ev: Evaluation) -> ScenePicture:
    """What the scene shows for `ev` in `state` (module docstring). The bullseye keeps the ring of the one last shown
    for the same target (`state.landing`): during a drag always, so a doubled error is drawn twice as far out, and
    after it while the offsets still fit (`node_values.landing_display`), so releasing does not rescale it."""
    display = state.display
    t = ev.targets
    landing = None
    tool = None
    if len(t.ids):
        sel = state.selected
        i = t.ids.index(sel[1]) if sel is not None and sel[0] == "targets" and sel[1] in t.ids else 0
        held = state.landing
        ring = held.ring_mm if held is not None and held.target == t.ids[i] else None
        vec = state.vec_landings().get(t.ids[i])
        landing = landing_display(t, i, display.marker_mm, vec, ring, keep_fitting=not state.drag_active)
        tool = session.target_tools.get(t.ids[i])
    true_pose = session.sensor_to_robot
    mapping = ev.registration.mapping
    frame_mag = frame_magnification(true_pose, mapping, AXES_SHARE * state.extent_mm, display.magnification)
    reg_wxyz, reg_position = registered_frame_pose(true_pose, mapping, frame_mag)
    if ev.bounds is not None:
        bound_rot, bound_axes = ev.bounds.rrbc.ellipsoids()
        if display.bound_scale == "arrows":  # drawn as the error arrows are: comparable with the landing offsets
            bound_axes = bound_axes * display.magnification
    else:
        bound_rot, bound_axes = np.zeros((len(t.ids), 3, 3)), np.full((len(t.ids), 3), np.nan)
    return ScenePicture(
        ev=ev,
        selected=state.selected,
        display=display,
        target_arrows=state.target_arrows,
        landing=landing,
        extent_mm=state.extent_mm,
        frame_mag=frame_mag,
        registered_wxyz=reg_wxyz,
        registered_position=reg_position,
        bias_scale=float(session.settings.bias_scale) if session.kind == "scene" else 1.0,
        tool=None if tool is None else (float(tool[0]), float(tool[1])),
        drag_active=state.drag_active,
        changed=changed_targets(state, ev),
        check_errors=check_errors(ev, display.check_error, display.magnification, state.extent_mm),
        bound_rotations=bound_rot,
        bound_axes=bound_axes,
    )
