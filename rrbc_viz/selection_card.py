"""The selected point's info card (markdown) and its landing bullseye (an SVG drawn in the panel, never hidden by
scene geometry).

Formatting only: every number comes from an `Evaluation`. The bullseye is a top view in the robot frame (x to the
right, y up, mm, unmagnified): the truth at the centre, the rigid and RRBC landings as dots at their x-y offsets,
scale rings at 1-2-5 radii; the z offsets are drawn on a vertical bar at the right with the same scale. Without
truth (measured targets) the rigid landing is the centre and only the RRBC shift is drawn.
"""

from __future__ import annotations

import numpy as np

from rrbc_core.session.evaluation import Evaluation

from . import colors
from .node_values import landing_offsets, nice_up

SIZE_PX = 220  # the bullseye's drawing, square
BAR_PX = 34  # the z bar at its right


def _v(x) -> str:
    return "[" + ", ".join(f"{float(c):.3f}" for c in np.asarray(x).reshape(-1)) + "]"


def _mm(x) -> str:
    return "—" if x is None or not np.isfinite(x) else f"{float(x):.3f} mm"


#: How the point list ("Selected point" dropdown) is ordered: its name -> what it sorts by.
SORTS = ("file order", "error rigid", "error RRBC", "fiducial residual")
_SEP = " · "


def _word(ev: Evaluation, kind: str, pid: str) -> str:
    if kind == "fiducials":
        return "fiducial"
    return "check" if pid in ev.check_ids else "target"


def point_names(ev: Evaluation, sort: str = "file order") -> tuple[str, ...]:
    """Choices of the "Selected point" dropdown, a point list ('none' first): targets (a file's check rows called
    checks) with their error rigid → RRBC, fiducials with their residual (the |correction| RRBC reads there), in
    file order or sorted by `sort` (`SORTS`, largest first): 'check C3 · 3.412 → 0.871 mm', 'fiducial F1 · 0.512 mm'."""
    t = ev.targets
    rows = []
    for i, pid in enumerate(t.ids):
        rig, rr = float(t.error_rigid[i]), float(t.error_rrbc[i])
        text = (
            f" {rig:.3f} → {rr:.3f} mm" if np.isfinite(rig) else f" ê {float(np.linalg.norm(t.correction[i])):.3f} mm"
        )
        rows.append((f"{_word(ev, 'targets', pid)} {pid}{_SEP}{text.strip()}", rig, rr, -np.inf, i))
    res = np.linalg.norm(np.nan_to_num(ev.corrections), axis=1) if len(ev.fiducial_ids) else np.zeros(0)
    for i, pid in enumerate(ev.fiducial_ids):
        rows.append((f"fiducial {pid}{_SEP}{res[i]:.3f} mm", -np.inf, -np.inf, float(res[i]), len(t.ids) + i))
    key = {"error rigid": 1, "error RRBC": 2, "fiducial residual": 3}.get(sort)
    if key is not None:
        rows.sort(key=lambda r: (-np.nan_to_num(r[key], nan=-np.inf), r[4]))
    return ("none",) + tuple(r[0] for r in rows)


def parse_choice(choice: str) -> tuple[str, str] | None:
    """(kind, id) of a dropdown choice, None for 'none'."""
    choice = choice.split(_SEP)[0]
    if choice == "none" or " " not in choice:
        return None
    word, pid = choice.split(" ", 1)
    return ({"target": "targets", "check": "targets", "fiducial": "fiducials"}[word], pid)


def choice_of(selected: tuple[str, str] | None, choices: tuple[str, ...] = ()) -> str:
    """The dropdown choice of a selection: the entry of `choices` that names it (with its numbers), else its name."""
    if selected is None:
        return "none"
    for c in choices:
        if parse_choice(c) == tuple(selected):
            return c
    kind, pid = selected
    return f"{'target' if kind == 'targets' else 'fiducial'} {pid}"


def _hull_line(ev: Evaluation, i: int, region_fraction: float | None) -> str:
    """The target's coverage in the core's words (`interpolation.hull.Coverage.describe`): inside or outside the
    fiducials' hull, its distance from their plane when that puts it outside, its region's fraction inside."""
    if ev.coverage is None:
        return "- no fiducials included: nothing is covered"
    words = ev.coverage.describe(i, region_fraction)
    return f"- ⚠ {words}: extrapolated" if not ev.coverage.inside[i] else f"- {words}"


BAR_CELLS = 10  # a budget bar's full width, in characters


