"""The investigation scripts as a user runs them: ``python scripts/X.py ...``."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(script: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(ROOT / "scripts" / script), *args],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        cwd=ROOT,
        timeout=120,
    )


@pytest.mark.parametrize(
    ("script", "args", "expected"),
    [
        ("corridor_var_floor.py", ["RUN", "--floors", "1e-3,x"], "finite numbers >= 0"),
        ("corridor_var_floor.py", ["RUN", "--cap", "0"], "whole number >= 1"),
        ("corridor_table_search.py", ["--penalties", "1,two"], "finite numbers >= 0"),
        ("corridor_table_search.py", ["--steps", "0"], "whole number >= 1"),
        ("corridor_cba_gates.py", ["--seeds", "0-x"], "a range, e.g. 0-9"),
        ("investigate_corridor_requests.py", ["--seeds", "3,a"], "a range, e.g. 0-9"),
        ("driving_components_at_clip.py", ["--caps", "30,0"], "whole numbers >= 1"),
    ],
)
def test_a_malformed_number_is_a_usage_error_before_anything_runs(script, args, expected):
    # Before, each died with a traceback (ValueError from float() or int(), or from
    # GaussianMixtureSet for --cap 0), corridor_var_floor's after printing its table's header.
    flag = next(a for a in args if a.startswith("--"))
    done = _run(script, *args)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert done.stdout == "" and "Traceback" not in done.stderr, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert f"error: argument {flag}: expected" in last and expected in last, last
