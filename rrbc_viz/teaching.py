"""The lesson: NIST's nine RRBC steps, one screen each, with live numbers.

Each `Step` names the scene layers that show its result (nodes.LAYERS) and renders one or two sentences as
markdown. Every number quoted comes from the current `Evaluation` (or, for regions, the session's scene);
nothing is computed here beyond picking, formatting and taking the length of vectors the Evaluation holds.
Frames: robot frame for positions, sensor frame where a sentence says so; millimetres throughout.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from rrbc_core.session.evaluation import Evaluation

from .node_values import FiducialReadings


@dataclass(frozen=True)
class LessonContext:
    """What a step may quote besides the Evaluation."""

    kind: str  # "scene" or "measurements"
    magnification: float  # arrows and landing offsets are drawn this many times longer
    regions: dict = field(default_factory=dict)  # target id -> rrbc_core.io.scene.Region (scene mode)
    frame_magnification: float = 1.0  # the registered sensor frame's error is drawn this many times larger
    sensor_drawn: bool = False  # the sensor's body is drawn (a scene's sensor that is not the ground truth)
    compact: bool = False  # presentation mode: the shorter text, readable without scrolling on a 1280x720 projector


@dataclass(frozen=True)
class Step:
    title: str
    layers: tuple[str, ...]  # layers shown at this step (the others are hidden)
    text: Callable[[Evaluation, LessonContext], str]
    target_arrows: bool = True  # with the "corrections" layer: also the targets' arrows (step 6 shows fiducials' only)
    #: what the camera frames at this step: names of `camera.CellGeometry.points` ("registration", "fiducials",
    #: "targets", "robot", "sensor", "mesh") and "corrections" (arrow tips) or "landing" (the landing display)
    focus: tuple[str, ...] = ("targets", "fiducials")
    see_through: bool = False  # the work cell drawn see-through: arrows may point into surfaces
    direction: tuple[float, float, float] | None = None  # the camera's viewing direction (None: camera.OBLIQUE)
    #: the kinds of point ("registration", "fiducials", "targets") or "frames" whose labels the step shows: what its
    #: text names
    labels: tuple[str, ...] = ()
    #: the targets' regions drawn this many times larger at this step (None: as the View tab has them)
    region_zoom: float | None = None
    sight_lines: bool = False  # the sensor's lines of sight to the targets (the step where it measures them)
    #: the points (kind, id) its text names by id: their labels are kept first where labels would overlap
    named: Callable[[Evaluation], tuple[tuple[str, str], ...]] | None = None
    readings: bool = False  # the first included fiducial's two readings, drawn beside it (`fiducial_readings`)
    #: the sensor's frames' axes drawn this many times their length at this step (None: their own)
    frames_zoom: float | None = None


#: The regions' zoom at the step that names them.
REGION_ZOOM = 10.0
#: The sensor's frames' zoom at the step that names them.
FRAMES_ZOOM = 3.0


def _v(x) -> str:
    return "[" + ", ".join(f"{float(c):.3f}" for c in np.asarray(x).reshape(-1)) + "]"


def _ids(ids, limit: int = 8) -> str:
    ids = list(ids)
    return ", ".join(ids[:limit]) + (f" … ({len(ids)} in all)" if len(ids) > limit else "")


def _norms(a) -> np.ndarray:
    return np.linalg.norm(np.asarray(a, float).reshape(-1, 3), axis=1)


def _mm(x) -> str:
    return "—" if x is None or not np.isfinite(x) else f"{float(x):.3f} mm"


def _step1(ev: Evaluation, ctx: LessonContext) -> str:
    n = len(ev.registration_ids)
    return (
        f"The robot and the sensor both measure **{n} registration points** ({_ids(ev.registration_ids)}, purple). "
        "At least 3 are needed; they should be well spread over the work volume, because the registration is "
        "only as good as the volume they span."
    )


def _step2(ev: Evaluation, ctx: LessonContext) -> str:
    reg = ev.registration
    res = _norms(reg.residuals)
    worst = int(np.argmax(res)) if len(res) else 0
    t = np.asarray(reg.mapping.translation, float)
    if ctx.compact:
        worst_text = f" ({ev.registration_ids[worst]} worst, {res[worst]:.3f} mm)" if len(res) else ""
        s = (
            f"**{reg.method}** (R, t) takes sensor points to the robot frame, leaving **FRE {reg.fre_rms_mm:.3f} mm** "
            f"RMS{worst_text}; a low FRE says nothing about the targets."
        )
        if ctx.kind == "scene":
            s += f" Thin axes: the registered sensor frame, its error ×{ctx.frame_magnification:g}."
        return s
    s = (
        f"**{reg.method}** registration gives (R, t) taking sensor points to the robot frame; t = {_v(t)} mm. "
        f"The fit leaves **FRE {reg.fre_rms_mm:.3f} mm** RMS over {len(res)} points"
        + (f" (largest residual {res[worst]:.3f} mm at {ev.registration_ids[worst]})." if len(res) else ".")
        + " A low FRE is no evidence of accuracy at the targets."
    )
    if ctx.kind == "scene":
        s += (
            f" The registered sensor frame (thin axes, black origin) is drawn beside the true one with its error "
            f"magnified ×{ctx.frame_magnification:g}."
        )
    return s


def _split(ev: Evaluation, ids) -> tuple[list[str], list[str]]:
    """`ids` split into targets and a measurement file's checks (`Evaluation.check_ids`), in order."""
    ids = list(ids)
    return [p for p in ids if p not in ev.check_ids], [p for p in ids if p in ev.check_ids]


