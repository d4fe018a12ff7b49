"""Markdown shown in the control panel: the drawing scale, the summary and the per-target table.

Formatting only: every number comes from an `Evaluation` (lengths of its vectors are taken for display).
"""

from __future__ import annotations

import numpy as np

from rrbc_core.session.evaluation import Evaluation


def _mm(x) -> str:
    return "—" if x is None or not np.isfinite(x) else f"{float(x):.3f}"


def scale_line(magnification: float) -> str:
    """The drawing scale of correction arrows and landing offsets, said on screen."""
    m = f"{magnification:g}"
    return f"Arrows and landing offsets **×{m}**: 1 mm is drawn as {m} mm."


def changes_line(changed) -> str:
    """The targets whose correction the last fiducial drag changed most ((id, mm), largest first), said under the
    scale line; "" without."""
    if not changed:
        return ""
    said = ", ".join(f"**{pid}** {mm:.3f} mm" for pid, mm in changed)
    return f"\n\nThe last fiducial drag changed these targets' corrections most (drawn larger and labelled with the change): {said}."


def summary(ev: Evaluation, kind: str) -> str:
    sm = ev.summary
    s = ev.settings
    interp = s.interpolation + (
        f" (k={s.neighbors}, p={s.power:g})"
        if s.interpolation == "idw"
        else f" (smoothing {s.smoothing:g})"
        if s.interpolation == "tps"
        else ""
    )
    lines = [
        f"Registration **{ev.registration.method}**: FRE {ev.registration.fre_rms_mm:.3f} mm RMS "
        f"({len(ev.registration_ids)} points). Interpolation **{interp}** over "
        f"{sm['fiducials_used']} of {len(ev.fiducial_ids)} fiducials.",
    ]
    if sm.get("rmst_rigid_mm") is not None:
        lines.append(
            f"Target error over {sm['scored']} scored: RMS **{_mm(sm['rmst_rigid_mm'])} mm rigid → "
            f"{_mm(sm['rmst_rrbc_mm'])} mm RRBC**; max {_mm(sm['max_rigid_mm'])} → {_mm(sm['max_rrbc_mm'])} mm."
        )
    elif kind == "measurements":
        lines.append("No target carries a truth: errors cannot be scored (check rows would be).")
    if ev.choice is not None:
        lines.append(f"Interpolation: {ev.choice.describe()}.")
    if sm.get("extrapolated"):
        lines.append(f"⚠ **Extrapolated** (outside the fiducials' hull): {', '.join(sm['extrapolated'])}.")
    lines += [f"⚠ {w}." for w in ev.warnings]
    return "\n\n".join(lines)


def headline(ev: Evaluation, kind: str) -> str:
    """The readout at the top of the panel, above the tabs: rigid → RRBC, the RMS error over what is scored (the scene's
    targets against their truth, a measurement file's check rows), from the same summary as `summary`; "" when
    nothing is scored. RRBC's figure is green only for a gain the scored points show, red for a loss they show and
    grey otherwise (`correction.check_statistics.gain_test`, the decision of rrbc diagnose's recommendation). HTML
    (large type)."""
    sm = ev.summary
    rig, rr = sm.get("rmst_rigid_mm"), sm.get("rmst_rrbc_mm")
    if rig is None or rr is None or not np.isfinite(rig) or not np.isfinite(rr):
        return ""
    what = "targets" if kind == "scene" else "check rows"
    change = f"{100.0 * (rr / rig - 1.0):+.0f} %" if rig > 0 else ""
    # green for a gain the scored points show, red for a loss they show, grey when they cannot tell (gain_test)
    colour = {"gain": "#1a7f37", "loss": "#b42318"}.get(sm.get("gain") or "", "#555555")
    return (
        '<div style="padding:0 0.75rem"><div class="rrbc-headline-main" '
        'style="font-size:1.25em;line-height:1.3;margin:2px 0 0 0">'
        f'rigid <b>{_mm(rig)}</b> → RRBC <b style="color:{colour}">{_mm(rr)}</b> mm '
        f'<span style="font-size:0.8em;color:{colour}">{change}</span></div>'
        f'<div class="rrbc-headline-note" style="font-size:0.875rem;color:#555">RMS error over {sm["scored"]} {what}'
        "</div></div>"
    )


def stations_line(session) -> str:
    """With stations: which one is open and `rrbc correct`'s pooled figures over all of them (the session's
    `stations_summary`), as a paragraph to append to the summary; "" without stations."""
    if not session.stations:
        return ""
    n = len(session.stations)
    text = f"\n\nStation **{session.station}** of {n} (File → Station)."
    s = session.stations_summary()
    if s is not None and s.get("rmst_rigid_mm") is not None:
        text += (
            f" All {n} stations, each registered and corrected on its own (as `rrbc correct`): check RMS "
            f"**{_mm(s['rmst_rigid_mm'])} mm rigid → {_mm(s['rmst_rrbc_mm'])} mm RRBC** over {s['checks']} checks."
        )
    return text


def target_table(ev: Evaluation) -> str:
    """Per target (and check: the column says which the rows are): error rigid, error RRBC (mm, — without truth),
    |correction|, gp std, extrapolation flag."""
    t = ev.targets
    has_std = t.correction_std is not None
    n_chk = sum(pid in ev.check_ids for pid in t.ids)
    name = "target" if n_chk == 0 else "check" if n_chk == len(t.ids) else "target / check"
    head = f"| {name} | rigid | RRBC | \\|ê\\| | " + ("std | " if has_std else "") + "hull |"
    sep = "|---|---:|---:|---:|" + ("---:|" if has_std else "") + ":---:|"  # centred: never runs into the number
    rows = [head, sep]
    corr = np.linalg.norm(t.correction.reshape(-1, 3), axis=1)
    std = np.linalg.norm(t.correction_std.reshape(-1, 3), axis=1) if t.correction_std is not None else None
    for i, pid in enumerate(t.ids):
        flag = "⚠ extrapolated" if bool(t.extrapolated[i]) else "inside"
        row = f"| {pid} | {_mm(t.error_rigid[i])} | {_mm(t.error_rrbc[i])} | {corr[i]:.3f} | "
        if has_std:
            row += f"{std[i]:.3f} | " if std is not None else ""
        rows.append(row + f"{flag} |")
    return "\n".join(rows) + (
        "\n\nmm. *rigid*, *RRBC*: target error against the truth (— where there is none); |ê|: interpolated "
        "correction" + ("; *std*: its 1σ from the Gaussian process." if has_std else ".")
    )
