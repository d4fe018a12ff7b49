"""Monte Carlo in the background: the UI never waits for it.

`MonteCarloRunner.request(session_snapshot, trials)` queues a run of `figures.monte_carlo(session, trials)` on one worker
thread (a `worker.CoalescingWorker`). Requests coalesce: a run starts only once no newer request has come for
`delay_s` (a slider being dragged asks many times), while a run is under way only the newest request is kept,
and a result that a newer request has made stale is dropped, so the plots always end on the latest setup. A run
that a newer request supersedes, or that `cancel()` stops, ends at its next chunk of trials
(`ExplorerSession.monte_carlo(should_stop=...)` raises `errors.Cancelled`), so slow setups (gp, clustering:
seconds) neither pile up nor keep a core busy for work nobody will see. Pass a snapshot (`copy.copy(session)`: settings and layout are immutable values, so a
shallow copy is a consistent picture) so the live session can keep changing while the worker runs.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable

from rrbc_core.errors import Cancelled, InputError
from rrbc_core.session import figures

from .drag_queue import drags_waiting
from .worker import CoalescingWorker

ResultCallback = Callable[[object, str | None, float], None]  # (MonteCarloPlots | None, error message, seconds)


class MonteCarloRunner:
    def __init__(self, on_result: ResultCallback, on_start: Callable[[], None] | None = None, delay_s: float = 0.3):
        self._on_result = on_result
        self._on_start = on_start
        self._worker = CoalescingWorker(self._run, delay_s, name="rrbc-monte-carlo")
        self._worker.start()

    def request(self, session, trials: int, seed: int | None = None) -> int:
        """Queue a run on `session` (a snapshot) with the noise seeded by `seed` (None: the session's seed, so the
        same setup gives the same plots); returns the request's generation number."""
        return self._worker.submit((session, int(trials), seed), supersede=True)

    def cancel(self) -> None:
        """Forget queued work and stop a running one at its next chunk of trials (the Stop button; the source
        changed)."""
        self._worker.cancel()

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until every request so far has finished (tests, scripts). True if idle in time."""
        return self._worker.wait_idle(timeout)

    @property
    def busy(self) -> bool:
        return self._worker.busy

    def stop(self) -> None:
        self._worker.stop()

    def _run(self, job, fresh: Callable[[], bool]) -> None:
        session, trials, seed = job
        if self._on_start is not None:
            try:
                self._on_start()
            except Exception:  # noqa: BLE001 - a display hiccup must not kill the worker
                traceback.print_exc()
        start = time.perf_counter()
        plots, error = None, None
        try:
            plots = figures.monte_carlo(session, trials=trials, seed=seed, should_stop=lambda: _between_chunks(fresh))
        except Cancelled:
            return  # stopped or superseded: whoever stopped it says so
        except InputError as exc:
            error = " ".join(str(exc).split())
        except Exception as exc:  # noqa: BLE001 - report, keep the worker alive
            traceback.print_exc()
            error = f"internal error: {type(exc).__name__}: {exc}"
        seconds = time.perf_counter() - start
        if fresh():
            try:
                self._on_result(plots, error, seconds)
            except Exception:  # noqa: BLE001
                traceback.print_exc()


def _between_chunks(fresh: Callable[[], bool]) -> bool:
    """Between two chunks of trials: wait while any session's drags are being handled (a drag is what a user
    watches; the plots can come a moment later), then say whether to stop (superseded or cancelled)."""
    while drags_waiting() and fresh():
        time.sleep(0.05)
    return not fresh()
