"""The words of a diagnosis: the lines `rrbc diagnose` prints, which the app's Diagnose tab shows unchanged.

One function writes them (`diagnosis_lines`), so the command line and the app cannot say two things about the same
data: noise σ per axis and where it came from, the bias RMS, each effect with its p-value and evidence, RRBC's verdict
with its basis (the file's own check rows as `rrbc correct` scores them, else leave-one-out), and the limits.
Lengths in mm.
"""

from __future__ import annotations

from rrbc_core.analysis.diagnosis import Diagnosis

__all__ = ["diagnosis_lines", "diagnosis_text"]


def _pct(x: float) -> str:
    return f"{100 * x:+.1f} %"


def diagnosis_lines(dg: Diagnosis) -> list[str]:
    """The lines `rrbc diagnose` prints for `dg` (no trailing newlines).

    Parameters
    ----------
    dg : Diagnosis
        A diagnosis (`analysis.diagnosis.diagnose`).

    Returns
    -------
    list of str
        The summary line (points, noise σ per robot axis and its source, bias RMS), one line per effect (most
        important first), the RRBC verdict with its basis, what the figure assumes, and one line per limit.
    """
    sig = ", ".join(f"{v:.4g}" for v in dg.noise_sigma_mm)
    lines = [
        f"{dg.n_points} paired points; noise sigma per axis ({dg.noise_source}): {sig} mm; "
        f"bias RMS {dg.bias_rms_mm:.4g} mm"
    ]
    if not dg.effects:
        lines.append("no effect found: the data are consistent with a rigid transform plus isotropic noise")
    for e in dg.effects:
        lines.append(f"{e.name} (p {e.p_value:.2g}): {e.evidence}")
    verdict = "recommended" if dg.rrbc_recommended else "not recommended"
    loo = dg.loo_rms_rrbc_mm / dg.loo_rms_rigid_mm - 1 if dg.loo_rms_rigid_mm > 0 else 0.0
    if dg.checks_rms_mm is not None:
        rig, rr = dg.checks_rms_mm
        lines.append(
            f"RRBC {verdict}: RMST change {_pct(dg.expected_rmst_change)} at the file's check rows "
            f"(rigid {rig:.4g} mm, RRBC {rr:.4g} mm, as rrbc correct scores them)"
        )
    else:
        lines.append(f"RRBC {verdict}: expected RMST change {_pct(dg.expected_rmst_change)} (leave-one-out)")
    if dg.gain is not None:
        lines.append(f"  {dg.gain.words()}" + (": not enough to recommend it" if dg.gain.verdict != "gain" else ""))
    if dg.expected_change_without_outliers is not None:
        lines.append(f"  with the outliers removed from the file: {_pct(dg.expected_change_without_outliers)}")
    lines.append(f"  {'measured' if dg.checks_rms_mm is not None else 'predicts'}: {dg.assumes}")
    if dg.checks_extrapolation is not None:
        lines.append(f"  extrapolated checks: {dg.checks_extrapolation}")
    if dg.checks_rms_mm is not None:
        lines.append(
            f"  leave-one-out over the paired points (not the basis of the verdict): {_pct(loo)}; it assumes each "
            "paired point stands in for a check at its place"
            + (", which checks outside the fiducials' hull are not" if dg.checks_extrapolation is not None else "")
        )
    if dg.check_statistics is not None:
        lines += dg.check_statistics.lines()
    lines += [f"limit: {text}" for text in dg.limits]
    return lines


def diagnosis_text(dg: Diagnosis) -> str:
    """`diagnosis_lines` joined: the text output of `rrbc diagnose`."""
    return "\n".join(diagnosis_lines(dg)) + "\n"
