"""The flag the control panels share while the app assigns their values (viser re-enters value callbacks)."""

from __future__ import annotations

from contextlib import contextmanager


class Syncing:
    """A flag the panels share: while it is set, their value callbacks do nothing (programmatic updates)."""

    def __init__(self):
        self.on = False

    @contextmanager
    def quiet(self):
        was = self.on
        self.on = True
        try:
            yield
        finally:
            self.on = was


def clamped(handle, fallback: float | None = None) -> float:
    """A slider's or number input's value as the server will use it (issue 16): viser does not clamp values a
    client sends, so a non-number or a non-finite value becomes `fallback` (default the lower bound) and the rest
    is clamped to [min, max]."""
    import math

    lo = getattr(handle, "min", None)
    hi = getattr(handle, "max", None)
    try:
        v = float(handle.value)
    except (TypeError, ValueError):
        v = math.nan
    if not math.isfinite(v):
        v = fallback if fallback is not None else (lo if lo is not None else 0.0)
    if lo is not None:
        v = max(v, float(lo))
    if hi is not None:
        v = min(v, float(hi))
    return v
