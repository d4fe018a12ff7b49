"""Independent tasks of a study, run in this process, on a local dask cluster or on an existing one (issue 18).

`run_tasks(fn, tasks, scheduler=...)` calls ``fn(task)`` for every task and returns the results **in task order**,
wherever they ran, so a reduction over them is the same on one process and on a cluster. Every task carries its own
randomness (`spawn_seeds`: `numpy.random.SeedSequence` children), never a generator shared between tasks: the
numbers cannot depend on which worker ran what, or in which order.

Where the tasks run (`scheduler`, else the environment variable ``RRBC_SCHEDULER``, else automatically):

- not given — automatic: a study whose caller estimates it at `AUTO_LOCAL_SECONDS` or more of one core's work, on a
  machine with more than one core, gets a local cluster; anything smaller runs in this process (a cluster's start
  costs a few seconds);
- ``""`` / ``"in-process"`` — one after the other in this process (no dask at all);
- ``"local"`` — a `distributed.LocalCluster` sized to the machine (one single-threaded worker process per core);
  ``"local:N"`` — one with N workers;
- an address such as ``tcp://10.0.0.5:8786`` — an existing scheduler (`dask scheduler` with `dask worker`s, or any
  deployment dask supports). Unreachable: one clear `InputError`.

A study with several stages holds one cluster for all of them (`task_runner`). Every task runs with rrbc's thread
policy (one BLAS thread, `runtime.threads.limited`), on a worker as in this process. Tasks are submitted with retries, so a worker that dies mid-task costs a rerun, not the study; a task that fails
again and again fails the run (nothing is written: the commands write their outputs only after `run_tasks`
returns). `progress(n)` is called as tasks finish.
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable, Sequence

import numpy as np

from rrbc_core.errors import InputError

SCHEDULER_ENV = "RRBC_SCHEDULER"
IN_PROCESS = ("", "in-process")
RETRIES = 3
CONNECT_TIMEOUT_S = 10
#: A job estimated at this many seconds of one core's work or more gets a local cluster when no scheduler is named
#: (below it, a cluster's start-up, ~3 s measured by benchmarks/reproduce_speed.py, is not worth paying).
AUTO_LOCAL_SECONDS = 60.0


def spawn_seeds(seed: int, n: int) -> list[np.random.SeedSequence]:
    """`n` independent seed sequences for `n` tasks of a study seeded by `seed` (the same for any cluster)."""
    return np.random.SeedSequence(int(seed)).spawn(int(n))


def scheduler_from(arg: str | None, estimate_s: float | None = None) -> str:
    """The scheduler a command uses: its `--scheduler` value, else $RRBC_SCHEDULER, else "local" for a job of at
    least AUTO_LOCAL_SECONDS of one core's work (`estimate_s`) on a machine with more than one core, else
    in-process ("")."""
    value = arg if arg is not None else os.environ.get(SCHEDULER_ENV)
    if value is not None:
        return str(value).strip()
    if estimate_s is not None and estimate_s >= AUTO_LOCAL_SECONDS and (os.cpu_count() or 1) > 1:
        return "local"
    return ""


def task_runner(scheduler: str | None = None, estimate_s: float | None = None, log: list | None = None) -> TaskRunner:
    """A `TaskRunner` for one study (use as a context manager): where `scheduler` says, else $RRBC_SCHEDULER, else
    automatically from the caller's estimate of one core's work in seconds (module docstring). `log`: a list that
    receives each call's task seconds when the tasks run in this process."""
    where = scheduler_from(scheduler, estimate_s)
    return TaskRunner(where, log)


def run_tasks(
    fn: Callable,
    tasks: Sequence,
    scheduler: str | None = None,
    progress: Callable[[int], object] | None = None,
    estimate_s: float | None = None,
) -> list:
    """``[fn(t) for t in tasks]``, run where `scheduler` says (module docstring), results in task order."""
    with task_runner(scheduler, estimate_s) as run:
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
        if self.where not in IN_PROCESS:
            self._client, self._cluster = _connect(self.where)
        return self

    def __exit__(self, *exc) -> None:
        if self._client is not None:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()
        self._client = self._cluster = None

    @property
    def workers(self) -> int:
        if self._client is None:
            return 1
        return max(1, len(self._client.scheduler_info().get("workers", {})))

    def __call__(self, fn: Callable, tasks: Sequence, progress: Callable[[int], object] | None = None) -> list:
        tasks = list(tasks)
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
        except (OSError, TimeoutError) as exc:
            raise InputError(
                f"the dask scheduler {self.where!r} was lost during the run ({type(exc).__name__})"
            ) from None


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
    if where == "local" or where.startswith("local:"):
        workers = max(1, os.cpu_count() or 1)
        if where != "local":
            count = where.split(":", 1)[1]
            if not count.isdigit() or not 1 <= int(count) <= 4 * workers:
                raise InputError(f"--scheduler {where[:40]!r}: local:N takes N from 1 to {4 * workers} workers")
            workers = int(count)
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0", silence_logs=50
        )
        return Client(cluster), cluster
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
