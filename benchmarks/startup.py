"""What a command costs before it reads a byte (issue 41, item 4): `rrbc --help`, a fresh process each time, CPU
time (user + system) of the child, idle and with a busy core beside it.

- `startup_help`: `rrbc --help` (the parser of every subcommand, no scipy, no thread controller: the process policy
  is applied after the arguments are parsed); baseline: a Python process that imports numpy, what any numpy program
  pays. Goal: the loaded CPU time under 0.25 s.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys

import numpy as np
from harness import both, row

REPEATS = 7


def _cpu(args: list[str], repeats: int) -> float:
    """Median CPU time (s, user + system) of `repeats` fresh processes running `args` (the caller's environment
    minus thread variables); raises RuntimeError when one fails."""
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    times = []
    for _ in range(repeats):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run(args, env=env, capture_output=True, check=False)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if done.returncode != 0:
            raise RuntimeError(f"{args}: exit {done.returncode}: {done.stderr.decode(errors='replace')[-300:]}")
        times.append((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime))
    return float(np.median(times))


def startup(quick: bool) -> list[dict]:
    """Row `startup_help` (module docstring)."""
    repeats = 3 if quick else REPEATS
    command = [sys.executable, "-c", "import sys; from rrbc_core.cli import main; sys.exit(main(sys.argv[1:]))"]

    def measure():
        return _cpu([sys.executable, "-c", "import numpy"], repeats), _cpu([*command, "--help"], repeats)

    (idle_base, idle), (busy_base, busy) = both(measure)
    return [
        row(
            "startup_help",
            busy,
            "s",
            loaded=busy,
            baseline=busy_base,
            goal="loaded CPU time < 0.25 s",
            met=bool(busy < 0.25),
            note=f"CPU time of a fresh `rrbc --help`; idle {idle * 1e3:.0f} ms against {idle_base * 1e3:.0f} ms for "
            "`python -c 'import numpy'`",
        )
    ]