def _step3(ev: Evaluation, ctx: LessonContext) -> str:
    t = ev.targets
    targets, checks = _split(ev, t.ids)
    parts = []
    if targets or not checks:
        parts.append(
            f"**{len(targets)} targets** ({_ids(targets)}, dark blue): the places where the robot must act accurately"
        )
    if checks:  # the colour the scene gives them (nodes: a check keeps a check's colour)
        parts.append(
            f"**{len(checks)} checks** ({_ids(checks)}, dark green): points the robot also measured, so the "
            "correction can be scored there"
        )
    s = "; ".join(parts) + "."
    if np.any(t.extrapolated):
        colour = "magenta" if not checks else "olive" if not targets else "magenta (targets) or olive (checks)"
        s += f" Those outside the fiducials' hull are drawn {colour} (step 4)."
    if ctx.regions and len(t.ids):
        r = ctx.regions.get(t.ids[0])
        if r is not None:
            dims = "×".join(f"{float(x):g}" for x in r.size)
            what = "extents" if r.kind == "box" else "radii"
            s += (
                f" Each has a region of variability where the part may really be; {t.ids[0]}'s is a {r.kind} with "
                f"{what} {dims} mm (translucent, drawn ×{REGION_ZOOM:g} at this step: *Region zoom* in the View "
                "tab)."
            )
    return s


def _step4(ev: Evaluation, ctx: LessonContext) -> str:
    used = int(np.count_nonzero(ev.included))
    out = ev.summary.get("extrapolated", [])
    s = (
        f"**{used} of {len(ev.fiducial_ids)} fiducials** (orange) are measured around the targets; their convex "
        f"hull (yellow, {len(ev.hull_edges)} edges) must contain every target's region."
    )
    if out:
        verb, its = ("lies", "its correction") if len(out) == 1 else ("lie", "their corrections")
        targets, checks = _split(ev, out)
        colour = "magenta" if not checks else "olive" if not targets else "magenta targets, olive checks"
        s += f" **{_ids(out)} {verb} outside the hull**: {its} will be extrapolated ({colour})."
    else:
        s += " Every target is inside the hull." if not ev.check_ids else " Every target and check is inside the hull."
    return s


def mapped_fiducial(ev: Evaluation) -> int | None:
    """The fiducial step 5 follows (its text and its picture): the first included one; None without any."""
    inc = np.flatnonzero(ev.included)
    return int(inc[0]) if len(inc) else None


def fiducial_readings(ev: Evaluation, magnification: float) -> FiducialReadings | None:
    """Step 5's picture: `mapped_fiducial`'s drawn position, its sensor reading placed by the registration
    (R s + t) and its robot reading b (robot frame, mm), their offset drawn `magnification` times longer."""
    i = mapped_fiducial(ev)
    if i is None:
        return None
    sensor = ev.registration.mapping.apply(ev.fiducial_readings.sensor[i][None])[0]
    return FiducialReadings(
        ev.fiducial_ids[i], ev.fiducial_positions[i], sensor, ev.fiducial_readings.robot[i], magnification
    )


