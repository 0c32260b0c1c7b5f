#!/usr/bin/env bash
# Set up .venv and run the whole test suite (notebooks included). Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/python -m pytest -q "$@"
