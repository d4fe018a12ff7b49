"""The text of `rrbc check-model` (docs/check_model.md): the lines the command prints and the app's Model tab shows,
from one `scene_check.SceneCheck`."""

from __future__ import annotations

from rrbc_core.analysis.scene_check import SceneCheck

__all__ = ["check_lines"]

#: how the command says where the rest is and how to write the extension; the app says it its own way
CLI_HINTS = {"more": "--json lists all", "write": "give --out EXTENDED.toml to write it"}


def check_lines(
    res: SceneCheck, data: str, scene: str, written: str | None = None, hints: dict | None = None
) -> list[str]:
    """The lines `rrbc check-model` prints (and the app's Model tab shows): `data` and `scene` name the files,
    `written` the extended scene written (None: not written); `hints` (`CLI_HINTS` by default) where the rows not
    listed are and how the extension is written."""
    hints = CLI_HINTS if hints is None else hints
    lines = [
        f"check-model: {data} against the error model of {scene} "
        f"({res.trials} trials; {res.n_rows} rows with both readings compared)",
        f"  {'':<12}{'measured':>10}   predicted mean [95 % range]",
    ]
    for label, m, iv, out in res.figure_rows():
        if iv is None or m is None:
            lines.append(f"  {label:<12}{'-':>10}   (no such rows in the file)")
            continue
        flag = "   OUTSIDE" if out else ""
        lines.append(f"  {label:<12}{m:>10.4g}   {iv.mean:.4g} [{iv.lo95:.4g}, {iv.hi95:.4g}]{flag}")
    n_out = len(res.outside)
    ch = res.outside_by_chance
    lines.append(
        f"rows outside their own 95 % region: {n_out} of {res.n_rows} (files of the model: {ch.lo95:.0f} to "
        f"{ch.hi95:.0f}, mean {ch.mean:.1f})"
        + (" MORE THAN CHANCE" if n_out > ch.hi95 else "")
        + (":" if n_out else "")
    )
    for p in res.outside[:10]:
        where = f" (group {p.group})" if p.group else ""
        lines.append(f"  {p.id}{where}: z {p.z:.3g}, {p.miss_mm:.3g} mm from its predicted residual")
    if n_out > 10:
        lines.append(f"  … and {n_out - 10} more ({hints['more']})")
    if res.follows:
        lines.append(f"the misfit follows: {', '.join(res.follows)}")
    if res.stations_off:
        lines.append(f"stations whose rows miss more than the model allows: {', '.join(res.stations_off)}")
    if res.unexplained:
        lines.append("unexplained by the model (diagnose's tests on what it leaves):")
        lines += [f"  {e.name}: {e.evidence}" for e in res.unexplained]
    else:
        lines.append("unexplained by the model: nothing diagnose's tests can find")
    if res.added:
        names = ", ".join(t.table["type"] for t in res.added)
        lines.append(
            f"extended model (robot-side terms): {names}; " + (f"written to {written}" if written else hints["write"])
        )
    lines += [f"  {s}" for s in res.not_written]
    g = res.gain
    if res.added:
        lines.append(
            f"out of sample ({g['folds']} folds by {g['fold_by']}): prediction error {g['prediction_error_before_mm']:.4g}"
            f" -> {g['prediction_error_after_mm']:.4g} mm; rows inside their 95 % region "
            f"{100 * g['coverage_before']:.0f} % -> {100 * g['coverage_after']:.0f} %"
        )
    lines += [f"limit: {s}" for s in res.limits]
    lines.append(
        "verdict: "
        + (
            "the model fits these data (every figure inside its range, nothing unexplained)"
            if res.model_fits
            else "the model misses these data" + (": see the extended model" if res.added else "")
        )
    )
    return lines
