"""Process helpers shared by the tests of worker start-up and Ctrl-C (tests/ is on sys.path)."""

from __future__ import annotations

import os
import signal
from collections.abc import Iterable


def exists(pid: int) -> bool:
    """Whether process ``pid`` exists: running, or dead but not yet reaped (signal 0 finds it)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def kill_left(pids: Iterable[int]) -> None:
    """SIGKILL whichever of ``pids`` a failing test left behind."""
    for pid in pids:
        if exists(pid):
            os.kill(pid, signal.SIGKILL)
