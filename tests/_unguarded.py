"""Run a script that starts a run at its top level, without ``if __name__ == "__main__":``."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent


def run_unguarded(tmp_path: Path, body: str, timeout: float = 60) -> tuple[int, str]:
    """Write ``body`` (the script's top-level code, after tests/ and the checkout are put on
    sys.path) to tmp_path/unguarded.py, run it and return (exit code, stderr). A script still
    running after ``timeout`` seconds is killed with its workers and fails the test."""
    script = tmp_path / "unguarded.py"
    script.write_text(f"import sys\nsys.path[:0] = [{str(TESTS)!r}, {str(ROOT)!r}]\n{body}")
    proc = subprocess.Popen(
        [sys.executable, str(script)],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
        start_new_session=True,  # its workers too are killed on a timeout
    )
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        _, err = proc.communicate()
        raise AssertionError(
            f"the script still ran after {timeout} s; its stderr ends with:\n{err[-2000:]}"
        ) from None
    return proc.returncode, err
