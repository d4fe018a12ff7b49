"""Markdown of the Diagnose tab: which rows the diagnosis sees, and its verdict said on screen.

`diagnosis_rows` keeps the rows of an export whose role is registration, fiducial or both: the diagnosis must not
see the targets' truth (scene mode exports them as `check` rows). Formatting only: every number comes from a
`rrbc_core.diagnosis.Diagnosis` (lengths in mm, linear terms in ppm).
"""

from __future__ import annotations

import numpy as np

from rrbc_core.analysis.diagnosis import Diagnosis, Effect
from rrbc_core.io.measurements import MeasurementSet

ROLES = ("registration", "fiducial", "both")
PROMPT = (
    "Tests the current registration points and fiducials (never the targets) for what a rigid fit with "
    "isotropic noise misses: outliers, scale, affine terms, drift, the arm's kinematic error (scenes with a "
    "kinematic arm: the joint angles go along), a smooth field, anisotropic noise. "
    "Press **Diagnose current data**."
)
STALE = "**(data changed since — press again)**"
LABELS = {
    "outliers": "Outliers",
    "scale": "Uniform scale",
    "affine": "Affine (beyond scale)",
    "drift": "Drift",
    "kinematic": "Arm kinematic (DH) error",
    "smooth_field": "Smooth field",
    "anisotropic_noise": "Anisotropic noise",
}


def diagnosis_rows(mset: MeasurementSet) -> MeasurementSet:
    """The rows of `mset` whose role is registration, fiducial or both (targets and check rows removed)."""
    keep = [i for i, role in enumerate(mset.roles) if role in ROLES]
    extra = {k: tuple(v[i] for i in keep) for k, v in mset.extra.items()}
    return MeasurementSet(
        ids=tuple(mset.ids[i] for i in keep),
        roles=tuple(mset.roles[i] for i in keep),
        sensor=mset.sensor[keep].reshape(len(keep), 3),
        robot=mset.robot[keep].reshape(len(keep), 3),
        time=mset.time[keep] if len(mset.time) == len(mset.roles) else np.full(len(keep), np.nan),
        lines=tuple(mset.lines[i] for i in keep),
        source=mset.source,
        extra=extra,
    )


def _g(x) -> str:
    return f"{float(x):.3g}"


def _p(p: float) -> str:
    return f"{p:.2g}" if p >= 1e-3 else f"{p:.1e}"


def _vec(v, unit: str, fmt=_g) -> str:
    return "(" + ", ".join(fmt(x) for x in v) + f") {unit}".rstrip()


def parameters(e: Effect) -> str:
    """An effect's parameters in words: mm, ppm (linear terms), mm/s (drift)."""
    p = e.parameters
    if e.name == "outliers":
        ids = list(p.get("ids", ()))
        return f"{len(ids)} point{'s' if len(ids) != 1 else ''}: {', '.join(map(str, ids))}"
    if e.name == "scale":
        return f"{p['ppm']:+.0f} ppm ± {p['ppm_standard_error']:.0f} ppm"
    if e.name == "affine":
        g = np.asarray(p["matrix"], float) * 1e6
        rows = "; ".join(" ".join(f"{x:+.0f}" for x in row) for row in g)
        return f"symmetric linear part [{rows}] ppm (largest {np.max(np.abs(np.linalg.eigvalsh(g))):.0f} ppm)"
    if e.name == "drift":
        rate = np.asarray(p["rate_mm_per_s"], float)
        return f"rate {_vec(rate, 'mm/s')} (|·| {np.linalg.norm(rate):.3g} mm/s)"
    if e.name == "smooth_field":
        return f"RMS {p['rms_mm']:.3f} mm, length scale {p['length_scale_mm']:.0f} mm"
    if e.name == "kinematic":
        return (
            f"RMS {p['rms_mm']:.3f} mm from {p['combinations']} combinations of the {str(p['robot']).upper()}'s "
            f"DH parameters (tool {p['tool_mm']:g} mm)"
        )
    if e.name == "anisotropic_noise":
        return f"{p['ratio']:.2f}× larger along the sensor axis {_vec(p['axis'], '', lambda x: f'{x:.3f}')}"
    return ", ".join(f"{k} {v}" for k, v in p.items())


def render(d: Diagnosis, source: str, stale: bool = False) -> str:
    """The verdict, noise, bias, RRBC recommendation and limits of `d` (most important effect first)."""
    lines = [STALE] if stale else []
    lines.append(
        f"Diagnosis of **{d.n_points} points** (registration points and fiducials of {source}; targets "
        f"withheld), α = {d.alpha:g} family-wise over {len(d.tests)} tests."
    )
    if d.effects:
        lines.append(
            f"**Verdict: {len(d.effects)} effect{'s' if len(d.effects) != 1 else ''} beyond rigid + "
            "isotropic noise**, most important first:"
        )
        lines.append(
            "\n".join(
                f"{i}. **{LABELS.get(e.name, e.name)}**: {parameters(e)}; p = {_p(e.p_value)}. *{e.evidence}*"
                for i, e in enumerate(d.effects, 1)
            )
        )
    else:
        lines.append("**Verdict: consistent with rigid + isotropic noise** (no test significant).")
    src = "repeated measurements" if d.noise_source == "repeats" else "fit residuals"
    lines.append(
        f"Noise σ (x, y, z): **{', '.join(f'{s:.3f}' for s in d.noise_sigma_mm)} mm** (from {src}). "
        f"Bias RMS: **{d.bias_rms_mm:.3f} mm**."
    )
    change = 100.0 * d.expected_rmst_change
    if d.checks_rms_mm is not None:
        basis = (
            f"at the check points, as `rrbc correct` scores them: RMS {d.checks_rms_mm[0]:.3f} mm rigid → "
            f"{d.checks_rms_mm[1]:.3f} mm RRBC"
        )
    else:
        basis = f"leave-one-out RMS {d.loo_rms_rigid_mm:.3f} mm rigid → {d.loo_rms_rrbc_mm:.3f} mm RRBC"
    lines.append(
        f"RRBC **{'recommended' if d.rrbc_recommended else 'not recommended'}**: expected RMST change "
        f"**{change:+.1f} %** ({basis})."
    )
    if d.limits:
        lines.append("Limits:\n" + "\n".join(f"- {s}" for s in d.limits))
    return "\n\n".join(lines)


def render_error(message: str, stale: bool = False) -> str:
    return ((STALE + "\n\n") if stale else "") + f"⚠ Cannot diagnose: {' '.join(str(message).split())}"
