"""Monte Carlo in the background: the UI never waits for it.

`MonteCarloRunner.request(session_snapshot, trials)` queues a run of `session.monte_carlo(trials)` on one worker
thread. Requests coalesce: a run starts only once no newer request has come for `delay_s` (a slider being
dragged asks many times), while a run is under way only the newest request is kept, and a result that a newer
request has made stale is dropped, so the plots always end on the latest setup. A run cannot be interrupted
(the core has no cancellation), so this is what keeps slow setups (gp, clustering: seconds) from piling up. Pass a snapshot
(`copy.copy(session)`: settings and layout are immutable values, so a shallow copy is a consistent picture) so the
live session can keep changing while the worker runs.
"""

from __future__ import annotations

import threading
import time
import traceback
from typing import Callable

from rrbc_core.errors import InputError

ResultCallback = Callable[[object, str | None, float], None]  # (MonteCarloPlots | None, error message, seconds)


class MonteCarloRunner:
    def __init__(self, on_result: ResultCallback, on_start: Callable[[], None] | None = None, delay_s: float = 0.3):
        self._delay_s = float(delay_s)
        self._last_request = 0.0
        self._on_result = on_result
        self._on_start = on_start
        self._cond = threading.Condition()
        self._pending: tuple | None = None  # (generation, session, trials)
        self._generation = 0
        self._done_generation = 0
        self._busy = False
        self._stopped = False
        self._thread = threading.Thread(target=self._loop, name="rrbc-monte-carlo", daemon=True)
        self._thread.start()

    def request(self, session, trials: int) -> int:
        """Queue a run on `session` (a snapshot); returns the request's generation number."""
        with self._cond:
            self._generation += 1
            self._pending = (self._generation, session, int(trials))
            self._last_request = time.monotonic()
            self._cond.notify_all()
            return self._generation

    def cancel(self) -> None:
        """Forget queued work and make a running result stale (e.g. the source changed)."""
        with self._cond:
            self._generation += 1
            self._pending = None
            self._done_generation = self._generation
            self._cond.notify_all()

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until every request so far has finished (tests, scripts). True if idle in time."""
        end = time.monotonic() + timeout
        with self._cond:
            while self._busy or self._pending is not None or self._done_generation < self._generation:
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
            return True

    @property
    def busy(self) -> bool:
        with self._cond:
            return self._busy or self._pending is not None

    def stop(self) -> None:
        with self._cond:
            self._stopped = True
            self._pending = None
            self._cond.notify_all()

    def _loop(self) -> None:
        while True:
            with self._cond:
                while not self._stopped:
                    if self._pending is None:
                        self._cond.wait()
                        continue
                    quiet_for = time.monotonic() - self._last_request
                    if quiet_for >= self._delay_s:
                        break
                    self._cond.wait(self._delay_s - quiet_for)
                if self._stopped:
                    return
                generation, session, trials = self._pending
                self._pending = None
                self._busy = True
            if self._on_start is not None:
                try:
                    self._on_start()
                except Exception:  # noqa: BLE001 - a display hiccup must not kill the worker
                    traceback.print_exc()
            start = time.perf_counter()
            plots, error = None, None
            try:
                plots = session.monte_carlo(trials=trials)
            except InputError as exc:
                error = " ".join(str(exc).split())
            except Exception as exc:  # noqa: BLE001 - report, keep the worker alive
                traceback.print_exc()
                error = f"internal error: {type(exc).__name__}: {exc}"
            seconds = time.perf_counter() - start
            with self._cond:
                fresh = generation == self._generation and not self._stopped
            if fresh:
                try:
                    self._on_result(plots, error, seconds)
                except Exception:  # noqa: BLE001
                    traceback.print_exc()
            with self._cond:
                self._busy = False
                self._done_generation = max(self._done_generation, generation)
                self._cond.notify_all()
