"""The text outputs of `rrbc correct`, `rrbc simulate` and `rrbc plan` (the `--json` outputs are the results'
`to_json()`). Formatting only: every number comes from the result objects. Lengths in mm."""

from __future__ import annotations

import numpy as np


def fmt_vec(v, width=9, prec=4):
    return " ".join(f"{x:{width}.{prec}f}" for x in v)


def correct_text(result) -> str:
    reg = result.registration
    lines = []
    m = reg.mapping.as_dict()
    lines.append(f"registration: {reg.method}   FRE {reg.fre_rms_mm:.4f} mm (RMS over {len(reg.residuals)} points)")
    if m.get("piecewise"):
        lines.append(f"  piecewise: {len(m['pieces'])} clusters, each point uses its nearest kernel")
        for k, pc in enumerate(m["pieces"]):
            lines.append(
                f"  kernel {k}: [{fmt_vec(pc['kernel'], 9, 2)}]  translation [{fmt_vec(pc['translation'], 10, 4)}]"
            )
    else:
        for k in range(3):
            label = "  rotation    " if k == 0 else "              "
            lines.append(f"{label}[{fmt_vec(m['rotation'][k], 10, 7)}]")
        lines.append(f"  translation [{fmt_vec(m['translation'], 10, 4)}] mm")
    if result.choice is not None:
        lines.append(f"interpolation: {result.choice.describe()}")
    else:
        interp = result.interpolation_json()
        opts = ", ".join(f"{k}={v}" for k, v in interp.items() if k != "method")
        lines.append(f"interpolation: {interp['method']}" + (f" ({opts})" if opts else ""))
    lines.append("")
    lines.append(f"fiducials ({len(result.fiducials.ids)}): correction e = R^T(b - t) - s, sensor frame, mm")
    lines.append(f"  {'id':<12} {'e_x':>9} {'e_y':>9} {'e_z':>9} {'|e|':>9}")
    for pid, e in zip(result.fiducials.ids, result.fiducial_corrections):
        lines.append(f"  {pid:<12} {fmt_vec(e)} {np.linalg.norm(e):9.4f}")
    bounds = result.bounds
    for title, group, cp, checks, cov, pb in (
        ("targets", result.targets, result.targets_corrected, False, result.targets_coverage, bounds.targets),
        ("checks", result.checks, result.checks_corrected, True, result.checks_coverage, bounds.checks),
    ):
        if cp is None:
            continue
        lines.append("")
        head = f"  {'id':<12} {'corr_x':>9} {'corr_y':>9} {'corr_z':>9}   {'robot_rrbc_x':>12} {'robot_rrbc_y':>12} {'robot_rrbc_z':>12}"
        head += f" {'bound95':>8}"
        if checks:
            head += f" {'err_rigid':>9} {'err_rrbc':>9}"
        lines.append(f"{title} ({len(group.ids)}): correction (sensor frame) and corrected robot position, mm")
        lines.append(head)
        for k, pid in enumerate(group.ids):
            row = f"  {pid:<12} {fmt_vec(cp.correction[k])}   {fmt_vec(cp.robot_rrbc[k], 12, 4)}"
            b = float(pb.bound95_mm[k]) if pb is not None else float("nan")
            row += f" {b:8.4f}" if np.isfinite(b) else f" {'-':>8}"
            if checks:
                row += f" {result.error_rigid[k]:9.4f} {result.error_rrbc[k]:9.4f}"
            if checks and result.error_rrbc[k] > result.error_rigid[k]:
                row += "  RRBC worse"
            if cp.extrapolated[k]:
                row += "  extrapolated" + (f": {cov.describe(k)}" if cov is not None else "")
            lines.append(row)
    lines += bound_lines(result)
    s = result.summary()
    lines.append("")
    if s["rmst_rigid_mm"] is None:
        lines.append("summary: no check points, so no error can be scored")
    else:
        change = (s["rmst_rrbc_mm"] - s["rmst_rigid_mm"]) / s["rmst_rigid_mm"] * 100 if s["rmst_rigid_mm"] > 0 else 0.0
        lines.append(
            f"summary over {len(result.checks.ids)} check points: RMST rigid {s['rmst_rigid_mm']:.4f} mm, "
            f"RRBC {s['rmst_rrbc_mm']:.4f} mm ({change:+.1f} %); max rigid {s['max_rigid_mm']:.4f} mm, "
            f"RRBC {s['max_rrbc_mm']:.4f} mm"
        )
        lines += result.statistics().lines()
    lines += warning_lines(result.warnings())
    return "\n".join(lines) + "\n"


