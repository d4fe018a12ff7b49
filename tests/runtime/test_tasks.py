"""Independent tasks on one process or a dask cluster (`runtime.tasks`, issue 18): the same numbers wherever they
run. A real scheduler and two workers are started as separate processes on 127.0.0.1."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.runtime.tasks import run_tasks, spawn_seeds
from tests.paths import ROOT, RRBC
from tests.support.cli_run import rrbc

DASK = str(Path(sys.executable).with_name("dask"))


def _slow_square(x: int) -> int:
    time.sleep(0.4)
    return x * x


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start(workers: int) -> tuple[str, list, list]:
    """A `dask scheduler` and `workers` single-threaded `dask worker`s, each its own process group."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    logs = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT, env=env, start_new_session=True)
    procs = [
        subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], **logs)
    ]
    from distributed import Client

    deadline = time.time() + 60
    while True:
        try:
            with Client(address, timeout=2):
                break
        except OSError:
            if time.time() > deadline:
                raise
            time.sleep(0.5)
    started = [
        subprocess.Popen([DASK, "worker", address, "--nthreads", "1", "--no-dashboard"], **logs) for _ in range(workers)
    ]
    with Client(address, timeout=10) as c:
        c.wait_for_workers(workers, timeout=60)
    return address, procs, started


def _stop(procs) -> None:
    for p in procs:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGTERM)
    for p in procs:
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)


@pytest.fixture(scope="module")
def cluster():
    """A `dask scheduler` and two single-threaded `dask worker`s, each its own process."""
    address, procs, workers = _start(2)
    yield address, workers
    _stop(procs + workers)


def test_in_process_keeps_order_and_reports_progress():
    seen = []
    assert run_tasks(lambda x: x + 1, [3, 1, 2], progress=seen.append) == [4, 2, 3] and seen == [1, 1, 1]
    a, b = spawn_seeds(5, 2), spawn_seeds(5, 2)
    assert [s.generate_state(2).tolist() for s in a] == [s.generate_state(2).tolist() for s in b]
    assert a[0].generate_state(2).tolist() != a[1].generate_state(2).tolist()


def test_a_bad_or_unreachable_scheduler_is_one_clear_error(monkeypatch):
    from rrbc_core.runtime import tasks

    monkeypatch.setattr(tasks, "CONNECT_TIMEOUT_S", 2)  # the refusal is the same; the wait for it shorter
    with pytest.raises(InputError, match="give 'local' or a scheduler address"):
        run_tasks(abs, [1, 2], scheduler="bogus")
    with pytest.raises(InputError, match="cannot reach the dask scheduler at .* within 2 s"):
        run_tasks(abs, [1, 2], scheduler=f"tcp://127.0.0.1:{_free_port()}")


def test_monte_carlo_gives_the_same_numbers_on_a_cluster(cluster):
    from rrbc_core.io.scene import default_scene_path
    from rrbc_core.io.scene_toml import load_scene
    from rrbc_core.simulation.montecarlo import monte_carlo, work_cell_from_scene

    address, _ = cluster
    cell = work_cell_from_scene(load_scene(default_scene_path()), seed=2)
    here = monte_carlo(cell, 90, seed=2, chunk=30, strategies=("least-squares",), interpolations=("idw", "none"))
    there = monte_carlo(
        cell, 90, seed=2, chunk=30, strategies=("least-squares",), interpolations=("idw", "none"), scheduler=address
    )
    assert here.to_json() == there.to_json()


@pytest.mark.slow
def test_rrbc_simulate_prints_the_same_bytes_with_and_without_a_scheduler(cluster, monkeypatch):
    """The command run here (`rrbc_core.cli.main` in this process, as the console script runs it), on the cluster
    by --scheduler and by RRBC_SCHEDULER: the same output."""
    address, _ = cluster
    args = ["simulate", ROOT / "scenes" / "demo_workcell.toml", "--trials", "20", "--json"]
    monkeypatch.delenv("RRBC_SCHEDULER", raising=False)
    local = rrbc(*args)
    remote = rrbc(*args, "--scheduler", address)
    assert local.returncode == 0 and remote.returncode == 0, remote.stderr
    assert local.stdout == remote.stdout
    monkeypatch.setenv("RRBC_SCHEDULER", address)
    assert rrbc(*args).stdout == local.stdout


@pytest.mark.slow
def test_rrbc_reproduce_prints_the_same_bytes_with_and_without_a_scheduler(cluster, monkeypatch):
    """Both studies, small sizes, every stage (the simulations and assessments; the crpi candidates and joint fits;
    the confusion tables in the next test) on two separate workers against one process (the command run in this
    process, `rrbc_core.cli.main`)."""
    address, _ = cluster
    monkeypatch.delenv("RRBC_SCHEDULER", raising=False)
    for args in (
        ["reproduce", "vanwyk2018", "--replicates", "5", "--layouts", "A", "--no-confusion", "--json"],
        ["reproduce", "crpi", "--replicates", "10", "--joint-replicates", "20", "--json"],
    ):
        here = rrbc(*args, "--scheduler", "in-process")
        there = rrbc(*args, "--scheduler", address)
        assert here.returncode == 0 and there.returncode == 0, there.stderr
        assert here.stdout == there.stdout and '"replicates"' in here.stdout


