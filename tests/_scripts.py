"""Run a small script in a process of its own: a run at a script's top level (without
``if __name__ == "__main__":``), or one whose worker process is killed mid-run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent


def run_script(tmp_path: Path, body: str, timeout: float = 60, name: str = "script.py"):
    """Write ``body`` (the script's code, after tests/ and the checkout are put on sys.path)
    to tmp_path/name, run it there and return (exit code, stderr). A script still running
    after ``timeout`` seconds is killed with its workers and fails the test."""
    script = tmp_path / name
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


def run_unguarded(tmp_path: Path, body: str, timeout: float = 60) -> str:
    """Run ``body`` as tmp_path/unguarded.py, a script that starts a run at its top level;
    check that it stopped with the error naming the script and the main guard, and return
    that error's line."""
    code, err = run_script(tmp_path, body, timeout, name="unguarded.py")
    last = err.strip().splitlines()[-1]
    assert code == 1 and last.startswith("RuntimeError: worker processes cannot start: "), err
    assert str(tmp_path / "unguarded.py") in last and "exited with code 1" in last
    assert 'under `if __name__ == "__main__":`' in last
    return last


def skip_without_proc_children() -> None:
    """kill_a_worker_when finds the workers by Linux's /proc/<pid>/task/<tid>/children."""
    if not Path(f"/proc/{os.getpid()}/task/{os.getpid()}/children").exists():
        pytest.skip("needs Linux's /proc/<pid>/task/<tid>/children to find the worker")


def kill_a_worker_when(marker: str) -> None:
    """In a script's thread: once ``marker`` exists (a file a worker writes as it runs),
    SIGKILL one spawned worker of this process, as the out-of-memory killer does."""
    while not Path(marker).exists():
        time.sleep(0.02)
    me = os.getpid()
    for pid in open(f"/proc/{me}/task/{me}/children", encoding="utf-8").read().split():
        if b"spawn_main" in open(f"/proc/{pid}/cmdline", "rb").read():
            os.kill(int(pid), signal.SIGKILL)
            return


class _TwoArgumentError(Exception):
    def __init__(self, a: int, b: int) -> None:  # its pickle calls it with one: unreadable
        super().__init__(a)


def end_this_process(how: str) -> None:
    """In a pool's worker: end it as ``how`` says: SIGKILL (``"kill"``), ``os._exit(3)``
    (``"exit"``) or ``os._exit(0)`` (``"exit-0"``), or raise an exception the parent cannot
    unpickle (``"unpicklable"``). (Here, not in a test module: a worker imports only this.)"""
    if how == "exit":
        os._exit(3)
    if how == "exit-0":
        os._exit(0)
    if how == "unpicklable":
        raise _TwoArgumentError(1, 2)
    os.kill(os.getpid(), signal.SIGKILL)
