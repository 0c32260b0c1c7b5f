#!/usr/bin/env bash
# Create .venv (if missing) and install the project with its test tools.
# torch is installed first, pinned to the CPU build this machine carries, so nothing else
# pulls a CUDA build; the package itself declares a range (torch>=2.2) that it satisfies.
# The install is editable, so code changes need no reinstall: when neither pyproject.toml nor
# this script changed since the last successful install (recorded in .venv/.setup-stamp),
# nothing is installed again. Delete .venv/.setup-stamp to force a reinstall.
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${PYTHON:-python3}"
STAMP=.venv/.setup-stamp
want="$(cat pyproject.toml scripts/setup.sh | sha256sum | cut -d' ' -f1)"
if [ -x .venv/bin/python ] && [ -x .venv/bin/torchcbl ] && [ "$(cat "$STAMP" 2>/dev/null)" = "$want" ]; then
  echo "set-up: .venv is up to date (pyproject.toml unchanged since its install)"
  exit 0
fi
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
rm -f "$STAMP"
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q "torch==2.13.0" || .venv/bin/python -m pip install -q "torch>=2.2"
.venv/bin/python -m pip install -q -e ".[test]"
echo "$want" > "$STAMP"
