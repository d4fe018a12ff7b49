"""The Explore tab's "Checks: rigid vs RRBC" folder: the before/after statistics of the data set's check rows,
their histogram, rigid against RRBC, and the per-point list (the largest errors first).

Every number comes from `rrbc_core.session.data_set.check_statistics` — `rrbc correct` with the session's method on
the data the CSV download writes — so the folder shows what `rrbc correct DATA.csv` prints (its
`CheckStatistics.lines()`, the same text). Hidden when the data have no check rows. Errors in mm.
"""

from __future__ import annotations

import numpy as np

from rrbc_core.correction.check_statistics import CheckStatistics

#: Histogram bins of the check errors.
BINS = 20
#: checks listed one by one (the largest RRBC errors); the rest are counted
LISTED = 15


def _series(label: str, colour: str) -> dict:
    return {"label": label, "stroke": colour, "width": 2, "points": {"show": False}}


def render(stats: CheckStatistics, method: str) -> str:
    """The folder's text: the statistics table as `rrbc correct` prints it, and which checks RRBC made worse."""
    rms = stats.change("rms")
    head = (
        f"**RMS rigid {stats.rigid['rms']:.3f} → RRBC {stats.rrbc['rms']:.3f} mm"
        + (f" ({rms:+.1f} %)" if rms is not None else "")
        + f"** over the data's {stats.n} check points ({method}; the numbers of `rrbc correct` on "
        "the CSV download)."
    )
    return head + "\n\n```\n" + "\n".join(stats.lines()[1:]) + "\n```"


def point_list(stats: CheckStatistics, limit: int = LISTED) -> str:
    """The per-point list (`CheckStatistics.per_point`): each check's rigid and RRBC error, the largest RRBC error
    first, those RRBC made worse marked; a fixed-width block like the statistics above it (not a second table
    beside the targets' one)."""
    rows = stats.per_point(limit)
    width = max([len("check")] + [len(pid) for pid, _, _ in rows])
    lines = [f"{'check':<{width}}  rigid mm   RRBC mm"]
    for pid, rigid, rrbc in rows:
        lines.append(f"{pid:<{width}}  {rigid:8.3f}  {rrbc:8.3f}" + ("  RRBC worse" if rrbc > rigid else ""))
    more = stats.n - len(rows)
    tail = f"\n\n… and {more} more (all in *Download corrected targets* and the report)." if more > 0 else ""
    return "**Per check**, the largest RRBC errors first:\n\n```\n" + "\n".join(lines) + "\n```" + tail


class ChecksPanel:
    """The folder's widgets (built inside the Explore tab); `show` gives it values, it owns its handles."""

    def __init__(self, gui):
        self.folder = gui.add_folder("Checks: rigid vs RRBC")
        with self.folder:
            self.text = gui.add_markdown("")
            self.histogram = gui.add_uplot(
                (np.array([0.0, 1.0]), np.zeros(2), np.zeros(2)),
                ({"label": "error (mm)"}, _series("rigid", "#dc2828"), _series("RRBC", "#1eb43c")),
                title="Check errors: histogram",
                scales={"x": {"time": False}},
                axes=({"label": "error (mm)"}, {"label": "fraction of checks"}),
                aspect=1.4,
            )
            self.points = gui.add_markdown("")
        self.folder.visible = False
        self.stats: CheckStatistics | None = None  # what is shown (None: hidden)

    def show(self, stats: CheckStatistics | None, method: str = "") -> None:
        """Show `stats` (None hides the folder: no check rows)."""
        self.stats = stats
        self.folder.visible = stats is not None
        if stats is None:
            return
        self.text.content = render(stats, method)
        self.histogram.data = stats.histogram(BINS)
        self.points.content = point_list(stats)
