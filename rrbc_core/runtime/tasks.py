"""Independent tasks of a study, run in this process, on a local dask cluster or on an existing one (issue 18).

`run_tasks(fn, tasks, scheduler=...)` calls ``fn(task)`` for every task and returns the results **in task order**,
wherever they ran, so a reduction over them is the same on one process and on a cluster. Every task carries its own
randomness (`spawn_seeds`: `numpy.random.SeedSequence` children), never a generator shared between tasks: the
numbers cannot depend on which worker ran what, or in which order.

Where the tasks run (`scheduler`, else the environment variable ``RRBC_SCHEDULER``, else in this process):

- ``""`` / ``"in-process"`` — one after the other in this process (no dask at all);
- ``"auto"`` — the commands' default (`command_scheduler`): the first task runs in this process and is timed; if
  the rest would take `AUTO_LOCAL_SECONDS` or more of one core at that pace, on a machine with more than one core,
  they go to a local cluster, else they stay here (a cluster takes about a second to start and stop). Library calls
  do not start processes unless asked;
- ``"local"`` — a `distributed.LocalCluster` sized to the machine (one single-threaded worker process per core);
  ``"local:N"`` — one with N workers;
- an address such as ``tcp://10.0.0.5:8786`` — an existing scheduler (`dask scheduler` with `dask worker`s, or any
  deployment dask supports). Unreachable: one clear `InputError`.

A study with several stages holds one cluster for all of them (`task_runner`). Every task runs with rrbc's thread
policy (one BLAS thread, `runtime.threads.limited`), on a worker as in this process. Tasks are submitted with
retries, so a worker that dies mid-task costs a rerun, not the study; a task that fails again and again fails the
run (nothing is written: the commands write their outputs only after their tasks return). `progress(n)` is called
as tasks finish.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import CancelledError

import numpy as np

from rrbc_core.errors import InputError

SCHEDULER_ENV = "RRBC_SCHEDULER"
IN_PROCESS = ("", "in-process")
RETRIES = 3
CONNECT_TIMEOUT_S = 10
#: seconds a new local cluster waits for all its workers to register before its first task
LOCAL_WORKERS_TIMEOUT_S = 60
AUTO = "auto"
_quiet = False  # set by quiet_dask_logs()
#: Under "auto", work measured at this many seconds of one core or more gets a local cluster (below it, a cluster's
#: start and stop, measured by benchmarks/reproduce_speed.py `cluster_costs`, is not worth paying).
AUTO_LOCAL_SECONDS = 60.0


def spawn_seeds(seed: int, n: int) -> list[np.random.SeedSequence]:
    """`n` independent seed sequences for `n` tasks of a study seeded by `seed` (the same for any cluster)."""
    return np.random.SeedSequence(int(seed)).spawn(int(n))


def scheduler_from(arg: str | None) -> str:
    """The scheduler a library call uses: `arg`, else $RRBC_SCHEDULER, else in this process ("")."""
    value = arg if arg is not None else os.environ.get(SCHEDULER_ENV, "")
    return str(value).strip()


def command_scheduler(arg: str | None) -> str:
    """The scheduler a command or study script uses: its --scheduler value, else $RRBC_SCHEDULER, else "auto"."""
    return scheduler_from(arg if arg is not None else os.environ.get(SCHEDULER_ENV, AUTO))


def task_runner(scheduler: str | None = None, log: list | None = None) -> TaskRunner:
    """A `TaskRunner` for one study (use as a context manager): where `scheduler` says, else $RRBC_SCHEDULER, else
    in this process (module docstring). `log`: a list that receives each call's task seconds when the tasks run in
    this process."""
    return TaskRunner(scheduler_from(scheduler), log)


def run_tasks(
    fn: Callable,
    tasks: Sequence,
    scheduler: str | None = None,
    progress: Callable[[int], object] | None = None,
) -> list:
    """``[fn(t) for t in tasks]``, run where `scheduler` says (module docstring), results in task order."""
    with task_runner(scheduler) as run:
        return run(fn, tasks, progress)


class TaskRunner:
    """Runs lists of tasks in this process or on one dask cluster, held open for the runner's life.

    ``with task_runner(...) as run: a = run(fn, tasks); b = run(gn, more)`` — each call returns ``[fn(t) ...]`` in
    task order. `where` is "" (in this process), "local" or a scheduler address; `workers` the cluster's size
    (1 in this process)."""

    def __init__(self, where: str, log: list | None = None):
        self.where = where
        self.log = log  # in this process: one list of task seconds appended per call (benchmarks' task sizes)
        self._client = None
        self._cluster = None

    def __enter__(self) -> TaskRunner:
        if self.where not in IN_PROCESS and self.where != AUTO:
            self._client, self._cluster = _connect(self.where)
        return self

    def __exit__(self, *exc) -> None:
        try:
            if self._client is not None:
                self._client.close()
            if self._cluster is not None:
                self._cluster.close()
        finally:
            self._client = self._cluster = None

    @property
    def workers(self) -> int:
        if self._client is None:
            return 1
        return max(1, len(self._client.scheduler_info().get("workers", {})))

    def __call__(self, fn: Callable, tasks: Sequence, progress: Callable[[int], object] | None = None) -> list:
        tasks = list(tasks)
        if self.where == AUTO and tasks:
            return self._first_then_decide(fn, tasks, progress)
        if self._client is None or not tasks:
            out, seconds = [], []
            for t in tasks:
                t0 = time.perf_counter()
                out.append(fn(t))
                seconds.append(time.perf_counter() - t0)
                if progress is not None:
                    progress(1)
            if self.log is not None:
                self.log.append(seconds)
            return out
        from distributed import as_completed

        try:
            futures = self._client.map(functools.partial(_limited_call, fn), tasks, pure=False, retries=RETRIES)
            index = {f.key: k for k, f in enumerate(futures)}
            results: list = [None] * len(futures)
            for fut in as_completed(futures):
                results[index[fut.key]] = fut.result()
                if progress is not None:
                    progress(1)
            return results
        except (OSError, TimeoutError, CancelledError) as exc:
            raise InputError(
                f"the dask scheduler {self.where!r} was lost during the run ({type(exc).__name__}); nothing was "
                "written: rerun when it is back, or drop --scheduler"
            ) from None

    def _first_then_decide(self, fn: Callable, tasks: list, progress) -> list:
        """Under "auto": run the first task here, timed; the rest on a local cluster if they would take
        AUTO_LOCAL_SECONDS or more at that pace (and there is more than one core), else here. Decided once."""
        t0 = time.perf_counter()
        first = fn(tasks[0])
        if progress is not None:
            progress(1)
        rest_s = (time.perf_counter() - t0) * (len(tasks) - 1)
        self.where = "local" if rest_s >= AUTO_LOCAL_SECONDS and (os.cpu_count() or 1) > 1 else ""
        if self.where == "local":
            self._client, self._cluster = _connect("local")
        elif self.log is not None:
            self.log.append([time.perf_counter() - t0])
        return [first] + self(fn, tasks[1:], progress)


def quiet_dask_logs() -> None:
    """For processes rrbc owns (the command line): dask's own log lines (a lost scheduler is logged at ERROR with a
    traceback before the run fails) never reach stderr; the failure is one `InputError` line instead. Library
    calls leave dask's logging as the caller configured it."""
    global _quiet
    _quiet = True


