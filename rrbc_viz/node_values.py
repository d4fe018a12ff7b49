"""Values the scene's nodes are built from, computed without viser: node names, the display options, the points'
labels, the landing bullseye's geometry, the registered frame's magnified pose and "nice" scale numbers. Robot frame,
mm. Used by `nodes.SceneNodes` and the panels."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import viser.transforms as vtf

from rrbc_core.session.evaluation import Evaluation

#: The scene's layers, each shown or hidden as a whole (View tab).
LAYERS = (
    "mesh",
    "arm",
    "arm_error",
    "sensor",
    "frames",
    "registration",
    "fiducials",
    "corrections",
    "hull",
    "targets",
    "regions",
    "bounds",
    "check_errors",
    "landing",
    "labels",
    "heatmap",
    "slice",
)
#: what the View tab calls each layer (a layer is its name above, its label here, its nodes in a scene class and
#: what it draws in `picture.ScenePicture`)
LAYER_LABELS = {
    "mesh": "Work-cell mesh",
    "arm": "Robot arm (reaching the selected target)",
    "arm_error": "Arm's model error at the tool (magnified)",
    "sensor": "Sensor cameras and their views",
    "frames": "Robot and sensor frames",
    "registration": "Registration points",
    "fiducials": "Fiducials",
    "corrections": "Correction arrows",
    "hull": "Fiducials' hull",
    "targets": "Targets",
    "regions": "Regions of variability",
    "bounds": "95 % bounds of the targets",
    "check_errors": "Check errors (measured rows, × arrows, coloured by size)",
    "landing": "Landing points (rigid vs RRBC)",
    "labels": "Labels",
    "heatmap": "Heat map of predicted error",
    "slice": "Error slice (predicted error on a plane)",
}


#: A drag gizmo's size in marker radii.
GIZMO_MARKERS = 5.0


def gizmo_size(marker_mm: float) -> float:
    """A drag gizmo's size (mm) for spheres of radius `marker_mm`."""
    return GIZMO_MARKERS * float(marker_mm)


def label_heights(marker_mm: float) -> tuple[float, float]:
    """How far above its point a point's label is drawn, and the selected point's (over its drag gizmo's up arrow,
    whose arrows and planes would cover it lower), mm, for spheres of radius `marker_mm`."""
    return 1.6 * float(marker_mm), 1.1 * gizmo_size(marker_mm)


def label_side(marker_mm: float) -> float:
    """How far beside the vertical line through its point the selected point's label starts (mm): its drag handle's
    up arrow and the arm's stylus (radius 4 mm) come down that line."""
    return 4.0 + float(marker_mm)


def node_key(pid: str) -> str:
    return str(pid).replace("/", "_") or "_"


def gizmo_name(kind: str, pid: str) -> str:
    """Scene-node name of the drag gizmo of a point: kind "targets" or "fiducials", e.g. /targets/H1/gizmo."""
    return f"/{kind}/{node_key(pid)}/gizmo"


@dataclass
class Display:
    """Display-only options (no effect on any number)."""

    magnification: float = 200.0  # arrows and landing offsets drawn this many times longer
    bound_scale: str = "arrows"  # the 95 % bounds drawn ×magnification like the arrows ("arrows") or "true" size
    check_error: str = "rrbc"  # the check rows' errors drawn (`CheckErrors`): after RRBC ("rrbc") or rigid ("rigid")
    marker_mm: float = 8.0  # radius of fiducial / target spheres
    region_zoom: float = 1.0  # regions and heat-map samples drawn this many times larger about their target
    heat_value: str = "rrbc"  # rrbc | rigid (scene); correction | std (measurements)
    slice_value: str = "rrbc"  # the error slice's value: rrbc | rigid | bound95 | correction | std
    slice_axis: str = "z"  # the slice plane's normal: x | y | z (robot frame)
    slice_offset: float | None = None  # mm along slice_axis; None: the work's median


def wxyz(rotation) -> np.ndarray:
    return np.asarray(vtf.SO3.from_matrix(np.asarray(rotation, float)).wxyz, float)


def unit_sphere():
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    return np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.uint32)


def identity_wxyzs(n: int) -> np.ndarray:
    q = np.zeros((n, 4), np.float32)
    q[:, 0] = 1.0
    return q


