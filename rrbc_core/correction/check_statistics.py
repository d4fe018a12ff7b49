"""Before/after statistics of the check errors: what a user reads to decide whether RRBC helped on their file.

One function (`check_statistics`) computes them for `rrbc correct` (text and JSON), `rrbc diagnose` and the app, so
every place shows the same numbers. For C check points with robot-frame truth t_c and predicted positions p_c
(rigid: the registered sensor reading; RRBC: the corrected one), the error e_c = p_c − t_c (robot frame, mm):

- the 3-D error |e_c|: mean, RMS, 95th percentile and maximum, rigid and RRBC, with RRBC's change in % of rigid;
- the horizontal error |(e_x, e_y)| and the vertical error |e_z| in the robot frame (z is the robot base's up
  axis): their 95th percentiles — the figure stationing benchmarks publish;
- the checks where RRBC is worse than rigid (|e_rrbc| > |e_rigid|), by id;
- whether the points show RRBC's change at all (`gain_test`): a one-sided paired t-test of the squared errors
  d_c = |e_rigid,c|² − |e_rrbc,c|² (the RMS is their mean's square root), at `GAIN_ALPHA`. A gain is "shown" only
  when the mean of d is above zero at that level, a loss likewise; else "unclear". `rrbc diagnose`'s recommendation
  (its `--alpha` is the level of the effects it names, not of this) and the app's headline colour are this one
  decision.

Percentiles are numpy's default (linear interpolation between order statistics), stated so that anyone can
reproduce them.
"""

from __future__ import annotations

import itertools
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from rrbc_core.errors import InputError

__all__ = [
    "GAIN_ALPHA",
    "STATISTICS",
    "CheckStatistics",
    "GainTest",
    "check_statistics",
    "gain_from_differences",
    "gain_test",
]

#: the level at which RRBC's change of the mean squared error counts as shown (`gain_test`)
GAIN_ALPHA = 0.05

