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
