#!/usr/bin/env bash
# Set up .venv and run the main job: the paper's reproduction in quick mode.
# Extra arguments go to `torchcbl reproduce` (e.g. --full for the paper's sizes).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/torchcbl reproduce "$@"