def _step5(ev: Evaluation, ctx: LessonContext) -> str:
    i = mapped_fiducial(ev)
    if i is None:
        return "Every fiducial is excluded: include one (click it) to see it mapped back."
    b = ev.fiducial_readings.robot[i]
    s = ev.fiducial_readings.sensor[i]
    e = ev.corrections[i]
    f = ev.fiducial_ids[i]
    if ctx.compact:
        return (
            f"The robot's reading b of **{f}**, taken back with (R, t)⁻¹, lands **{float(np.linalg.norm(e)):.3f} mm** "
            f"from the sensor's s: the rigid-body condition is broken there. Drawn above {f}: s placed by (R, t) "
            f"(black) and b (orange), their offset ×{ctx.magnification:g}."
        )
    return (
        f"The robot's fiducial readings are taken back into the sensor frame with (R, t)⁻¹. For "
        f"**{ev.fiducial_ids[i]}** the robot read b = {_v(b)} mm (robot frame); the sensor saw s = {_v(s)} mm "
        f"(sensor frame). Mapped back, b lands **{float(np.linalg.norm(e)):.3f} mm** from s: the rigid-body "
        f"condition is broken there. Drawn above {ev.fiducial_ids[i]}: s where (R, t) puts it (black) and b "
        f"(orange), their offset ×{ctx.magnification:g}."
    )


def _extreme_corrections(ev: Evaluation) -> tuple[int, int] | None:
    """(smallest, largest): the included fiducials with the smallest and the largest correction (None: none)."""
    inc = np.flatnonzero(ev.included)
    if not len(inc):
        return None
    n = _norms(ev.corrections[inc])
    return int(inc[int(np.argmin(n))]), int(inc[int(np.argmax(n))])


def _step6_named(ev: Evaluation) -> tuple[tuple[str, str], ...]:
    ends = _extreme_corrections(ev)
    return () if ends is None else tuple(("fiducials", ev.fiducial_ids[i]) for i in ends[::-1])


def _outside_hull(ev: Evaluation) -> tuple[tuple[str, str], ...]:
    """Step 4's named points: the targets and checks outside the fiducials' hull (its text lists them)."""
    return tuple(("targets", p) for p in ev.summary.get("extrapolated", []))


def _first_target(ev: Evaluation) -> tuple[tuple[str, str], ...]:
    return (("targets", ev.targets.ids[0]),) if len(ev.targets.ids) else ()


def _step6(ev: Evaluation, ctx: LessonContext) -> str:
    ends = _extreme_corrections(ev)
    if ends is None:
        return "Every fiducial is excluded: there are no corrections."
    lo, hi = ends
    n = _norms(ev.corrections[np.flatnonzero(ev.included)])
    return (
        f"The corrections e_i = Rᵀ(b_i − t) − s_i (orange arrows, ×{ctx.magnification:g}) range from "
        f"**{n.min():.3f} mm** ({ev.fiducial_ids[lo]}) to **{n.max():.3f} mm** ({ev.fiducial_ids[hi]}). "
        f"{ev.fiducial_ids[hi]}: e = {_v(ev.corrections[hi])} mm, sensor frame."
    )


def _step7(ev: Evaluation, ctx: LessonContext) -> str:
    t = ev.targets
    if not len(t.ids):
        return "There are no targets."
    what = _kinds_word(ev, t.ids)
    sensor = (
        "The sensor (its lines of sight to them drawn) measures"
        if ctx.sensor_drawn
        else "The sensor measured"  # no sensor body to draw: a measurement file, or a scene's ground truth
    )
    return (
        f"{sensor} the {len(t.ids)} {what}; **{t.ids[0]}** reads x = {_v(t.sensor[0])} mm (sensor frame). "
        "Drag a target's handle to move it: everything below follows live."
    )


def _kinds_word(ev: Evaluation, ids) -> str:
    """ "targets", "checks" or "targets and checks": what `ids` are (`_split`)."""
    targets, checks = _split(ev, ids)
    return "targets and checks" if targets and checks else "checks" if checks else "targets"


def _step8(ev: Evaluation, ctx: LessonContext) -> str:
    t = ev.targets
    if not len(t.ids):
        return "There are no targets."
    n = _norms(t.correction)
    s = (
        f"Each target's correction ê(x) is interpolated (**{ev.settings.interpolation}**) from the nearby fiducial "
        f"corrections (blue arrows, ×{ctx.magnification:g}): {t.ids[0]} gets ê = {_v(t.correction[0])} "
        f"(|ê| = {n[0]:.3f} mm); over all {_kinds_word(ev, t.ids)} |ê| is {n.min():.3f}–{n.max():.3f} mm."
    )
    if t.correction_std is not None:
        s += f" The Gaussian process puts ±{float(np.linalg.norm(t.correction_std[0])):.3f} mm (1σ) on {t.ids[0]}'s."
    return s


