"""`syncing.LatestOnly`: a quickly moved control computes only its newest value (the Arm tab's tool sliders)."""

from __future__ import annotations

import threading
import time

from rrbc_viz.syncing import LatestOnly


def test_calls_while_one_runs_leave_only_the_newest_and_it_runs_last():
    seen: list[int] = []
    first_started, release = threading.Event(), threading.Event()

    def slow(value: int) -> None:
        if value == 0:
            first_started.set()
            release.wait(10)
        seen.append(value)

    latest = LatestOnly(slow)
    runner = threading.Thread(target=latest, args=(0,))
    runner.start()
    assert first_started.wait(10)
    t0 = time.perf_counter()
    for v in range(1, 40):  # arrive while 0 runs: each returns at once
        latest(v)
    assert time.perf_counter() - t0 < 1.0
    release.set()
    runner.join(10)
    assert seen == [0, 39]  # the first, then only the newest
    latest(40)  # nothing running: runs at once, in the caller's thread
    assert seen == [0, 39, 40]


def test_an_error_in_one_call_does_not_stop_the_next(capsys):
    seen: list[int] = []

    def f(v: int) -> None:
        if v == 1:
            raise ValueError("boom")
        seen.append(v)

    latest = LatestOnly(f)
    latest(1)
    latest(2)
    assert seen == [2] and "boom" in capsys.readouterr().err
