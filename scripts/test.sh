#!/usr/bin/env bash
# Set up .venv and run the whole test suite (notebooks included). Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s.%N)
bash scripts/setup.sh
echo "set-up took $(awk -v s="$start" -v e="$(date +%s.%N)" 'BEGIN { printf "%.1f", e - s }') s"
.venv/bin/python -m pytest -q "$@"
