#!/usr/bin/env bash
# Set up .venv and run the whole test suite (notebooks included) in two processes (pytest-xdist,
# about 4 minutes on 2 cores instead of 7). Extra arguments go to pytest: `-n 0` after the
# command runs it in one process (for pdb, or -x to stop at the first failure in order).
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s.%N)
bash scripts/setup.sh
echo "set-up took $(awk -v s="$start" -v e="$(date +%s.%N)" 'BEGIN { printf "%.1f", e - s }') s"
.venv/bin/python -m pytest -q -n 2 "$@"