def bound_lines(result) -> list[str]:
    """What the bound column is and rests on (`CorrectionResult.bounds`), and the budget's RMS over the points."""
    b = result.bounds
    inst = b.instrument
    lines = [
        "",
        "bound95: 95 % bound on the 3-D error of the corrected position (mm; '-': none, see the warnings)",
        f"  instrument: {inst.name}, {inst.source}; robot: "
        + ("-" if inst.robot_mm is None else f"{inst.robot_mm:.4g} mm")
        + f" ({inst.robot_source})",
    ]
    if b.profile is not None:
        p = b.profile
        lines.append(
            f"  interpolation: {p.folds}-fold cross-validation over {p.n} fiducials, RMS {p.rms_mm:.4f} mm"
            + (f", tail factor {p.tail:.2f}" if p.tail > 1 else "")
        )
    for title, pb in (("targets", b.targets), ("checks", b.checks)):
        if pb is None or not np.any(np.isfinite(pb.bound95_mm)):
            continue
        ok = np.isfinite(pb.bound95_mm)
        parts = ", ".join(f"{k} {np.sqrt(np.mean(v[ok] ** 2)):.4f}" for k, v in pb.budget_mm.items())
        lines.append(f"  budget over the {title} (RMS, mm): {parts}")
    return lines


def stations_text(result) -> str:
    """The text of `rrbc correct` on a file with groups: each station's text under a header, then the pooled
    summary, statistics and warnings."""
    lines: list[str] = []
    for g, r in zip(result.groups, result.stations):
        lines.append(f"=== group {g!r} ===")
        lines += correct_text(r).rstrip("\n").split("\n")
        lines.append("")
    s = result.summary()
    lines.append(f"=== all {s['stations']} groups, each registered and corrected on its own ===")
    fre = s.get("fre_rms_mm_per_station")
    if fre:
        lines.append(f"FRE per station: {fre['min']:.4f}-{fre['max']:.4f} mm (median {fre['median']:.4f} mm)")
    if s["rmst_rigid_mm"] is None:
        lines.append("summary: no check points, so no error can be scored")
    else:
        change = (s["rmst_rrbc_mm"] / s["rmst_rigid_mm"] - 1) * 100 if s["rmst_rigid_mm"] > 0 else 0.0
        lines.append(
            f"summary over {s['checks']} check points: RMST rigid {s['rmst_rigid_mm']:.4f} mm, "
            f"RRBC {s['rmst_rrbc_mm']:.4f} mm ({change:+.1f} %); max rigid {s['max_rigid_mm']:.4f} mm, "
            f"RRBC {s['max_rrbc_mm']:.4f} mm"
        )
        lines += result.statistics().lines()
    lines += warning_lines(result.warnings())
    return "\n".join(lines) + "\n"


def warning_lines(warnings) -> list[str]:
    """The text form of a `warnings` list: a blank line and one "warning: ..." line each (none when empty)."""
    return ([""] if warnings else []) + [f"warning: {w}" for w in warnings]


def simulate_text(res) -> str:
    lines = [
        f"scene: {res.scene}   trials: {res.trials}   seed: {res.seed}   {res.seconds:.1f} s",
        f"points: {res.n_registration} registration, {res.n_fiducials} fiducials, {res.n_checks} check points"
        + (f"; hidden from the sensor: {', '.join(res.occluded)}" if res.occluded else ""),
        "",
        "rigid registration (TRE at check points, mm) and RRBC with IDW (k=4, p=2):",
        f"  {'strategy':<15} {'mean':>8} {'rms':>8} {'max':>8} {'r(dist)':>8}   {'rmst_rrbc':>9} {'max_rrbc':>9}",
    ]
    for st in res.strategies:
        lines.append(
            f"  {st.name:<15} {st.tre_mean_mm:8.4f} {st.tre_rms_mm:8.4f} {st.tre_max_mm:8.4f} {st.r_distance:8.3f}"
            f"   {st.rmst_rrbc_mm:9.4f} {st.max_rrbc_mm:9.4f}"
        )
    if res.interpolations:
        lines += [
            "",
            "least-squares registration + RRBC by interpolation method (mm):",
            f"  {'method':<8} {'rmst':>8} {'mean':>8} {'max':>8}",
        ]
        for it in res.interpolations:
            lines.append(f"  {it.name:<8} {it.rmst_mm:8.4f} {it.mean_mm:8.4f} {it.max_mm:8.4f}")
    return "\n".join(lines) + "\n"