def fiducial_labels(ev: Evaluation) -> list[str]:
    """Label texts of every fiducial (correction size, or 'excluded')."""
    norms = np.linalg.norm(ev.corrections, axis=1)
    return [
        f"{pid} · e {norms[i]:.3f} mm" if ev.included[i] else f"{pid} · excluded"
        for i, pid in enumerate(ev.fiducial_ids)
    ]


def fiducial_label(pid: str, ev: Evaluation, i: int) -> str:
    return fiducial_labels(ev)[i]


def target_labels(ev: Evaluation, compact: bool = False) -> list[str]:
    """Label texts of every target (errors against the truth, or the correction and its std without truth);
    `compact`: short texts for large labels (presentation mode), "H1 0.738 → 0.119 mm"."""
    t = ev.targets
    corr = np.linalg.norm(t.correction, axis=1)
    std = None if t.correction_std is None else np.linalg.norm(t.correction_std, axis=1)
    out = []
    for i, pid in enumerate(t.ids):
        if np.isfinite(t.error_rigid[i]) and compact:
            s = f"{pid} {t.error_rigid[i]:.3f} → {t.error_rrbc[i]:.3f} mm"
        elif np.isfinite(t.error_rigid[i]):
            s = f"{pid} · rigid {t.error_rigid[i]:.3f} / RRBC {t.error_rrbc[i]:.3f} mm"
        else:
            s = f"{pid} · ê {corr[i]:.3f} mm"
            if std is not None:
                s += f" ± {std[i]:.3f}"
        if bool(t.extrapolated[i]):
            s += " ⚠" if compact else " ⚠ extrapolated"
        out.append(s)
    return out


def target_label(pid: str, ev: Evaluation, i: int) -> str:
    return target_labels(ev)[i]


@dataclass(frozen=True)
class LandingDisplay:
    """The landing bullseye of one target, floating `lift` mm above it (and beside it, away from the robot's base)
    so neither part geometry nor the arm hides it (robot frame, mm; display only): `anchor` (3,) stands for the truth, `rigid` and `rrbc` (3,) for the landings, their
    offsets from the truth drawn ×`scale`; a horizontal scale ring of real radius `ring_mm` (a 1-2-5 number at
    least as large as the larger offset) is drawn `ring_mm × scale` = RING_MARKERS marker radii wide, whatever the
    arrows' magnification. Without truth the offsets are taken from the rigid landing (rigid at the centre)."""

    target: str
    position: np.ndarray
    anchor: np.ndarray
    rigid: np.ndarray
    rrbc: np.ndarray
    lift: float
    ring_mm: float
    scale: float
    vec: np.ndarray | None = None  # VEC's landing (Arm tab on), drawn like the others

    def rings(self) -> np.ndarray:
        """(2 * RING_SEGMENTS, 2, 3) segments: the scale ring and a dashed half-size ring (every other segment)."""
        a = np.linspace(0.0, 2 * np.pi, RING_SEGMENTS + 1)
        c = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], 1) * self.ring_mm * self.scale
        outer = np.stack([c[:-1], c[1:]], 1)
        inner = 0.5 * outer
        inner[1::2] = inner[::2][: len(inner[1::2])]  # dashed: odd segments collapse onto even ones
        return self.anchor + np.concatenate([outer, inner])


RING_SEGMENTS = 48
RING_MARKERS = 6.0


def frame_magnification(true_pose, registered, axes_mm: float, limit: float) -> float:
    """The 1-2-5 magnification (≤ limit, ≥ 1) that draws the registered frame's offset from the true one about
    half an axis long: beside it, not across the cell."""
    if true_pose is None:
        return 1.0
    d = float(np.linalg.norm(np.asarray(registered.translation, float) - np.asarray(true_pose.translation, float)))
    if d <= 0:
        return float(limit)
    return float(np.clip(nice_down(0.5 * axes_mm / d), 1.0, limit))