#: The statistics reported, in order: name -> (label, what it is of).
STATISTICS = {
    "mean": ("mean", "3-D error"),
    "rms": ("RMS", "3-D error"),
    "p95": ("p95", "3-D error"),
    "max": ("max", "3-D error"),
    "p95_xy": ("p95 horizontal (xy)", "horizontal error, robot frame"),
    "p95_z": ("p95 vertical (z)", "vertical error, robot frame"),
}
#: the text table's width in characters (`CheckStatistics.lines`: a label of 19, two columns of 8 and one of 7;
#: the app shows it in its side panel)
TABLE_WIDTH = 47


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

    def per_point(self, limit: int | None = None) -> list[tuple[str, float, float]]:
        """(id, rigid error, RRBC error) mm per check, the largest RRBC error first (ties: the larger rigid error,
        then the file's order); the first `limit` (all when None)."""
        order = np.lexsort((np.arange(self.n), -self.error_rigid_mm, -self.error_rrbc_mm))
        rows = [(str(self.ids[i]), float(self.error_rigid_mm[i]), float(self.error_rrbc_mm[i])) for i in order]
        return rows if limit is None else rows[: max(int(limit), 0)]

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
            f"errors at {self.n} checks (robot frame, mm):",
            f"  {'':<19} {'rigid':>8} {'RRBC':>8} {'change':>7}",
        ]
        for name, (label, _) in STATISTICS.items():
            c = self.change(name)
            out.append(
                f"  {label:<19} {self.rigid[name]:8.4f} {self.rrbc[name]:8.4f} "
                + (f"{f'{c:+.1f}%' if abs(c) < 1000 else f'{c:+.0f}%':>7}" if c is not None else f"{'-':>7}")
            )
        out.append(f"  RRBC worse than rigid at {len(self.worse)} of {self.n}" + (":" if self.worse else ""))
        # the ids wrapped as wide as the table (the app shows these lines in its side panel)
        listed = ", ".join(self.worse[:20]) + (" …" if len(self.worse) > 20 else "")
        out += textwrap.wrap(
            listed,
            TABLE_WIDTH,
            initial_indent=" " * 4,
            subsequent_indent=" " * 4,
            break_long_words=False,
            break_on_hyphens=False,
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
    names = tuple(map(str, ids))
    worse = tuple(itertools.compress(names, (d_rrbc > d_rigid).tolist()))  # (no Python loop over a million checks)
    return CheckStatistics(names, _stats(e_rigid), _stats(e_rrbc), d_rigid, d_rrbc, worse)


@dataclass(frozen=True)
class GainTest:
    """Whether the points show RRBC's change (module docstring): `change` = RMS RRBC / RMS rigid − 1, the one-sided
    p-values of a gain and of a loss, the number of points and the level; `verdict` "gain", "loss" or "unclear"."""

    change: float
    p_gain: float
    p_loss: float
    n: int
    alpha: float
    #: (n,) the tested differences rigid² − rrbc², mm² (pooling tests: `gain_from_differences`)
    differences: np.ndarray = field(default_factory=lambda: np.zeros(0), compare=False, repr=False)

    @property
    def verdict(self) -> str:
        if self.p_gain < self.alpha:
            return "gain"
        if self.p_loss < self.alpha:
            return "loss"
        return "unclear"

    def words(self) -> str:
        """The decision in words, e.g. "a gain these 40 points show (paired test of the squared errors, p 3e-05)"."""
        test = "paired test of the squared errors"
        if self.verdict == "unclear":
            p = min(self.p_gain, self.p_loss)
            return f"these {self.n} points do not show the change at the {self.alpha:g} level ({test}, p {p:.2g})"
        p = self.p_gain if self.verdict == "gain" else self.p_loss
        return f"a {self.verdict} these {self.n} points show ({test}, p {p:.2g})"

    def to_json(self) -> dict:
        return {
            "verdict": self.verdict,
            "p_gain": self.p_gain,
            "p_loss": self.p_loss,
            "n": self.n,
            "alpha": self.alpha,
        }


def gain_test(error_rigid_mm, error_rrbc_mm, alpha: float = GAIN_ALPHA) -> GainTest:
    """`GainTest` of the 3-D errors (C,) mm of the same points, rigid and RRBC (non-finite pairs left out): a
    one-sided paired t-test of d = rigid² − rrbc² each way. Fewer than 3 points, or no spread in d: p = 1 both ways
    unless every d has one sign and they are not all zero (then that side's p is 0)."""
    a, b = np.asarray(error_rigid_mm, float), np.asarray(error_rrbc_mm, float)
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    rms = lambda e: float(np.sqrt(np.mean(e**2))) if len(e) else 0.0
    change = rms(b) / rms(a) - 1.0 if rms(a) > 0 else 0.0
    return gain_from_differences(a**2 - b**2, change, alpha)


def gain_from_differences(d, change: float, alpha: float = GAIN_ALPHA) -> GainTest:
    """`GainTest` of the squared-error differences d (n,) = rigid² − rrbc², mm² (`gain_test`; pooled over stations
    by concatenating theirs), RRBC's RMS `change` given."""
    from scipy.special import stdtr

    d = np.asarray(d, float)
    n = int(len(d))
    if n < 3:
        return GainTest(change, 1.0, 1.0, n, float(alpha), d)
    if float(np.std(d)) <= 1e-15 * max(float(np.max(np.abs(d))), 1e-300):
        mean = float(np.mean(d))
        return GainTest(change, 0.0 if mean > 0 else 1.0, 0.0 if mean < 0 else 1.0, n, float(alpha), d)
    # the one-sample t statistic of d against 0 and its Student-t tails with n − 1 degrees of freedom (what
    # scipy.stats.ttest_1samp gives, without its per-call machinery: this runs on every drag update of the app)
    t = float(np.mean(d)) / (float(np.std(d, ddof=1)) / np.sqrt(n))
    p_gain, p_loss = float(stdtr(n - 1, -t)), float(stdtr(n - 1, t))
    return GainTest(change, p_gain, p_loss, n, float(alpha), d)
