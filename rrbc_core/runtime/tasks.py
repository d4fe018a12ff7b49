"""Independent tasks of a study, run in this process, on a local dask cluster or on an existing one (issue 18).

`run_tasks(fn, tasks, scheduler=...)` calls ``fn(task)`` for every task and returns the results **in task order**,
wherever they ran, so a reduction over them is the same on one process and on a cluster. Every task carries its own
randomness (`spawn_seeds`: `numpy.random.SeedSequence` children), never a generator shared between tasks: the
numbers cannot depend on which worker ran what, or in which order.

Where the tasks run (`scheduler`, else the environment variable ``RRBC_SCHEDULER``, else in this process):

- ``None`` / ``""`` / ``"in-process"`` — one after the other in this process (no dask at all);
- ``"local"`` — a `distributed.LocalCluster` sized to the machine (one single-threaded worker process per core);
- an address such as ``tcp://10.0.0.5:8786`` — an existing scheduler (`dask scheduler` with `dask worker`s, or any
  deployment dask supports). Unreachable: one clear `InputError`.

Tasks are submitted with retries, so a worker that dies mid-task costs a rerun, not the study; a task that fails
again and again fails the run (nothing is written: the commands write their outputs only after `run_tasks`
returns). `progress(n)` is called as tasks finish.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence

import numpy as np

from rrbc_core.errors import InputError

SCHEDULER_ENV = "RRBC_SCHEDULER"
IN_PROCESS = ("", "in-process")
RETRIES = 3
CONNECT_TIMEOUT_S = 10


def spawn_seeds(seed: int, n: int) -> list[np.random.SeedSequence]:
    """`n` independent seed sequences for `n` tasks of a study seeded by `seed` (the same for any cluster)."""
    return np.random.SeedSequence(int(seed)).spawn(int(n))


def scheduler_from(arg: str | None) -> str:
    """The scheduler a command uses: its `--scheduler` value, else $RRBC_SCHEDULER, else in-process ("")."""
    value = arg if arg is not None else os.environ.get(SCHEDULER_ENV, "")
    return str(value).strip()


def run_tasks(
    fn: Callable, tasks: Sequence, scheduler: str | None = None, progress: Callable[[int], object] | None = None
) -> list:
    """``[fn(t) for t in tasks]``, run where `scheduler` says (module docstring), results in task order."""
    where = scheduler_from(scheduler)
    if where in IN_PROCESS or len(tasks) == 0:
        out = []
        for t in tasks:
            out.append(fn(t))
            if progress is not None:
                progress(1)
        return out
    client, cluster = _connect(where)
    try:
        from distributed import as_completed

        futures = client.map(fn, list(tasks), pure=False, retries=RETRIES)
        index = {f.key: k for k, f in enumerate(futures)}
        results: list = [None] * len(futures)
        for fut in as_completed(futures):
            results[index[fut.key]] = fut.result()
            if progress is not None:
                progress(1)
        return results
    except (OSError, TimeoutError) as exc:
        raise InputError(f"the dask scheduler {where!r} was lost during the run ({type(exc).__name__})") from None
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _connect(where: str):
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - a pinned dependency
        raise InputError("dask.distributed is not installed: run scripts/setup.sh") from None
    if where == "local":
        workers = max(1, os.cpu_count() or 1)
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=50
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