def budget_lines(ev: Evaluation, i: int) -> list[str]:
    """Target i's 95 % bound (RRBC's, rigid's beside it) and its budget as bars, each source's RMS contribution
    against the largest (`Evaluation.bounds`, as `rrbc correct` gives them); or why there is none."""
    b = ev.bounds
    if b is None:
        return []
    bound = float(b.rrbc.bound95_mm[i])
    rigid = float(b.rigid.bound95_mm[i])
    rigid_words = f"; rigid {rigid:.3f} mm" if np.isfinite(rigid) else ""
    if not np.isfinite(bound):
        why = next((w for w in b.source.warnings if w.startswith("no ")), "the data cannot back one here")
        return [f"- 95 % bound: none{rigid_words.replace(';', ' (')}{')' if rigid_words else ''} — {why}"]
    parts = {k: float(v[i]) for k, v in b.rrbc.budget_mm.items()}
    top = max(max(parts.values()), 1e-12)
    # a table: each source's name, bar and figure in one row however narrow the panel (as lines, a name wrapped
    # onto the line of the bar before it)
    inst = b.source.instrument.source or b.source.instrument.name
    lines = [
        f"- 95 % bound **{bound:.3f} mm** (RRBC{rigid_words}); its budget (instrument: {inst}):",
        "",
        "| source | | RMS mm |",
        "|---|---|---|",
    ]
    for k, v in parts.items():
        n = int(round(BAR_CELLS * v / top))
        lines.append(f"| {k} | `{'█' * n}{'░' * (BAR_CELLS - n)}` | {v:.3f} |")
    return lines


def info_card(ev: Evaluation, selected: tuple[str, str] | None, region_fraction: float | None = None) -> str:
    """Markdown: the selected point's numbers (or how to select one)."""
    if selected is None:
        return "*Click a target or fiducial in the scene (or pick one above) to select it: it gets the drag handle.*"
    kind, pid = selected
    if kind == "targets":
        t = ev.targets
        i = t.ids.index(pid)
        lines = [
            f"**{_word(ev, kind, pid).capitalize()} {pid}** at {_v(t.positions[i])} mm (robot frame)",
            f"- sensor reading x = {_v(t.sensor[i])} mm (sensor frame)",
            f"- correction ê = {_v(t.correction[i])} mm (sensor frame), |ê| = {float(np.linalg.norm(t.correction[i])):.3f} mm"
            + (f" ± {float(np.linalg.norm(t.correction_std[i])):.3f} (1σ)" if t.correction_std is not None else ""),
            f"- error rigid **{_mm(t.error_rigid[i])}** → RRBC **{_mm(t.error_rrbc[i])}**",
            _hull_line(ev, i, region_fraction),
            *budget_lines(ev, i),
        ]
        return "\n".join(lines)
    i = ev.fiducial_ids.index(pid)
    r = ev.fiducial_readings
    lines = [
        f"**Fiducial {pid}** at {_v(ev.fiducial_positions[i])} mm (robot frame)",
        f"- robot read b = {_v(r.robot[i])} mm; sensor saw s = {_v(r.sensor[i])} mm",
    ]
    if bool(ev.included[i]):
        e = ev.corrections[i]
        lines.append(f"- correction e = {_v(e)} mm (sensor frame), |e| = {float(np.linalg.norm(e)):.3f} mm")
    else:
        lines.append("- **excluded** from the interpolation")
    return "\n".join(lines)


