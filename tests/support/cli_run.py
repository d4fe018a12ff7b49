"""`rrbc ARGS` run in this process (`rrbc_core.cli.main`), returning what a subprocess would (exit code, stdout,
stderr) without a new interpreter's start-up (about a second of imports per call, most of a refusal test's time).
The console script itself (its entry point, signals, environment) is tested through real subprocesses in
tests/cli/test_cli.py and the writer-fault tests."""

from __future__ import annotations

import io
import subprocess
from contextlib import redirect_stderr, redirect_stdout

from rrbc_core.cli import main


def rrbc(*args, timeout=None) -> subprocess.CompletedProcess:
    """The command's exit code, stdout and stderr (text) for `args` (paths and numbers as strings); `timeout` is
    accepted for the subprocess helpers' signature and not used."""
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main([str(a) for a in args])
    return subprocess.CompletedProcess(["rrbc", *map(str, args)], code, out.getvalue(), err.getvalue())
