"""`rrbc reproduce vanwyk2018` at its default size: today's code against the code before issue 18, and on 1 and 2
dask workers, measured in one run (issue 18, items 4 and 5).

Every run is a fresh process with the caller's environment minus thread variables (`harness.run_command`):

1. **before** — the tree of BASELINE_COMMIT (the last commit before the speed-up), extracted with `git archive`
   into a temporary folder and run as its own `rrbc reproduce vanwyk2018 --json` (the import is checked to come
   from that folder);
2. **now, in this process** — the call the command makes (`vanwyk2018.run`, in-process, rrbc's thread policy), which
   also logs every task's seconds (`task_log`);
3. **now, 1 and 2 workers** — `rrbc reproduce vanwyk2018 --json --scheduler local:1` and `local:2`.

Checks, each raising if it fails (a speed-up with other numbers would not count): 1 and 2 give the same JSON (the
old output's wall-time field aside; floats compared exactly); 3's two outputs are byte-identical and equal to 2's.

The scaling table: stages of independent tasks (their measured seconds, from 2) are placed on W workers longest
first (each task on the worker that frees first, which is how the scheduler hands out a ready list, to within its
heuristics), stage after stage; plus the serial part (in-process wall time − the tasks' sum), a local cluster's
start and stop, and a per-task overhead, both measured here with tasks that do nothing (`cluster_costs`). Moving
results between processes (a simulation's result is ~20 MB at the default size) is not in the model; the note
sets the model's 1- and 2-worker figures beside the measured ones, so the gap shows. The rows for more workers are
the model's prediction, not measurements, and say so.
"""

from __future__ import annotations

import heapq
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from harness import ROOT, RRBC, row, run_command

BASELINE_COMMIT = "20b9397ee43ae5e093db402cf08c37e77bed24df"
_OLD_CLI = (
    "import sys, rrbc_core; assert rrbc_core.__file__.startswith(sys.argv[1]), rrbc_core.__file__; "
    "from rrbc_core.cli import main; sys.exit(main(sys.argv[2:]))"
)
_NEW_CALL = (
    "import json, sys; from rrbc_core.runtime.threads import apply_process_policy; apply_process_policy(); "
    "from rrbc_core.studies import vanwyk2018; log = []; "
    "rep = vanwyk2018.run(replicates=int(sys.argv[1]), layout_names=sys.argv[2].split(','), "
    "scheduler='in-process', task_log=log); json.dump({'json': rep.to_json(), 'log': log}, sys.stdout)"
)


def makespan(stages: list[list[float]], workers: int) -> float:
    """Seconds to run each stage's tasks on `workers` (longest first onto the worker that frees first), stages one
    after the other."""
    total = 0.0
    for tasks in stages:
        free = [0.0] * workers
        for t in sorted(tasks, reverse=True):
            heapq.heappush(free, heapq.heappop(free) + t)
        total += max(free)
    return total


def cluster_costs(workers: int = 2, tasks: int = 200) -> tuple[float, float]:
    """(seconds to start and stop a local cluster of `workers` with its client, seconds of overhead per task):
    measured here with tasks that do nothing (submission, scheduling, a result's round trip)."""
    import time

    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0")
    client = Client(cluster)
    client.wait_for_workers(workers)
    started = time.perf_counter() - t0
    client.gather(client.map(abs, range(-10, 0), pure=False))  # warm
    t1 = time.perf_counter()
    client.gather(client.map(abs, range(-tasks, 0), pure=False))
    per_task = (time.perf_counter() - t1) * workers / tasks
    t2 = time.perf_counter()
    client.close()
    cluster.close()
    return started + time.perf_counter() - t2, per_task


def reproduce_speed(quick: bool) -> list[dict]:
    """Item 5: today's single-process run against BASELINE_COMMIT's (goal: at least 3x faster, same numbers).
    Item 4: 1 against 2 workers, and the modelled scaling for more."""
    replicates, layouts = (20, "A") if quick else (200, "A,B,C,D")
    size = ["--replicates", str(replicates), "--layouts", layouts]
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        base.mkdir()
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", BASELINE_COMMIT], check=True, capture_output=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(base)], input=archive, check=True)
        t_old, mb_old, out_old = run_command(
            [sys.executable, "-c", _OLD_CLI, str(base), "reproduce", "vanwyk2018", "--json", *size], 1, cwd=base
        )
    t_new, mb_new, out_new = run_command([sys.executable, "-c", _NEW_CALL, str(replicates), layouts], 1)
    new = json.loads(out_new)
    old = json.loads(out_old)
    old.pop("seconds", None)
    if old != new["json"]:
        differ = [k for k in old if old[k] != new["json"].get(k)]
        raise RuntimeError(f"the sped-up run changed the numbers: {differ}")
    walls, outs = {}, {}
    for w in (1, 2):
        walls[w], _, outs[w] = run_command(
            [RRBC, "reproduce", "vanwyk2018", "--json", *size, "--scheduler", f"local:{w}"], 1
        )
    if outs[1] != outs[2] or json.loads(outs[1]) != new["json"]:
        raise RuntimeError("the cluster runs do not print the in-process numbers")
    stages = new["log"]
    tasks_s = sum(map(sum, stages))
    serial = t_new - tasks_s
    start, overhead = cluster_costs()
    n = sum(map(len, stages))

    def model(w: int) -> float:
        return serial + start + makespan(stages, w) + overhead * n / w

    predicted = {w: model(w) for w in (4, 8, 16, 32, 64)}
    sizes = ", ".join(
        f"stage {k + 1}: {len(s)} tasks, {sum(s):.0f} s, longest {max(s):.1f} s" for k, s in enumerate(stages) if s
    )
    rows = [
        row(
            "reproduce_vs_before",
            t_new,
            "s",
            baseline=t_old,
            goal=">= 3x faster, same numbers",
            met=bool(t_old / t_new >= 3.0),
            note=f"`rrbc reproduce vanwyk2018 {' '.join(size)}` before ({BASELINE_COMMIT[:7]}, its own CLI, "
            f"{t_old:.0f} s, peak {mb_old:.0f} MB) and now in one process ({t_new:.0f} s, peak {mb_new:.0f} MB): "
            "the same JSON",
        ),
        row(
            "reproduce_2_workers",
            walls[2],
            "s",
            baseline=walls[1],
            note=f"--scheduler local:1 {walls[1]:.0f} s, local:2 {walls[2]:.0f} s (this machine has 2 cores), "
            "byte-identical JSON",
        ),
    ]
    for w, t in predicted.items():
        rows.append(
            row(
                f"reproduce_{w}_workers_modelled",
                t,
                "s",
                baseline=walls[1],
                note=f"MODELLED, not measured: serial {serial:.1f} s + cluster start and stop {start:.1f} s + the "
                f"measured tasks placed longest first on {w} workers + {overhead * 1e3:.1f} ms per task ({sizes}); "
                f"the same model gives {model(1):.0f} s for 1 worker and {model(2):.0f} s for 2 (measured: "
                f"{walls[1]:.0f} s and {walls[2]:.0f} s)"
                if w == 4
                else "",
            )
        )
    return rows
