"""The thread policy's figures (docs/threads.md): rrbc's one BLAS thread against OpenBLAS's default pool (one
thread per core), where a larger pool could help (the large batched Monte Carlo) and where it hurts (planning with
a busy core beside it). The library's own limit is widened for the comparison by setting threads.THREADS, which
`threads.limited()` reads at each call.
"""

from __future__ import annotations

import os

import numpy as np
from harness import best_time, both, busy_core, median_time, row
from montecarlo import batched, work_cell


def mc_blas_threads(quick: bool) -> list[dict]:
    """Does a larger BLAS pool help the large batched Monte Carlo? The same `batched` run (20 000 trials) with
    rrbc's policy (threads.THREADS BLAS threads) and with one BLAS thread per core (threadpoolctl). ratio > 1
    means the policy is faster. The figure behind docs/threads.md's choice."""
    from threadpoolctl import threadpool_limits

    from rrbc_core.runtime import threads

    cores = os.cpu_count() or 1
    if cores <= threads.THREADS:
        return []
    n, chunk = (4000, 2000) if quick else (20_000, 2000)
    c = work_cell(np.random.default_rng(5), n)
    policy = threads.THREADS

    def timed(pool: int) -> float:
        threads.THREADS = pool  # what the library's own limit sets while a call runs
        try:
            with threadpool_limits(pool):
                batched(c, chunk, chunk)
                return best_time(lambda: batched(c, n, chunk))[0]
        finally:
            threads.THREADS = policy

    t_pool, t_one = timed(cores), timed(policy)
    note = (
        f"batch.rrbc_batch least-squares + IDW, {n} trials in chunks of {chunk}; value: {threads.THREADS} BLAS "
        f"thread(s) (rrbc's policy), baseline: {cores} (one per core); best of 3"
    )
    return [row("mc_blas_threads", n / t_one, "trials/s", baseline=n / t_pool, higher_is_better=True, note=note)]


def blas_pool_when_busy(quick: bool) -> list[dict]:
    """What the thread policy is for: `planning.plan(demo, add=4)` (the work behind `rrbc plan --add 4` and the
    Suggest button) with rrbc's policy (threads.THREADS BLAS threads) and with OpenBLAS's default pool (one
    thread per core), on an idle machine and with a busy core beside it. value/loaded: the policy; baseline:
    the default pool with the busy core; ratio: baseline / loaded (how much the policy saves a loaded user)."""
    from threadpoolctl import threadpool_limits

    from rrbc_core.analysis import planning
    from rrbc_core.io.scene import default_scene_path
    from rrbc_core.io.scene_toml import load_scene
    from rrbc_core.runtime import threads

    cores = os.cpu_count() or 1
    if cores <= threads.THREADS:
        return []
    scene = load_scene(default_scene_path())
    planning.plan(scene, 1)  # warm-up
    policy = threads.THREADS
    repeats = 1 if quick else 3

    def timed(pool: int) -> float:
        threads.THREADS = pool
        try:
            with threadpool_limits(pool):
                return median_time(lambda: planning.plan(scene, 4), repeats)[0]
        finally:
            threads.THREADS = policy

    idle, loaded = both(lambda: timed(policy))
    with busy_core():
        pool_loaded = timed(cores)
    r = row(
        "blas_pool_plan_busy",
        idle,
        "s",
        loaded=loaded,
        baseline=pool_loaded,
        note=f"planning.plan(demo, add=4), median of {repeats}; value/loaded: {policy} BLAS thread(s) (the "
        f"policy), baseline: {cores} (OpenBLAS's default) with a busy core beside it; ratio: baseline / "
        "loaded",
    )
    r["ratio"] = pool_loaded / loaded
    return [r]