@pytest.mark.slow
def test_the_confusion_tables_are_the_same_on_a_cluster(cluster):
    from rrbc_core.studies import model_fit, reproduction, vanwyk2018

    address, _ = cluster
    sims = [("A", m.name, 5, 0) for m in reproduction.MODELS]
    moments = {t[1]: model_fit.Moments.of(d) for t, d in zip(sims, run_tasks(vanwyk2018.simulate_task, sims, address))}
    # two planted models' tables (the first and the last), one per worker: each task is the same code for every
    # model, and every table is computed here as well
    jobs = [("A", i, 1, 0) for i in (0, len(reproduction.MODELS) - 1)]
    tables = run_tasks(vanwyk2018._confusion_tables_task, jobs, address)
    assert [t[0].tolist() for t in tables] == [
        t[0].tolist() for t in run_tasks(vanwyk2018._confusion_tables_task, jobs)
    ]
    choose = [(moments, t[0]) for t in tables]  # two tasks, one per worker (each ~1 s of fits)
    here = run_tasks(vanwyk2018.choose_task, choose, "in-process")
    assert run_tasks(vanwyk2018.choose_task, choose, address) == here
    assert set(here) <= {m.name for m in reproduction.MODELS}


def _nap(seconds: float) -> float:
    time.sleep(seconds)
    return seconds


def test_auto_keeps_short_work_here_and_sends_long_work_to_a_local_cluster(monkeypatch):
    """Under "auto" (the commands' default) the first task is timed here; the rest go to a local cluster only if
    they would take AUTO_LOCAL_SECONDS or more at that pace (lowered here), and on one core never."""
    from rrbc_core.runtime import tasks

    monkeypatch.delenv(tasks.SCHEDULER_ENV, raising=False)
    assert tasks.command_scheduler(None) == "auto" and tasks.scheduler_from(None) == ""
    assert tasks.command_scheduler("in-process") == "in-process"
    monkeypatch.setenv(tasks.SCHEDULER_ENV, "tcp://10.0.0.5:8786")
    assert tasks.command_scheduler(None) == "tcp://10.0.0.5:8786"
    monkeypatch.delenv(tasks.SCHEDULER_ENV)

    monkeypatch.setattr(tasks, "AUTO_LOCAL_SECONDS", 0.5)
    with tasks.task_runner("auto") as run:
        assert run(_nap, [0.01] * 3) == [0.01] * 3
        assert run.where == "" and run.workers == 1
    monkeypatch.setattr(tasks.os, "cpu_count", lambda: 2)
    with tasks.task_runner("auto") as run:
        seen = []
        assert run(_nap, [0.3] * 4, seen.append) == [0.3] * 4 and seen == [1] * 4
        assert run.where == "local" and run.workers == 2
        assert run(abs, [-1, -2]) == [1, 2]  # later stages use the same cluster
    monkeypatch.setattr(tasks.os, "cpu_count", lambda: 1)
    with tasks.task_runner("auto") as run:
        assert run(_nap, [0.3] * 4) == [0.3] * 4 and run.where == ""


def test_a_local_cluster_of_n_workers_and_a_bad_n():
    with pytest.raises(InputError, match="local:N takes N from 1"):
        run_tasks(abs, [1, 2], scheduler="local:0")
    with pytest.raises(InputError, match="local:N takes N from 1"):
        run_tasks(abs, [1, 2], scheduler="local:x")
    assert run_tasks(abs, [-1, 2, -3], scheduler="local:1") == [1, 2, 3]


@pytest.mark.slow
def test_a_worker_killed_mid_run_is_survived(cluster):
    """Eight 0.4 s tasks on two workers; one worker is killed after the first results: the other finishes every
    task (the scheduler reruns the lost ones) and the results come back complete and in order."""
    address, workers = cluster
    done = []

    def progress(n):
        done.append(n)
        if len(done) == 2:
            os.killpg(workers[0].pid, signal.SIGKILL)

    out = run_tasks(_slow_square, list(range(8)), scheduler=address, progress=progress)
    assert out == [x * x for x in range(8)]
    assert workers[0].wait(10) is not None
    assert np.all(np.diff(out) > 0)


@pytest.mark.slow
def test_a_scheduler_lost_mid_run_is_one_line_and_exit_2():
    """The scheduler is killed while `rrbc simulate` waits on it: one stderr line naming the loss, exit 2, no
    output (the client gives up after its reconnect timeout)."""
    address, procs, workers = _start(1)
    try:
        env = {k: v for k, v in os.environ.items() if k != "RRBC_SCHEDULER"}
        args = [*RRBC, "simulate", str(ROOT / "scenes" / "demo_workcell.toml"), "--trials", "40000", "--json"]
        run = subprocess.Popen([*args, "--scheduler", address], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
        from distributed import Client

        with Client(address, timeout=10) as watch:  # wait until the run's tasks are on the scheduler
            deadline = time.time() + 120
            while not watch.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)):
                assert run.poll() is None and time.time() < deadline, "the run never sent its tasks"
                time.sleep(0.1)
        assert run.poll() is None, "the run ended before the scheduler was killed"
        os.killpg(procs[0].pid, signal.SIGKILL)
        out, err = run.communicate(timeout=120)
        lines = err.decode().strip().splitlines()
        assert run.returncode == 2 and out == b""
        assert len(lines) == 1 and "was lost during the run" in lines[0], lines
    finally:
        _stop(procs + workers)
