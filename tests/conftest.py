"""Shared test settings."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import torch

# The tests' small EM fits are far slower with torch's default 2 threads on a busy 2-core
# machine (10-50x measured): one thread, as the experiments' worker processes use.
torch.set_num_threads(1)
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("TORCHCBL_QUICK", "1")
# tests/ helpers (e.g. _toy_envs) import as top-level modules, also from subprocesses.
sys.path.insert(0, str(Path(__file__).parent))
