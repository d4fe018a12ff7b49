"""RRBC on a file with stations (a `group` column, `io.groups`): each station corrected on its own, results per
station and pooled.

A station is one stationing of the robot: its own registration, its own fiducials and corrections; its targets and
checks are corrected from its own fiducials only. The pooled figures are over all stations' checks together (each
check scored against its own station's registration). Units mm; frames as in the measurement file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.correction import metrics
from rrbc_core.correction.check_statistics import CheckStatistics, check_statistics
from rrbc_core.correction.pipeline import CorrectionResult, correct_measurements
from rrbc_core.io.groups import has_groups, split_groups
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.methods import MethodOptions
from rrbc_core.models.instrument import Instrument


@dataclass(frozen=True, eq=False)
class StationsResult:
    """Per-station `CorrectionResult`s (``stations[k]`` for group ``groups[k]``) and their pooled figures.

    `summary()` and `statistics()` pool all stations' checks; `warnings()` prefixes each station's warnings with
    its group; `to_json()` is the JSON of `rrbc correct --json` on a file with groups (docs/cli.md).
    """

    groups: tuple[str, ...]
    stations: tuple[CorrectionResult, ...]
    options: MethodOptions

    def _pooled(self, name: str) -> np.ndarray:
        return np.concatenate([getattr(r, name) for r in self.stations])

    def summary(self) -> dict:
        """RMST and max error over all stations' checks, rigid and with RRBC (None without checks), and counts."""
        rigid, rrbc = self._pooled("error_rigid"), self._pooled("error_rrbc")
        out: dict = {"stations": len(self.groups), "checks": len(rigid)}
        if len(rigid) == 0:
            return {**out, "rmst_rigid_mm": None, "rmst_rrbc_mm": None, "max_rigid_mm": None, "max_rrbc_mm": None}
        fre = np.array([r.registration.fre_rms_mm for r in self.stations])
        return {
            **out,
            "rmst_rigid_mm": metrics.rmst(rigid),
            "rmst_rrbc_mm": metrics.rmst(rrbc),
            "max_rigid_mm": metrics.max_error(rigid),
            "max_rrbc_mm": metrics.max_error(rrbc),
            "fre_rms_mm_per_station": {
                "min": float(fre.min()),
                "median": float(np.median(fre)),
                "max": float(fre.max()),
            },
        }

    def statistics(self) -> CheckStatistics | None:
        """Before/after statistics over all stations' checks (ids written ``group/id``), None without checks."""
        ids, rigid, rrbc, truth = [], [], [], []
        for g, r in zip(self.groups, self.stations):
            if r.checks_corrected is None or len(r.error_rigid) == 0:
                continue
            ids += [f"{g}/{pid}" for pid in r.checks.ids]
            rigid.append(r.checks_corrected.robot_rigid)
            rrbc.append(r.checks_corrected.robot_rrbc)
            truth.append(r.checks.robot)
        if not ids:
            return None
        return check_statistics(ids, np.vstack(rigid), np.vstack(rrbc), np.vstack(truth))

    def warnings(self) -> tuple[str, ...]:
        """Every station's warnings, each prefixed ``group 'g': ``."""
        return tuple(f"group {g!r}: {w}" for g, r in zip(self.groups, self.stations) for w in r.warnings())

    def to_json(self, lazy: bool = False) -> dict:
        """The JSON of `rrbc correct --json` on a file with groups: ``groups`` (one object per station: ``group`` and
        the keys of a file without groups), pooled ``summary``, ``check_statistics`` and ``warnings``, and the
        ``interpolation`` used; `lazy` as `CorrectionResult.to_json`."""
        stations = [{"group": g, **r.to_json(lazy=lazy)} for g, r in zip(self.groups, self.stations)]
        return {
            "interpolation": self.options.interpolation_json(),
            "groups": stations,
            "summary": self.summary(),
            "check_statistics": None if (st := self.statistics()) is None else st.to_json(),
            "warnings": list(self.warnings()),
        }


def correct_stations(
    mset: MeasurementSet, options: MethodOptions | None = None, instrument: Instrument | None = None
) -> CorrectionResult | StationsResult:
    """`correct_measurements` per station of a file with a `group` column, else on the whole file.

    Parameters
    ----------
    mset : MeasurementSet
        A validated set (`read_measurements` checks each station has three usable registration points).
    options : MethodOptions, optional
        As for `correct_measurements`, the same for every station.
    instrument : Instrument, optional
        The reading noise for the per-point bounds (default: estimated from each station's data).

    Returns
    -------
    CorrectionResult or StationsResult
        A `StationsResult` when the set has a `group` column (even a single group), else the `CorrectionResult`.
    """
    options = MethodOptions() if options is None else options
    if not has_groups(mset):
        return correct_measurements(mset, options, instrument)
    parts = split_groups(mset)
    return StationsResult(
        tuple(g for g, _ in parts), tuple(correct_measurements(m, options, instrument) for _, m in parts), options
    )