def bullseye_svg(ev: Evaluation, pid: str, vec=None) -> tuple[str, str, str]:
    """The landing bullseye of target `pid` (module docstring), with VEC's landing `vec` (3,) robot frame mm when
    given (Arm tab on): (inline SVG, markdown caption, HTML key)."""
    t = ev.targets
    i = t.ids.index(pid)
    rigid, rrbc, known = landing_offsets(t, i)
    off_vec = None if vec is None or not known else np.asarray(vec, float) - t.truth[i]
    biggest = max(float(np.linalg.norm(rigid)), float(np.linalg.norm(rrbc)), 1e-6)
    if off_vec is not None:
        biggest = max(biggest, float(np.linalg.norm(off_vec)))
    ring = nice_up(biggest)
    c = SIZE_PX / 2
    px = 0.42 * SIZE_PX / ring  # px per mm: the outer ring fills ~84 % of the square

    def xy(off) -> tuple[float, float]:
        return c + px * float(off[0]), c - px * float(off[1])

    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{SIZE_PX + BAR_PX}" height="{SIZE_PX}" '
        f'viewBox="0 0 {SIZE_PX + BAR_PX} {SIZE_PX}" data-ring-mm="{ring:g}" data-px-per-mm="{px:.6g}">',
        f'<rect x="0" y="0" width="{SIZE_PX}" height="{SIZE_PX}" fill="#fbfbfb" stroke="#ccc"/>',
    ]
    for k, frac in enumerate((1.0, 0.5)):
        parts.append(
            f'<circle cx="{c}" cy="{c}" r="{px * ring * frac:.2f}" fill="none" stroke="#999" '
            f'stroke-dasharray="{"" if k == 0 else "3 3"}"/>'
        )
    parts.append(f'<line x1="{c}" y1="4" x2="{c}" y2="{SIZE_PX - 4}" stroke="#ddd"/>')
    parts.append(f'<line x1="4" y1="{c}" x2="{SIZE_PX - 4}" y2="{c}" stroke="#ddd"/>')
    parts.append(
        f'<text x="{c + px * ring * 0.71 + 3:.1f}" y="{c - px * ring * 0.71 - 3:.1f}" font-size="11" fill="#555">'
        f"{ring:g} mm</text>"
    )
    parts.append(f'<text x="{SIZE_PX - 16}" y="{c - 4}" font-size="10" fill="#777">x</text>')
    parts.append(f'<text x="{c + 4}" y="12" font-size="10" fill="#777">y</text>')
    dots = [("rigid", rigid, colors.LAND_RIGID)] if known else []
    dots.append(("rrbc", rrbc, colors.LAND_RRBC))
    if off_vec is not None:
        dots.append(("vec", off_vec, colors.LAND_VEC))
    parts.append(f'<circle cx="{c}" cy="{c}" r="4" fill="{colors.hex_color(colors.LAND_ANCHOR)}" data-kind="truth"/>')
    for name, off, col in dots:
        x, y = xy(off)
        parts.append(f'<line x1="{c}" y1="{c}" x2="{x:.2f}" y2="{y:.2f}" stroke="{colors.hex_color(col)}"/>')
        parts.append(
            f'<circle cx="{x:.2f}" cy="{y:.2f}" r="6" fill="{colors.hex_color(col)}" stroke="#fff" '
            f'data-kind="{name}" data-dx-mm="{float(off[0]):.6g}" data-dy-mm="{float(off[1]):.6g}"/>'
        )
    # z bar: the same scale, vertical
    bx = SIZE_PX + BAR_PX / 2
    parts.append(f'<line x1="{bx}" y1="{c - px * ring}" x2="{bx}" y2="{c + px * ring}" stroke="#999"/>')
    parts.append(f'<line x1="{bx - 6}" y1="{c}" x2="{bx + 6}" y2="{c}" stroke="#333"/>')
    parts.append(f'<text x="{bx - 4}" y="{c - px * ring - 4:.1f}" font-size="10" fill="#777">z</text>')
    for name, off, col in dots:
        z = c - px * float(off[2])
        parts.append(
            f'<rect x="{bx - 5}" y="{z - 2:.2f}" width="10" height="4" fill="{colors.hex_color(col)}" '
            f'data-kind="{name}-z" data-dz-mm="{float(off[2]):.6g}"/>'
        )
    parts.append("</svg>")
    if known:
        caption = (
            f"**{pid}**: where the robot lands, seen from above (offsets from the truth, true size, mm): rigid "
            f"{float(np.linalg.norm(rigid)):.3f} mm, RRBC {float(np.linalg.norm(rrbc)):.3f} mm"
            + (f", VEC {float(np.linalg.norm(off_vec)):.3f} mm" if off_vec is not None else "")
            + ". The bar at the right: z."
        )
    else:
        caption = (
            f"**{pid}**: no truth here; the dot is RRBC's shift from the rigid landing "
            f"({float(np.linalg.norm(rrbc)):.3f} mm)."
        )
    legend = (
        f'<span style="color:{colors.hex_color(colors.LAND_RIGID)}">● rigid</span> &nbsp; '
        f'<span style="color:{colors.hex_color(colors.LAND_RRBC)}">● RRBC</span> &nbsp; '
        + (
            f'<span style="color:{colors.hex_color(colors.LAND_VEC)}">● VEC</span> &nbsp; '
            if off_vec is not None
            else ""
        )
        + "● truth"
    )
    return "".join(parts), caption, legend
