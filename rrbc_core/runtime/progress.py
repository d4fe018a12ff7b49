"""A minimal progress bar on stderr for long runs (no global state; the caller owns the object).

It stays silent for the first `delay_s` seconds (so short runs print nothing) and when `stream` is not a
terminal, unless `force=True` (tests). Output goes to stderr only, so `--json` on stdout stays clean.
"""

from __future__ import annotations

import sys
import time


class ProgressBar:
    def __init__(
        self, total: int, label: str = "", stream=None, delay_s: float = 1.0, force: bool = False, width: int = 30
    ):
        self.total = max(int(total), 1)
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        self.delay_s = delay_s
        self.width = width
        self.enabled = force or bool(getattr(self.stream, "isatty", lambda: False)())
        self.start = time.perf_counter()
        self.done = 0
        self.shown = False

    def update(self, n: int = 1, label: str | None = None) -> None:
        self.done = min(self.done + n, self.total)
        if label is not None:
            self.label = label
        if not self.enabled or time.perf_counter() - self.start < self.delay_s:
            return
        frac = self.done / self.total
        bar = "#" * int(frac * self.width)
        self.stream.write(f"\r{self.label:<28.28} [{bar:<{self.width}}] {frac * 100:5.1f} %")
        self.stream.flush()
        self.shown = True

    def close(self) -> None:
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()
