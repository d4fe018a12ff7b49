#!/usr/bin/env bash
# The whole test suite, set-up included (idempotent). Extra arguments go to pytest.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/setup.sh" --browser
cd "$root"
# No thread variables: tests run as users run (rrbc sets its own BLAS pools, docs/threads.md).
# Lint, format and types first (ruff and mypy, configured in pyproject.toml): a failure stops the run before the tests.
"$root/.venv/bin/ruff" check rrbc_core rrbc_viz tests scripts benchmarks examples scenes
"$root/.venv/bin/ruff" format --check rrbc_core rrbc_viz tests scripts benchmarks examples scenes
"$root/.venv/bin/mypy"
# Both cores (pytest-xdist, -n 2): the browser tests run on one worker (one Chromium drawing at a time, docs in
# tests/browser/conftest.py), the rest are spread over both; the 25 slowest are printed. Arguments given after
# override these (e.g. `-n 0` for one process, `-m "not browser and not slow"` for the fast tier).
exec "$root/.venv/bin/python" -m pytest -q -p no:cacheprovider -n 2 --dist loadgroup --durations=25 "$@"
