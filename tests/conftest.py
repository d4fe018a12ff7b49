"""Test-wide settings: hypothesis runs derandomised (the same examples every run, no example database), so the
suite is deterministic like every other seeded test here. Set HYPOTHESIS_PROFILE=explore to search afresh.

The test processes run under rrbc's own process policy, as the command line and the app server do: one BLAS thread
(`rrbc_core.runtime.threads.apply_process_policy`, docs/threads.md; no environment variable). The suite runs on two
workers on two cores (scripts/test.sh), and tests call library internals that are not entry points: OpenBLAS's
second, spinning thread would fight the other worker for a core (a calibration test took 9x as long). The policy
itself, and the entry points' limit in a user's process, are tested in subprocesses (tests/runtime/test_threads.py)."""

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import settings

from rrbc_core.runtime.threads import apply_process_policy

apply_process_policy()

# Each test process (each pytest-xdist worker) has a temporary folder of its own: tests that count the app's
# temporary files (uploads spooled to disk, tests/viz/test_upload_spool.py) see their own process's, not those of a
# test running beside them on the other worker. Removed when the process ends.
tempfile.tempdir = tempfile.mkdtemp(prefix=f"rrbc-tests-{os.environ.get('PYTEST_XDIST_WORKER', 'main')}-")
atexit.register(shutil.rmtree, tempfile.tempdir, ignore_errors=True)

settings.register_profile("deterministic", derandomize=True, database=None, deadline=None, print_blob=True)
settings.register_profile("explore", deadline=None, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))


# Modules whose module-scoped fixtures are costly run on one pytest-xdist worker each (scripts/test.sh: --dist
# loadgroup), so the fixture is built once, not once per worker: the reproduction study's simulated moments (about
# 30 s), calibrate's compliance cases, the reproduce report, the dask cluster. xdist hands out work units largest
# first (by test count), and the browser tests are one unit of 21 on one worker: at most one group may be larger
# (test_reproduction, 45 tests), or the browser unit starts after two others and the run grows by minutes (measured:
# grouping test_metrics too, 61 tests, took 14 min 12 s against 11 min 55 s).
SHARED_FIXTURE_MODULES = (
    "studies/test_reproduction.py",
    "analysis/test_compliance.py",
    "cli/test_cli_reproduce.py",
    "runtime/test_tasks.py",
)
_TESTS = Path(__file__).resolve().parent


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the groups (its worker plugin registers after us)
def pytest_collection_modifyitems(config, items) -> None:
    for item in items:
        path = Path(str(item.fspath)).resolve()
        if _TESTS in path.parents and (rel := path.relative_to(_TESTS).as_posix()) in SHARED_FIXTURE_MODULES:
            item.add_marker(pytest.mark.xdist_group(rel))