def plan_text(res) -> str:
    from rrbc_core.interpolation.hull import OFF_PLANE_TOL_MM

    p0, p1 = res.predicted, res.predicted_after
    lines = [
        f"scene: {res.scene}   coverage of the target regions by the fiducials' hull: "
        f"{100 * res.overall_coverage():.1f} % (volume-weighted)"
    ]
    lines.append(
        f"  {'target':<12} {'hull':<8} {'coverage':>9}"
        + (f" {'after':>9} {'hull after':<10}" if res.suggested_ids else "")
    )
    word = lambda inside: "inside" if inside else "OUTSIDE"
    for k, tid in enumerate(res.target_ids):
        row = f"  {tid:<12} {word(res.inside[k]):<8} {100 * res.coverage[k]:8.1f}%"
        if res.suggested_ids:
            row += f" {100 * res.coverage_after[k]:8.1f}% {word(res.inside_after[k]):<10}"
        if not res.inside[k] and res.off_plane_mm[k] > OFF_PLANE_TOL_MM:
            row += f"  ({res.off_plane_mm[k]:.1f} mm off the fiducials' plane)"
        lines.append(row.rstrip())
    lines.append(
        "  hull: the target's own position inside the fiducials' hull (what RRBC's extrapolation flag tests); "
        "coverage: the fraction of its region of variability inside"
    )
    for tid, why in res.uncovered.items():
        lines.append(f"  not covered{' after the suggestions' if res.suggested_ids else ''}: {tid}: {why['reason']}")
    lines += [
        "",
        f"predicted RMST over the regions ({p0.method}), mm:",
        f"  {'fiducials':<28} {'rigid':>8} {'RRBC':>8} {'+-':>7}",
        f"  {'current':<28} {p0.rigid_mm:8.4f} {p0.rrbc_mm:8.4f} {p0.rrbc_std_mm:7.4f}",
    ]
    if res.requested:
        k = res.requested
        if res.suggested_ids:
            n = len(res.suggested_ids)
            lines.append(f"  {f'+ {n} suggested':<28} {p1.rigid_mm:8.4f} {p1.rrbc_mm:8.4f} {p1.rrbc_std_mm:7.4f}")
        for name, b in res.baselines.items():
            lines.append(
                f"  {f'+ {k} by rule {name}':<28} {b.rigid_mm:8.4f} {b.rrbc_mm:8.4f} {b.rrbc_std_mm:7.4f}"
                + ("  (mean, sd over draws)" if name == "random" else "")
            )
        lines += ["", f"suggestion: {res.note}"]
        if res.suggested_ids:
            lines.append(
                f"suggested fiducials ({res.n_usable} usable candidates, {len(res.rejected)} rejected), robot frame, mm:"
            )
        for pid, pos in zip(res.suggested_ids, res.suggested):
            lines.append(f"  {pid:<12} {fmt_vec(pos, 9, 1)}")
    if res.rejected:
        shown = list(res.rejected.items())[:5]
        lines.append(
            "rejected candidates: "
            + "; ".join(f"{i}: {r}" for i, r in shown)
            + (f"; and {len(res.rejected) - 5} more" if len(res.rejected) > 5 else "")
        )
    return "\n".join(lines) + "\n"


def report_text(acc: dict) -> str:
    """The text of `rrbc report` for its object (`analysis.acceptance.acceptance`): the verdict, its criterion and
    reason, the failing points, the methods' RMS at the checks and the recommended one."""
    from rrbc_core.analysis.acceptance import METHOD_NAMES

    tol = acc["tolerance_mm"]
    lines = [
        f"verdict: {acc['verdict']} ({acc['reason']})",
        f"criterion: {acc['criterion']}" + (f": {tol:g} mm" if tol is not None else ""),
    ]
    for f in acc["failing"]:
        where = f" (station {f['group']})" if f["group"] is not None else ""
        what = "95 % bound" if f["what"] == "bound95" else "error"
        lines.append(f"  beyond: {f['role']} {f['id']}{where}: {what} {f['mm']:.3f} mm")
    for name, fig in acc["methods"].items():
        rms = fig.get("calibrate_rmst_mm", fig.get("rmst_mm"))
        shown = "-" if rms is None else f"{rms:.4f} mm"
        lines.append(
            f"{METHOD_NAMES[name]:<11} RMS at the checks {shown}"
            + ("  (recommended)" if name == acc["recommended"] else "")
        )
    lines.append(f"recommended: {METHOD_NAMES[acc['recommended']]}: {acc['recommendation_basis']}")
    m = acc["measured"]
    lines.append(f"{m['targets']} targets, {m['checks']} checks, {m['fiducials']} fiducials")
    return "\n".join(lines) + "\n"
