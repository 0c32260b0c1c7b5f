"""Shared test settings."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import torch

# The tests' small EM fits are far slower with torch's default 2 threads on a busy 2-core
# machine (10-50x measured): one thread, as the experiments' worker processes use.
torch.set_num_threads(1)
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("TORCHCBL_QUICK", "1")
# tests/ helpers (e.g. _toy_envs) import as top-level modules, also from subprocesses.
sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture
def ascii_locale() -> Iterator[None]:
    """This process's locale as under ``LC_ALL=C``: a file opened without an encoding is read
    and written as ASCII, as on a machine whose locale is C or POSIX (sys.stdout is left as it
    is). Skipped in Python's UTF-8 mode, where the locale's encoding is never used."""
    import codecs
    import locale

    if sys.flags.utf8_mode:
        pytest.skip("Python's UTF-8 mode (PYTHONUTF8=1): files are UTF-8 whatever the locale")
    saved = locale.setlocale(locale.LC_CTYPE)
    try:
        locale.setlocale(locale.LC_CTYPE, "C")
        if codecs.lookup(locale.getencoding()).name != "ascii":
            pytest.skip(f"the C locale's encoding here is {locale.getencoding()}, not ASCII")
        yield
    finally:
        locale.setlocale(locale.LC_CTYPE, saved)
