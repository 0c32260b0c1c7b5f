#!/usr/bin/env bash
# Create .venv (if missing) and install the project with its test tools.
# torch is installed first, pinned to 2.13.0, so nothing else picks one; the package itself
# declares a range (torch>=2.2) that it satisfies. On this project's machines pip finds the CPU
# build of 2.13.0 in their wheel cache; elsewhere pip's default index gives its default build
# (on Linux x86-64 the CUDA one, several GB): set TORCH_INDEX_URL (e.g.
# https://download.pytorch.org/whl/cpu) to take torch from another index.
# The install is editable, so code changes need no reinstall: when neither pyproject.toml nor
# this script changed since the last successful install (recorded in .venv/.setup-stamp),
# nothing is installed again. Delete .venv/.setup-stamp to force a reinstall.
# The interpreter: $PYTHON if set, else python3.11 if on the PATH, else python3; it must be
# Python 3.11 or newer (pyproject.toml's requires-python), else nothing is done. A .venv made by
# another Python version, or left without pip by a failed `venv` (e.g. no python3-venv package),
# is made again.
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${PYTHON:-$(command -v python3.11 || command -v python3)}"
STAMP=.venv/.setup-stamp
version="$("$PY" -c 'import sys; print(sys.version.split()[0])')"
# pyproject.toml's requires-python: said before anything is made or downloaded
IFS=. read -r major minor _ <<< "$version"
if [ "${major:-0}" -lt 3 ] || { [ "$major" -eq 3 ] && [ "${minor:-0}" -lt 11 ]; }; then
  echo "set-up: $PY is Python $version; torchcbl needs Python 3.11 or newer: install python3.11 (or newer), or set PYTHON to one" >&2
  exit 1
fi
want="$( (cat pyproject.toml scripts/setup.sh; echo "$version") | sha256sum | cut -d' ' -f1)"
if [ -x .venv/bin/python ] && [ -x .venv/bin/torchcbl ] && [ "$(cat "$STAMP" 2>/dev/null)" = "$want" ]; then
  echo "set-up: .venv is up to date (pyproject.toml and Python $version unchanged since its install)"
  exit 0
fi
if [ -x .venv/bin/python ]; then
  have="$(.venv/bin/python -c 'import sys; print(sys.version.split()[0])' 2>/dev/null || true)"
  if [ "$have" != "$version" ] || ! .venv/bin/python -m pip --version >/dev/null 2>&1; then
    echo "set-up: .venv (Python ${have:-unknown}) is not a working venv of Python $version; making it again"
    rm -rf .venv
  fi
fi
if [ ! -x .venv/bin/python ]; then
  if ! "$PY" -m venv .venv; then
    rm -rf .venv
    echo "set-up: '$PY -m venv' failed; on Debian/Ubuntu install the python3.11-venv package (apt install python3.11-venv), or set PYTHON to a Python 3.11 with venv" >&2
    exit 1
  fi
fi
rm -f "$STAMP"
.venv/bin/python -m pip install -q --upgrade pip
if ! .venv/bin/python -m pip install -q ${TORCH_INDEX_URL:+--index-url "$TORCH_INDEX_URL"} "torch==2.13.0"; then
  echo "set-up: torch 2.13.0 could not be installed; falling back to the newest torch>=2.2" >&2
  .venv/bin/python -m pip install -q ${TORCH_INDEX_URL:+--index-url "$TORCH_INDEX_URL"} "torch>=2.2"
fi
.venv/bin/python -m pip install -q -e ".[test]"
echo "$want" > "$STAMP"
