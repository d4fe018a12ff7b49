"""Warnings about a correction a user should not take at face value (issue 28: no silent blow-up).

One function, `correction_warnings`, used by `rrbc correct` (text and JSON ``warnings``), by each station of a file
with groups, and by the app's Explore tab, so that all say the same. Each warning is one line. Three kinds:

* **Wild corrections**: a target's or check's interpolated correction larger than `WILD_FACTOR` times the largest
  fiducial correction. An interpolation between fiducials has no business predicting more than its data; where it
  does, it extrapolates or swings (on pooled stations an exact spline swings far beyond its data:
  tests/interpolation/test_no_blow_up.py).
* **Conflicting twins**: fiducials nearly at one place (closer than `NEAR_FRACTION` of the fiducials' RMS radius, at
  least `NEAR_MIN_MM`) whose corrections differ by more than `CONFLICT_FRACTION` of the fiducials' RMS correction (at
  least `CONFLICT_MIN_MM`): the same place measured at two stations or reached in two arm configurations. No
  interpolation can honour both; a file with stations should say so with a `group` column.
* **Extrapolation**: targets or checks outside the fiducials' hull, and those off the fiducials' plane (how many, how
  far): RRBC's corrections there are extrapolated, and a check's score there says little about points inside.

Units mm; positions and corrections in the sensor frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rrbc_core.interpolation.hull import Coverage

#: a correction beyond this multiple of the largest fiducial correction is reported
WILD_FACTOR = 2.0
#: fiducials closer than this fraction of their RMS radius (and at least NEAR_MIN_MM) are "nearly coincident"
NEAR_FRACTION = 0.01
NEAR_MIN_MM = 0.5
#: ... and "conflicting" when their corrections differ by more than this fraction of the RMS fiducial correction
#: (and at least CONFLICT_MIN_MM, above a tracker's repeatability)
CONFLICT_FRACTION = 0.5
CONFLICT_MIN_MM = 0.2
#: at most this many pairs are named in one warning
NAMED_PAIRS = 3


@dataclass(frozen=True, eq=False)
class Corrected:
    """Points of one kind ("target" or "check") as the warnings see them: ids (M,), correction (M, 3) mm, and their
    coverage by the fiducials (`interpolation.hull.assess_coverage`; None without fiducials)."""

    kind: str
    ids: Sequence[str]
    correction: np.ndarray
    coverage: Coverage | None


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def wild_corrections(fiducial_corrections: np.ndarray, points: Corrected) -> str | None:
    """The warning for corrections beyond WILD_FACTOR × the largest fiducial correction, or None."""
    if len(points.ids) == 0 or len(fiducial_corrections) == 0:
        return None
    largest = float(np.max(np.linalg.norm(fiducial_corrections, axis=1)))
    size = np.linalg.norm(points.correction, axis=1)
    wild = size > WILD_FACTOR * largest
    if not np.any(wild) or largest == 0.0:
        return None
    k = int(np.argmax(size))
    return (
        f"{int(wild.sum())} of {_plural(len(size), points.kind)} get a correction above {WILD_FACTOR:g} × the largest "
        f"fiducial correction ({largest:.2f} mm), up to {size[k]:.1f} mm at {points.ids[k]!r}: the interpolation "
        "goes beyond its data there (extrapolation or conflicting fiducials); do not trust those corrections"
    )


def conflicting_fiducials(ids: Sequence[str], sensor: np.ndarray, corrections: np.ndarray) -> str | None:
    """The warning for nearly coincident fiducials with conflicting corrections (named, at most NAMED_PAIRS), or
    None. sensor, corrections: (N, 3) mm, sensor frame."""
    n = len(ids)
    if n < 2:
        return None
    from scipy.spatial import cKDTree

    radius = float(np.sqrt(np.mean(np.sum((sensor - sensor.mean(axis=0)) ** 2, axis=1))))
    near = max(NEAR_MIN_MM, NEAR_FRACTION * radius)
    rms_e = float(np.sqrt(np.mean(np.sum(corrections**2, axis=1))))
    conflict = max(CONFLICT_MIN_MM, CONFLICT_FRACTION * rms_e)
    pairs = np.array(sorted(cKDTree(sensor).query_pairs(near)), dtype=int).reshape(-1, 2)
    if len(pairs) == 0:
        return None
    d = np.linalg.norm(sensor[pairs[:, 0]] - sensor[pairs[:, 1]], axis=1)
    de = np.linalg.norm(corrections[pairs[:, 0]] - corrections[pairs[:, 1]], axis=1)
    bad = np.flatnonzero(de > conflict)
    if len(bad) == 0:
        return None
    bad = bad[np.argsort(-de[bad])]
    named = "; ".join(
        f"{ids[pairs[i, 0]]!r} and {ids[pairs[i, 1]]!r} ({d[i]:.2f} mm apart, corrections {de[i]:.2f} mm apart)"
        for i in bad[:NAMED_PAIRS]
    )
    more = f" and {len(bad) - NAMED_PAIRS} more" if len(bad) > NAMED_PAIRS else ""
    return (
        f"{_plural(len(bad), 'pair')} of nearly coincident fiducials (closer than {near:.2f} mm) carry conflicting "
        f"corrections: {named}{more} — the same place measured at two stations or in two arm configurations? "
        "Give each station its own `group`, or drop one of each pair"
    )


def extrapolation(points: Corrected) -> str | None:
    """The warning for targets or checks outside the fiducials' hull and off their plane (how many, how far), or
    None when all are inside."""
    cov = points.coverage
    if cov is None or len(points.ids) == 0:
        return None
    out = ~np.asarray(cov.inside, dtype=bool)
    if not np.any(out):
        return None
    m = len(points.ids)
    text = f"{int(out.sum())} of {_plural(m, points.kind)} lie outside the fiducials' hull: their corrections are extrapolated"
    if cov.plane_tol_mm is not None:
        off = np.asarray(cov.off_plane_mm) > cov.plane_tol_mm
        if np.any(off):
            what = "plane" if cov.dim == 2 else ("line" if cov.dim == 1 else "point")
            dist = np.asarray(cov.off_plane_mm)[off]
            text += (
                f"; {int(off.sum())} are off the fiducials' {what} by {dist.min():.0f}–{dist.max():.0f} mm "
                f"(median {np.median(dist):.0f} mm), where fiducials on the {what} say nothing about the error"
            )
    return text


def correction_warnings(
    fiducial_ids: Sequence[str],
    fiducial_sensor: np.ndarray,
    fiducial_corrections: np.ndarray,
    points: Sequence[Corrected],
) -> tuple[str, ...]:
    """All warnings on one correction, in a fixed order: conflicting fiducials, then per kind of point (targets,
    checks) wild corrections and extrapolation.

    Parameters
    ----------
    fiducial_ids : sequence of str, (N,)
    fiducial_sensor, fiducial_corrections : ndarray (N, 3)
        The fiducials' sensor readings and corrections e (sensor frame, mm).
    points : sequence of Corrected
        The targets and checks with their interpolated corrections and coverage.

    Returns
    -------
    tuple of str
        One-line warnings; empty when there is nothing to say.
    """
    e = np.asarray(fiducial_corrections, dtype=float).reshape(-1, 3)
    s = np.asarray(fiducial_sensor, dtype=float).reshape(-1, 3)
    found = [conflicting_fiducials(fiducial_ids, s, e)]
    for p in points:
        found += [wild_corrections(e, p), extrapolation(p)]
    return tuple(w for w in found if w)
