"""Does a measured file hold an error of the arm, and which: one decision for `rrbc diagnose` and `rrbc calibrate`.

`kinematic` (the arm's geometric parameters) and `compliance` (the arm giving way under its links' weight) are
named by `diagnose`'s nested tests (`diagnosis_systematic`, docs/theory.md §6.5): the arm's Jacobian columns must
reduce the rigid residuals beyond every accepted term (scale, affine, drift, ...) at the family-wise level, AND do so
beside a smooth field of position (a sensor field can follow the arm's smooth columns); the load terms must do the
same beyond the geometric columns. `rrbc calibrate` reports the same decision (`kinematic_error.claimed`,
`compliance.claimed`) by calling this module on the same file and arm model, so the two commands cannot disagree.

Why not calibrate's former rule (χ² of the identified errors, p < 0.001, and VEC's cross-validated RMST below 0.8 ×
RRBC's): it mixed two questions. Whether the arm has an error is a test of the data; whether a model-based correction
beats an interpolated one at the targets is the recommendation's question (cross-validation over the fiducials and
the one-standard-error rule, unchanged). On a file where `diagnose` named a kinematic error of 2.75 mm, VEC's
cross-validated error was 0.83 × RRBC's and calibrate said "not claimed", although at the checks VEC was 1.7× better.
"""

from __future__ import annotations

from dataclasses import dataclass

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import MeasurementSet

#: what both commands say the decision rests on (calibrate's `kinematic_error.rule`, docs/calibration.md)
RULE = (
    "named by rrbc diagnose's tests on the same file and arm model (one function, analysis.arm_verdict): the arm's "
    "columns reduce the rigid residuals beyond every accepted term at the family-wise level alpha, and beside a "
    "smooth field of position; compliance: the load terms do so beyond the geometric columns"
)
ALPHA = 0.01  # `rrbc diagnose`'s default family-wise level


@dataclass(frozen=True)
class ArmVerdict:
    """`kinematic`, `compliance`: named or not; their p-values (`tests`: every arm test the diagnosis ran, name ->
    p) and sizes (RMS over the points of what each explains, mm; None when not named); `limits`: what the diagnosis
    says it could not test about the arm (no joint columns, too few points, a field it cannot be told from)."""

    kinematic: bool
    compliance: bool
    tests: dict
    kinematic_rms_mm: float | None
    compliance_rms_mm: float | None
    limits: tuple[str, ...]
    alpha: float

    def to_json(self) -> dict:
        return {
            "kinematic": self.kinematic,
            "compliance": self.compliance,
            "tests": dict(self.tests),
            "kinematic_rms_mm": self.kinematic_rms_mm,
            "compliance_rms_mm": self.compliance_rms_mm,
            "alpha": self.alpha,
            "limits": list(self.limits),
        }


def verdict_of(diagnosis) -> ArmVerdict:
    """The arm's part of a `diagnosis.Diagnosis`, or of a `diagnosis_stations.StationsDiagnosis` (a file with
    stations, diagnosed per station at alpha / stations): named when any station names it (tests and limits prefixed
    with the station's name, the size the largest over the stations)."""
    if hasattr(diagnosis, "diagnoses"):
        per = [(g, verdict_of(d)) for g, d in zip(diagnosis.groups, diagnosis.diagnoses)]

        def largest(sizes) -> float | None:
            sizes = [x for x in sizes if x is not None]
            return max(sizes) if sizes else None

        return ArmVerdict(
            kinematic=any(v.kinematic for _, v in per),
            compliance=any(v.compliance for _, v in per),
            tests={f"{g}: {k}": p for g, v in per for k, p in v.tests.items()},
            kinematic_rms_mm=largest(v.kinematic_rms_mm for _, v in per),
            compliance_rms_mm=largest(v.compliance_rms_mm for _, v in per),
            limits=tuple(f"{g}: {lim}" for g, v in per for lim in v.limits),
            alpha=float(diagnosis.alpha),
        )
    found = {e.name: e for e in diagnosis.effects}
    arm_tests = {k: float(v) for k, v in diagnosis.tests.items() if k.startswith(("kinematic", "compliance"))}
    words = ("arm", "joint", "kinematic", "compliance", "configuration")
    return ArmVerdict(
        kinematic="kinematic" in found,
        compliance="compliance" in found,
        tests=arm_tests,
        kinematic_rms_mm=found["kinematic"].magnitude_mm if "kinematic" in found else None,
        compliance_rms_mm=found["compliance"].magnitude_mm if "compliance" in found else None,
        limits=tuple(lim for lim in diagnosis.limits if any(w in lim for w in words)),
        alpha=float(diagnosis.alpha),
    )


def arm_verdict(
    mset: MeasurementSet,
    robot: str | None = None,
    tool=None,
    urdf=None,
    tip: str | None = None,
    base=None,
    alpha: float = ALPHA,
    seed: int = 0,
) -> ArmVerdict:
    """The decision of `rrbc diagnose FILE` (per station when the file has stations) with the same arm model (`robot` or `urdf`, `tip`, `base`; `tool` a
    length along the flange's z axis or a point (3,) in the tip link's frame, mm), at family-wise level `alpha`.
    Where `diagnose` refuses the file (a station of fewer than 5 points), nothing is named and `limits` says why."""
    import numpy as np

    from rrbc_core.analysis.diagnosis_stations import diagnose_stations

    if tool is not None and np.ndim(tool) > 0:
        tool = tuple(float(x) for x in np.ravel(tool))
    try:
        found = diagnose_stations(
            mset, alpha=alpha, seed=seed, robot=robot, tool_mm=tool, urdf=urdf, tip=tip, base=base
        )
    except InputError as e:  # what diagnose cannot run on (a station of fewer than 5 points): nothing is named
        return ArmVerdict(False, False, {}, None, None, (f"the arm was not tested: {e}",), float(alpha))
    return verdict_of(found)
