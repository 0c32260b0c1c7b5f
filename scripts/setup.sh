#!/usr/bin/env bash
# Create .venv (if missing) and install the project with its test tools.
# torch is installed first, pinned to the CPU build this machine carries, so nothing else
# pulls a CUDA build; the package itself declares a range (torch>=2.2) that it satisfies.
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q "torch==2.13.0" || .venv/bin/python -m pip install -q "torch>=2.2"
.venv/bin/python -m pip install -q -e ".[test]"
