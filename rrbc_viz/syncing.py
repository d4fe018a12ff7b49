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


class LatestOnly:
    """Runs `fn` with the newest arguments only: a call arriving while one runs leaves its arguments and returns at
    once; when the running call ends, the newest waiting arguments run (those in between are dropped). For controls
    a user moves quickly (a slider's arrow keys send one update per step) whose every update is expensive."""

    def __init__(self, fn):
        import threading

        self._fn = fn
        self._lock = threading.Lock()
        self._pending: tuple | None = None
        self._running = False

    def __call__(self, *args, **kwargs) -> None:
        with self._lock:
            self._pending = (args, kwargs)
            if self._running:
                return
            self._running = True
        while True:
            with self._lock:
                job, self._pending = self._pending, None
                if job is None:
                    self._running = False
                    return
            try:
                self._fn(*job[0], **job[1])
            except Exception:  # noqa: BLE001 - the caller's thread carries on; the next value still runs
                import traceback

                traceback.print_exc()
