"""A class under load (issue 31, item 1), bounded: a few real websocket clients drag at once in the shared and the
per-client mode. Every client keeps receiving frames while it drags, nothing is left queued once the drags end,
and a click then is answered at once. The goal figures (20 clients, every client a frame at least every 0.5 s, a
click answered within 1 s) are measured by benchmarks/class_load.py; the bounds here are four times the goals, for
a loaded test machine."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from class_load import CLICK_GOAL_S, GAP_GOAL_S, class_run


@pytest.mark.slow
@pytest.mark.parametrize("per_client,clients", [(False, 6), (True, 4)], ids=["shared", "per-client"])
def test_every_dragging_client_keeps_moving_and_a_click_after_is_answered(per_client, clients, monkeypatch):
    from rrbc_viz import worker_pool

    # callback threads retire after 1 s idle instead of 5 s: the run waits twice for them to retire (the count after
    # one tab and after the class), and what is tested is that they do, not how soon
    monkeypatch.setattr(worker_pool, "IDLE_S", 1.0)
    res = class_run(per_client, clients=clients, seconds=4.0)
    assert len(res["gaps_s"]) == clients
    assert res["max_gap_s"] <= 4 * GAP_GOAL_S, res["gaps_s"]
    assert res["click_s"] is not None and res["click_s"] <= 4 * CLICK_GOAL_S, res
    # memory: the class's sessions and buffers are given back (against the server as started, module docstring of
    # benchmarks/class_load.py); a generous bound here, the benchmark holds the 30 % goal
    assert res["rss_after_mb"] <= 1.5 * res["rss_started_mb"], res
    # the threads the class started are gone again (issue 42, item 5; rrbc_viz.worker_pool), less the shared app's
    # own workers started when first needed (on a loaded machine a slow planning update starts the Plan tab's)
    assert not res["threads_left"], (res["thread_names_after"], res["threads_left_stacks"])
