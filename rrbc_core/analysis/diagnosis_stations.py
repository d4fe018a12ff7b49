"""`rrbc diagnose` on a file with stations (a `group` column, `io.groups`): each station diagnosed as a file of its
own, the false-alarm rate held over the whole file, and RRBC's verdict on all stations' checks together.

Each station has its own registration, so its own residuals: pooling them would call the stations' differences an
effect. Every station is diagnosed by `diagnosis.diagnose` at alpha / G (Bonferroni over the G stations), so the
chance of any false effect anywhere in the file stays at most alpha. RRBC's verdict: with check rows, `rrbc correct`'s
pooled figure over all stations (`correction.stations`), each station corrected from its own fiducials; without, the
stations' leave-one-out RMS errors pooled (root of the point-weighted mean of squares).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.analysis.diagnosis import Diagnosis, diagnose
from rrbc_core.correction.check_statistics import GainTest, gain_from_differences, gain_test
from rrbc_core.correction.stations import StationsResult, correct_stations
from rrbc_core.errors import InputError
from rrbc_core.io.groups import has_groups, split_groups
from rrbc_core.io.measurements import MeasurementSet


@dataclass(frozen=True, eq=False)
class StationsDiagnosis:
    """Per-station `Diagnosis` (``diagnoses[k]`` for ``groups[k]``, each at ``alpha / len(groups)``), the file-wide
    ``alpha``, and the pooled `rrbc correct` result (None without checks or when it cannot run)."""

    groups: tuple[str, ...]
    diagnoses: tuple[Diagnosis, ...]
    alpha: float
    pooled: StationsResult | None

    def effects(self) -> dict[str, list[str]]:
        """Effect name -> the stations where it was found, in order of how many."""
        found: dict[str, list[str]] = {}
        for g, d in zip(self.groups, self.diagnoses):
            for name in d.names:
                found.setdefault(name, []).append(g)
        return dict(sorted(found.items(), key=lambda kv: -len(kv[1])))

    def rrbc(self) -> dict:
        """The pooled verdict: ``basis`` ("checks" or "leave-one-out"), ``rms_rigid_mm``, ``rms_rrbc_mm``,
        ``expected_rmst_change``, ``recommended`` (a lower RMS the pooled points show: `gain_test`) and ``gain`` (the test)."""
        s = self.pooled.summary() if self.pooled is not None else None
        if s is not None and s["rmst_rigid_mm"] is not None:
            basis, rigid, rrbc = "checks", float(s["rmst_rigid_mm"]), float(s["rmst_rrbc_mm"])
        else:
            n = np.array([d.n_points for d in self.diagnoses], float)
            rigid = float(np.sqrt(np.sum(n * np.array([d.loo_rms_rigid_mm for d in self.diagnoses]) ** 2) / n.sum()))
            rrbc = float(np.sqrt(np.sum(n * np.array([d.loo_rms_rrbc_mm for d in self.diagnoses]) ** 2) / n.sum()))
            basis = "leave-one-out"
        change = rrbc / rigid - 1.0 if rigid > 0 else 0.0
        stats = self.pooled.statistics() if basis == "checks" and self.pooled is not None else None
        if stats is not None:
            gain = gain_test(stats.error_rigid_mm, stats.error_rrbc_mm)
        else:  # each station's own leave-one-out differences, pooled
            diffs = [d.gain.differences for d in self.diagnoses if d.gain is not None]
            gain = gain_from_differences(np.concatenate(diffs) if diffs else np.zeros(0), change)
        return {
            "basis": basis,
            "rms_rigid_mm": rigid,
            "rms_rrbc_mm": rrbc,
            "expected_rmst_change": change,
            "recommended": bool(rrbc < rigid and gain.verdict == "gain"),
            "gain": gain.to_json(),
        }

    def to_json(self) -> dict:
        """The JSON of `rrbc diagnose --json` on a file with groups (docs/cli.md)."""
        return {
            "alpha": float(self.alpha),
            "alpha_per_group": float(self.alpha / len(self.groups)),
            "groups": [{"group": g, **d.to_json()} for g, d in zip(self.groups, self.diagnoses)],
            "effects": self.effects(),
            "rrbc": self.rrbc(),
        }

    def lines(self) -> list[str]:
        """The text: each station's diagnosis under a header, then the effects across stations and the pooled
        verdict."""
        from rrbc_core.analysis.diagnosis_text import diagnosis_lines

        out: list[str] = []
        for g, d in zip(self.groups, self.diagnoses):
            out.append(f"=== group {g!r} ===")
            out += diagnosis_lines(d)
            out.append("")
        n = len(self.groups)
        out.append(
            f"=== all {n} groups, each diagnosed on its own at alpha {self.alpha:g}/{n} "
            f"(a false effect anywhere in the file at most {self.alpha:g}) ==="
        )
        eff = self.effects()
        if not eff:
            out.append("no effect found in any station")
        for name, where in eff.items():
            shown = ", ".join(repr(g) for g in where[:8]) + (" …" if len(where) > 8 else "")
            out.append(f"{name}: in {len(where)} of {n} stations ({shown})")
        v = self.rrbc()
        verdict = "recommended" if v["recommended"] else "not recommended"
        basis = (
            "at all stations' check rows, each station corrected from its own fiducials (as rrbc correct scores them)"
            if v["basis"] == "checks"
            else "leave-one-out within each station, pooled"
        )
        out.append(
            f"RRBC {verdict}: RMST change {100 * v['expected_rmst_change']:+.1f} % {basis} "
            f"(rigid {v['rms_rigid_mm']:.4g} mm, RRBC {v['rms_rrbc_mm']:.4g} mm)"
        )
        g = v["gain"]
        test = GainTest(v["expected_rmst_change"], g["p_gain"], g["p_loss"], g["n"], g["alpha"])
        out.append(f"  {test.words()}" + (": not enough to recommend it" if test.verdict != "gain" else ""))
        return out


def diagnose_stations(mset: MeasurementSet, alpha: float = 0.01, **options) -> Diagnosis | StationsDiagnosis:
    """`diagnose` per station of a file with a `group` column (module docstring), else on the whole file.

    Parameters
    ----------
    mset : MeasurementSet
    alpha : float
        The family-wise false-alarm rate over the whole file.
    **options
        Passed to `diagnose` (seed, robot, tool_mm, urdf, tip, base).
    """
    if not has_groups(mset):
        return diagnose(mset, alpha=alpha, **options)
    parts = split_groups(mset)
    per = alpha / len(parts)
    diagnoses = tuple(diagnose(m, alpha=per, **options) for _, m in parts)
    try:
        pooled: StationsResult | None = correct_stations(mset)  # type: ignore[assignment]
    except InputError:  # a station without fiducials: no pooled check figure
        pooled = None
    return StationsDiagnosis(tuple(g for g, _ in parts), diagnoses, float(alpha), pooled)