def _silence_dask() -> None:
    if _quiet:
        for name in list(logging.root.manager.loggerDict):
            if name == "distributed" or name.startswith("distributed."):
                logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def _limited_call(fn: Callable, task):
    """fn(task) under rrbc's thread policy (one BLAS thread while it runs), wherever it runs."""
    from rrbc_core.runtime.threads import limited

    with limited():
        return fn(task)


def _connect(where: str):
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - a pinned dependency
        raise InputError("dask.distributed is not installed: run scripts/setup.sh") from None
    _silence_dask()
    if where == "local" or where.startswith("local:"):
        workers = max(1, os.cpu_count() or 1)
        if where != "local":
            count = where.split(":", 1)[1]
            if not count.isdigit() or not 1 <= int(count) <= 4 * workers:
                raise InputError(f"--scheduler {where[:40]!r}: local:N takes N from 1 to {4 * workers} workers")
            workers = int(count)
        import dask

        # dask starts its workers with MALLOC_TRIM_THRESHOLD_=65536, which fixes glibc's mmap threshold low: every
        # large numpy temporary is then mapped and unmapped afresh (ad hoc: the layout-A simulations of `reproduce
        # vanwyk2018` took 46 s in one process and 52 s with that variable set); our tasks free what they allocate,
        # so the workers keep glibc's default. The statistical profiler (a stack sample every 10 ms) is off too.
        environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
        environ.pop("MALLOC_TRIM_THRESHOLD_", None)
        settings = {"distributed.nanny.pre-spawn-environ": environ, "distributed.worker.profile.enabled": False}
        with dask.config.set(settings):
            cluster = LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0", silence_logs=50
            )
        client = Client(cluster)
        # the cluster's workers register with its scheduler on their own; on a loaded machine one can come after the
        # first tasks (then only the others work, and `workers` says so): wait for all of them, within a bound
        with contextlib.suppress(TimeoutError, OSError):
            client.wait_for_workers(workers, timeout=LOCAL_WORKERS_TIMEOUT_S)
        return client, cluster
    if "://" not in where and ":" not in where:
        raise InputError(
            f"--scheduler {where[:60]!r}: give 'local' or a scheduler address such as tcp://127.0.0.1:8786"
        )
    try:
        return Client(where, timeout=CONNECT_TIMEOUT_S), None
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(
            f"cannot reach the dask scheduler at {where[:80]!r} within {CONNECT_TIMEOUT_S} s ({type(exc).__name__}); "
            "start one with `dask scheduler` and `dask worker ADDRESS`, or drop --scheduler"
        ) from None
