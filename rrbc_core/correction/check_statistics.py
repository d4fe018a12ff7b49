"""Before/after statistics of the check errors: what a user reads to decide whether RRBC helped on their file.

One function (`check_statistics`) computes them for `rrbc correct` (text and JSON), `rrbc diagnose` and the app, so
every place shows the same numbers. For C check points with robot-frame truth t_c and predicted positions p_c
(rigid: the registered sensor reading; RRBC: the corrected one), the error e_c = p_c − t_c (robot frame, mm):

- the 3-D error |e_c|: mean, RMS, 95th percentile and maximum, rigid and RRBC, with RRBC's change in % of rigid;
- the horizontal error |(e_x, e_y)| and the vertical error |e_z| in the robot frame (z is the robot base's up
  axis): their 95th percentiles — the figure stationing benchmarks publish;
- the checks where RRBC is worse than rigid (|e_rrbc| > |e_rigid|), by id.

Percentiles are numpy's default (linear interpolation between order statistics), stated so that anyone can
reproduce them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError

__all__ = ["STATISTICS", "CheckStatistics", "check_statistics"]

#: The statistics reported, in order: name -> (label, what it is of).
STATISTICS = {
    "mean": ("mean", "3-D error"),
    "rms": ("RMS", "3-D error"),
    "p95": ("p95", "3-D error"),
    "max": ("max", "3-D error"),
    "p95_xy": ("p95 horizontal (xy)", "horizontal error, robot frame"),
    "p95_z": ("p95 vertical (z)", "vertical error, robot frame"),
}


def _stats(e: np.ndarray) -> dict:
    """The STATISTICS of robot-frame error vectors (C, 3), mm."""
    d = np.linalg.norm(e, axis=1)
    return {
        "mean": float(np.mean(d)),
        "rms": float(np.sqrt(np.mean(d**2))),
        "p95": float(np.percentile(d, 95)),
        "max": float(np.max(d)),
        "p95_xy": float(np.percentile(np.linalg.norm(e[:, :2], axis=1), 95)),
        "p95_z": float(np.percentile(np.abs(e[:, 2]), 95)),
    }


@dataclass(frozen=True)
class CheckStatistics:
    """The check errors' statistics (module docstring). ``rigid`` and ``rrbc``: name -> mm (`STATISTICS`);
    ``ids``: the checks; ``error_rigid_mm``, ``error_rrbc_mm``: (C,) 3-D errors; ``worse``: ids where RRBC's
    error exceeds rigid's."""

    ids: tuple
    rigid: dict
    rrbc: dict
    error_rigid_mm: np.ndarray
    error_rrbc_mm: np.ndarray
    worse: tuple

    @property
    def n(self) -> int:
        return len(self.ids)

    def change(self, name: str) -> float | None:
        """RRBC's change of statistic `name` in % of rigid (None where rigid is 0)."""
        r = self.rigid[name]
        return 100.0 * (self.rrbc[name] / r - 1.0) if r > 0 else None

    def to_json(self) -> dict:
        return {
            "n": self.n,
            "rigid_mm": dict(self.rigid),
            "rrbc_mm": dict(self.rrbc),
            "change_percent": {k: self.change(k) for k in STATISTICS},
            "rrbc_worse": list(self.worse),
        }

    def histogram(self, bins: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(bin centres (B,), fraction of checks per bin rigid (B,), RRBC (B,)) of the 3-D errors over one set of
        bins from 0 to the largest error, mm."""
        top = float(max(self.error_rigid_mm.max(), self.error_rrbc_mm.max())) or 1.0
        edges = np.linspace(0.0, top * (1 + 1e-9), int(bins) + 1)
        n = max(self.n, 1)
        rigid = np.histogram(self.error_rigid_mm, edges)[0] / n
        rrbc = np.histogram(self.error_rrbc_mm, edges)[0] / n
        return 0.5 * (edges[1:] + edges[:-1]), rigid, rrbc

    def lines(self) -> list[str]:
        """The statistics as a text table (the command line's and the app's), one line each."""
        out = [
            f"check errors over {self.n} check points (robot frame, mm):",
            f"  {'':<22} {'rigid':>9} {'RRBC':>9} {'change':>9}",
        ]
        for name, (label, _) in STATISTICS.items():
            c = self.change(name)
            out.append(
                f"  {label:<22} {self.rigid[name]:9.4f} {self.rrbc[name]:9.4f} "
                + (f"{c:+8.1f}%" if c is not None else f"{'-':>9}")
            )
        out.append(
            f"  RRBC is worse than rigid at {len(self.worse)} of {self.n} check points"
            + (f": {', '.join(self.worse[:20])}{' …' if len(self.worse) > 20 else ''}" if self.worse else "")
        )
        return out


def check_statistics(ids: Sequence[str], robot_rigid, robot_rrbc, truth) -> CheckStatistics:
    """Before/after statistics of C check points (module docstring).

    Parameters
    ----------
    ids : sequence of str
        (C,) the checks' ids.
    robot_rigid, robot_rrbc : (C, 3) array_like
        Where rigid registration and RRBC put each check, robot frame, mm.
    truth : (C, 3) array_like
        Each check's robot-frame truth, mm.

    Returns
    -------
    CheckStatistics

    Raises
    ------
    InputError
        No checks, mismatched shapes or non-finite values.
    """
    a = np.asarray(robot_rigid, float).reshape(-1, 3)
    b = np.asarray(robot_rrbc, float).reshape(-1, 3)
    t = np.asarray(truth, float).reshape(-1, 3)
    if not (len(a) == len(b) == len(t) == len(ids)) or len(t) == 0:
        raise InputError(f"check statistics need C > 0 checks with 3 positions each, got {len(ids)} ids")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(np.isfinite(t))):
        raise InputError("check statistics: positions must be finite")
    e_rigid, e_rrbc = a - t, b - t
    d_rigid, d_rrbc = np.linalg.norm(e_rigid, axis=1), np.linalg.norm(e_rrbc, axis=1)
    worse = tuple(str(pid) for pid, x, y in zip(ids, d_rigid, d_rrbc) if y > x)
    return CheckStatistics(tuple(str(i) for i in ids), _stats(e_rigid), _stats(e_rrbc), d_rigid, d_rrbc, worse)