def _step9(ev: Evaluation, ctx: LessonContext) -> str:
    sm = ev.summary
    if sm.get("rmst_rigid_mm") is None:
        return (
            "b̂ = R(x + ê(x)) + t sends the robot to the corrected targets (teal) instead of the rigid-only "
            "ones (vermillion). These data carry no truth for the targets, so the gain cannot be scored here; "
            "add check rows to score it."
        )
    scored = f"{sm['scored']} scored {'checks' if ev.check_ids else 'targets'}"
    if ctx.compact:
        return (
            "b̂ = R(x + ê(x)) + t. The bullseye beside the selected point: where the robot lands rigid-only "
            f"(vermillion) and with RRBC (teal) around the truth. RMS over {scored}: "
            f"**{_mm(sm['rmst_rigid_mm'])} → {_mm(sm['rmst_rrbc_mm'])}**."
        )
    return (
        f"b̂ = R(x + ê(x)) + t: where the robot lands rigid-only (vermillion) versus with RRBC (teal), offsets "
        f"from the truth (the dark centre) on the bullseye beside the selected point, ring scale written beside it "
        f"(select another point to move it; the panel's bullseye shows the same at true size). Over "
        f"{scored} the RMS error is "
        f"**{_mm(sm['rmst_rigid_mm'])} rigid → {_mm(sm['rmst_rrbc_mm'])} with RRBC** "
        f"(max {_mm(sm['max_rigid_mm'])} → {_mm(sm['max_rrbc_mm'])})."
    )


STEPS: tuple[Step, ...] = (
    Step(
        "Measure registration points",
        ("mesh", "arm", "sensor", "registration", "labels"),
        _step1,
        focus=("registration", "robot", "sensor"),  # its text: the robot and the sensor both measure them
        see_through=True,  # seen with the sensor, some points lie behind its mast
        labels=("registration",),  # its text names R1-R6
    ),
    Step(
        "Register the sensor to the robot",
        ("mesh", "frames", "registration"),
        _step2,
        focus=("sensor", "registration"),  # the two sensor frames and the points the fit rests on
        direction=(0.7, -0.55, 0.15),  # from the work's side, level with the head: its mast is behind it
        see_through=True,  # the frames' origins lie inside the sensor's casing
        frames_zoom=FRAMES_ZOOM,  # high above the work, at their size in the cell they are a few pixels long
        labels=("frames", "registration"),  # its text names the two sensor frames and the points
    ),
    Step(
        "Identify the targets",
        ("mesh", "targets", "regions"),
        _step3,
        focus=("targets",),
        labels=("targets",),
        region_zoom=REGION_ZOOM,  # a few-millimetre region is hidden inside its target's marker at true size
    ),
    Step(
        "Choose fiducials around the targets",
        ("mesh", "targets", "fiducials", "hull", "regions"),
        _step4,
        labels=("targets",),  # its text names the points outside the hull
        named=_outside_hull,
    ),
    Step(
        "Map the robot's fiducials back",
        ("mesh", "frames", "fiducials"),
        _step5,
        focus=("fiducials", "sensor"),
        see_through=True,  # from the sensor's side some fiducials lie behind parts of the cell
        readings=True,  # the two readings its text names, labelled beside the fiducial (no other labels to clash)
    ),
    Step(
        "Corrections at the fiducials",
        ("mesh", "fiducials", "corrections"),
        _step6,
        target_arrows=False,
        focus=("fiducials", "corrections"),
        see_through=True,
        labels=("fiducials",),  # its text names the largest and the smallest correction's fiducials
        named=_step6_named,
    ),
    Step(
        "Measure the targets",
        ("mesh", "sensor", "targets", "fiducials"),
        _step7,
        focus=("targets", "sensor"),  # the sensor that measures them, in view
        labels=("targets",),
        named=_first_target,
        sight_lines=True,
        see_through=True,  # the sensor's mast stands between the camera and the lines
    ),
    Step(
        "Interpolate corrections to the targets",
        ("mesh", "fiducials", "targets", "corrections"),
        _step8,
        focus=("targets", "fiducials", "corrections"),
        see_through=True,
        labels=("targets",),  # its text names the first target's correction
        named=_first_target,
    ),
    Step("Correct and map to the robot", ("mesh", "arm", "targets", "landing"), _step9, focus=("targets", "landing")),
)


def render(index: int, ev: Evaluation, ctx: LessonContext) -> str:
    """Markdown for step `index` (0-based)."""
    step = STEPS[index]
    return f"**Step {index + 1} of {len(STEPS)}: {step.title}**\n\n{step.text(ev, ctx)}"
