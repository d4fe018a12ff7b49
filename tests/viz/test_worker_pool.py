"""The server's callback threads end when idle (issue 42, item 5: no threads kept after a class):
`rrbc_viz.worker_pool.RetiringExecutor` runs tasks as viser's ThreadPoolExecutor does (results, exceptions, a
thread per task while none is idle, at most `max_workers`) and its idle threads end."""

from __future__ import annotations

import threading
import time

import pytest

from rrbc_viz.worker_pool import RetiringExecutor


def _until(cond, timeout: float = 10.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


def test_tasks_run_in_parallel_give_results_and_errors_and_idle_threads_end():
    pool = RetiringExecutor(max_workers=4, idle_s=0.3)
    gate = threading.Event()
    started = []

    def wait(k):
        started.append(k)
        gate.wait(5)
        return k * k

    futures = [pool.submit(wait, k) for k in range(6)]
    assert _until(lambda: len(started) == 4)  # four at once: the limit
    assert pool.threads == 4
    gate.set()
    assert [f.result(5) for f in futures] == [k * k for k in range(6)]
    failing = pool.submit(lambda: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        failing.result(5)
    assert _until(lambda: pool.threads == 0)  # idle: every thread ended
    assert pool.submit(lambda: "again").result(5) == "again"  # and a new one starts for the next task
    pool.shutdown(wait=True)
    assert pool.threads == 0
    with pytest.raises(RuntimeError):
        pool.submit(lambda: None)


def test_a_burst_of_short_tasks_keeps_no_thread_and_loses_no_task():
    pool = RetiringExecutor(max_workers=8, idle_s=0.05)
    done = []
    for round_ in range(20):  # tasks arriving while threads are timing out
        futures = [pool.submit(done.append, (round_, k)) for k in range(10)]
        for f in futures:
            f.result(5)
        time.sleep(0.04 if round_ % 2 else 0.06)
    assert len(done) == 200
    assert _until(lambda: pool.threads == 0)
    pool.shutdown()
