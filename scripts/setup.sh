#!/usr/bin/env bash
# Idempotent set-up on Debian 12 as root: Debian packages, a virtual environment in .venv/ at the
# repository root, and this project installed into it (editable, with the test extras).
# Safe to run again: it skips what is already present.
#   --browser   also install Debian's chromium (driven headless by Playwright in tests/browser and
#               scripts/screenshots.py; never `playwright install`). The app itself does not need it.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

browser=0
for arg in "$@"; do
  case "$arg" in
    --browser) browser=1 ;;
    *) echo "setup: unknown argument '$arg' (usage: setup.sh [--browser])" >&2; exit 2 ;;
  esac
done

# Debian packages: open3d needs libusb-1.0-0, libegl1, libgl1, libx11-6 (see shared notes/stack.md).
debs=(libusb-1.0-0 libegl1 libgl1 libx11-6 libgomp1 python3-venv)
# Browser tests: chromium (software WebGL via SwiftShader, no GPU needed) and a font for headless text.
if [ "$browser" -eq 1 ]; then
  debs+=(chromium fonts-dejavu-core)
fi
missing=()
for p in "${debs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "setup: missing Debian packages ${missing[*]}; run as root or install them" >&2
    exit 1
  fi
  echo "setup: installing Debian packages: ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  # Quiet unless it fails (debconf chatter such as "delaying package configuration" goes to the log).
  log="$(mktemp)"
  if ! { apt-get update -qq && apt-get install -y -qq --no-install-recommends "${missing[@]}"; } >"$log" 2>&1; then
    cat "$log" >&2
    echo "setup: apt-get failed (full log above)" >&2
    rm -f "$log"
    exit 1
  fi
  rm -f "$log"
fi
if [ "$browser" -eq 1 ] && [ ! -x /usr/bin/chromium ]; then
  echo "setup: /usr/bin/chromium is missing although the chromium package is installed" >&2
  exit 1
fi

py="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv" >&2
  "$py" -m venv .venv
fi
stamp=.venv/.rrbc-installed
hash="$(cat pyproject.toml | sha256sum | cut -d' ' -f1)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$hash" ]; then
  echo "setup: installing rrbc and its pinned dependencies into .venv" >&2
  # (pip compiles every installed file's bytecode: keep it. Where PYTHONDONTWRITEBYTECODE is set, as on this
  # machine these figures come from, Python never writes it later, and every process would compile what it imports: tried
  # with --no-compile, the suite took 5 minutes more CPU)
  log="$(mktemp)"
  if ! { .venv/bin/python -m pip install --disable-pip-version-check --upgrade pip \
         && .venv/bin/python -m pip install --disable-pip-version-check -e ".[test]"; } >"$log" 2>&1; then
    cat "$log" >&2
    echo "setup: pip install failed (full log above)" >&2
    rm -f "$log"
    exit 1
  fi
  rm -f "$log"
  echo "$hash" > "$stamp"
fi
# The project's own packages are installed editable, so pip compiles none of their bytecode; where
# PYTHONDONTWRITEBYTECODE is set, every `rrbc` process would compile what it imports (about 0.35 s of CPU for a
# small `rrbc correct` on this machine). Compile them here (only files changed since are recompiled; Python ignores
# a .pyc whose source has changed).
.venv/bin/python -m compileall -q rrbc_core rrbc_viz >/dev/null
