#!/usr/bin/env bash
# The main job, set-up included (idempotent): the RRBC explorer in the browser on the bundled default scene.
# Prints the URL (http://127.0.0.1:8080 unless the port is taken) and runs until Ctrl+C.
# Extra arguments go to `rrbc view`, e.g. `bash scripts/run.sh scenes/peg_in_hole_cell.toml --port 9000`.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/setup.sh"
exec "$root/.venv/bin/rrbc" view "$@"
