"""One background thread that runs the newest of many requests once they stop coming (`CoalescingWorker`).

Both background jobs of the app follow this pattern: Monte Carlo (`montecarlo.MonteCarloRunner`) and the Plan
tab's planning during drags of a slow scene (`planning_panel.PlanningPanel.request_background`). Requests
coalesce: a job starts only once no newer request has come for `delay_s` (a slider or a drag asks many times),
only the newest pending request is kept, and a job that cannot be interrupted (the core has no cancellation)
learns on finishing whether its result is still wanted.

Staleness goes by generation numbers. Each request carries the generation current when it was queued;
`submit(job, supersede=True)` first starts a new generation (a result still being computed is then stale), and
`invalidate()` starts one without queueing anything (queued and running work becomes stale: it still runs, its
result is dropped). `cancel()` does that and forgets the queued job. The job function gets `fresh`, a zero-arg
callable that says, when called, whether its request is still current and the worker not stopped; the caller
decides what to hold while it checks and shows the result.
"""

from __future__ import annotations

import functools
import threading
import time
import traceback
from collections.abc import Callable

Job = Callable[[object, Callable[[], bool]], None]  # (the submitted job, fresh) -> None


class CoalescingWorker:
    def __init__(self, run: Job, delay_s: float, name: str):
        """`run(job, fresh)` is called in the worker thread for each job that starts (an exception it raises is
        printed; the worker goes on). The thread starts with `start()` or the first `submit`."""
        self._run = run
        self._delay_s = float(delay_s)
        self._name = name
        self._cond = threading.Condition()
        self._pending: tuple | None = None  # (generation, job)
        self._last_request = 0.0
        self._generation = 0
        self._done_generation = 0  # every request up to this generation has finished or was invalidated
        self._busy = False  # a job is running
        self._stopped = False
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Start the thread (once; later calls do nothing)."""
        with self._cond:
            if self._thread is None:
                self._thread = threading.Thread(target=self._loop, name=self._name, daemon=True)
                self._thread.start()

    def submit(self, job, supersede: bool = False) -> int:
        """Queue `job` in place of any queued one; returns its generation. supersede=True makes the result of a
        job running now stale (a new generation); otherwise that result is still shown."""
        with self._cond:
            if supersede:
                self._generation += 1
            waiting = self._pending is not None  # the worker is already counting down to it: no wake-up needed
            self._pending = (self._generation, job)
            self._last_request = time.monotonic()
            if not waiting:
                self._cond.notify_all()
            generation = self._generation
        self.start()
        return generation

    def invalidate(self) -> int:
        """Make queued and running work stale (it still runs; its result is not fresh). Returns the new generation."""
        with self._cond:
            unblocks = self._done_generation < self._generation  # only then can a wait_idle be waiting on it
            self._generation += 1
            self._done_generation = self._generation
            if unblocks:
                self._cond.notify_all()
            return self._generation

    def cancel(self) -> None:
        """Forget the queued job and make a running job's result stale."""
        with self._cond:
            self._pending = None
            self.invalidate()
            self._cond.notify_all()

    def current(self, generation: int) -> bool:
        """Whether a result of `generation` is still wanted: no newer generation and not stopped."""
        with self._cond:
            return generation == self._generation and not self._stopped

    def wait_idle(self, timeout: float) -> bool:
        """Block until nothing is queued or running and every generation so far has finished or was invalidated
        (a superseding request that stop() dropped never finishes). True if idle in time."""
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
        """A job is queued or running."""
        with self._cond:
            return self._busy or self._pending is not None

    def stop(self) -> None:
        """Drop the queued job and end the thread (after the running job, whose result is then stale)."""
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
                assert self._pending is not None  # the wait loop ends only with a pending job (or stopped)
                generation, job = self._pending
                self._pending = None
                self._busy = True
            try:
                self._run(job, functools.partial(self.current, generation))
            except Exception:  # noqa: BLE001 - report, keep the worker alive
                traceback.print_exc()
            finally:
                with self._cond:
                    self._busy = False
                    self._done_generation = max(self._done_generation, generation)
                    self._cond.notify_all()
