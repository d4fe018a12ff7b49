#!/usr/bin/env bash
# The main job, set-up included (idempotent): until the browser app lands (issue 4), run RRBC on the bundled
# example measurement file and print the readable table. Extra arguments go to `rrbc correct`.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/setup.sh"
exec "$root/.venv/bin/rrbc" correct "$root/rrbc_core/data/example_measurements.csv" "$@"
