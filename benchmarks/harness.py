"""What every benchmark shares: timing, a busy core beside the timed code, subprocess runs of the real command,
and the row format.

Rows (one dict per measured quantity; `--json` prints each as one line):

| key        | meaning |
|------------|---------|
| `name`     | the row |
| `value`    | the quantity on an otherwise idle machine |
| `loaded`   | the same with one busy core beside it (`busy_core`), or null where the row is not interactive |
| `unit`     | `s`, `trials/s`, `MB` |
| `baseline` | the same quantity for the row's stated baseline, measured in the same run, or null (absolute goal) |
| `ratio`    | how many times better than the baseline (higher is better), or null |
| `goal`     | the goal, in words, or null |
| `met`      | whether the goal is met (on the loaded figure where there is one), or null |
| `note`     | what exactly was measured |

No thread variables are set anywhere: the timed code runs as a user's process does (rrbc sets its own BLAS pools,
docs/threads.md).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RRBC = str(Path(sys.executable).with_name("rrbc"))


def best_time(fn, repeats: int = 3) -> tuple[float, object]:
    """Best wall time (time.perf_counter, s) of `repeats` calls of fn(), and the last result."""
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def median_time(fn, repeats: int = 3) -> tuple[float, object]:
    """Median wall time (s) of `repeats` calls of fn(), and the last result."""
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


@contextmanager
def busy_core():
    """One other process spinning on a core for the duration of the block (a user's machine running something
    else: a browser, a compiler, another job). Started before and killed after the block."""
    spinner = subprocess.Popen(
        [sys.executable, "-c", "while True: pass"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        time.sleep(0.3)  # let it reach the scheduler's steady state
        yield
    finally:
        spinner.kill()
        spinner.wait()


def both(measure):
    """measure() on an idle machine, then with a busy core beside it: (idle result, loaded result)."""
    idle = measure()
    with busy_core():
        loaded = measure()
    return idle, loaded


def _peak_rss_mb(pid: int) -> float | None:
    """VmHWM (peak resident set, MB) of a running process from /proc, None once it has exited."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def run_command(args, repeats: int = 3, cwd=None, keep_output: bool = True) -> tuple[float, float, str]:
    """Run the real command `repeats` times, each a fresh process with the caller's environment minus any
    *_NUM_THREADS variable. Returns (median wall time s, largest peak resident memory MB, stdout of the last
    run, "" when not `keep_output`: a gigabyte of JSON need not be read back); raises RuntimeError if a run fails.

    Peak memory is the child's own high-water mark (VmHWM in /proc/PID/status), read every 2 ms while it runs;
    the last reading before it exits is its peak (the mark never falls). (The kernel's ru_maxrss of a child would
    count this benchmark process's own memory, inherited across fork.)"""
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    times, rss, out = [], 0.0, ""
    for _ in range(repeats):
        with tempfile.TemporaryFile() as fout, tempfile.TemporaryFile() as ferr:
            peak = 0.0
            t0 = time.perf_counter()
            proc = subprocess.Popen(
                list(map(str, args)), stdout=fout, stderr=ferr, stdin=subprocess.DEVNULL, env=env, cwd=cwd or ROOT
            )
            while proc.poll() is None:
                mark = _peak_rss_mb(proc.pid)
                if mark is not None and proc.poll() is None:
                    peak = max(peak, mark)
                time.sleep(0.002)
            times.append(time.perf_counter() - t0)
            fout.seek(0), ferr.seek(0)
            out, err = (fout.read().decode() if keep_output else ""), ferr.read().decode()
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(map(str, args))} failed ({proc.returncode}): {err[-500:]}")
        rss = max(rss, peak)
    return float(np.median(times)), rss, out


def row(name, value, unit, *, loaded=None, baseline=None, higher_is_better=False, goal=None, met=None, note=""):
    """A result row (see the module docstring). ratio = value / baseline for throughputs (higher_is_better),
    baseline / value for times and sizes."""
    ratio = None
    if baseline is not None and value:
        ratio = value / baseline if higher_is_better else baseline / value
    return {
        "name": name,
        "value": value,
        "loaded": loaded,
        "unit": unit,
        "baseline": baseline,
        "ratio": ratio,
        "goal": goal,
        "met": met,
        "note": note,
    }
