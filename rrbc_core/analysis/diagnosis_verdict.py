"""RRBC's verdict in `rrbc diagnose`: what `rrbc correct` will do on the file as given (docs/cli.md, theory.md §6.5).

Two bases, chosen by what the file holds:

- **checks** — the file has check rows (robot values scored by `rrbc correct`). The verdict is then exactly what
  `rrbc correct` measures on them, computed by the same pipeline (`correction.pipeline.correct_measurements`:
  registration rows, fiducial rows, IDW k = 4, p = 2). Nothing is predicted that the file can measure: whatever the
  check rows hold (noisy readings or noise-free truth, outliers or not) is scored as `rrbc correct` scores it.
- **leave-one-out** — no check rows. Each paired point is left out in turn and predicted by a rigid fit and RRBC
  from all the others, scored against its own reading (`diagnosis_stats.loo`). This is a prediction for points
  measured like the paired ones; against noise-free truth RRBC does worse than it says (the left-out reading's own
  noise is added to both errors and dilutes the difference).

With outliers found, the same figure is also computed with the outliers' rows removed from the file.

RRBC is recommended only for a gain the points show (`correction.check_statistics.gain_test` at its level,
the one decision the app's headline colour also uses): a change of a few % over checks that cannot tell it from
nothing is "not recommended", with the test's words.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.analysis.diagnosis_stats import loo_errors
from rrbc_core.correction.check_statistics import GAIN_ALPHA, CheckStatistics, GainTest, gain_test
from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.correction.warnings import Corrected, extrapolation
from rrbc_core.errors import InputError
from rrbc_core.io.measurements import MeasurementSet, select_rows


@dataclass(frozen=True)
class Verdict:
    """RRBC against a rigid fit on one file: ``basis`` (one of `BASES`), the two RMS errors (mm) on that basis,
    ``change`` = rrbc / rigid − 1, ``without_outliers`` (the same change with the outliers' rows removed, or
    None without outliers) and the leave-one-out RMS errors (mm), computed on either basis."""

    basis: str
    rms_rigid_mm: float
    rms_rrbc_mm: float
    without_outliers: float | None
    loo_rigid_mm: float
    loo_rrbc_mm: float
    statistics: CheckStatistics | None = None  # `rrbc correct`'s before/after statistics of the checks (basis checks)
    #: how many checks lie outside the fiducials' hull and how far off their plane (`correction.warnings.extrapolation`),
    #: None when all are inside or there are no scored checks
    checks_extrapolation: str | None = None
    #: whether the basis's points show the change (`gain_test`); None: not tested (no points)
    gain: GainTest | None = None

    @property
    def change(self) -> float:
        return self.rms_rrbc_mm / self.rms_rigid_mm - 1.0 if self.rms_rigid_mm > 0 else 0.0

    @property
    def recommended(self) -> bool:
        """RRBC lowers the RMS and the points show it (`gain_test`)."""
        return bool(self.rms_rrbc_mm < self.rms_rigid_mm and self.gain is not None and self.gain.verdict == "gain")


def _check_rms(mset: MeasurementSet) -> tuple[float, float, CheckStatistics, str | None] | None:
    """`rrbc correct`'s check RMST (rigid, RRBC) on `mset`, its check statistics and its words on the checks'
    extrapolation, or None when it has no scored checks or cannot run."""
    if not any(r == "check" for r in mset.roles):
        return None
    try:
        res = correct_measurements(mset)
    except InputError:  # too few registration points, no fiducials: rrbc correct refuses, no check figure
        return None
    s = res.summary()
    if s["rmst_rigid_mm"] is None:
        return None
    corrected = res.checks_corrected
    words = None
    if corrected is not None:
        words = extrapolation(Corrected("check", res.checks.ids, corrected.correction, res.checks_coverage))
    stats = res.statistics()
    if stats is None:
        return None
    return float(s["rmst_rigid_mm"]), float(s["rmst_rrbc_mm"]), stats, words


def _without_ids(mset: MeasurementSet, drop: set) -> MeasurementSet:
    return select_rows(mset, [i for i, pid in enumerate(mset.ids) if pid not in drop])


def rrbc_verdict(
    mset: MeasurementSet,
    sensor: np.ndarray,
    robot: np.ndarray,
    count: np.ndarray,
    outlier_ids: tuple[str, ...] = (),
    ids: tuple[str, ...] = (),
    alpha: float = GAIN_ALPHA,
) -> Verdict:
    """RRBC's verdict on the file as given: on its check rows when it has any, else by leave-one-out.

    Parameters
    ----------
    mset : MeasurementSet
        The file as read.
    sensor, robot : (N, 3) ndarray
        The distinct paired points' mean readings, sensor and robot frame (mm), in the order of `ids`.
    count : (N,) ndarray
        Rows averaged per point (the leave-one-out fits' weights).
    outlier_ids : tuple of str
        Ids diagnose found to be outliers: kept in the fits, not scored by leave-one-out; removed from the file for
        ``without_outliers``.
    ids : tuple of str
        The paired points' ids (length N).
    alpha : float
        The level at which the gain must be shown (`gain_test`).

    Returns
    -------
    Verdict
    """
    drop = set(outlier_ids)
    good = np.array([pid not in drop for pid in ids], bool)
    e_rigid, e_rrbc = loo_errors(sensor, robot, count, evaluate=good)
    rms = lambda e: float(np.sqrt(np.mean(e**2)))
    loo_rigid, loo_rrbc = rms(e_rigid), rms(e_rrbc)
    checks = _check_rms(mset)
    if checks is not None:
        without = None
        if drop:
            w = _check_rms(_without_ids(mset, drop))
            without = (w[1] / w[0] - 1.0 if w[0] > 0 else 0.0) if w is not None else None
        stats = checks[2]
        gain = gain_test(stats.error_rigid_mm, stats.error_rrbc_mm, alpha)
        return Verdict("checks", checks[0], checks[1], without, loo_rigid, loo_rrbc, stats, checks[3], gain)
    without = None
    if drop:
        r2, f2 = (rms(e) for e in loo_errors(sensor[good], robot[good], count[good]))
        without = f2 / r2 - 1.0 if r2 > 0 else 0.0
    gain = gain_test(e_rigid, e_rrbc, alpha)
    return Verdict("leave-one-out", loo_rigid, loo_rrbc, without, loo_rigid, loo_rrbc, gain=gain)