def nice_down(x: float) -> float:
    """The 1-2-5 number at or below x (x > 0)."""
    e = 10.0 ** np.floor(np.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * e <= x:
            return m * e
    return e


def registered_frame_pose(true_pose, registered, magnification: float) -> tuple[np.ndarray, np.ndarray]:
    """(wxyz, position) at which the registered sensor frame is drawn: its translation and rotation error from the
    true pose (when known) magnified `magnification` times (`frame_magnification`), so the two frames stand apart;
    without a true pose, where it is. Robot frame, mm."""
    if true_pose is None:
        return wxyz(registered.rotation), np.asarray(registered.translation, float)
    r_true = vtf.SO3.from_matrix(np.asarray(true_pose.rotation, float))
    r_reg = vtf.SO3.from_matrix(np.asarray(registered.rotation, float))
    err = (r_true.inverse() @ r_reg).log()  # rotation error, radians, in the true frame
    angle = float(np.linalg.norm(err))
    k = magnification if angle * magnification < np.pi else np.pi / max(angle, 1e-300) * 0.99  # stay < 180°
    rot = r_true @ vtf.SO3.exp(err * k)
    t_true = np.asarray(true_pose.translation, float)
    position = t_true + magnification * (np.asarray(registered.translation, float) - t_true)
    return np.asarray(rot.wxyz, float), position


def nice_up(x: float) -> float:
    """The 1-2-5 number at or above x (x > 0)."""
    e = 10.0 ** np.floor(np.log10(x))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * e >= x * (1 - 1e-12):
            return m * e
    return 10.0 * e


def landing_offsets(t, i: int) -> tuple[np.ndarray, np.ndarray, bool]:
    """Target i's rigid and RRBC landing offsets (3,) each, robot frame, mm, from the truth (known=True) or from
    the rigid landing (known=False); `t` an evaluation.TargetResult."""
    known = bool(np.all(np.isfinite(t.truth[i])))
    ref = t.truth[i] if known else t.robot_rigid[i]
    return t.robot_rigid[i] - ref, t.robot_rrbc[i] - ref, known


#: after a drag the bullseye keeps its ring while its largest offset stays within this many rings of the centre and
#: above a tenth of a ring (beyond, the offsets would leave the bullseye or shrink to dots: the ring is fitted again)
KEEP_RINGS = 3.0


def landing_display(
    t, i: int, marker_mm: float, vec=None, ring_mm: float | None = None, keep_fitting: bool = False
) -> LandingDisplay:
    """The landing bullseye of target i of `t` (evaluation.TargetResult), with VEC's landing `vec` (3,) robot frame
    mm when given. It floats beside the target, away from the robot's base (the arm reaches the target from that
    side, its wrist straight above it) and above it. `ring_mm`: keep this ring (and so the drawing scale) instead of
    fitting the ring to the offsets (during a drag: a doubled error is drawn twice as far out); with `keep_fitting`
    (after the drag) only while the largest offset lies between a tenth of a ring and `KEEP_RINGS` rings."""
    off_rigid, off_rrbc, known = landing_offsets(t, i)
    off_vec = None if vec is None else np.asarray(vec, float) - (t.truth[i] if known else t.robot_rigid[i])
    biggest = float(max(np.linalg.norm(off_rigid), np.linalg.norm(off_rrbc)))
    if off_vec is not None:
        biggest = max(biggest, float(np.linalg.norm(off_vec)))
    if ring_mm is not None and keep_fitting and not 0.1 * ring_mm <= biggest <= KEEP_RINGS * ring_mm:
        ring_mm = None
    ring = float(ring_mm) if ring_mm is not None else nice_up(biggest) if biggest > 0 else 0.1
    radius = RING_MARKERS * marker_mm
    scale = radius / ring
    out = np.array([t.positions[i][0], t.positions[i][1], 0.0])
    out = out / np.linalg.norm(out) if np.linalg.norm(out) > 1e-9 else np.array([1.0, 0.0, 0.0])
    lift = radius + 2.0 * marker_mm
    anchor = t.positions[i] + 1.6 * radius * out + np.array([0.0, 0.0, lift])
    return LandingDisplay(
        str(t.ids[i]),
        t.positions[i],
        anchor,
        anchor + scale * off_rigid,
        anchor + scale * off_rrbc,
        lift,
        ring,
        scale,
        None if off_vec is None else anchor + scale * off_vec,
    )


#: the pair's anchor stands this many marker radii above its fiducial
LIFT_MARKERS = 4.0


@dataclass(frozen=True)
class FiducialReadings:
    """One fiducial's readings as the scene draws them: `fiducial` its drawn position, `sensor` R s + t and `robot`
    b (each (3,) robot frame, mm), `magnification` the drawn offset's scale."""

    pid: str
    fiducial: np.ndarray
    sensor: np.ndarray
    robot: np.ndarray
    magnification: float

    def drawn(self, marker_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """Where s and b are drawn (robot frame, mm): s above the fiducial, b at s + magnification × (b − s)."""
        anchor = np.asarray(self.fiducial, float) + np.array([0.0, 0.0, LIFT_MARKERS * marker_mm])
        return anchor, anchor + self.magnification * (np.asarray(self.robot, float) - np.asarray(self.sensor, float))


#: the check rows' largest errors that are labelled in the scene
CHECK_ERROR_LABELS = 3
#: the longest check-error arrow is at most this share of the point sets' extent (millimetre errors on a station
#: several metres wide would otherwise run out of the view at the arrows' magnification)
CHECK_ERROR_SHARE = 0.15


def legible_magnification(largest_mm: float, length_mm: float, limit: float) -> float:
    """The largest 1-2-5 magnification, at most `limit` and at least 1, that draws `largest_mm` at most `length_mm`
    long (`limit` itself when that fits)."""
    if not (largest_mm > 0) or largest_mm * limit <= length_mm:
        return float(limit)
    top = length_mm / largest_mm
    if top <= 1.0:
        return 1.0
    decade = 10.0 ** np.floor(np.log10(top))
    return float(max(m * decade for m in (1.0, 2.0, 5.0) if m * decade <= top))


@dataclass(frozen=True, eq=False)
class CheckErrors:
    """A measurement file's check rows' errors as the scene draws them: `ids` (K,), `starts` (K, 3) where each is
    drawn (the row's position), `vectors` (K, 3) its error (corrected position − measured robot position, robot
    frame, mm) times `magnification`, `sizes_mm` (K,) the error's length (`TargetResult.error_rrbc` or
    `error_rigid`: the card's and the table's numbers), `method` "rrbc" or "rigid", `magnification` the arrows'
    (`legible_magnification`), `labelled` the indices of the largest `CHECK_ERROR_LABELS` errors."""

    ids: tuple
    starts: np.ndarray
    vectors: np.ndarray
    sizes_mm: np.ndarray
    method: str
    magnification: float

    @property
    def labelled(self) -> np.ndarray:
        return np.argsort(-self.sizes_mm, kind="stable")[:CHECK_ERROR_LABELS]


def check_errors(ev: Evaluation, method: str, magnification: float, extent_mm: float) -> CheckErrors | None:
    """The check rows' errors of `ev` after `method` ("rrbc" or "rigid"), drawn at the arrows' `magnification` or
    less, so the longest is at most `CHECK_ERROR_SHARE` of the point sets' `extent_mm`; None without check rows with
    a known robot position."""
    t = ev.targets
    rows = [i for i, pid in enumerate(t.ids) if pid in ev.check_ids and np.all(np.isfinite(t.truth[i]))]
    if not rows:
        return None
    at = np.asarray(rows, int)
    landed = (t.robot_rrbc if method == "rrbc" else t.robot_rigid)[at]
    sizes = np.asarray((t.error_rrbc if method == "rrbc" else t.error_rigid)[at], float)
    largest = float(np.nanmax(sizes)) if np.any(np.isfinite(sizes)) else 0.0
    mag = legible_magnification(largest, CHECK_ERROR_SHARE * extent_mm, magnification)
    return CheckErrors(
        tuple(t.ids[i] for i in rows),
        np.asarray(t.positions[at], float),
        mag * (landed - t.truth[at]),
        sizes,
        method,
        mag,
    )


def draws_sensor(session) -> bool:
    """Whether the app draws the session's sensor (its cameras' bodies and lines of sight): a scene's sensor that is
    not the ground truth. A measurement file says nothing of where its sensor stood."""
    scene = getattr(session, "scene", None) if session.kind == "scene" else None
    return scene is not None and scene.sensor_kind != "ground_truth"
