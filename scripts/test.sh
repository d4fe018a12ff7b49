#!/usr/bin/env bash
# The whole test suite, set-up included (idempotent). Extra arguments go to pytest.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/setup.sh" --browser
cd "$root"
# Small matrices everywhere: BLAS threads only contend on 2 cores (measured in tests/test_batch.py).
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}" OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}"
exec "$root/.venv/bin/python" -m pytest -q -p no:cacheprovider "$@"
